// The matrix-free path (issue 9): compressed form factors, K⁻¹ by conjugate gradients, and the
// solver on top of it, against the dense path on the very same F.
#include <memory>
#include <utility>

#include <gtest/gtest.h>

#include "compensation/objective.h"
#include "compensation/problem.h"
#include "compensation/radiosity.h"
#include "compensation/solver.h"
#include "datasets_synthetic/rooms.h"
#include "geometry/form_factors.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

struct Pair {
  Scene scene;
  PatchHierarchy patches;
  std::shared_ptr<const CompressedFormFactors> compressed;
  CompensationProblem matrix_free;  // F compressed
  CompensationProblem dense;        // F = the compressed F written out
};

// A box room with an occluder, big enough for far blocks at the default admissibility.
Pair MakePair(int target_patches) {
  Pair pair;
  SubdividedRoom room = MakeSubdividedBoxRoom(target_patches);
  pair.scene = std::move(room.scene);
  pair.patches = std::move(room.patches);
  CompressedBuildSummary summary;
  pair.compressed = std::make_shared<const CompressedFormFactors>(ComputeCompressedFormFactors(
      pair.scene, pair.patches.fine, FormFactorOptions(), ClusterOptions(), &summary));
  EXPECT_GT(summary.far_blocks, 0);
  pair.dense = MakeProblem(pair.scene, pair.patches.fine, pair.compressed->ToDense(), 0.5);
  pair.matrix_free = MakeProblem(pair.scene, pair.patches.fine, Eigen::MatrixXd(), 0.5);
  pair.matrix_free.compressed_form_factors = pair.compressed;
  return pair;
}

class MatrixFree : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { pair_ = new Pair(MakePair(1200)); }
  static void TearDownTestSuite() { delete pair_; }
  static Pair* pair_;
};
Pair* MatrixFree::pair_ = nullptr;

TEST_F(MatrixFree, SolvesMatchTheDenseFactorsForGreyColouredAndBlackPatches) {
  const int n = pair_->dense.size();
  Eigen::MatrixX3d rho = pair_->dense.reflectance;
  for (int variant = 0; variant < 3; ++variant) {
    if (variant == 1) rho.col(1) *= 0.7;
    if (variant == 2) rho(5, 2) = 0.0;  // black: the dense path takes LU, CG needs no care
    const RadiositySystem dense(pair_->dense.form_factors, pair_->dense.area, rho);
    const RadiositySystem iterative(pair_->compressed, rho);
    ASSERT_NE(iterative.compressed(), nullptr);
    const Eigen::MatrixX3d e = Eigen::MatrixX3d::Random(n, 3).cwiseAbs();
    const Eigen::MatrixX3d b = iterative.Solve(e), expected_b = dense.Solve(e);
    const Eigen::MatrixX3d x = iterative.SolveTransposed(e), expected_x = dense.SolveTransposed(e);
    EXPECT_LT((b - expected_b).norm(), 1e-9 * expected_b.norm()) << "variant " << variant;
    EXPECT_LT((x - expected_x).norm(), 1e-9 * expected_x.norm()) << "variant " << variant;
    // The equation itself, through the compressed products.
    EXPECT_LT((iterative.Multiply(b) - e).norm(), 1e-9 * e.norm());
    EXPECT_LT((iterative.MultiplyTransposed(x) - e).norm(), 1e-9 * e.norm());
    // Fast solves: within their looser tolerance.
    EXPECT_LT((iterative.SolveFast(e) - expected_b).norm(), 1e-4 * expected_b.norm());
    EXPECT_LT((iterative.SolveTransposedFast(e) - expected_x).norm(), 1e-4 * expected_x.norm());
  }
  const RadiositySystem iterative(pair_->compressed, pair_->dense.reflectance);
  iterative.Solve(Eigen::MatrixX3d::Ones(n, 3));
  // Conjugate gradients on M, cond(M) ≤ 19: a few dozen products with F per channel, not n.
  EXPECT_GT(iterative.solve_iterations(), 0);
  EXPECT_LT(iterative.solve_iterations(), 100);
}

TEST_F(MatrixFree, NonConvergenceIsAnError) {
  IterativeRadiosityOptions options;
  options.max_iterations = 2;
  const RadiositySystem iterative(pair_->compressed, pair_->dense.reflectance, options);
  EXPECT_THROW(iterative.Solve(Eigen::MatrixX3d::Ones(pair_->dense.size(), 3)), std::runtime_error);
}

TEST_F(MatrixFree, SolverReachesTheDenseOptimumForBothMethods) {
  ASSERT_EQ(pair_->matrix_free.Validate(), "");
  for (const CompensationMethod method : {CompensationMethod::kPerceptual, CompensationMethod::kLinear}) {
    SolverOptions options;
    options.method = method;
    SolverSummary dense_summary, free_summary;
    const CompensationSolution dense = Solve(options, pair_->dense, &dense_summary);
    const CompensationSolution free = Solve(options, pair_->matrix_free, &free_summary);
    EXPECT_NEAR(free_summary.final_cost, dense_summary.final_cost, 1e-6 * dense_summary.final_cost)
        << dense_summary.BriefReport() << "\n" << free_summary.BriefReport();
    EXPECT_TRUE(((free.emittance - pair_->dense.lower).array() >= 0.0).all());
    EXPECT_TRUE(((pair_->dense.upper - free.emittance).array() >= 0.0).all());
    // Both are minimisers of the same problem: their radiosities agree closely.
    EXPECT_LT((free.radiosity - dense.radiosity).norm(), 1e-3 * dense.radiosity.norm());
  }
}

TEST_F(MatrixFree, ProblemValidationNamesTheCompressedF) {
  CompensationProblem both = pair_->matrix_free;
  both.form_factors = Eigen::MatrixXd::Zero(both.size(), both.size());
  EXPECT_NE(both.Validate().find("both"), std::string::npos);
  CompensationProblem wrong = pair_->matrix_free;
  wrong.area.conservativeResize(wrong.size() - 1);
  EXPECT_FALSE(wrong.Validate().empty());
}

}  // namespace
}  // namespace procam
