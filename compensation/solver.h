#pragma once
// Compensation solvers with a Ceres-like API: Solve(options, problem, &summary).
//
//   kNaive      E = clamp(Bd, l, u): show the desired picture and ignore the bounces.
//   kReverse    E = clamp(K·Bd, l, u): reverse radiosity, exact when no bound is hit.
//   kLinear     Sheng et al. 2010: the objective of Eq. 5–6 in a linear luma/chroma space;
//               a convex bound-constrained QP, solved to optimality.
//   kPerceptual Sheng et al. 2011: the objective in L*a*b*, active-set Gauss–Newton (Alg. 1)
//               with the modified projected Newton inner solver (Alg. 2) and an Armijo line
//               search; optionally warm-started from the coarse patch level (multires).
//   kPerceptual2000  the same solver on the objective measured in CIEDE2000 instead of CIE76
//               (docs/solver.md): rounds of the L*a*b* objective, each patch's residual
//               measured by CIEDE2000's metric (DeltaE2000Metric) at the midpoint of its colour
//               and the desired one, scaled to its exact ΔE00, and its data term weighted by a
//               robust loss's ρ′ at that ΔE00² (iteratively reweighted least squares); the
//               spatial term is kept, each neighbour pair under the same loss at the length of
//               the difference of their measured residuals; each round warm-starts from the last.
//
// Every Newton system H_FF d_F = −g_F (H = K⁻ᵀ M K⁻¹, M the sparse colour-space Gauss–Newton
// matrix) is solved by preconditioned conjugate gradients, by default with (M_FF)⁻¹ (a sparse
// factorisation of M restricted to the free variables), optionally with (K M⁻¹ Kᵀ)_FF (exact
// when no bound is active); no dense 3n×3n matrix is ever formed. docs/solver.md compares them.

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "compensation/objective.h"
#include "compensation/problem.h"
#include "compensation/solver_driver.h"
#include "compensation/solver_records.h"

namespace procam {

enum class CompensationMethod { kNaive, kReverse, kLinear, kPerceptual, kPerceptual2000 };
const char* MethodName(CompensationMethod method);
// Parses "naive", "reverse", "linear", "perceptual", "perceptual2000"; false if unknown.
bool ParseMethod(const std::string& name, CompensationMethod* method);

// Where the dense work of a solve (every K⁻¹ and K⁻ᵀ application) runs.
enum class Device { kCpu, kCuda };
const char* DeviceName(Device device);
// Parses "cpu", "cuda"; false if unknown.
bool ParseDevice(const std::string& name, Device* device);
// Whether this build has the CUDA backend (PROCAM_WITH_CUDA) and a CUDA device can be used;
// `description` gets the device, or one line saying what is missing.
bool CudaAvailable(std::string* description);

// The algorithm's numbers (iteration limits, tolerances, the Armijo constant, the second-order
// term) are AlgorithmSettings' (solver_driver.h documents each); the rest is here.
// procam play's stopping rule for its warm solve of each frame (function_tolerance; compensate
// and evaluate keep AlgorithmSettings' 1e-12). On the play benchmark's drifting frames every
// patch's emittance then lies within 0.0006–0.0027 of the converged solve's (emittances up to
// 1.6), the cost within 3e-8 of it, in 4–6 iterations instead of 8–10 (docs/nodes.md).
inline constexpr double kPlayFunctionTolerance = 1e-6;

struct SolverOptions : AlgorithmSettings {
  // The solver's own default is the paper's method; compensate, play and verify start from
  // RecommendedSolverOptions() instead.
  CompensationMethod method = CompensationMethod::kPerceptual;
  // kCpu: the CPU factorisation and kernels of radiosity.h (the reference). kCuda: K⁻¹ formed
  // once on the GPU and every solve one matrix product (cuda_radiosity.h); the algorithm is the
  // same. kCuda needs a build with PROCAM_WITH_CUDA and a device: otherwise Solve throws
  // std::runtime_error with one line saying which is missing.
  Device device = Device::kCpu;
  // kCuda only: objective values, gradients and line searches with the float32 K⁻¹ as well (CG
  // products always use it). Off: float64 (docs/gpu.md compares the two). Host loop only.
  bool device_float32 = false;
  // kCuda only: run Alg. 1 on the host with only the K⁻¹/K⁻ᵀ applications on the device (n×3
  // copied each way per application), the first GPU path, kept for comparison. Off (default):
  // the whole loop stays on the device (cuda_solver.h: own CG preconditioner, float64
  // values), for the linear and perceptual methods and both levels of multires.
  bool device_host_loop = false;
  // kCuda, device loop only: problems below 4096 patches on the dense K⁻¹ (one K⁻¹ for all
  // three channels) run the whole loop in one cooperative kernel, with no host round trip
  // (cuda_solver.h; 2–3× faster there, docs/gpu.md). Off: one kernel per step with the host
  // reading scalars in between, as larger problems run; for comparison.
  bool device_fused = true;
  // kCuda, device loop only: CG's preconditioner (the CPU's `preconditioner` below is not used
  // there; docs/gpu.md compares the two):
  //   kBlockJacobiNeumann  the inverse 3×3 diagonal blocks D of M_FF with one Neumann term for
  //                        their coupling N through W: z = D⁻¹r + D⁻¹ N D⁻¹ r (SPD, docs/gpu.md).
  //   kBlockJacobi         z = D⁻¹r alone (more CG iterations; for comparison).
  enum class DevicePreconditioner { kBlockJacobiNeumann, kBlockJacobi };
  DevicePreconditioner device_preconditioner = DevicePreconditioner::kBlockJacobiNeumann;
  // kCuda, dense F, device loop only: the copy of K⁻¹ that CG's Hessian products (float32
  // vectors) read: kFloat16, 2^k K⁻¹ in float16 (half the bytes, within 2^-11 relative), or
  // kFloat32. kFloat32 keeps the loop from fusing (the fused kernel reads the float16 copy).
  enum class DeviceCgMatrix { kFloat16, kFloat32 };
  DeviceCgMatrix device_cg_matrix = DeviceCgMatrix::kFloat16;
  // kCuda, dense F: outputs per block of the device's own K⁻¹ product kernel, one of 1, 2, 4, 8;
  // 0: cuBLAS's GEMM instead; -1 (default): 4 for float64 and float32 K⁻¹, 8 for the float16
  // copy (measured best, docs/gpu.md). Any value but -1 keeps the loop from fusing. Products only:
  // the solver's steps are the same (sums in another order).
  int device_product_rows = -1;
  // kCuda, dense F, loop with a kernel per step: replay its fixed sequences of kernels as CUDA
  // graphs (fewer launch costs); off: plain launches, the same arithmetic.
  bool device_graphs = true;
  // kCuda, fused loop: blocks of its cooperative grid, ≥ 0; 0 (default): one per multiprocessor
  // (at most 1024). A count past what the device holds at once makes the cooperative launch fail
  // before anything ran, and the loop with a kernel per step solves the problem instead.
  int device_fused_blocks = 0;
  // kCuda, device loop: print to stderr after each solve where its time went (host reads of the
  // scalars, launches, graph captures, unit costs of its operations). Diagnostics only.
  bool device_profile = false;
  // Solve the coarse level first and start the fine solve from it (needs a coarse level).
  bool multires = false;
  // kPerceptual2000: the loss on each patch's ΔE00² = s, as Ceres's loss functions with scale
  // c = robust_scale (ΔE00 units): kSquared ρ(s) = s; kSoftL1 ρ(s) = 2c²(√(1 + s/c²) − 1);
  // kHuber ρ(s) = s up to c², 2c√s − c² beyond; kCauchy ρ(s) = c² log(1 + s/c²). The mean
  // CIEDE2000 that Table 1 reports is what soft-L1 with a small c approaches (ρ ≈ 2c·ΔE00).
  enum class RobustLoss { kSquared, kSoftL1, kHuber, kCauchy };
  RobustLoss robust_loss = RobustLoss::kSoftL1;
  double robust_scale = 1.0;  // > 0 (1 measured best of 1, 2, 3, 5, 8 on the six synthetic scenes)
  // kPerceptual2000: reweighting rounds, ≥ 1 (the first measures with the metric at the desired
  // colours and weight 1).
  int metric_rounds = 4;
  // kPerceptual2000: the stopping rule of every round but the last (whose metric and weights the
  // next round replaces): stop once an iteration lowers the round's objective by less than this
  // fraction of it (function_tolerance where that is looser); the last round stops by
  // AlgorithmSettings' tolerances. In [0, 1). 0 (default): every round solved to the last's
  // tolerances. 1e-3 halves the Gauss–Newton and CG iterations (docs/solver.md), but the rounds
  // then end 0.1–2% apart in objective depending on where they started (a warm start no longer
  // returns to the same solution), so it is not the default.
  double metric_round_tolerance = 0.0;
  // kPerceptual2000: when the metric and the robust weights are measured again.
  //   kEveryIteration  (default) one Gauss–Newton run that measures them again at every iterate:
  //   each
  //                    iteration is one step of Alg. 1 (its Armijo search included) on the
  //                    objective with the metric and weights measured at its start point. It stops
  //                    at the fixed point of the reweighting: where the projected gradient test of
  //                    AlgorithmSettings holds for the objective measured at the iterate itself, or
  //                    once a step lowers its objective by less than metric_update_tolerance of it.
  //                    Lower objective and per-patch ΔE00 than the rounds in 3–6× fewer
  //                    iterations on every room measured (docs/solver.md).
  //   kRounds          metric_rounds rounds, each a whole solve with them fixed (above).
  enum class MetricUpdate { kRounds, kEveryIteration };
  MetricUpdate metric_update = MetricUpdate::kEveryIteration;
  // kEveryIteration: the relative decrease of a step's objective below which it stops, in [0, 1).
  double metric_update_tolerance = 1e-4;
  // Preconditioner of the free-variable Newton systems H_FF d = −g_F (H = K⁻ᵀ M K⁻¹):
  //   kInverseHessian   (K M⁻¹ Kᵀ)_FF: the exact inverse when no bound is active; two products
  //                     with F per application.
  //   kFreeColourHessian (M_FF)⁻¹: M restricted to the free variables, factorised (sparse
  //                     LDLᵀ) once per outer iteration; exact when K = I, no products with F.
  enum class Preconditioner { kInverseHessian, kFreeColourHessian };
  Preconditioner preconditioner = Preconditioner::kFreeColourHessian;
  // Called after every outer iteration with (iteration, cost, seconds since start).
  std::function<void(int, double, double)> progress;

  bool Check(std::string* why) const;
};
// The options the commands start from (CompensationOptions: compensate and verify; procam play;
// Python's compensate): perceptual2000 with the metric measured at every iterate, the lowest
// per-pixel CIEDE2000 of all methods on every synthetic scene (docs/solver.md).
inline SolverOptions RecommendedSolverOptions() {
  SolverOptions options;
  options.method = CompensationMethod::kPerceptual2000;
  options.metric_update = SolverOptions::MetricUpdate::kEveryIteration;
  return options;
}
// "squared", "soft_l1", "huber", "cauchy".
const char* RobustLossName(SolverOptions::RobustLoss loss);
bool ParseRobustLoss(const std::string& name, SolverOptions::RobustLoss* loss);
// ρ′(s) of `loss` with scale c: the weight of a residual whose squared length is s.
double RobustLossWeight(SolverOptions::RobustLoss loss, double scale, double s);
// The ColourMetric of a kPerceptual2000 round at radiosity B: per patch CIEDE2000's metric at the
// midpoint of Lab(B_i) and the desired Lab, scaled so that the residual's squared length is its
// ΔE00² exactly, and the data weight ρ′(ΔE00²) (normalised to mean 1). An empty `radiosity` gives
// the first round's: the metric at the desired colour, weights 1.
ColourMetric Ciede2000Metric(const SolverOptions& options, const CompensationProblem& problem,
                             const Eigen::MatrixX3d& radiosity);
// The robust objective that kPerceptual2000 approaches, at radiosity B (n×3): α Σ A_i/Ā w_i
// ρ(ΔE00_i²) + (1 − α) Σ_pairs ρ(‖L_i r_i − L_j r_j‖²), L_i the metric of Ciede2000Metric measured
// at B itself, w the problem's patch_weight (1 without one), ρ the options' loss.
double Ciede2000RobustObjective(const SolverOptions& options, const CompensationProblem& problem,
                                const Eigen::MatrixX3d& radiosity);
// "rounds", "every_iteration".
const char* MetricUpdateName(SolverOptions::MetricUpdate update);
bool ParseMetricUpdate(const std::string& name, SolverOptions::MetricUpdate* update);
// "block_jacobi_neumann", "block_jacobi"; "float16", "float32".
const char* DevicePreconditionerName(SolverOptions::DevicePreconditioner preconditioner);
const char* DeviceCgMatrixName(SolverOptions::DeviceCgMatrix matrix);

struct SolverSummary {
  CompensationMethod method = CompensationMethod::kPerceptual;
  TerminationType termination = TerminationType::kMaxIterations;
  std::string message;
  double initial_cost = 0.0;
  double final_cost = 0.0;
  int iterations = 0;             // outer iterations
  int inner_iterations = 0;       // projected-Newton iterations, all outer iterations together
  int cg_iterations = 0;
  // Work counted for profiling: objective evaluations (each one K⁻¹ application in double),
  // gradients (one K⁻ᵀ in double), Hessian products (K⁻¹ and K⁻ᵀ in float32) and
  // preconditioner applications, all outer iterations together.
  int evaluations = 0;
  int gradients = 0;
  int hessian_products = 0;
  int preconditioner_applications = 0;
  // kPerceptual2000: measurements of CIEDE2000's metric at every patch (Ciede2000Metric).
  int metric_measurements = 0;
  double setup_seconds = 0.0;     // factorising K (and the coarse level's K with multires)
  double solve_seconds = 0.0;     // everything after the setup
  double coarse_seconds = 0.0;    // part of solve_seconds spent on the coarse level
  int coarse_iterations = 0;
  // kCuda: the (fine level's) loop ran fused in one kernel (SolverOptions::device_fused), on
  // this many blocks.
  bool device_fused = false;
  int device_fused_blocks = 0;
  // kCuda, device loop (not the host loop): it ran, with this CG preconditioner and, on the dense
  // F, this copy of K⁻¹ for CG's products (SolverOptions' fields of the same names).
  bool device_loop = false;
  SolverOptions::DevicePreconditioner device_preconditioner = SolverOptions::DevicePreconditioner::kBlockJacobiNeumann;
  SolverOptions::DeviceCgMatrix device_cg_matrix = SolverOptions::DeviceCgMatrix::kFloat16;
  std::vector<IterationRecord> trace;

  // One line: method, termination, costs, iterations, times.
  std::string BriefReport() const;
};

// Adds what one run of MinimiseBoundedDriver counted to `summary` as MinimiseBounded adds its
// records: the counters added, the termination, costs and last iteration set, the message where
// the termination has one (the trace is the executor's to append).
void AddDriverRecords(const DriverRecords& records, SolverSummary* summary);

// A coarser patch level for multires: its problem and each fine patch's parent.
struct CoarseLevel {
  const CompensationProblem* problem = nullptr;
  const std::vector<int>* coarse_of_fine = nullptr;
};

struct CompensationSolution {
  Eigen::MatrixX3d emittance;  // E, n×3, within the bounds
  Eigen::MatrixX3d radiosity;  // B = K⁻¹E
  // The factorised K the solve used, for callers that evaluate more (objectives, ΔE) without
  // factorising it again.
  std::shared_ptr<const RadiositySystem> radiosity_system;
  // kPerceptual2000: the metric of the last round, whose objective the solution minimises.
  ColourMetric metric;
};

// Where a solve starts, for a sequence of problems that differ only in their desired colours
// (procam play: one per frame of changing content).
struct WarmStart {
  // Made for this problem's form factors and reflectance (an earlier solution's
  // radiosity_system, with the same options' device): reused instead of factorising K again.
  // Null: made here.
  std::shared_ptr<const RadiositySystem> radiosity;
  // The start of the iterative methods (projected onto the bounds), e.g. the previous frame's
  // emittance; it replaces multires's coarse start. Empty: the reverse method's E, as Solve does.
  Eigen::MatrixX3d emittance;
};

// Solves `problem` (validated first: throws std::invalid_argument naming the fault).
CompensationSolution Solve(const SolverOptions& options, const CompensationProblem& problem,
                           SolverSummary* summary, const CoarseLevel& coarse = {},
                           const WarmStart& start = {});

// Alg. 1 on an objective, from `initial` (projected onto the bounds). Used by Solve for the
// linear and perceptual methods; exposed for tests and benchmarks.
Eigen::MatrixX3d MinimiseBounded(const SolverOptions& options, const CompensationObjective& objective,
                                 const Eigen::MatrixX3d& initial, SolverSummary* summary);

// ‖E − P(E − ∇f)‖∞: zero exactly at first-order critical points of the bounded problem.
double ProjectedGradientNorm(const Eigen::MatrixX3d& emittance, const Eigen::MatrixX3d& gradient,
                             const Eigen::MatrixX3d& lower, const Eigen::MatrixX3d& upper);

}  // namespace procam
