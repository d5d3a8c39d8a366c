// The CUDA device against the CPU reference on analytic problems (analytic_problem.h), in a
// binary that links only procam_compensation: it runs on the device machine, which has the
// CUDA libraries but not Embree, OpenCV or Ceres' dependencies (docs/gpu.md). Skips without a
// device. DISABLED_Timings is the GPU benchmark (scripts/bench_gpu.sh runs it).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "compensation/solver.h"
#include "tests/compensation/analytic_problem.h"

namespace procam {
namespace {

#define SKIP_WITHOUT_CUDA_DEVICE()                                                      \
  do {                                                                                  \
    std::string why;                                                                    \
    if (!CudaAvailable(&why)) GTEST_SKIP() << "no CUDA device: skipped (" << why << ")"; \
  } while (0)

TEST(SolveCudaAnalytic, MatchesTheCpuReference) {
  SKIP_WITHOUT_CUDA_DEVICE();
  struct Case {
    int grid;
    double alpha;
    bool coloured;
    CompensationMethod method;
    bool multires;
  };
  const Case cases[] = {{8, 0.5, false, CompensationMethod::kPerceptual, false},
                        {16, 0.3, false, CompensationMethod::kPerceptual, false},
                        {16, 0.5, true, CompensationMethod::kPerceptual, false},
                        {22, 0.5, false, CompensationMethod::kPerceptual, true},
                        {16, 0.5, false, CompensationMethod::kLinear, false}};
  for (const Case& c : cases) {
    testing::AnalyticProblem test = testing::MakeAnalyticProblem(c.grid, c.alpha);
    if (c.coloured) test.fine.reflectance.col(2) *= 0.6;
    const CompensationProblem& problem = test.fine;
    const CoarseLevel coarse{&test.coarse, &test.coarse_of_fine};
    SolverOptions options;
    options.method = c.method;
    options.multires = c.multires;
    SolverSummary cpu_summary;
    const CompensationSolution cpu = Solve(options, problem, &cpu_summary, coarse);
    const RadiositySystem radiosity(problem.form_factors, problem.area, problem.reflectance);
    const CompensationObjective objective(
        problem, radiosity, c.method == CompensationMethod::kLinear ? ColourModel::kLinear : ColourModel::kLab);
    const double reference = objective.Value(cpu.emittance);
    EXPECT_GT(((cpu.emittance - problem.lower).array() == 0.0).count(), 0) << "no active bound";
    for (const bool float32 : {false, true}) {
      options.device = Device::kCuda;
      options.device_float32 = float32;
      SolverSummary summary;
      const CompensationSolution gpu = Solve(options, problem, &summary, coarse);
      std::ostringstream label;
      label << MethodName(c.method) << " " << problem.size() << " patches alpha " << c.alpha
            << (c.coloured ? " coloured" : "") << (c.multires ? " multires" : "") << (float32 ? " float32" : " float64");
      EXPECT_TRUE(((gpu.emittance - problem.lower).array() >= 0.0).all()) << label.str();
      EXPECT_TRUE(((problem.upper - gpu.emittance).array() >= 0.0).all()) << label.str();
      ObjectivePoint point;
      const double cost = objective.Evaluate(gpu.emittance, &point);  // CPU, double
      const double relative = std::abs(cost - reference) / reference;
      EXPECT_LT(relative, 1e-4) << label.str() << ": " << summary.BriefReport();
      const double projected =
          ProjectedGradientNorm(gpu.emittance, objective.Gradient(point), problem.lower, problem.upper);
      EXPECT_LT(projected, (float32 ? 1e-3 : 1e-6) * (1.0 + cost)) << label.str() << ": " << summary.BriefReport();
      std::printf("%-48s objective %.10g (CPU %.10g, relative %.1e), projected gradient %.1e, %d iterations "
                  "(CPU %d), %s\n", label.str().c_str(), cost, reference, relative, projected, summary.iterations,
                  cpu_summary.iterations, TerminationName(summary.termination));
    }
  }
}

std::vector<int> IntegersFromEnvironment(const char* name, std::vector<int> fallback) {
  const char* text = std::getenv(name);
  if (text == nullptr) return fallback;
  std::vector<int> values;
  std::stringstream stream(text);
  for (std::string item; std::getline(stream, item, ',');) values.push_back(std::stoi(item));
  return values;
}

// Markdown rows: variables, patches, solver, setup s, solve s (median of `repeats`), iterations,
// objective (CPU-evaluated where the problem fits the CPU, else the solver's own).
TEST(SolveCudaAnalytic, DISABLED_Timings) {
  SKIP_WITHOUT_CUDA_DEVICE();
  std::string device;
  CudaAvailable(&device);
  const std::vector<int> grids = IntegersFromEnvironment("PROCAM_BENCH_GRIDS", {22, 40, 70});
  const int cpu_max_variables = IntegersFromEnvironment("PROCAM_BENCH_CPU_MAX_VARIABLES", {10000})[0];
  const int repeats = IntegersFromEnvironment("PROCAM_BENCH_REPEATS", {5})[0];
  std::printf("device: %s\n\n| variables | patches | solver | setup s | solve s | iterations | objective |\n"
              "|---:|---:|---|---:|---:|---:|---:|\n", device.c_str());
  for (const int g : grids) {
    const testing::AnalyticProblem test = testing::MakeAnalyticProblem(g);
    const CoarseLevel coarse{&test.coarse, &test.coarse_of_fine};
    const int n = test.fine.size();
    struct Row {
      const char* name;
      Device device;
      bool multires, float32;
      CompensationMethod method;
    };
    const Row rows[] = {{"perceptual (CPU)", Device::kCpu, false, false, CompensationMethod::kPerceptual},
                        {"perceptual --multires (CPU)", Device::kCpu, true, false, CompensationMethod::kPerceptual},
                        {"linear (CPU)", Device::kCpu, false, false, CompensationMethod::kLinear},
                        {"perceptual [cuda]", Device::kCuda, false, false, CompensationMethod::kPerceptual},
                        {"perceptual --multires [cuda]", Device::kCuda, true, false, CompensationMethod::kPerceptual},
                        {"perceptual --multires [cuda float32]", Device::kCuda, true, true,
                         CompensationMethod::kPerceptual},
                        {"linear [cuda]", Device::kCuda, false, false, CompensationMethod::kLinear}};
    for (const Row& row : rows) {
      if (row.device == Device::kCpu && 3 * n > cpu_max_variables) continue;
      SolverOptions options;
      options.method = row.method;
      options.device = row.device;
      options.multires = row.multires;
      options.device_float32 = row.float32;
      const int runs = row.device == Device::kCuda ? repeats : 1;
      std::vector<double> solve_seconds;
      SolverSummary summary;
      CompensationSolution solution;
      for (int run = 0; run < runs; ++run) {
        solution = Solve(options, test.fine, &summary, coarse);
        solve_seconds.push_back(summary.solve_seconds);
      }
      std::sort(solve_seconds.begin(), solve_seconds.end());
      double objective = summary.final_cost;
      if (row.method == CompensationMethod::kPerceptual) {  // same yardstick for every row: double
        const CompensationObjective lab(test.fine, *solution.radiosity_system, ColourModel::kLab);
        objective = lab.Value(solution.emittance);
      }
      std::printf("| %d | %d | %s | %.4f | %.4f | %d | %.10g |\n", 3 * n, n, row.name, summary.setup_seconds,
                  solve_seconds[solve_seconds.size() / 2], summary.iterations, objective);
      std::fflush(stdout);
    }
  }
}

}  // namespace
}  // namespace procam
