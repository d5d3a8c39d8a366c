// The objective measured in CIEDE2000 (kPerceptual2000): CIEDE2000's metric against ΔE00 itself,
// the reweighted objective against its definition and finite differences, the robust losses'
// weights against finite differences of ρ, and the solver's result against the bounds, first-order
// optimality of its last round and the published perceptual method's ΔE00.
#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "compensation/colour.h"
#include "compensation/solver.h"
#include "datasets_synthetic/rooms.h"
#include "geometry/form_factors.h"

namespace procam {
namespace {

struct TestProblem {
  PatchHierarchy patches;
  CompensationProblem fine, coarse;
};

// The box room with an occluder and saturated desired colours (bounds bite).
TestProblem MakeProblem(int target_patches, double alpha) {
  TestProblem test;
  SubdividedRoom room = MakeSubdividedBoxRoom(target_patches);
  test.patches = std::move(room.patches);
  Eigen::MatrixXd f = ComputeFormFactors(room.scene, test.patches.fine, FormFactorOptions(), nullptr);
  const Eigen::MatrixXd coarse_f = AggregateFormFactors(
      f, test.patches.fine.Areas(), test.patches.coarse_of_fine, test.patches.coarse.size());
  test.fine = MakeProblem(room.scene, test.patches.fine, std::move(f), alpha);
  test.coarse = MakeProblem(room.scene, test.patches.coarse, coarse_f, alpha);
  return test;
}

Eigen::MatrixX3d LabOf(const CompensationProblem& problem, const Eigen::MatrixX3d& rgb) {
  Eigen::MatrixX3d lab(rgb.rows(), 3);
  for (int i = 0; i < rgb.rows(); ++i)
    lab.row(i) = XyzToLab(problem.rgb_to_xyz * rgb.row(i).transpose(), problem.white_xyz).transpose();
  return lab;
}

// B = K⁻¹E by a dense LU per channel, independent of the solver's radiosity code.
Eigen::MatrixX3d RadiosityByLu(const CompensationProblem& problem, const Eigen::MatrixX3d& e) {
  const int n = problem.size();
  Eigen::MatrixX3d b(n, 3);
  for (int c = 0; c < 3; ++c) {
    const Eigen::MatrixXd k = Eigen::MatrixXd::Identity(n, n) -
                              problem.reflectance.col(c).asDiagonal() * problem.form_factors;
    b.col(c) = k.fullPivLu().solve(e.col(c));
  }
  return b;
}

// f with the metric, written out patch by patch and pair by pair: each residual r̃_i = L_i r_i.
double ObjectiveByDefinition(const CompensationProblem& problem, const ColourMetric& metric,
                             const Eigen::MatrixX3d& e) {
  const int n = problem.size();
  const Eigen::MatrixX3d r0 =
      LabOf(problem, RadiosityByLu(problem, e)) - LabOf(problem, problem.desired);
  Eigen::MatrixX3d r(n, 3);
  for (int i = 0; i < n; ++i) r.row(i) = (metric.factor[i] * r0.row(i).transpose()).transpose();
  double f = 0.0;
  for (int i = 0; i < n; ++i)
    f += problem.alpha * problem.area[i] / problem.area.mean() * metric.weight[i] * r.row(i).squaredNorm();
  for (std::size_t k = 0; k < problem.adjacency.size(); ++k) {
    const auto& pair = problem.adjacency[k];
    const double w = metric.pair_weight.size() == 0 ? 1.0 : metric.pair_weight[static_cast<Eigen::Index>(k)];
    f += (1 - problem.alpha) * w * (r.row(pair[0]) - r.row(pair[1])).squaredNorm();
  }
  return f;
}

double AreaMeanDeltaE2000(const CompensationProblem& problem, const Eigen::MatrixX3d& radiosity) {
  const Eigen::MatrixX3d lab = LabOf(problem, radiosity), desired = LabOf(problem, problem.desired);
  double sum = 0.0;
  for (int i = 0; i < problem.size(); ++i) {
    sum += problem.area[i] * DeltaE2000(lab.row(i).transpose(), desired.row(i).transpose());
  }
  return sum / problem.area.sum();
}

TEST(DeltaE2000Metric, LightnessAxisMatchesTheClosedForm) {
  // Along L* alone, ΔE00 = ΔL / S_L with S_L = 1 + 0.015 (L̄ − 50)² / √(20 + (L̄ − 50)²).
  for (const double l : {10.0, 35.0, 50.0, 72.0, 95.0}) {
    const Eigen::Matrix3d m = DeltaE2000Metric(Eigen::Vector3d(l, 20.0, -30.0));
    const double d = l - 50.0;
    const double sl = 1.0 + 0.015 * d * d / std::sqrt(20.0 + d * d);
    EXPECT_NEAR(m(0, 0), 1.0 / (sl * sl), 2e-3 / (sl * sl)) << "L* " << l;
  }
}

TEST(DeltaE2000Metric, SmallDifferencesMatchDeltaE2000) {
  std::mt19937 random(7);
  std::uniform_real_distribution<double> l(5.0, 95.0), ab(-80.0, 80.0), unit(-1.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3d lab(l(random), ab(random), ab(random));
    const Eigen::Matrix3d m = DeltaE2000Metric(lab);
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(m);
    EXPECT_GT(eigen.eigenvalues().minCoeff(), 0.0);
    const Eigen::Vector3d delta = 0.02 * Eigen::Vector3d(unit(random), unit(random), unit(random));
    const double distance = DeltaE2000(lab + delta, lab);
    EXPECT_NEAR(delta.dot(m * delta), distance * distance, 0.03 * distance * distance)
        << "Lab " << lab.transpose() << ", δ " << delta.transpose();
  }
}

TEST(RobustLoss, WeightsAreTheLossDerivative) {
  const double c = 1.7;
  const auto rho = [c](SolverOptions::RobustLoss loss, double s) {
    switch (loss) {
      case SolverOptions::RobustLoss::kSquared: return s;
      case SolverOptions::RobustLoss::kSoftL1: return 2 * c * c * (std::sqrt(1 + s / (c * c)) - 1);
      case SolverOptions::RobustLoss::kHuber: return s <= c * c ? s : 2 * c * std::sqrt(s) - c * c;
      case SolverOptions::RobustLoss::kCauchy: return c * c * std::log(1 + s / (c * c));
    }
    return 0.0;
  };
  for (const auto loss : {SolverOptions::RobustLoss::kSquared, SolverOptions::RobustLoss::kSoftL1,
                          SolverOptions::RobustLoss::kHuber, SolverOptions::RobustLoss::kCauchy}) {
    for (const double s : {0.01, 0.5, 2.0, 9.0, 150.0}) {
      const double h = 1e-6 * s;
      const double numeric = (rho(loss, s + h) - rho(loss, s - h)) / (2 * h);
      EXPECT_NEAR(RobustLossWeight(loss, c, s), numeric, 1e-6) << RobustLossName(loss) << " s " << s;
    }
    SolverOptions::RobustLoss parsed;
    ASSERT_TRUE(ParseRobustLoss(RobustLossName(loss), &parsed));
    EXPECT_EQ(parsed, loss);
  }
}

class Ciede2000Objective : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { test_ = new TestProblem(MakeProblem(60, 0.4)); }
  static void TearDownTestSuite() { delete test_; }
  // A metric at a random radiosity, with uneven robust weights.
  static ColourMetric Metric() {
    SolverOptions options;
    options.robust_loss = SolverOptions::RobustLoss::kCauchy;
    options.robust_scale = 3.0;
    const Eigen::MatrixX3d b = 0.5 * (Eigen::MatrixX3d::Random(test_->fine.size(), 3).array() + 1.0);
    return Ciede2000Metric(options, test_->fine, b);
  }
  static TestProblem* test_;
};
TestProblem* Ciede2000Objective::test_ = nullptr;

TEST_F(Ciede2000Objective, MetricGivesEachPatchItsExactDeltaE2000) {
  const CompensationProblem& problem = test_->fine;
  SolverOptions options;
  const Eigen::MatrixX3d b = 0.5 * (Eigen::MatrixX3d::Random(problem.size(), 3).array() + 1.0);
  const ColourMetric metric = Ciede2000Metric(options, problem, b);
  const Eigen::MatrixX3d r = LabOf(problem, b) - LabOf(problem, problem.desired);
  for (int i = 0; i < problem.size(); ++i) {
    const double expected = DeltaE2000(LabOf(problem, b).row(i).transpose(),
                                       LabOf(problem, problem.desired).row(i).transpose());
    EXPECT_NEAR((metric.factor[i] * r.row(i).transpose()).norm(), expected, 1e-9 * (1 + expected));
  }
  EXPECT_NEAR(metric.weight.mean(), 1.0, 1e-12);
  EXPECT_GT(metric.weight.maxCoeff() - metric.weight.minCoeff(), 0.1);  // soft-L1 reweights
  // Each neighbour pair: soft-L1's ρ′ at the squared distance between the two measured
  // residuals, normalised to mean 1 like the patches' weights.
  ASSERT_EQ(metric.pair_weight.size(), static_cast<Eigen::Index>(problem.adjacency.size()));
  Eigen::VectorXd expected(metric.pair_weight.size());
  const double c = options.robust_scale;
  for (Eigen::Index k = 0; k < expected.size(); ++k) {
    const auto& pair = problem.adjacency[static_cast<std::size_t>(k)];
    const Eigen::Vector3d d = metric.factor[pair[0]] * r.row(pair[0]).transpose() -
                              metric.factor[pair[1]] * r.row(pair[1]).transpose();
    expected[k] = 1.0 / std::sqrt(1.0 + d.squaredNorm() / (c * c));
  }
  expected /= expected.mean();
  EXPECT_LT((metric.pair_weight - expected).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_GT(metric.pair_weight.maxCoeff() - metric.pair_weight.minCoeff(), 0.1);
}

TEST_F(Ciede2000Objective, MetricAtTheDesiredColoursWeighsNothing) {
  const ColourMetric metric = Ciede2000Metric(SolverOptions(), test_->fine, Eigen::MatrixX3d());
  EXPECT_EQ(metric.pair_weight.size(), 0);
  EXPECT_TRUE((metric.weight.array() == 1.0).all());
}

TEST_F(Ciede2000Objective, ValueMatchesTheDefinition) {
  const CompensationProblem& problem = test_->fine;
  const ColourMetric metric = Metric();
  const RadiositySystem radiosity(problem.form_factors, problem.area, problem.reflectance);
  const CompensationObjective objective(problem, radiosity, ColourModel::kLab, metric);
  const Eigen::MatrixX3d e = 0.5 * (Eigen::MatrixX3d::Random(problem.size(), 3).array() + 1.0);
  const double expected = ObjectiveByDefinition(problem, metric, e);
  EXPECT_NEAR(objective.Value(e), expected, 1e-9 * expected);
  const CompensationObjective published(problem, radiosity, ColourModel::kLab);
  EXPECT_GT(std::abs(published.Value(e) - expected), 1e-2 * expected);  // the metric matters
}

TEST_F(Ciede2000Objective, GradientAndHessianMatchFiniteDifferences) {
  const CompensationProblem& problem = test_->fine;
  const RadiositySystem radiosity(problem.form_factors, problem.area, problem.reflectance);
  const CompensationObjective objective(problem, radiosity, ColourModel::kLab, Metric());
  Eigen::MatrixX3d e = 0.5 * (Eigen::MatrixX3d::Random(problem.size(), 3).array() + 1.0);
  e.topRows(4) *= 1e-4;  // the linear branch of L*a*b*'s h as well
  ObjectivePoint point;
  objective.Evaluate(e, &point);
  const Eigen::MatrixX3d gradient = objective.Gradient(point);
  const double step = 1e-6;
  for (int i = 0; i < problem.size(); i += 5) {
    for (int c = 0; c < 3; ++c) {
      Eigen::MatrixX3d plus = e, minus = e;
      plus(i, c) += step;
      minus(i, c) -= step;
      const double numeric = (objective.Value(plus) - objective.Value(minus)) / (2 * step);
      EXPECT_NEAR(gradient(i, c), numeric, 1e-5 * (1.0 + std::abs(numeric)));
    }
  }
  objective.AddSecondOrder(&point);
  for (int trial = 0; trial < 3; ++trial) {
    const Eigen::MatrixX3d v = Eigen::MatrixX3d::Random(problem.size(), 3);
    ObjectivePoint plus, minus;
    objective.Evaluate(e + step * v, &plus);
    objective.Evaluate(e - step * v, &minus);
    const Eigen::MatrixX3d numeric = (objective.Gradient(plus) - objective.Gradient(minus)) / (2 * step);
    EXPECT_LT((objective.GaussNewtonProduct(point, v) - numeric).norm(), 1e-5 * numeric.norm());
  }
}

TEST(SolvePerceptual2000, OptimalWithinTheBoundsAndLowerInCiede2000ThanPerceptual) {
  const TestProblem test = MakeProblem(200, 0.5);
  const CompensationProblem& problem = test.fine;
  const CoarseLevel coarse{&test.coarse, &test.patches.coarse_of_fine};
  SolverOptions perceptual;
  perceptual.multires = true;
  SolverSummary perceptual_summary;
  const CompensationSolution published = Solve(perceptual, problem, &perceptual_summary, coarse);
  const double published_mean = AreaMeanDeltaE2000(problem, published.radiosity);
  for (const auto loss : {SolverOptions::RobustLoss::kSoftL1, SolverOptions::RobustLoss::kSquared,
                          SolverOptions::RobustLoss::kHuber, SolverOptions::RobustLoss::kCauchy}) {
    SolverOptions options = perceptual;
    options.method = CompensationMethod::kPerceptual2000;
    options.robust_loss = loss;
    SolverSummary summary;
    const CompensationSolution solution = Solve(options, problem, &summary, coarse);
    EXPECT_TRUE(((solution.emittance - problem.lower).array() >= 0.0).all());
    EXPECT_TRUE(((problem.upper - solution.emittance).array() >= 0.0).all());
    // First-order optimal for its last round's objective, recomputed here.
    const RadiositySystem radiosity(problem.form_factors, problem.area, problem.reflectance);
    const CompensationObjective objective(problem, radiosity, ColourModel::kLab, solution.metric);
    ObjectivePoint point;
    const double cost = objective.Evaluate(solution.emittance, &point);
    EXPECT_NEAR(cost, ObjectiveByDefinition(problem, solution.metric, solution.emittance),
                1e-8 * cost);
    EXPECT_NEAR(summary.final_cost, cost, 1e-8 * cost) << summary.BriefReport();
    const double projected =
        ProjectedGradientNorm(solution.emittance, objective.Gradient(point), problem.lower, problem.upper);
    EXPECT_LT(projected, 1e-6 * (1.0 + cost)) << summary.BriefReport();
    // The radiosity returned is that of the emittance returned (the last round's).
    const Eigen::MatrixX3d exact = RadiosityByLu(problem, solution.emittance);
    EXPECT_LT((solution.radiosity - exact).cwiseAbs().maxCoeff(), 1e-8 * (1.0 + exact.cwiseAbs().maxCoeff()));
    const double mean = AreaMeanDeltaE2000(problem, exact);
    std::printf("%s: per patch mean ΔE00 %.3f (perceptual %.3f), %d iterations\n",
                RobustLossName(loss), mean, published_mean, summary.iterations);
    if (loss == SolverOptions::RobustLoss::kSoftL1) {
      EXPECT_LT(mean, published_mean);
    }
  }
}

TEST(SolvePerceptual2000, BadOptionsAreRefused) {
  SolverOptions options;
  std::string why;
  options.robust_scale = 0.0;
  EXPECT_FALSE(options.Check(&why));
  EXPECT_NE(why.find("robust_scale"), std::string::npos);
  options = SolverOptions();
  options.metric_rounds = 0;
  EXPECT_FALSE(options.Check(&why));
  EXPECT_NE(why.find("metric_rounds"), std::string::npos);
  CompensationMethod method;
  ASSERT_TRUE(ParseMethod("perceptual2000", &method));
  EXPECT_EQ(method, CompensationMethod::kPerceptual2000);
}

}  // namespace
}  // namespace procam
