// Each projector pixel's reflectance measured from flat fields (projection/reflectance_map.h),
// against the simulated world's truth: the tiny box with a poster printed on its back wall and
// paint varying ±5% (SimulatedRigOptions::albedo_variation 0.05), photographed by the simulated
// camera with its shot and read noise.
#include "projection/reflectance_map.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <opencv2/imgproc.hpp>

#include "base/io.h"
#include "compensation/unit_light.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/simulated_rig.h"
#include "geometry/form_factors.h"
#include "geometry/ray_scene.h"
#include "projection/camera_rays.h"
#include "projection/photometric_transfer.h"
#include "projection/projection_rig.h"
#include "projection/rig_directory.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

// Fine enough that the estimate's per-patch reflectance is good to about 2% rms (rig_test's
// ScenePhotometry on the same box).
constexpr int kPatches = 600;

// A smooth poster (no detail finer than the camera resolves on the wall): per channel a product
// of waves between 0.2 and 0.9, different per channel, 128 × 128 texels.
ReflectanceTexture SmoothPoster() {
  ReflectanceTexture poster;
  poster.texture_linear = cv::Mat(128, 128, CV_32FC3);
  for (int row = 0; row < 128; ++row) {
    for (int col = 0; col < 128; ++col) {
      const double u = (col + 0.5) / 128, v = 1.0 - (row + 0.5) / 128;
      cv::Vec3f& texel = poster.texture_linear.at<cv::Vec3f>(row, col);
      for (int c = 0; c < 3; ++c) {
        texel[c] =
            static_cast<float>(0.55 + 0.35 * std::sin(2 * std::numbers::pi * (1.5 * u + 0.2 * c)) *
                                          std::cos(2 * std::numbers::pi * (v + 0.15 * c)));
      }
    }
  }
  return poster;
}

// The texture coordinate of a point on a rectangular quad surface (corner 0, u along 0→1, v
// along 0→3), from the surface's own corners.
Vec2 RectangleUv(const Surface& surface, const Vec3& point) {
  const Vec3 e1 = surface.quad[1] - surface.quad[0], e3 = surface.quad[3] - surface.quad[0];
  const Vec3 d = point - surface.quad[0];
  return Vec2(d.dot(e1) / e1.squaredNorm(), d.dot(e3) / e3.squaredNorm());
}

class ReflectanceMapTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    SyntheticScene synthetic = MakeSyntheticScene("tiny_box", kPatches);
    Surface& back_wall = synthetic.scene.surfaces[1];
    back_wall.reflectance_texture = SmoothPoster();
    back_wall.reflectance = back_wall.reflectance_texture.Mean();
    scene_ = new Scene(synthetic.scene);
    projector_ = new Projector(ProjectorFromPlacement(synthetic.projectors[0]));
    SimulatedRigOptions options;
    options.solver_patches = kPatches;
    options.albedo_variation = 0.05;
    options.camera.vignetting = 0.0;  // the camera's flat field is not what is measured here
    rig_ = new SimulatedRig(*scene_, {*projector_}, CameraFromPlacement(synthetic.camera), options);
    SubdivisionOptions subdivision;
    subdivision.target_patches = kPatches;
    level_ = new PatchLevel(SubdividePatches(*scene_, subdivision).fine);
    form_factors_ = new Eigen::MatrixXd(ComputeFormFactors(*scene_, *level_, {}, nullptr));
  }
  static void TearDownTestSuite() {
    delete scene_;
    delete projector_;
    delete rig_;
    delete level_;
    delete form_factors_;
  }

  static ProjectorImage Flat(double drive) {
    ProjectorImage image;
    image.bits = projector_->photometry.bits;
    image.codes = cv::Mat(projector_->geometry.height(), projector_->geometry.width(), CV_16UC3,
                          cv::Scalar::all(std::lround(drive * projector_->photometry.MaxCode())));
    return image;
  }

  // White minus black as the camera (B, G, R) records it: with noise (seeds 1, 2), or without.
  static cv::Mat Difference(bool noise) {
    cv::Mat white, black;
    if (noise) {
      white = rig_->PhotographLinear({Flat(1.0)}, 1);
      black = rig_->PhotographLinear({Flat(0.0)}, 2);
    } else {
      white = rig_->RenderRadiance({Flat(1.0)});
      black = rig_->RenderRadiance({Flat(0.0)});
    }
    cv::Mat difference;
    cv::cvtColor(white - black, difference, cv::COLOR_RGB2BGR);
    return difference;
  }

  struct Measured {
    ReflectanceEstimate estimate;
    ReflectanceMap map;
  };
  static Measured Measure(const cv::Mat& difference) {
    const CameraPixelLighting lighting =
        LightCameraPixels(*scene_, *level_, projector_->geometry, rig_->camera());
    const UnitLightModel model =
        ModelUnitLight(*level_, *form_factors_, UnitLightExitance(*level_, *projector_));
    // The projector's photometry is known here (its fit is photometric_test's and rig_test's).
    const Eigen::Vector3d output = projector_->photometry.max - projector_->photometry.black;
    Measured measured;
    measured.estimate =
        EstimatePatchReflectance(lighting, *level_, *form_factors_, model, difference, cv::Mat(),
                                 output, Eigen::Vector3d::Ones(), 4);
    measured.map = EstimateReflectanceMap(*level_, projector_->geometry, rig_->camera(), lighting,
                                          measured.estimate, difference, cv::Mat(), output,
                                          Eigen::Vector3d::Ones());
    return measured;
  }

  // The world's reflectance at the point each projector pixel lights (R, G, B; the surface's
  // texture or nominal reflectance times the paint's albedo factor, at most 0.99), cast against
  // the scene's surfaces; −1 where the pixel lights nothing.
  static cv::Mat Truth() {
    const RayScene surfaces(*scene_);
    const ProjectorGeometry& geometry = projector_->geometry;
    std::vector<Vec3> directions;
    std::vector<double> densities;
    geometry.UnprojectImage(&directions, &densities);
    const Eigen::Isometry3d world_from_proj = geometry.proj_from_world().inverse();
    cv::Mat truth(geometry.height(), geometry.width(), CV_32FC3, cv::Scalar::all(-1));
    for (int row = 0; row < geometry.height(); ++row) {
      for (int col = 0; col < geometry.width(); ++col) {
        const Vec3 direction = world_from_proj.linear() * directions[row * geometry.width() + col];
        double t;
        int s;
        if (!surfaces.Intersect(world_from_proj.translation(), direction, 0.0, 1e9, &t, &s))
          continue;
        const Surface& surface = scene_->surfaces[s];
        const Vec2 uv = RectangleUv(surface, world_from_proj.translation() + t * direction);
        const Vec3 rho = (rig_->AlbedoFactor(s, uv) * surface.ReflectanceAt(uv)).cwiseMin(0.99);
        truth.at<cv::Vec3f>(row, col) = cv::Vec3f(rho[0], rho[1], rho[2]);
      }
    }
    return truth;
  }

  // Relative RMS of the map (and of its patches' reflectance alone) against the truth over the
  // measured pixels, all channels; `back_wall` only the poster's.
  struct Errors {
    double map_rms = 0.0, patch_rms = 0.0;
    int pixels = 0;
  };
  static Errors Compare(const Measured& measured, const cv::Mat& truth, bool back_wall) {
    Errors errors;
    double map_squares = 0.0, patch_squares = 0.0;
    for (int row = 0; row < truth.rows; ++row) {
      for (int col = 0; col < truth.cols; ++col) {
        if (!measured.map.measured.at<uchar>(row, col)) continue;
        const int i = measured.map.patch.at<int32_t>(row, col);
        if (back_wall && level_->patches[i].surface != 1) continue;
        const cv::Vec3f& expected = truth.at<cv::Vec3f>(row, col);
        const cv::Vec3f& value = measured.map.reflectance.at<cv::Vec3f>(row, col);
        for (int c = 0; c < 3; ++c) {
          map_squares += std::pow(value[c] / expected[c] - 1.0, 2);
          patch_squares += std::pow(measured.estimate.reflectance(i, c) / expected[c] - 1.0, 2);
        }
        ++errors.pixels;
      }
    }
    errors.map_rms = std::sqrt(map_squares / (3.0 * errors.pixels));
    errors.patch_rms = std::sqrt(patch_squares / (3.0 * errors.pixels));
    return errors;
  }

  static Scene* scene_;
  static Projector* projector_;
  static SimulatedRig* rig_;
  static PatchLevel* level_;
  static Eigen::MatrixXd* form_factors_;
};
Scene* ReflectanceMapTest::scene_ = nullptr;
Projector* ReflectanceMapTest::projector_ = nullptr;
SimulatedRig* ReflectanceMapTest::rig_ = nullptr;
PatchLevel* ReflectanceMapTest::level_ = nullptr;
Eigen::MatrixXd* ReflectanceMapTest::form_factors_ = nullptr;

// Each patch's mean over the projector pixels lighting it is the patch's estimated reflectance,
// measured pixels or not, also where values reach the clamp at 0.99 (the walls reflect up to
// 0.9 × 1.05 and the per-pixel ratio overshoots near the box's corners, where the bounce light is
// far from the patch's constant).
TEST_F(ReflectanceMapTest, EachPatchMeanIsThePatchReflectance) {
  const Measured measured = Measure(Difference(false));
  const int n = level_->size();
  Eigen::MatrixX3d sum = Eigen::MatrixX3d::Zero(n, 3);
  Eigen::VectorXi count = Eigen::VectorXi::Zero(n);
  for (int row = 0; row < measured.map.patch.rows; ++row) {
    for (int col = 0; col < measured.map.patch.cols; ++col) {
      const int i = measured.map.patch.at<int32_t>(row, col);
      if (i < 0) {
        EXPECT_EQ(measured.map.reflectance.at<cv::Vec3f>(row, col), cv::Vec3f(0, 0, 0));
        continue;
      }
      const cv::Vec3f& value = measured.map.reflectance.at<cv::Vec3f>(row, col);
      sum.row(i) += Eigen::RowVector3d(value[0], value[1], value[2]);
      ++count[i];
    }
  }
  int patches = 0;
  for (int i = 0; i < n; ++i) {
    if (count[i] == 0) continue;
    ++patches;
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(sum(i, c) / count[i], measured.estimate.reflectance(i, c), 1e-5) << i;
    }
  }
  EXPECT_GT(patches, 100);
  EXPECT_GT(measured.map.measured_pixels, measured.map.lit_pixels / 2);
}

// The map against the world's truth at each measured projector pixel. The bound is the noise the
// camera puts on one pixel of white − black (shot noise 0.01·√signal and read noise 0.002 on each
// of the two photos; the bilinear interpolation between camera pixels only lowers it), added in
// quadrature to the 2% rms per-patch accuracy of the estimate the map is normalised to (rig_test's
// ScenePhotometry bound on this box), with a factor 1.5 for the model's bounce light being
// constant over each patch. The map must also beat the patches' one reflectance each by half.
TEST_F(ReflectanceMapTest, MatchesTheWorldsReflectance) {
  const cv::Mat difference = Difference(true);
  const Measured measured = Measure(difference);
  const cv::Mat truth = Truth();
  // The camera's predicted relative noise on white − black over the pixels that see a lit patch.
  const cv::Mat white = rig_->RenderRadiance({Flat(1.0)}),
                black = rig_->RenderRadiance({Flat(0.0)});
  const double shot = 0.01, read = 0.002;
  double noise_squares = 0.0;
  int noise_pixels = 0;
  for (int row = 0; row < white.rows; ++row) {
    for (int col = 0; col < white.cols; ++col) {
      const float w = white.at<cv::Vec3f>(row, col)[1], b = black.at<cv::Vec3f>(row, col)[1];
      if (!(w - b > 0.05 * w) || !(w > 0.0f)) continue;
      noise_squares += (shot * shot * (w + b) + 2 * read * read) / ((w - b) * (w - b));
      ++noise_pixels;
    }
  }
  const double noise_rms = std::sqrt(noise_squares / noise_pixels);
  const double bound = 1.5 * std::hypot(noise_rms, 0.02);

  const Errors all = Compare(measured, truth, false);
  const Errors poster = Compare(measured, truth, true);
  std::printf("camera noise on white - black: %.2f%% rms per pixel; bound %.2f%%\n",
              100 * noise_rms, 100 * bound);
  std::printf("all measured pixels (%d): map %.2f%% rms, patches alone %.2f%%\n", all.pixels,
              100 * all.map_rms, 100 * all.patch_rms);
  std::printf("poster (%d): map %.2f%% rms, patches alone %.2f%%\n", poster.pixels,
              100 * poster.map_rms, 100 * poster.patch_rms);
  ASSERT_GT(poster.pixels, 2000);
  EXPECT_LT(all.map_rms, bound);
  EXPECT_LT(poster.map_rms, bound);
  EXPECT_LT(poster.map_rms, 0.5 * poster.patch_rms);

  // Without noise what is left is the model's (the bounce light constant over each patch).
  const Errors exact = Compare(Measure(Difference(false)), truth, false);
  std::printf("noise-free: map %.2f%% rms over %d pixels\n", 100 * exact.map_rms, exact.pixels);
  EXPECT_LT(exact.map_rms, 1.5 * 0.02);
}

// Written and read back through its owner: codes of 1/65535, the rig.json entry, and one clear
// line for a missing file or a size that differs from the entry.
TEST_F(ReflectanceMapTest, RoundTripsThroughTheRigDirectory) {
  const Measured measured = Measure(Difference(false));
  testing::TempDir dir;
  RigReflectanceMap entry;
  WriteReflectanceMap(dir.path(), "left", measured.map, &entry);
  entry.target_patches = kPatches;
  RigFile rig;
  rig.reflectance_maps["left"] = entry;
  WriteRigFile(dir.path(), rig);
  const RigFile read = ReadRigFile(dir.path());
  ASSERT_EQ(read.reflectance_maps.count("left"), 1u);
  const RigReflectanceMap& back = read.reflectance_maps.at("left");
  EXPECT_EQ(back.file, "left.reflectance_map.png");
  EXPECT_EQ(back.width, projector_->geometry.width());
  EXPECT_EQ(back.measured_pixels, measured.map.measured_pixels);
  EXPECT_EQ(back.target_patches, kPatches);
  const cv::Mat map = ReadReflectanceMap(dir.path(), "left", back);
  double worst = 0.0;
  for (int row = 0; row < map.rows; ++row) {
    for (int col = 0; col < map.cols; ++col) {
      for (int c = 0; c < 3; ++c) {
        worst =
            std::max<double>(worst, std::abs(map.at<cv::Vec3f>(row, col)[c] -
                                             measured.map.reflectance.at<cv::Vec3f>(row, col)[c]));
      }
    }
  }
  EXPECT_LE(worst, 0.5 / 65535 + 1e-7);

  RigReflectanceMap wrong_size = back;
  wrong_size.width += 1;
  try {
    ReadReflectanceMap(dir.path(), "left", wrong_size);
    ADD_FAILURE() << "a map of another size was read";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what())
                  .find("left.reflectance_map.png: 320x200, rig.json's "
                        "reflectance_maps.left says 321x200"),
              std::string::npos)
        << error.what();
  }
  std::filesystem::remove(dir / "left.reflectance_map.png");
  try {
    ReadReflectanceMap(dir.path(), "left", back);
    ADD_FAILURE() << "a missing map was read";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("rig.json: reflectance_maps.left.file: "),
              std::string::npos)
        << error.what();
  }
}

}  // namespace
}  // namespace procam
