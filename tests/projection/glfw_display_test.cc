// The GLFW output backend for real, under a virtual X server (Xvfb, started here on a free
// display number): monitors are listed, a fullscreen window shows images and test patterns pixel
// for pixel (read back from its framebuffer), sizes are checked, and `procam show` does the same
// from the command line.
#include "projection/glfw_display.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <stdexcept>
#include <thread>

#include "base/io.h"
#include "projection/test_pattern.h"
#include "tests/projection/xvfb.h"
#include "tests/testing/testing.h"

extern char** environ;

namespace procam {
namespace {

constexpr int kWidth = 640, kHeight = 480;

::testing::Environment* const xvfb =
    ::testing::AddGlobalTestEnvironment(new testing::XvfbEnvironment(kWidth, kHeight));

ProjectorImage RandomImage(int bits, unsigned seed) {
  ProjectorImage image;
  image.bits = bits;
  image.codes = cv::Mat(kHeight, kWidth, CV_16UC3);
  cv::RNG random(seed);
  random.fill(image.codes, cv::RNG::UNIFORM, cv::Scalar::all(0), cv::Scalar::all(1 << bits));
  return image;
}

TEST(GlfwDisplay, ListsAndFindsMonitors) {
  SKIP_WITHOUT_XVFB();
  const std::vector<MonitorInfo> monitors = ListMonitors();
  ASSERT_EQ(monitors.size(), 1u);
  EXPECT_EQ(monitors[0].width, kWidth);
  EXPECT_EQ(monitors[0].height, kHeight);
  EXPECT_EQ(FindMonitor("0").name, monitors[0].name);
  EXPECT_EQ(FindMonitor(monitors[0].name).index, 0);
  try {
    FindMonitor("HDMI-9");
    FAIL() << "no error";
  } catch (const IoError& error) {
    EXPECT_EQ(std::string(error.what()),
              "monitor 'HDMI-9' not found (monitors: 0 '" + monitors[0].name + "' 640x480)");
  }
}

TEST(GlfwDisplay, ShowsImagesPixelForPixel) {
  SKIP_WITHOUT_XVFB();
  GlfwDisplay display(FindMonitor("0"));
  EXPECT_EQ(display.Resolution(), cv::Size(kWidth, kHeight));
  // 8-bit codes come back exactly (R, G, B, row 0 at the top).
  const ProjectorImage image = RandomImage(8, 1);
  display.Show(image);
  cv::Mat expected;
  image.codes.convertTo(expected, CV_8UC3);
  EXPECT_EQ(cv::norm(display.ReadBack(), expected, cv::NORM_INF), 0.0);
  // 10-bit codes on an 8-bit output: the nearest level.
  const ProjectorImage deep = RandomImage(10, 2);
  display.Show(deep);
  deep.codes.convertTo(expected, CV_8UC3, 255.0 / 1023.0);
  EXPECT_LE(cv::norm(display.ReadBack(), expected, cv::NORM_INF), 1.0);
  // OpenCV images (B, G, R), as the capture module's sequencer shows patterns.
  cv::Mat bgr(kHeight, kWidth, CV_8UC3);
  cv::RNG(3).fill(bgr, cv::RNG::UNIFORM, cv::Scalar::all(0), cv::Scalar::all(256));
  display.Show(bgr);
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  EXPECT_EQ(cv::norm(display.ReadBack(), rgb, cv::NORM_INF), 0.0);
}

TEST(GlfwDisplay, ShowsTestPatterns) {
  SKIP_WITHOUT_XVFB();
  GlfwDisplay display(FindMonitor("0"));
  for (const TestPattern pattern :
       {TestPattern::kGrid, TestPattern::kBars, TestPattern::kWhite, TestPattern::kBlack}) {
    const ProjectorImage image = MakeTestPattern(pattern, display.Resolution());
    display.Show(image);
    cv::Mat expected;
    image.codes.convertTo(expected, CV_8UC3);
    EXPECT_EQ(cv::norm(display.ReadBack(), expected, cv::NORM_INF), 0.0)
        << TestPatternName(pattern);
  }
}

// Placed by procam as an override-redirect window rather than through the window manager (here
// there is none, so GLFW's own fullscreen places it too): the same pixels on the same monitor.
TEST(GlfwDisplay, PlacesTheWindowByHand) {
  SKIP_WITHOUT_XVFB();
  GlfwDisplayOptions options;
  options.placement = WindowPlacement::kByHand;
  GlfwDisplay display(FindMonitor("0"), options);
  EXPECT_EQ(display.Resolution(), cv::Size(kWidth, kHeight));
  const ProjectorImage image = RandomImage(8, 5);
  display.Show(image);
  cv::Mat expected;
  image.codes.convertTo(expected, CV_8UC3);
  EXPECT_EQ(cv::norm(display.ReadBack(), expected, cv::NORM_INF), 0.0);
}

TEST(GlfwDisplay, PlacementOptions) {
  WindowPlacement placement = WindowPlacement::kAuto;
  EXPECT_TRUE(ParseWindowPlacement("by-hand", &placement));
  EXPECT_EQ(placement, WindowPlacement::kByHand);
  EXPECT_TRUE(ParseWindowPlacement("window-manager", &placement));
  EXPECT_EQ(placement, WindowPlacement::kWindowManager);
  EXPECT_TRUE(ParseWindowPlacement("auto", &placement));
  EXPECT_EQ(placement, WindowPlacement::kAuto);
  EXPECT_FALSE(ParseWindowPlacement("sideways", &placement));
  GlfwDisplayOptions options;
  EXPECT_EQ(options.Check(), "");
  options.placement_seconds = 0.0;
  EXPECT_NE(options.Check(), "");
  MonitorInfo monitor;
  EXPECT_THROW(GlfwDisplay(monitor, options), std::invalid_argument);
}

TEST(GlfwDisplay, ImageOfTheWrongSizeIsAnError) {
  SKIP_WITHOUT_XVFB();
  GlfwDisplay display(FindMonitor("0"));
  ProjectorImage image;
  image.codes = cv::Mat(240, 320, CV_16UC3, cv::Scalar::all(0));
  try {
    display.Show(image);
    FAIL() << "no error";
  } catch (const IoError& error) {
    EXPECT_EQ(std::string(error.what()),
              display.Name() + ": image is 320x240, the monitor runs at 640x480");
  }
}

// A projector lost mid-run (its window closed by hand or by the window manager): the next Show
// is one error naming the monitor, which the capture and verify commands report and stop on.
TEST(GlfwDisplay, ClosedWindowIsAnErrorNamingTheMonitor) {
  SKIP_WITHOUT_XVFB();
  GlfwDisplay display(FindMonitor("0"));
  const cv::Mat black(display.Resolution(), CV_8UC3, cv::Scalar::all(0));
  display.Show(black);
  display.RequestClose();
  try {
    display.Show(black);
    FAIL() << "no error";
  } catch (const IoError& error) {
    EXPECT_EQ(std::string(error.what()), display.Name() + ": the projector's window was closed");
  }
}

TEST(TestPatterns, MarkTheCornersAndTheGrid) {
  const ProjectorImage grid = MakeTestPattern(TestPattern::kGrid, cv::Size(200, 100));
  EXPECT_EQ(grid.codes.at<cv::Vec3w>(0, 0), cv::Vec3w(255, 0, 0));
  EXPECT_EQ(grid.codes.at<cv::Vec3w>(0, 199), cv::Vec3w(0, 255, 0));
  EXPECT_EQ(grid.codes.at<cv::Vec3w>(99, 199), cv::Vec3w(0, 0, 255));
  EXPECT_EQ(grid.codes.at<cv::Vec3w>(99, 0), cv::Vec3w(255, 255, 0));
  EXPECT_EQ(grid.codes.at<cv::Vec3w>(30, 64), cv::Vec3w(255, 255, 255));
  EXPECT_EQ(grid.codes.at<cv::Vec3w>(30, 63), cv::Vec3w(0, 0, 0));
  const ProjectorImage bars = MakeTestPattern(TestPattern::kBars, cv::Size(80, 10));
  EXPECT_EQ(bars.codes.at<cv::Vec3w>(5, 5), cv::Vec3w(255, 255, 255));
  EXPECT_EQ(bars.codes.at<cv::Vec3w>(5, 55), cv::Vec3w(255, 0, 0));
  EXPECT_EQ(bars.codes.at<cv::Vec3w>(5, 75), cv::Vec3w(0, 0, 0));
}

using testing::CommandRun;

CommandRun Procam(const std::string& arguments) { return testing::RunProcam(arguments); }

TEST(ShowCommand, ShowsAnImageAndReadsItBack) {
  SKIP_WITHOUT_XVFB();
  testing::TempDir dir;
  const ProjectorImage image = RandomImage(8, 4);
  WriteProjectorImage(dir / "p.png", image);
  const CommandRun list = Procam("show --list");
  ASSERT_EQ(list.exit_code, 0) << list.output;
  EXPECT_NE(list.output.find("640x480"), std::string::npos) << list.output;
  const CommandRun run = Procam("show " + (dir / "p.png").string() + " --seconds 0.1 --readback " +
                                (dir / "rb").string());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const cv::Mat shown =
      cv::imread((dir / "rb" / "monitor0.png").string(), cv::IMREAD_COLOR);  // B, G, R
  cv::Mat expected;
  image.codes.convertTo(expected, CV_8UC3);
  cv::cvtColor(expected, expected, cv::COLOR_RGB2BGR);
  EXPECT_EQ(cv::norm(shown, expected, cv::NORM_INF), 0.0);
  // Test pattern mode.
  const CommandRun pattern =
      Procam("show --pattern grid --seconds 0.1 --readback " + (dir / "grid").string());
  ASSERT_EQ(pattern.exit_code, 0) << pattern.output;
  // An image of another size than the monitor: one clear error, before any window opens.
  ProjectorImage small;
  small.codes = cv::Mat(100, 100, CV_16UC3, cv::Scalar::all(0));
  WriteProjectorImage(dir / "small.png", small);
  const CommandRun wrong = Procam("show " + (dir / "small.png").string() + " --seconds 0.1");
  EXPECT_EQ(wrong.exit_code, 1);
  EXPECT_NE(wrong.output.find("small.png: image is 100x100, but monitor 0"), std::string::npos)
      << wrong.output;
  const CommandRun missing = Procam("show --monitor HDMI-9 --pattern white --seconds 0.1");
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.output.find("monitor 'HDMI-9' not found"), std::string::npos) << missing.output;
}

}  // namespace
}  // namespace procam
