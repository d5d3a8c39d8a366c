#include "datasets_synthetic/simulated_rig.h"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>

#include "compensation/colour.h"
#include "compensation/colour_image.h"
#include "compensation/radiosity.h"
#include "geometry/form_factors.h"
#include "projection/projection_rig.h"

namespace procam {
namespace {

struct World {
  SyntheticScene synthetic;
  PatchHierarchy patches;  // the solver's level
  std::vector<Projector> projectors;
  std::unique_ptr<SimulatedRig> rig;
};

World MakeWorld(int solver_patches, const SimulatedCameraOptions& camera,
                double albedo_variation = 0.0, bool smooth_bounce = false) {
  World world;
  world.synthetic = MakeSyntheticScene("tiny_box", solver_patches);
  SubdivisionOptions subdivision;
  subdivision.target_patches = solver_patches;
  world.patches = SubdividePatches(world.synthetic.scene, subdivision);
  for (const DevicePlacement& placement : world.synthetic.projectors) {
    world.projectors.push_back(ProjectorFromPlacement(placement));
  }
  SimulatedRigOptions options;
  options.solver_patches = solver_patches;
  options.camera = camera;
  options.albedo_variation = albedo_variation;
  options.smooth_bounce = smooth_bounce;
  world.rig = std::make_unique<SimulatedRig>(world.synthetic.scene, world.projectors,
                                             CameraFromPlacement(world.synthetic.camera), options);
  return world;
}

// The solver patch each camera pixel sees (−1 for none).
std::vector<int> SolverPatchPerPixel(const World& world) {
  const RayScene patches(PatchScene(world.patches.fine));
  const CameraGeometry& camera = world.rig->camera();
  std::vector<Vec3> directions;
  std::vector<double> densities;
  camera.UnprojectImage(&directions, &densities);
  const Eigen::Isometry3d world_from_cam = camera.proj_from_world().inverse();
  std::vector<int> patch_of(directions.size(), -1);
  for (size_t k = 0; k < directions.size(); ++k) {
    double t;
    int patch;
    if (patches.Intersect(world_from_cam.translation(), world_from_cam.linear() * directions[k],
                          0.0, std::numeric_limits<double>::infinity(), &t, &patch)) {
      patch_of[k] = patch;
    }
  }
  return patch_of;
}

TEST(SimulatedRig, OneLitPatchPhotographsAsTheRadiosityModelPredicts) {
  SimulatedCameraOptions camera;
  camera.vignetting = 0.0;  // compare exitance directly
  const World world = MakeWorld(100, camera);
  const PatchLevel& level = world.patches.fine;
  const ProjectionRig rig = BuildProjectionRig(level, world.projectors, ProjectionRigOptions());
  // Light one back-wall patch the camera sees well; everything else at the projectors' black.
  const std::vector<int> patch_of = SolverPatchPerPixel(world);
  std::vector<int> pixel_count(level.size(), 0);
  for (const int patch : patch_of) {
    if (patch >= 0) ++pixel_count[patch];
  }
  int lit = -1;
  for (int i = 0; i < level.size(); ++i) {
    if (world.synthetic.scene.surfaces[level.patches[i].surface].name == "back wall" &&
        rig.upper(i, 0) > 0.0 && (lit < 0 || pixel_count[i] > pixel_count[lit])) {
      lit = i;
    }
  }
  ASSERT_GE(lit, 0);
  Eigen::MatrixX3d emittance = rig.lower;
  emittance.row(lit) = 0.7 * rig.upper.row(lit);
  RenderSummary render;
  const std::vector<ProjectorImage> images =
      RenderProjectorImages(rig, emittance, RenderOptions(), &render);

  // The solver's model of the result: B = K⁻¹ E, with E what the images deliver.
  const Eigen::MatrixXd f =
      ComputeFormFactors(world.synthetic.scene, level, FormFactorOptions(), nullptr);
  const RadiositySystem radiosity(f, level.Areas(), level.reflectance);
  const Eigen::MatrixX3d predicted = radiosity.Solve(render.delivered);

  const cv::Mat photo = world.rig->PhotographLinear(images);
  Eigen::MatrixX3d measured = Eigen::MatrixX3d::Zero(level.size(), 3);
  for (size_t k = 0; k < patch_of.size(); ++k) {
    if (patch_of[k] < 0) continue;
    const cv::Vec3f& value =
        photo.at<cv::Vec3f>(static_cast<int>(k / photo.cols), static_cast<int>(k % photo.cols));
    measured.row(patch_of[k]) +=
        Eigen::RowVector3d(value[0], value[1], value[2]) / pixel_count[patch_of[k]];
  }
  // The lit patch: within 10%. The world lights it pixel by pixel, so light of projector pixels
  // straddling its border spills onto neighbours (the model puts all of it on the patch), and
  // the camera's pixel mean weights the patch by perspective. Bounce-lit patches the camera
  // sees well: within 15% of the model plus the noise of their pixel mean (the world's
  // bounces come from a 4× finer mesh and exact direct light).
  EXPECT_NEAR(measured(lit, 1), predicted(lit, 1), 0.10 * predicted(lit, 1));
  int compared = 0;
  for (int i = 0; i < level.size(); ++i) {
    if (i == lit || pixel_count[i] < 30) continue;
    const double noise = 4.0 *
                         std::sqrt(camera.shot_noise * camera.shot_noise * predicted(i, 1) +
                                   camera.read_noise * camera.read_noise) /
                         std::sqrt(pixel_count[i]);
    EXPECT_NEAR(measured(i, 1), predicted(i, 1), 0.15 * predicted(i, 1) + noise) << "patch " << i;
    ++compared;
  }
  EXPECT_GT(compared, 10);
  // Bounces are really there: patches far from the lit one are brighter than black alone.
  EXPECT_GT(predicted.col(1).minCoeff(), render.delivered.col(1).minCoeff());
}

TEST(SimulatedRig, KnownPointsLandWhereTheCameraModelProjectsThem) {
  SimulatedCameraOptions camera;
  camera.shot_noise = camera.read_noise = 0.0;
  camera.vignetting = 0.0;
  const World world = MakeWorld(400, camera);
  const PatchLevel& level = world.patches.fine;
  const ProjectionRig rig = BuildProjectionRig(level, world.projectors, ProjectionRigOptions());
  int tested = 0;
  for (int i = 0; i < level.size() && tested < 3; i += 37) {
    if (rig.upper(i, 0) <= 0.0) continue;
    Vec2 expected;
    if (!world.rig->camera().Project(level.patches[i].centroid, &expected) ||
        !world.rig->camera().InImage(expected)) {
      continue;
    }
    Eigen::MatrixX3d emittance = Eigen::MatrixX3d::Zero(level.size(), 3);
    emittance.row(i) = rig.upper.row(i);
    RenderSummary render;
    RenderOptions options;
    options.dither = DitherMethod::kNone;
    const cv::Mat radiance = world.rig->RenderRadiance(
        RenderProjectorImages(rig, emittance.cwiseMax(rig.lower), options, &render));
    // Centroid of the directly lit spot: pixels well above the bounce and black levels.
    double peak = 0.0;
    for (int r = 0; r < radiance.rows; ++r)
      for (int c = 0; c < radiance.cols; ++c)
        peak = std::max(peak, double(radiance.at<cv::Vec3f>(r, c)[1]));
    Vec2 sum = Vec2::Zero();
    double weight = 0.0;
    for (int r = 0; r < radiance.rows; ++r) {
      for (int c = 0; c < radiance.cols; ++c) {
        const double v = radiance.at<cv::Vec3f>(r, c)[1];
        if (v > 0.5 * peak) {
          sum += Vec2(c, r);
          weight += 1.0;
        }
      }
    }
    ASSERT_GT(weight, 4.0);
    EXPECT_LT((sum / weight - expected).norm(), 1.5)
        << "patch " << i << " expected at " << expected.transpose();
    ++tested;
  }
  EXPECT_EQ(tested, 3);
}

TEST(SimulatedRig, TexturedAlbedoModulatesWhatTheCameraSees) {
  SimulatedCameraOptions camera;
  camera.shot_noise = camera.read_noise = 0.0;
  const World plain = MakeWorld(100, camera, 0.0);
  const World textured = MakeWorld(100, camera, 0.2);
  const ProjectionRig rig =
      BuildProjectionRig(plain.patches.fine, plain.projectors, ProjectionRigOptions());
  RenderSummary render;
  const auto images =
      RenderProjectorImages(rig, 0.5 * (rig.lower + rig.upper), RenderOptions(), &render);
  const cv::Mat a = plain.rig->RenderRadiance(images), b = textured.rig->RenderRadiance(images);
  // On the back wall (surface 1: corner 0 at (1, 1, 0), u up along z, v along −x), the ratio of
  // the two renders follows the albedo pattern at the point's texture coordinate.
  double sum_xy = 0, sum_xx = 0, sum_yy = 0, sum_x = 0, sum_y = 0, abs_difference = 0;
  int count = 0;
  for (int row = 0; row < a.rows; row += 2) {
    for (int col = 0; col < a.cols; col += 2) {
      Vec3 point, normal;
      if (!plain.rig->PointSeenByPixel(row, col, &point, &normal) ||
          std::abs(point.y() - 1.0) > 1e-6)
        continue;
      const double ratio = b.at<cv::Vec3f>(row, col)[1] / a.at<cv::Vec3f>(row, col)[1];
      const double albedo = textured.rig->AlbedoFactor(1, Vec2(point.z(), 1.0 - point.x()));
      abs_difference += std::abs(ratio - albedo);
      sum_x += albedo, sum_y += ratio, sum_xy += albedo * ratio, sum_xx += albedo * albedo,
          sum_yy += ratio * ratio;
      ++count;
    }
  }
  ASSERT_GT(count, 200);
  const double cov = sum_xy / count - sum_x * sum_y / count / count;
  const double correlation = cov / std::sqrt((sum_xx / count - sum_x * sum_x / count / count) *
                                             (sum_yy / count - sum_y * sum_y / count / count));
  // The direct light follows the albedo exactly; the bounces change too (the world's patches
  // reflect with their own albedo), smoothly, which blurs the relation a little.
  EXPECT_GT(correlation, 0.8);
  EXPECT_LT(abs_difference / count, 0.05);  // the pattern's amplitude is 0.2
  std::printf("albedo: correlation %.3f, mean |ratio - albedo| %.4f over %d pixels\n", correlation,
              abs_difference / count, count);
  EXPECT_EQ(plain.rig->AlbedoFactor(1, Vec2(0.3, 0.7)), 1.0);
}

// Bounce light constant per world patch steps at world-patch borders, which are also the solver
// patches' borders: seams in the camera's view that no projector image causes. Interpolated
// between the world patches' centroids it keeps its level and loses the steps.
TEST(SimulatedRig, SmoothBounceLightHasNoPatchSteps) {
  SimulatedCameraOptions camera;
  camera.shot_noise = camera.read_noise = 0.0;
  const World stepped = MakeWorld(400, camera, 0.0, false);
  const World smooth = MakeWorld(400, camera, 0.0, true);
  const ProjectionRig rig =
      BuildProjectionRig(stepped.patches.fine, stepped.projectors, ProjectionRigOptions());
  // Every projector pixel at one code, so that the projectors add no steps of their own.
  std::vector<ProjectorImage> images(stepped.projectors.size());
  for (size_t k = 0; k < images.size(); ++k) {
    const ProjectorGeometry& geometry = stepped.projectors[k].geometry;
    images[k].codes = cv::Mat(geometry.height(), geometry.width(), CV_16UC3, cv::Scalar::all(160));
  }
  const cv::Mat a = stepped.rig->RenderRadiance(images), b = smooth.rig->RenderRadiance(images);
  const std::vector<int> patch_of = SolverPatchPerPixel(stepped);
  const cv::Mat patch(a.rows, a.cols, CV_32SC1, const_cast<int*>(patch_of.data()));
  const LabConverter lab = LabConverter::ForWhite(SrgbToXyzMatrix(), stepped.synthetic.scene.white);
  const cv::Mat desired = LabImage(stepped.rig->RenderDesired(), lab);
  const SeamMeasure seams_stepped = MeasureSeams(LabImage(a, lab), desired, patch, rig.surface);
  const SeamMeasure seams_smooth = MeasureSeams(LabImage(b, lab), desired, patch, rig.surface);
  std::printf("seam with bounce light per world patch %.3f, smooth %.3f\n", seams_stepped.seam,
              seams_smooth.seam);
  EXPECT_LT(seams_smooth.seam, 0.5 * seams_stepped.seam);
  EXPECT_NEAR(cv::mean(b, stepped.rig->coverage())[1] / cv::mean(a, stepped.rig->coverage())[1],
              1.0, 0.02);
}

TEST(SimulatedRig, PhotosAreQuantisedThroughTheResponseAndRejectWrongInput) {
  const World world = MakeWorld(64, SimulatedCameraOptions());
  const ProjectionRig rig =
      BuildProjectionRig(world.patches.fine, world.projectors, ProjectionRigOptions());
  RenderSummary render;
  const auto images =
      RenderProjectorImages(rig, 0.5 * (rig.lower + rig.upper), RenderOptions(), &render);
  const cv::Mat photo = world.rig->Photograph8(images);
  EXPECT_EQ(photo.type(), CV_8UC3);
  EXPECT_EQ(photo.cols, world.rig->camera().width());
  EXPECT_GT(cv::countNonZero(world.rig->coverage()),
            2 * photo.rows * photo.cols / 5);  // the box fills the view
  EXPECT_THROW(world.rig->RenderRadiance({images.front()}), std::invalid_argument);
  const cv::Mat desired = world.rig->RenderDesired();
  EXPECT_EQ(desired.type(), CV_32FC3);
  SimulatedRigOptions bad;
  bad.camera.exposure = 0.0;
  std::string why;
  EXPECT_FALSE(bad.Check(&why));
}

}  // namespace
}  // namespace procam
