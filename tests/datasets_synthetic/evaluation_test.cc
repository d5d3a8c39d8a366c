// The lowest mean ΔE bound of procam evaluate (datasets_synthetic/evaluation.h).
#include "datasets_synthetic/evaluation.h"

#include <gtest/gtest.h>

#include "compensation/objective.h"
#include "compensation/solver.h"
#include "datasets_synthetic/rooms.h"
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

// Area-weighted mean ΔE76 per patch of `method`'s solution, and the per-patch values.
double MeanDeltaE(const CompensationProblem& problem, CompensationMethod method, Eigen::VectorXd* delta_e76) {
  SolverOptions options;
  options.method = method;
  SolverSummary summary;
  const CompensationSolution solution = Solve(options, problem, &summary);
  const CompensationObjective lab(problem, *solution.radiosity_system, ColourModel::kLab);
  Eigen::VectorXd delta_e2000;
  lab.DeltaE(solution.radiosity, delta_e76, &delta_e2000);
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

}  // namespace
}  // namespace procam
