#pragma once
// The solver's records that the CUDA loop (cuda_solver_device.h, compiled by nvcc) fills as
// well: plain C++, no Eigen or OpenCV, so that both sides share one definition (solver.h has the
// rest of SolverSummary).

#include <cmath>

#include "compensation/host_device.h"

namespace procam {

enum class TerminationType {
  // ‖E − P(E − ∇f(E))‖∞ ≤ gradient_tolerance·(1 + f): a first-order critical point.
  kGradientTolerance,
  // f(E_k) − f(E_k+1) ≤ function_tolerance · f(E_k).
  kFunctionTolerance,
  // The closed-form methods (naive, reverse) return after one evaluation.
  kClosedForm,
  // max_iterations outer iterations were done without meeting a tolerance.
  kMaxIterations,
  // No step along the Gauss–Newton direction satisfied the Armijo condition (f is then at a
  // point where the model no longer predicts decrease; the result is still feasible).
  kLineSearchFailure,
  // The objective or a direction became non-finite; the last finite iterate is returned.
  kNumericalFailure,
};
const char* TerminationName(TerminationType type);

struct IterationRecord {
  int iteration = 0;
  double cost = 0.0;
  double seconds = 0.0;          // since the solve started
  double step = 0.0;             // line-search step length (0 for the start)
  int free_variables = 0;
  int cg_iterations = 0;
  double projected_gradient = 0.0;  // ‖E − P(E − ∇f)‖∞
};

// Alg. 1's Armijo test of a line-search trial, and the message when no trial passes: one rule
// for the CPU loop (solver.cc) and the CUDA loop (cuda_solver.cu).
PROCAM_HOST_DEVICE inline bool ArmijoAccepts(double trial_cost, double cost, double armijo, double step, double slope) {
  return std::isfinite(trial_cost) && trial_cost <= cost + armijo * step * slope;
}
inline constexpr char kNoArmijoStep[] = "no Armijo step along the Gauss-Newton direction";

}  // namespace procam
