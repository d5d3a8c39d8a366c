// Emittance → projector images → simulated direct light on the patches (forward projection of
// quadrature points, shadow rays: independent of the pixel maps) gives back the emittance; two
// overlapping projectors add up to it; pixels that light nothing stay at code 0; bounds are met
// exactly; PNG round trips.
#include "projection/projector_images.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <random>

#include "geometry/io.h"
#include "tests/projection/stage.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::MakeStage;
using testing::Stage;
using testing::StageOptions;

// Emittance drawn uniformly between the bounds, per patch and channel.
Eigen::MatrixX3d RandomEmittance(const ProjectionRig& rig, unsigned seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  Eigen::MatrixX3d emittance(rig.size(), 3);
  for (int i = 0; i < rig.size(); ++i) {
    for (int c = 0; c < 3; ++c)
      emittance(i, c) = rig.lower(i, c) + unit(random) * (rig.upper(i, c) - rig.lower(i, c));
  }
  return emittance;
}

// Rigorous quantisation bound per patch: every lit pixel off by the largest step of its
// response in light (no credit for dithering), in exitance.
Eigen::VectorXd QuantisationBound(const ProjectionRig& rig) {
  Eigen::VectorXd bound = Eigen::VectorXd::Zero(rig.size());
  for (size_t k = 0; k < rig.maps.size(); ++k) {
    const ProjectorPhotometry& photometry = rig.projectors[k].photometry;
    double step = 0.0;
    for (int q = 0; q < photometry.MaxCode(); ++q) {
      for (int c = 0; c < 3; ++c) {
        step = std::max(step, photometry.response[c].Light((q + 1.0) / photometry.MaxCode()) -
                                  photometry.response[c].Light(double(q) / photometry.MaxCode()));
      }
    }
    const double light_step = step * (photometry.max - photometry.black).maxCoeff();
    for (const int32_t patch : rig.maps[k].patch) {
      if (patch >= 0)
        bound[patch] += rig.coverage_scale(patch, k) * rig.maps[k].pixel_solid_angle * light_step;
    }
  }
  for (int i = 0; i < rig.size(); ++i) bound[i] *= rig.reflectance.row(i).maxCoeff() / rig.area[i];
  return bound;
}

TEST(ProjectorImages, EmittanceComesBackThroughTheImages) {
  const Stage stage = MakeStage({});
  const ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
  const Eigen::MatrixX3d emittance = RandomEmittance(rig, 11);
  const Eigen::VectorXd quantisation = QuantisationBound(rig);
  for (const DitherMethod dither :
       {DitherMethod::kOrdered, DitherMethod::kErrorDiffusion, DitherMethod::kNone}) {
    RenderOptions options;
    options.dither = dither;
    RenderSummary summary;
    const std::vector<ProjectorImage> images =
        RenderProjectorImages(rig, emittance, options, &summary);
    ASSERT_EQ(images.size(), 2u);
    EXPECT_EQ(summary.patches_below_lower + summary.patches_above_upper, 0);
    // The flux bookkeeping of the quantised codes: within one code step per pixel, and much
    // better on average when dithered.
    double mean_error = 0.0;
    for (int i = 0; i < rig.size(); ++i) {
      const double error = (summary.delivered.row(i) - emittance.row(i)).cwiseAbs().maxCoeff();
      EXPECT_LE(error, quantisation[i] + 1e-12) << DitherName(dither) << " patch " << i;
      mean_error += error / rig.size();
    }
    if (dither != DitherMethod::kNone) {
      EXPECT_LT(mean_error, 2e-3 * rig.upper.maxCoeff()) << DitherName(dither);
    }
  }
}

// True when every projector that lights patch i lights it wholly (rig.coverage_scale ≠ 1).
bool WhollyLit(const ProjectionRig& rig, int i) {
  bool any = false;
  for (size_t k = 0; k < rig.maps.size(); ++k) {
    if (std::find(rig.maps[k].patch.begin(), rig.maps[k].patch.end(), i) == rig.maps[k].patch.end())
      continue;
    any = true;
    if (rig.coverage_scale(i, k) == 1.0) return false;
  }
  return any;
}

TEST(ProjectorImages, SimulatedDirectLightMatchesTheEmittance) {
  StageOptions stage_options;
  stage_options.bits = 10;
  const Stage stage = MakeStage(stage_options);
  const PatchLevel& level = stage.patches.fine;
  const ProjectionRig rig = BuildProjectionRig(level, stage.projectors, {});
  const double scale = rig.upper.maxCoeff();
  // A smooth emittance (a ramp across the room), then a random one. The light on the surface
  // changes at pixel edges, not patch edges: a pixel straddling two patches lights both with
  // the value meant for the one its centre falls on. That costs about |ΔE| × ½ pixel row per
  // edge (patches here are ~20 pixels across, so a few % for random E, little for smooth E);
  // patches cut by an image border or a shadow keep a ½-pixel-row uncertainty of their lit
  // area. The quantised codes themselves are exact to ~1e-4 (RenderSummary::delivered).
  Eigen::MatrixX3d smooth(rig.size(), 3);
  for (int i = 0; i < rig.size(); ++i) {
    const double t = 0.2 + 0.6 * level.patches[i].centroid.x() / 4.0;
    smooth.row(i) = rig.lower.row(i) + t * (rig.upper.row(i) - rig.lower.row(i));
  }
  struct Case {
    Eigen::MatrixX3d emittance;
    double wholly_worst, all_worst, all_mean;
  };
  for (const Case& test :
       {Case{smooth, 0.008, 0.025, 0.003}, Case{RandomEmittance(rig, 5), 0.03, 0.04, 0.01}}) {
    RenderSummary summary;
    const std::vector<ProjectorImage> images =
        RenderProjectorImages(rig, test.emittance, {}, &summary);
    EXPECT_LT(summary.max_relative_error, 1e-3);
    const Eigen::MatrixX3d simulated = SimulateDirectLight(level, stage.projectors, images, 24);
    double wholly_worst = 0.0, all_worst = 0.0, all_mean = 0.0;
    int wholly = 0, lit = 0;
    for (int i = 0; i < rig.size(); ++i) {
      if (!(rig.upper(i, 0) > 0.0)) {
        EXPECT_EQ(simulated.row(i).norm(), 0.0) << "patch " << i << " no projector reaches";
        continue;
      }
      const double error = (simulated.row(i) - test.emittance.row(i)).cwiseAbs().maxCoeff() / scale;
      all_worst = std::max(all_worst, error);
      all_mean += error;
      ++lit;
      if (WhollyLit(rig, i)) {
        wholly_worst = std::max(wholly_worst, error);
        ++wholly;
      }
    }
    EXPECT_GT(wholly, 100);
    EXPECT_LT(wholly_worst, test.wholly_worst);
    EXPECT_LT(all_worst, test.all_worst);
    EXPECT_LT(all_mean / lit, test.all_mean);
  }
}

TEST(ProjectorImages, OverlappingProjectorsAddUpToTheTarget) {
  const Stage stage = MakeStage({});
  const PatchLevel& level = stage.patches.fine;
  const ProjectionRig rig = BuildProjectionRig(level, stage.projectors, {});
  const Eigen::MatrixX3d emittance = rig.lower + 0.6 * (rig.upper - rig.lower);
  const std::vector<ProjectorImage> images = RenderProjectorImages(rig, emittance, {}, nullptr);
  std::vector<ProjectorImage> black = images;  // cv::Mat copies share pixels: make new ones
  for (ProjectorImage& image : black)
    image.codes = cv::Mat(image.codes.size(), CV_16UC3, cv::Scalar::all(0));
  const Eigen::MatrixX3d both = SimulateDirectLight(level, stage.projectors, images, 8);
  const Eigen::MatrixX3d dark = SimulateDirectLight(level, stage.projectors, black, 8);
  const Eigen::MatrixX3d left =
      SimulateDirectLight(level, stage.projectors, {images[0], black[1]}, 8) - dark;
  const Eigen::MatrixX3d right =
      SimulateDirectLight(level, stage.projectors, {black[0], images[1]}, 8) - dark;
  int shared = 0;
  for (int i = 0; i < rig.size(); ++i) {
    const double wanted = emittance(i, 1) - rig.lower(i, 1);
    // Patches cut by a shadow or border are integrated too coarsely by 8×8 points to compare.
    if (!WhollyLit(rig, i) || !(left(i, 1) > 0.2 * wanted && right(i, 1) > 0.2 * wanted)) continue;
    ++shared;
    EXPECT_NEAR((left(i, 1) + right(i, 1)) / wanted, 1.0, 0.02) << "patch " << i;
    EXPECT_NEAR(both(i, 1) / emittance(i, 1), 1.0, 0.02) << "patch " << i;
  }
  EXPECT_GT(shared, 40);
}

TEST(ProjectorImages, UnlitPixelsStayBlackAndShadowsAreFilledByTheOtherProjector) {
  const Stage stage = MakeStage({});
  const PatchLevel& level = stage.patches.fine;
  const ProjectionRig rig = BuildProjectionRig(level, stage.projectors, {});
  const Eigen::MatrixX3d emittance = rig.upper;  // the brightest possible: black pixels stand out
  const std::vector<ProjectorImage> images = RenderProjectorImages(rig, emittance, {}, nullptr);
  // Pixels whose ray meets no surface (checked here with plain ray–plane tests) are code 0.
  for (size_t k = 0; k < images.size(); ++k) {
    const ProjectorGeometry& geometry = stage.projectors[k].geometry;
    const Vec3 centre = geometry.CentreInWorld();
    const Eigen::Matrix3d world_from_proj = geometry.proj_from_world().rotation().transpose();
    int unlit = 0;
    for (int y = 0; y < geometry.height(); ++y) {
      for (int x = 0; x < geometry.width(); ++x) {
        const Vec3 d = world_from_proj * geometry.Unproject(Vec2(x, y));
        // Could the ray meet any surface of the stage (rectangles grown by 2 cm)?
        bool may_hit = false;
        for (const Surface& surface : stage.scene.surfaces) {
          const Vec3 origin = surface.quad[0], u = surface.quad[1] - origin,
                     v = surface.quad[3] - origin;
          const Vec3 normal = u.cross(v).normalized();
          const double t = normal.dot(origin - centre) / normal.dot(d);
          if (!(t > 0.0)) continue;
          const Vec3 hit = centre + t * d - origin;
          const double s = hit.dot(u) / u.norm(), r = hit.dot(v) / v.norm();
          may_hit |= s > -0.02 && s < u.norm() + 0.02 && r > -0.02 && r < v.norm() + 0.02;
        }
        if (may_hit) continue;
        ++unlit;
        EXPECT_EQ(images[k].codes.at<cv::Vec3w>(y, x), cv::Vec3w(0, 0, 0))
            << "projector " << k << " pixel " << x << "," << y;
      }
    }
    EXPECT_GT(unlit, 100) << "the stage should leave some pixels of projector " << k << " unlit";
  }
  // Wall patches the plate hides from the left projector: it sends them nothing, not even its
  // black; the right projector alone delivers their emittance.
  std::vector<ProjectorImage> black = images;  // cv::Mat copies share pixels: make new ones
  for (ProjectorImage& image : black)
    image.codes = cv::Mat(image.codes.size(), CV_16UC3, cv::Scalar::all(0));
  const Eigen::MatrixX3d from_left =
      SimulateDirectLight(level, stage.projectors, {images[0], black[1]}, 8) -
      SimulateDirectLight(level, stage.projectors, black, 8);
  const Eigen::MatrixX3d both = SimulateDirectLight(level, stage.projectors, images, 24);
  int filled = 0;
  const Vec3 left_centre = stage.projectors[0].geometry.CentreInWorld();
  int hidden = 0;
  for (int i = 0; i < level.size(); ++i) {
    const Patch& patch = level.patches[i];
    if (patch.surface != Stage::kWall) continue;
    bool behind_plate = true;
    for (int k = 0; k < 4; ++k) {
      const Vec3 a = patch.corners[k], b = left_centre;
      const double s = (2.0 - a.y()) / (b.y() - a.y());
      const Vec3 crossing = a + s * (b - a);
      behind_plate &=
          crossing.x() > 1.6 && crossing.x() < 2.4 && crossing.z() > 0.9 && crossing.z() < 1.6;
    }
    if (!behind_plate) continue;
    ++hidden;
    EXPECT_EQ(from_left.row(i).norm(), 0.0) << "patch " << i;
    // The right projector's light is cut by the plate's shadow too on some of these patches:
    // a ½-pixel-row uncertainty of the lit area there, hence 3%.
    if (rig.upper(i, 1) > 0.0) {
      EXPECT_NEAR(both(i, 1) / emittance(i, 1), 1.0, 0.03) << "patch " << i;
      ++filled;
    }
  }
  EXPECT_GT(hidden, 1);
  EXPECT_GT(filled, 0);
}

TEST(ProjectorImages, BoundsAreDeliveredExactly) {
  const Stage stage = MakeStage({});
  const ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
  RenderSummary summary;
  std::vector<ProjectorImage> images = RenderProjectorImages(rig, rig.upper, {}, &summary);
  EXPECT_LT((summary.delivered - rig.upper).cwiseAbs().maxCoeff(), 1e-9 * rig.upper.maxCoeff());
  for (size_t k = 0; k < images.size(); ++k) {
    for (size_t index = 0; index < rig.maps[k].patch.size(); ++index) {
      if (rig.maps[k].patch[index] < 0) continue;
      ASSERT_EQ(images[k].codes.at<cv::Vec3w>(int(index) / images[k].codes.cols,
                                              int(index) % images[k].codes.cols),
                cv::Vec3w(255, 255, 255));
    }
  }
  images = RenderProjectorImages(rig, rig.lower, {}, &summary);
  EXPECT_LT((summary.delivered - rig.lower).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ(cv::countNonZero(images[0].codes.reshape(1)), 0);
  // Outside the bounds: clipped and counted.
  RenderProjectorImages(rig, 2.0 * rig.upper + Eigen::MatrixX3d::Constant(rig.size(), 3, 1.0), {},
                        &summary);
  EXPECT_EQ(summary.patches_above_upper, rig.size());
  EXPECT_LT((summary.delivered - rig.upper).cwiseAbs().maxCoeff(), 1e-9 * rig.upper.maxCoeff());
  // Near the top, pixels saturate and the rest of the patch makes up for them.
  const Eigen::MatrixX3d high = rig.lower + 0.97 * (rig.upper - rig.lower);
  RenderProjectorImages(rig, high, {}, &summary);
  EXPECT_GT(summary.level_passes, 1);
  EXPECT_GT(summary.saturated_pixels[0] + summary.saturated_pixels[1], 0);
  EXPECT_LT((summary.delivered - high).cwiseAbs().maxCoeff(), 5e-3 * rig.upper.maxCoeff());
}

TEST(ProjectorImages, MixingAndMeasuredResponseAreInverted) {
  Stage stage = MakeStage({});
  for (Projector& projector : stage.projectors) {
    projector.photometry.mixing << 0.92, 0.06, 0.02, 0.04, 0.9, 0.06, 0.01, 0.07, 0.92;
    projector.photometry.response.fill(
        ResponseCurve::Table({0.0, 0.01, 0.05, 0.13, 0.26, 0.42, 0.62, 0.8, 1.0}));
    projector.photometry.black = Vec3(0.02, 0.03, 0.04);
    projector.photometry.max = Vec3(11.0, 12.0, 10.0);
  }
  const ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
  // Greyish colours stay inside the mixing gamut.
  std::mt19937 random(3);
  std::uniform_real_distribution<double> unit(0.3, 0.6), tint(-0.05, 0.05);
  Eigen::MatrixX3d emittance(rig.size(), 3);
  for (int i = 0; i < rig.size(); ++i) {
    const double level = unit(random);
    for (int c = 0; c < 3; ++c) {
      emittance(i, c) =
          rig.lower(i, c) + (level + tint(random)) * (rig.upper(i, c) - rig.lower(i, c));
    }
  }
  RenderSummary summary;
  const std::vector<ProjectorImage> images = RenderProjectorImages(rig, emittance, {}, &summary);
  // Pixels the blending pushes to full drive in one channel leave the mixing gamut and are
  // clipped (the level solve works per channel); that stays rare for greyish colours.
  const long long lit = rig.maps[0].lit_pixels + rig.maps[1].lit_pixels;
  EXPECT_LT(summary.clipped_pixels[0] + summary.clipped_pixels[1], lit / 50);
  const Eigen::VectorXd quantisation = QuantisationBound(rig);
  for (int i = 0; i < rig.size(); ++i) {
    EXPECT_LE((summary.delivered.row(i) - emittance.row(i)).cwiseAbs().maxCoeff(),
              quantisation[i] + 1e-12);
  }
  const Eigen::MatrixX3d simulated =
      SimulateDirectLight(stage.patches.fine, stage.projectors, images, 8);
  double mean = 0.0;
  for (int i = 0; i < rig.size(); ++i)
    mean += (simulated.row(i) - emittance.row(i)).cwiseAbs().maxCoeff() / rig.size();
  EXPECT_LT(mean, 1e-2 * rig.upper.maxCoeff());
}

TEST(ProjectorImages, PngRoundTripsAndSizesAreChecked) {
  testing::TempDir dir;
  for (const int bits : {8, 10}) {
    ProjectorImage image;
    image.bits = bits;
    image.codes = cv::Mat(37, 53, CV_16UC3);
    cv::randu(image.codes, cv::Scalar::all(0), cv::Scalar::all(1 << bits));
    const auto path = dir / ("image" + std::to_string(bits) + ".png");
    WriteProjectorImage(path, image);
    const ProjectorImage read = ReadProjectorImage(path, bits);
    EXPECT_EQ(cv::norm(read.codes, image.codes, cv::NORM_INF), 0.0) << bits << " bits";
  }
  EXPECT_THROW(ReadProjectorImage(dir / "image8.png", 10), IoError);
  EXPECT_THROW(ReadProjectorImage(dir / "missing.png", 8), IoError);

  const Stage stage = MakeStage({});
  ProjectorImage wrong;
  wrong.codes = cv::Mat(10, 10, CV_16UC3, cv::Scalar::all(0));
  ProjectorImage right;
  right.codes = cv::Mat(240, 320, CV_16UC3, cv::Scalar::all(0));
  try {
    SimulateDirectLight(stage.patches.fine, stage.projectors, {right, wrong}, 4);
    FAIL() << "no error";
  } catch (const std::invalid_argument& error) {
    EXPECT_EQ(std::string(error.what()),
              "projector 'right': image is 10x10, the projector 320x240");
  }
}

}  // namespace
}  // namespace procam
