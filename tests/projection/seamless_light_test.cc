// Seamless light against the flat per-patch rendering: every patch receives the same flux (the
// light summed over its projector pixels, computed here from the codes), the light steps much
// less across patch borders, a field that is flat per surface stays flat, the field does not
// cross an edge of the desired appearance, and the direct light on the patches (integrated
// independently of the pixel maps) is the same.
#include "projection/seamless_light.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "projection/projector_images.h"
#include "tests/projection/stage.h"

namespace procam {
namespace {

using testing::MakeStage;
using testing::Stage;

// The flux above black each patch receives from the images (n,3): per lit pixel the light of
// its codes (response, times max − black, grey mixing), times its solid angle and the patch's
// coverage scale, summed over the patch's pixels of every projector.
Eigen::MatrixX3d FluxFromCodes(const ProjectionRig& rig,
                               const std::vector<ProjectorImage>& images) {
  Eigen::MatrixX3d flux = Eigen::MatrixX3d::Zero(rig.size(), 3);
  for (size_t k = 0; k < rig.maps.size(); ++k) {
    const ProjectorMap& map = rig.maps[k];
    const ProjectorPhotometry& photometry = rig.projectors[k].photometry;
    for (size_t index = 0; index < map.patch.size(); ++index) {
      const int i = map.patch[index];
      if (i < 0) continue;
      const cv::Vec3w code =
          images[k].codes.at<cv::Vec3w>(int(index) / map.width, int(index) % map.width);
      for (int c = 0; c < 3; ++c) {
        const double light = photometry.response[c].Light(double(code[c]) / photometry.MaxCode());
        flux(i, c) += rig.coverage_scale(i, k) * map.pixel_solid_angle * light *
                      (photometry.max[c] - photometry.black[c]);
      }
    }
  }
  return flux;
}

// E as a compensation solution has it on this stage: a ramp across the room, mostly away from the
// bounds (the pixels of the far corners still saturate).
Eigen::MatrixX3d RampEmittance(const PatchLevel& level, const ProjectionRig& rig) {
  Eigen::MatrixX3d emittance(rig.size(), 3);
  for (int i = 0; i < rig.size(); ++i) {
    const Vec3& c = level.patches[i].centroid;
    const Eigen::RowVector3d t(0.2 + 0.15 * c.x(), 0.3 + 0.1 * c.x() + 0.05 * c.z(), 0.5);
    emittance.row(i) = rig.lower.row(i) + t.cwiseProduct(rig.upper.row(i) - rig.lower.row(i));
  }
  return emittance;
}

// Mean relative difference of the irradiance that projector 0 sends (per unit blending weight:
// light × gain / w, channel 1) between horizontally neighbouring pixels on `surface`, across patch
// borders and within patches; pixels at code 0 or full drive are left out.
struct Steps {
  double across = 0, within = 0;
};
Steps LightSteps(const ProjectionRig& rig, const ProjectorImage& image, int surface) {
  const ProjectorMap& map = rig.maps[0];
  const ProjectorPhotometry& photometry = rig.projectors[0].photometry;
  const auto irradiance = [&](int index, double* value) {
    const int code = image.codes.at<cv::Vec3w>(index / map.width, index % map.width)[1];
    if (code == 0 || code == photometry.MaxCode()) return false;
    *value = photometry.response[1].Light(double(code) / photometry.MaxCode()) * map.gain[index] /
             map.weight[index];
    return true;
  };
  double across = 0, within = 0;
  int across_count = 0, within_count = 0;
  for (int y = 0; y < map.height; ++y) {
    for (int x = 0; x + 1 < map.width; ++x) {
      const int index = y * map.width + x;
      const int a = map.patch[index], b = map.patch[index + 1];
      if (a < 0 || b < 0 || rig.surface[a] != surface || rig.surface[b] != surface) continue;
      double value_a = 0, value_b = 0;
      if (!irradiance(index, &value_a) || !irradiance(index + 1, &value_b)) continue;
      const double step = std::abs(value_a - value_b) / (0.5 * (value_a + value_b));
      if (a != b) {
        across += step;
        ++across_count;
      } else {
        within += step;
        ++within_count;
      }
    }
  }
  return {across / std::max(1, across_count), within / std::max(1, within_count)};
}

TEST(SeamlessLight, EachPatchReceivesTheFluxOfTheFlatRendering) {
  const Stage stage = MakeStage({});
  const ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
  const Eigen::MatrixX3d emittance = RampEmittance(stage.patches.fine, rig);
  RenderOptions flat_options, smooth_options;
  flat_options.light = LightField::kFlat;
  smooth_options.light = LightField::kSmooth;
  for (const DitherMethod dither : {DitherMethod::kNone, DitherMethod::kOrdered}) {
    flat_options.dither = smooth_options.dither = dither;
    RenderSummary flat_summary, smooth_summary;
    const auto flat = RenderProjectorImages(rig, emittance, flat_options, &flat_summary);
    const auto smooth = RenderProjectorImages(rig, emittance, smooth_options, &smooth_summary);
    const Eigen::MatrixX3d flat_flux = FluxFromCodes(rig, flat),
                           smooth_flux = FluxFromCodes(rig, smooth);
    double worst = 0.0, mean = 0.0;
    int compared = 0;
    for (int i = 0; i < rig.size(); ++i) {
      if (!(rig.blended_area[i] > 0.0)) continue;
      for (int c = 0; c < 3; ++c) {
        const double relative = std::abs(smooth_flux(i, c) - flat_flux(i, c)) / flat_flux(i, c);
        worst = std::max(worst, relative);
        mean += relative;
        ++compared;
      }
    }
    mean /= compared;
    // Quantisation alone (8 bits, ~20×20 pixels per patch): the same flux to a fraction of a
    // code step per pixel; rounding without dither shifts a whole patch by up to ½ step.
    EXPECT_LT(mean, 3e-3) << DitherName(dither);
    EXPECT_LT(worst, 2.5e-2) << DitherName(dither);
    EXPECT_LT(smooth_summary.max_relative_error, 2e-3) << DitherName(dither);
    // And the light is smooth: it steps across patch borders hardly more than within patches.
    const Steps flat_steps = LightSteps(rig, flat[0], Stage::kWall);
    const Steps smooth_steps = LightSteps(rig, smooth[0], Stage::kWall);
    std::printf(
        "%s: relative light steps across borders / within patches: flat %.3f / %.3f, smooth %.3f / "
        "%.3f\n",
        DitherName(dither), flat_steps.across, flat_steps.within, smooth_steps.across,
        smooth_steps.within);
    EXPECT_LT(smooth_steps.across - smooth_steps.within,
              0.25 * (flat_steps.across - flat_steps.within))
        << DitherName(dither);
  }
}

TEST(SeamlessLight, DirectLightOnThePatchesIsThatOfTheFlatRendering) {
  testing::StageOptions stage_options;
  stage_options.bits = 10;
  const Stage stage = MakeStage(stage_options);
  const PatchLevel& level = stage.patches.fine;
  const ProjectionRig rig = BuildProjectionRig(level, stage.projectors, {});
  const Eigen::MatrixX3d emittance = RampEmittance(level, rig);
  RenderOptions flat_options;
  flat_options.light = LightField::kFlat;
  const auto flat = RenderProjectorImages(rig, emittance, flat_options, nullptr);
  const auto smooth = RenderProjectorImages(rig, emittance, RenderOptions(), nullptr);
  const Eigen::MatrixX3d flat_light = SimulateDirectLight(level, stage.projectors, flat, 8);
  const Eigen::MatrixX3d smooth_light = SimulateDirectLight(level, stage.projectors, smooth, 8);
  double mean = 0.0;
  int compared = 0;
  for (int i = 0; i < rig.size(); ++i) {
    if (!(flat_light(i, 1) > 0.0)) continue;  // patches no projector lights
    mean += std::abs(smooth_light(i, 1) / flat_light(i, 1) - 1.0);
    ++compared;
  }
  mean /= std::max(1, compared);
  std::printf("direct light, smooth / flat − 1: mean |.| %.2e over %d patches\n", mean, compared);
  EXPECT_LT(mean, 5e-3);
}

// A field that is constant over each surface has nothing to smooth: factors exactly 1. So does
// a field that steps only where the desired colour steps.
TEST(SeamlessLight, FlatFieldsAndDesiredEdgesAreLeftAlone) {
  const Stage stage = MakeStage({});
  ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
  Eigen::MatrixX3d exitance(rig.size(), 3);
  for (int i = 0; i < rig.size(); ++i) exitance.row(i).setConstant(1.0 + rig.surface[i]);
  const auto check_ones = [&](const char* what) {
    const auto factors = SeamlessLightFactors(rig, exitance, {});
    for (const auto& projector : factors) {
      for (const Eigen::Vector3f& m : projector)
        ASSERT_LT((m - Eigen::Vector3f::Ones()).cwiseAbs().maxCoeff(), 1e-5) << what;
    }
  };
  check_ones("constant per surface");
  // The wall's left half desired darker than its right half, and lit so.
  for (int i = 0; i < rig.size(); ++i) {
    if (rig.surface[i] != Stage::kWall) continue;
    const bool left = stage.patches.fine.patches[i].centroid.x() < 2.0;
    rig.desired.row(i).setConstant(left ? 0.3 : 0.6);
    exitance.row(i).setConstant(left ? 0.5 : 1.0);
  }
  check_ones("a step where the desired colour steps");
}

TEST(SeamlessLight, RejectsBadInput) {
  const Stage stage = MakeStage({});
  ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
  const Eigen::MatrixX3d exitance = Eigen::MatrixX3d::Ones(rig.size(), 3);
  SeamlessLightOptions options;
  options.radius = 0.1;
  EXPECT_THROW(SeamlessLightFactors(rig, exitance, options), std::invalid_argument);
  EXPECT_THROW(SeamlessLightFactors(rig, -exitance, {}), std::invalid_argument);
  EXPECT_THROW(SeamlessLightFactors(rig, Eigen::MatrixX3d::Ones(3, 3), {}), std::invalid_argument);
  rig.maps[0].point_by_patch.clear();
  EXPECT_THROW(SeamlessLightFactors(rig, exitance, {}), std::invalid_argument);
}

}  // namespace
}  // namespace procam
