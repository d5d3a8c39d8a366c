#include "compensation/peers.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <limits>
#include <stdexcept>

#include <LBFGSB.h>
#include <ceres/ceres.h>
#include <ceres/manifold.h>

#include "base/timing.h"

namespace procam {
namespace {

using RowMatrixXd = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

Eigen::MatrixX3d Project(const Eigen::MatrixX3d& emittance, const CompensationProblem& problem) {
  return emittance.cwiseMax(problem.lower).cwiseMin(problem.upper);
}

// ‖E − P(E − g)‖∞.
double ProjectedGradientInfNorm(const Eigen::MatrixX3d& emittance, const Eigen::MatrixX3d& gradient,
                                const CompensationProblem& problem) {
  return (emittance - Project(emittance - gradient, problem)).cwiseAbs().maxCoeff();
}

// What every solver does first: checks the options and the input, projects `initial`, evaluates
// f there and records the start of the trace. Returns false (with `result` complete) if the
// solve cannot go on.
bool Start(const CompensationObjective& objective, const Eigen::MatrixX3d& initial,
           const PeerOptions& options, Clock::time_point start, PeerResult* result) {
  const CompensationProblem& problem = objective.problem();
  const int n = objective.patches();
  result->emittance = initial;
  std::string why;
  if (!options.Check(&why)) {
    result->termination = "invalid options: " + why;
  } else if (initial.rows() != n || problem.lower.rows() != n || problem.upper.rows() != n) {
    result->termination =
        "invalid input: initial emittance and bounds must have " + std::to_string(n) + " rows";
  } else if (!initial.allFinite() || !problem.lower.allFinite() || !problem.upper.allFinite()) {
    result->termination = "invalid input: non-finite initial emittance or bounds";
  } else if ((problem.lower.array() > problem.upper.array()).any()) {
    result->termination = "invalid input: lower > upper for some patch";
  }
  if (!result->termination.empty()) {
    result->cost = std::numeric_limits<double>::quiet_NaN();
    result->seconds = SecondsSince(start);
    return false;
  }
  result->emittance = Project(initial, problem);
  result->cost = objective.Value(result->emittance);
  result->trace.emplace_back(SecondsSince(start), result->cost);
  if (!std::isfinite(result->cost)) {
    result->termination = "numerical failure: f is not finite at the initial point";
    result->seconds = SecondsSince(start);
    return false;
  }
  return true;
}

// Re-evaluates f at the final point (projected against rounding) and stamps the time.
void Finish(const CompensationObjective& objective, const Eigen::MatrixX3d& emittance,
            Clock::time_point start, PeerResult* result) {
  result->emittance = Project(emittance, objective.problem());
  result->cost = objective.Value(result->emittance);
  result->seconds = SecondsSince(start);
}

// Relative-decrease and step-length tests shared by L-BFGS-B and projected gradient; returns
// the termination or "" to go on.
std::string AcceptedStepTermination(const PeerOptions& options, double previous_cost, double cost,
                                    const Eigen::MatrixX3d& step,
                                    const Eigen::MatrixX3d& emittance) {
  if (previous_cost - cost <= options.function_tolerance * previous_cost) {
    return "function tolerance";
  }
  if (step.norm() <=
      options.parameter_tolerance * (emittance.norm() + options.parameter_tolerance)) {
    return "parameter tolerance";
  }
  return "";
}

// ---------------------------------------------------------------------------------------------
// Ceres

class LeastSquaresCost : public ceres::CostFunction {
 public:
  explicit LeastSquaresCost(const CompensationLeastSquares& least_squares)
      : least_squares_(least_squares) {
    set_num_residuals(least_squares.residuals());
    mutable_parameter_block_sizes()->push_back(least_squares.variables());
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const Eigen::Map<const Eigen::VectorXd> x(parameters[0], least_squares_.variables());
    return least_squares_.Evaluate(Unflatten(x), residuals,
                                   jacobians != nullptr ? jacobians[0] : nullptr);
  }

 private:
  const CompensationLeastSquares& least_squares_;
};

class TraceCallback : public ceres::IterationCallback {
 public:
  TraceCallback(Clock::time_point start, PeerResult* result) : start_(start), result_(result) {}

  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    // Iteration 0 is the initial point, already in the trace.
    if (summary.iteration > 0)
      result_->trace.emplace_back(SecondsSince(start_), 2.0 * summary.cost);
    return ceres::SOLVER_CONTINUE;
  }

 private:
  Clock::time_point start_;
  PeerResult* result_;
};

std::string CeresTermination(const ceres::Solver::Summary& summary) {
  const std::string& message = summary.message;
  auto starts_with = [&](const char* prefix) { return message.rfind(prefix, 0) == 0; };
  switch (summary.termination_type) {
    case ceres::CONVERGENCE:
      if (starts_with("Gradient tolerance")) return "gradient tolerance: " + message;
      if (starts_with("Function tolerance")) return "function tolerance: " + message;
      if (starts_with("Parameter tolerance")) return "parameter tolerance: " + message;
      return "function tolerance: " + message;
    case ceres::NO_CONVERGENCE:
      return "max iterations: " + message;
    default:
      if (message.find("evaluation failed") != std::string::npos) {
        return "numerical failure: " + message;
      }
      return "solver failure: " + message;
  }
}

// ---------------------------------------------------------------------------------------------
// L-BFGS-B

// Why an L-BFGS-B solve stops from inside LBFGSpp, which offers no callback: thrown by
// LbfgsbFunction and caught by SolveWithLbfgsb.
struct LbfgsbStop {
  std::string termination;
};

// f and ∇f for LBFGSpp, plus the per-iteration hook that TracingLineSearch calls: it records
// the trace and applies PeerOptions' tests, so that they mean the same as for projected
// gradient. Keeps the best point it has evaluated.
class LbfgsbFunction {
 public:
  LbfgsbFunction(const CompensationObjective& objective, const PeerOptions& options,
                 Clock::time_point start, PeerResult* result, double initial_cost)
      : objective_(objective),
        options_(options),
        start_(start),
        result_(result),
        accepted_cost_(initial_cost),
        best_cost_(initial_cost),
        best_(Flatten(result->emittance)) {}

  double operator()(const Eigen::VectorXd& x, Eigen::VectorXd& gradient) {
    ObjectivePoint point;
    const double cost = objective_.Evaluate(Unflatten(x), &point);
    if (!std::isfinite(cost)) throw LbfgsbStop{"numerical failure: f is not finite"};
    gradient = Flatten(objective_.Gradient(point));
    if (!gradient.allFinite()) throw LbfgsbStop{"numerical failure: gradient is not finite"};
    if (cost < best_cost_) {
      best_cost_ = cost;
      best_ = x;
    }
    return cost;
  }

  // After the line search of each iteration: `x` is the accepted point, `previous` the last.
  void AfterIteration(const Eigen::VectorXd& x, double cost, const Eigen::VectorXd& gradient,
                      const Eigen::VectorXd& previous) {
    ++result_->iterations;
    result_->trace.emplace_back(SecondsSince(start_), cost);
    const Eigen::MatrixX3d emittance = Project(Unflatten(x), objective_.problem());
    const double projected_gradient =
        ProjectedGradientInfNorm(emittance, Unflatten(gradient), objective_.problem());
    if (projected_gradient <= options_.gradient_tolerance * (1.0 + cost)) {
      throw LbfgsbStop{"gradient tolerance"};
    }
    const std::string termination =
        AcceptedStepTermination(options_, accepted_cost_, cost, Unflatten(x - previous), emittance);
    if (!termination.empty()) throw LbfgsbStop{termination};
    if (result_->iterations >= options_.max_iterations) throw LbfgsbStop{"max iterations"};
    accepted_cost_ = cost;
  }

  const Eigen::VectorXd& best() const { return best_; }

 private:
  const CompensationObjective& objective_;
  const PeerOptions& options_;
  Clock::time_point start_;
  PeerResult* result_;
  double accepted_cost_;
  double best_cost_;
  Eigen::VectorXd best_;
};

// LBFGSpp's Moré–Thuente line search, followed by LbfgsbFunction::AfterIteration: the only
// place where LBFGSpp hands control back once per iteration.
template <typename Scalar>
class TracingLineSearch {
 public:
  using Vector = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;

  template <typename Function>
  static void LineSearch(Function& f, Scalar& fx, Vector& x, Vector& grad, Scalar& step,
                         const Scalar& step_max, const Vector& drt, const Vector& xp,
                         const LBFGSpp::LBFGSBParam<Scalar>& param) {
    LBFGSpp::LineSearchMoreThuente<Scalar>::LineSearch(f, fx, x, grad, step, step_max, drt, xp,
                                                       param);
    f.AfterIteration(x, fx, grad, xp);
  }
};

}  // namespace

bool PeerOptions::Check(std::string* why) const {
  auto fail = [why](const char* message) {
    if (why != nullptr) *why = message;
    return false;
  };
  if (max_iterations < 0) return fail("max_iterations must be >= 0");
  if (!(function_tolerance >= 0.0) || !std::isfinite(function_tolerance)) {
    return fail("function_tolerance must be finite and >= 0");
  }
  if (!(gradient_tolerance >= 0.0) || !std::isfinite(gradient_tolerance)) {
    return fail("gradient_tolerance must be finite and >= 0");
  }
  if (!(parameter_tolerance >= 0.0) || !std::isfinite(parameter_tolerance)) {
    return fail("parameter_tolerance must be finite and >= 0");
  }
  return true;
}

// ---------------------------------------------------------------------------------------------
// CompensationLeastSquares

CompensationLeastSquares::CompensationLeastSquares(const CompensationObjective& objective)
    : objective_(objective) {
  const CompensationProblem& problem = objective.problem();
  const double alpha = problem.alpha;
  patch_scale_ = (alpha * problem.area / problem.area.mean()).cwiseSqrt();
  pair_scale_ = std::sqrt(std::max(0.0, 1.0 - alpha));
  // With grey reflectance every channel has the same K, so one inverse serves all three.
  const RadiositySystem& radiosity = objective.radiosity();
  const bool grey = radiosity.factorisations() == 1;
  for (int c = 0; c < (grey ? 1 : 3); ++c) inverse_.push_back(radiosity.InverseMatrix(c));
}

bool CompensationLeastSquares::Evaluate(const Eigen::MatrixX3d& emittance, double* residual,
                                        double* jacobian) const {
  const int n = objective_.patches();
  const int m = pairs();
  const int rows = residuals();
  const int columns = variables();
  ObjectivePoint point;
  if (!std::isfinite(objective_.Evaluate(emittance, &point))) return false;
  const auto& adjacency = objective_.problem().adjacency;

  Eigen::Map<Eigen::VectorXd> rho(residual, rows);
  for (int i = 0; i < n; ++i) {
    rho.segment<3>(3 * i) = patch_scale_[i] * point.residual.row(i).transpose();
  }
  for (int p = 0; p < m; ++p) {
    const auto [i, j] = adjacency[p];
    rho.segment<3>(3 * n + 3 * p) =
        pair_scale_ * (point.residual.row(i) - point.residual.row(j)).transpose();
  }
  if (!rho.allFinite()) return false;
  if (jacobian == nullptr) return true;

  // First ∂r_i/∂E (unscaled) into the patch rows, then the pair rows from them, then the scale.
  Eigen::Map<RowMatrixXd> d(jacobian, rows, columns);
  for (int i = 0; i < n; ++i) {
    const Eigen::Matrix3d& colour_jacobian = point.colour_jacobian[i];
    for (int j = 0; j < n; ++j) {
      for (int c = 0; c < 3; ++c) {
        const double k_inverse = inverse_[inverse_.size() == 1 ? 0 : c](i, j);
        d.block<3, 1>(3 * i, 3 * j + c) = colour_jacobian.col(c) * k_inverse;
      }
    }
  }
  for (int p = 0; p < m; ++p) {
    const auto [i, j] = adjacency[p];
    d.middleRows<3>(3 * n + 3 * p) =
        pair_scale_ * (d.middleRows<3>(3 * i) - d.middleRows<3>(3 * j));
  }
  for (int i = 0; i < n; ++i) d.middleRows<3>(3 * i) *= patch_scale_[i];
  return d.allFinite();
}

bool CompensationLeastSquares::Evaluate(const Eigen::MatrixX3d& emittance,
                                        Eigen::VectorXd* residual,
                                        Eigen::MatrixXd* jacobian) const {
  residual->resize(residuals());
  if (jacobian == nullptr) return Evaluate(emittance, residual->data(), nullptr);
  RowMatrixXd row_major(residuals(), variables());
  const bool ok = Evaluate(emittance, residual->data(), row_major.data());
  *jacobian = row_major;
  return ok;
}

// ---------------------------------------------------------------------------------------------
// Solvers

PeerResult SolveWithCeres(const CompensationObjective& objective, const Eigen::MatrixX3d& initial,
                          const PeerOptions& options) {
  const Clock::time_point start = Clock::now();
  PeerResult result;
  if (!Start(objective, initial, options, start, &result)) return result;
  if (options.max_iterations == 0) {
    result.termination = "max iterations";
    Finish(objective, result.emittance, start, &result);
    return result;
  }

  // Ceres keeps the bounds by clipping each Levenberg–Marquardt step (plus a line search along
  // the clipped step). The step itself ignores the bounds, so once variables press against
  // them the clipped steps stop decreasing f and Ceres ends on its function tolerance well
  // short of a critical point. Hence an outer active-set loop: hold the variables whose bound
  // binds (at the bound, gradient pointing out) constant through a SubsetManifold, solve
  // again on the rest, and repeat until the binding set no longer changes.
  const CompensationLeastSquares least_squares(objective);
  LeastSquaresCost cost(least_squares);
  Eigen::VectorXd x = Flatten(result.emittance);
  const Eigen::VectorXd lower = Flatten(objective.problem().lower);
  const Eigen::VectorXd upper = Flatten(objective.problem().upper);
  ceres::Solver::Options solver_options;
  solver_options.minimizer_type = ceres::TRUST_REGION;
  solver_options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solver_options.function_tolerance = options.function_tolerance;
  solver_options.gradient_tolerance = options.gradient_tolerance;
  solver_options.parameter_tolerance = options.parameter_tolerance;
  solver_options.logging_type = ceres::SILENT;
  solver_options.minimizer_progress_to_stdout = false;
  TraceCallback callback(start, &result);
  solver_options.callbacks.push_back(&callback);

  constexpr int kMaxRounds = 100;
  std::vector<int> held;
  int rounds = 0;
  bool settled = false;
  while (!settled && rounds < kMaxRounds) {
    ++rounds;
    settled = true;
    ceres::Problem::Options problem_options;
    problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(problem_options);
    problem.AddResidualBlock(&cost, nullptr, x.data());
    for (int k = 0; k < x.size(); ++k) {
      problem.SetParameterLowerBound(x.data(), k, lower[k]);
      problem.SetParameterUpperBound(x.data(), k, upper[k]);
    }
    if (!held.empty()) {
      problem.SetManifold(x.data(), new ceres::SubsetManifold(static_cast<int>(x.size()), held));
    }
    solver_options.max_num_iterations = options.max_iterations - result.iterations;
    ceres::Solver::Summary summary;
    ceres::Solve(solver_options, &problem, &summary);
    // summary.iterations holds iteration 0 and each iteration the callback saw.
    if (!summary.iterations.empty()) {
      result.iterations += static_cast<int>(summary.iterations.size()) - 1;
    }
    result.termination = CeresTermination(summary);
    if (summary.termination_type != ceres::CONVERGENCE) break;
    if (result.iterations >= options.max_iterations) break;

    ObjectivePoint point;
    objective.Evaluate(Unflatten(x), &point);
    const Eigen::VectorXd gradient = Flatten(objective.Gradient(point));
    std::vector<int> binding;
    for (int k = 0; k < x.size(); ++k) {
      if ((x[k] <= lower[k] && gradient[k] > 0.0) || (x[k] >= upper[k] && gradient[k] < 0.0)) {
        binding.push_back(k);
      }
    }
    // Done when the face is unchanged, or when every variable binds (E is then a vertex of the
    // box that f pushes outwards on every side: a critical point).
    if (binding != held && binding.size() < static_cast<size_t>(x.size())) {
      held = std::move(binding);
      settled = false;
    }
  }
  if (!settled && rounds == kMaxRounds) {
    result.termination = "max iterations: the binding set still changed after " +
                         std::to_string(kMaxRounds) + " active-set rounds";
  } else {
    result.termination += " (" + std::to_string(rounds) + " active-set rounds)";
  }
  // Ceres leaves x at the best point it accepted (the start if it failed).
  Finish(objective, Unflatten(x), start, &result);
  return result;
}

PeerResult SolveWithLbfgsb(const CompensationObjective& objective, const Eigen::MatrixX3d& initial,
                           const PeerOptions& options) {
  const Clock::time_point start = Clock::now();
  PeerResult result;
  if (!Start(objective, initial, options, start, &result)) return result;
  {
    ObjectivePoint point;
    objective.Evaluate(result.emittance, &point);
    const double projected_gradient =
        ProjectedGradientInfNorm(result.emittance, objective.Gradient(point), objective.problem());
    if (!std::isfinite(projected_gradient)) {
      result.termination = "numerical failure: gradient is not finite at the initial point";
    } else if (projected_gradient <= options.gradient_tolerance * (1.0 + result.cost)) {
      result.termination = "gradient tolerance";
    } else if (options.max_iterations == 0) {
      result.termination = "max iterations";
    }
    if (!result.termination.empty()) {
      Finish(objective, result.emittance, start, &result);
      return result;
    }
  }

  // LBFGSpp's own stopping tests are switched off (tolerances 0, no iteration limit):
  // LbfgsbFunction::AfterIteration applies PeerOptions' instead.
  LBFGSpp::LBFGSBParam<double> param;
  param.m = 10;
  param.epsilon = 0.0;
  param.epsilon_rel = 0.0;
  param.past = 0;
  param.delta = 0.0;
  param.max_iterations = 0;
  param.max_linesearch = 40;
  LBFGSpp::LBFGSBSolver<double, TracingLineSearch> solver(param);
  LbfgsbFunction function(objective, options, start, &result, result.cost);
  Eigen::VectorXd x = Flatten(result.emittance);
  const Eigen::VectorXd lower = Flatten(objective.problem().lower);
  const Eigen::VectorXd upper = Flatten(objective.problem().upper);
  double cost = result.cost;
  try {
    solver.minimize(function, x, cost, lower, upper);
    // With the tests above switched off LBFGSpp returns only when ‖P(x − g) − x‖∞ = 0.
    result.termination = "gradient tolerance";
  } catch (const LbfgsbStop& stop) {
    result.termination = stop.termination;
  } catch (const std::exception& error) {
    const std::string what = error.what();
    const bool line_search = what.find("line search") != std::string::npos ||
                             what.find("moving direction") != std::string::npos ||
                             what.find("step") != std::string::npos;
    result.termination = (line_search ? "line search failure: " : "solver failure: ") + what;
  }
  Finish(objective, Unflatten(function.best()), start, &result);
  return result;
}

PeerResult SolveWithProjectedGradient(const CompensationObjective& objective,
                                      const Eigen::MatrixX3d& initial, const PeerOptions& options) {
  const Clock::time_point start = Clock::now();
  PeerResult result;
  if (!Start(objective, initial, options, start, &result)) return result;
  const CompensationProblem& problem = objective.problem();
  constexpr double kArmijo = 1e-4;
  constexpr int kMaxBacktracks = 60;
  constexpr double kMinStep = 1e-30, kMaxStep = 1e30;

  Eigen::MatrixX3d emittance = result.emittance;
  double cost = 0.0;
  Eigen::MatrixX3d gradient;
  {
    ObjectivePoint point;
    cost = objective.Evaluate(emittance, &point);
    gradient = objective.Gradient(point);
  }
  // Before any Barzilai–Borwein step exists, move the steepest coordinate by one unit.
  double step = 1.0 / std::max(gradient.cwiseAbs().maxCoeff(), 1e-300);
  while (result.termination.empty()) {
    const double projected_gradient = ProjectedGradientInfNorm(emittance, gradient, problem);
    if (!std::isfinite(projected_gradient)) {
      result.termination = "numerical failure: gradient is not finite";
      break;
    }
    if (projected_gradient <= options.gradient_tolerance * (1.0 + cost)) {
      result.termination = "gradient tolerance";
      break;
    }
    if (result.iterations >= options.max_iterations) {
      result.termination = "max iterations";
      break;
    }

    // Armijo backtracking along the projection arc E(a) = P[E − a g] (Bertsekas 1976):
    // accept f(E(a)) ≤ f(E) + σ gᵀ(E(a) − E).
    double trial_step = std::clamp(step, kMinStep, kMaxStep);
    Eigen::MatrixX3d trial, move;
    ObjectivePoint trial_point;
    double trial_cost = 0.0;
    bool accepted = false;
    for (int backtrack = 0; backtrack < kMaxBacktracks; ++backtrack, trial_step *= 0.5) {
      trial = Project(emittance - trial_step * gradient, problem);
      move = trial - emittance;
      if (move.cwiseAbs().maxCoeff() == 0.0) break;  // the arc has collapsed onto E
      trial_cost = objective.Evaluate(trial, &trial_point);
      if (!std::isfinite(trial_cost)) break;
      if (trial_cost <= cost + kArmijo * gradient.cwiseProduct(move).sum()) {
        accepted = true;
        break;
      }
    }
    if (!accepted) {
      result.termination =
          std::isfinite(trial_cost) ? "line search failure" : "numerical failure: f is not finite";
      break;
    }

    const Eigen::MatrixX3d trial_gradient = objective.Gradient(trial_point);
    if (!trial_gradient.allFinite()) {
      result.termination = "numerical failure: gradient is not finite";
      break;
    }
    // Barzilai–Borwein step sᵀs / sᵀy for the next iteration; without positive curvature
    // along s, try a longer step than the one just accepted.
    const double s_y = move.cwiseProduct(trial_gradient - gradient).sum();
    step = s_y > 0.0 ? move.squaredNorm() / s_y : 2.0 * trial_step;

    ++result.iterations;
    const double previous_cost = cost;
    emittance = trial;
    cost = trial_cost;
    gradient = trial_gradient;
    result.trace.emplace_back(SecondsSince(start), cost);
    // max_iterations is tested at the top of the loop, after the optimality test.
    result.termination = AcceptedStepTermination(options, previous_cost, cost, move, emittance);
  }
  Finish(objective, emittance, start, &result);
  return result;
}

}  // namespace procam
