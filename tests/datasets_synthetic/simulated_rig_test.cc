#include "datasets_synthetic/simulated_rig.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/core.hpp>

#include "compensation/colour.h"
#include "compensation/colour_image.h"
#include "compensation/radiosity.h"
#include "datasets_synthetic/scene_files.h"
#include "datasets_synthetic/true_reflectance.h"
#include "geometry/form_factors.h"
#include "geometry/ray_scene.h"
#include "projection/projection_rig.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

struct World {
  SyntheticScene synthetic;
  PatchHierarchy patches;  // the solver's level
  std::vector<Projector> projectors;
  std::unique_ptr<SimulatedRig> rig;
};

World MakeWorld(int solver_patches, const SimulatedCameraOptions& camera,
                double albedo_variation = 0.0, bool smooth_bounce = false,
                const ReflectanceTexture& back_wall_print = ReflectanceTexture(),
                double other_reflectance = 0.0) {
  World world;
  world.synthetic = MakeSyntheticScene("tiny_box", solver_patches);
  if (other_reflectance > 0.0) {  // every surface but the back wall
    for (size_t s = 0; s < world.synthetic.scene.surfaces.size(); ++s) {
      if (s != 1) world.synthetic.scene.surfaces[s].reflectance = Vec3::Constant(other_reflectance);
    }
  }
  if (back_wall_print.HasTexture()) {
    Surface& back_wall = world.synthetic.scene.surfaces[1];
    back_wall.reflectance_texture = back_wall_print;
    back_wall.reflectance = back_wall_print.Mean();  // as LoadScene sets it
  }
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

// A poster on the back wall: a 4 × 4 checkerboard of linear reflectances 0.8 and 0.2 (× scale
// 0.9), 64 × 64 texels. The back wall's texture coordinate at a point is (z, 1 − x) (corner 0 at
// (1, 1, 0), u up along z, v along −x).
ReflectanceTexture CheckerPoster() {
  ReflectanceTexture poster;
  poster.texture_linear = cv::Mat(64, 64, CV_32FC3);
  for (int row = 0; row < 64; ++row) {
    for (int col = 0; col < 64; ++col) {
      const float value = ((row / 16 + col / 16) % 2 == 0) ? 0.8f : 0.2f;
      poster.texture_linear.at<cv::Vec3f>(row, col) = cv::Vec3f(value, value, value);
    }
  }
  poster.scale = 0.9;
  return poster;
}

// The poster's reflectance at UV, from the checkerboard's definition (row 0 = v near 1), and
// whether UV is more than one texel from a cell edge (where the bilinear lookup is the cell's).
double CheckerAt(const Vec2& uv, bool* inside_cell) {
  const double x = uv.x() * 64.0, y = (1.0 - uv.y()) * 64.0;
  const double fx = std::fmod(x, 16.0), fy = std::fmod(y, 16.0);
  *inside_cell = fx > 1.0 && fx < 15.0 && fy > 1.0 && fy < 15.0;
  const int col = std::clamp(static_cast<int>(x), 0, 63),
            row = std::clamp(static_cast<int>(y), 0, 63);
  return 0.9 * (((row / 16 + col / 16) % 2 == 0) ? 0.8 : 0.2);
}

// The world reflects the poster at each point, times the paint's albedo variation.
TEST(SimulatedRig, PrintedSurfaceReflectsItsTextureAtEachPoint) {
  SimulatedCameraOptions camera;
  camera.shot_noise = camera.read_noise = 0.0;
  const World printed = MakeWorld(100, camera, 0.05, false, CheckerPoster());
  int count = 0;
  for (int row = 0; row < printed.rig->camera().height(); ++row) {
    for (int col = 0; col < printed.rig->camera().width(); ++col) {
      Vec3 point;
      if (!printed.rig->PointSeenByPixel(row, col, &point) || std::abs(point.y() - 1.0) > 1e-6)
        continue;
      const Vec2 uv(point.z(), 1.0 - point.x());
      bool inside = false;
      const double truth = CheckerAt(uv, &inside) * printed.rig->AlbedoFactor(1, uv);
      if (!inside) continue;
      ASSERT_NEAR(printed.rig->ReflectanceSeenByPixel(row, col)[1], truth, 1e-5)
          << row << "," << col;
      ++count;
    }
  }
  EXPECT_GT(count, 1000);
}

// What the camera sees of a printed wall against the same wall painted evenly with the poster's
// mean: the ratio of the two renders is the poster's reflectance over its mean at each point.
// Direct light follows it exactly; the bounce light a pixel gets is its world patch's mean
// reflectance times the indirect irradiance there (the world mesh's patches are ¼ of a cell's
// side, so nearly all lie within one cell), and the other walls see the poster's mean, so the
// bounce follows it too, except on world patches that straddle a cell edge (left out here with
// the points within a texel of an edge) and through the small change in the bounce's layout.
TEST(SimulatedRig, PrintedSurfaceModulatesWhatTheCameraSees) {
  SimulatedCameraOptions camera;
  camera.shot_noise = camera.read_noise = 0.0;
  // The even wall: a one-texel print of the poster's mean, 0.9 × 0.5, so that the rest of the
  // room gets the same light back from it.
  ReflectanceTexture even;
  even.texture_linear = cv::Mat(1, 1, CV_32FC3, cv::Scalar::all(0.5));
  even.scale = 0.9;
  const World plain = MakeWorld(100, camera, 0.0, false, even);
  const World printed = MakeWorld(100, camera, 0.0, false, CheckerPoster());
  EXPECT_NEAR(printed.synthetic.scene.surfaces[1].reflectance[0], 0.45, 1e-6);
  EXPECT_NEAR(plain.synthetic.scene.surfaces[1].reflectance[0], 0.45, 1e-6);
  const ProjectionRig rig =
      BuildProjectionRig(plain.patches.fine, plain.projectors, ProjectionRigOptions());
  RenderSummary render;
  const auto images =
      RenderProjectorImages(rig, 0.5 * (rig.lower + rig.upper), RenderOptions(), &render);
  const cv::Mat a = plain.rig->RenderRadiance(images), b = printed.rig->RenderRadiance(images);
  double relative_error = 0.0;
  int count = 0, dark = 0, light = 0;
  for (int row = 0; row < a.rows; ++row) {
    for (int col = 0; col < a.cols; ++col) {
      Vec3 point;
      if (!plain.rig->PointSeenByPixel(row, col, &point) || std::abs(point.y() - 1.0) > 1e-6)
        continue;
      bool inside = false;
      const double rho = CheckerAt(Vec2(point.z(), 1.0 - point.x()), &inside);
      if (!inside || a.at<cv::Vec3f>(row, col)[1] <= 0.0f) continue;
      const double expected = rho / 0.45;
      const double ratio = b.at<cv::Vec3f>(row, col)[1] / a.at<cv::Vec3f>(row, col)[1];
      relative_error += std::abs(ratio - expected) / expected;
      ++count;
      (rho < 0.4 ? dark : light) += 1;
    }
  }
  ASSERT_GT(dark, 500);
  ASSERT_GT(light, 500);
  // A checkerboard of 4:1 contrast: a render that ignored the print would be 60% off on
  // average; followed at every point it is within the bounce light's change, a few per cent.
  EXPECT_LT(relative_error / count, 0.05);
  std::printf("printed wall: mean |ratio - truth| / truth %.4f over %d pixels\n",
              relative_error / count, count);
}

// A fine checkerboard poster: `cells` × `cells` cells of linear reflectance 0.8 and 0.2 (× 0.9),
// 16 texels each.
ReflectanceTexture FineChecker(int cells) {
  ReflectanceTexture poster;
  const int size = 16 * cells;
  poster.texture_linear = cv::Mat(size, size, CV_32FC3);
  for (int row = 0; row < size; ++row) {
    for (int col = 0; col < size; ++col) {
      const float value = ((row / 16 + col / 16) % 2 == 0) ? 0.8f : 0.2f;
      poster.texture_linear.at<cv::Vec3f>(row, col) = cv::Vec3f(value, value, value);
    }
  }
  poster.scale = 0.9;
  return poster;
}

// A printed wall written as a scene file (a 16-bit sRGB PNG and its scale) reads back as the
// same reflectance, within the PNG's quantisation (one 16-bit sRGB step: < 1e-4 in linear light).
TEST(SimulatedRig, PrintedSurfaceRoundTripsThroughASceneFile) {
  SyntheticScene synthetic = MakeSyntheticScene("tiny_box", 100);
  Surface& back_wall = synthetic.scene.surfaces[1];
  back_wall.reflectance_texture = FineChecker(4);
  back_wall.reflectance = back_wall.reflectance_texture.Mean();
  testing::TempDir dir;
  const std::filesystem::path file =
      WriteSyntheticSceneFile(synthetic, "printed", "a printed back wall", dir.path());
  const Scene scene = LoadScene(file);
  const Surface& read = scene.surfaces[1];
  ASSERT_TRUE(read.reflectance_texture.HasTexture());
  EXPECT_FALSE(scene.surfaces[0].reflectance_texture.HasTexture());
  EXPECT_EQ(read.reflectance_texture.scale, 0.9);
  for (const Vec2& uv : {Vec2(0.1, 0.1), Vec2(0.4, 0.1), Vec2(0.6, 0.9), Vec2(0.9, 0.35)}) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(read.ReflectanceAt(uv)[c], back_wall.ReflectanceAt(uv)[c], 1e-4);
    }
  }
  EXPECT_NEAR(read.reflectance[1], back_wall.reflectance[1], 1e-4);
}

// Per pixel rendering with the reflectance map: a wall printed with a checkerboard finer than the
// patches (16 × 16 cells of 4:1 contrast on the 1 m back wall, about 4 cells per patch side), lit
// with the same emittance by images rendered without and with RenderOptions::reflectance and
// photographed by the synthetic camera (noise off). Returns the pixel-weighted mean over the back
// wall's patches of each patch's coefficient of variation (standard deviation / mean) of the
// camera's radiance, without and with. Each patch keeps its flux.
struct Evenness {
  double before = 0.0, after = 0.0;
  int patches = 0, pixels = 0;
  long long saturated = 0;
};
// `edge_margin` (metres): leave out the points nearer a cell edge than this.
Evenness EvenOutPrintedWall(const World& world, double edge_margin = 0.0) {
  ProjectionRig rig =
      BuildProjectionRig(world.patches.fine, world.projectors, ProjectionRigOptions());
  std::vector<cv::Mat> maps;
  for (const Projector& projector : world.projectors) {
    maps.push_back(TrueReflectanceMap(world.synthetic.scene, projector.geometry));
  }
  AttachReflectanceMaps(maps, &rig);
  const Eigen::MatrixX3d emittance = rig.lower + 0.3 * (rig.upper - rig.lower);
  RenderOptions per_patch;
  RenderOptions per_pixel;
  per_pixel.reflectance = true;
  RenderSummary before_summary, after_summary;
  const auto before_images = RenderProjectorImages(rig, emittance, per_patch, &before_summary);
  const auto after_images = RenderProjectorImages(rig, emittance, per_pixel, &after_summary);
  // The same flux per patch (the delivered exitance is the flux's, by the rig's bookkeeping).
  EXPECT_LT(after_summary.max_relative_error, 0.01);
  EXPECT_LT((after_summary.delivered - before_summary.delivered).cwiseAbs().maxCoeff(),
            0.01 * rig.upper.maxCoeff());

  const cv::Mat before = world.rig->RenderRadiance(before_images);
  const cv::Mat after = world.rig->RenderRadiance(after_images);
  const std::vector<int> patch_of = SolverPatchPerPixel(world);
  const int n = world.patches.fine.size();
  std::vector<double> sum_before(n, 0), squares_before(n, 0), sum_after(n, 0), squares_after(n, 0);
  std::vector<int> count(n, 0);
  for (size_t k = 0; k < patch_of.size(); ++k) {
    const int i = patch_of[k];
    if (i < 0 || world.patches.fine.patches[i].surface != 1) continue;
    const int row = static_cast<int>(k / before.cols), col = static_cast<int>(k % before.cols);
    Vec3 point;
    if (!world.rig->PointSeenByPixel(row, col, &point)) continue;
    constexpr double kCell = 1.0 / 16;  // FineChecker(16) on the 1 m wall; UV = (z, 1 − x)
    const double du = std::fmod(point.z(), kCell), dv = std::fmod(1.0 - point.x(), kCell);
    if (std::min({du, kCell - du, dv, kCell - dv}) < edge_margin) continue;
    const double a = before.at<cv::Vec3f>(row, col)[1], b = after.at<cv::Vec3f>(row, col)[1];
    sum_before[i] += a, squares_before[i] += a * a;
    sum_after[i] += b, squares_after[i] += b * b;
    ++count[i];
  }
  // The pixel-weighted mean over the back wall's patches of each patch's coefficient of
  // variation (standard deviation / mean) of the camera's radiance.
  double variation_before = 0.0, variation_after = 0.0;
  int pixels = 0, patches = 0;
  for (int i = 0; i < n; ++i) {
    if (count[i] < 50) continue;
    const auto variation = [&](double sum, double squares) {
      const double mean = sum / count[i];
      return std::sqrt(std::max(0.0, squares / count[i] - mean * mean)) / mean;
    };
    variation_before += count[i] * variation(sum_before[i], squares_before[i]);
    variation_after += count[i] * variation(sum_after[i], squares_after[i]);
    pixels += count[i];
    ++patches;
  }
  variation_before /= pixels;
  variation_after /= pixels;
  Evenness evenness;
  evenness.before = variation_before;
  evenness.after = variation_after;
  evenness.patches = patches;
  evenness.pixels = pixels;
  evenness.saturated = std::accumulate(after_summary.saturated_pixels.begin(),
                                       after_summary.saturated_pixels.end(), 0LL);
  return evenness;
}

// The rendering shapes the direct light only, at the projectors' resolution. On the back wall a
// projector pixel is about 6.7 mm wide, so a band of about one pixel along each edge of the
// 62 mm cells is lit with one level for both cells (about a fifth of the wall): there the print
// stays. In the tiny box as it is (walls 0.8–0.9) the bounce light, which reflects with the
// print too, is a large part of the back wall's light at this emittance, and it stays (predicting
// the bounce per pixel is what would remove it). A dark room (every other surface reflecting
// 0.05) and points more than 8 mm from a cell edge separate the two; a residual of about a
// quarter of the print's variation remains even there, not explained yet (docs/projection.md).
// Held to: the print fades by at least 30% in each case.
TEST(SimulatedRig, ReflectanceMapEvensOutAPrintedWall) {
  SimulatedCameraOptions camera;
  camera.shot_noise = camera.read_noise = 0.0;
  camera.vignetting = 0.0;
  const World dark_room = MakeWorld(100, camera, 0.0, false, FineChecker(16), 0.05);
  const Evenness interior = EvenOutPrintedWall(dark_room, 0.008);
  const Evenness dark = EvenOutPrintedWall(dark_room);
  const Evenness bright = EvenOutPrintedWall(MakeWorld(100, camera, 0.0, false, FineChecker(16)));
  for (const auto& [name, e] :
       {std::pair<const char*, Evenness>("dark room, away from cell edges", interior),
        std::pair<const char*, Evenness>("dark room", dark),
        std::pair<const char*, Evenness>("tiny box", bright)}) {
    std::printf(
        "printed back wall, %s, %d patches, %d pixels: radiance within a patch varies by "
        "%.1f%% (one level per patch), %.1f%% (per pixel with the reflectance map); "
        "saturated pixels %lld\n",
        name, e.patches, e.pixels, 100 * e.before, 100 * e.after, e.saturated);
    ASSERT_GT(e.patches, 8);
    // 4:1 cells in about equal parts vary by 0.6: the print shows.
    EXPECT_GT(e.before, 0.4);
    EXPECT_LT(e.after, 0.7 * e.before);
  }
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
