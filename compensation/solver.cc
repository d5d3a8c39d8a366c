#include "compensation/solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>

#include <Eigen/Cholesky>
#include <Eigen/SparseCholesky>

#include "base/timing.h"
#include "compensation/colour.h"
#include "procam/config.h"
#if PROCAM_WITH_CUDA
#include "compensation/cuda_compressed.h"
#include "compensation/cuda_radiosity.h"
#include "compensation/cuda_solver.h"
#endif

namespace procam {
namespace {


Eigen::MatrixX3d Clamp(const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& lower, const Eigen::MatrixX3d& upper) {
  return x.cwiseMax(lower).cwiseMin(upper);
}

double Dot(const Eigen::MatrixX3d& a, const Eigen::MatrixX3d& b) { return a.cwiseProduct(b).sum(); }

// K factorised on the CPU, or inverted on the device that options.device names.
std::shared_ptr<const RadiositySystem> MakeRadiositySystem(const SolverOptions& options,
                                                           const CompensationProblem& problem) {
  if (problem.compressed()) {
    if (options.device == Device::kCpu) {
      return std::make_shared<const RadiositySystem>(problem.compressed_form_factors, problem.reflectance);
    }
#if PROCAM_WITH_CUDA
    return std::make_shared<const RadiositySystem>(
        problem.compressed_form_factors, problem.reflectance, IterativeRadiosityOptions(),
        MakeCudaCompressedRadiosityBackend(*problem.compressed_form_factors, problem.reflectance,
                                           IterativeRadiosityOptions()));
#else
    throw std::runtime_error("--device cuda: this build of procam has no CUDA backend (PROCAM_WITH_CUDA is OFF: "
                             "no nvcc was found when it was configured)");
#endif
  }
  if (options.device == Device::kCpu) {
    return std::make_shared<const RadiositySystem>(problem.form_factors, problem.area, problem.reflectance);
  }
#if PROCAM_WITH_CUDA
  return std::make_shared<const RadiositySystem>(
      problem.form_factors, problem.area, problem.reflectance,
      MakeCudaRadiosityBackend(problem.form_factors, problem.area, problem.reflectance, options.device_float32,
                               {options.device_product_rows,
                                options.device_cg_matrix == SolverOptions::DeviceCgMatrix::kFloat16}));
#else
  throw std::runtime_error("--device cuda: this build of procam has no CUDA backend (PROCAM_WITH_CUDA is OFF: "
                           "no nvcc was found when it was configured)");
#endif
}

// Alg. 1 where options say: on the device (cuda_solver.h) for kCuda unless device_host_loop, else
// MinimiseBounded (whose K⁻¹ applications run on the objective's RadiositySystem backend).
// `radiosity` (if not null) gets the result's K⁻¹E where the device formed it, else stays empty.
struct FreeColourHessian;
Eigen::MatrixX3d MinimiseOnCpu(const SolverOptions& options, const CompensationObjective& objective,
                               const Eigen::MatrixX3d& initial, SolverSummary* summary,
                               Eigen::MatrixX3d* radiosity, const Eigen::MatrixX3d* start_radiosity,
                               FreeColourHessian* free_colour_hessian);

// `free_colour_hessian` (CPU only, optional): the preconditioner's factorisation carried over
// from an earlier call on the same problem (its ordering reused while the free set repeats).
Eigen::MatrixX3d Minimise(const SolverOptions& options, const CompensationObjective& objective,
                          const Eigen::MatrixX3d& initial, SolverSummary* summary,
                          Eigen::MatrixX3d* radiosity = nullptr,
                          const Eigen::MatrixX3d* start_radiosity = nullptr,
                          FreeColourHessian* free_colour_hessian = nullptr) {
#if PROCAM_WITH_CUDA
  if (options.device == Device::kCuda && !options.device_host_loop) {
    return MinimiseBoundedOnGpu(options, objective, initial, summary, radiosity);
  }
#endif
  return MinimiseOnCpu(options, objective, initial, summary, radiosity, start_radiosity,
                       free_colour_hessian);
}

// M_FF's sparse factorisation, kept across outer iterations: once the active set settles the
// free set, and with it the sparsity pattern, repeats, and only the numeric factorisation is
// redone (skipping the fill-reducing ordering saved ~10% of the factorisation time).
struct FreeColourHessian {
  std::vector<int> free_index;  // flattened index 3i + c of each free variable
  bool analysed = false;
  bool ok = false;              // the numeric factorisation succeeded (M_FF is SPD in theory)
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt;
};

// The Newton systems of one outer iteration: H restricted to a set of free variables,
// preconditioned by SolverOptions::preconditioner restricted to the same set.
class NewtonSystem {
 public:
  NewtonSystem(const CompensationObjective& objective, const ObjectivePoint& point,
               SolverOptions::Preconditioner preconditioner, FreeColourHessian* free_colour_hessian)
      : objective_(objective), point_(point), preconditioner_(preconditioner),
        free_(*free_colour_hessian) {
    if (preconditioner_ == SolverOptions::Preconditioner::kInverseHessian) {
      jacobian_inverse_ = objective.InverseColourJacobians(point);
    }
  }

  Eigen::MatrixX3d Product(const Eigen::MatrixX3d& v) const {
    return objective_.GaussNewtonProduct(point_, v, /*fast=*/true);
  }

  // The preconditioner is always built from the Gauss–Newton colour matrix M (positive
  // definite); products may include the second-order term, whose negative curvature CG detects.
  //   kFreeColourHessian: (M_FF)⁻¹ r_F, one sparse solve.
  //   kInverseHessian:    K M⁻¹ Kᵀ r, the exact H⁻¹ when S = 0 and no bound is active.
  Eigen::MatrixX3d Precondition(const Eigen::MatrixX3d& r) const {
    ++preconditioner_applications_;
    if (preconditioner_ == SolverOptions::Preconditioner::kFreeColourHessian) {
      if (!free_.ok) return r;
      const std::vector<int>& free_index = free_.free_index;
      Eigen::VectorXd packed(free_index.size());
      for (size_t k = 0; k < free_index.size(); ++k) packed[k] = r(free_index[k] / 3, free_index[k] % 3);
      packed = free_.ldlt.solve(packed);
      Eigen::MatrixX3d z = Eigen::MatrixX3d::Zero(r.rows(), 3);
      for (size_t k = 0; k < free_index.size(); ++k) z(free_index[k] / 3, free_index[k] % 3) = packed[k];
      return z;
    }
    const Eigen::MatrixX3d kt = objective_.radiosity().MultiplyTransposedFast(r);
    return objective_.radiosity().MultiplyFast(objective_.SolveGaussNewtonColour(jacobian_inverse_, kt));
  }

  // Preconditioned CG on H_FF p = rhs_F (mask: 1 on free variables). Returns iterations used;
  // `curvature` gets pᵀ H p of the returned p (from CG's residual, no extra product).
  int SolveMasked(const Eigen::MatrixX3d& rhs, const Eigen::MatrixX3d& mask, int max_iterations,
                  double tolerance, Eigen::MatrixX3d* solution, double* curvature_of_solution) const {
    if (preconditioner_ == SolverOptions::Preconditioner::kFreeColourHessian) FactoriseFree(mask);
    // The recurrence's decisions are solver_driver.h's (CgState), as on the GPU.
    Eigen::MatrixX3d x = Eigen::MatrixX3d::Zero(rhs.rows(), 3);
    Eigen::MatrixX3d r = rhs.cwiseProduct(mask);
    const Eigen::MatrixX3d b = r;
    CgState cg;
    const double r0 = r.norm();
    Eigen::MatrixX3d z, p;
    if (r0 > 0.0) {
      z = Precondition(r).cwiseProduct(mask);
      p = z;
    }
    CgStart(cg, r0, r0 > 0.0 ? Dot(r, z) : 0.0);
    *curvature_of_solution = 0.0;
    while (!cg.done) {
      const Eigen::MatrixX3d hp = Product(p).cwiseProduct(mask);
      CgCurvature(cg, Dot(p, hp));
      if (cg.negative_first) {
        *solution = p;
        *curvature_of_solution = cg.curvature;
        return cg.iterations;
      }
      if (cg.done) break;
      x += cg.step * p;
      r -= cg.step * hp;
      if (!CgResidual(cg, r.norm(), tolerance)) break;
      z = Precondition(r).cwiseProduct(mask);
      CgDirection(cg, Dot(r, z), max_iterations);
      p = z + cg.beta * p;
    }
    *curvature_of_solution = r0 > 0.0 ? Dot(x, b - r) : 0.0;  // H_FF x = b − r
    *solution = x;
    return cg.iterations;
  }

 private:
  const CompensationObjective& objective_;
  const ObjectivePoint& point_;
  // M_FF = 2 (Jᵀ (W ⊗ I₃) J)_FF, assembled directly for the free variables of `mask` and
  // factorised; the fill-reducing ordering is redone only when the free set changed.
  void FactoriseFree(const Eigen::MatrixX3d& mask) const {
    if (factorised_mask_.rows() == mask.rows() && mask == factorised_mask_) return;
    factorised_mask_ = mask;
    const int n = static_cast<int>(mask.rows());
    std::vector<int> packed_of(3 * n, -1);
    std::vector<int> free_index;
    for (int i = 0; i < n; ++i) {
      for (int c = 0; c < 3; ++c) {
        if (mask(i, c) == 0.0) continue;
        packed_of[3 * i + c] = static_cast<int>(free_index.size());
        free_index.push_back(3 * i + c);
      }
    }
    // Column by column in order, rows ascending within a column (W's are, and packed_of is
    // increasing), lower triangle only (what SimplicialLDLT reads): no triplet sort.
    const Eigen::SparseMatrix<double>& w = objective_.weights();  // symmetric, column-major
    const int size = static_cast<int>(free_index.size());
    Eigen::SparseMatrix<double> m(size, size);
    m.reserve(5 * w.nonZeros());
    for (int j = 0; j < n; ++j) {
      for (int b = 0; b < 3; ++b) {
        const int column = packed_of[3 * j + b];
        if (column < 0) continue;
        m.startVec(column);
        for (Eigen::SparseMatrix<double>::InnerIterator it(w, j); it; ++it) {
          const int i = static_cast<int>(it.row());
          if (i < j) continue;
          // Column b of block (i, j) = 2 W_ij J_iᵀ J_j e_b.
          const Eigen::Vector3d block_column =
              2.0 * it.value() * (point_.colour_jacobian[i].transpose() * point_.colour_jacobian[j].col(b));
          for (int a = 0; a < 3; ++a) {
            const int row = packed_of[3 * i + a];
            if (row >= column) m.insertBack(row, column) = block_column[a];
          }
        }
      }
    }
    m.finalize();
    if (!free_.analysed || free_index != free_.free_index) free_.ldlt.analyzePattern(m);
    free_.analysed = true;
    free_.free_index = std::move(free_index);
    free_.ldlt.factorize(m);
    free_.ok = free_.ldlt.info() == Eigen::Success;
  }

  SolverOptions::Preconditioner preconditioner_;
  std::vector<Eigen::Matrix3d> jacobian_inverse_;  // J_i⁻¹ per patch (kInverseHessian)
  FreeColourHessian& free_;                         // kFreeColourHessian: M_FF ...
  mutable Eigen::MatrixX3d factorised_mask_;        // ... factorised for this mask at this point

 public:
  mutable int preconditioner_applications_ = 0;  // Precondition calls, all systems together
};

// MinimiseBoundedDriver's executor on the CPU: Eigen vectors, the objective's K⁻¹ solves, and CG
// with the sparse preconditioner of NewtonSystem.
class CpuExecutor {
 public:
  // `start_radiosity` (optional): K⁻¹ start, already known; the first evaluation then needs no
  // solve with K.
  CpuExecutor(const SolverOptions& options, const CompensationObjective& objective,
              const Eigen::MatrixX3d& start, SolverSummary* summary,
              const Eigen::MatrixX3d* start_radiosity = nullptr,
              FreeColourHessian* free_colour_hessian = nullptr)
      : options_(options),
        objective_(objective),
        lower_(objective.problem().lower),
        upper_(objective.problem().upper),
        n_(objective.patches()),
        x_(start),
        summary_(summary),
        start_time_(Clock::now()),
        start_radiosity_(start_radiosity),
        free_colour_hessian_(free_colour_hessian != nullptr ? free_colour_hessian
                                                            : &own_free_colour_hessian_) {}

  const Eigen::MatrixX3d& x() const { return x_; }
  // K⁻¹x of the current iterate (after Evaluate).
  const Eigen::MatrixX3d& radiosity() const { return point_.radiosity; }

  int Variables() const { return 3 * n_; }

  double Evaluate() {
    if (start_radiosity_ == nullptr) return objective_.Evaluate(x_, &point_);
    point_.emittance = x_;
    point_.radiosity = *start_radiosity_;
    point_.residual.resize(n_, 3);
    point_.colour_jacobian.resize(n_);
    for (int i = 0; i < n_; ++i) {
      const Eigen::Vector3d rgb = point_.radiosity.row(i).transpose();
      point_.residual.row(i) = objective_.Residual(i, rgb).transpose();
      point_.colour_jacobian[i] = objective_.PatchJacobian(i, rgb);
    }
    point_.value = point_.residual.cwiseProduct(objective_.weights() * point_.residual).sum();
    return point_.value;
  }

  GradientCheck Gradient() {
    gradient_ = objective_.Gradient(point_);
    // Eq. 12: variables on a bound whose gradient points out of the box stay there.
    fixed_ = Eigen::MatrixX3d::Zero(n_, 3);
    int free_variables = 0;
    for (int i = 0; i < n_; ++i) {
      for (int c = 0; c < 3; ++c) {
        const bool at_lower = x_(i, c) <= lower_(i, c) && gradient_(i, c) > 0.0;
        const bool at_upper = x_(i, c) >= upper_(i, c) && gradient_(i, c) < 0.0;
        fixed_(i, c) = (at_lower || at_upper) ? 1.0 : 0.0;
        free_variables += (at_lower || at_upper) ? 0 : 1;
      }
    }
    return {ProjectedGradientNorm(x_, gradient_, lower_, upper_), free_variables};
  }

  // Alg. 2 on q(d) = gᵀd + ½ dᵀHd, lo = l − x ≤ d ≤ hi = u − x, d fixed at 0 where `fixed_` is 1.
  // Rows and columns of bound variables are dropped from H (not diagonalised), as in the paper.
  double InnerStart(bool first) {
    if (first) {
      if (options_.second_order) objective_.AddSecondOrder(&point_);
      system_.emplace(objective_, point_, options_.preconditioner, free_colour_hessian_);
      lo_ = lower_ - x_;
      hi_ = upper_ - x_;
      d_ = Eigen::MatrixX3d::Zero(n_, 3);
      hd_ = Eigen::MatrixX3d::Zero(n_, 3);
    }
    q_gradient_ = gradient_ + hd_;
    const double eps = 1e-13;
    mask_.resize(n_, 3);
    for (int i = 0; i < n_; ++i) {
      for (int c = 0; c < 3; ++c) {
        const bool at_lo = d_(i, c) <= lo_(i, c) + eps * (1.0 + std::abs(lo_(i, c)));
        const bool at_hi = d_(i, c) >= hi_(i, c) - eps * (1.0 + std::abs(hi_(i, c)));
        const bool bound =
            fixed_(i, c) != 0.0 || (at_lo && q_gradient_(i, c) > 0.0) || (at_hi && q_gradient_(i, c) < 0.0);
        mask_(i, c) = bound ? 0.0 : 1.0;
      }
    }
    return ((d_ - q_gradient_).cwiseMax(lo_).cwiseMin(hi_) - d_)
        .cwiseProduct(Eigen::MatrixX3d::Ones(n_, 3) - fixed_)
        .cwiseAbs()
        .maxCoeff();
  }

  NewtonStep SolveNewton() {
    const int applications = system_->preconditioner_applications_;
    double curvature = 0.0;
    const int iterations = system_->SolveMasked(-q_gradient_, mask_, options_.max_cg_iterations,
                                                options_.cg_tolerance, &step_, &curvature);
    const bool finite = step_.allFinite();
    return {iterations, system_->preconditioner_applications_ - applications, finite,
            finite ? step_.cwiseAbs().maxCoeff() : 0.0, finite ? Dot(q_gradient_, step_) : 0.0, curvature};
  }

  TrialStep StepTrial(double alpha) {
    trial_step_ = (d_ + alpha * step_).cwiseMax(lo_).cwiseMin(hi_);
    delta_ = trial_step_ - d_;
    return {(delta_ - alpha * step_).cwiseAbs().maxCoeff() > 0.0, Dot(q_gradient_, delta_)};
  }

  double StepCurvature() {
    h_delta_ = system_->Product(delta_);
    return Dot(delta_, h_delta_);
  }

  void AcceptStep(bool accumulate) {
    d_ = trial_step_;
    if (accumulate) hd_ += h_delta_;
  }

  SearchDirection Direction() {
    direction_ = d_;
    return {direction_.allFinite(), Dot(gradient_, direction_)};
  }

  double SteepestDirection() {
    direction_ = Clamp(x_ - gradient_, lower_, upper_) - x_;
    return Dot(gradient_, direction_);
  }

  double LineTrial(double step) { return objective_.Evaluate(Clamp(x_ + step * direction_, lower_, upper_), &trial_); }

  void AcceptTrial() {
    point_ = std::move(trial_);
    x_ = point_.emittance;
  }

  double FinalProjectedGradient() { return ProjectedGradientNorm(x_, objective_.Gradient(point_), lower_, upper_); }

  void Record(int iteration, double cost, double step, int free_variables, int cg_iterations) {
    const double seconds = SecondsSince(start_time_);
    summary_->trace.push_back({iteration, cost, seconds, step, free_variables, cg_iterations, 0.0});
    if (iteration > 0 && options_.progress) options_.progress(iteration, cost, SecondsSince(start_time_));
  }

  void SetProjectedGradient(double projected) { summary_->trace.back().projected_gradient = projected; }

 private:
  const SolverOptions& options_;
  const CompensationObjective& objective_;
  const Eigen::MatrixX3d& lower_;
  const Eigen::MatrixX3d& upper_;
  const int n_;
  Eigen::MatrixX3d x_;
  SolverSummary* summary_;
  const Clock::time_point start_time_;
  const Eigen::MatrixX3d* start_radiosity_;
  ObjectivePoint point_, trial_;
  Eigen::MatrixX3d gradient_, fixed_, direction_;
  // Alg. 2's state within one outer iteration.
  FreeColourHessian own_free_colour_hessian_;
  FreeColourHessian* free_colour_hessian_;
  std::optional<NewtonSystem> system_;
  Eigen::MatrixX3d lo_, hi_, d_, hd_, q_gradient_, mask_, step_, trial_step_, delta_, h_delta_;
};

}  // namespace

const char* MethodName(CompensationMethod method) {
  switch (method) {
    case CompensationMethod::kNaive: return "naive";
    case CompensationMethod::kReverse: return "reverse";
    case CompensationMethod::kLinear: return "linear";
    case CompensationMethod::kPerceptual: return "perceptual";
    case CompensationMethod::kPerceptual2000: return "perceptual2000";
  }
  return "?";
}

const char* RobustLossName(SolverOptions::RobustLoss loss) {
  switch (loss) {
    case SolverOptions::RobustLoss::kSquared: return "squared";
    case SolverOptions::RobustLoss::kSoftL1: return "soft_l1";
    case SolverOptions::RobustLoss::kHuber: return "huber";
    case SolverOptions::RobustLoss::kCauchy: return "cauchy";
  }
  return "?";
}

bool ParseRobustLoss(const std::string& name, SolverOptions::RobustLoss* loss) {
  for (SolverOptions::RobustLoss l :
       {SolverOptions::RobustLoss::kSquared, SolverOptions::RobustLoss::kSoftL1,
        SolverOptions::RobustLoss::kHuber, SolverOptions::RobustLoss::kCauchy}) {
    if (name == RobustLossName(l)) {
      *loss = l;
      return true;
    }
  }
  return false;
}

double RobustLossWeight(SolverOptions::RobustLoss loss, double scale, double s) {
  const double c2 = scale * scale;
  switch (loss) {
    case SolverOptions::RobustLoss::kSquared: return 1.0;
    case SolverOptions::RobustLoss::kSoftL1: return 1.0 / std::sqrt(1.0 + s / c2);
    case SolverOptions::RobustLoss::kHuber: return s <= c2 ? 1.0 : scale / std::sqrt(s);
    case SolverOptions::RobustLoss::kCauchy: return 1.0 / (1.0 + s / c2);
  }
  return 1.0;
}

namespace {

// ρ(s) of `loss` with scale c (RobustLossWeight is its derivative).
double RobustLossValue(SolverOptions::RobustLoss loss, double scale, double s) {
  const double c2 = scale * scale;
  switch (loss) {
    case SolverOptions::RobustLoss::kSquared:
      return s;
    case SolverOptions::RobustLoss::kSoftL1:
      return 2.0 * c2 * (std::sqrt(1.0 + s / c2) - 1.0);
    case SolverOptions::RobustLoss::kHuber:
      return s <= c2 ? s : 2.0 * scale * std::sqrt(s) - c2;
    case SolverOptions::RobustLoss::kCauchy:
      return c2 * std::log1p(s / c2);
  }
  return s;
}

// Ciede2000Metric into `metric_out`; returns Ciede2000RobustObjective at `radiosity` (0 for the
// first round's metric, at the desired colours).
double MeasureCiede2000(const SolverOptions& options, const CompensationProblem& problem,
                        const Eigen::MatrixX3d& radiosity, ColourMetric* metric_out) {
  const int n = problem.size();
  ColourMetric& metric = *metric_out;
  metric = ColourMetric();
  metric.factor.resize(n);
  metric.weight = Eigen::VectorXd::Ones(n);
  const bool measured = radiosity.rows() == n;  // else the first round's: at the desired colours
  std::vector<Eigen::Vector3d> residual(n);     // L_i r_i
  Eigen::VectorXd data_loss = Eigen::VectorXd::Zero(n);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d desired =
        XyzToLab(problem.rgb_to_xyz * problem.desired.row(i).transpose(), problem.white_xyz);
    Eigen::Vector3d lab = desired;
    if (measured) lab = XyzToLab(problem.rgb_to_xyz * radiosity.row(i).transpose(), problem.white_xyz);
    Eigen::Matrix3d m = DeltaE2000MetricClosedForm(0.5 * (lab + desired));
    const Eigen::Vector3d r = lab - desired;
    const double quadratic = r.dot(m * r);
    const double distance = DeltaE2000(lab, desired);
    if (quadratic > 1e-12 && std::isfinite(distance)) m *= distance * distance / quadratic;
    metric.factor[i] = Eigen::LLT<Eigen::Matrix3d>(m).matrixU();
    residual[i] = metric.factor[i] * r;
    if (measured) {
      metric.weight[i] =
          RobustLossWeight(options.robust_loss, options.robust_scale, distance * distance);
      data_loss[i] =
          RobustLossValue(options.robust_loss, options.robust_scale, distance * distance);
    }
  }
  metric.weight /= metric.weight.mean();
  if (!measured) return 0.0;
  if (problem.patch_weight.size() == n) data_loss = data_loss.cwiseProduct(problem.patch_weight);
  double value = problem.alpha * (problem.area / problem.area.mean()).dot(data_loss);
  if (!problem.adjacency.empty()) {
    // The spatial term's pairs under the same loss, at the difference of their metric residuals.
    const Eigen::Index pairs = static_cast<Eigen::Index>(problem.adjacency.size());
    metric.pair_weight.resize(pairs);
    double pair_loss = 0.0;
    for (Eigen::Index k = 0; k < pairs; ++k) {
      const auto& pair = problem.adjacency[k];
      const double s = (residual[pair[0]] - residual[pair[1]]).squaredNorm();
      metric.pair_weight[k] = RobustLossWeight(options.robust_loss, options.robust_scale, s);
      pair_loss += RobustLossValue(options.robust_loss, options.robust_scale, s);
    }
    metric.pair_weight /= metric.pair_weight.mean();
    value += (1.0 - problem.alpha) * pair_loss;
  }
  return value;
}

}  // namespace

ColourMetric Ciede2000Metric(const SolverOptions& options, const CompensationProblem& problem,
                             const Eigen::MatrixX3d& radiosity) {
  ColourMetric metric;
  MeasureCiede2000(options, problem, radiosity, &metric);
  return metric;
}

double Ciede2000RobustObjective(const SolverOptions& options, const CompensationProblem& problem,
                                const Eigen::MatrixX3d& radiosity) {
  ColourMetric metric;
  return MeasureCiede2000(options, problem, radiosity, &metric);
}

bool ParseMethod(const std::string& name, CompensationMethod* method) {
  for (CompensationMethod m : {CompensationMethod::kNaive, CompensationMethod::kReverse,
                               CompensationMethod::kLinear, CompensationMethod::kPerceptual,
                               CompensationMethod::kPerceptual2000}) {
    if (name == MethodName(m)) {
      *method = m;
      return true;
    }
  }
  return false;
}

const char* DeviceName(Device device) {
  switch (device) {
    case Device::kCpu: return "cpu";
    case Device::kCuda: return "cuda";
  }
  return "?";
}

bool ParseDevice(const std::string& name, Device* device) {
  for (Device d : {Device::kCpu, Device::kCuda}) {
    if (name == DeviceName(d)) {
      *device = d;
      return true;
    }
  }
  return false;
}

bool CudaAvailable(std::string* description) {
#if PROCAM_WITH_CUDA
  return CudaDeviceAvailable(description);
#else
  *description = "this build of procam has no CUDA backend (PROCAM_WITH_CUDA is OFF)";
  return false;
#endif
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
  if (!(robust_scale > 0.0 && std::isfinite(robust_scale))) {
    *why = "robust_scale must be a positive number";
    return false;
  }
  if (metric_rounds < 1 || metric_rounds > 100) {
    *why = "metric_rounds must be in [1, 100]";
    return false;
  }
  if (!(metric_round_tolerance >= 0.0 && metric_round_tolerance < 1.0)) {
    *why = "metric_round_tolerance must be in [0, 1)";
    return false;
  }
  if (!(metric_update_tolerance >= 0.0 && metric_update_tolerance < 1.0)) {
    *why = "metric_update_tolerance must be in [0, 1)";
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
  const int rows = device_product_rows;
  if (rows != -1 && rows != 0 && rows != 1 && rows != 2 && rows != 4 && rows != 8) {
    *why = "device_product_rows must be -1 (default), 0 (cuBLAS), 1, 2, 4 or 8";
    return false;
  }
  if (device_fused_blocks < 0) {
    *why = "device_fused_blocks must be >= 0";
    return false;
  }
  return true;
}

const char* MetricUpdateName(SolverOptions::MetricUpdate update) {
  switch (update) {
    case SolverOptions::MetricUpdate::kRounds:
      return "rounds";
    case SolverOptions::MetricUpdate::kEveryIteration:
      return "every_iteration";
  }
  return "?";
}

bool ParseMetricUpdate(const std::string& name, SolverOptions::MetricUpdate* update) {
  for (SolverOptions::MetricUpdate u :
       {SolverOptions::MetricUpdate::kRounds, SolverOptions::MetricUpdate::kEveryIteration}) {
    if (name == MetricUpdateName(u)) {
      *update = u;
      return true;
    }
  }
  return false;
}

const char* DevicePreconditionerName(SolverOptions::DevicePreconditioner preconditioner) {
  switch (preconditioner) {
    case SolverOptions::DevicePreconditioner::kBlockJacobiNeumann: return "block_jacobi_neumann";
    case SolverOptions::DevicePreconditioner::kBlockJacobi: return "block_jacobi";
  }
  return "?";
}

const char* DeviceCgMatrixName(SolverOptions::DeviceCgMatrix matrix) {
  switch (matrix) {
    case SolverOptions::DeviceCgMatrix::kFloat16: return "float16";
    case SolverOptions::DeviceCgMatrix::kFloat32: return "float32";
  }
  return "?";
}

std::string SolverSummary::BriefReport() const {
  std::ostringstream out;
  out << MethodName(method) << ": " << TerminationName(termination) << ", cost " << initial_cost << " -> "
      << final_cost << ", " << iterations << " iterations (" << inner_iterations << " inner, " << cg_iterations
      << " CG; " << evaluations << " evaluations, " << gradients << " gradients, " << hessian_products
      << " Hessian products, " << preconditioner_applications << " preconditioner applications), setup " << setup_seconds << " s, solve " << solve_seconds << " s";
  if (device_loop) {
    out << ", device loop (CG preconditioner " << DevicePreconditionerName(device_preconditioner) << ", CG matrix "
        << DeviceCgMatrixName(device_cg_matrix) << ")";
  }
  if (device_fused) out << ", fused device loop on " << device_fused_blocks << " blocks";
  if (!message.empty()) out << " (" << message << ")";
  return out.str();
}

double ProjectedGradientNorm(const Eigen::MatrixX3d& emittance, const Eigen::MatrixX3d& gradient,
                             const Eigen::MatrixX3d& lower, const Eigen::MatrixX3d& upper) {
  if (emittance.size() == 0) return 0.0;
  return (Clamp(emittance - gradient, lower, upper) - emittance).cwiseAbs().maxCoeff();
}

namespace {

// Adds the work counters `from` (a DriverRecords or another SolverSummary) to `to`.
template <typename Counters>
void AddWorkCounters(const Counters& from, SolverSummary* to) {
  to->inner_iterations += from.inner_iterations;
  to->cg_iterations += from.cg_iterations;
  to->evaluations += from.evaluations;
  to->gradients += from.gradients;
  to->hessian_products += from.hessian_products;
  to->preconditioner_applications += from.preconditioner_applications;
}

}  // namespace

void AddDriverRecords(const DriverRecords& records, SolverSummary* summary) {
  summary->termination = records.termination;
  const std::string message = TerminationMessage(records.termination);
  if (!message.empty()) summary->message = message;
  summary->initial_cost = records.initial_cost;
  summary->final_cost = records.final_cost;
  if (records.iterations > 0) summary->iterations = records.iterations;
  AddWorkCounters(records, summary);
}

namespace {

// MinimiseBounded, with the result's radiosity (where `radiosity` is not null) and, where
// `start_radiosity` is not null, the start's K⁻¹ initial known (initial must then lie within the
// bounds).
Eigen::MatrixX3d MinimiseOnCpu(const SolverOptions& options, const CompensationObjective& objective,
                               const Eigen::MatrixX3d& initial, SolverSummary* summary,
                               Eigen::MatrixX3d* radiosity, const Eigen::MatrixX3d* start_radiosity,
                               FreeColourHessian* free_colour_hessian) {
  const CompensationProblem& problem = objective.problem();
  CpuExecutor executor(options, objective, Clamp(initial, problem.lower, problem.upper), summary,
                       start_radiosity, free_colour_hessian);
  DriverRecords records;
  MinimiseBoundedDriver(options, executor, &records);
  AddDriverRecords(records, summary);
  if (radiosity != nullptr) *radiosity = executor.radiosity();
  return executor.x();
}

}  // namespace

Eigen::MatrixX3d MinimiseBounded(const SolverOptions& options,
                                 const CompensationObjective& objective,
                                 const Eigen::MatrixX3d& initial, SolverSummary* summary) {
  return MinimiseOnCpu(options, objective, initial, summary, nullptr, nullptr, nullptr);
}

namespace {

// Multires: the coarse level solved (from its reverse radiosity) in `model`, each fine patch
// starting from its parent's emittance.
Eigen::MatrixX3d MultiresStart(const SolverOptions& options, const CompensationProblem& problem,
                               const CoarseLevel& coarse, ColourModel model,
                               const Eigen::MatrixX3d& reverse, SolverSummary* summary,
                               double* coarse_setup_seconds) {
  const auto coarse_start = Clock::now();
  const auto setup_coarse = Clock::now();
  const std::shared_ptr<const RadiositySystem> coarse_system =
      MakeRadiositySystem(options, *coarse.problem);
  const RadiositySystem& coarse_radiosity = *coarse_system;
  *coarse_setup_seconds = SecondsSince(setup_coarse);
  summary->setup_seconds += *coarse_setup_seconds;
  const CompensationObjective coarse_objective(*coarse.problem, coarse_radiosity, model);
  SolverSummary coarse_summary;
  SolverOptions coarse_options = options;
  coarse_options.progress = nullptr;
  const Eigen::MatrixX3d coarse_reverse = Clamp(coarse_radiosity.Multiply(coarse.problem->desired),
                                                coarse.problem->lower, coarse.problem->upper);
  const Eigen::MatrixX3d coarse_emittance =
      Minimise(coarse_options, coarse_objective, coarse_reverse, &coarse_summary);
  Eigen::MatrixX3d initial = reverse;
  for (int i = 0; i < problem.size(); ++i)
    initial.row(i) = coarse_emittance.row((*coarse.coarse_of_fine)[i]);
  summary->coarse_iterations = coarse_summary.iterations;
  summary->coarse_seconds = SecondsSince(coarse_start) - *coarse_setup_seconds;
  return Clamp(initial, problem.lower, problem.upper);
}

// kPerceptual2000's rounds (solver.h), from `initial`; counters and the trace accumulate over the
// rounds, the costs are the last round's objective.
void SolveCiede2000Rounds(const SolverOptions& options, const CompensationProblem& problem,
                          const RadiositySystem& radiosity, const Eigen::MatrixX3d& initial,
                          SolverSummary* summary, CompensationSolution* solution) {
  Eigen::MatrixX3d emittance = initial;
  Eigen::MatrixX3d current_radiosity;  // empty: the first round's metric
  for (int round = 0; round < options.metric_rounds; ++round) {
    ColourMetric metric = Ciede2000Metric(options, problem, current_radiosity);
    const CompensationObjective objective(problem, radiosity, ColourModel::kLab, metric);
    SolverSummary round_summary;
    Eigen::MatrixX3d round_radiosity;  // filled by the device loop only
    // Every round but the last only sets the next round's metric and weights: solved to
    // metric_round_tolerance where that is set (docs/solver.md).
    SolverOptions round_options = options;
    if (round + 1 < options.metric_rounds) {
      round_options.function_tolerance = std::max(options.function_tolerance, options.metric_round_tolerance);
    }
    emittance = Minimise(round_options, objective, emittance, &round_summary, &round_radiosity);
    current_radiosity = round_radiosity.rows() == problem.size() ? std::move(round_radiosity)
                                                                   : radiosity.Solve(emittance);
    if (round == 0) summary->initial_cost = round_summary.initial_cost;
    summary->final_cost = round_summary.final_cost;
    summary->termination = round_summary.termination;
    summary->message = round_summary.message;
    summary->iterations += round_summary.iterations;
    AddWorkCounters(round_summary, summary);
    summary->device_loop = round_summary.device_loop;  // how the rounds ran on a device
    summary->device_fused = round_summary.device_fused;
    summary->device_fused_blocks = round_summary.device_fused_blocks;
    summary->device_preconditioner = round_summary.device_preconditioner;
    summary->device_cg_matrix = round_summary.device_cg_matrix;
    summary->trace.insert(summary->trace.end(), round_summary.trace.begin(), round_summary.trace.end());
    solution->metric = std::move(metric);
  }
  solution->emittance = emittance;
  solution->radiosity = current_radiosity;
}

// The CG forcing term of the every-iteration path's Newton systems (at least;
// SolveCiede2000EveryIteration).
constexpr double kEveryIterationCgTolerance = 0.5;

// The every-iteration path's preconditioner, chosen by what its Newton systems cost. It starts
// with (M_FF)⁻¹ (options.preconditioner's default) and changes to (K M⁻¹ Kᵀ)_FF for the rest of
// the run once the last kPreconditionerWindow systems took more than kInverseHessianSwitchCg CG
// iterations on average. Why:
//   (M_FF)⁻¹ ignores K. Writing K⁻¹ = I + R, the preconditioned matrix is I + R + M⁻¹RᵀM + ...:
//   the patches' coupling R scaled by the ratio of neighbouring colour matrices. Under CIE76 that
//   ratio is modest; CIEDE2000's metric (chroma weighted down by up to ~25× on saturated colours)
//   and the robust weights (1 down to ~1/30) make it large where saturated and grey, or well and
//   badly matched, patches meet, which is a property of the room's desired picture, not of the
//   active set: measured per Newton system (docs/solver.md) 1.3–4.5 CG iterations on average on
//   the box room and five of the six scenes, 7.8 on interior_partitions.
//   (K M⁻¹ Kᵀ)_FF is H⁻¹ restricted to the free set: exact for any M when no bound is active,
//   its error (the Schur complement's correction) of rank at most the number of bound variables.
//   It took 1.6–4.6 CG iterations per system on the same problems, but each application costs
//   two products with K, as much again as the Hessian product CG does anyway: a CG iteration
//   costs about twice the (M_FF)⁻¹ one.
// So (K M⁻¹ Kᵀ)_FF pays only where (M_FF)⁻¹ needs more than twice its ~3 iterations: 6. The
// average is over four systems, since single systems take 8–9 even where the average is 3 (the
// box room: at most 5.5 over any four); once changed it stays, since the (M_FF)⁻¹ count is not
// observed any more, until the run would stop: it stops only on a step with (M_FF)⁻¹ (a small
// decrease or a failed step with (K M⁻¹ Kᵀ)_FF returns to (M_FF)⁻¹ for the rest of the run: used
// throughout, (K M⁻¹ Kᵀ)_FF stopped short of the fixed point on ciede2000_test's 200-patch box
// room with metric_update_tolerance 0: a step without decrease where the projected gradient was
// 1). The share of variables on a bound was measured as the rule first and does
// not separate the cases: the box room's systems with 10–20% on a bound took 1–3 iterations with
// (M_FF)⁻¹ and 6–9 with (K M⁻¹ Kᵀ)_FF, interior_partitions' with 35% on a bound 3–12 and 1–4.
constexpr int kPreconditionerWindow = 4;
constexpr double kInverseHessianSwitchCg = 6.0;
// The every-iteration path's safeguard (SolveCiede2000EveryIteration): halvings of a step it
// tries (each costs one measurement of the metric, O(n)), and its window: a step must end below
// the highest measured objective of the last kSafeguardWindow kept points, and the run stops
// after kSafeguardWindow steps without a new best.
constexpr int kSafeguardHalvings = 3;
constexpr int kSafeguardWindow = 5;

// kPerceptual2000 with MetricUpdate::kEveryIteration (solver.h), from `initial`: one Gauss–Newton
// run whose every iteration is one step of Alg. 1 (its Armijo search included) on the objective
// with the metric and weights measured at the iteration's start point. The costs are that
// objective's at the start and at the result (CompensationSolution::metric, measured there); the
// trace's costs are the robust objective's.
void SolveCiede2000EveryIteration(const SolverOptions& options, const CompensationProblem& problem,
                                  const RadiositySystem& radiosity, const Eigen::MatrixX3d& initial,
                                  SolverSummary* summary, CompensationSolution* solution) {
  const auto start_time = Clock::now();
  Eigen::MatrixX3d emittance = initial;
  Eigen::MatrixX3d current_radiosity = radiosity.Solve(emittance);
  ColourMetric metric;
  double robust = MeasureCiede2000(options, problem, current_radiosity, &metric);
  ++summary->metric_measurements;
  SolverOptions step_options = options;
  // Each Newton system's model (metric and weights) is replaced at the next iterate, so the
  // reweighting's linear convergence, not each step's accuracy, sets the rate: CG stops at a
  // relative residual of kEveryIterationCgTolerance where cg_tolerance is tighter (docs/solver.md:
  // the box room's CG iterations 159 -> 96, c_shaped's 68 -> 54). A step
  // that lowers its objective too little to go on may be a poor loose step rather than the fixed
  // point, so the run stops only on such a step solved to cg_tolerance.
  const double loose_cg_tolerance = std::max(options.cg_tolerance, kEveryIterationCgTolerance);
  step_options.cg_tolerance = loose_cg_tolerance;
  step_options.max_iterations = 1;
  step_options.progress = nullptr;
  summary->termination = TerminationType::kMaxIterations;
  bool first = true;
  FreeColourHessian free_colour_hessian;  // its ordering reused while the free set repeats
  // The CG iterations of the last kPreconditionerWindow steps under (M_FF)⁻¹, while it is used
  // (options.preconditioner kFreeColourHessian): the preconditioner's rule above.
  std::vector<int> recent_cg;
  bool may_change = true;  // cleared once the run went back to the asked-for preconditioner
  // The safeguard's state (below): the measured objective at the last kept points, the best.
  std::vector<double> recent_robust = {robust};
  struct Point {
    Eigen::MatrixX3d emittance, radiosity;
    ColourMetric metric;
    double robust = 0.0;
    int iteration = 0;
  } best{emittance, current_radiosity, metric, robust, 0};
  for (int iteration = 1; iteration <= options.max_iterations; ++iteration) {
    const CompensationObjective objective(problem, radiosity, ColourModel::kLab, metric);
    SolverSummary step_summary;
    Eigen::MatrixX3d step_radiosity;
    Eigen::MatrixX3d step_emittance =
        Minimise(step_options, objective, emittance, &step_summary, &step_radiosity,
                 &current_radiosity, &free_colour_hessian);
    AddWorkCounters(step_summary, summary);
    summary->device_loop = step_summary.device_loop;  // how the steps ran on a device
    summary->device_fused = step_summary.device_fused;
    summary->device_fused_blocks = step_summary.device_fused_blocks;
    summary->device_preconditioner = step_summary.device_preconditioner;
    summary->device_cg_matrix = step_summary.device_cg_matrix;
    if (first) {
      summary->initial_cost = step_summary.initial_cost;
      summary->trace.push_back({0, robust, 0.0, 0.0, 3 * problem.size(), 0, 0.0});
      first = false;
    }
    summary->final_cost = step_summary.initial_cost;
    // At the fixed point: first-order optimal for the objective measured where it stands.
    if (step_summary.termination == TerminationType::kGradientTolerance) {
      summary->termination = TerminationType::kGradientTolerance;
      break;
    }
    const bool changed = step_options.preconditioner != options.preconditioner;
    if (step_summary.iterations == 0 ||
        step_summary.termination == TerminationType::kLineSearchFailure ||
        step_summary.termination == TerminationType::kNumericalFailure) {
      if (changed && step_summary.termination != TerminationType::kNumericalFailure) {
        // No step with the changed preconditioner: the run goes on with the asked-for one.
        step_options.preconditioner = options.preconditioner;
        may_change = false;
        continue;
      }
      summary->termination = step_summary.termination;
      summary->message = step_summary.message;
      break;
    }
    if (may_change &&
        step_options.preconditioner == SolverOptions::Preconditioner::kFreeColourHessian) {
      recent_cg.push_back(step_summary.cg_iterations);
      if (static_cast<int>(recent_cg.size()) > kPreconditionerWindow)
        recent_cg.erase(recent_cg.begin());
      double sum = 0.0;
      for (int count : recent_cg) sum += count;
      if (static_cast<int>(recent_cg.size()) == kPreconditionerWindow &&
          sum > kInverseHessianSwitchCg * kPreconditionerWindow) {
        step_options.preconditioner = SolverOptions::Preconditioner::kInverseHessian;
      }
    }
    if (step_radiosity.rows() != problem.size()) step_radiosity = radiosity.Solve(step_emittance);
    // The safeguard: the step lowered the objective measured at its start, not necessarily the
    // one measured where it lands (the metric and the robust weights move with the iterate).
    // Unguarded, the run can cycle: on data/scenes/room.json the measured objective went round
    // 7 720–7 800 for 95 iterations after reaching 7 640. Requiring every step to lower it stops
    // too early instead: on the box room it rises and falls on its way down (27 517 → 27 676 →
    // 27 168 → … → 26 105). So the rule is non-monotone (Grippo, Lampariello and Lucidi 1986):
    // a step is kept if the measured objective ends below the highest of the last
    // kSafeguardWindow kept ones, else shorter steps along it (B is linear in E, so each costs
    // one measurement); the run ends when kSafeguardWindow steps in a row found nothing lower
    // than the best, or no step is kept, and returns the best point it measured.
    ColourMetric step_metric;
    double step_robust = MeasureCiede2000(options, problem, step_radiosity, &step_metric);
    ++summary->metric_measurements;
    const double reference = *std::max_element(recent_robust.begin(), recent_robust.end());
    double fraction = 1.0;
    for (int halving = 0; !(step_robust < reference) && halving < kSafeguardHalvings; ++halving) {
      fraction *= 0.5;
      Eigen::MatrixX3d shorter =
          current_radiosity + fraction * (step_radiosity - current_radiosity);
      step_robust = MeasureCiede2000(options, problem, shorter, &step_metric);
      ++summary->metric_measurements;
      if (step_robust < reference) {
        step_radiosity = std::move(shorter);
        step_emittance = emittance + fraction * (step_emittance - emittance);
      }
    }
    if (!(step_robust < reference)) {
      if (step_options.cg_tolerance > options.cg_tolerance || changed) {
        step_options.cg_tolerance = options.cg_tolerance;  // confirm with a tight step first
        step_options.preconditioner = options.preconditioner;
        may_change = false;
        continue;
      }
      summary->termination = TerminationType::kFunctionTolerance;
      summary->message = "no step lowers the measured objective";
      break;
    }
    emittance = step_emittance;
    current_radiosity = std::move(step_radiosity);
    metric = std::move(step_metric);
    robust = step_robust;
    recent_robust.push_back(robust);
    if (static_cast<int>(recent_robust.size()) > kSafeguardWindow)
      recent_robust.erase(recent_robust.begin());
    if (robust < best.robust) best = {emittance, current_radiosity, metric, robust, iteration};
    summary->iterations = iteration;
    if (!step_summary.trace.empty()) {
      IterationRecord record = step_summary.trace.back();
      record.iteration = iteration;
      record.cost = robust;
      record.seconds = SecondsSince(start_time);
      summary->trace.push_back(record);
    }
    if (options.progress) options.progress(iteration, robust, SecondsSince(start_time));
    if (iteration - best.iteration >= kSafeguardWindow) {
      summary->termination = TerminationType::kFunctionTolerance;
      summary->message = "the measured objective stopped falling";
      break;
    }
    // The step's decrease of its own objective: zero at the fixed point.
    const double decrease = step_summary.initial_cost - step_summary.final_cost;
    if (decrease <= options.metric_update_tolerance * step_summary.initial_cost) {
      if (step_options.cg_tolerance <= options.cg_tolerance && !changed) {
        summary->termination = TerminationType::kFunctionTolerance;
        break;
      }
      step_options.cg_tolerance = options.cg_tolerance;  // confirm with a tight step ...
      if (changed) {  // ... and with the asked-for preconditioner, for the rest of the run
        step_options.preconditioner = options.preconditioner;
        may_change = false;
      }
    } else {
      step_options.cg_tolerance = loose_cg_tolerance;
    }
  }
  if (best.robust < robust) {  // the safeguard's best point, where the run ended above it
    emittance = std::move(best.emittance);
    current_radiosity = std::move(best.radiosity);
    metric = std::move(best.metric);
  }
  // The costs: the objective with the metric measured at the result.
  const CompensationObjective objective(problem, radiosity, ColourModel::kLab, metric);
  double value = 0.0;
  {
    Eigen::MatrixX3d residual(problem.size(), 3);
    for (int i = 0; i < problem.size(); ++i)
      residual.row(i) = objective.Residual(i, current_radiosity.row(i).transpose()).transpose();
    value = residual.cwiseProduct(objective.weights() * residual).sum();
  }
  summary->final_cost = value;
  solution->metric = std::move(metric);
  solution->emittance = emittance;
  solution->radiosity = current_radiosity;
}

}  // namespace

CompensationSolution Solve(const SolverOptions& options, const CompensationProblem& problem,
                           SolverSummary* summary, const CoarseLevel& coarse, const WarmStart& start) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("solver options: " + why);
  why = problem.Validate();
  if (!why.empty()) throw std::invalid_argument("compensation problem: " + why);
  const bool warm = start.emittance.size() > 0;
  if (warm && (start.emittance.rows() != problem.size() || start.emittance.cols() != 3 ||
               !start.emittance.allFinite())) {
    throw std::invalid_argument("warm start: need finite (" + std::to_string(problem.size()) + ",3) emittance");
  }
  if (!warm && options.multires && (coarse.problem == nullptr || coarse.coarse_of_fine == nullptr)) {
    throw std::invalid_argument("multires needs a coarse level");
  }
  *summary = SolverSummary();
  summary->method = options.method;
  auto setup_start = Clock::now();
  auto radiosity_system = start.radiosity ? start.radiosity : MakeRadiositySystem(options, problem);
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
      const Eigen::MatrixX3d initial =
          warm ? Clamp(start.emittance, problem.lower, problem.upper)
               : options.multires ? MultiresStart(options, problem, coarse, model, reverse, summary,
                                                  &coarse_setup_seconds)
                                  : reverse;
      const CompensationObjective objective(problem, radiosity, model);
      solution.emittance = Minimise(options, objective, initial, summary, &solution.radiosity);
      break;
    }
    case CompensationMethod::kPerceptual2000: {
      const Eigen::MatrixX3d initial =
          warm ? Clamp(start.emittance, problem.lower, problem.upper)
               : options.multires ? MultiresStart(options, problem, coarse, ColourModel::kLab, reverse,
                                                  summary, &coarse_setup_seconds)
                                  : reverse;
      if (options.metric_update == SolverOptions::MetricUpdate::kEveryIteration) {
        SolveCiede2000EveryIteration(options, problem, radiosity, initial, summary, &solution);
      } else {
        SolveCiede2000Rounds(options, problem, radiosity, initial, summary, &solution);
      }
      break;
    }
  }
  if (solution.radiosity.rows() != problem.size()) solution.radiosity = radiosity.Solve(solution.emittance);
  solution.radiosity_system = std::move(radiosity_system);
  summary->solve_seconds = SecondsSince(solve_start) - coarse_setup_seconds;
  return solution;
}

}  // namespace procam
