// The lowest mean ΔE bound of procam evaluate (datasets_synthetic/evaluation.h).
#include "datasets_synthetic/evaluation.h"

#include <cstdio>
#include <filesystem>

#include <gtest/gtest.h>

#include "compensation/objective.h"
#include "compensation/solver.h"
#include "datasets_synthetic/rooms.h"
#include "datasets_synthetic/scene_files.h"
#include "datasets_synthetic/simulated_rig.h"
#include "tests/testing/testing.h"
#include "geometry/form_factors.h"

namespace procam {
namespace {

CompensationProblem BoxProblem() {
  BoxRoomOptions room;
  room.target_patches = 150;
  const Scene scene = MakeBoxRoom(room);
  SubdivisionOptions subdivision;
  subdivision.target_patches = room.target_patches;
  const PatchHierarchy patches = SubdividePatches(scene, subdivision);
  return MakeProblem(scene, patches.fine, ComputeFormFactors(scene, patches.fine, FormFactorOptions(), nullptr), 0.5);
}

// Area-weighted mean ΔE76 per patch of `method`'s solution, and the per-patch values; the mean
// CIEDE2000 in `mean2000` when given.
double MeanDeltaE(const CompensationProblem& problem, CompensationMethod method, Eigen::VectorXd* delta_e76,
                  double* mean2000 = nullptr) {
  SolverOptions options;
  options.method = method;
  SolverSummary summary;
  const CompensationSolution solution = Solve(options, problem, &summary);
  const CompensationObjective lab(problem, *solution.radiosity_system, ColourModel::kLab);
  Eigen::VectorXd delta_e2000;
  lab.DeltaE(solution.radiosity, delta_e76, &delta_e2000);
  if (mean2000 != nullptr) *mean2000 = problem.area.dot(delta_e2000) / problem.area.sum();
  return problem.area.dot(*delta_e76) / problem.area.sum();
}

TEST(LowestMeanDeltaE, IsZeroWhenTheDesiredAppearanceIsReachable) {
  CompensationProblem problem = BoxProblem();
  problem.lower.setConstant(-10.0);  // E = K Bd fits: every method reaches ΔE 0
  problem.upper.setConstant(10.0);
  Eigen::VectorXd delta;
  MeanDeltaE(problem, CompensationMethod::kPerceptual, &delta);
  EXPECT_LT(LowestMeanDeltaE(problem, delta, 3), 1e-6);
}

TEST(LowestMeanDeltaE, GoesBelowBothMethodsWhenBoundsBite) {
  const CompensationProblem problem = BoxProblem();
  Eigen::VectorXd linear_delta, perceptual_delta;
  const double linear = MeanDeltaE(problem, CompensationMethod::kLinear, &linear_delta);
  const double perceptual = MeanDeltaE(problem, CompensationMethod::kPerceptual, &perceptual_delta);
  const double lowest = LowestMeanDeltaE(problem, perceptual_delta);
  EXPECT_GT(lowest, 1.0);  // saturated colours in a white room: not reachable
  // Minimising the mean itself beats both least-squares optima on the mean.
  EXPECT_LT(lowest, 0.99 * perceptual) << "linear " << linear << ", perceptual " << perceptual;
  EXPECT_LT(lowest, linear);
}

TEST(LowestMeanDeltaE2000, IsZeroWhenReachableAndBelowEveryMethodWhenBoundsBite) {
  CompensationProblem loose = BoxProblem();
  loose.lower.setConstant(-10.0);
  loose.upper.setConstant(10.0);
  EXPECT_LT(LowestMeanDeltaE2000(loose, 3), 1e-6);

  const CompensationProblem problem = BoxProblem();
  const double lowest = LowestMeanDeltaE2000(problem);
  EXPECT_GT(lowest, 1.0);
  for (const CompensationMethod method : {CompensationMethod::kReverse, CompensationMethod::kLinear,
                                          CompensationMethod::kPerceptual,
                                          CompensationMethod::kPerceptual2000}) {
    Eigen::VectorXd delta;
    double mean2000 = 0.0;
    MeanDeltaE(problem, method, &delta, &mean2000);
    std::printf("%s: per patch mean CIEDE2000 %.3f (lowest reachable %.3f)\n", MethodName(method),
                mean2000, lowest);
    if (method == CompensationMethod::kPerceptual2000) {
      // The minimiser of the mean is a local one (an upper bound), and the recommended method,
      // which aims at CIEDE2000 too, goes below it here (19.89 against 20.06): within 1% of it.
      EXPECT_LT(lowest, 1.01 * mean2000);
    } else {
      EXPECT_LT(lowest, mean2000) << MethodName(method);
    }
  }
}

// A scene file with projectors and a camera is the rig it describes: tiny_box written as a file
// (WriteSyntheticSceneFile) and evaluated from it has the built-in scene's camera and projectors
// and photographs the same compensation (the linear method's per-pixel ΔE76, within the rounding
// of the written numbers), and its geometry records the file it came from.
TEST(EvaluateSyntheticScene, ASceneFileWithProjectorsAndACameraIsTheRigItDescribes) {
  const testing::TempDir dir;
  const std::filesystem::path file = WriteSyntheticSceneFile("tiny_box", 100, dir.path());
  EvaluationOptions options;
  options.patches = 100;
  options.methods = {CompensationMethod::kLinear};
  const SceneEvaluation built_in = EvaluateSyntheticScene("tiny_box", options);
  const SceneEvaluation from_file = EvaluateSyntheticScene(file.string(), options);
  EXPECT_EQ(from_file.geometry.scene.path, file);
  EXPECT_EQ(built_in.geometry.scene.path, "synthetic:tiny_box");
  const auto same_device = [](const ProjectorGeometry& a, const ProjectorGeometry& b) {
    EXPECT_EQ(a.width(), b.width());
    EXPECT_EQ(a.height(), b.height());
    ASSERT_EQ(a.intrinsics().size(), b.intrinsics().size());
    for (size_t i = 0; i < a.intrinsics().size(); ++i)
      EXPECT_NEAR(a.intrinsics()[i], b.intrinsics()[i], 1e-6 * (1.0 + std::abs(a.intrinsics()[i])));
    EXPECT_LT((a.proj_from_world().matrix() - b.proj_from_world().matrix()).norm(), 1e-9);
  };
  same_device(from_file.world->camera(), built_in.world->camera());
  ASSERT_EQ(from_file.world->projectors().size(), built_in.world->projectors().size());
  for (size_t k = 0; k < built_in.world->projectors().size(); ++k)
    same_device(from_file.world->projectors()[k].geometry, built_in.world->projectors()[k].geometry);
  ASSERT_EQ(from_file.methods.size(), 1u);
  ASSERT_EQ(built_in.methods.size(), 1u);
  std::printf("linear: mean ΔE76 %.4f built in, %.4f from the file\n",
              built_in.methods[0].mean_delta_e76, from_file.methods[0].mean_delta_e76);
  EXPECT_NEAR(from_file.methods[0].mean_delta_e76, built_in.methods[0].mean_delta_e76,
              1e-3 * built_in.methods[0].mean_delta_e76);
}

// The scene with the most shadows and partly lit patches (partitions in front of the walls), as
// `procam evaluate interior_partitions --patches 300` runs it (300 rather than the default 600 to
// keep the sanitizer run short): with seamless light (the default) the patch grid does not show
// (seam metric below 0.5: measured 0.32; 0.15 at 600 patches), with flat light per patch it does
// (1.37; 0.91), and perceptual2000 is lower than linear in per-pixel mean CIEDE2000 (9.49
// against 10.64).
TEST(EvaluateSyntheticScene, SeamlessLightHidesThePatchGridOnInteriorPartitions) {
  EvaluationOptions options;
  options.patches = 300;
  options.methods = {CompensationMethod::kLinear, CompensationMethod::kPerceptual2000};
  const SceneEvaluation smooth = EvaluateSyntheticScene("interior_partitions", options);
  options.methods = {CompensationMethod::kPerceptual2000};
  options.render.light = LightField::kFlat;
  const SceneEvaluation flat = EvaluateSyntheticScene("interior_partitions", options);
  const MethodEvaluation& linear = smooth.methods[0];
  const MethodEvaluation& perceptual2000 = smooth.methods[1];
  std::printf("interior_partitions: seam %.3f (flat light %.3f); CIEDE2000 perceptual2000 %.3f, "
              "linear %.3f\n",
              perceptual2000.seams.seam, flat.methods[0].seams.seam,
              perceptual2000.mean_delta_e2000, linear.mean_delta_e2000);
  EXPECT_GT(perceptual2000.seams.across_pairs, 10000);
  EXPECT_LT(perceptual2000.seams.seam, 0.5);
  EXPECT_GT(flat.methods[0].seams.seam, 2.0 * perceptual2000.seams.seam);
  EXPECT_LT(perceptual2000.mean_delta_e2000, linear.mean_delta_e2000);
}

}  // namespace
}  // namespace procam
