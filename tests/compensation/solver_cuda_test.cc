// The CUDA device of the solver (SolverOptions::device = kCuda) against the CPU reference.
// Tests that need a GPU skip with "no CUDA device: skipped" where there is none (CI); the one
// that checks the error without a device runs everywhere else.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "tests/compensation/cuda_skip.h"

#include "compensation/solver.h"
#include "datasets_synthetic/rooms.h"
#include "geometry/form_factors.h"
#include "base/io.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

struct TestProblem {
  PatchHierarchy patches;
  CompensationProblem fine, coarse;
};

// A box room with an occluder and saturated desired colours (bounds [0, 1] bite), as in
// solver_test.cc; `variant` 1 colours the reflectance (three K⁻¹), 2 adds a black patch (LU).
TestProblem MakeTestProblem(int target_patches, double alpha, int variant = 0) {
  TestProblem test;
  SubdividedRoom room = MakeSubdividedBoxRoom(target_patches);
  const Scene& scene = room.scene;
  test.patches = std::move(room.patches);
  Eigen::MatrixXd f = ComputeFormFactors(scene, test.patches.fine, FormFactorOptions(), nullptr);
  const Eigen::MatrixXd coarse_f = AggregateFormFactors(f, test.patches.fine.Areas(), test.patches.coarse_of_fine,
                                                        test.patches.coarse.size());
  test.fine = MakeProblem(scene, test.patches.fine, std::move(f), alpha);
  test.coarse = MakeProblem(scene, test.patches.coarse, coarse_f, alpha);
  if (variant >= 1) test.fine.reflectance.col(1) *= 0.7;
  if (variant == 2) test.fine.reflectance(5, 2) = 0.0;
  return test;
}

TEST(SolveCuda, WithoutADeviceFailsWithOneLine) {
  std::string why;
  if (CudaAvailable(&why)) GTEST_SKIP() << "a CUDA device is present (" << why << "): the error path is not reachable";
  const TestProblem test = MakeTestProblem(60, 0.5);
  SolverOptions options;
  options.device = Device::kCuda;
  SolverSummary summary;
  try {
    Solve(options, test.fine, &summary);
    FAIL() << "Solve with Device::kCuda and no device did not throw";
  } catch (const std::runtime_error& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("cuda"), std::string::npos) << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
  }
}

TEST(RadiosityCuda, SolvesMatchTheCpuFactorsForGreyColouredAndBlackPatches) {
  SKIP_WITHOUT_CUDA_DEVICE();
  for (int variant = 0; variant < 3; ++variant) {
    const TestProblem test = MakeTestProblem(200, 0.5, variant);
    const CompensationProblem& p = test.fine;
    SolverOptions options;
    const RadiositySystem cpu(p.form_factors, p.area, p.reflectance);
    SolverSummary summary;
    options.device = Device::kCuda;
    options.method = CompensationMethod::kNaive;  // only to get the device's RadiositySystem
    const CompensationSolution solution = Solve(options, p, &summary);
    const RadiositySystem& gpu = *solution.radiosity_system;
    ASSERT_NE(gpu.backend(), nullptr);
    EXPECT_EQ(gpu.factorisations(), cpu.factorisations()) << "variant " << variant;
    const Eigen::MatrixX3d e = Eigen::MatrixX3d::Random(p.size(), 3);
    const Eigen::MatrixX3d b = cpu.Solve(e), x = cpu.SolveTransposed(e);
    EXPECT_LT((gpu.Solve(e) - b).norm(), 1e-12 * b.norm()) << "variant " << variant;
    EXPECT_LT((gpu.SolveTransposed(e) - x).norm(), 1e-12 * x.norm()) << "variant " << variant;
    // float32 K⁻¹: rounding of K⁻¹ and of the products, cond(K) ≤ 19.
    EXPECT_LT((gpu.SolveFast(e) - b).norm(), 1e-5 * b.norm()) << "variant " << variant;
    EXPECT_LT((gpu.SolveTransposedFast(e) - x).norm(), 1e-5 * x.norm()) << "variant " << variant;
    // K (K⁻¹ e) = e closes the loop independently of the CPU factors.
    EXPECT_LT(testing::MaxAbsDifference(gpu.Multiply(gpu.Solve(e)), e), 1e-12) << "variant " << variant;
  }
}

struct Case {
  const char* name;
  int patches;
  double alpha;
  int variant;
  CompensationMethod method;
  bool multires;
};

const Case kCases[] = {
    {"perceptual 60", 60, 0.5, 0, CompensationMethod::kPerceptual, false},
    {"perceptual 200 alpha 0.3", 200, 0.3, 0, CompensationMethod::kPerceptual, false},
    {"perceptual 200 coloured", 200, 0.5, 1, CompensationMethod::kPerceptual, false},
    {"perceptual 200 black patch", 200, 0.5, 2, CompensationMethod::kPerceptual, false},
    {"perceptual 1000 multires", 1000, 0.5, 0, CompensationMethod::kPerceptual, true},
    {"linear 200", 200, 0.5, 0, CompensationMethod::kLinear, false},
    {"linear 1000", 1000, 0.5, 0, CompensationMethod::kLinear, false},
};

// The GPU solve reaches the CPU reference's objective within 1e-4 relative (float64 and float32
// objective evaluations), stays within the bounds and is first-order optimal by the CPU's own
// double-precision gradient.
TEST(SolveCuda, MatchesTheCpuReferenceOnEveryTestProblem) {
  SKIP_WITHOUT_CUDA_DEVICE();
  for (const Case& c : kCases) {
    const TestProblem test = MakeTestProblem(c.patches, c.alpha, c.variant);
    const CompensationProblem& problem = test.fine;
    const CoarseLevel coarse{&test.coarse, &test.patches.coarse_of_fine};
    SolverOptions options;
    options.method = c.method;
    options.multires = c.multires;
    SolverSummary cpu_summary;
    const CompensationSolution cpu = Solve(options, problem, &cpu_summary, coarse);
    const RadiositySystem radiosity(problem.form_factors, problem.area, problem.reflectance);
    const CompensationObjective objective(
        problem, radiosity, c.method == CompensationMethod::kLinear ? ColourModel::kLinear : ColourModel::kLab);
    const double reference = objective.Value(cpu.emittance);
    for (const bool float32 : {false, true}) {
      options.device = Device::kCuda;
      options.device_float32 = float32;
      SolverSummary summary;
      const CompensationSolution gpu = Solve(options, problem, &summary, coarse);
      const std::string label = std::string(c.name) + (float32 ? " float32" : " float64") + ": " + summary.BriefReport();
      EXPECT_TRUE(((gpu.emittance - problem.lower).array() >= 0.0).all()) << label;
      EXPECT_TRUE(((problem.upper - gpu.emittance).array() >= 0.0).all()) << label;
      ObjectivePoint point;
      const double cost = objective.Evaluate(gpu.emittance, &point);  // on the CPU, in double
      const double relative = std::abs(cost - reference) / reference;
      EXPECT_LT(relative, 1e-4) << label;
      const double projected =
          ProjectedGradientNorm(gpu.emittance, objective.Gradient(point), problem.lower, problem.upper);
      EXPECT_LT(projected, (float32 ? 1e-3 : 1e-6) * (1.0 + cost)) << label;
      std::printf("%-28s %s: objective %.10g (CPU %.10g, relative %.1e), projected gradient %.1e, %d iterations, "
                  "CPU %d\n", c.name, float32 ? "float32" : "float64", cost, reference, relative, projected,
                  summary.iterations, cpu_summary.iterations);
    }
  }
}

// This binary needs Embree and OpenCV, which the device machine lacks. With
// PROCAM_EXPORT_TEST_PROBLEMS=DIR it writes the fine level of every problem above (one per room
// variant and α, as `procam compensate --export` would) under DIR/test_*; carried to the device
// machine, solver_cuda_device_test's SolveCudaExported solves them there on the CPU and the GPU
// (perceptual and linear, without the coarse level). Checks what was written reads back.
TEST(SolveCuda, ExportsItsProblemsForTheDeviceMachine) {
  const char* root = std::getenv("PROCAM_EXPORT_TEST_PROBLEMS");
  if (root == nullptr) GTEST_SKIP() << "PROCAM_EXPORT_TEST_PROBLEMS not set: nothing to export";
  std::set<std::string> written;
  for (const Case& c : kCases) {
    const std::string name = "test_" + std::to_string(c.patches) + "_alpha_" + std::to_string(c.alpha).substr(0, 3) +
                             "_variant_" + std::to_string(c.variant);
    if (!written.insert(name).second) continue;  // perceptual and linear share a problem
    const TestProblem test = MakeTestProblem(c.patches, c.alpha, c.variant);
    const std::filesystem::path directory = std::filesystem::path(root) / name;
    ExportProblem(test.fine, test.patches.fine, test.patches.coarse_of_fine, directory,
                  R"({"source": "tests/compensation/solver_cuda_test.cc"})");
    const NpyArray f = ReadNpy(directory / "F.npy"), rho = ReadNpy(directory / "rho.npy");
    ASSERT_EQ(f.shape, (std::vector<int64_t>{test.fine.size(), test.fine.size()})) << name;
    EXPECT_EQ(f.values[1], test.fine.form_factors(0, 1)) << name;  // C order: row 0, column 1
    EXPECT_EQ(rho.values[3 * 5 + 2], test.fine.reflectance(5, 2)) << name;  // the black patch of variant 2
    std::printf("wrote %s (%d patches)\n", directory.c_str(), test.fine.size());
  }
}

TEST(Devices, NamesRoundTrip) {
  for (const Device device : {Device::kCpu, Device::kCuda}) {
    Device parsed = Device::kCpu;
    ASSERT_TRUE(ParseDevice(DeviceName(device), &parsed));
    EXPECT_EQ(parsed, device);
  }
  Device parsed;
  EXPECT_FALSE(ParseDevice("gpu", &parsed));
}

}  // namespace
}  // namespace procam
