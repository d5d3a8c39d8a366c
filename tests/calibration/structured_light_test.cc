// Structured light: exact round trips on ideal captures, and decoding in the synthetic tiny box
// (a 1 m open box: strong interreflections) against its geometry — the point each camera pixel
// sees, projected into the projector — comparing the naive global threshold with the robust
// decoder (complementary patterns, XOR codes, phase shifting).
#include "calibration/structured_light.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "calibration/registration.h"
#include "datasets_synthetic/simulated_rig.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "geometry/ray_scene.h"

namespace procam {
namespace {

// The patterns themselves as captures: camera pixel (x, y) sees projector pixel (x, y).
std::vector<cv::Mat> IdealCaptures(const CaptureSequence& sequence) {
  std::vector<cv::Mat> captured;
  for (const Pattern& pattern : sequence.patterns) captured.push_back(pattern.image);
  return captured;
}

TEST(StructuredLight, IdealCapturesDecodeToTheProjectorPixel) {
  for (const int period : {0, 16}) {
    for (const bool xor_codes : {false, true}) {
      StructuredLightOptions options;
      options.width = 200;  // not a power of two: the code is truncated
      options.height = 72;
      options.phase_period = period;
      options.xor_codes = xor_codes;
      const CaptureSequence sequence = MakeStructuredLightSequence(options);
      const StructuredLightMap map = DecodeStructuredLight(options, IdealCaptures(sequence));
      EXPECT_EQ(cv::countNonZero(map.mask), options.width * options.height);
      double worst = 0.0;
      for (int v = 0; v < options.height; ++v) {
        for (int u = 0; u < options.width; ++u) {
          worst = std::max<double>(worst, std::abs(map.column.at<float>(v, u) - u));
          worst = std::max<double>(worst, std::abs(map.row.at<float>(v, u) - v));
        }
      }
      // Phase: 8-bit sinusoids, 4 steps.
      EXPECT_LT(worst, period ? 0.05 : 1e-9) << "period " << period << " xor " << xor_codes;
    }
  }
}

// A surface lit at a grazing angle crowds several projector columns into each camera pixel: here
// every capture averaged over 8 camera pixels along x, which turns the 4-pixel stripes of the
// finest shown column plane (and, XORed with it, every column plane) into flat grey, while the
// rows, constant along x, stay as shown. The rows decode on their own; the columns are refused.
TEST(StructuredLight, EachAxisDecodesOnItsOwn) {
  StructuredLightOptions options;
  options.width = 128;
  options.height = 64;
  const CaptureSequence sequence = MakeStructuredLightSequence(options);
  std::vector<cv::Mat> captured;
  for (const cv::Mat& ideal : IdealCaptures(sequence)) {
    cv::Mat grey;
    ideal.convertTo(grey, CV_32F);
    cv::Mat crowded(grey.size(), grey.type(), cv::Scalar::all(0));
    for (int v = 0; v < grey.rows; ++v)
      for (int u = 0; u < grey.cols; ++u)
        for (int j = 0; j < 8; ++j)  // wrapping around: every pixel sees one whole period
          crowded.at<cv::Vec3f>(v, u) += grey.at<cv::Vec3f>(v, (u + j) % grey.cols) / 8.0f;
    captured.push_back(crowded);
  }
  const StructuredLightMap map = DecodeStructuredLight(options, captured);
  const int pixels = options.width * options.height;
  EXPECT_EQ(cv::countNonZero(map.mask), 0);
  EXPECT_EQ(map.ambiguous, pixels);  // each pixel counted once
  int rows = 0, columns = 0;
  double worst = 0.0;
  for (int v = 0; v < options.height; ++v) {
    for (int u = 0; u < options.width; ++u) {
      columns += std::isfinite(map.column.at<float>(v, u));
      if (!std::isfinite(map.row.at<float>(v, u))) continue;
      ++rows;
      worst = std::max<double>(worst, std::abs(map.row.at<float>(v, u) - v));
    }
  }
  EXPECT_EQ(columns, 0);
  EXPECT_EQ(rows, pixels);
  EXPECT_LT(worst, 0.05);  // as IdealCapturesDecodeToTheProjectorPixel: 8-bit sinusoids

  // The correspondences: none on both axes, every pixel on its row alone but one, whose row is
  // made to disagree with its neighbours' (as a code that passed its tests by chance does).
  StructuredLightMap chance = map;
  chance.row = map.row.clone();
  chance.row.at<float>(20, 30) += 40.0f;
  const ProjectorObservations observations =
      ObservationsFromMap(chance, "p", options.width, options.height);
  EXPECT_TRUE(observations.camera_pixels.empty());
  ASSERT_EQ(observations.one_axis_camera_pixels.size(), static_cast<size_t>(pixels - 1));
  EXPECT_EQ(std::count(observations.one_axis_camera_pixels.begin(),
                       observations.one_axis_camera_pixels.end(), Vec2(30, 20)),
            0);
  const Vec2& camera_pixel = observations.one_axis_camera_pixels.back();
  const Vec2& decoded = observations.one_axis_projector_pixels.back();
  EXPECT_EQ(camera_pixel, Vec2(options.width - 1, options.height - 1));
  EXPECT_TRUE(std::isnan(decoded.x()));
  EXPECT_NEAR(decoded.y(), options.height - 1, 0.05);
}

TEST(StructuredLight, OptionsAreChecked) {
  StructuredLightOptions options;
  std::string why;
  options.phase_period = 12;
  EXPECT_FALSE(options.Check(&why));
  EXPECT_NE(why.find("power of two"), std::string::npos) << why;
  options.phase_period = 16;
  options.rows = options.columns = false;
  EXPECT_FALSE(options.Check(&why));
  options.columns = true;
  EXPECT_TRUE(options.Check(&why));
  EXPECT_THROW(DecodeStructuredLight(options, {cv::Mat(4, 4, CV_8UC1)}), std::invalid_argument);
}


struct Accuracy {
  int lit = 0;        // camera pixels the projector lights (geometry)
  int correct = 0;    // of those, within 1 projector pixel on both axes
  int wrong = 0;      // decoded anywhere (lit or not) but off by more than 1 pixel, or unlit
  double sq = 0.0;    // squared error of the correct ones, both axes
  double Rms() const { return correct ? std::sqrt(sq / (2.0 * correct)) : 0.0; }
};

class TinyBox : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const SyntheticScene synthetic = MakeSyntheticScene("tiny_box", 100);
    std::vector<Projector> projectors;
    for (const DevicePlacement& placement : synthetic.projectors)
      projectors.push_back(ProjectorFromPlacement(placement));
    SimulatedRigOptions options;
    options.solver_patches = 100;
    rig_ = new SimulatedRig(synthetic.scene, projectors, CameraFromPlacement(synthetic.camera),
                            options);
    // Ground truth: where projector 0 lights the point each camera pixel sees.
    const RayScene surfaces(rig_->scene());
    const ProjectorGeometry& geometry = rig_->projectors()[0].geometry;
    truth_ = cv::Mat(rig_->camera().height(), rig_->camera().width(), CV_32FC2,
                     cv::Scalar::all(std::nanf("")));
    for (int row = 0; row < truth_.rows; ++row)
      for (int col = 0; col < truth_.cols; ++col) {
        Vec3 point, normal;
        Vec2 pixel;
        if (!rig_->PointSeenByPixel(row, col, &point, &normal)) continue;
        if (geometry.Gain(point, normal, &pixel) <= 0.0 || !geometry.InImage(pixel)) continue;
        if (surfaces.Occluded(point, geometry.CentreInWorld(), 1e-4)) continue;
        truth_.at<cv::Vec2f>(row, col) = cv::Vec2f(pixel.x(), pixel.y());
      }
  }
  static void TearDownTestSuite() { delete rig_; }

  // Linear photos (noise, vignetting) of projector 0 showing each pattern, projector 1 black.
  static std::vector<cv::Mat> Capture(const CaptureSequence& sequence) {
    const ProjectorGeometry& other = rig_->projectors()[1].geometry;
    ProjectorImage dark{cv::Mat(other.height(), other.width(), CV_16UC3, cv::Scalar::all(0)), 8};
    std::vector<cv::Mat> captured;
    uint32_t seed = 0;
    for (const Pattern& pattern : sequence.patterns)
      captured.push_back(rig_->PhotographLinear({CodesFromPattern(pattern.image, rig_->projectors()[0]), dark}, ++seed));
    return captured;
  }

  static Accuracy Score(const StructuredLightMap& map) {
    Accuracy accuracy;
    for (int row = 0; row < truth_.rows; ++row)
      for (int col = 0; col < truth_.cols; ++col) {
        const cv::Vec2f truth = truth_.at<cv::Vec2f>(row, col);
        const bool lit = !std::isnan(truth[0]);
        const bool decoded = map.mask.at<uint8_t>(row, col) != 0;
        accuracy.lit += lit;
        if (!decoded) continue;
        const double du = map.column.at<float>(row, col) - truth[0];
        const double dv = map.row.at<float>(row, col) - truth[1];
        if (!lit || std::abs(du) > 1.0 || std::abs(dv) > 1.0) {
          ++accuracy.wrong;
          continue;
        }
        ++accuracy.correct;
        accuracy.sq += du * du + dv * dv;
      }
    return accuracy;
  }

  static SimulatedRig* rig_;
  static cv::Mat truth_;  // CV_32FC2 projector (x, y), NaN where projector 0 does not light
};
SimulatedRig* TinyBox::rig_ = nullptr;
cv::Mat TinyBox::truth_;

TEST_F(TinyBox, RobustDecodingBeatsTheGlobalThresholdUnderInterreflections) {
  const ProjectorGeometry& geometry = rig_->projectors()[0].geometry;
  StructuredLightOptions plain;  // textbook Gray code to single pixels
  plain.width = geometry.width();
  plain.height = geometry.height();
  plain.phase_period = 0;
  plain.xor_codes = false;
  StructuredLightOptions robust = plain;
  robust.phase_period = 16;
  robust.xor_codes = true;
  robust.pattern_gamma = rig_->projectors()[0].photometry.response[0].gamma();
  StructuredLightOptions phase_only = robust;
  phase_only.xor_codes = false;

  const std::vector<cv::Mat> plain_captures = Capture(MakeStructuredLightSequence(plain));
  const std::vector<cv::Mat> robust_captures = Capture(MakeStructuredLightSequence(robust));
  const std::vector<cv::Mat> phase_captures = Capture(MakeStructuredLightSequence(phase_only));

  struct Case {
    const char* name;
    const StructuredLightOptions* options;
    const std::vector<cv::Mat>* captures;
    Binarization binarization;
  };
  const Case cases[] = {
      {"Gray, global threshold", &plain, &plain_captures, Binarization::kGlobalThreshold},
      {"Gray, per-pixel threshold", &plain, &plain_captures, Binarization::kPixelThreshold},
      {"Gray, complementary", &plain, &plain_captures, Binarization::kComplementary},
      {"Gray+phase, complementary", &phase_only, &phase_captures, Binarization::kComplementary},
      {"XOR Gray+phase, complementary", &robust, &robust_captures, Binarization::kComplementary},
  };
  std::vector<Accuracy> results;
  for (const Case& c : cases) {
    StructuredLightDecodeOptions decode;
    decode.binarization = c.binarization;
    const StructuredLightMap map = DecodeStructuredLight(*c.options, *c.captures, decode);
    const Accuracy a = Score(map);
    results.push_back(a);
    std::printf("%-32s lit %d: correct (<=1 px) %.1f%%, wrong %d (%.2f%% of decoded), rms %.3f px; "
                "refused: shadow %lld, ambiguous %lld, weak phase %lld\n",
                c.name, a.lit, 100.0 * a.correct / a.lit, a.wrong,
                100.0 * a.wrong / std::max(1, a.correct + a.wrong), a.Rms(), map.shadowed,
                map.ambiguous, map.weak_phase);
  }
  const Accuracy& naive = results[0];
  const Accuracy& best = results[4];
  EXPECT_GT(best.correct, naive.correct);
  EXPECT_LT(best.wrong, naive.wrong);
  EXPECT_GT(best.correct, 0.95 * best.lit);
  EXPECT_LT(best.wrong, 0.005 * (best.correct + best.wrong));
}

}  // namespace
}  // namespace procam
