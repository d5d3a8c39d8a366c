// Camera linearity (calibration/camera_response.h): the inverse response of a camera with a
// known output curve (the test camera's response_gamma), recovered from exposure brackets, and
// the HDR merge that uses it. End to end: `procam capture` with the synthetic camera bracketing
// the lit tiny box, `procam calibrate response`, then a capture linearised with the result.
#include "calibration/camera_response.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "capture/sequencer.h"
#include "capture/session.h"
#include "capture/test_camera.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

constexpr double kGamma = 2.2;

// One mean frame per exposure of the test camera's chart (a horizontal ramp 0..1 in the upper
// two thirds; radiance 1 fills full scale at the reference exposure), as float digital numbers.
std::vector<cv::Mat> ChartBrackets(const std::vector<double>& exposures_us, double gamma) {
  TestCameraOptions options;
  options.width = 256;
  options.height = 96;
  options.pixel_format = PixelFormat::kBGR8;
  options.frame_rate = 1000;
  options.reference_exposure_us = 1000;
  options.noise_sigma = 0.5;
  options.response_gamma = gamma;
  TestCamera camera(options, SceneView());
  std::vector<cv::Mat> means;
  for (double exposure : exposures_us) {
    camera.SetExposure(exposure);
    camera.Start();
    cv::Mat sum(options.height, options.width, CV_32FC3, cv::Scalar::all(0));
    const int frames = 8;
    for (int f = 0; f < frames; ++f) {
      cv::Mat frame;
      camera.Grab(std::chrono::milliseconds(2000)).image.convertTo(frame, CV_32FC3);
      sum += frame;
    }
    camera.Stop();
    means.push_back(sum / frames);
  }
  return means;
}

std::vector<cv::Mat> Codes(const std::vector<cv::Mat>& means) {
  std::vector<cv::Mat> codes;
  for (const cv::Mat& mean : means) {
    cv::Mat code;
    mean.convertTo(code, CV_8U);
    codes.push_back(code);
  }
  return codes;
}

// Largest relative deviation of the merged ramp from the true radiance (ramp x/(W−1), in full
// scale per second at the reference exposure of 1 ms) over columns with radiance in [0.05, 1],
// upper rows, green channel.
double MaxRelativeError(const cv::Mat& merged) {
  double worst = 0.0;
  for (int x = 0; x < merged.cols; ++x) {
    const double truth = static_cast<double>(x) / (merged.cols - 1) / 1e-3;
    if (truth < 0.05 / 1e-3) continue;
    const double value = merged.at<cv::Vec3f>(10, x)[1];
    worst = std::max(worst, std::abs(value / truth - 1.0));
  }
  return worst;
}

const std::vector<double> kExposures = {62.5, 125, 250, 500, 1000, 2000, 4000};

TEST(CameraResponse, RecoversTheTestCamerasGammaAndLinearisesItsHdrMerge) {
  const std::vector<cv::Mat> means = ChartBrackets(kExposures, kGamma);
  CameraResponse response;
  std::string why;
  ASSERT_TRUE(
      CalibrateCameraResponse(Codes(means), kExposures, CameraResponseOptions(), &response, &why))
      << why;
  for (int c = 0; c < 3; ++c) {
    std::printf("channel %c: gamma %.4f (true %.1f), fit rms %.4f\n", "RGB"[c], response.gamma[c],
                kGamma, response.gamma_rms[c]);
    EXPECT_LT(std::abs(response.gamma[c] / kGamma - 1.0), 0.02) << "channel " << c;
    ASSERT_EQ(response.inverse[c].size(), 256u);
    EXPECT_EQ(response.inverse[c][0], 0.0);
    double worst = 0.0;  // the table against the true inverse response over mid codes
    for (int z = 26; z <= 230; ++z) {
      worst = std::max(worst, std::abs(response.inverse[c][z] - std::pow(z / 255.0, kGamma)));
    }
    std::printf("  table vs (z/255)^%.1f, codes 26..230: max |error| %.4f\n", kGamma, worst);
    EXPECT_LT(worst, 0.02) << "channel " << c;
  }

  // The HDR merge: with the inverse response the chart's ramp comes back linear; without it the
  // merge (which assumes a linear sensor) is far off.
  HdrMergeOptions linear_merge;
  const double plain = MaxRelativeError(MergeExposures(means, kExposures, 255.0, linear_merge));
  HdrMergeOptions linearised;
  linearised.inverse_response = {response.inverse[2], response.inverse[1], response.inverse[0]};
  const double corrected = MaxRelativeError(MergeExposures(means, kExposures, 255.0, linearised));
  std::printf("HDR merge of the ramp, max relative error: %.1f%% assuming linear, %.2f%% "
              "linearised\n", 100 * plain, 100 * corrected);
  EXPECT_GT(plain, 0.2);
  EXPECT_LT(corrected, 0.03);
}

TEST(CameraResponse, ALinearCameraComesOutLinear) {
  const std::vector<cv::Mat> means = ChartBrackets(kExposures, 1.0);
  CameraResponse response;
  std::string why;
  ASSERT_TRUE(
      CalibrateCameraResponse(Codes(means), kExposures, CameraResponseOptions(), &response, &why))
      << why;
  for (int c = 0; c < 3; ++c) EXPECT_LT(std::abs(response.gamma[c] - 1.0), 0.02);
}

TEST(CameraResponse, RefusesInputItCannotFit) {
  const cv::Mat image(8, 8, CV_8UC3, cv::Scalar::all(100));
  CameraResponse response;
  std::string why;
  EXPECT_FALSE(CalibrateCameraResponse({image, image}, {1000, 2000}, {}, &response, &why));
  EXPECT_NE(why.find("at least 3 exposures"), std::string::npos) << why;
  EXPECT_FALSE(
      CalibrateCameraResponse({image, image, image}, {1000, 2000, 2000}, {}, &response, &why));
  EXPECT_NE(why.find("must all differ"), std::string::npos) << why;
  const cv::Mat grey(8, 8, CV_8UC1, cv::Scalar(100));
  EXPECT_FALSE(
      CalibrateCameraResponse({image, image, grey}, {1000, 2000, 4000}, {}, &response, &why));
  EXPECT_NE(why.find("CV_8UC3"), std::string::npos) << why;
  HdrMergeOptions bad;
  bad.inverse_response = {{0.0, 0.5, 0.4}};
  EXPECT_FALSE(bad.Check(&why));
  EXPECT_NE(why.find("non-decreasing"), std::string::npos) << why;
}

nlohmann::json ReadJson(const std::filesystem::path& path) {
  std::ifstream file(path);
  return nlohmann::json::parse(file);
}

// The synthetic camera with a gamma-2.2 output, bracketing the tiny box lit white by projector 0.
TEST(CalibrateResponseCommand, CalibratesFromABracketedSessionAndLinearisesLaterCaptures) {
  testing::TempDir dir;
  const std::string camera =
      "'synthetic:tiny_box?patches=20&fps=1000&reference_exposure_us=1000&noise=0.5"
      "&response_gamma=2.2'";
  const std::string bracket = " --exposure-us 125,250,500,1000,2000,4000,8000";
  const testing::CommandRun capture = testing::RunProcam(
      "capture --camera " + camera + " --projector 0 --sequence photometric --levels 255"
      " --channels w --frames 4 --settle-ms 1" + bracket + " --out " + (dir / "bracket").string());
  ASSERT_EQ(capture.exit_code, 0) << capture.output;
  const testing::CommandRun run = testing::RunProcam(
      "calibrate response " + (dir / "bracket").string() + " --out " + (dir / "rig").string());
  std::printf("%s", run.output.c_str());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const nlohmann::json file = ReadJson(dir / "rig/camera_response.json");
  for (int c = 0; c < 3; ++c) {
    EXPECT_LT(std::abs(file["gamma"][c].get<double>() / 2.2 - 1.0), 0.02) << "channel " << c;
  }
  EXPECT_EQ(ReadJson(dir / "rig/rig.json")["camera"]["response"], "camera_response.json");

  // A capture linearised with the calibration: its HDR merge is proportional to the (linear)
  // merge of the same room photographed by a linear camera.
  const testing::CommandRun linearised = testing::RunProcam(
      "capture --camera " + camera + " --projector 0 --sequence photometric --levels 255"
      " --channels w --frames 4 --settle-ms 1" + bracket + " --camera-response " +
      (dir / "rig/camera_response.json").string() + " --out " + (dir / "corrected").string());
  ASSERT_EQ(linearised.exit_code, 0) << linearised.output;
  const std::string linear_camera =
      "'synthetic:tiny_box?patches=20&fps=1000&reference_exposure_us=1000&noise=0.5'";
  const testing::CommandRun reference = testing::RunProcam(
      "capture --camera " + linear_camera + " --projector 0 --sequence photometric --levels 255"
      " --channels w --frames 4 --settle-ms 1" + bracket + " --out " + (dir / "linear").string());
  ASSERT_EQ(reference.exit_code, 0) << reference.output;
  const CaptureSessionData corrected = CaptureSessionData::Load(dir / "corrected");
  const CaptureSessionData truth = CaptureSessionData::Load(dir / "linear");
  const int white = corrected.pattern_count() - 1;
  const cv::Mat a = corrected.Hdr(white), b = truth.Hdr(white);
  ASSERT_FALSE(a.empty());
  ASSERT_EQ(a.size(), b.size());
  // Pixels the room lights (well above the darkest bracket's floor): the ratio corrected/linear
  // is one constant (the response's normalisation), within a few percent.
  std::vector<double> ratios;
  for (int y = 0; y < a.rows; ++y) {
    for (int x = 0; x < a.cols; ++x) {
      const double reference_value = b.at<cv::Vec3f>(y, x)[1];
      if (reference_value > 20.0) ratios.push_back(a.at<cv::Vec3f>(y, x)[1] / reference_value);
    }
  }
  ASSERT_GT(ratios.size(), 1000u);
  std::sort(ratios.begin(), ratios.end());
  const double median = ratios[ratios.size() / 2];
  const double p05 = ratios[ratios.size() / 20], p95 = ratios[ratios.size() * 19 / 20];
  std::printf("linearised / linear HDR: median %.4f, 5%%..95%% %.4f..%.4f over %zu pixels\n",
              median, p05, p95, ratios.size());
  EXPECT_LT(p95 / p05, 1.05);

  // A session with one exposure cannot calibrate a response: one line naming it, nothing written.
  const testing::CommandRun single = testing::RunProcam(
      "capture --camera " + camera + " --projector 0 --sequence photometric --levels 255"
      " --channels w --settle-ms 1 --out " + (dir / "single").string());
  ASSERT_EQ(single.exit_code, 0) << single.output;
  const testing::CommandRun refused = testing::RunProcam(
      "calibrate response " + (dir / "single").string() + " --out " + (dir / "rig2").string());
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_NE(refused.output.find("bracket at least 3"), std::string::npos) << refused.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "rig2"));
}

}  // namespace
}  // namespace procam
