// The GPU renderer of projector images (gl_renderer.h) against the CPU's (frame_plan.h), on
// Mesa's llvmpipe under a virtual X server: on a stage lit by two overlapping projectors (one
// with colour mixing), for flat and smooth light, without and with ordered dithering, on
// emittance between the bounds and near the upper bound (saturated patches), every pixel's codes
// are within one code step of the CPU's and few differ at all. A frame plan shaded on the CPU is
// RenderProjectorImages's images bit for bit; on the patches the planner does not refine, no
// pixel reaches full drive (its saturation bound holds); detail and error diffusion are refused;
// a display draws and presents frames separately. DISABLED_Timings is the benchmark of docs/projection.md.
#include "projection/gl_renderer.h"

#include <epoxy/gl.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/core.hpp>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "base/io.h"
#include "base/timing.h"
#include "capture/camera.h"
#include "projection/frame_plan.h"
#include "projection/glfw_display.h"
#include "projection/offscreen_gl.h"
#include "projection/render_steps.h"
#include "tests/projection/stage.h"
#include "tests/projection/xvfb.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::MakeStage;
using testing::Stage;
using testing::StageOptions;

// The screen holds a 1080p window (the benchmark's); the small stages draw into its lower left.
constexpr int kScreenWidth = 1920, kScreenHeight = 1080;

::testing::Environment* const xvfb =
    ::testing::AddGlobalTestEnvironment(new testing::XvfbEnvironment(kScreenWidth, kScreenHeight));

// The stage of the projection tests (two 320×240 projectors overlapping on the wall, a plate in
// front), the second projector with colour mixing so that the shader's mixing inverse and
// gamut clip are exercised.
struct Rig {
  Stage stage;
  ProjectionRig rig;
};
const Rig& SmallRig() {
  static const Rig* rig = [] {
    auto* made = new Rig{MakeStage({}), {}};
    made->stage.projectors[1].photometry.mixing << 0.9, 0.1, 0.0, 0.05, 0.9, 0.05, 0.0, 0.2, 0.8;
    made->stage.projectors[0].photometry.response[1] = ResponseCurve::Gamma(1.8);
    made->rig = BuildProjectionRig(made->stage.patches.fine, made->stage.projectors, {});
    return made;
  }();
  return *rig;
}

// E per patch and channel at lower + t (upper − lower), t uniform in [t_low, t_high], clipped by
// the renderer where t > 1.
Eigen::MatrixX3d Emittance(const ProjectionRig& rig, double t_low, double t_high, unsigned seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> t(t_low, t_high);
  Eigen::MatrixX3d emittance(rig.size(), 3);
  for (int i = 0; i < rig.size(); ++i) {
    for (int c = 0; c < 3; ++c)
      emittance(i, c) = rig.lower(i, c) + t(random) * (rig.upper(i, c) - rig.lower(i, c));
  }
  return emittance;
}

// A smooth E across the room, within [0.1, 0.6] of the range (run shifts it a little).
Eigen::MatrixX3d RampEmittance(const Stage& stage, const ProjectionRig& rig, int run) {
  Eigen::MatrixX3d emittance(rig.size(), 3);
  for (int i = 0; i < rig.size(); ++i) {
    const Vec3& c = stage.patches.fine.patches[i].centroid;
    const Eigen::RowVector3d t(0.1 + 0.1 * c.x() + 0.01 * run, 0.2 + 0.08 * c.x() + 0.05 * c.z(),
                               0.45);
    emittance.row(i) = rig.lower.row(i) + t.cwiseProduct(rig.upper.row(i) - rig.lower.row(i));
  }
  return emittance;
}

struct Difference {
  int largest = 0;        // largest |GPU − CPU| code over pixels and channels
  double fraction = 0.0;  // of the pixels, those with some channel different
};
Difference Compare(const ProjectorImage& gpu, const ProjectorImage& cpu) {
  Difference difference;
  long long differing = 0;
  for (int y = 0; y < cpu.codes.rows; ++y) {
    for (int x = 0; x < cpu.codes.cols; ++x) {
      const cv::Vec3w a = gpu.codes.at<cv::Vec3w>(y, x), b = cpu.codes.at<cv::Vec3w>(y, x);
      int largest = 0;
      for (int c = 0; c < 3; ++c) largest = std::max(largest, std::abs(int(a[c]) - int(b[c])));
      difference.largest = std::max(difference.largest, largest);
      differing += largest > 0;
    }
  }
  difference.fraction = double(differing) / cpu.codes.total();
  return difference;
}

struct Case {
  LightField light;
  DitherMethod dither;
  double t_low, t_high;  // emittance between the bounds (see Emittance)
  // The seamless field's bump radius (in √area): at the default most pixels sum 5 to 9 bumps
  // from the shader's per-pixel slots; at 2 some have more than its 12, at 3 most do (the shader
  // then evaluates every bump of the patch's list).
  double radius = SeamlessLightOptions().radius;
};

class GlRendererTest : public ::testing::TestWithParam<Case> {};

TEST_P(GlRendererTest, EqualsTheCpuWithinOneCodeStep) {
  SKIP_WITHOUT_XVFB();
  const Case& test = GetParam();
  const ProjectionRig& rig = SmallRig().rig;
  RenderOptions options;
  options.light = test.light;
  options.dither = test.dither;
  options.seamless.radius = test.radius;
  const FramePlanner planner(rig, options);
  const FramePlan plan = planner.Plan(Emittance(rig, test.t_low, test.t_high, 11));
  const std::vector<ProjectorImage> cpu = ShadeProjectorImages(planner, plan, nullptr);

  // Offscreen (EGL): no display server needed, so it runs on a compute GPU's machine too.
  OffscreenGl gl(kScreenWidth, kScreenHeight);
  std::printf("OpenGL %s (%s)\n", OpenGlDescription().c_str(), gl.description().c_str());
  // Both shader paths; Mesa's llvmpipe (the test machines' OpenGL) has compute shaders.
  ASSERT_TRUE(GlComputeShading()) << "the context has no OpenGL 4.3: the compute path is untested";
  for (const GlShading shading : {GlShading::kFragment, GlShading::kCompute}) {
    for (int k = 0; k < static_cast<int>(rig.projectors.size()); ++k) {
      GlProjectorRenderer renderer(planner, k, shading);
      ASSERT_EQ(renderer.shading(), shading);
      glClearColor(0.5f, 0.25f, 0.75f, 1.0f);  // what a pixel the shader missed would keep
      glClear(GL_COLOR_BUFFER_BIT);
      renderer.Draw(plan);
      const ProjectorImage gpu = renderer.ReadBack();
      ASSERT_EQ(gpu.codes.size(), cpu[k].codes.size());
      const Difference difference = Compare(gpu, cpu[k]);
      std::printf(
          "%s shader, %s light (radius %.1f), dither %s, t in [%.2f, %.2f], projector %d: %d of "
          "%d patches refined, %.4f%% of the pixels differ, by at most %d\n",
          GlShadingName(shading), LightFieldName(test.light), test.radius,
          DitherName(test.dither), test.t_low, test.t_high, k, plan.refined_patches, rig.size(),
          100.0 * difference.fraction, difference.largest);
      EXPECT_LE(difference.largest, 1);
      EXPECT_LT(difference.fraction, 0.01);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(
    Cases, GlRendererTest,
    ::testing::Values(Case{LightField::kFlat, DitherMethod::kNone, 0.0, 1.0},
                      Case{LightField::kFlat, DitherMethod::kOrdered, 0.0, 1.0},
                      Case{LightField::kSmooth, DitherMethod::kNone, 0.0, 1.0},
                      Case{LightField::kSmooth, DitherMethod::kOrdered, 0.0, 1.0},
                      // Near and above the upper bound: many patches saturate (step 2 refines
                      // them; τ = +inf where a patch needs every pixel at full drive).
                      Case{LightField::kFlat, DitherMethod::kOrdered, 0.8, 1.1},
                      Case{LightField::kSmooth, DitherMethod::kOrdered, 0.8, 1.1},
                      Case{LightField::kSmooth, DitherMethod::kNone, 1.0, 1.0},
                      Case{LightField::kSmooth, DitherMethod::kOrdered, 0.0, 1.0, 2.0},
                      Case{LightField::kSmooth, DitherMethod::kOrdered, 0.0, 1.0, 3.0}));

// The plan and its CPU shading are RenderProjectorImages, bit for bit, and the planner refines
// only the patches whose bound reaches full drive.
TEST(FramePlan, ShadedOnTheCpuIsRenderProjectorImages) {
  const ProjectionRig& rig = SmallRig().rig;
  for (const LightField light : {LightField::kFlat, LightField::kSmooth}) {
    for (const DitherMethod dither :
         {DitherMethod::kNone, DitherMethod::kOrdered, DitherMethod::kErrorDiffusion}) {
      for (const double t_high : {1.0, 1.1}) {
        RenderOptions options;
        options.light = light;
        options.dither = dither;
        const Eigen::MatrixX3d emittance = Emittance(rig, t_high - 0.9, t_high, 5);
        RenderSummary reference_summary, summary;
        const std::vector<ProjectorImage> reference =
            RenderProjectorImages(rig, emittance, options, &reference_summary);
        const FramePlan plan = PlanFrame(rig, emittance, options);
        const std::vector<ProjectorImage> shaded =
            ShadeProjectorImages(FramePlanner(rig, options), plan, &summary);
        EXPECT_LT(plan.refined_patches, rig.size());
        ASSERT_EQ(shaded.size(), reference.size());
        for (size_t k = 0; k < reference.size(); ++k) {
          EXPECT_EQ(cv::norm(shaded[k].codes, reference[k].codes, cv::NORM_INF), 0.0)
              << LightFieldName(light) << " " << DitherName(dither) << " projector " << k;
        }
        EXPECT_EQ(summary.delivered, reference_summary.delivered);
        EXPECT_EQ(summary.level_passes, reference_summary.level_passes);
        EXPECT_EQ(summary.saturated_pixels, reference_summary.saturated_pixels);
        EXPECT_EQ(summary.clipped_pixels, reference_summary.clipped_pixels);
        EXPECT_EQ(summary.patches_above_upper, reference_summary.patches_above_upper);
      }
    }
  }
}

// A display node's frames: the seamless bumps cached at every pixel and the images' buffers
// reused from frame to frame give the images a fresh planner gives, bit for bit, frame after
// frame (the second frame's plan differs from the first's, so a buffer left holding the first
// would show), and the buffers are indeed kept.
TEST(FramePlan, CachedBumpsAndReusedImagesShadeTheSame) {
  const ProjectionRig& rig = SmallRig().rig;
  for (const LightField light : {LightField::kFlat, LightField::kSmooth}) {
    RenderOptions options;
    options.light = light;
    const FramePlanner fresh(rig, options);
    FramePlanner cached(rig, options);
    cached.CacheBumps();
    if (light == LightField::kSmooth) {
      for (size_t k = 0; k < rig.maps.size(); ++k) EXPECT_TRUE(cached.field()->BumpsCached(k));
    }
    std::vector<ProjectorImage> reused;
    std::vector<const uint8_t*> buffers;
    for (const int seed : {3, 4, 5}) {
      const Eigen::MatrixX3d emittance = Emittance(rig, 0.1, 1.05, seed);
      const FramePlan plan = cached.Plan(emittance);
      const FramePlan reference_plan = fresh.Plan(emittance);
      EXPECT_EQ(plan.level, reference_plan.level);
      EXPECT_EQ(plan.refined_patches, reference_plan.refined_patches);
      const std::vector<ProjectorImage> reference =
          ShadeProjectorImages(fresh, reference_plan, nullptr);
      ShadeProjectorImages(cached, plan, nullptr, {}, &reused);
      ASSERT_EQ(reused.size(), reference.size());
      for (size_t k = 0; k < reference.size(); ++k) {
        EXPECT_EQ(cv::norm(reused[k].codes, reference[k].codes, cv::NORM_INF), 0.0)
            << LightFieldName(light) << " seed " << seed << " projector " << k;
        if (seed == 3) buffers.push_back(reused[k].codes.data);
        EXPECT_EQ(reused[k].codes.data, buffers[k]) << "projector " << k << ": a new buffer";
      }
    }
  }
  // The cache is per projector: caching one leaves the other evaluated, with the same images.
  RenderOptions options;
  FramePlanner one(rig, options);
  const std::vector<char> first_only = {1, 0};
  one.CacheBumps(&first_only);
  EXPECT_TRUE(one.field()->BumpsCached(0));
  EXPECT_FALSE(one.field()->BumpsCached(1));
  const Eigen::MatrixX3d emittance = Emittance(rig, 0.0, 1.0, 7);
  const std::vector<ProjectorImage> mixed = ShadeProjectorImages(one, one.Plan(emittance), nullptr);
  const FramePlanner fresh(rig, options);
  const std::vector<ProjectorImage> reference =
      ShadeProjectorImages(fresh, fresh.Plan(emittance), nullptr);
  for (size_t k = 0; k < reference.size(); ++k)
    EXPECT_EQ(cv::norm(mixed[k].codes, reference[k].codes, cv::NORM_INF), 0.0) << k;
}

// The CPU shading walks each channel's code from the last pixel's (down the map's order by
// share for a flat light, along the pixels of each row otherwise) instead of looking it up. Its
// codes are those of CodeTable::Quantise's lookup at every pixel, computed here pixel by pixel
// from the plan (and the seamless factors): 8- and 10-bit projectors, both dithers that shade by
// patch, both lights, patches at full drive and saturated pixels included. A map without the
// order by share gives the same images and counts; the delivered light differs only by the
// order of its sums. (The first projector has no colour mixing: the walk is its; the second's
// mixing keeps it on the lookup.)
// A plan keeps its refined patches' factors while the planner makes newer plans; the planner reuses
// the arrays only once no plan holds them.
TEST(FramePlan, APlanKeepsItsFactorsWhileNewerPlansAreMade) {
  const ProjectionRig& rig = SmallRig().rig;
  const RenderOptions options;  // seamless light
  FramePlanner planner(rig, options);
  const FramePlanner fresh(rig, options);
  const Eigen::MatrixX3d first = Emittance(rig, 0.1, 1.05, 3), second = Emittance(rig, 0.1, 1.05, 4);
  const std::vector<ProjectorImage> expected =
      ShadeProjectorImages(fresh, fresh.Plan(first), nullptr);
  const void* arrays = nullptr;
  {
    const FramePlan a = planner.Plan(first);
    ASSERT_GT(a.refined_patches, 0);
    ASSERT_TRUE(a.refined_factors);
    const FramePlan b = planner.Plan(second);
    ASSERT_GT(b.refined_patches, 0);
    EXPECT_NE(a.refined_factors.get(), b.refined_factors.get());  // a's are still a's
    const std::vector<ProjectorImage> shaded = ShadeProjectorImages(planner, a, nullptr);
    for (size_t k = 0; k < expected.size(); ++k)
      EXPECT_EQ(cv::norm(shaded[k].codes, expected[k].codes, cv::NORM_INF), 0.0) << k;
    arrays = b.refined_factors.get();
  }
  // Both plans gone: the next plan takes the last arrays made, and shades as a fresh planner.
  const FramePlan again = planner.Plan(first);
  EXPECT_EQ(again.refined_factors.get(), arrays);
  const std::vector<ProjectorImage> shaded = ShadeProjectorImages(planner, again, nullptr);
  for (size_t k = 0; k < expected.size(); ++k)
    EXPECT_EQ(cv::norm(shaded[k].codes, expected[k].codes, cv::NORM_INF), 0.0) << k;
}

// An E within one binary16 step of its upper bound is at the bound: the emittance a display node
// receives in half precision (rounded down by at most 2^-11 of itself) renders as the bound does.
TEST(FramePlan, EmittanceWithinABinary16StepOfTheUpperBoundIsFullDrive) {
  const ProjectionRig& rig = SmallRig().rig;
  const RenderOptions options;
  const FramePlanner planner(rig, options);
  const Eigen::MatrixX3d at = rig.upper;
  const Eigen::MatrixX3d rounded = rig.upper - std::ldexp(1.0, -11) * rig.upper.cwiseAbs();
  const Eigen::MatrixX3d below = rig.upper - std::ldexp(1.0, -8) * rig.upper.cwiseAbs();
  const FramePlan at_plan = planner.Plan(at), rounded_plan = planner.Plan(rounded),
                  below_plan = planner.Plan(below);
  int checked = 0;
  for (int i = 0; i < rig.size(); ++i) {
    if (!(rig.blended_area[i] > 0.0)) continue;
    for (int c = 0; c < 3; ++c) {
      if (!(rig.reflectance(i, c) > 0.0) || !(below(i, c) > rig.lower(i, c))) continue;
      EXPECT_EQ(at_plan.level(i, c), internal::kInfinity) << i;
      EXPECT_EQ(rounded_plan.level(i, c), internal::kInfinity) << i;
      EXPECT_LT(below_plan.level(i, c), internal::kInfinity) << i;  // 2^-8 below: not at the bound
      ++checked;
    }
  }
  EXPECT_GT(checked, 100);
  const std::vector<ProjectorImage> at_images = ShadeProjectorImages(planner, at_plan, nullptr);
  const std::vector<ProjectorImage> rounded_images =
      ShadeProjectorImages(planner, rounded_plan, nullptr);
  for (size_t k = 0; k < at_images.size(); ++k)
    EXPECT_EQ(cv::norm(at_images[k].codes, rounded_images[k].codes, cv::NORM_INF), 0.0) << k;
}

TEST(FramePlan, WalkedCodesAreTheLookedUpOnes) {
  for (const int bits : {8, 10}) {
    Stage stage = MakeStage({});
    stage.projectors[1].photometry.mixing << 0.9, 0.1, 0.0, 0.05, 0.9, 0.05, 0.0, 0.2, 0.8;
    stage.projectors[0].photometry.response[1] = ResponseCurve::Gamma(1.8);
    for (Projector& projector : stage.projectors) projector.photometry.bits = bits;
    const ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
    ASSERT_EQ(rig.maps[0].pixels_by_share.size(), size_t(rig.maps[0].lit_pixels));
    ProjectionRig by_pixel = rig;
    for (ProjectorMap& map : by_pixel.maps) {
      map.pixels_by_share.clear();
      map.share_by_share.clear();
      map.bayer_by_share.clear();
    }
    const ProjectorMap& map = rig.maps[0];
    const internal::ProjectorTables tables(rig.projectors[0]);
    for (const LightField light : {LightField::kFlat, LightField::kSmooth}) {
      for (const DitherMethod dither : {DitherMethod::kNone, DitherMethod::kOrdered}) {
        RenderOptions options;
        options.light = light;
        options.dither = dither;
        const FramePlanner planner(rig, options), reference_planner(by_pixel, options);
        for (const unsigned seed : {1u, 2u}) {
          const std::string what = std::to_string(bits) + " bits, " + LightFieldName(light) +
                                   ", " + DitherName(dither) + ", seed " + std::to_string(seed);
          const FramePlan plan =
              planner.Plan(Emittance(rig, 0.0, seed == 1 ? 1.0 : 1.3, seed));
          if (seed == 2) {
            EXPECT_TRUE((plan.level.array() == std::numeric_limits<double>::infinity()).any())
                << what;
          }
          RenderSummary summary, reference_summary;
          const std::vector<ProjectorImage> images = ShadeProjectorImages(planner, plan, &summary);
          const std::vector<ProjectorImage> reference =
              ShadeProjectorImages(reference_planner, plan, &reference_summary);
          for (size_t k = 0; k < images.size(); ++k) {
            EXPECT_EQ(cv::norm(images[k].codes, reference[k].codes, cv::NORM_INF), 0.0)
                << what << ", projector " << k;
          }
          EXPECT_EQ(summary.saturated_pixels, reference_summary.saturated_pixels) << what;
          EXPECT_EQ(summary.detail_saturated_pixels, reference_summary.detail_saturated_pixels)
              << what;
          EXPECT_GT(summary.saturated_pixels[0], 0) << what;
          EXPECT_LE((summary.delivered - reference_summary.delivered).cwiseAbs().maxCoeff(),
                    1e-12 * reference_summary.delivered.cwiseAbs().maxCoeff())
              << what;
          // The first projector's codes looked up pixel by pixel.
          const auto* codes = reinterpret_cast<const cv::Vec3w*>(images[0].codes.data);
          std::vector<Eigen::Vector3f> factors;
          long long differing = 0;
          for (int i = 0; i < rig.size(); ++i) {
            const int first = map.patch_begin[i], count = map.patch_begin[i + 1] - first;
            factors.assign(count, Eigen::Vector3f::Ones());
            if (light == LightField::kSmooth && !planner.field()->Flat(i)) {
              planner.field()->PatchFactors(i, 0, plan.node_value, plan.mean, factors.data());
            }
            for (int j = 0; j < count; ++j) {
              const int32_t index = map.pixels_by_patch[first + j];
              const double threshold =
                  dither == DitherMethod::kOrdered
                      ? internal::BayerThreshold(index % map.width, index / map.width)
                      : 0.5;
              for (int c = 0; c < 3; ++c) {
                const double tau = plan.level(i, c);
                const double r =
                    tau == std::numeric_limits<double>::infinity()
                        ? 1.0
                        : std::min(1.0, map.share[index] * (tau * tables.inverse_delta[c]) *
                                            double(factors[j][c]));
                differing += codes[index][c] != tables.codes[c].Quantise(r, threshold);
              }
            }
          }
          EXPECT_EQ(differing, 0) << what;
        }
      }
    }
  }
}

// A display node shades only its own projectors: their images are those of the whole rig's
// shading, bit for bit, the others are left empty, and so is the delivered exitance (the rest of
// the rig's light is not known); an index outside the rig is refused.
TEST(FramePlan, ShadesOnlyTheProjectorsAsked) {
  const ProjectionRig& rig = SmallRig().rig;
  ASSERT_EQ(rig.projectors.size(), 2u);
  for (const LightField light : {LightField::kFlat, LightField::kSmooth}) {
    for (const DitherMethod dither : {DitherMethod::kOrdered, DitherMethod::kErrorDiffusion}) {
      RenderOptions options;
      options.light = light;
      options.dither = dither;
      const FramePlanner planner(rig, options);
      const FramePlan plan = planner.Plan(Emittance(rig, 0.2, 1.05, 9));
      RenderSummary all_summary, one_summary;
      const std::vector<ProjectorImage> all = ShadeProjectorImages(planner, plan, &all_summary);
      for (const int k : {0, 1}) {
        const std::vector<ProjectorImage> one =
            ShadeProjectorImages(planner, plan, &one_summary, {k});
        ASSERT_EQ(one.size(), 2u);
        EXPECT_EQ(cv::norm(one[k].codes, all[k].codes, cv::NORM_INF), 0.0)
            << LightFieldName(light) << " " << DitherName(dither) << " projector " << k;
        EXPECT_TRUE(one[1 - k].codes.empty());
        EXPECT_EQ(one_summary.saturated_pixels[k], all_summary.saturated_pixels[k]);
        EXPECT_EQ(one_summary.saturated_pixels[1 - k], 0);
        EXPECT_EQ(one_summary.delivered.rows(), 0);
      }
      EXPECT_EQ(all_summary.delivered.rows(), rig.size());
      EXPECT_THROW(ShadeProjectorImages(planner, plan, nullptr, {2}), std::invalid_argument);
    }
  }
}

// The saturation bound holds: on every patch the planner did not refine, no pixel of any
// projector reaches full drive (share · τ · m / Δ < 1 with m the pixel's exact seamless factor),
// so step 2 would have left its τ unchanged.
TEST(FramePlan, UnrefinedPatchesHaveNoPixelAtFullDrive) {
  const ProjectionRig& rig = SmallRig().rig;
  for (const LightField light : {LightField::kFlat, LightField::kSmooth}) {
    RenderOptions options;
    options.light = light;
    const FramePlanner planner(rig, options);
    for (const double t_high : {0.6, 1.0, 1.1}) {
      const FramePlan plan = planner.Plan(Emittance(rig, t_high - 0.6, t_high, 9));
      ASSERT_EQ(static_cast<int>(plan.refined.size()), rig.size());
      double highest = 0.0;  // of share · τ · m / Δ over the unrefined patches' pixels
      for (size_t k = 0; k < rig.maps.size(); ++k) {
        const ProjectorMap& map = rig.maps[k];
        const ProjectorPhotometry& photometry = rig.projectors[k].photometry;
        for (int i = 0; i < rig.size(); ++i) {
          if (plan.refined[i]) continue;
          for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
            const Eigen::Vector3f m =
                planner.field() ? planner.field()->Factor(i, map.point_by_patch[position],
                                                          plan.node_value, plan.mean)
                                : Eigen::Vector3f::Ones();
            for (int c = 0; c < 3; ++c) {
              if (std::isinf(plan.level(i, c))) continue;
              highest = std::max(highest, map.share[map.pixels_by_patch[position]] *
                                              plan.level(i, c) * m[c] /
                                              (photometry.max[c] - photometry.black[c]));
            }
          }
        }
      }
      std::printf("%s light, t in [%.1f, %.1f]: %d of %d patches refined; the others' pixels "
                  "reach at most %.3f of full drive\n",
                  LightFieldName(light), t_high - 0.6, t_high, plan.refined_patches, rig.size(),
                  highest);
      EXPECT_LT(highest, 1.0);
    }
  }
}

TEST(FramePlan, RefusesDetail) {
  const ProjectionRig& rig = SmallRig().rig;
  RenderOptions options;
  options.detail = true;
  try {
    FramePlanner planner(rig, options);
    FAIL() << "no error";
  } catch (const std::invalid_argument& error) {
    EXPECT_EQ(std::string(error.what()),
              "RenderOptions::detail: frame plans carry no per-pixel texture detail (render it "
              "with RenderProjectorImages and the scene)");
  }
  EXPECT_THROW(PlanFrame(rig, Eigen::MatrixX3d::Zero(3, 3), RenderOptions()),
               std::invalid_argument);
}

// Checked before any OpenGL call: no context needed.
TEST(GlProjectorRenderer, RefusesErrorDiffusionAndBadProjectors) {
  const ProjectionRig& rig = SmallRig().rig;
  RenderOptions options;
  options.dither = DitherMethod::kErrorDiffusion;
  const FramePlanner planner(rig, options);
  try {
    GlProjectorRenderer renderer(planner, 0);
    FAIL() << "no error";
  } catch (const std::invalid_argument& error) {
    EXPECT_EQ(std::string(error.what()),
              "GlProjectorRenderer: error diffusion is sequential per image and renders on the "
              "CPU only (ShadeProjectorImages)");
  }
  EXPECT_THROW(GlProjectorRenderer(FramePlanner(rig, RenderOptions()), 2), std::invalid_argument);
}

// A display node's frame: drawn into the back buffer, then presented (the swap's time
// returned); a CPU image the same way; the renderer's size must be the monitor's.
TEST(GlfwDisplay, DrawsAndPresentsSeparately) {
  SKIP_WITHOUT_XVFB();
  GlfwDisplay display(FindMonitor("0"));
  ProjectorImage image;
  image.codes = cv::Mat(kScreenHeight, kScreenWidth, CV_16UC3);
  cv::RNG(3).fill(image.codes, cv::RNG::UNIFORM, cv::Scalar::all(0), cv::Scalar::all(256));
  const int64_t before = SteadyNowNs();
  display.Draw(image);
  const int64_t presented = display.Present();
  EXPECT_GE(presented, before);
  cv::Mat expected;
  image.codes.convertTo(expected, CV_8UC3);
  EXPECT_EQ(cv::norm(display.ReadBack(), expected, cv::NORM_INF), 0.0);

  const ProjectionRig& rig = SmallRig().rig;
  const FramePlanner planner(rig, RenderOptions());
  display.MakeContextCurrent();
  GlProjectorRenderer renderer(planner, 0);
  try {
    display.Draw(renderer, planner.Plan(Emittance(rig, 0.0, 1.0, 1)));
    FAIL() << "no error";
  } catch (const IoError& error) {
    EXPECT_EQ(std::string(error.what()),
              display.Name() + ": image is 320x240, the monitor runs at 1920x1080");
  }
}

// The benchmark of docs/projection.md: three 1080p projectors on the stage at ~3000 patches;
// PlanFrame's time, the CPU shading's, and the GPU's for one projector (plan upload + draw +
// glFinish, into an offscreen framebuffer), medians of 20. Run by hand:
// build/release/tests/projection_gl_renderer_test
// --gtest_also_run_disabled_tests --gtest_filter='*Timings*'
TEST(GlProjectorRenderer, DISABLED_Timings) {
  StageOptions stage_options;
  stage_options.width = kScreenWidth;
  stage_options.height = kScreenHeight;
  stage_options.target_patches = 3000;
  Stage stage = MakeStage(stage_options);
  stage.projectors.push_back(testing::MakeStageProjector("middle", Vec3(2.0, -1.5, 1.6),
                                                         Vec3(2.0, 3.0, 1.0), stage_options));
  auto start = Clock::now();
  const ProjectionRig rig = BuildProjectionRig(stage.patches.fine, stage.projectors, {});
  std::printf("rig: %d patches, %zu projectors %dx%d, built in %.2f s\n", rig.size(),
              rig.projectors.size(), kScreenWidth, kScreenHeight, SecondsSince(start));
  const auto median = [](std::vector<double> seconds) {
    std::sort(seconds.begin(), seconds.end());
    return 1e3 * seconds[seconds.size() / 2];
  };
  constexpr int kRuns = 20;
  // Offscreen (EGL): no display server needed, so it runs on a compute GPU's machine too.
  OffscreenGl gl(kScreenWidth, kScreenHeight);
  std::printf("OpenGL %s (%s)\n", OpenGlDescription().c_str(), gl.description().c_str());
  for (const LightField light : {LightField::kFlat, LightField::kSmooth}) {
    RenderOptions options;
    options.light = light;
    start = Clock::now();
    const FramePlanner planner(rig, options);
    const double planner_seconds = SecondsSince(start);
    // PlanFrame on E uniform between the bounds (many patches saturate: the worst case for
    // step 2; neighbours' E differ as much as they can: the worst case for the seamless bound),
    // uniform within [0.1, 0.6] of the range, and a smooth ramp across the room within it (as
    // compensation solutions mostly are).
    std::vector<FramePlan> plans;
    std::vector<double> shade_seconds, gpu_seconds;
    std::string planning;
    for (const int kind : {0, 1, 2}) {
      std::vector<double> plan_seconds;
      int refined = 0;
      for (int run = 0; run < kRuns; ++run) {
        const Eigen::MatrixX3d emittance = kind == 0   ? Emittance(rig, 0.0, 1.0, run)
                                           : kind == 1 ? Emittance(rig, 0.1, 0.6, run)
                                                       : RampEmittance(stage, rig, run);
        start = Clock::now();
        const FramePlan plan = planner.Plan(emittance);
        plan_seconds.push_back(SecondsSince(start));
        refined = plan.refined_patches;
        if (kind == 0) plans.push_back(plan);
      }
      char line[200];
      std::snprintf(line, sizeof(line), "%s%.1f ms (%d patches refined) for %s",
                    planning.empty() ? "" : ", ", median(plan_seconds), refined,
                    kind == 0   ? "E in [0, 1]"
                    : kind == 1 ? "E in [0.1, 0.6]"
                                : "a ramp");
      planning += line;
    }
    for (int run = 0; run < 3; ++run) {
      start = Clock::now();
      ShadeProjectorImages(planner, plans[run], nullptr);
      shade_seconds.push_back(SecondsSince(start));
    }
    GlProjectorRenderer renderer(planner, 0);
    renderer.Draw(plans[0]);  // first draw: the driver compiles the shader for real
    renderer.Finish();
    for (int run = 0; run < kRuns; ++run) {
      start = Clock::now();
      renderer.Draw(plans[run]);
      renderer.Finish();
      gpu_seconds.push_back(SecondsSince(start));
    }
    std::printf(
        "%s light: planner (static) %.0f ms; PlanFrame median %s; CPU shading of %zu "
        "images median of 3 %.0f ms; GPU one image (upload + draw + glFinish) median "
        "%.1f ms\n",
        LightFieldName(light), 1e3 * planner_seconds, planning.c_str(), rig.projectors.size(),
        median(shade_seconds), median(gpu_seconds));
  }
}

}  // namespace
}  // namespace procam
