// The matrix-free CUDA backend (cuda_compressed.h) against the CPU reference: the compressed
// F's own product (CompressedFormFactors::Multiply), RadiositySystem's matrix-free CG, and the
// equation K b = e itself. Two facing unit plates 0.5 m apart (as analytic_problem.h), F built
// by BuildCompressedFormFactors from the point-to-point exchange without Embree, in a binary
// compiled from the solver's sources (it runs on the device machine, docs/gpu.md). Skips
// without a device. DISABLED_Timings is the benchmark (10⁴ to 10⁵ patches).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include <cuda_runtime.h>
#include <gtest/gtest.h>

#include "tests/compensation/cuda_skip.h"

#include "compensation/colour.h"
#include "compensation/cuda_compressed.h"
#include "compensation/objective.h"
#include "compensation/radiosity.h"
#include "compensation/solver.h"
#include "geometry/compressed_form_factors.h"

namespace procam {
namespace {

constexpr double kPlateDistance = 0.5;  // m

// Two facing unit plates, g×g patches each: plate 0 at z = 0 facing +z, plate 1 at z = 0.5
// facing −z; patch plate·g² + row·g + column has its centre at ((column + ½)/g, (row + ½)/g).
std::vector<ClusterPatch> Plates(int g) {
  const double side = 1.0 / g;
  std::vector<ClusterPatch> patches(2 * g * g);
  for (int plate = 0; plate < 2; ++plate) {
    for (int r = 0; r < g; ++r) {
      for (int c = 0; c < g; ++c) {
        ClusterPatch& patch = patches[plate * g * g + r * g + c];
        patch.centroid = Eigen::Vector3d((c + 0.5) * side, (r + 0.5) * side, plate * kPlateDistance);
        patch.normal = Eigen::Vector3d(0.0, 0.0, plate == 0 ? 1.0 : -1.0);
        patch.area = side * side;
        patch.surface = plate;
      }
    }
  }
  return patches;
}

// F of the plates, compressed: exchange A_i A_j cosθ_i cosθ_j / (π r²) = A_i A_j d² / (π r⁴)
// between the plates (both cosines d / r), nothing within a plate, no occluder.
std::shared_ptr<const CompressedFormFactors> CompressedPlates(int g, const ClusterOptions& options,
                                                              CompressedBuildSummary* summary = nullptr) {
  const std::vector<ClusterPatch> patches = Plates(g);
  const PairExchange exchange = [&patches](int i, int j) {
    if (patches[i].surface == patches[j].surface) return 0.0;
    const double r2 = (patches[i].centroid - patches[j].centroid).squaredNorm();
    return patches[i].area * patches[j].area * kPlateDistance * kPlateDistance / (std::numbers::pi * r2 * r2);
  };
  CompressedBuildSummary local;
  return std::make_shared<const CompressedFormFactors>(BuildCompressedFormFactors(
      patches, options, exchange, Visibility(), 0, nullptr, summary != nullptr ? summary : &local));
}

// analytic_problem.h's PlatesProblem on the compressed F (form_factors left empty, so no n²
// matrix anywhere): grid adjacency, bounds [0, 1], quadrants of saturated and pale desired
// colours (about half the variables end on a bound), grey reflectance `rho`.
CompensationProblem CompressedPlatesProblem(int g, const ClusterOptions& options, double rho = 0.9,
                                            CompressedBuildSummary* summary = nullptr) {
  CompensationProblem p;
  p.compressed_form_factors = CompressedPlates(g, options, summary);
  const int n = p.compressed_form_factors->size();
  p.area = p.compressed_form_factors->area();
  p.reflectance = Eigen::MatrixX3d::Constant(n, 3, rho);
  const double side = 1.0 / g;
  const Eigen::Vector3d colours[4] = {{0.9, 0.05, 0.05}, {0.05, 0.8, 0.1}, {0.1, 0.1, 0.9}, {0.9, 0.9, 0.85}};
  p.desired.resize(n, 3);
  for (int plate = 0; plate < 2; ++plate) {
    for (int r = 0; r < g; ++r) {
      for (int c = 0; c < g; ++c) {
        const int i = plate * g * g + r * g + c;
        if (c + 1 < g) p.adjacency.push_back({i, i + 1});
        if (r + 1 < g) p.adjacency.push_back({i, i + g});
        const int quadrant = ((c + 0.5) * side < 0.5 ? 0 : 1) + ((r + 0.5) * side < 0.5 ? 0 : 2);
        p.desired.row(i) = colours[(quadrant + plate) % 4].transpose();
      }
    }
  }
  p.lower = Eigen::MatrixX3d::Zero(n, 3);
  p.upper = Eigen::MatrixX3d::Ones(n, 3);
  p.rgb_to_xyz = SrgbToXyzMatrix();
  p.white_xyz = p.rgb_to_xyz * Eigen::Vector3d::Ones();
  p.alpha = 0.5;
  return p;
}

// A test configuration of the builder and which parts of F it gives on the plates.
struct Layout {
  int grid;
  int leaf_size;
  double admissibility;
  bool near, far;  // whether F has near entries, far blocks

  ClusterOptions options() const {
    ClusterOptions o;
    o.leaf_size = leaf_size;
    o.admissibility = admissibility;
    return o;
  }
  std::string label() const {
    std::ostringstream text;
    text << 2 * grid * grid << " patches (leaf " << leaf_size << ", admissibility " << admissibility << ")";
    return text.str();
  }
};
// Both parts; near only (no cluster pair admissible); far only (every leaf pair admissible).
const Layout kBothParts{16, 8, 0.5, true, true};
const Layout kBothPartsLarger{30, 16, 0.3, true, true};
const Layout kNearOnly{16, 32, 0.5, true, false};
const Layout kFarOnly{40, 32, 0.5, false, true};
const Layout kBothPartsDefaultOptions{24, 32, 0.5, true, true};

double MaxRelativeDifference(const Eigen::MatrixXd& value, const Eigen::MatrixXd& truth) {
  return (value - truth).cwiseAbs().maxCoeff() / truth.cwiseAbs().maxCoeff();
}

// Checks that the layout's F has the parts the test means to exercise.
void ExpectParts(const Layout& layout, const CompressedFormFactors& f) {
  EXPECT_EQ(f.near().nonZeros() > 0, layout.near) << layout.label();
  EXPECT_EQ(f.far().size() > 0, layout.far) << layout.label();
}

TEST(CompressedCuda, ProductMatchesTheCpu) {
  SKIP_WITHOUT_CUDA_DEVICE();
  for (const Layout& layout : {kBothParts, kBothPartsLarger, kNearOnly, kFarOnly}) {
    const std::shared_ptr<const CompressedFormFactors> f = CompressedPlates(layout.grid, layout.options());
    ExpectParts(layout, *f);
    const int n = f->size();
    // Four columns: one full group of three and a padded one; the last is 1 (F's row sums).
    Eigen::MatrixXd x = Eigen::MatrixXd::Random(n, 4);
    x.col(3).setOnes();
    const Eigen::MatrixXd truth = f->Multiply(x);
    const double relative = MaxRelativeDifference(CudaCompressedMultiply(*f, x), truth);
    EXPECT_LT(relative, 1e-12) << layout.label();
    std::printf("%-44s near entries %8ld, far blocks %6ld: product relative difference %.1e\n",
                layout.label().c_str(), static_cast<long>(f->near().nonZeros()), static_cast<long>(f->far().size()),
                relative);
  }
}

TEST(CompressedCuda, SolvesMatchTheCpuAndTheEquation) {
  SKIP_WITHOUT_CUDA_DEVICE();
  for (const Layout& layout : {kBothParts, kBothPartsLarger, kFarOnly}) {
    const std::shared_ptr<const CompressedFormFactors> f = CompressedPlates(layout.grid, layout.options());
    ExpectParts(layout, *f);
    const int n = f->size();
    for (const char* variant : {"grey", "coloured", "black patch"}) {
      Eigen::MatrixX3d rho = Eigen::MatrixX3d::Constant(n, 3, 0.9);
      if (std::string(variant) == "coloured") {
        for (int i = 0; i < n; ++i) {
          for (int c = 0; c < 3; ++c) rho(i, c) = 0.3 + 0.6 * ((i * (c + 3)) % 11) / 10.0;
        }
      } else if (std::string(variant) == "black patch") {
        rho.row(5).setZero();  // one patch reflects nothing
        rho(n - 3, 1) = 0.0;   // one channel of another
      }
      const std::string label = layout.label() + " " + variant;
      const CudaCompressedRadiosity gpu(*f, rho, IterativeRadiosityOptions());
      const RadiositySystem cpu(f, rho);
      const Eigen::MatrixX3d emittance = Eigen::MatrixX3d::Random(n, 3).cwiseAbs();
      const Eigen::MatrixX3d y = Eigen::MatrixX3d::Random(n, 3);

      // K b = e: K b = b − rho ∘ (F b) with the CPU's product.
      int64_t gpu_before = gpu.solve_iterations(), cpu_before = cpu.solve_iterations();
      const Eigen::MatrixX3d b = gpu.Solve(emittance, /*transposed=*/false, /*fast=*/false);
      const Eigen::MatrixX3d b_cpu = cpu.Solve(emittance);
      const int64_t gpu_iterations = gpu.solve_iterations() - gpu_before;
      const int64_t cpu_iterations = cpu.solve_iterations() - cpu_before;
      EXPECT_LT(MaxRelativeDifference(b, b_cpu), 1e-9) << label;
      const Eigen::MatrixX3d residual = b - rho.cwiseProduct(f->Multiply(b)) - emittance;
      EXPECT_LT(residual.norm() / emittance.norm(), 1e-9) << label;
      // The same algorithm: the iteration counts may differ only where a channel's residual
      // lands on its goal within rounding.
      EXPECT_LE(std::abs(gpu_iterations - cpu_iterations), 1) << label;

      // Kᵀ x = y: Kᵀ x = x − Fᵀ (rho ∘ x).
      const Eigen::MatrixX3d x = gpu.Solve(y, /*transposed=*/true, /*fast=*/false);
      EXPECT_LT(MaxRelativeDifference(x, cpu.SolveTransposed(y)), 1e-9) << label;
      const Eigen::MatrixX3d residual_transposed = x - f->MultiplyTransposed(rho.cwiseProduct(x)) - y;
      EXPECT_LT(residual_transposed.norm() / y.norm(), 1e-9) << label;

      // The fast solves stop at the looser tolerance (1e-5 on the symmetric system).
      EXPECT_LT(MaxRelativeDifference(gpu.Solve(emittance, false, /*fast=*/true), b_cpu), 1e-3) << label;
      EXPECT_LT(MaxRelativeDifference(gpu.Solve(y, true, /*fast=*/true), cpu.SolveTransposed(y)), 1e-3) << label;

      // Through RadiositySystem, as the solver uses it.
      const RadiositySystem system(f, rho, IterativeRadiosityOptions(),
                                   MakeCudaCompressedRadiosityBackend(*f, rho, IterativeRadiosityOptions()));
      EXPECT_LT(MaxRelativeDifference(system.Solve(emittance), b_cpu), 1e-9) << label;
      EXPECT_EQ(system.factorisations(), std::string(variant) == "grey" ? 1 : 3) << label;
      std::printf("%-56s K b = e: %.1e from the CPU, residual %.1e, %ld CG iterations (CPU %ld)\n", label.c_str(),
                  MaxRelativeDifference(b, b_cpu), residual.norm() / emittance.norm(),
                  static_cast<long>(gpu_iterations), static_cast<long>(cpu_iterations));
    }
  }
}

TEST(CompressedCuda, NonConvergenceThrows) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const std::shared_ptr<const CompressedFormFactors> f = CompressedPlates(kBothParts.grid, kBothParts.options());
  IterativeRadiosityOptions options;
  options.max_iterations = 2;
  const CudaCompressedRadiosity gpu(*f, Eigen::MatrixX3d::Constant(f->size(), 3, 0.9), options);
  try {
    gpu.Solve(Eigen::MatrixX3d::Random(f->size(), 3), false, false);
    ADD_FAILURE() << "2 iterations converged";
  } catch (const std::runtime_error& error) {
    EXPECT_NE(std::string(error.what()).find("GPU"), std::string::npos) << error.what();
  }
}

TEST(CompressedCuda, PerceptualSolveMatchesTheCpu) {
  SKIP_WITHOUT_CUDA_DEVICE();
  struct Case {
    Layout layout;
    bool coloured;
    CompensationMethod method;
  };
  for (const Case& c : {Case{kBothParts, false, CompensationMethod::kPerceptual},
                        Case{kBothParts, true, CompensationMethod::kPerceptual},
                        Case{kBothPartsDefaultOptions, false, CompensationMethod::kPerceptual},
                        Case{kFarOnly, false, CompensationMethod::kPerceptual},
                        Case{kBothPartsLarger, true, CompensationMethod::kLinear}}) {
    CompensationProblem problem = CompressedPlatesProblem(c.layout.grid, c.layout.options());
    ExpectParts(c.layout, *problem.compressed_form_factors);
    if (c.coloured) problem.reflectance.col(2) *= 0.6;
    ASSERT_EQ(problem.Validate(), "");
    ASSERT_EQ(problem.form_factors.size(), 0);
    SolverOptions options;
    options.method = c.method;
    SolverSummary cpu_summary;
    const CompensationSolution cpu = Solve(options, problem, &cpu_summary);
    // Both solutions on one yardstick: the CPU's matrix-free system.
    const RadiositySystem radiosity(problem.compressed_form_factors, problem.reflectance);
    const CompensationObjective objective(
        problem, radiosity, c.method == CompensationMethod::kLinear ? ColourModel::kLinear : ColourModel::kLab);
    const double reference = objective.Value(cpu.emittance);
    EXPECT_GT(((cpu.emittance - problem.lower).array() == 0.0).count(), 0) << c.layout.label() << ": no active bound";
    for (const bool host_loop : {true, false}) {
      const std::string label = c.layout.label() + " " + MethodName(c.method) + (c.coloured ? " coloured" : " grey") +
                                (host_loop ? " [cuda host loop]" : " [cuda resident]");
      options.device = Device::kCuda;
      options.device_host_loop = host_loop;
      SolverSummary gpu_summary;
      const CompensationSolution gpu = Solve(options, problem, &gpu_summary);
      ASSERT_NE(gpu.radiosity_system->backend(), nullptr) << label;
      EXPECT_TRUE(((gpu.emittance - problem.lower).array() >= 0.0).all()) << label;
      EXPECT_TRUE(((problem.upper - gpu.emittance).array() >= 0.0).all()) << label;
      ObjectivePoint point;
      const double cost = objective.Evaluate(gpu.emittance, &point);
      const double relative = std::abs(cost - reference) / reference;
      EXPECT_LT(relative, 1e-6) << label << ": " << gpu_summary.BriefReport();
      const double projected =
          ProjectedGradientNorm(gpu.emittance, objective.Gradient(point), problem.lower, problem.upper);
      EXPECT_LT(projected, 1e-6 * (1.0 + cost)) << label << ": " << gpu_summary.BriefReport();
      if (!host_loop) {
        EXPECT_LT(std::abs(gpu_summary.final_cost - cost), 1e-9 * cost) << label;
      }
      std::printf("%-72s objective %.10g (CPU %.10g, relative %.1e), projected gradient %.1e, %d iterations (CPU %d), "
                  "%d CG (CPU %d), %s\n",
                  label.c_str(), cost, reference, relative, projected, gpu_summary.iterations, cpu_summary.iterations,
                  gpu_summary.cg_iterations, cpu_summary.cg_iterations, TerminationName(gpu_summary.termination));
    }
  }
}

// Median wall time of `repeats` calls, in ms, with the device idle before and after each.
template <typename Call>
double MedianMilliseconds(int repeats, const Call& call) {
  std::vector<double> times;
  for (int run = 0; run < repeats; ++run) {
    cudaDeviceSynchronize();
    const auto start = std::chrono::steady_clock::now();
    call();
    cudaDeviceSynchronize();
    times.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
  }
  std::sort(times.begin(), times.end());
  return times[times.size() / 2];
}

// Markdown rows per grid g (n = 2g² patches): F's build and size, the GPU's product and K⁻¹
// solve (median of PROCAM_BENCH_REPEATS, each including the n×3 copies to and from the device),
// the perceptual solve on the GPU and, up to PROCAM_BENCH_CPU_MAX_VARIABLES variables, the same
// on the CPU's matrix-free path. Objectives are the solvers' own final costs (float64 solves to
// 1e-11). PROCAM_BENCH_LEAF_SIZE and PROCAM_BENCH_ADMISSIBILITY set the builder's options (the
// defaults make every leaf pair of the plates far from g = 40 on: no near part).
// A second table compares the GPU solves: `[cuda host loop]` (device_host_loop: K⁻¹ on the
// device, the loop on the host; the first table's solve) and `[cuda resident]` (the whole loop
// on the device; median of PROCAM_BENCH_SOLVE_REPEATS solves, default 3), with the objective's
// relative difference from the CPU's (where it ran) or else the host loop's.
TEST(CompressedCuda, DISABLED_Timings) {
  SKIP_WITHOUT_CUDA_DEVICE();
  std::string device;
  CudaAvailable(&device);
  std::vector<int> grids;
  for (const double g : testing::ListFromEnvironment<double>("PROCAM_BENCH_COMPRESSED_GRIDS", {40, 120, 224})) {
    grids.push_back(static_cast<int>(g));
  }
  const double cpu_max_variables = testing::ListFromEnvironment<double>("PROCAM_BENCH_CPU_MAX_VARIABLES", {30000})[0];
  const int repeats = static_cast<int>(testing::ListFromEnvironment<double>("PROCAM_BENCH_REPEATS", {5})[0]);
  const int solve_repeats =
      static_cast<int>(testing::ListFromEnvironment<double>("PROCAM_BENCH_SOLVE_REPEATS", {3})[0]);
  struct Comparison {
    int variables, patches;
    const char* name;
    double setup_seconds, solve_seconds, loop_seconds;
    int iterations, cg_iterations;
    double objective;
  };
  std::vector<Comparison> comparisons;
  ClusterOptions cluster_options;
  cluster_options.leaf_size =
      static_cast<int>(testing::ListFromEnvironment<double>("PROCAM_BENCH_LEAF_SIZE", {32})[0]);
  cluster_options.admissibility = testing::ListFromEnvironment<double>("PROCAM_BENCH_ADMISSIBILITY", {0.5})[0];
  std::printf("device: %s; leaf size %d, admissibility %g, rho 0.9, alpha 0.5\n\n"
              "| variables | patches | build s | near entries | far blocks | far values | GPU upload s | GPU product ms | "
              "GPU K⁻¹ solve ms | CG iterations | perceptual solve s (GPU) | iterations | objective | "
              "CPU product ms | CPU K⁻¹ solve ms | CPU CG iterations | perceptual solve s (CPU) | CPU iterations | "
              "CPU objective |\n"
              "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
              device.c_str(), cluster_options.leaf_size, cluster_options.admissibility);
  for (const int g : grids) {
    CompressedBuildSummary build;
    const CompensationProblem problem = CompressedPlatesProblem(g, cluster_options, 0.9, &build);
    const std::shared_ptr<const CompressedFormFactors>& f = problem.compressed_form_factors;
    const int n = problem.size();
    const Eigen::MatrixXd x = Eigen::MatrixXd::Random(n, 3);
    const Eigen::MatrixX3d& emittance = problem.desired;

    std::unique_ptr<CudaCompressedRadiosity> gpu;
    const double upload_ms = MedianMilliseconds(1, [&] {
      gpu = std::make_unique<CudaCompressedRadiosity>(*f, problem.reflectance, IterativeRadiosityOptions());
    });
    gpu->Multiply(x);  // first launches
    const double product_ms = MedianMilliseconds(repeats, [&] { gpu->Multiply(x); });
    gpu->Solve(emittance, false, false);
    const int64_t before = gpu->solve_iterations();
    const double solve_ms = MedianMilliseconds(repeats, [&] { gpu->Solve(emittance, false, false); });
    const double iterations = static_cast<double>(gpu->solve_iterations() - before) / repeats;
    SolverOptions options;
    options.device = Device::kCuda;
    options.device_host_loop = true;
    SolverSummary summary;
    Solve(options, problem, &summary);
    std::printf("| %d | %d | %.3f | %ld | %ld | %ld | %.3f | %.3f | %.2f | %.1f | %.3f | %d | %.10g |", 3 * n, n,
                build.seconds, static_cast<long>(build.near_entries), static_cast<long>(build.far_blocks),
                static_cast<long>(build.far_values), upload_ms / 1000.0, product_ms, solve_ms, iterations,
                summary.solve_seconds, summary.iterations, summary.final_cost);
    if (3 * n <= cpu_max_variables) {
      const RadiositySystem cpu(f, problem.reflectance);
      const double cpu_product_ms = MedianMilliseconds(repeats, [&] { f->Multiply(x); });
      const int64_t cpu_before = cpu.solve_iterations();
      const double cpu_solve_ms = MedianMilliseconds(repeats, [&] { cpu.Solve(emittance); });
      const double cpu_iterations = static_cast<double>(cpu.solve_iterations() - cpu_before) / repeats;
      options.device = Device::kCpu;
      SolverSummary cpu_summary;
      Solve(options, problem, &cpu_summary);
      std::printf(" %.3f | %.2f | %.1f | %.3f | %d | %.10g |\n", cpu_product_ms, cpu_solve_ms, cpu_iterations,
                  cpu_summary.solve_seconds, cpu_summary.iterations, cpu_summary.final_cost);
      comparisons.push_back({3 * n, n, "perceptual (CPU)", cpu_summary.setup_seconds, cpu_summary.solve_seconds,
                             cpu_summary.trace.back().seconds, cpu_summary.iterations, cpu_summary.cg_iterations,
                             cpu_summary.final_cost});
    } else {
      std::printf(" – | – | – | – | – | – |\n");
    }
    std::fflush(stdout);
    for (const bool host_loop : {true, false}) {
      options.device = Device::kCuda;
      options.device_host_loop = host_loop;
      std::vector<double> seconds, loop_seconds;
      SolverSummary gpu_summary = summary;  // the host loop's: the first table's solve
      if (host_loop) {
        seconds.push_back(summary.solve_seconds);
        loop_seconds.push_back(summary.trace.back().seconds);
      }
      for (int run = 0; run < solve_repeats && !host_loop; ++run) {
        Solve(options, problem, &gpu_summary);
        seconds.push_back(gpu_summary.solve_seconds);
        loop_seconds.push_back(gpu_summary.trace.back().seconds);
      }
      std::sort(seconds.begin(), seconds.end());
      std::sort(loop_seconds.begin(), loop_seconds.end());
      comparisons.push_back({3 * n, n, host_loop ? "perceptual [cuda host loop]" : "perceptual [cuda resident]",
                             gpu_summary.setup_seconds, seconds[seconds.size() / 2],
                             loop_seconds[loop_seconds.size() / 2], gpu_summary.iterations,
                             gpu_summary.cg_iterations, gpu_summary.final_cost});
    }
  }
  std::printf("\n| variables | patches | solver | setup s | solve s | loop s | iterations | CG iterations | "
              "objective | relative to reference |\n|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|\n");
  double reference = 0.0;
  int reference_variables = 0;
  for (const Comparison& row : comparisons) {
    if (row.variables != reference_variables) {  // the first row of each size
      reference = row.objective;
      reference_variables = row.variables;
    }
    std::printf("| %d | %d | %s | %.3f | %.4f | %.4f | %d | %d | %.10g | %.1e |\n", row.variables, row.patches,
                row.name, row.setup_seconds, row.solve_seconds, row.loop_seconds, row.iterations, row.cg_iterations,
                row.objective, std::abs(row.objective - reference) / reference);
  }
  std::fflush(stdout);
}

}  // namespace
}  // namespace procam
