// The CUDA device against the CPU reference on analytic problems (analytic_problem.h), in a
// binary that links only procam_compensation: it runs on the device machine, which has the
// CUDA libraries but not Embree, OpenCV or Ceres' dependencies (docs/gpu.md). Skips without a
// device. DISABLED_Timings is the GPU benchmark (scripts/bench_gpu.sh runs it).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "tests/compensation/cuda_skip.h"

#include <filesystem>

#include <cublas_v2.h>
#include <cuda_runtime.h>
#include <nlohmann/json.hpp>

#include "compensation/colour.h"
#include "compensation/cuda_dense.h"
#include "compensation/cuda_radiosity.h"
#include "base/io.h"
#include "compensation/solver.h"
#include "tests/compensation/analytic_problem.h"
#include "tests/compensation/exported_problem.h"

namespace procam {
namespace {

// The summary's records agree with each other (as MinimiseBounded keeps them).
// The trace, one line per outer iteration (printed where a check failed).
void PrintTrace(const char* name, const SolverSummary& summary) {
  std::printf("  %s: %s\n", name, summary.BriefReport().c_str());
  for (const IterationRecord& record : summary.trace) {
    std::printf("    %2d cost %.12g step %.3g free %d CG %d projected gradient %.3g\n", record.iteration, record.cost,
                record.step, record.free_variables, record.cg_iterations, record.projected_gradient);
  }
}

void ExpectConsistentSummary(const SolverSummary& summary, const std::string& label) {
  ASSERT_FALSE(summary.trace.empty()) << label;
  EXPECT_EQ(summary.trace.back().cost, summary.final_cost) << label;
  EXPECT_EQ(summary.trace.front().cost, summary.initial_cost) << label;
  int cg = 0;
  for (const IterationRecord& record : summary.trace) cg += record.cg_iterations;
  EXPECT_EQ(cg, summary.cg_iterations) << label;
  EXPECT_GE(summary.hessian_products, summary.cg_iterations) << label;
  EXPECT_GE(summary.evaluations, summary.iterations + 1) << label;
  EXPECT_LE(summary.final_cost, summary.initial_cost) << label;
}

// Every problem directory under $PROCAM_DEVICE_PROBLEMS (written on the build machine by
// `procam compensate ROOM --export`: Embree's F, the projectors' bounds): solved on the CPU, the
// resident loop (fused below 4096 patches, and with a kernel per step) and the host loop,
// objectives compared; one markdown row each with the solve
// time (GPU: median of 3; scripts/bench_gpu.sh collects the rows into its table).
TEST(SolveCudaExported, ResidentAndHostLoopMatchTheCpuOnRealRooms) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const char* root = std::getenv("PROCAM_DEVICE_PROBLEMS");
  if (root == nullptr) GTEST_SKIP() << "PROCAM_DEVICE_PROBLEMS not set: no exported rooms to solve";
  int solved = 0;
  std::printf("| room | patches | variables | method | solver | solve s | iterations | CG iterations | objective | "
              "relative to the CPU |\n|---|---:|---:|---|---|---:|---:|---:|---:|---:|\n");
  for (const auto& entry : std::filesystem::directory_iterator(root)) {
    if (!std::filesystem::exists(entry.path() / "F.npy")) continue;
    const CompensationProblem p = testing::ReadExportedProblem(entry.path());
    ASSERT_EQ(p.Validate(), "") << entry.path();
    const std::string room = entry.path().filename().string();
    // perceptual2000 both ways: its metric measured per round, and at every iterate (the default,
    // RecommendedSolverOptions: one call of the device loop per Gauss–Newton step).
    using Update = SolverOptions::MetricUpdate;
    const std::pair<CompensationMethod, Update> configurations[] = {
        {CompensationMethod::kPerceptual, Update::kRounds},
        {CompensationMethod::kLinear, Update::kRounds},
        {CompensationMethod::kPerceptual2000, Update::kRounds},
        {CompensationMethod::kPerceptual2000, Update::kEveryIteration}};
    for (const auto& [method, update] : configurations) {
      SolverOptions cpu;
      cpu.method = method;
      cpu.metric_update = update;
      SolverSummary reference;
      const CompensationSolution cpu_solution = Solve(cpu, p, &reference);
      const std::string method_name =
          std::string(MethodName(method)) +
          (method == CompensationMethod::kPerceptual2000
               ? (update == Update::kRounds ? " (rounds)" : " (every iteration)")
               : "");
      const auto row = [&](const char* solver, const SolverSummary& summary, double seconds) {
        std::printf("| %s | %d | %d | %s | %s | %.4f | %d | %d | %.10g | %.1e |\n", room.c_str(),
                    p.size(), 3 * p.size(), method_name.c_str(), solver, seconds,
                    summary.iterations, summary.cg_iterations, summary.final_cost,
                    std::abs(summary.final_cost - reference.final_cost) / reference.final_cost);
      };
      row("CPU", reference, reference.solve_seconds);
      struct Variant {
        bool host_loop, fused;
        const char* name;
      };
      const bool rounds = method == CompensationMethod::kPerceptual2000;
      for (const Variant& v : {Variant{false, true, "cuda resident"}, Variant{false, false, "cuda kernel per step"},
                               Variant{true, false, "cuda host loop"}}) {
        SolverOptions gpu = cpu;
        gpu.device = Device::kCuda;
        gpu.device_host_loop = v.host_loop;
        gpu.device_fused = v.fused;
        SolverSummary summary;
        CompensationSolution solution;
        std::vector<double> seconds;
        for (int run = 0; run < 3; ++run) {
          solution = Solve(gpu, p, &summary);
          seconds.push_back(summary.solve_seconds);
        }
        std::sort(seconds.begin(), seconds.end());
        row(v.name, summary, seconds[1]);
        if (!v.host_loop) {
          // Fused below 4096 patches, unless a black patch sends K⁻¹ down the LU path.
          const bool fusable = p.size() < 4096 && (p.reflectance.array() > 0.0).all();
          EXPECT_EQ(summary.device_fused, v.fused && fusable) << entry.path();
        }
        if (update == Update::kEveryIteration) {
          // Each iterate's metric is measured where the last step landed and the safeguard keeps
          // the best point by the robust objective, so the GPU's rounding can lead it along
          // another path: held to the CPU's robust objective (lower is better), not its path.
          EXPECT_LE(Ciede2000RobustObjective(gpu, p, solution.radiosity),
                    (1.0 + 1e-3) * Ciede2000RobustObjective(cpu, p, cpu_solution.radiosity))
              << entry.path() << " " << method_name;
        } else {
          // perceptual2000's rounds: each round's metric is measured at the last round's result,
          // so the rounding of the GPU's products moves the next round's objective a little.
          const double relative =
              std::abs(summary.final_cost - reference.final_cost) / reference.final_cost;
          EXPECT_LT(relative, rounds ? 1e-4 : 1e-6) << entry.path() << " " << method_name;
        }
        EXPECT_TRUE(((solution.emittance - p.lower).array() >= 0.0).all());
        EXPECT_TRUE(((p.upper - solution.emittance).array() >= 0.0).all());
      }
    }
    ++solved;
  }
  EXPECT_GT(solved, 0) << "no problem directories under " << root;
}

// A random reciprocal room of n patches: areas spread over two decades, exchange areas G
// symmetric and positive, F = A⁻¹G scaled to row sums ≤ 0.9; reflectance in [0.05, 0.95] with
// patch `black` (if ≥ 0) at 0, which sends InverseRadiosity down its LU path.
struct RandomRoom {
  Eigen::MatrixXd form_factors;
  Eigen::VectorXd area, reflectance;
};
RandomRoom MakeRandomRoom(int n, int black, unsigned seed) {
  std::srand(seed);
  RandomRoom room;
  room.area = (Eigen::VectorXd::Random(n).array() + 1.0).unaryExpr([](double u) { return std::pow(10.0, u); });
  Eigen::MatrixXd g = (Eigen::MatrixXd::Random(n, n).array() + 1.0).matrix();
  g = 0.5 * (g + g.transpose()).eval();
  g.diagonal().setZero();
  room.form_factors = room.area.cwiseInverse().asDiagonal() * g;
  const double largest = room.form_factors.rowwise().sum().maxCoeff();
  if (largest > 0.0) room.form_factors *= 0.9 / largest;  // one factor for all: reciprocity holds
  room.reflectance = 0.5 + 0.45 * Eigen::VectorXd::Random(n).array();
  if (black >= 0) room.reflectance[black] = 0.0;
  return room;
}

template <typename T>
struct DeviceBuffer {
  explicit DeviceBuffer(size_t count) : count(count) { EXPECT_EQ(cudaMalloc(&data, count * sizeof(T)), cudaSuccess); }
  ~DeviceBuffer() { cudaFree(data); }
  T* data = nullptr;
  size_t count;
};

// InverseRadiosity::ApplyOnDevice on x in T (float64 or float32), with the output poisoned
// (NaN) first so that an entry not written shows.
template <typename T>
Eigen::MatrixXd DeviceProduct(const cuda::InverseRadiosity& inverse, const Eigen::MatrixXd& x, bool transposed) {
  const Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic> input = x.cast<T>();
  const size_t count = static_cast<size_t>(x.size());
  DeviceBuffer<T> in(count), out(count);
  cudaMemcpy(in.data, input.data(), count * sizeof(T), cudaMemcpyHostToDevice);
  cudaMemset(out.data, 0xff, count * sizeof(T));
  inverse.ApplyOnDevice(in.data, static_cast<int>(x.cols()), transposed, out.data, nullptr);
  Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic> output(x.rows(), x.cols());
  EXPECT_EQ(cudaMemcpy(output.data(), out.data, count * sizeof(T), cudaMemcpyDeviceToHost), cudaSuccess);
  return output.template cast<double>();
}

// InverseRadiosity::ApplyOnDevice (own product kernel, both directions, float64 and float32 with
// the float32 or the float16 copy of K⁻¹, 1–3 columns) against K⁻¹x and K⁻ᵀx solved on the CPU by
// LU of K = I − diag(ρ)F, on rooms whose areas differ (the kernel's K⁻¹x goes through s² = ρ/A)
// and with a black patch (LU path, cuBLAS for K⁻¹x). Sizes not multiples of the block: 1, 37,
// 1000, 4500 patches. Outputs are poisoned with NaN first: every entry must be written.
TEST(SolveCudaAnalytic, DenseProductsOnTheDeviceMatchTheCpu) {
  SKIP_WITHOUT_CUDA_DEVICE();
  for (const int n : {1, 37, 1000, 4500}) {
    for (const int black : {-1, n / 2}) {
      const RandomRoom room = MakeRandomRoom(n, black, 17u + n);
      const Eigen::MatrixXd k =
          Eigen::MatrixXd::Identity(n, n) - room.reflectance.asDiagonal() * room.form_factors;
      const Eigen::PartialPivLU<Eigen::MatrixXd> lu(k);
      const Eigen::PartialPivLU<Eigen::MatrixXd> lu_transposed(k.transpose());
      for (const char* cg_matrix : {"float32", "float16"}) {
        cuda::DenseProductSettings settings;
        settings.half_cg_matrix = std::string(cg_matrix) == "float16";
        const auto inverse = cuda::InverseRadiosity::Create(room.form_factors.data(), room.area.data(),
                                                            room.reflectance.data(), n, settings);
        EXPECT_EQ(inverse->cholesky(), black < 0) << n;
        // float16 entries keep 11 significant bits: each product within 2^-11 of the truth in
        // the worst case (measured ~1e-4; float32 ~1e-7).
        const double single_tolerance = std::string(cg_matrix) == "float16" ? 5e-4 : 1e-5;
        for (const int columns : {1, 3}) {
          const Eigen::MatrixXd x = Eigen::MatrixXd::Random(n, columns);
          for (const bool transposed : {false, true}) {
            const Eigen::MatrixXd truth = transposed ? lu_transposed.solve(x) : lu.solve(x);
            const std::string label = std::to_string(n) + " patches, black " + std::to_string(black) + ", " +
                                      std::to_string(columns) + " columns, transposed " +
                                      std::to_string(transposed) + ", CG matrix " + cg_matrix;
            const Eigen::MatrixXd y = DeviceProduct<double>(*inverse, x, transposed);
            EXPECT_LT((y - truth).norm(), 1e-12 * truth.norm()) << label;
            const double error = (DeviceProduct<float>(*inverse, x, transposed) - truth).norm() / truth.norm();
            EXPECT_LT(error, single_tolerance) << label << " (float32 vectors)";
            if (n == 4500 && columns == 3) std::printf("  %s: float32 vectors, relative error %.1e\n", label.c_str(), error);
          }
        }
      }
    }
  }
}

// Median microseconds of `runs` timed calls of work(run) after `warmup` untimed ones (CUDA
// events on the default stream).
template <typename Work>
double MedianMicroseconds(int warmup, int runs, const Work& work) {
  cudaEvent_t start, stop;
  cudaEventCreate(&start);
  cudaEventCreate(&stop);
  std::vector<float> times;
  for (int run = 0; run < warmup + runs; ++run) {
    cudaEventRecord(start);
    work(run);
    cudaEventRecord(stop);
    cudaEventSynchronize(stop);
    float ms = 0.0f;
    cudaEventElapsedTime(&ms, start, stop);
    if (run >= warmup) times.push_back(ms);
  }
  cudaEventDestroy(start);
  cudaEventDestroy(stop);
  std::sort(times.begin(), times.end());
  return 1e3 * times[times.size() / 2];
}

// Microseconds per K⁻¹ product with three columns (median of 200, CUDA events, inputs rotated
// over 4 buffers): cuBLAS GEMM against TransposedProductKernel with 4 and 8 outputs per block
// (DenseProductSettings::rows), float64, and float32 vectors with the float32 or the float16 copy
// of K⁻¹ (DenseProductSettings::half_cg_matrix); K⁻¹x and K⁻ᵀx. Sizes: PROCAM_BENCH_GRIDS. GB/s:
// the matrix's bytes over the best time.
TEST(SolveCudaAnalytic, DISABLED_ProductTimings) {
  SKIP_WITHOUT_CUDA_DEVICE();
  struct Variant {
    int rows;  // 0: cuBLAS
    const char* cg_matrix;
  };
  const Variant variants[] = {{0, "float32"}, {4, "float32"}, {8, "float32"}, {4, "float16"}, {8, "float16"}};
  std::printf("| patches | vectors | product | cuBLAS µs | 4 rows µs | 8 rows µs | 4 rows, float16 K⁻¹ µs | "
              "8 rows, float16 K⁻¹ µs |\n|---:|---|---|---:|---:|---:|---:|---:|\n");
  for (const int g : testing::ListFromEnvironment<int>("PROCAM_BENCH_GRIDS", {22, 40, 70})) {
    const CompensationProblem p = testing::PlatesProblem(g, 0.5, 0.9);
    const int n = p.size();
    const Eigen::VectorXd rho = p.reflectance.col(0);
    std::vector<std::unique_ptr<cuda::InverseRadiosity>> inverses;
    for (const Variant& variant : variants) {
      cuda::DenseProductSettings settings;
      settings.rows = variant.rows;
      settings.half_cg_matrix = std::string(variant.cg_matrix) == "float16";
      inverses.push_back(
          cuda::InverseRadiosity::Create(p.form_factors.data(), p.area.data(), rho.data(), n, settings));
    }
    const size_t count = 3 * static_cast<size_t>(n);
    const Eigen::VectorXd x = Eigen::VectorXd::Random(4 * count);
    const Eigen::VectorXf xf = x.cast<float>();
    DeviceBuffer<double> dx(4 * count), dy(count);
    DeviceBuffer<float> fx(4 * count), fy(count);
    cudaMemcpy(dx.data, x.data(), x.size() * sizeof(double), cudaMemcpyHostToDevice);
    cudaMemcpy(fx.data, xf.data(), xf.size() * sizeof(float), cudaMemcpyHostToDevice);
    for (const bool single : {true, false}) {
      for (const bool transposed : {false, true}) {
        std::printf("| %d | %s | %s |", n, single ? "float32" : "float64", transposed ? "K⁻ᵀx" : "K⁻¹x");
        for (size_t v = 0; v < inverses.size(); ++v) {
          if (!single && std::string(variants[v].cg_matrix) == "float16") {
            std::printf(" – |");
            continue;
          }
          const double us = MedianMicroseconds(20, 200, [&](int run) {
            const size_t offset = (run % 4) * count;
            if (single) {
              inverses[v]->ApplyOnDevice(fx.data + offset, 3, transposed, fy.data, nullptr);
            } else {
              inverses[v]->ApplyOnDevice(dx.data + offset, 3, transposed, dy.data, nullptr);
            }
          });
          std::printf(" %.1f |", us);
        }
        std::printf("\n");
        std::fflush(stdout);
      }
    }
    ASSERT_EQ(cudaGetLastError(), cudaSuccess);
  }
}

// Microseconds per product of an n×n symmetric matrix with three columns through cuBLAS: GEMM
// against SYMM (which reads one triangle, half the bytes), float64 and float32 (a question for
// the dense backend's storage: K⁻¹ = S M⁻¹ S⁻¹ with M⁻¹ symmetric). Median of 100, CUDA events.
TEST(SolveCudaAnalytic, DISABLED_SymmetricProductTimings) {
  SKIP_WITHOUT_CUDA_DEVICE();
  cublasHandle_t handle;
  ASSERT_EQ(cublasCreate(&handle), CUBLAS_STATUS_SUCCESS);
  std::printf("| n | precision | GEMM µs | SYMM µs |\n|---:|---|---:|---:|\n");
  for (const int n : {968, 3200, 9800}) {
    Eigen::MatrixXd a = Eigen::MatrixXd::Random(n, n);
    a = (0.5 * (a + a.transpose())).eval();
    const Eigen::MatrixXf af = a.cast<float>();
    const Eigen::MatrixXd x = Eigen::MatrixXd::Random(n, 3);
    const Eigen::MatrixXf xf = x.cast<float>();
    const size_t n2 = static_cast<size_t>(n) * n;
    DeviceBuffer<double> da(n2), dx(3 * n), dy(3 * n);
    DeviceBuffer<float> fa(n2), fx(3 * n), fy(3 * n);
    cudaMemcpy(da.data, a.data(), n2 * sizeof(double), cudaMemcpyHostToDevice);
    cudaMemcpy(fa.data, af.data(), n2 * sizeof(float), cudaMemcpyHostToDevice);
    cudaMemcpy(dx.data, x.data(), 3 * n * sizeof(double), cudaMemcpyHostToDevice);
    cudaMemcpy(fx.data, xf.data(), 3 * n * sizeof(float), cudaMemcpyHostToDevice);
    const auto time = [&](const auto& product) { return MedianMicroseconds(20, 100, [&](int) { product(); }); };
    const double one = 1.0, zero = 0.0;
    const float onef = 1.0f, zerof = 0.0f;
    const double dgemm = time([&] {
      cublasDgemm(handle, CUBLAS_OP_N, CUBLAS_OP_N, n, 3, n, &one, da.data, n, dx.data, n, &zero, dy.data, n);
    });
    const double dsymm = time([&] {
      cublasDsymm(handle, CUBLAS_SIDE_LEFT, CUBLAS_FILL_MODE_LOWER, n, 3, &one, da.data, n, dx.data, n, &zero,
                  dy.data, n);
    });
    Eigen::MatrixXd y(n, 3);
    cudaMemcpy(y.data(), dy.data, 3 * n * sizeof(double), cudaMemcpyDeviceToHost);
    EXPECT_LT((y - a * x).norm(), 1e-12 * (a * x).norm());
    const double sgemm = time([&] {
      cublasSgemm(handle, CUBLAS_OP_N, CUBLAS_OP_N, n, 3, n, &onef, fa.data, n, fx.data, n, &zerof, fy.data, n);
    });
    const double ssymm = time([&] {
      cublasSsymm(handle, CUBLAS_SIDE_LEFT, CUBLAS_FILL_MODE_LOWER, n, 3, &onef, fa.data, n, fx.data, n, &zerof,
                  fy.data, n);
    });
    std::printf("| %d | float64 | %.1f | %.1f |\n| %d | float32 | %.1f | %.1f |\n", n, dgemm, dsymm, n, sgemm, ssymm);
    std::fflush(stdout);
  }
  cublasDestroy(handle);
}

TEST(SolveCudaAnalytic, ProductsWithKOnTheDeviceMatchTheCpu) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const CompensationProblem p = testing::PlatesProblem(16, 0.5, 0.9);
  Eigen::MatrixX3d rho = p.reflectance;
  rho.col(1) *= 0.8;
  const RadiositySystem cpu(p.form_factors, p.area, rho);
  const RadiositySystem gpu(p.form_factors, p.area, rho, MakeCudaRadiosityBackend(p.form_factors, p.area, rho, false));
  const Eigen::MatrixX3d x = Eigen::MatrixX3d::Random(p.size(), 3);
  const Eigen::MatrixX3d kx = cpu.Multiply(x), ktx = cpu.MultiplyTransposed(x);
  EXPECT_LT((gpu.Multiply(x) - kx).norm(), 1e-12 * kx.norm());
  EXPECT_LT((gpu.MultiplyTransposed(x) - ktx).norm(), 1e-12 * ktx.norm());
}

TEST(SolveCudaAnalytic, MatchesTheCpuReference) {
  SKIP_WITHOUT_CUDA_DEVICE();
  struct Case {
    int grid;
    double alpha;
    bool coloured;
    CompensationMethod method;
    bool multires;
    int inner_iterations;  // SolverOptions::max_inner_iterations
    bool second_order;
  };
  const Case cases[] = {{8, 0.5, false, CompensationMethod::kPerceptual, false, 1, true},
                        {16, 0.3, false, CompensationMethod::kPerceptual, false, 1, true},
                        {16, 0.5, true, CompensationMethod::kPerceptual, false, 1, true},
                        {22, 0.5, false, CompensationMethod::kPerceptual, true, 1, true},
                        {16, 0.5, false, CompensationMethod::kLinear, false, 1, true},
                        {24, 0.3, true, CompensationMethod::kPerceptual, true, 1, true},
                        {24, 0.3, true, CompensationMethod::kLinear, true, 1, true},
                        {16, 0.5, false, CompensationMethod::kPerceptual, false, 3, true},
                        {16, 0.3, true, CompensationMethod::kPerceptual, false, 1, false},
                        {40, 0.5, false, CompensationMethod::kPerceptual, false, 1, true}};
  for (const Case& c : cases) {
    testing::AnalyticProblem test = testing::MakeAnalyticProblem(c.grid, c.alpha);
    if (c.coloured) {
      test.fine.reflectance.col(2) *= 0.6;
      test.coarse.reflectance.col(2) *= 0.6;
    }
    const CompensationProblem& problem = test.fine;
    const CoarseLevel coarse{&test.coarse, &test.coarse_of_fine};
    SolverOptions options;
    options.method = c.method;
    options.multires = c.multires;
    options.max_inner_iterations = c.inner_iterations;
    options.second_order = c.second_order;
    SolverSummary cpu_summary;
    const CompensationSolution cpu = Solve(options, problem, &cpu_summary, coarse);
    const RadiositySystem radiosity(problem.form_factors, problem.area, problem.reflectance);
    const CompensationObjective objective(
        problem, radiosity, c.method == CompensationMethod::kLinear ? ColourModel::kLinear : ColourModel::kLab);
    const double reference = objective.Value(cpu.emittance);
    EXPECT_GT(((cpu.emittance - problem.lower).array() == 0.0).count(), 0) << "no active bound";
    struct Variant {
      bool host_loop, float32, fused;
      const char* name;
    };
    // The fused loop serves problems below 4096 patches: there the resident loop runs both ways.
    const bool fusable = problem.size() < 4096;
    for (const Variant& v :
         {Variant{true, false, false, "host loop float64"}, Variant{true, true, false, "host loop float32"},
          Variant{false, false, true, fusable ? "resident fused" : "resident"},
          Variant{false, false, false, "resident, kernel per step"}}) {
      if (!v.host_loop && !v.fused && !fusable) continue;  // the row above ran this already
      options.device = Device::kCuda;
      options.device_host_loop = v.host_loop;
      options.device_float32 = v.float32;
      options.device_fused = v.fused;
      SolverSummary summary;
      const CompensationSolution gpu = Solve(options, problem, &summary, coarse);
      std::ostringstream label;
      label << MethodName(c.method) << " " << problem.size() << " patches alpha " << c.alpha
            << (c.coloured ? " coloured" : "") << (c.multires ? " multires" : "")
            << (c.inner_iterations > 1 ? " inner 3" : "") << (c.second_order ? "" : " gauss-newton") << " ["
            << v.name << "]";
      EXPECT_TRUE(((gpu.emittance - problem.lower).array() >= 0.0).all()) << label.str();
      EXPECT_TRUE(((problem.upper - gpu.emittance).array() >= 0.0).all()) << label.str();
      ObjectivePoint point;
      const double cost = objective.Evaluate(gpu.emittance, &point);  // CPU, double
      // The solution's radiosity (from the device's last evaluation on the resident path) is K⁻¹E
      // (the host loop's float32 variant solves with the float32 K⁻¹).
      EXPECT_LT((gpu.radiosity - point.radiosity).norm(), (v.float32 ? 1e-5 : 1e-10) * point.radiosity.norm())
          << label.str();
      const double relative = std::abs(cost - reference) / reference;
      EXPECT_LT(relative, v.host_loop ? 1e-4 : 1e-6) << label.str() << ": " << summary.BriefReport();
      const double projected =
          ProjectedGradientNorm(gpu.emittance, objective.Gradient(point), problem.lower, problem.upper);
      EXPECT_LT(projected, (v.float32 ? 1e-3 : 1e-6) * (1.0 + cost)) << label.str() << ": " << summary.BriefReport();
      if (!v.host_loop) {
        // The solver's own final cost is the objective at its result, evaluated on the device.
        EXPECT_LT(std::abs(summary.final_cost - cost), 1e-9 * cost) << label.str();
        EXPECT_NE(summary.termination, TerminationType::kNumericalFailure) << label.str();
        ExpectConsistentSummary(summary, label.str());
        EXPECT_EQ(summary.device_fused, v.fused && fusable) << label.str();
        if (c.multires) {
          EXPECT_GT(summary.coarse_iterations, 0) << label.str();
        }
      }
      if (::testing::Test::HasFailure() && !v.host_loop) {
        PrintTrace("CPU", cpu_summary);
        PrintTrace("GPU", summary);
      }
      std::printf("%-62s objective %.10g (CPU %.10g, relative %.1e), projected gradient %.1e, %d iterations "
                  "(CPU %d), %d CG (CPU %d), %s, solve %.4f s (CPU %.4f s)\n",
                  label.str().c_str(), cost, reference, relative, projected, summary.iterations,
                  cpu_summary.iterations, summary.cg_iterations, cpu_summary.cg_iterations,
                  TerminationName(summary.termination), summary.solve_seconds, cpu_summary.solve_seconds);
    }
  }
}

// The resident loop stops where MinimiseBounded does on its other rules: at max_iterations, and
// at once when the start is already optimal (the closed form E = K·Bd inside the bounds).
TEST(SolveCudaAnalytic, ResidentStoppingRules) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const testing::AnalyticProblem test = testing::MakeAnalyticProblem(12, 0.5);
  for (const bool fused : {true, false}) {
    SCOPED_TRACE(fused ? "fused" : "kernel per step");
    SolverOptions options;
    options.device = Device::kCuda;
    options.device_fused = fused;
    options.max_iterations = 2;
    // The progress callback gets every iteration once, in order, as the trace records it (the
    // fused loop calls it after its kernel).
    std::vector<std::pair<int, double>> progress;
    options.progress = [&](int iteration, double cost, double) { progress.emplace_back(iteration, cost); };
    SolverSummary summary;
    Solve(options, test.fine, &summary);
    EXPECT_EQ(summary.device_fused, fused);
    EXPECT_EQ(summary.termination, TerminationType::kMaxIterations) << summary.BriefReport();
    EXPECT_EQ(summary.iterations, 2);
    ASSERT_EQ(summary.trace.size(), 3u);
    ASSERT_EQ(progress.size(), 2u);
    for (int k = 0; k < 2; ++k) {
      EXPECT_EQ(progress[k].first, k + 1);
      EXPECT_EQ(progress[k].second, summary.trace[k + 1].cost);
    }

    // Desired colours every patch can reach: the reverse-radiosity start is the optimum (f = 0).
    CompensationProblem reachable = test.fine;
    reachable.desired.setConstant(0.2);
    reachable.upper.setConstant(10.0);
    options.max_iterations = 100;
    Solve(options, reachable, &summary);
    EXPECT_LT(summary.final_cost, 1e-12) << summary.BriefReport();
    EXPECT_NE(summary.termination, TerminationType::kNumericalFailure) << summary.BriefReport();

    // A desired colour at the largest double: its XYZ overflows, so the objective is infinite at
    // the start; the loop stops at once with a numerical failure and returns its (finite) start.
    CompensationProblem broken = test.fine;
    broken.desired.row(0).setConstant(std::numeric_limits<double>::max());
    const CompensationSolution solution = Solve(options, broken, &summary);
    EXPECT_EQ(summary.termination, TerminationType::kNumericalFailure) << summary.BriefReport();
    EXPECT_EQ(summary.iterations, 0);
    EXPECT_TRUE(solution.emittance.allFinite());
  }
}

// Where the device cannot hold the fused loop's grid at once (another context holding
// multiprocessors, or SolverOptions::device_fused_blocks past what fits, as here), the cooperative
// launch fails and the loop with a kernel per step solves the problem instead: same result as the
// CPU, device_fused false.
TEST(SolveCudaAnalytic, FusedLoopFallsBackWhereItsGridDoesNotFit) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const testing::AnalyticProblem test = testing::MakeAnalyticProblem(16, 0.5);
  SolverOptions options;
  SolverSummary cpu_summary, summary;
  Solve(options, test.fine, &cpu_summary);
  options.device = Device::kCuda;
  options.device_fused_blocks = 100000;  // no device holds this many blocks at once
  Solve(options, test.fine, &summary);
  EXPECT_FALSE(summary.device_fused) << summary.BriefReport();
  EXPECT_LT(std::abs(summary.final_cost - cpu_summary.final_cost), 1e-6 * cpu_summary.final_cost)
      << summary.BriefReport();
}

// Solves from two threads at once (each resident solve takes a device workspace of its own from
// a pool) give exactly what the same solves give one at a time: the fused loop, the loop with a
// kernel per step, and the two at once, on two problems; the reductions are deterministic, so the
// results must be equal to the last bit.
TEST(SolveCudaAnalytic, SolvesFromTwoThreadsAtOnceMatchOneAtATime) {
  SKIP_WITHOUT_CUDA_DEVICE();
  const testing::AnalyticProblem problems[2] = {testing::MakeAnalyticProblem(16, 0.5),
                                                testing::MakeAnalyticProblem(22, 0.3)};
  for (const bool fused_first : {true, false}) {
    for (const bool fused_second : {true, false}) {
      SCOPED_TRACE(std::string(fused_first ? "fused" : "kernel per step") + " and " +
                   (fused_second ? "fused" : "kernel per step"));
      SolverOptions options[2];
      options[0].device = options[1].device = Device::kCuda;
      options[0].device_fused = fused_first;
      options[1].device_fused = fused_second;
      SolverSummary alone[2], together[2];
      CompensationSolution alone_solution[2], together_solution[2];
      for (int k = 0; k < 2; ++k) alone_solution[k] = Solve(options[k], problems[k].fine, &alone[k]);
      // Several rounds, so that the two loops overlap on the device at least once.
      for (int round = 0; round < 3; ++round) {
        std::exception_ptr failure[2];
        std::vector<std::thread> threads;
        for (int k = 0; k < 2; ++k) {
          threads.emplace_back([&, k] {
            try {
              together_solution[k] = Solve(options[k], problems[k].fine, &together[k]);
            } catch (...) {
              failure[k] = std::current_exception();
            }
          });
        }
        for (std::thread& thread : threads) thread.join();
        for (int k = 0; k < 2; ++k) {
          ASSERT_FALSE(failure[k]) << "solve " << k << " threw";
          EXPECT_EQ(together[k].device_fused, alone[k].device_fused) << k;
          EXPECT_EQ(together[k].final_cost, alone[k].final_cost) << k << ": " << together[k].BriefReport();
          EXPECT_EQ(together[k].iterations, alone[k].iterations) << k;
          EXPECT_EQ(together[k].cg_iterations, alone[k].cg_iterations) << k;
          EXPECT_EQ(together[k].termination, alone[k].termination) << k;
          EXPECT_TRUE(together_solution[k].emittance == alone_solution[k].emittance) << k;
          EXPECT_TRUE(together_solution[k].radiosity == alone_solution[k].radiosity) << k;
        }
      }
    }
  }
}

// Markdown rows: variables, patches, solver, setup s, solve s (median of `repeats`), loop s (the
// fine level's Alg. 1 alone: the trace's last time; solve s adds the reverse-radiosity start K·Bd
// on the CPU, the objective's set-up, the coarse level and the final B = K⁻¹E), iterations,
// CG iterations, objective (evaluated in double), and its relative difference from the
// reference (the CPU row where the problem fits the CPU, else the host-loop GPU row of the same
// method). `[cuda host loop]`: SolverOptions::device_host_loop (K⁻¹ on the device, the rest on the
// host); `[cuda resident]`: the whole loop on the device (cuda_solver.h).
TEST(SolveCudaAnalytic, DISABLED_Timings) {
  SKIP_WITHOUT_CUDA_DEVICE();
  std::string device;
  CudaAvailable(&device);
  const std::vector<int> grids = testing::ListFromEnvironment<int>("PROCAM_BENCH_GRIDS", {22, 40, 70});
  const int cpu_max_variables = testing::ListFromEnvironment<int>("PROCAM_BENCH_CPU_MAX_VARIABLES", {10000})[0];
  const int repeats = testing::ListFromEnvironment<int>("PROCAM_BENCH_REPEATS", {5})[0];
  std::printf("device: %s\n\n| variables | patches | solver | setup s | solve s | loop s | iterations | "
              "CG iterations | objective | relative to reference |\n"
              "|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|\n",
              device.c_str());
  for (const int g : grids) {
    const testing::AnalyticProblem test = testing::MakeAnalyticProblem(g);
    const CoarseLevel coarse{&test.coarse, &test.coarse_of_fine};
    const int n = test.fine.size();
    struct Row {
      const char* name;
      Device device;
      bool multires, float32, host_loop;
      CompensationMethod method;
      bool fused = true;
    };
    constexpr auto kPerceptual = CompensationMethod::kPerceptual;
    constexpr auto kLinear = CompensationMethod::kLinear;
    constexpr auto k2000 = CompensationMethod::kPerceptual2000;
    const Row rows[] = {{"perceptual (CPU)", Device::kCpu, false, false, false, kPerceptual},
                        {"perceptual --multires (CPU)", Device::kCpu, true, false, false, kPerceptual},
                        {"linear (CPU)", Device::kCpu, false, false, false, kLinear},
                        {"perceptual [cuda host loop]", Device::kCuda, false, false, true, kPerceptual},
                        {"perceptual --multires [cuda host loop]", Device::kCuda, true, false, true, kPerceptual},
                        {"perceptual --multires [cuda host loop float32]", Device::kCuda, true, true, true,
                         kPerceptual},
                        {"linear [cuda host loop]", Device::kCuda, false, false, true, kLinear},
                        {"perceptual [cuda resident]", Device::kCuda, false, false, false, kPerceptual},
                        {"perceptual [cuda resident, kernel per step]", Device::kCuda, false, false, false,
                         kPerceptual, false},
                        {"perceptual --multires [cuda resident]", Device::kCuda, true, false, false, kPerceptual},
                        {"linear [cuda resident]", Device::kCuda, false, false, false, kLinear},
                        {"perceptual2000 (CPU)", Device::kCpu, false, false, false, k2000},
                        {"perceptual2000 [cuda host loop]", Device::kCuda, false, false, true, k2000},
                        {"perceptual2000 [cuda resident]", Device::kCuda, false, false, false, k2000},
                        {"perceptual2000 --multires [cuda resident]", Device::kCuda, true, false, false, k2000}};
    double reference[3] = {0.0, 0.0, 0.0};  // perceptual, linear, perceptual2000: the first row's
    // Same yardstick for every row: the objective in double, with the float64 K⁻¹ formed on the
    // device (a CPU factorisation of the largest sizes would take minutes).
    const RadiositySystem yardstick(
        test.fine.form_factors, test.fine.area, test.fine.reflectance,
        MakeCudaRadiosityBackend(test.fine.form_factors, test.fine.area, test.fine.reflectance, /*float32=*/false));
    for (const Row& row : rows) {
      if (row.device == Device::kCpu && 3 * n > cpu_max_variables) continue;
      SolverOptions options;
      options.method = row.method;
      options.device = row.device;
      options.multires = row.multires;
      options.device_float32 = row.float32;
      options.device_host_loop = row.host_loop;
      options.device_fused = row.fused;
      // PROCAM_BENCH_ROUND_TOLERANCE: perceptual2000's metric_round_tolerance (CPU and GPU rows).
      if (const char* tolerance = std::getenv("PROCAM_BENCH_ROUND_TOLERANCE")) {
        options.metric_round_tolerance = std::atof(tolerance);
      }
      // PROCAM_BENCH_CG_TOLERANCE: the inexact-Newton forcing term of the GPU rows, to compare.
      if (const char* tolerance = std::getenv("PROCAM_BENCH_CG_TOLERANCE"); tolerance && row.device == Device::kCuda) {
        options.cg_tolerance = std::atof(tolerance);
      }
      const int runs = row.device == Device::kCuda ? repeats : 1;
      std::vector<double> solve_seconds, loop_seconds;
      SolverSummary summary;
      CompensationSolution solution;
      for (int run = 0; run < runs; ++run) {
        solution = Solve(options, test.fine, &summary, coarse);
        solve_seconds.push_back(summary.solve_seconds);
        loop_seconds.push_back(summary.trace.back().seconds);
      }
      std::sort(solve_seconds.begin(), solve_seconds.end());
      std::sort(loop_seconds.begin(), loop_seconds.end());
      // perceptual2000: its last round's objective (the metric the solution minimises).
      const CompensationObjective objective(test.fine, yardstick,
                                            row.method == kLinear ? ColourModel::kLinear : ColourModel::kLab,
                                            row.method == k2000 ? solution.metric : ColourMetric());
      const double value = objective.Value(solution.emittance);
      double& first = reference[row.method == kLinear ? 1 : row.method == k2000 ? 2 : 0];
      if (first == 0.0) first = value;
      std::printf("| %d | %d | %s | %.4f | %.4f | %.4f | %d | %d | %.10g | %.1e |\n", 3 * n, n, row.name,
                  summary.setup_seconds, solve_seconds[solve_seconds.size() / 2],
                  loop_seconds[loop_seconds.size() / 2], summary.iterations, summary.cg_iterations, value,
                  std::abs(value - first) / first);
      std::fflush(stdout);
    }
  }
}

}  // namespace
}  // namespace procam
