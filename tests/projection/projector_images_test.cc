// Emittance → projector images → simulated direct light on the patches (forward projection of
// quadrature points, shadow rays: independent of the pixel maps) gives back the emittance; two
// overlapping projectors add up to it; pixels that light nothing stay at code 0; bounds are met
// exactly; a desired texture's detail modulates the light within patches without changing their
// light (and changes nothing on untextured surfaces); PNG round trips.
#include "projection/projector_images.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/core.hpp>
#include <random>

#include "base/io.h"
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
  for (int i = 0; i < rig.size(); ++i) {
    if (rig.lit_fraction[i] > 0.0)
      bound[i] *= rig.reflectance.row(i).maxCoeff() / rig.LitArea(i);
  }
  return bound;
}

// The mean direct light over each patch for emittance E (what SimulateDirectLight measures): a
// partly lit patch's E is that of its lit part (projection_rig.h), the rest is dark.
Eigen::MatrixX3d PatchMean(const ProjectionRig& rig, const Eigen::MatrixX3d& emittance) {
  return rig.lit_fraction.asDiagonal() * emittance;
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
      const double error =
          (simulated.row(i) - PatchMean(rig, test.emittance).row(i)).cwiseAbs().maxCoeff() / scale;
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
      EXPECT_NEAR(both(i, 1) / PatchMean(rig, emittance)(i, 1), 1.0, 0.03) << "patch " << i;
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
    mean += (simulated.row(i) - PatchMean(rig, emittance).row(i)).cwiseAbs().maxCoeff() / rig.size();
  EXPECT_LT(mean, 1e-2 * rig.upper.maxCoeff());
}

// The wall's desired texture in the detail tests (linear RGB at uv): red varies along u
// (vertical stripes, period 0.2 m on the 4 m wall: ~16 projector pixels), green along v
// (horizontal stripes, period 0.25 m), blue is constant. Patches are ~0.27 m across.
Vec3 Stripes(const Vec2& uv) {
  constexpr double kTwoPi = 6.283185307179586;
  return Vec3(0.5 + 0.35 * std::sin(kTwoPi * 20.0 * uv.x()),
              0.5 + 0.35 * std::sin(kTwoPi * 10.0 * uv.y()), 0.4);
}

// Stripes() sampled at texel centres (row 0 = top: v = 1 at the top, as DesiredAppearance says).
cv::Mat StripeTexture(int width, int height) {
  cv::Mat texture(height, width, CV_32FC3);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const Vec3 rgb = Stripes(Vec2((x + 0.5) / width, 1.0 - (y + 0.5) / height));
      texture.at<cv::Vec3f>(y, x) = cv::Vec3f(rgb[0], rgb[1], rgb[2]);
    }
  }
  return texture;
}

// The stage with the striped wall, and its rig with texture coordinates.
struct TexturedStage {
  Stage stage;
  ProjectionRig rig;
};

TexturedStage MakeTexturedStage(const StageOptions& options) {
  TexturedStage textured{MakeStage(options), {}};
  textured.stage.scene.surfaces[Stage::kWall].desired.texture_linear = StripeTexture(1024, 512);
  ProjectionRigOptions rig_options;
  rig_options.texture_coordinates = true;
  textured.rig =
      BuildProjectionRig(textured.stage.patches.fine, textured.stage.projectors, rig_options);
  return textured;
}

TEST(ProjectorImages, DetailKeepsEachPatchsLight) {
  const TexturedStage textured = MakeTexturedStage({});
  const Stage& stage = textured.stage;
  const ProjectionRig& rig = textured.rig;
  const PatchLevel& level = stage.patches.fine;
  const Eigen::VectorXd quantisation = QuantisationBound(rig);
  const double scale = rig.upper.maxCoeff();
  // E as a compensation solution would have it: following each patch's mean of the texture
  // (computed here from Stripes() directly), so that the light is continuous across patch edges;
  // a smooth ramp that ignores the texture; and one near the top, where the stripes' peaks
  // (1.7 × the mean) cannot all be delivered: they clip, and the rest of the patch makes up.
  Eigen::MatrixX3d following(rig.size(), 3), smooth(rig.size(), 3);
  std::vector<PatchSample> samples;
  for (int i = 0; i < rig.size(); ++i) {
    const Patch& patch = level.patches[i];
    Vec3 mean = Vec3::Constant(0.5);
    if (patch.surface == Stage::kWall) {
      SamplePatch(patch, 16, &samples);
      mean.setZero();
      for (const PatchSample& sample : samples)
        mean += sample.weight / patch.area * Stripes(sample.uv);
    }
    const double t = 0.2 + 0.6 * patch.centroid.x() / 4.0;
    smooth.row(i) = rig.lower.row(i) + t * (rig.upper.row(i) - rig.lower.row(i));
    following.row(i) = rig.lower.row(i) +
                       0.5 * (rig.upper.row(i) - rig.lower.row(i)).cwiseProduct(mean.transpose());
  }
  const Eigen::MatrixX3d high = rig.lower + 0.85 * (rig.upper - rig.lower);
  // Simulated worst and mean error (relative to the largest upper bound) allowed on the wall
  // patches lit wholly; measured 0.0030/0.0010, 0.0060/0.0022, 0.0080/0.0024 (without detail:
  // 0.0022/0.0005, 0.0028/0.0006, 0.0065/0.0011). Light that changes within pixels' reach of a
  // patch edge costs a ½-pixel row there, like random E does without detail.
  struct Case {
    const char* name;
    const Eigen::MatrixX3d& emittance;
    double worst, mean;
    long long fewest_clipped, most_clipped;  // detail_saturated_pixels, both projectors
  };
  for (const Case& test : {Case{"following", following, 0.005, 0.0015, 0, 100},
                           Case{"smooth", smooth, 0.01, 0.003, 1000, 50000},
                           Case{"high", high, 0.012, 0.004, 50000, 100000}}) {
    RenderOptions options;
    options.detail = true;
    RenderSummary summary;
    const std::vector<ProjectorImage> images =
        RenderProjectorImages(rig, stage.scene, test.emittance, options, &summary);
    EXPECT_GT(summary.detail_pixels, 50000) << test.name;
    const long long clipped =
        summary.detail_saturated_pixels[0] + summary.detail_saturated_pixels[1];
    EXPECT_GE(clipped, test.fewest_clipped) << test.name;
    EXPECT_LE(clipped, test.most_clipped) << test.name;
    // The flux bookkeeping of the quantised codes: E to within one code step per pixel, also
    // where the highlights clip (the rest of the patch makes up for them).
    EXPECT_LT(summary.max_relative_error, 1e-3) << test.name;
    for (int i = 0; i < rig.size(); ++i) {
      EXPECT_LE((summary.delivered.row(i) - test.emittance.row(i)).cwiseAbs().maxCoeff(),
                quantisation[i] + 1e-12)
          << test.name << " patch " << i;
    }
    // Independently: Gauss points projected forward into the images (48² per patch: the light
    // now changes from pixel to pixel, so 24² would add quadrature error).
    const Eigen::MatrixX3d simulated = SimulateDirectLight(level, stage.projectors, images, 48);
    double worst = 0.0, mean = 0.0;
    int wall = 0;
    for (int i = 0; i < rig.size(); ++i) {
      if (level.patches[i].surface != Stage::kWall || !WhollyLit(rig, i)) continue;
      const double error = (simulated.row(i) - test.emittance.row(i)).cwiseAbs().maxCoeff() / scale;
      worst = std::max(worst, error);
      mean += error;
      ++wall;
    }
    EXPECT_GT(wall, 50) << test.name;
    EXPECT_LT(worst, test.worst) << test.name;
    EXPECT_LT(mean / wall, test.mean) << test.name;
  }
}

// Correlation coefficient of two samples.
double Correlation(const std::vector<double>& a, const std::vector<double>& b) {
  const double n = static_cast<double>(a.size());
  double mean_a = 0.0, mean_b = 0.0;
  for (size_t j = 0; j < a.size(); ++j) {
    mean_a += a[j] / n;
    mean_b += b[j] / n;
  }
  double ab = 0.0, aa = 0.0, bb = 0.0;
  for (size_t j = 0; j < a.size(); ++j) {
    ab += (a[j] - mean_a) * (b[j] - mean_b);
    aa += (a[j] - mean_a) * (a[j] - mean_a);
    bb += (b[j] - mean_b) * (b[j] - mean_b);
  }
  return ab / std::sqrt(aa * bb);
}

TEST(ProjectorImages, DetailFollowsTheTextureWithinEachPatch) {
  const TexturedStage textured = MakeTexturedStage({});
  const Stage& stage = textured.stage;
  const ProjectionRig& rig = textured.rig;
  const PatchLevel& level = stage.patches.fine;
  // Low enough that the stripes' peaks (1.7 × the patch mean) stay below full drive also where
  // one projector alone lights what the bounds count two for.
  const Eigen::MatrixX3d emittance = rig.lower + 0.25 * (rig.upper - rig.lower);
  RenderOptions options;
  const std::vector<ProjectorImage> plain =
      RenderProjectorImages(rig, stage.scene, emittance, options, nullptr);
  options.detail = true;
  const std::vector<ProjectorImage> detailed =
      RenderProjectorImages(rig, stage.scene, emittance, options, nullptr);
  // Per pixel, the light with detail over the light without, against the texture at the wall
  // point the pixel's centre ray meets (ray–plane, independent of the rig's maps); red and green
  // per (patch, projector), blue (no detail) must stay as it was.
  double worst = 1.0, mean = 0.0, worst_rms = 0.0, worst_mean = 0.0, blue_worst = 0.0;
  int pairs = 0;
  std::vector<PatchSample> samples;
  for (size_t k = 0; k < stage.projectors.size(); ++k) {
    const Projector& projector = stage.projectors[k];
    const ProjectorGeometry& geometry = projector.geometry;
    const Eigen::Isometry3d world_from_proj = geometry.proj_from_world().inverse();
    const Vec3 centre = geometry.CentreInWorld();
    const ProjectorMap& map = rig.maps[k];
    const double max_code = projector.photometry.MaxCode();
    for (int i = 0; i < rig.size(); ++i) {
      if (level.patches[i].surface != Stage::kWall) continue;
      std::array<std::vector<double>, 2> ratio, texture;
      for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
        const int index = map.pixels_by_patch[position];
        const int x = index % map.width, y = index / map.width;
        const cv::Vec3w plain_code = plain[k].codes.at<cv::Vec3w>(y, x);
        const cv::Vec3w detail_code = detailed[k].codes.at<cv::Vec3w>(y, x);
        Vec3 plain_light, detail_light;
        for (int c = 0; c < 3; ++c) {
          plain_light[c] = projector.photometry.response[c].Light(plain_code[c] / max_code);
          detail_light[c] = projector.photometry.response[c].Light(detail_code[c] / max_code);
        }
        // Pixels the blending ramps down carry too few code steps to show the texture.
        if (plain_light.minCoeff() < 0.1) continue;
        const Vec3 direction = world_from_proj.rotation() * geometry.Unproject(Vec2(x, y));
        const Vec3 point = centre + (3.0 - centre.y()) / direction.y() * direction;
        const Vec3 stripes = Stripes(Vec2(point.x() / 4.0, point.z() / 2.5));
        for (int c = 0; c < 2; ++c) {
          ratio[c].push_back(detail_light[c] / plain_light[c]);
          texture[c].push_back(stripes[c]);
        }
        blue_worst = std::max(blue_worst, std::abs(detail_light[2] - plain_light[2]));
      }
      if (ratio[0].size() < 100) continue;
      for (int c = 0; c < 2; ++c) {
        const double correlation = Correlation(ratio[c], texture[c]);
        worst = std::min(worst, correlation);
        mean += correlation;
        ++pairs;
        // And with the texture's contrast: the ratio is T / T̄, proportional to T (no offset,
        // no compressed contrast), T̄ the texture's mean over the patch (Gauss points here; the
        // renderer weights its pixels by footprint and blending, the same to a pixel row).
        double rt = 0.0, tt = 0.0;
        for (size_t j = 0; j < ratio[c].size(); ++j) {
          rt += ratio[c][j] * texture[c][j];
          tt += texture[c][j] * texture[c][j];
        }
        const double slope = rt / tt;
        double squares = 0.0;
        for (size_t j = 0; j < ratio[c].size(); ++j)
          squares += std::pow(ratio[c][j] - slope * texture[c][j], 2);
        worst_rms = std::max(worst_rms, std::sqrt(squares / ratio[c].size()));
        if (WhollyLit(rig, i)) {
          SamplePatch(level.patches[i], 16, &samples);
          double patch_mean = 0.0;
          for (const PatchSample& sample : samples)
            patch_mean += sample.weight / level.patches[i].area * Stripes(sample.uv)[c];
          worst_mean = std::max(worst_mean, std::abs(slope * patch_mean - 1.0));
        }
      }
    }
  }
  EXPECT_GT(pairs, 100);
  EXPECT_GT(worst, 0.95);
  EXPECT_GT(mean / pairs, 0.98);
  // Measured: correlation 0.9988 worst, 0.9999 mean; residual 0.010; mean 1.2% off.
  EXPECT_LT(worst_rms, 0.03);
  EXPECT_LT(worst_mean, 0.03);
  EXPECT_LT(blue_worst, 0.02);  // one 8-bit code step near 0.5 (measured: identical codes)
}

TEST(ProjectorImages, DetailLeavesUntexturedSurfacesAlone) {
  const Stage stage = MakeStage({});
  ProjectionRigOptions rig_options;
  rig_options.texture_coordinates = true;
  const ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, rig_options);
  const Eigen::MatrixX3d emittance = RandomEmittance(rig, 7);
  for (const DitherMethod dither :
       {DitherMethod::kOrdered, DitherMethod::kErrorDiffusion, DitherMethod::kNone}) {
    RenderOptions options;
    options.dither = dither;
    RenderSummary plain_summary, detail_summary;
    const std::vector<ProjectorImage> plain =
        RenderProjectorImages(rig, emittance, options, &plain_summary);
    options.detail = true;
    const std::vector<ProjectorImage> detailed =
        RenderProjectorImages(rig, stage.scene, emittance, options, &detail_summary);
    ASSERT_EQ(detailed.size(), plain.size());
    for (size_t k = 0; k < plain.size(); ++k) {
      EXPECT_EQ(cv::norm(detailed[k].codes, plain[k].codes, cv::NORM_INF), 0.0)
          << DitherName(dither) << " projector " << k;
      // Pixels the seamless light's peaks saturate, the same with detail as without.
      EXPECT_EQ(detail_summary.detail_saturated_pixels[k], plain_summary.detail_saturated_pixels[k]);
    }
    EXPECT_EQ(detail_summary.detail_pixels, 0);
    EXPECT_EQ(detail_summary.delivered, plain_summary.delivered);
  }
}

TEST(ProjectorImages, DetailNeedsTheSceneAndTextureCoordinates) {
  const Stage stage = MakeStage({});
  const ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
  const Eigen::MatrixX3d emittance = 0.5 * (rig.lower + rig.upper);
  RenderOptions options;
  options.detail = true;
  EXPECT_THROW(RenderProjectorImages(rig, emittance, options, nullptr), std::invalid_argument);
  try {
    RenderProjectorImages(rig, stage.scene, emittance, options, nullptr);
    FAIL() << "no error";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("no texture coordinates"), std::string::npos)
        << error.what();
  }
  options.detail_min = 0.0;
  std::string why;
  EXPECT_FALSE(options.Check(&why));
  options.detail_min = 0.2;
  options.detail_max = 0.5;
  EXPECT_FALSE(options.Check(&why));
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
