#include "compensation/solver.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>

#include <Eigen/SparseCholesky>

namespace procam {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

Eigen::MatrixX3d Clamp(const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& lower, const Eigen::MatrixX3d& upper) {
  return x.cwiseMax(lower).cwiseMin(upper);
}

double Dot(const Eigen::MatrixX3d& a, const Eigen::MatrixX3d& b) { return a.cwiseProduct(b).sum(); }

// The Newton systems of one outer iteration: H restricted to a set of free variables,
// preconditioned by (K M⁻¹ Kᵀ) restricted to the same set.
class NewtonSystem {
 public:
  // `colour_hessian` is reused across outer iterations: its symbolic analysis (fill-reducing
  // ordering) is done on the first call only, since M's sparsity pattern never changes.
  NewtonSystem(const CompensationObjective& objective, const ObjectivePoint& point,
               Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>* colour_hessian, bool analysed)
      : objective_(objective), point_(point), colour_hessian_(*colour_hessian) {
    // The preconditioner is always the Gauss–Newton inverse K M⁻¹ Kᵀ (M is positive definite);
    // products may include the second-order term, whose negative curvature CG detects.
    ObjectivePoint gauss_newton;
    gauss_newton.colour_jacobian = point.colour_jacobian;
    const Eigen::SparseMatrix<double> m = objective.ColourHessian(gauss_newton);
    if (!analysed) colour_hessian_.analyzePattern(m);
    colour_hessian_.factorize(m);
    preconditioner_ok_ = colour_hessian_.info() == Eigen::Success;
  }

  Eigen::MatrixX3d Product(const Eigen::MatrixX3d& v) const {
    return objective_.GaussNewtonProduct(point_, v, /*fast=*/true);
  }

  Eigen::MatrixX3d Precondition(const Eigen::MatrixX3d& r) const {
    if (!preconditioner_ok_) return r;
    const Eigen::MatrixX3d kt = objective_.radiosity().MultiplyTransposedFast(r);
    const Eigen::MatrixX3d solved = Unflatten(colour_hessian_.solve(Flatten(kt)));
    return objective_.radiosity().MultiplyFast(solved);
  }

  // Preconditioned CG on H_FF p = rhs_F (mask: 1 on free variables). Returns iterations used.
  int SolveMasked(const Eigen::MatrixX3d& rhs, const Eigen::MatrixX3d& mask, int max_iterations,
                  double tolerance, Eigen::MatrixX3d* solution) const {
    Eigen::MatrixX3d x = Eigen::MatrixX3d::Zero(rhs.rows(), 3);
    Eigen::MatrixX3d r = rhs.cwiseProduct(mask);
    const double r0 = r.norm();
    if (r0 == 0.0) {
      *solution = x;
      return 0;
    }
    Eigen::MatrixX3d z = Precondition(r).cwiseProduct(mask);
    Eigen::MatrixX3d p = z;
    double rz = Dot(r, z);
    int iteration = 0;
    while (iteration < max_iterations) {
      ++iteration;
      const Eigen::MatrixX3d hp = Product(p).cwiseProduct(mask);
      const double curvature = Dot(p, hp);
      if (!(curvature > 0.0)) {
        // Negative curvature (second-order term): stop with the descent direction so far.
        if (iteration == 1) x = p;
        break;
      }
      const double step = rz / curvature;
      x += step * p;
      r -= step * hp;
      if (r.norm() <= tolerance * r0) break;
      z = Precondition(r).cwiseProduct(mask);
      const double rz_next = Dot(r, z);
      p = z + (rz_next / rz) * p;
      rz = rz_next;
    }
    *solution = x;
    return iteration;
  }

 private:
  const CompensationObjective& objective_;
  const ObjectivePoint& point_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>& colour_hessian_;
  bool preconditioner_ok_ = false;
};

// Alg. 2 (modified projected Newton) on the Gauss–Newton model
//   q(d) = gᵀd + ½ dᵀHd,  lo ≤ d ≤ hi,  d fixed at 0 where `fixed` is 1.
// Rows and columns of bound variables are dropped from H (not diagonalised), as in the paper.
Eigen::MatrixX3d SolveInnerQp(const SolverOptions& options, const NewtonSystem& system,
                              const Eigen::MatrixX3d& gradient, const Eigen::MatrixX3d& lo,
                              const Eigen::MatrixX3d& hi, const Eigen::MatrixX3d& fixed,
                              SolverSummary* summary, int* cg_total) {
  const int n = static_cast<int>(gradient.rows());
  Eigen::MatrixX3d d = Eigen::MatrixX3d::Zero(n, 3);
  Eigen::MatrixX3d hd = Eigen::MatrixX3d::Zero(n, 3);
  double q = 0.0;
  double first_norm = -1.0;
  for (int inner = 0; inner < options.max_inner_iterations; ++inner) {
    const Eigen::MatrixX3d q_gradient = gradient + hd;
    const double eps = 1e-13;
    Eigen::MatrixX3d mask(n, 3);
    for (int i = 0; i < n; ++i) {
      for (int c = 0; c < 3; ++c) {
        const bool at_lo = d(i, c) <= lo(i, c) + eps * (1.0 + std::abs(lo(i, c)));
        const bool at_hi = d(i, c) >= hi(i, c) - eps * (1.0 + std::abs(hi(i, c)));
        const bool bound = fixed(i, c) != 0.0 || (at_lo && q_gradient(i, c) > 0.0) || (at_hi && q_gradient(i, c) < 0.0);
        mask(i, c) = bound ? 0.0 : 1.0;
      }
    }
    const double projected = ((d - q_gradient).cwiseMax(lo).cwiseMin(hi) - d).cwiseProduct(Eigen::MatrixX3d::Ones(n, 3) - fixed).cwiseAbs().maxCoeff();
    if (first_norm < 0.0) first_norm = projected;
    if (projected <= options.cg_tolerance * first_norm || projected == 0.0) break;
    ++summary->inner_iterations;
    Eigen::MatrixX3d step;
    *cg_total += system.SolveMasked(-q_gradient, mask, options.max_cg_iterations, options.cg_tolerance, &step);
    if (!step.allFinite() || step.cwiseAbs().maxCoeff() == 0.0) break;
    // Exact minimiser along the step, then projection; halve until q decreases enough.
    const Eigen::MatrixX3d h_step = system.Product(step);
    const double curvature = Dot(step, h_step);
    const double slope = Dot(q_gradient, step);
    double alpha = curvature > 0.0 ? std::max(-slope / curvature, 0.0) : 1.0;
    bool accepted = false;
    for (int halving = 0; halving < 30 && alpha > 0.0; ++halving, alpha *= 0.5) {
      const Eigen::MatrixX3d trial = (d + alpha * step).cwiseMax(lo).cwiseMin(hi);
      const Eigen::MatrixX3d delta = trial - d;
      const Eigen::MatrixX3d h_delta = system.Product(delta);
      const double change = Dot(q_gradient, delta) + 0.5 * Dot(delta, h_delta);
      if (change <= 1e-4 * Dot(q_gradient, delta) && change < 0.0) {
        d = trial;
        hd += h_delta;
        q += change;
        accepted = true;
        break;
      }
    }
    if (!accepted) break;
  }
  return d;
}

}  // namespace

const char* MethodName(CompensationMethod method) {
  switch (method) {
    case CompensationMethod::kNaive: return "naive";
    case CompensationMethod::kReverse: return "reverse";
    case CompensationMethod::kLinear: return "linear";
    case CompensationMethod::kPerceptual: return "perceptual";
  }
  return "?";
}

bool ParseMethod(const std::string& name, CompensationMethod* method) {
  for (CompensationMethod m : {CompensationMethod::kNaive, CompensationMethod::kReverse,
                               CompensationMethod::kLinear, CompensationMethod::kPerceptual}) {
    if (name == MethodName(m)) {
      *method = m;
      return true;
    }
  }
  return false;
}

const char* TerminationName(TerminationType type) {
  switch (type) {
    case TerminationType::kGradientTolerance: return "gradient_tolerance";
    case TerminationType::kFunctionTolerance: return "function_tolerance";
    case TerminationType::kClosedForm: return "closed_form";
    case TerminationType::kMaxIterations: return "max_iterations";
    case TerminationType::kLineSearchFailure: return "line_search_failure";
    case TerminationType::kNumericalFailure: return "numerical_failure";
  }
  return "?";
}

bool SolverOptions::Check(std::string* why) const {
  if (max_iterations < 1 || max_inner_iterations < 1 || max_cg_iterations < 1) {
    *why = "iteration limits must be >= 1";
    return false;
  }
  if (!(cg_tolerance > 0.0 && cg_tolerance < 1.0)) {
    *why = "cg_tolerance must be in (0, 1)";
    return false;
  }
  if (!(gradient_tolerance >= 0.0) || !(function_tolerance >= 0.0)) {
    *why = "tolerances must be >= 0";
    return false;
  }
  if (!(armijo > 0.0 && armijo < 0.5)) {
    *why = "armijo must be in (0, 0.5)";
    return false;
  }
  return true;
}

std::string SolverSummary::BriefReport() const {
  std::ostringstream out;
  out << MethodName(method) << ": " << TerminationName(termination) << ", cost " << initial_cost << " -> "
      << final_cost << ", " << iterations << " iterations (" << inner_iterations << " inner, " << cg_iterations
      << " CG), setup " << setup_seconds << " s, solve " << solve_seconds << " s";
  if (!message.empty()) out << " (" << message << ")";
  return out.str();
}

double ProjectedGradientNorm(const Eigen::MatrixX3d& emittance, const Eigen::MatrixX3d& gradient,
                             const Eigen::MatrixX3d& lower, const Eigen::MatrixX3d& upper) {
  if (emittance.size() == 0) return 0.0;
  return (Clamp(emittance - gradient, lower, upper) - emittance).cwiseAbs().maxCoeff();
}

Eigen::MatrixX3d MinimiseBounded(const SolverOptions& options, const CompensationObjective& objective,
                                 const Eigen::MatrixX3d& initial, SolverSummary* summary) {
  const auto start = Clock::now();
  const Eigen::MatrixX3d& lower = objective.problem().lower;
  const Eigen::MatrixX3d& upper = objective.problem().upper;
  const int n = objective.patches();
  Eigen::MatrixX3d x = Clamp(initial, lower, upper);
  ObjectivePoint point;
  double cost = objective.Evaluate(x, &point);
  summary->initial_cost = cost;
  summary->trace.push_back({0, cost, SecondsSince(start), 0.0, 3 * n, 0, 0.0});
  summary->termination = TerminationType::kMaxIterations;
  if (!std::isfinite(cost)) {
    summary->termination = TerminationType::kNumericalFailure;
    summary->message = "objective is not finite at the start";
    summary->final_cost = cost;
    return x;
  }
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> colour_hessian;
  for (int iteration = 1; iteration <= options.max_iterations; ++iteration) {
    const Eigen::MatrixX3d gradient = objective.Gradient(point);
    const double projected = ProjectedGradientNorm(x, gradient, lower, upper);
    summary->trace.back().projected_gradient = projected;
    if (projected <= options.gradient_tolerance * (1.0 + cost)) {
      summary->termination = TerminationType::kGradientTolerance;
      break;
    }
    // Eq. 12: variables on a bound whose gradient points out of the box stay there.
    Eigen::MatrixX3d fixed = Eigen::MatrixX3d::Zero(n, 3);
    int free_variables = 0;
    for (int i = 0; i < n; ++i) {
      for (int c = 0; c < 3; ++c) {
        const bool at_lower = x(i, c) <= lower(i, c) && gradient(i, c) > 0.0;
        const bool at_upper = x(i, c) >= upper(i, c) && gradient(i, c) < 0.0;
        fixed(i, c) = (at_lower || at_upper) ? 1.0 : 0.0;
        free_variables += (at_lower || at_upper) ? 0 : 1;
      }
    }
    if (options.second_order) objective.AddSecondOrder(&point);
    const NewtonSystem system(objective, point, &colour_hessian, iteration > 1);
    int cg = 0;
    Eigen::MatrixX3d direction =
        SolveInnerQp(options, system, gradient, lower - x, upper - x, fixed, summary, &cg);
    summary->cg_iterations += cg;
    double slope = Dot(gradient, direction);
    if (!direction.allFinite() || !(slope < 0.0)) {
      // Fall back to the projected steepest-descent step.
      direction = Clamp(x - gradient, lower, upper) - x;
      slope = Dot(gradient, direction);
    }
    // Armijo along the (feasible) segment x + a·d, a ∈ (0, 1].
    double step = 1.0;
    ObjectivePoint trial;
    bool accepted = false;
    for (int halving = 0; halving < 40; ++halving, step *= 0.5) {
      const double trial_cost = objective.Evaluate(Clamp(x + step * direction, lower, upper), &trial);
      if (std::isfinite(trial_cost) && trial_cost <= cost + options.armijo * step * slope) {
        accepted = true;
        break;
      }
    }
    summary->iterations = iteration;
    if (!accepted) {
      summary->termination = TerminationType::kLineSearchFailure;
      summary->message = "no Armijo step along the Gauss-Newton direction";
      break;
    }
    const double previous = cost;
    point = std::move(trial);
    x = point.emittance;
    cost = point.value;
    summary->trace.push_back({iteration, cost, SecondsSince(start), step, free_variables, cg, 0.0});
    if (options.progress) options.progress(iteration, cost, SecondsSince(start));
    if (previous - cost <= options.function_tolerance * previous) {
      summary->termination = TerminationType::kFunctionTolerance;
      summary->trace.back().projected_gradient =
          ProjectedGradientNorm(x, objective.Gradient(point), lower, upper);
      break;
    }
  }
  summary->final_cost = cost;
  return x;
}

CompensationSolution Solve(const SolverOptions& options, const CompensationProblem& problem,
                           SolverSummary* summary, const CoarseLevel& coarse) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("solver options: " + why);
  why = problem.Validate();
  if (!why.empty()) throw std::invalid_argument("compensation problem: " + why);
  if (options.multires && (coarse.problem == nullptr || coarse.coarse_of_fine == nullptr)) {
    throw std::invalid_argument("multires needs a coarse level");
  }
  *summary = SolverSummary();
  summary->method = options.method;
  auto setup_start = Clock::now();
  auto radiosity_system =
      std::make_shared<const RadiositySystem>(problem.form_factors, problem.area, problem.reflectance);
  const RadiositySystem& radiosity = *radiosity_system;
  summary->setup_seconds = SecondsSince(setup_start);
  const auto solve_start = Clock::now();
  CompensationSolution solution;
  double coarse_setup_seconds = 0.0;
  const Eigen::MatrixX3d reverse = Clamp(radiosity.Multiply(problem.desired), problem.lower, problem.upper);
  switch (options.method) {
    case CompensationMethod::kNaive:
    case CompensationMethod::kReverse: {
      solution.emittance = options.method == CompensationMethod::kNaive
                               ? Clamp(problem.desired, problem.lower, problem.upper)
                               : reverse;
      const CompensationObjective objective(problem, radiosity, ColourModel::kLab);
      summary->initial_cost = summary->final_cost = objective.Value(solution.emittance);
      summary->termination = TerminationType::kClosedForm;
      break;
    }
    case CompensationMethod::kLinear:
    case CompensationMethod::kPerceptual: {
      const ColourModel model =
          options.method == CompensationMethod::kLinear ? ColourModel::kLinear : ColourModel::kLab;
      Eigen::MatrixX3d initial = reverse;
      if (options.multires) {
        const auto coarse_start = Clock::now();
        const auto setup_coarse = Clock::now();
        const RadiositySystem coarse_radiosity(coarse.problem->form_factors, coarse.problem->area,
                                               coarse.problem->reflectance);
        coarse_setup_seconds = SecondsSince(setup_coarse);
        summary->setup_seconds += coarse_setup_seconds;
        const CompensationObjective coarse_objective(*coarse.problem, coarse_radiosity, model);
        SolverSummary coarse_summary;
        SolverOptions coarse_options = options;
        coarse_options.progress = nullptr;
        const Eigen::MatrixX3d coarse_reverse =
            Clamp(coarse_radiosity.Multiply(coarse.problem->desired), coarse.problem->lower, coarse.problem->upper);
        const Eigen::MatrixX3d coarse_emittance =
            MinimiseBounded(coarse_options, coarse_objective, coarse_reverse, &coarse_summary);
        for (int i = 0; i < problem.size(); ++i) initial.row(i) = coarse_emittance.row((*coarse.coarse_of_fine)[i]);
        initial = Clamp(initial, problem.lower, problem.upper);
        summary->coarse_iterations = coarse_summary.iterations;
        summary->coarse_seconds = SecondsSince(coarse_start) - coarse_setup_seconds;
      }
      const CompensationObjective objective(problem, radiosity, model);
      solution.emittance = MinimiseBounded(options, objective, initial, summary);
      break;
    }
  }
  solution.radiosity = radiosity.Solve(solution.emittance);
  solution.radiosity_system = std::move(radiosity_system);
  summary->solve_seconds = SecondsSince(solve_start) - coarse_setup_seconds;
  return solution;
}

}  // namespace procam
