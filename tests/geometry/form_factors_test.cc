#include "geometry/form_factors.h"

#include <cmath>

#include <gtest/gtest.h>
#include <numbers>

#include "datasets_synthetic/rooms.h"
#include "geometry/patches.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

// Closed forms (Howell, "A Catalog of Radiation Heat Transfer Configuration Factors").
// Coaxial parallel rectangles a × b at distance c.
double ParallelRectangles(double a, double b, double c) {
  const double x = a / c, y = b / c;
  const double x2 = 1 + x * x, y2 = 1 + y * y;
  return 2.0 / (std::numbers::pi * x * y) *
         (0.5 * std::log(x2 * y2 / (1 + x * x + y * y)) + x * std::sqrt(y2) * std::atan(x / std::sqrt(y2)) +
          y * std::sqrt(x2) * std::atan(y / std::sqrt(x2)) - x * std::atan(x) - y * std::atan(y));
}

// From rectangle 1 (width w) to rectangle 2 (height h), perpendicular, sharing an edge of length l.
double PerpendicularRectangles(double w, double h, double l) {
  const double W = w / l, H = h / l, W2 = W * W, H2 = H * H, S = std::sqrt(H2 + W2);
  const double log_term =
      std::log((1 + W2) * (1 + H2) / (1 + W2 + H2)) +
      W2 * std::log(W2 * (1 + W2 + H2) / ((1 + W2) * (W2 + H2))) +
      H2 * std::log(H2 * (1 + H2 + W2) / ((1 + H2) * (H2 + W2)));
  return (W * std::atan(1 / W) + H * std::atan(1 / H) - S * std::atan(1 / S) + 0.25 * log_term) / (std::numbers::pi * W);
}

// Differential element to a parallel rectangle a × b whose corner lies above it at height c.
double ElementToCornerRectangle(double a, double b, double c) {
  const double A = a / c, B = b / c;
  return (A / std::sqrt(1 + A * A) * std::atan(B / std::sqrt(1 + A * A)) +
          B / std::sqrt(1 + B * B) * std::atan(A / std::sqrt(1 + B * B))) /
         (2 * std::numbers::pi);
}

// Total form factor from surface `from` to surface `to`, summed over their patches.
double SurfaceFormFactor(const PatchLevel& level, const Eigen::MatrixXd& f, int from, int to) {
  double exchange = 0.0, area = 0.0;
  for (int i = 0; i < level.size(); ++i) {
    if (level.patches[i].surface != from) continue;
    area += level.patches[i].area;
    for (int j = 0; j < level.size(); ++j) {
      if (level.patches[j].surface == to) exchange += level.patches[i].area * f(i, j);
    }
  }
  return exchange / area;
}

struct Computed {
  PatchHierarchy patches;
  Eigen::MatrixXd f;
  FormFactorSummary summary;
};

Computed Compute(const Scene& scene, int target_patches) {
  SubdivisionOptions subdivision;
  subdivision.target_patches = target_patches;
  Computed computed;
  computed.patches = SubdividePatches(scene, subdivision);
  computed.f = ComputeFormFactors(scene, computed.patches.fine, FormFactorOptions(), &computed.summary);
  return computed;
}

TEST(PointToPolygon, MatchesCornerRectangleClosedForm) {
  const Vec3 quad[4] = {Vec3(0, 0, 1), Vec3(0, 0.7, 1), Vec3(1.3, 0.7, 1), Vec3(1.3, 0, 1)};  // faces down
  const double computed = PointToPolygonFormFactor(Vec3::Zero(), Vec3::UnitZ(), quad, 4);
  EXPECT_NEAR(computed, ElementToCornerRectangle(1.3, 0.7, 1.0), 1e-12);
  // Seen from behind, or wholly below the horizon, nothing arrives.
  EXPECT_EQ(PointToPolygonFormFactor(Vec3(0, 0, 2), -Vec3::UnitZ(), quad, 4), 0.0);
  EXPECT_EQ(PointToPolygonFormFactor(Vec3(0, 0, 0), -Vec3::UnitZ(), quad, 4), 0.0);
}

TEST(PointToPolygon, ClipsAtTheHorizon) {
  // A wall standing on the element's plane, half of it below: only the upper half counts.
  const Vec3 wall[4] = {Vec3(1, -1, -1), Vec3(1, 1, -1), Vec3(1, 1, 1), Vec3(1, -1, 1)};  // faces -x
  const Vec3 upper[4] = {Vec3(1, -1, 0), Vec3(1, 1, 0), Vec3(1, 1, 1), Vec3(1, -1, 1)};
  EXPECT_NEAR(PointToPolygonFormFactor(Vec3::Zero(), Vec3::UnitZ(), wall, 4),
              PointToPolygonFormFactor(Vec3::Zero(), Vec3::UnitZ(), upper, 4), 1e-14);
}

TEST(FormFactors, ParallelCoaxialSquares) {
  for (const double distance : {0.5, 1.0, 2.0}) {
    Scene scene;
    scene.surfaces.push_back(MakeRectangle(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), 0.5, Vec3::Ones()));
    scene.surfaces.push_back(MakeRectangle(Vec3(0, 0, distance), Vec3(0, 1, 0), Vec3(1, 0, 0), 0.5, Vec3::Ones()));
    for (const int patches : {8, 128}) {
      const Computed computed = Compute(scene, patches);
      const double expected = ParallelRectangles(1.0, 1.0, distance);
      EXPECT_NEAR(SurfaceFormFactor(computed.patches.fine, computed.f, 0, 1), expected, 2e-3 * expected)
          << "distance " << distance << ", " << patches << " patches";
      EXPECT_NEAR(SurfaceFormFactor(computed.patches.fine, computed.f, 1, 0), expected, 2e-3 * expected);
    }
  }
}

TEST(FormFactors, PerpendicularRectanglesSharingAnEdge) {
  // Floor 1 (x) × 2 (y, the shared edge); wall along y, 0.6 high.
  Scene scene;
  scene.surfaces.push_back(MakeRectangle(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 2, 0), 0.5, Vec3::Ones()));
  scene.surfaces.push_back(MakeRectangle(Vec3(0, 0, 0), Vec3(0, 2, 0), Vec3(0, 0, 0.6), 0.5, Vec3::Ones()));
  for (const int patches : {8, 200}) {
    const Computed computed = Compute(scene, patches);
    const double floor_to_wall = PerpendicularRectangles(1.0, 0.6, 2.0);
    const double wall_to_floor = PerpendicularRectangles(0.6, 1.0, 2.0);
    EXPECT_NEAR(SurfaceFormFactor(computed.patches.fine, computed.f, 0, 1), floor_to_wall, 5e-3 * floor_to_wall)
        << patches << " patches";
    EXPECT_NEAR(SurfaceFormFactor(computed.patches.fine, computed.f, 1, 0), wall_to_floor, 5e-3 * wall_to_floor);
  }
}

TEST(FormFactors, ClosedBoxRowsSumToOne) {
  BoxRoomOptions options;
  options.occluder = false;
  const Computed computed = Compute(MakeBoxRoom(options), 600);
  const Eigen::VectorXd rows = computed.f.rowwise().sum();
  EXPECT_LT((rows.array() - 1.0).abs().maxCoeff(), 1e-3);
  EXPECT_LT(computed.summary.max_reciprocity_error, 1e-12);
  EXPECT_GE(computed.f.minCoeff(), 0.0);
  // Patches of one planar wall do not see each other.
  for (int i = 0; i < computed.patches.fine.size(); ++i) {
    for (int j = 0; j < computed.patches.fine.size(); ++j) {
      if (computed.patches.fine.patches[i].surface == computed.patches.fine.patches[j].surface) {
        ASSERT_EQ(computed.f(i, j), 0.0);
      }
    }
  }
}

TEST(FormFactors, OccluderCastsTheExpectedShadow) {
  // A small emitter under the centre of a 2 m square receiver 1 m above. Unoccluded it sees
  // four corner rectangles; a plate just below the receiver covering x > 0 hides two of them.
  Scene open;
  open.surfaces.push_back(MakeRectangle(Vec3(-0.01, -0.01, 0), Vec3(0.02, 0, 0), Vec3(0, 0.02, 0), 0.5, Vec3::Ones()));
  open.surfaces.push_back(MakeRectangle(Vec3(-1, -1, 1), Vec3(0, 2, 0), Vec3(2, 0, 0), 0.5, Vec3::Ones()));
  Scene shadowed = open;
  shadowed.surfaces.push_back(MakeRectangle(Vec3(0, -1.5, 0.98), Vec3(0, 3, 0), Vec3(1.5, 0, 0), 0.5, Vec3::Ones()));
  const double quarter = ElementToCornerRectangle(1.0, 1.0, 1.0);
  const Computed unoccluded = Compute(open, 64);
  const Computed occluded = Compute(shadowed, 64);
  EXPECT_NEAR(SurfaceFormFactor(unoccluded.patches.fine, unoccluded.f, 0, 1), 4 * quarter, 2e-3 * quarter);
  EXPECT_NEAR(SurfaceFormFactor(occluded.patches.fine, occluded.f, 0, 1), 2 * quarter, 2e-3 * quarter);
  EXPECT_GT(occluded.summary.shadow_rays, 0);
}

TEST(FormFactors, MeshCubeRowsSumToOne) {
  testing::TempDir dir;
  // A unit cube with inward-facing quads (counter-clockwise seen from inside).
  dir.Write("cube.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
            "f 1 2 3 4\nf 5 8 7 6\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 4 8 5 1\n");
  Scene scene;
  Surface cube;
  LoadObjMesh(dir / "cube.obj", 1e-6, &cube);
  cube.reflectance = Vec3::Constant(0.5);
  scene.surfaces.push_back(cube);
  const Computed computed = Compute(scene, 700);
  EXPECT_EQ(computed.patches.fine.patches.front().corner_count, 3);
  const Eigen::VectorXd rows = computed.f.rowwise().sum();
  EXPECT_LT((rows.array() - 1.0).abs().maxCoeff(), 1e-3);
}

TEST(FormFactors, AggregationConservesExchange) {
  BoxRoomOptions options;
  const Computed computed = Compute(MakeBoxRoom(options), 300);
  const PatchHierarchy& h = computed.patches;
  const Eigen::MatrixXd coarse = AggregateFormFactors(computed.f, h.fine.Areas(), h.coarse_of_fine, h.coarse.size());
  const Eigen::VectorXd coarse_area = h.coarse.Areas();
  // Total exchange between coarse patches equals the sum over their children.
  const double fine_total = (h.fine.Areas().asDiagonal() * computed.f).sum();
  const double coarse_total = (coarse_area.asDiagonal() * coarse).sum();
  EXPECT_NEAR(coarse_total, fine_total, 1e-9 * fine_total);
  FormFactorSummary summary;
  SummariseFormFactors(coarse, coarse_area, &summary);
  EXPECT_LT(summary.max_reciprocity_error, 1e-9);
  EXPECT_LE(summary.max_row_sum, 1.0 + 1e-3);
}

TEST(FormFactors, RoomWithOccluderKeepsRowsAtMostOneAndReciprocity) {
  const Computed computed = Compute(MakeBoxRoom(BoxRoomOptions()), 400);
  EXPECT_LE(computed.summary.max_row_sum, 1.0 + 1e-12);
  EXPECT_LT(computed.summary.max_row_correction, 0.03);  // noise-level cut only
  EXPECT_LT(computed.summary.max_reciprocity_error, 1e-12);
  // Rows of wall patches (nothing hides them from the whole enclosure) still sum to ~1.
  for (int i = 0; i < computed.patches.fine.size(); ++i) {
    if (computed.patches.fine.patches[i].surface == 1) {  // ceiling
      EXPECT_NEAR(computed.f.row(i).sum(), 1.0, 0.02);
    }
  }
}

TEST(LimitRowSums, ScalesSymmetricallyToAtMostOne) {
  Eigen::VectorXd area(3);
  area << 1.0, 2.0, 4.0;
  Eigen::MatrixXd exchange(3, 3);  // symmetric G = diag(A) F
  exchange << 0.0, 0.7, 0.5, 0.7, 0.0, 1.0, 0.5, 1.0, 0.0;
  Eigen::MatrixXd f = area.cwiseInverse().asDiagonal() * exchange;  // row 0 sums to 1.2
  const double cut = LimitRowSums(&f);
  EXPECT_NEAR(cut, 1.0 - 1.0 / 1.2, 1e-15);
  EXPECT_LE(f.rowwise().sum().maxCoeff(), 1.0 + 1e-15);
  const Eigen::MatrixXd g = area.asDiagonal() * f;
  EXPECT_LT(testing::MaxAbsDifference(g, g.transpose()), 1e-15);
  EXPECT_NEAR(f(1, 2), 0.5, 1e-15);  // rows already at most 1 keep their entries between them
}

TEST(FormFactorOptions, RejectsBadSettings) {
  FormFactorOptions options;
  std::string why;
  EXPECT_TRUE(options.Check(&why));
  options.near_samples = 1;
  options.far_samples = 2;
  EXPECT_FALSE(options.Check(&why));
  EXPECT_FALSE(why.empty());
}

}  // namespace
}  // namespace procam
