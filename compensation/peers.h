#pragma once
// Peer solvers for the bound-constrained compensation objective
//
//   minimise f(E)  subject to  lower ≤ E ≤ upper   (objective.h; paper Eq. 5–6),
//
// built on general-purpose optimisers. They are baselines and oracles for the active-set
// Gauss–Newton solver of solver.h: tests check that all of them reach the same objective, and
// benchmarks compare their speed. None of them uses the structure that solver.h exploits
// (sparse colour-space Hessian, preconditioned CG), so they are for small problems:
//
//   SolveWithCeres              Levenberg–Marquardt (Ceres Solver) on the least-squares form of
//                               f (CompensationLeastSquares) with an analytic Jacobian and a
//                               dense QR factorisation, inside an outer active-set loop that
//                               holds binding variables constant (Ceres's clipped LM steps stall
//                               once bounds bind). The Jacobian is dense, (3n + 3m) × 3n for n
//                               patches and m adjacent pairs, so keep to ≤ ~3000 variables
//                               (n ≤ ~1000 patches).
//   SolveWithLbfgsb             L-BFGS-B (LBFGSpp) on f and ∇f.
//   SolveWithProjectedGradient  Projected gradient descent with a Barzilai–Borwein first trial
//                               step and Armijo backtracking along the projection arc.
//
// Every solver projects `initial` onto the bounds first and returns a point within them. They
// never throw on numerical trouble: a non-finite objective, a failed line search or invalid
// options end the solve with a `termination` that says so, and the best feasible point seen.

#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "compensation/objective.h"

namespace procam {

struct PeerOptions {
  // Iterations (LM steps tried, L-BFGS-B iterations, projected-gradient steps), ≥ 0. With 0 the
  // projected initial point is returned.
  int max_iterations = 1000;
  // Stop when an iteration lowers f by less than function_tolerance · f (relative decrease), ≥ 0.
  double function_tolerance = 1e-12;
  // First-order optimality, ≥ 0. L-BFGS-B and projected gradient stop when
  // ‖E − P(E − ∇f)‖∞ ≤ gradient_tolerance · (1 + f), as solver.h does. Ceres applies its own
  // test, ‖E − P(E − ∇(f/2))‖∞ ≤ gradient_tolerance (absolute, on its cost f/2).
  double gradient_tolerance = 1e-10;
  // Stop when a step changes E by at most parameter_tolerance · (‖E‖₂ + parameter_tolerance)
  // (Ceres's test; the others use it too, on accepted steps), ≥ 0.
  double parameter_tolerance = 1e-12;

  bool Check(std::string* why) const;
};

struct PeerResult {
  Eigen::MatrixX3d emittance;  // E (n×3), within the bounds
  double cost = 0.0;           // f(E), objective.h's value (Ceres's cost is f/2)
  // Accepted steps for L-BFGS-B and projected gradient; for Ceres the iterations its summaries
  // list (successful and unsuccessful LM steps) over all active-set rounds.
  int iterations = 0;
  double seconds = 0.0;  // wall time of the whole call
  // Why the solve stopped: one of "gradient tolerance", "function tolerance",
  // "parameter tolerance", "max iterations", "line search failure" (no acceptable step),
  // "solver failure" (another error inside the library), "numerical failure" (f or ∇f not
  // finite), "invalid options" or "invalid input" (wrong sizes, non-finite initial point or
  // bounds), optionally followed by ": " and details.
  std::string termination;
  // (seconds since the start, f) for the initial point, then after each iteration.
  std::vector<std::pair<double, double>> trace;
};

PeerResult SolveWithCeres(const CompensationObjective& objective, const Eigen::MatrixX3d& initial,
                          const PeerOptions& options);
PeerResult SolveWithLbfgsb(const CompensationObjective& objective, const Eigen::MatrixX3d& initial,
                           const PeerOptions& options);
PeerResult SolveWithProjectedGradient(const CompensationObjective& objective,
                                      const Eigen::MatrixX3d& initial, const PeerOptions& options);

// The objective as a sum of squares, f(E) = ‖ρ(E)‖², as SolveWithCeres sees it. The residual
// vector ρ holds, in this order,
//   rows 3i + k      (patch i):           sqrt(α A_i / A_avg) · r_ik
//   rows 3n + 3p + k (adjacent pair p = (i, j)): sqrt(1 − α) · (r_ik − r_jk)
// with r = C(B) − C(Bd) the objective's colour residual (k = colour component). Its Jacobian
// with respect to the flattened E (patch-major, column 3j + c) follows from B_c = K_c⁻¹ E_c:
//   ∂r_i/∂E_jc = (∂C/∂B)_i(:, c) · (K_c⁻¹)_ij.
// Keeps a reference to `objective`; holds the dense K_c⁻¹ (n² doubles per channel).
class CompensationLeastSquares {
 public:
  explicit CompensationLeastSquares(const CompensationObjective& objective);

  int residuals() const { return 3 * (objective_.patches() + pairs()); }
  int variables() const { return objective_.variables(); }
  int pairs() const { return static_cast<int>(objective_.problem().adjacency.size()); }

  // Fills ρ (residuals()) and, if `jacobian` is not null, the dense ∂ρ/∂E (residuals() ×
  // variables()). Returns false, leaving the outputs unspecified, if anything is non-finite.
  bool Evaluate(const Eigen::MatrixX3d& emittance, Eigen::VectorXd* residual,
                Eigen::MatrixXd* jacobian) const;
  // The same for raw row-major output buffers (Ceres's layout); `jacobian` may be null.
  bool Evaluate(const Eigen::MatrixX3d& emittance, double* residual, double* jacobian) const;

 private:
  const CompensationObjective& objective_;
  Eigen::VectorXd patch_scale_;           // sqrt(α A_i / A_avg)
  double pair_scale_ = 0.0;               // sqrt(1 − α)
  std::vector<Eigen::MatrixXd> inverse_;  // K_c⁻¹ per channel
};

}  // namespace procam
