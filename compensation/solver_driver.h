#pragma once
// The control flow of the paper's Alg. 1 (active-set Gauss–Newton with an Armijo line search)
// and Alg. 2 (modified projected Newton on the quadratic model), written once for every place it
// runs: the CPU (solver.cc: Eigen vectors), the GPU loop with a kernel per step (cuda_solver.cu:
// kernel launches, the host reading a few scalars back) and the GPU's fused loop (cuda_solver.cu:
// phases of one cooperative kernel with grid barriers between them, the driver running in every
// thread). Plain C++ without Eigen or the standard library's containers, compiled for the device
// as well (PROCAM_HOST_DEVICE): a change to the stopping rules or the steps' acceptance is made
// here, for all three.
//
// The driver decides; an executor does the vector work and returns the scalars the decisions
// need. Executor (the operations in the order the driver calls them; x the iterate, g = ∇f(x),
// d Alg. 2's step, s CG's solution, q(d) = gᵀd + ½ dᵀHd the model, l ≤ x ≤ u the bounds):
//
//   double Evaluate()                 f at the start (already within the bounds)
//   int Variables() const             3n
//   GradientCheck Gradient()          g at x, ‖x − P(x − g)‖∞, and the variables Eq. 12 leaves
//                                     free (fixed: at a bound with g pointing out of the box)
//   double InnerStart(bool first)     Alg. 2: ∇q = g + Hd at d (first: d = 0), the free mask (fixed
//                                     variables, and those at a bound of l − x ≤ d ≤ u − x with
//                                     ∇q pointing out), ‖d − P(d − ∇q)‖∞ over the non-fixed ones
//   NewtonStep SolveNewton()          CG on H_FF s = −∇q_F from s = 0 (the executor's own
//                                     preconditioner), to cg_tolerance or max_cg_iterations
//   TrialStep StepTrial(double alpha) δ = P(d + α s) − d within l − x ≤ · ≤ u − x
//   double StepCurvature()            δᵀHδ (one Hessian product)
//   void AcceptStep(bool accumulate)  d += δ; Hd += Hδ where `accumulate` (another inner
//                                     iteration follows; StepCurvature ran)
//   SearchDirection Direction()       Alg. 1's direction: d, and gᵀd
//   double SteepestDirection()        d = P(x − g) − x instead; returns gᵀd
//   double LineTrial(double step)     f(P(x + step·d)) (the trial point, kept until the next)
//   void AcceptTrial()                x = the last line trial (its f, g, ... go with it)
//   double FinalProjectedGradient()   ‖x − P(x − g)‖∞ at x, for the record
//   void Record(int iteration, double cost, double step, int free_variables, int cg_iterations)
//                                     one trace entry (and the progress callback, where there is
//                                     one); projected gradient 0 until SetProjectedGradient
//   void SetProjectedGradient(double) the last trace entry's
//
// Executors may run work ahead of the driver's calls (the loop with a kernel per step starts CG
// while the host reads the gradient test, and evaluates the line search's first trial with the
// direction's slope), as long as each operation returns what it would have returned alone.

#include "compensation/host_device.h"
#include "compensation/solver_records.h"

namespace procam {

// The numbers of SolverOptions that steer Alg. 1 and 2 (SolverOptions derives from this; the
// device takes it as it is).
struct AlgorithmSettings {
  // Outer (Gauss–Newton) iterations, ≥ 1.
  int max_iterations = 100;
  // Inner projected-Newton iterations per outer iteration (Alg. 2), ≥ 1. The paper runs
  // Alg. 2 to convergence; one iteration (the outer loop then updates the active set) was
  // measured 2–5× faster to the same optimum on our benchmark rooms (docs/solver.md).
  int max_inner_iterations = 1;
  // Conjugate-gradient iterations per Newton system, ≥ 1.
  int max_cg_iterations = 200;
  // Relative CG residual at which a Newton system counts as solved, in (0, 1) (an inexact
  // Newton forcing term; also the inner solver's relative stopping tolerance). 0.3 reached the
  // benchmark's target 10–30% sooner than 0.1 with multires (docs/solver.md).
  double cg_tolerance = 0.3;
  // Add the second-order term of the colour transform (block diagonal in B, so the same cost
  // per product) to the Gauss–Newton model, making it the exact Hessian; CG stops at negative
  // curvature and the preconditioner stays Gauss–Newton. Off: the paper's pure Gauss–Newton,
  // which converges only linearly on large-residual problems (unreachable desired colours).
  bool second_order = true;
  // Stop when ‖E − P(E − ∇f)‖∞ ≤ gradient_tolerance · (1 + f) (first-order optimality), ≥ 0.
  double gradient_tolerance = 1e-9;
  // Stop when an iteration lowers f by less than function_tolerance · f, ≥ 0.
  double function_tolerance = 1e-12;
  // Armijo sufficient-decrease constant, in (0, 0.5).
  double armijo = 1e-4;
};

// What one run of the driver counted and how it ended (SolverSummary's fields of the same names).
struct DriverRecords {
  TerminationType termination = TerminationType::kMaxIterations;
  double initial_cost = 0.0;
  double final_cost = 0.0;
  int iterations = 0;
  int inner_iterations = 0;
  int cg_iterations = 0;
  int evaluations = 0;
  int gradients = 0;
  int hessian_products = 0;
  int preconditioner_applications = 0;
};

// SolverSummary::message for a termination the driver reports ("" for the others).
inline const char* TerminationMessage(TerminationType termination) {
  switch (termination) {
    case TerminationType::kNumericalFailure:
      return "objective is not finite at the start";
    case TerminationType::kLineSearchFailure:
      return kNoArmijoStep;
    default:
      return "";
  }
}

// Executor results.
struct GradientCheck {
  double projected_gradient;  // ‖x − P(x − g)‖∞
  int free_variables;         // not fixed by Eq. 12
};
struct NewtonStep {
  int iterations;  // CG iterations, one Hessian product each
  int preconditioner_applications;
  bool finite;       // every entry of s is finite
  double max_abs;    // max |s_k|
  double slope;      // ∇qᵀs
  double curvature;  // sᵀHs (from CG's residual where it converged)
};
struct TrialStep {
  bool cut;      // the projection moved some entry: δ ≠ α s
  double slope;  // ∇qᵀδ
};
struct SearchDirection {
  bool finite;   // every entry of d is finite
  double slope;  // gᵀd
};

// Preconditioned conjugate gradients on H_FF s = b from s = 0, as SolveNewton runs it (the CPU's
// NewtonSystem::SolveMasked, the GPU's CG phases): the vector work is each executor's, the
// decisions are these. CG stops at non-positive curvature (with the step so far, or with p itself
// when that happens in the first iteration: a descent direction), once ‖r‖ ≤ tolerance ‖r0‖, or
// after max_iterations products.
struct CgState {
  double r0;         // ‖r‖ at the start
  double rz;         // rᵀz
  double curvature;  // pᵀHp of the last iteration
  double step;       // rᵀz / pᵀHp
  double beta;
  int iterations;  // products done
  int preconditioner_applications;
  int done;            // CG has stopped: converged, negative curvature or the iteration limit
  int negative_first;  // stopped at negative curvature in its first iteration: the solution is p
};

// The start: r = b, z = M⁻¹r, p = z; `residual_norm` = ‖r‖, `rz` = rᵀz. Done at once when b = 0.
PROCAM_HOST_DEVICE inline void CgStart(CgState& cg, double residual_norm, double rz) {
  cg.r0 = residual_norm;
  cg.rz = rz;
  cg.curvature = cg.step = cg.beta = 0.0;
  cg.iterations = 0;
  cg.done = residual_norm == 0.0 ? 1 : 0;
  cg.preconditioner_applications = cg.done ? 0 : 1;
  cg.negative_first = 0;
}

// After a product: `curvature` = pᵀHp. Counts the product; stops at non-positive curvature, else
// sets the step length rᵀz / pᵀHp (x += step p, r −= step Hp follow).
PROCAM_HOST_DEVICE inline void CgCurvature(CgState& cg, double curvature) {
  ++cg.iterations;
  cg.curvature = curvature;
  if (!(curvature > 0.0)) {
    cg.done = 1;
    cg.negative_first = cg.iterations == 1 ? 1 : 0;
  } else {
    cg.step = cg.rz / curvature;
  }
}

// After the step: `residual_norm` = ‖r‖. Stops when converged; returns whether CG goes on (z =
// M⁻¹r and CgDirection follow).
PROCAM_HOST_DEVICE inline bool CgResidual(CgState& cg, double residual_norm, double tolerance) {
  if (residual_norm <= tolerance * cg.r0) cg.done = 1;
  return cg.done == 0;
}

// With the new rᵀz: β = rᵀz / (rᵀz)_previous (p = z + β p follows); stops at the iteration limit.
PROCAM_HOST_DEVICE inline void CgDirection(CgState& cg, double rz, int max_iterations) {
  ++cg.preconditioner_applications;
  cg.beta = rz / cg.rz;
  cg.rz = rz;
  if (cg.iterations >= max_iterations) cg.done = 1;
}

// Alg. 2's first step length along s: the minimiser of q along s where the curvature is
// positive (never negative), else 1. The GPU loops also form it on the device, for a first trial
// enqueued before the host reads it.
PROCAM_HOST_DEVICE inline double InnerStepLength(double slope, double curvature) {
  if (!(curvature > 0.0)) return 1.0;
  const double minimiser = -slope / curvature;
  return minimiser < 0.0 ? 0.0 : minimiser;  // std::max(minimiser, 0.0), NaN included
}

// Alg. 2 from d = 0: leaves the step in the executor's d. `cg_total` gets the CG iterations.
PROCAM_HOST_DEVICE_TEMPLATE
template <typename Executor>
PROCAM_HOST_DEVICE void SolveInnerQp(const AlgorithmSettings& settings, Executor& executor,
                                     DriverRecords* records, int* cg_total) {
  double first_norm = -1.0;
  for (int inner = 0; inner < settings.max_inner_iterations; ++inner) {
    const double projected = executor.InnerStart(inner == 0);
    if (first_norm < 0.0) first_norm = projected;
    if (projected <= settings.cg_tolerance * first_norm || projected == 0.0) break;
    ++records->inner_iterations;
    const NewtonStep newton = executor.SolveNewton();
    *cg_total += newton.iterations;
    records->hessian_products += newton.iterations;
    records->preconditioner_applications += newton.preconditioner_applications;
    if (!newton.finite || newton.max_abs == 0.0) break;
    // The minimiser along s, then projection; halve until q decreases enough. Where the
    // projection cuts nothing, δᵀHδ = α² sᵀHs comes from CG; Hδ itself is only needed when
    // another inner iteration follows.
    const bool last_inner = inner + 1 == settings.max_inner_iterations;
    double alpha = InnerStepLength(newton.slope, newton.curvature);
    bool accepted = false;
    for (int halving = 0; halving < 30 && alpha > 0.0; ++halving, alpha *= 0.5) {
      const TrialStep trial = executor.StepTrial(alpha);
      double quadratic = alpha * alpha * newton.curvature;
      if (trial.cut || !last_inner) {
        const double exact = executor.StepCurvature();
        ++records->hessian_products;
        if (trial.cut) quadratic = exact;
      }
      const double change = trial.slope + 0.5 * quadratic;
      if (change <= 1e-4 * trial.slope && change < 0.0) {
        executor.AcceptStep(!last_inner);
        accepted = true;
        break;
      }
    }
    if (!accepted) break;
  }
}

// Alg. 1 from the executor's start point (within the bounds): fills `records` (counters from 0).
PROCAM_HOST_DEVICE_TEMPLATE
template <typename Executor>
PROCAM_HOST_DEVICE void MinimiseBoundedDriver(const AlgorithmSettings& settings, Executor& executor,
                                              DriverRecords* records) {
  *records = DriverRecords();
  double cost = executor.Evaluate();
  ++records->evaluations;
  records->initial_cost = cost;
  executor.Record(0, cost, 0.0, executor.Variables(), 0);
  if (!std::isfinite(cost)) {
    records->termination = TerminationType::kNumericalFailure;
    records->final_cost = cost;
    return;
  }
  for (int iteration = 1; iteration <= settings.max_iterations; ++iteration) {
    const GradientCheck check = executor.Gradient();
    ++records->gradients;
    executor.SetProjectedGradient(check.projected_gradient);
    if (check.projected_gradient <= settings.gradient_tolerance * (1.0 + cost)) {
      records->termination = TerminationType::kGradientTolerance;
      break;
    }
    int cg = 0;
    SolveInnerQp(settings, executor, records, &cg);
    records->cg_iterations += cg;
    const SearchDirection direction = executor.Direction();
    double slope = direction.slope;
    if (!direction.finite || !(slope < 0.0))
      slope = executor.SteepestDirection();  // projected steepest descent
    // Armijo along the (feasible) segment x + a·d, a ∈ (0, 1].
    double step = 1.0, trial_cost = 0.0;
    bool accepted = false;
    for (int halving = 0; halving < 40; ++halving, step *= 0.5) {
      trial_cost = executor.LineTrial(step);
      ++records->evaluations;
      if (ArmijoAccepts(trial_cost, cost, settings.armijo, step, slope)) {
        accepted = true;
        break;
      }
    }
    records->iterations = iteration;
    if (!accepted) {
      records->termination = TerminationType::kLineSearchFailure;
      break;
    }
    const double previous = cost;
    executor.AcceptTrial();
    cost = trial_cost;
    executor.Record(iteration, cost, step, check.free_variables, cg);
    if (previous - cost <= settings.function_tolerance * previous) {
      records->termination = TerminationType::kFunctionTolerance;
      executor.SetProjectedGradient(executor.FinalProjectedGradient());
      break;
    }
  }
  records->final_cost = cost;
}

}  // namespace procam
