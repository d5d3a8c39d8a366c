// The pattern sequencer against the test camera, whose radiance model gives the truth: averages
// converge as σ/√N, stale frames never reach an average, brackets merge to the true radiance,
// and camera faults are retried and then reported.
#include "capture/sequencer.h"

#include <gtest/gtest.h>

#include <cmath>

#include "capture/display.h"
#include "capture/test_camera.h"

namespace procam {
namespace {

TestCameraOptions SmallCamera() {
  TestCameraOptions options;
  options.width = 32;
  options.height = 24;
  options.frame_rate = 400;
  options.exposure_us = 1000;
  options.reference_exposure_us = 1000;
  return options;
}

SequencerOptions FastSequencer() {
  SequencerOptions options;
  options.settle_ms = 5;
  options.frames_per_pattern = 4;
  options.grab_timeout_ms = 200;
  options.retry_delay_ms = 1;
  return options;
}

cv::Mat Uniform(cv::Size size, int value) { return cv::Mat(size, CV_8UC3, cv::Scalar::all(value)); }

TEST(MergeExposures, RecoversRadianceFromLinearBrackets) {
  // Radiance r (full scale per second) seen for t gives z = min(1, r t); black 0.
  const std::vector<double> exposures_us = {1000, 4000, 16000};
  const std::vector<float> radiance = {2.0f, 30.0f, 200.0f, 900.0f};  // up to 0.9 at 1 ms
  std::vector<cv::Mat> means;
  for (double exposure : exposures_us) {
    cv::Mat mean(1, static_cast<int>(radiance.size()), CV_32FC1);
    for (size_t i = 0; i < radiance.size(); ++i) {
      mean.at<float>(0, static_cast<int>(i)) =
          static_cast<float>(std::min(1.0, radiance[i] * exposure * 1e-6) * 255.0);
    }
    means.push_back(mean);
  }
  const cv::Mat merged = MergeExposures(means, exposures_us, 255.0);
  for (size_t i = 0; i < radiance.size(); ++i) {
    EXPECT_NEAR(merged.at<float>(0, static_cast<int>(i)), radiance[i], radiance[i] * 1e-4) << i;
  }
  // Saturated in every exposure: the shortest exposure's (clipped) value.
  std::vector<cv::Mat> saturated = {cv::Mat(1, 1, CV_32FC1, cv::Scalar(255)),
                                    cv::Mat(1, 1, CV_32FC1, cv::Scalar(255))};
  EXPECT_NEAR(MergeExposures(saturated, {1000, 2000}, 255.0).at<float>(0, 0), 1000.0, 1e-3);
  EXPECT_THROW(MergeExposures(saturated, {1000}, 255.0), std::invalid_argument);
}

TEST(Sequencer, AveragingReducesNoiseBySqrtN) {
  TestCameraOptions camera_options = SmallCamera();
  camera_options.width = 128;
  camera_options.height = 96;
  camera_options.pixel_format = PixelFormat::kMono16;
  camera_options.noise_sigma = 400;
  auto display = std::make_shared<MemoryDisplay>(cv::Size(16, 12));
  TestCamera camera(camera_options, MakeLoopbackView(display));
  SequencerOptions options = FastSequencer();
  options.frames_per_pattern = 16;
  PatternSequencer sequencer(options, &camera, display.get());
  const PatternCapture capture =
      sequencer.Capture(Uniform(display->Resolution(), 153));  // radiance 0.6
  ASSERT_EQ(capture.exposures.size(), 1u);
  const ExposureCapture& exposure = capture.exposures[0];
  EXPECT_EQ(exposure.frames, 16);
  EXPECT_EQ(exposure.sequences.size(), 16u);
  EXPECT_TRUE(capture.hdr.empty());
  EXPECT_DOUBLE_EQ(capture.full_scale, 65535.0);
  cv::Scalar mean, deviation;
  cv::meanStdDev(exposure.mean, mean, deviation);
  EXPECT_NEAR(mean[0], 0.6 * 65535, 20.0);
  EXPECT_NEAR(deviation[0], 400.0 / 4.0, 400.0 / 4.0 * 0.1);  // σ/√16
}

// The camera sees the display 25 ms late and keeps buffered frames: without settling and
// dropping, the first frames would show the previous pattern.
TEST(Sequencer, FramesExposedBeforeThePatternSettledAreNeverAveraged) {
  TestCameraOptions camera_options = SmallCamera();
  camera_options.display_latency_ms = 25;
  camera_options.buffers = 4;
  auto display = std::make_shared<MemoryDisplay>(cv::Size(16, 12));
  TestCamera camera(camera_options, MakeLoopbackView(display));
  SequencerOptions options = FastSequencer();
  options.settle_ms = 30;  // ≥ the latency
  options.frames_per_pattern = 3;
  PatternSequencer sequencer(options, &camera, display.get());
  for (int value : {0, 250, 10, 180}) {
    const PatternCapture capture = sequencer.Capture(Uniform(display->Resolution(), value));
    double low = 0, high = 0;
    cv::minMaxLoc(capture.exposures[0].mean, &low, &high);
    EXPECT_EQ(low, value);
    EXPECT_EQ(high, value);
    EXPECT_GE(capture.exposures[0].first_exposure_start_ns, capture.settled_ns);
  }

  // The same camera without settling shows why: its frames still see the previous pattern (180).
  options.settle_ms = 0;
  PatternSequencer hasty(options, &camera, display.get());
  const PatternCapture capture = hasty.Capture(Uniform(display->Resolution(), 90));
  double low = 0, high = 0;
  cv::minMaxLoc(capture.exposures[0].mean, &low, &high);
  EXPECT_EQ(low, 180);
  EXPECT_EQ(high, 180);
}

// A display that reaches the camera later than the settle time (a compositor's hiccup): the
// first frames after settling still show the previous pattern, the last ones the new one. The
// sequencer sees its first and last frames disagree and takes the frames again: the average is
// the new pattern alone, one retry is counted with its reason. When every frame is late (no
// disagreement to see) nothing can tell; that is the settle time's job.
TEST(Sequencer, APictureStillChangingDuringItsFramesIsTakenAgain) {
  TestCameraOptions camera_options = SmallCamera();
  camera_options.display_latency_ms = 200;
  camera_options.buffers = 4;
  auto display = std::make_shared<MemoryDisplay>(cv::Size(16, 12));
  TestCamera camera(camera_options, MakeLoopbackView(display));
  SequencerOptions options = FastSequencer();
  options.settle_ms = 20;            // 180 ms short of the latency (wide, for loaded machines)
  options.frames_per_pattern = 100;  // 250 ms at 400 fps: spans the change
  PatternSequencer sequencer(options, &camera, display.get());
  sequencer.Capture(Uniform(display->Resolution(), 20));
  const PatternCapture capture = sequencer.Capture(Uniform(display->Resolution(), 200));
  double low = 0, high = 0;
  cv::minMaxLoc(capture.exposures[0].mean, &low, &high);
  EXPECT_EQ(low, 200);
  EXPECT_EQ(high, 200);
  ASSERT_EQ(capture.retries, 1);
  EXPECT_NE(capture.retry_reasons[0].find("still changing"), std::string::npos)
      << capture.retry_reasons[0];

  // Off (max_changed_fraction 1): the same capture averages both pictures.
  options.max_changed_fraction = 1.0;
  PatternSequencer blind(options, &camera, display.get());
  blind.Capture(Uniform(display->Resolution(), 20));
  const PatternCapture mixed = blind.Capture(Uniform(display->Resolution(), 200));
  cv::minMaxLoc(mixed.exposures[0].mean, &low, &high);
  EXPECT_GT(low, 20);
  EXPECT_LT(high, 200);
  EXPECT_EQ(mixed.retries, 0);
}

TEST(Sequencer, BracketingMergesToTheTrueRadiance) {
  TestCameraOptions camera_options = SmallCamera();
  camera_options.width = 64;
  camera_options.height = 4;
  camera_options.reference_exposure_us = 4000;  // radiance 1 fills full scale at 4 ms
  camera_options.frame_rate = 1000;
  camera_options.noise_sigma = 0.3;
  // A ramp of radiance from 0.02 to 8 (times what fills full scale at the reference exposure).
  const auto ramp = [](int64_t) {
    cv::Mat radiance(1, 64, CV_32FC1);
    for (int x = 0; x < 64; ++x)
      radiance.at<float>(0, x) = static_cast<float>(0.02 * std::pow(400.0, x / 63.0));
    return radiance;
  };
  MemoryDisplay display(cv::Size(8, 8));
  TestCamera camera(camera_options, ramp);
  SequencerOptions options = FastSequencer();
  options.exposures_us = {250, 1000, 4000};
  options.frames_per_pattern = 8;
  PatternSequencer sequencer(options, &camera, &display);
  const PatternCapture capture = sequencer.Capture(Uniform(display.Resolution(), 255));
  ASSERT_EQ(capture.exposures.size(), 3u);
  for (size_t i = 0; i < 3; ++i)
    EXPECT_DOUBLE_EQ(capture.exposures[i].exposure_us, options.exposures_us[i]);
  ASSERT_FALSE(capture.hdr.empty());
  // Truth, in full scale per second: r / t_ref.
  const cv::Mat truth = ramp(0) / 4000e-6;
  for (int x = 0; x < 64; ++x) {
    const float expected = truth.at<float>(0, x);
    EXPECT_NEAR(capture.hdr.at<float>(2, x), expected, expected * 0.02 + 0.5) << "x=" << x;
  }
  // The longest exposure alone clips the upper half of the ramp; the merge does not.
  double longest_max = 0;
  cv::minMaxLoc(capture.exposures[2].mean, nullptr, &longest_max);
  EXPECT_EQ(longest_max, 255.0);
}

TEST(Sequencer, TransientTimeoutsAreRetried) {
  auto display = std::make_shared<MemoryDisplay>(cv::Size(16, 12));
  TestCameraOptions camera_options = SmallCamera();
  camera_options.fault = TestCameraOptions::Fault::kTimeout;
  camera_options.fault_after_frames = 2;
  camera_options.fault_grabs = 2;
  TestCamera camera(camera_options, MakeLoopbackView(display));
  SequencerOptions options = FastSequencer();
  options.grab_timeout_ms = 20;
  options.max_retries = 2;
  PatternSequencer sequencer(options, &camera, display.get());
  const PatternCapture capture = sequencer.Capture(Uniform(display->Resolution(), 100));
  EXPECT_EQ(capture.retries, 2);
  ASSERT_EQ(capture.retry_reasons.size(), 2u);
  EXPECT_NE(capture.retry_reasons[0].find("no frame within"), std::string::npos);
  EXPECT_EQ(capture.exposures[0].frames, 4);
  double low = 0, high = 0;
  cv::minMaxLoc(capture.exposures[0].mean, &low, &high);
  EXPECT_EQ(low, 100);
  EXPECT_EQ(high, 100);
}

TEST(Sequencer, PersistentFaultsEndInACaptureFaultNamingTheCamera) {
  auto display = std::make_shared<MemoryDisplay>(cv::Size(16, 12));
  TestCameraOptions camera_options = SmallCamera();
  camera_options.name = "dying";
  camera_options.fault = TestCameraOptions::Fault::kDisconnect;
  camera_options.fault_after_frames = 6;
  TestCamera camera(camera_options, MakeLoopbackView(display));
  SequencerOptions options = FastSequencer();
  options.max_retries = 3;
  PatternSequencer sequencer(options, &camera, display.get());
  EXPECT_NO_THROW(sequencer.Capture(Uniform(display->Resolution(), 50)));
  try {
    sequencer.Capture(Uniform(display->Resolution(), 60));
    FAIL() << "no fault";
  } catch (const CaptureFault& fault) {
    const std::string message = fault.what();
    EXPECT_NE(message.find("camera 'test:dying': device disappeared"), std::string::npos)
        << message;
    EXPECT_NE(message.find("gave up after 3 retries"), std::string::npos) << message;
  }
}

TEST(Sequencer, OptionsAreChecked) {
  SequencerOptions options;
  std::string why;
  EXPECT_TRUE(options.Check(&why)) << why;
  options.frames_per_pattern = 0;
  EXPECT_FALSE(options.Check(&why));
  EXPECT_NE(why.find("frames_per_pattern"), std::string::npos);
  options = SequencerOptions();
  options.exposures_us = {1000, -5};
  EXPECT_FALSE(options.Check(&why));
  options = SequencerOptions();
  options.hdr.min_signal = 0.99;
  EXPECT_FALSE(options.Check(&why));
  MemoryDisplay display(cv::Size(4, 4));
  EXPECT_THROW(PatternSequencer(options, nullptr, &display), std::invalid_argument);
}

}  // namespace
}  // namespace procam
