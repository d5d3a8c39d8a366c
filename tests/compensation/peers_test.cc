#include "compensation/peers.h"

#include <cmath>
#include <functional>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "compensation/objective.h"
#include "compensation/problem.h"
#include "compensation/radiosity.h"
#include "datasets_synthetic/rooms.h"
#include "geometry/form_factors.h"
#include "geometry/patches.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using PeerSolver = std::function<PeerResult(const CompensationObjective&, const Eigen::MatrixX3d&,
                                            const PeerOptions&)>;

struct NamedPeer {
  const char* name;
  PeerSolver solve;
};

const NamedPeer kPeers[] = {{"ceres", SolveWithCeres},
                            {"lbfgsb", SolveWithLbfgsb},
                            {"projected gradient", SolveWithProjectedGradient}};

// A small perceptual (L*a*b*) compensation problem in a box room, with its radiosity system and
// objective. `saturated` gives some walls pure primaries, which a room that mixes colours by
// interreflection can only approach with some emittances at their bounds.
struct SmallRoom {
  CompensationProblem problem;
  std::unique_ptr<RadiositySystem> radiosity;
  std::unique_ptr<CompensationObjective> objective;

  SmallRoom(int target_patches, bool occluder, bool saturated, double alpha = 0.5) {
    BoxRoomOptions room;
    room.target_patches = target_patches;
    room.occluder = occluder;
    room.reflectance = 0.8;
    Scene scene = MakeBoxRoom(room);
    if (saturated) {
      scene.surfaces[2].desired.srgb = Vec3(1.0, 0.0, 0.0);  // front: red
      scene.surfaces[3].desired.srgb = Vec3(0.0, 0.0, 1.0);  // back: blue
      scene.surfaces[4].desired.srgb = Vec3(0.0, 1.0, 0.0);  // left: green
      scene.surfaces[1].desired.srgb = Vec3(1.0, 1.0, 1.0);  // ceiling: white
    }
    SubdivisionOptions subdivision;
    subdivision.target_patches = target_patches;
    const PatchHierarchy hierarchy = SubdividePatches(scene, subdivision);
    Eigen::MatrixXd form_factors =
        ComputeFormFactors(scene, hierarchy.fine, FormFactorOptions(), nullptr);
    problem = MakeProblem(scene, hierarchy.fine, std::move(form_factors), alpha);
    EXPECT_EQ(problem.Validate(), "");
    Rebuild();
  }

  // After changing `problem`.
  void Rebuild() {
    objective.reset();
    radiosity =
        std::make_unique<RadiositySystem>(problem.form_factors, problem.area, problem.reflectance);
    objective = std::make_unique<CompensationObjective>(problem, *radiosity, ColourModel::kLab);
  }

  Eigen::MatrixX3d Gradient(const Eigen::MatrixX3d& emittance) const {
    ObjectivePoint point;
    objective->Evaluate(emittance, &point);
    return objective->Gradient(point);
  }

  // ‖E − P(E − ∇f)‖∞, computed here rather than taken from any solver.
  double ProjectedGradient(const Eigen::MatrixX3d& emittance) const {
    const Eigen::MatrixX3d stepped =
        (emittance - Gradient(emittance)).cwiseMax(problem.lower).cwiseMin(problem.upper);
    return (emittance - stepped).cwiseAbs().maxCoeff();
  }
};

std::string Describe(const char* name, const PeerResult& result) {
  std::ostringstream out;
  out << name << ": f = " << result.cost << ", " << result.iterations << " iterations, "
      << result.seconds << " s, " << result.termination;
  return out.str();
}

TEST(PeerOptions, CheckRejectsBadValues) {
  std::string why;
  EXPECT_TRUE(PeerOptions().Check(&why));
  PeerOptions options;
  options.max_iterations = -1;
  EXPECT_FALSE(options.Check(&why));
  EXPECT_NE(why.find("max_iterations"), std::string::npos);
  options = PeerOptions();
  options.function_tolerance = -1e-3;
  EXPECT_FALSE(options.Check(&why));
  options = PeerOptions();
  options.gradient_tolerance = std::nan("");
  EXPECT_FALSE(options.Check(&why));
  options = PeerOptions();
  options.parameter_tolerance = -1.0;
  EXPECT_FALSE(options.Check(&why));
}

TEST(PeerSolvers, ReportInvalidOptionsWithoutSolving) {
  const SmallRoom room(24, false, false);
  PeerOptions options;
  options.max_iterations = -5;
  const Eigen::MatrixX3d initial = room.problem.desired;
  for (const NamedPeer& peer : kPeers) {
    const PeerResult result = peer.solve(*room.objective, initial, options);
    EXPECT_EQ(result.termination.rfind("invalid options", 0), 0u) << peer.name;
  }
}

TEST(CompensationLeastSquares, SumOfSquaresIsTheObjectiveAndJacobianMatchesDifferences) {
  const SmallRoom room(24, false, true, 0.3);
  const CompensationLeastSquares least_squares(*room.objective);
  const int n = room.problem.size();
  ASSERT_EQ(least_squares.variables(), 3 * n);
  ASSERT_EQ(least_squares.residuals(), 3 * (n + static_cast<int>(room.problem.adjacency.size())));
  // A point with some radiosities in L*a*b*'s linear segment (near black) and some above it.
  Eigen::MatrixX3d emittance = 0.5 * (Eigen::MatrixX3d::Random(n, 3).array() + 1.0);
  emittance.topRows(3) *= 1e-3;

  Eigen::VectorXd residual;
  Eigen::MatrixXd jacobian;
  ASSERT_TRUE(least_squares.Evaluate(emittance, &residual, &jacobian));
  const double f = room.objective->Value(emittance);
  EXPECT_NEAR(residual.squaredNorm(), f, 1e-12 * f);

  // Central differences of ρ, one variable at a time (patch-major: column 3j + c).
  const double h = 1e-6;
  Eigen::MatrixXd numeric(jacobian.rows(), jacobian.cols());
  for (int j = 0; j < n; ++j) {
    for (int c = 0; c < 3; ++c) {
      Eigen::MatrixX3d plus = emittance, minus = emittance;
      plus(j, c) += h;
      minus(j, c) -= h;
      Eigen::VectorXd residual_plus, residual_minus;
      ASSERT_TRUE(least_squares.Evaluate(plus, &residual_plus, nullptr));
      ASSERT_TRUE(least_squares.Evaluate(minus, &residual_minus, nullptr));
      numeric.col(3 * j + c) = (residual_plus - residual_minus) / (2 * h);
    }
  }
  const double scale = jacobian.cwiseAbs().maxCoeff();
  EXPECT_LT(testing::MaxAbsDifference(jacobian, numeric), 1e-6 * scale)
      << "largest entry " << scale;

  // The least-squares gradient 2 Jᵀρ is the objective's gradient.
  const Eigen::VectorXd gradient = 2.0 * jacobian.transpose() * residual;
  const Eigen::VectorXd expected = Flatten(room.Gradient(emittance));
  EXPECT_LT(testing::MaxAbsDifference(gradient, expected), 1e-9 * expected.cwiseAbs().maxCoeff());

  Eigen::MatrixX3d broken = emittance;
  broken(1, 2) = std::nan("");
  EXPECT_FALSE(least_squares.Evaluate(broken, &residual, &jacobian));
}

// With bounds that never bind, the minimum is the reverse-radiosity emittance E = K·Bd, f = 0.
TEST(PeerSolvers, LooseBoundsReachReverseRadiosity) {
  SmallRoom room(40, false, false);
  room.problem.lower.setConstant(-10.0);
  room.problem.upper.setConstant(10.0);
  room.Rebuild();
  const Eigen::MatrixX3d exact = room.radiosity->Multiply(room.problem.desired);
  ASSERT_LT(exact.cwiseAbs().maxCoeff(), 10.0);
  EXPECT_LT(room.objective->Value(exact), 1e-16);
  const Eigen::MatrixX3d initial = room.problem.desired;  // "show the picture": f > 0
  const double initial_cost = room.objective->Value(initial);
  ASSERT_GT(initial_cost, 1.0);

  PeerOptions options;
  options.max_iterations = 20000;
  for (const NamedPeer& peer : kPeers) {
    const PeerResult result = peer.solve(*room.objective, initial, options);
    SCOPED_TRACE(Describe(peer.name, result));
    std::cout << "[ variables " << room.objective->variables() << " ] "
              << Describe(peer.name, result) << "\n";
    EXPECT_LT(result.cost, 1e-8 * initial_cost);
    EXPECT_LT(testing::MaxAbsDifference(result.emittance, exact), 1e-4);
    EXPECT_NEAR(result.cost, room.objective->Value(result.emittance), 1e-12 * initial_cost);
    ASSERT_FALSE(result.trace.empty());
    EXPECT_EQ(result.trace.front().second, initial_cost);
    EXPECT_EQ(static_cast<int>(result.trace.size()), result.iterations + 1);
    EXPECT_NEAR(result.trace.back().second, result.cost, 1e-9 * initial_cost);
  }
}

// With the default bounds [0, white] and pure primaries wanted, bounds bind: every peer must
// stop at a feasible first-order critical point, and all must find the same minimum.
TEST(PeerSolvers, TightBoundsAgreeAtAFirstOrderPoint) {
  const SmallRoom room(48, true, true);
  const Eigen::MatrixX3d initial = room.problem.desired;
  PeerOptions options;
  options.max_iterations = 100000;
  options.function_tolerance = 1e-15;
  options.parameter_tolerance = 1e-15;
  double costs[3];
  int k = 0;
  int active_bounds = 0;
  for (const NamedPeer& peer : kPeers) {
    const PeerResult result = peer.solve(*room.objective, initial, options);
    SCOPED_TRACE(Describe(peer.name, result));
    std::cout << "[ variables " << room.objective->variables() << " ] "
              << Describe(peer.name, result) << "\n";
    EXPECT_TRUE((result.emittance.array() >= room.problem.lower.array()).all());
    EXPECT_TRUE((result.emittance.array() <= room.problem.upper.array()).all());
    const double projected_gradient = room.ProjectedGradient(result.emittance);
    EXPECT_LT(projected_gradient, 1e-7 * (1.0 + result.cost));
    std::cout << std::setprecision(15) << "    f " << result.cost << ", projected gradient "
              << projected_gradient << " (initial " << room.ProjectedGradient(initial)
              << "), active bounds "
              << ((result.emittance.array() == room.problem.lower.array()) ||
                  (result.emittance.array() == room.problem.upper.array()))
                     .count()
              << std::setprecision(6) << "\n";
    EXPECT_EQ(static_cast<int>(result.trace.size()), result.iterations + 1);
    active_bounds = ((result.emittance.array() == room.problem.lower.array()) ||
                     (result.emittance.array() == room.problem.upper.array()))
                        .count();
    costs[k++] = result.cost;
  }
  EXPECT_GT(active_bounds, 0) << "the test problem should have active bounds";
  const double reference = costs[0];
  EXPECT_GT(reference, 1e-3) << "saturated colours should not be reachable exactly";
  for (int i = 1; i < 3; ++i) {
    EXPECT_NEAR(costs[i], reference, 1e-6 * reference) << kPeers[i].name;
  }
}

TEST(PeerSolvers, ProjectTheInitialPointOntoTheBounds) {
  const SmallRoom room(24, false, false);
  const int n = room.problem.size();
  Eigen::MatrixX3d initial = Eigen::MatrixX3d::Constant(n, 3, 0.5);
  initial(0, 0) = -3.0;
  initial(1, 2) = 7.0;
  Eigen::MatrixX3d projected = initial;
  projected(0, 0) = room.problem.lower(0, 0);
  projected(1, 2) = room.problem.upper(1, 2);
  PeerOptions options;
  options.max_iterations = 0;
  for (const NamedPeer& peer : kPeers) {
    const PeerResult result = peer.solve(*room.objective, initial, options);
    EXPECT_EQ(result.iterations, 0) << peer.name;
    EXPECT_EQ(result.termination.rfind("max iterations", 0), 0u) << peer.name;
    EXPECT_EQ(testing::MaxAbsDifference(result.emittance, projected), 0.0) << peer.name;
    EXPECT_EQ(result.cost, room.objective->Value(projected)) << peer.name;
  }
}

TEST(PeerSolvers, NonFiniteObjectiveIsReportedNotThrown) {
  SmallRoom room(24, false, false);
  room.problem.desired(2, 1) = std::nan("");
  room.Rebuild();
  const Eigen::MatrixX3d initial = Eigen::MatrixX3d::Constant(room.problem.size(), 3, 0.5);
  for (const NamedPeer& peer : kPeers) {
    PeerResult result;
    EXPECT_NO_THROW(result = peer.solve(*room.objective, initial, PeerOptions()));
    EXPECT_EQ(result.termination.rfind("numerical failure", 0), 0u)
        << peer.name << ": " << result.termination;
    EXPECT_EQ(result.emittance.rows(), room.problem.size());
  }
  Eigen::MatrixX3d bad_initial = initial;
  bad_initial(0, 0) = std::nan("");
  for (const NamedPeer& peer : kPeers) {
    const PeerResult result = peer.solve(*room.objective, bad_initial, PeerOptions());
    EXPECT_EQ(result.termination.rfind("invalid input", 0), 0u) << peer.name;
  }
}

}  // namespace
}  // namespace procam
