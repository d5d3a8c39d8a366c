// MeasureDisplayLatency against the test camera, whose frames see the display as it was
// `latency_ms` before their exposure start (test_camera.h): the configured latency is the truth.
#include "capture/latency.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <memory>

#include "capture/sequencer.h"
#include "capture/test_camera.h"

namespace procam {
namespace {

struct Rig {
  std::shared_ptr<MemoryDisplay> display = std::make_shared<MemoryDisplay>(cv::Size(64, 48));
  std::unique_ptr<TestCamera> camera;
  Rig(double latency_ms, double fps, PixelFormat format = PixelFormat::kMono8, double noise = 0.0) {
    TestCameraOptions options;
    options.width = 160;
    options.height = 120;
    options.frame_rate = fps;
    options.exposure_us = 2000;
    options.reference_exposure_us = 2000;
    options.display_latency_ms = latency_ms;
    options.pixel_format = format;
    options.noise_sigma = noise;
    LoopbackOptions view;
    view.ambient = 0.05;
    camera = std::make_unique<TestCamera>(options, MakeLoopbackView(display, view));
    camera->Start();
  }
};

TEST(DisplayLatency, BracketsTheConfiguredLatencyWithinAFramePeriod) {
  struct Case {
    double latency_ms, fps;
    PixelFormat format;
    double noise;
  };
  for (const Case& c : {Case{50, 100, PixelFormat::kMono8, 0.0}, Case{200, 100, PixelFormat::kBGR8, 2.0},
                        Case{0, 60, PixelFormat::kMono8, 0.0}}) {
    Rig rig(c.latency_ms, c.fps, c.format, c.noise);
    LatencyOptions options;
    options.max_latency_ms = 500;
    const LatencyMeasurement measured = MeasureDisplayLatency(rig.camera.get(), rig.display.get(), options);
    std::printf("configured %.0f ms at %.0f fps: %s\n", c.latency_ms, c.fps, measured.Summary().c_str());
    const double period = 1000.0 / c.fps;
    // (lower, upper]: the test camera's frame sees the display at exposure start − latency, and
    // the change is timed when Show() returned, microseconds after the display took it.
    EXPECT_LT(measured.lower_ms, c.latency_ms) << c.latency_ms;
    EXPECT_GE(measured.upper_ms, c.latency_ms - 0.5) << c.latency_ms;
    // Each change's interval holds the latency and spans at most a frame period, so their
    // union spans at most two and each middle is within half a period of the latency.
    EXPECT_LE(measured.upper_ms - measured.lower_ms, 2 * period + 0.5) << c.latency_ms;
    EXPECT_NEAR(measured.EstimateMs(), c.latency_ms, 0.5 * period + 0.5) << c.latency_ms;
    EXPECT_NEAR(measured.frame_period_ms, period, 0.5);
    EXPECT_NEAR(measured.exposure_ms, 2.0, 1e-9);
    EXPECT_GE(measured.SettleMs(), c.latency_ms + 5.0);
    // upper ≤ latency + a period, plus the margin: the spread (≤ two periods), 10 % or 5 ms.
    EXPECT_GE(measured.SettleMs(), measured.upper_ms + (measured.upper_ms - measured.lower_ms));
    EXPECT_LE(measured.SettleMs(), c.latency_ms + period +
                                       std::max({5.0, 0.1 * (c.latency_ms + period), 2 * period + 0.5}) + 1.0);
    EXPECT_EQ(measured.edges, 8);
    EXPECT_GT(measured.lit_fraction, 0.99);
  }
}

// The measured settle time is what the sequencer needs: with it every capture of a run of
// different patterns sees its own pattern; with a guessed settle shorter than the latency the
// captures see the pattern before.
TEST(DisplayLatency, MeasuredSettleMakesEveryCaptureSeeItsOwnPattern) {
  Rig rig(120, 100);
  LatencyOptions options;
  options.max_latency_ms = 400;
  const LatencyMeasurement measured = MeasureDisplayLatency(rig.camera.get(), rig.display.get(), options);
  const auto captures_own = [&](double settle_ms) {
    SequencerOptions sequencer;
    sequencer.settle_ms = settle_ms;
    sequencer.frames_per_pattern = 1;
    PatternSequencer capture(sequencer, rig.camera.get(), rig.display.get());
    int own = 0;
    for (int k = 0; k < 6; ++k) {  // grey levels 40, 80, ... : each differs from the one before
      const double level = 40.0 * (k + 1);
      const cv::Mat mean = capture.Capture(cv::Mat(rig.display->Resolution(), CV_8UC1, cv::Scalar(level)))
                               .exposures[0].mean;
      // Loopback: DN = (ambient + level/255) · 255 at the reference exposure, clipped.
      own += std::abs(cv::mean(mean)[0] - std::min(255.0, 0.05 * 255 + level)) < 2.0;
    }
    return own;
  };
  EXPECT_EQ(captures_own(measured.SettleMs()), 6) << measured.Summary();
  EXPECT_EQ(captures_own(20.0), 0) << "a 20 ms settle against a 120 ms latency";
}

TEST(DisplayLatency, RefusesADisplayTheCameraDoesNotSee) {
  auto display = std::make_shared<MemoryDisplay>(cv::Size(64, 48), "projector-far");
  TestCameraOptions options;
  options.frame_rate = 200;
  TestCamera camera(options, SceneView());  // the fixed chart: no display in view
  camera.Start();
  LatencyOptions latency;
  latency.max_latency_ms = 50;
  try {
    MeasureDisplayLatency(&camera, display.get(), latency);
    ADD_FAILURE() << "measured a display the camera does not see";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("display 'projector-far' lights nothing camera 'test:loopback' sees"),
              std::string::npos)
        << error.what();
  }
  latency.edges = 0;
  EXPECT_THROW(MeasureDisplayLatency(&camera, display.get(), latency), std::invalid_argument);
}

// A latency beyond max_latency_ms fails with one line naming the camera, the display and the
// limit, in bounded time.
TEST(DisplayLatency, LatencyBeyondTheLimitFailsInBoundedTime) {
  Rig rig(400, 100);
  LatencyOptions options;
  options.max_latency_ms = 100;
  options.grab_timeout_ms = 100;
  try {
    MeasureDisplayLatency(rig.camera.get(), rig.display.get(), options);
    ADD_FAILURE() << "a 400 ms latency was measured with a 100 ms limit";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("display 'memory' lights nothing camera 'test:loopback' sees within 100 ms"),
              std::string::npos)
        << error.what();
  }
}

}  // namespace
}  // namespace procam
