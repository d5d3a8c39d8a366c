// Pixel → patch maps and the direct-light bounds they give, against closed forms: the
// irradiance of a pinhole projector on a plane (output · cos θ / (cos³ψ d²)), shadows computed
// by ray–rectangle tests written here, exact coarsening, and seam-free blending weights.
#include "projection/projection_rig.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "base/io.h"
#include "tests/projection/stage.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::MakeStage;
using testing::Stage;
using testing::StageOptions;

// Irradiance per unit output of a pinhole projector at a point, from first principles: equal
// flux per pixel means intensity ∝ 1/cos³ψ (ψ off the axis), then cos θ / d².
double PinholeIrradiance(const ProjectorGeometry& geometry, const Vec3& point, const Vec3& normal) {
  const Vec3 centre = geometry.proj_from_world().inverse().translation();
  const Vec3 axis = geometry.proj_from_world().rotation().row(2).transpose();
  const Vec3 to_point = point - centre;
  const double d = to_point.norm();
  const double cos_psi = axis.dot(to_point) / d;
  const double cos_theta = -normal.dot(to_point) / d;
  return cos_theta / (cos_psi * cos_psi * cos_psi * d * d);
}

// Does the segment from `from` to `to` cross rectangle surface `surface` (quad corners)?
bool SegmentCrossesRectangle(const Vec3& from, const Vec3& to, const Surface& surface) {
  const Vec3 origin = surface.quad[0], u = surface.quad[1] - origin, v = surface.quad[3] - origin;
  const Vec3 normal = u.cross(v).normalized();
  const double a = normal.dot(from - origin), b = normal.dot(to - origin);
  if (a * b >= 0.0) return false;
  const Vec3 hit = from + a / (a - b) * (to - from);
  const double s = (hit - origin).dot(u) / u.squaredNorm(),
               t = (hit - origin).dot(v) / v.squaredNorm();
  return s > 0.0 && s < 1.0 && t > 0.0 && t < 1.0;
}

bool FullyInImage(const ProjectorGeometry& geometry, const Patch& patch) {
  for (int k = 0; k < patch.corner_count; ++k) {
    Vec2 q;
    if (!geometry.Project(patch.corners[k], &q)) return false;
    if (q.x() < 1.0 || q.y() < 1.0 || q.x() > geometry.width() - 2.0 ||
        q.y() > geometry.height() - 2.0)
      return false;
  }
  return true;
}

TEST(ProjectionRig, BoundsMatchThePinholeIrradianceIntegral) {
  StageOptions options;
  options.plate = false;
  options.width = 640;
  options.height = 480;
  Stage stage = MakeStage(options);
  stage.projectors.resize(1);  // left alone
  const ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
  const PatchLevel& level = stage.patches.fine;
  const Projector& projector = stage.projectors[0];
  int compared = 0;
  double worst = 0.0, flux_rig = 0.0, flux_exact = 0.0;
  std::vector<PatchSample> samples;
  for (int i = 0; i < level.size(); ++i) {
    if (!FullyInImage(projector.geometry, level.patches[i])) continue;
    SamplePatch(level.patches[i], 8, &samples);
    double integral = 0.0;
    for (const PatchSample& sample : samples) {
      integral += sample.weight *
                  PinholeIrradiance(projector.geometry, sample.point, level.patches[i].normal);
    }
    const double exact =
        level.reflectance(i, 1) * projector.photometry.max[1] * integral / level.patches[i].area;
    worst = std::max(worst, std::abs(rig.upper(i, 1) / exact - 1.0));
    flux_rig += rig.upper(i, 1) * level.patches[i].area;
    flux_exact += exact * level.patches[i].area;
    EXPECT_NEAR(rig.lower(i, 1) / rig.upper(i, 1),
                projector.photometry.black[1] / projector.photometry.max[1], 1e-12);
    ++compared;
  }
  EXPECT_GT(compared, 40);
  // Patches wholly in the image have their pixel footprints rescaled to their exact area
  // (projection_rig.h), which leaves a second-order error (measured 8e-4 worst).
  EXPECT_LT(worst, 2e-3);
  EXPECT_NEAR(flux_rig / flux_exact, 1.0, 1e-4);
}

TEST(ProjectionRig, OccludedPointsGetNoLightAndPixelsStopAtThePlate) {
  Stage stage = MakeStage({});
  stage.projectors.resize(1);
  const Projector& projector = stage.projectors[0];
  const ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
  const PatchLevel& level = stage.patches.fine;
  const Vec3 centre = projector.geometry.CentreInWorld();
  const Surface& plate = stage.scene.surfaces[Stage::kPlate];
  int shadowed = 0;
  for (int i = 0; i < level.size(); ++i) {
    const Patch& patch = level.patches[i];
    if (patch.surface == Stage::kPlate) {
      EXPECT_GT(rig.upper(i, 0), 0.0);
      continue;
    }
    bool all_corners_shadowed = true;
    for (int k = 0; k < patch.corner_count; ++k) {
      all_corners_shadowed &= SegmentCrossesRectangle(patch.corners[k], centre, plate);
    }
    if (!all_corners_shadowed) continue;
    ++shadowed;
    EXPECT_EQ(rig.upper(i, 0), 0.0) << "patch " << i << " behind the plate";
    EXPECT_EQ(rig.lower(i, 0), 0.0);
  }
  EXPECT_GT(shadowed, 2);
  // Every pixel whose ray crosses the plate lights a plate patch.
  const ProjectorMap& map = rig.maps[0];
  const Eigen::Isometry3d world_from_proj = projector.geometry.proj_from_world().inverse();
  int on_plate = 0;
  for (int y = 0; y < map.height; ++y) {
    for (int x = 0; x < map.width; ++x) {
      const Vec3 far = world_from_proj * (20.0 * projector.geometry.Unproject(Vec2(x, y)));
      if (!SegmentCrossesRectangle(centre, far, plate)) continue;
      const int patch = map.patch[size_t(y) * map.width + x];
      ASSERT_GE(patch, 0);
      // A ray grazing the plate's rim may miss it in single precision; the rest must hit it.
      if (level.patches[patch].surface == Stage::kPlate) ++on_plate;
    }
  }
  EXPECT_GT(on_plate, 500);
}

// A patch cut by the plate's shadow or an image border: its bounds are its lit part's, the
// patch's mean bounds divided by its lit fraction, and that fraction is the part of the patch
// some projector lights, measured here with 32² quadrature points tested against the images and
// the plate by the ray–rectangle test above.
TEST(ProjectionRig, PartlyLitPatchesBoundTheirLitPart) {
  const Stage stage = MakeStage({});
  const PatchLevel& level = stage.patches.fine;
  const ProjectionRig rig = BuildProjectionRig(level, stage.projectors, {});
  ProjectionRigOptions mean_options;
  mean_options.lit_part = false;
  const ProjectionRig mean = BuildProjectionRig(level, stage.projectors, mean_options);
  const Surface& plate = stage.scene.surfaces[Stage::kPlate];
  int partly = 0;
  std::vector<PatchSample> samples;
  for (int i = 0; i < level.size(); ++i) {
    const Patch& patch = level.patches[i];
    SamplePatch(patch, 32, &samples);
    double lit_area = 0.0;
    for (const PatchSample& sample : samples) {
      bool lit = false;
      for (const Projector& projector : stage.projectors) {
        Vec2 q;
        const Vec3 centre = projector.geometry.CentreInWorld();
        lit |= projector.geometry.Project(sample.point, &q) && q.x() > -0.5 && q.y() > -0.5 &&
               q.x() < projector.geometry.width() - 0.5 &&
               q.y() < projector.geometry.height() - 0.5 &&
               patch.normal.dot(centre - sample.point) > 0.0 &&
               (patch.surface == Stage::kPlate ||
                !SegmentCrossesRectangle(sample.point, centre, plate));
      }
      if (lit) lit_area += sample.weight;
    }
    const double fraction = lit_area / rig.area[i];
    if (rig.lit_fraction[i] == 0.0) {
      EXPECT_LT(fraction, 0.02) << "patch " << i << " unreached";
      continue;
    }
    // The lit area counts the pixels whose centre falls on the patch: half a pixel row along
    // the cut (patches here are about 20 pixels across).
    EXPECT_NEAR(rig.lit_fraction[i], fraction, 0.05) << "patch " << i;
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(rig.upper(i, c) * rig.lit_fraction[i], mean.upper(i, c), 1e-12 * mean.upper(i, c));
      EXPECT_NEAR(rig.lower(i, c) * rig.lit_fraction[i], mean.lower(i, c), 1e-12 * mean.lower(i, c));
    }
    if (rig.lit_fraction[i] < 0.9) ++partly;
    EXPECT_EQ(mean.lit_fraction[i], 1.0);
  }
  EXPECT_GT(partly, 5);
}

TEST(ProjectionRig, CoarseBoundsAreTheAreaWeightedFineBounds) {
  const Stage stage = MakeStage({});
  const ProjectionRig fine = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
  const ProjectionRig coarse = BuildProjectionRig(stage.patches.coarse, stage.projectors, {});
  // Compared as each patch's mean (a partly lit patch's bounds are its lit part's: f × bound).
  const auto mean = [](const ProjectionRig& rig, const Eigen::MatrixX3d& bound) {
    return Eigen::MatrixX3d(rig.lit_fraction.asDiagonal() * bound);
  };
  const Eigen::MatrixX3d upper = CoarsenPatchValues(mean(fine, fine.upper), fine.area,
                                                    stage.patches.coarse_of_fine,
                                                    stage.patches.coarse.size());
  const Eigen::MatrixX3d lower = CoarsenPatchValues(mean(fine, fine.lower), fine.area,
                                                    stage.patches.coarse_of_fine,
                                                    stage.patches.coarse.size());
  // Same pixels, same hit points, and the children tile their parent; what differs is where
  // the pixel count is rescaled to exact areas (projection_rig.h): per child or per parent, and
  // only where wholly lit. Both approximate the same integral to a fraction of a pixel row.
  const Eigen::MatrixX3d coarse_upper = mean(coarse, coarse.upper);
  const Eigen::MatrixX3d coarse_lower = mean(coarse, coarse.lower);
  EXPECT_LT((upper - coarse_upper).cwiseAbs().maxCoeff(), 5e-3 * coarse_upper.maxCoeff());
  EXPECT_LT((lower - coarse_lower).cwiseAbs().maxCoeff(), 5e-3 * coarse_lower.maxCoeff());
  // Summed over the room (exitance × area: reflected flux), the two levels agree closely.
  EXPECT_NEAR(fine.area.dot(mean(fine, fine.upper).col(1)) /
                  coarse.area.dot(coarse_upper.col(1)),
              1.0, 2e-3);
}

// Within 8 pixels (a third of the blending ramp) of a left pixel that lights the plate: where
// the plate's shadows from both projectors begin at nearly the same place on the wall (its
// bottom edge here), both projectors fade out together and their ratio turns within a few
// pixels; the shadow edge itself is there, so it shows no seam.
bool NearSilhouette(const ProjectorMap& map, const PatchLevel& level, int x, int y) {
  for (int dy = -8; dy <= 8; ++dy) {
    for (int dx = -8; dx <= 9; ++dx) {
      const int nx = x + dx, ny = y + dy;
      if (nx < 0 || ny < 0 || nx >= map.width || ny >= map.height) continue;
      const int patch = map.patch[size_t(ny) * map.width + nx];
      if (patch >= 0 && level.patches[patch].surface == Stage::kPlate) return true;
    }
  }
  return false;
}

TEST(ProjectionRig, BlendWeightsSumToOneAndFeatherRemovesSeams) {
  const Stage stage = MakeStage({});
  const PatchLevel& level = stage.patches.fine;
  auto largest_jump = [&](double feather) {
    ProjectionRigOptions options;
    options.feather = feather;
    const ProjectionRig rig = BuildProjectionRig(level, stage.projectors, options);
    const ProjectorMap& left = rig.maps[0];
    const ProjectorMap& right = rig.maps[1];
    const ProjectorGeometry& left_geometry = stage.projectors[0].geometry;
    const ProjectorGeometry& right_geometry = stage.projectors[1].geometry;
    const Eigen::Isometry3d world_from_left = left_geometry.proj_from_world().inverse();
    double jump = 0.0, worst_sum = 0.0;
    int overlap = 0;
    for (int y = 0; y < left.height; ++y) {
      for (int x = 0; x < left.width; ++x) {
        const size_t index = size_t(y) * left.width + x;
        const int patch = left.patch[index];
        if (patch < 0 || level.patches[patch].surface != Stage::kWall) continue;
        if (x + 1 < left.width && left.patch[index + 1] >= 0 &&
            level.patches[left.patch[index + 1]].surface == Stage::kWall) {
          if (!NearSilhouette(left, level, x, y)) {
            const double j = std::abs(left.weight[index + 1] - left.weight[index]);
            jump = std::max(jump, j);
          }
        }
        if (left.weight[index] > 0.999f || NearSilhouette(left, level, x, y)) continue;
        // The wall point this pixel lights, seen from the right projector.
        const Vec3 direction = world_from_left.rotation() * left_geometry.Unproject(Vec2(x, y));
        const Vec3 centre = left_geometry.CentreInWorld();
        const Vec3 point = centre + (3.0 - centre.y()) / direction.y() * direction;
        Vec2 q;
        if (!right_geometry.Project(point, &q) || !right_geometry.InImage(q)) continue;
        const size_t other = size_t(std::lround(q.y())) * right.width + size_t(std::lround(q.x()));
        if (right.patch[other] != patch) continue;
        worst_sum = std::max(worst_sum, std::abs(left.weight[index] + right.weight[other] - 1.0));
        ++overlap;
      }
    }
    EXPECT_GT(overlap, 5000);
    return std::make_pair(jump, worst_sum);
  };
  const auto [jump, worst_sum] = largest_jump(0.1);
  // A 24-pixel C¹ ramp (steepest 1.5/24 per pixel of the right image, about as large here).
  EXPECT_LT(jump, 0.1);
  // Weights of the two projectors at the same point sum to 1; smooth weights make that hold
  // also between a pixel and the other projector's nearest pixel (≤ ½ pixel away).
  EXPECT_LT(worst_sum, 0.05);
  EXPECT_GT(largest_jump(0.0).first, 0.3);  // without the ramp the right image's border is a step
}

TEST(ProjectionRig, TextureCoordinatesInterpolateThePatchCorners) {
  // A parallelogram quad and a mesh triangle: on both the corners' uv map affinely, so the
  // barycentric interpolation gives SamplePatch's uv at its points exactly.
  Scene scene;
  Surface parallelogram =
      MakeRectangle(Vec3(0, 0, 0), Vec3(2, 0, 0), Vec3(0.7, 0, 1.5), 0.5, Vec3::Constant(0.5));
  std::swap(parallelogram.quad[1], parallelogram.quad[3]);  // lit side −y (order does not matter)
  Surface triangle;
  triangle.kind = Surface::Kind::kMesh;
  triangle.mesh_vertices = {Vec3(3, 0, 0), Vec3(5, 0.5, 0), Vec3(3.5, 0.2, 2)};
  MeshTriangle corners;
  corners.vertex = {0, 1, 2};
  corners.uv = {Vec2(0.1, 0.2), Vec2(0.9, 0.3), Vec2(0.4, 0.95)};
  triangle.mesh_triangles = {corners};
  // A trapezoid: its bilinear map is not affine; the two-triangle map differs at second order.
  Surface trapezoid =
      MakeRectangle(Vec3(0, 2, 0), Vec3(2, 0, 0), Vec3(0, 0, 1), 0.5, Vec3::Constant(0.5));
  trapezoid.quad[2] = Vec3(1.4, 2, 1);
  scene.surfaces = {parallelogram, triangle, trapezoid};
  SubdivisionOptions subdivision;
  subdivision.target_patches = 64;
  const PatchLevel level = SubdividePatches(scene, subdivision).fine;
  std::vector<PatchSample> samples;
  double affine_worst = 0.0, trapezoid_worst = 0.0, trapezoid_corner_worst = 0.0;
  for (const Patch& patch : level.patches) {
    SamplePatch(patch, 5, &samples);
    for (const PatchSample& sample : samples) {
      double& worst = patch.surface == 2 ? trapezoid_worst : affine_worst;
      worst = std::max(worst, (PatchTextureCoordinate(patch, sample.point) - sample.uv).norm());
    }
    for (int k = 0; k < patch.corner_count; ++k) {
      const double error = (PatchTextureCoordinate(patch, patch.corners[k]) - patch.uv[k]).norm();
      if (patch.surface == 2) trapezoid_corner_worst = std::max(trapezoid_corner_worst, error);
    }
  }
  EXPECT_LT(affine_worst, 1e-12);
  EXPECT_LT(trapezoid_corner_worst, 1e-12);
  EXPECT_LT(trapezoid_worst, 5e-3);  // cells 1/8 of the surface across: a few 1e-3 of its uv

  // The rig records each lit pixel's uv when asked: on the stage's wall (uv = (x/4, z/2.5)),
  // checked against the ray–plane intersection of the pixel's ray.
  const Stage stage = MakeStage({});
  EXPECT_TRUE(BuildProjectionRig(stage.patches.fine, stage.projectors, {}).maps[0].uv.empty());
  ProjectionRigOptions options;
  options.texture_coordinates = true;
  const ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, options);
  const ProjectorGeometry& geometry = stage.projectors[0].geometry;
  const ProjectorMap& map = rig.maps[0];
  ASSERT_EQ(map.uv.size(), map.patch.size());
  const Eigen::Isometry3d world_from_proj = geometry.proj_from_world().inverse();
  const Vec3 centre = geometry.CentreInWorld();
  double worst = 0.0;
  int wall_pixels = 0;
  for (int y = 0; y < map.height; ++y) {
    for (int x = 0; x < map.width; ++x) {
      const size_t index = size_t(y) * map.width + x;
      const int patch = map.patch[index];
      if (patch < 0 || stage.patches.fine.patches[patch].surface != Stage::kWall) continue;
      const Vec3 direction = world_from_proj.rotation() * geometry.Unproject(Vec2(x, y));
      const Vec3 point = centre + (3.0 - centre.y()) / direction.y() * direction;
      worst = std::max(
          worst, (map.uv[index].cast<double>() - Vec2(point.x() / 4, point.z() / 2.5)).norm());
      ++wall_pixels;
    }
  }
  EXPECT_GT(wall_pixels, 20000);
  EXPECT_LT(worst, 2e-6);  // single precision
  EXPECT_EQ(rig.surface.size(), size_t(rig.size()));
}

TEST(ProjectionRig, ProjectorThatLightsNothingIsAnError) {
  Stage stage = MakeStage({});
  stage.projectors[1].geometry = ProjectorGeometry::Pinhole(
      300, 300, 160, 120, 320, 240,
      ProjFromWorldLookingAt(Vec3(2, -1.5, 1.5), Vec3(2, -5, 1.5), Vec3::UnitZ()));
  try {
    BuildProjectionRig(stage.patches.fine, stage.projectors, {});
    FAIL() << "no error";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("projector 'right' lights no patch"),
              std::string::npos)
        << error.what();
  }
}

TEST(ProjectionRig, SetBoundsFromProjectorsReadsTheScene) {
  testing::TempDir dir;
  const Stage stage = MakeStage({});
  WriteCameraModel(dir / "left.cameramodel", stage.projectors[0].geometry);
  WriteCameraModel(dir / "right.cameramodel", stage.projectors[1].geometry);
  const auto path = dir.Write("stage.json", R"({
    "patches": 300,
    "projectors": [
      {"name": "left", "model": "left.cameramodel", "black": 0.02, "max": 12},
      {"name": "right", "model": "right.cameramodel", "black": 0.02, "max": 12}
    ],
    "surfaces": [
      {"name": "wall", "quad": [[0,3,0],[4,3,0],[4,3,2.5],[0,3,2.5]], "reflectance": 0.8, "desired": [0.5,0.5,0.5]},
      {"name": "floor", "quad": [[0,0,0],[4,0,0],[4,3,0],[0,3,0]], "reflectance": 0.6, "desired": [0.5,0.5,0.5]},
      {"name": "plate", "quad": [[1.6,2,0.9],[2.4,2,0.9],[2.4,2,1.6],[1.6,2,1.6]], "reflectance": 0.7, "desired": [0.5,0.5,0.5]}
    ]})");
  const Scene scene = LoadScene(path);
  const PatchLevel& level = stage.patches.fine;
  Eigen::MatrixX3d lower, upper;
  ASSERT_TRUE(SetBoundsFromProjectors(scene, level, &lower, &upper));
  const ProjectionRig rig = BuildProjectionRig(level, stage.projectors, {});
  EXPECT_LT((upper - rig.upper).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((lower - rig.lower).cwiseAbs().maxCoeff(), 1e-12);
  Scene bare = scene;
  bare.projectors_json.clear();
  EXPECT_FALSE(SetBoundsFromProjectors(bare, level, &lower, &upper));
}

}  // namespace
}  // namespace procam
