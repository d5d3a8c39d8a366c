// procam show on a display server with three monitors: sway's headless backend with Xwayland
// (scripts/multi_monitor.sh), outputs HEADLESS-1..3 of 320×240 side by side. What each output
// shows is captured by grim through the compositor, independently of procam, and compared with
// the image procam was asked to show there; the other outputs must show nothing (one colour).
// sway's Xwayland window manager fullscreens a new X11 window on the focused output whatever
// monitor it was meant for, which is what these tests catch.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <sstream>
#include <string>

#include "projection/projector_images.h"
#include "projection/test_pattern.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

constexpr int kWidth = 320, kHeight = 240, kOutputs = 3;

using testing::CommandRun;
using testing::RunShell;

bool Installed(const std::string& program) {
  return RunShell("command -v " + program + " >/dev/null").exit_code == 0;
}

// An 8-bit R, G, B image as grim writes it with -t ppm ("P6\nW H\n255\n", rows top down).
std::string Ppm(const cv::Mat& rgb) {
  std::string bytes =
      "P6\n" + std::to_string(rgb.cols) + " " + std::to_string(rgb.rows) + "\n255\n";
  for (int r = 0; r < rgb.rows; ++r)
    bytes.append(rgb.ptr<char>(r), static_cast<size_t>(rgb.cols) * 3);
  return bytes;
}

// Reads a PPM written by grim; an empty Mat when the file is missing or not one.
cv::Mat ReadPpm(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  std::string magic;
  int width = 0, height = 0, max_value = 0;
  if (!(file >> magic >> width >> height >> max_value) || magic != "P6" || max_value != 255)
    return {};
  file.get();  // the one whitespace after the header
  cv::Mat rgb(height, width, CV_8UC3);
  file.read(reinterpret_cast<char*>(rgb.data), static_cast<std::streamsize>(rgb.total() * 3));
  return file ? rgb : cv::Mat();
}

cv::Mat Rgb8(const ProjectorImage& image) {
  cv::Mat rgb;
  image.codes.convertTo(rgb, CV_8UC3);
  return rgb;
}

bool Uniform(const cv::Mat& rgb) {
  const cv::Vec3b first = rgb.at<cv::Vec3b>(0, 0);
  const cv::Mat same(rgb.size(), CV_8UC3, cv::Scalar(first[0], first[1], first[2]));
  return cv::norm(rgb, same, cv::NORM_INF) == 0.0;
}

// Run inside the server with procam's arguments: lists the monitors into list.txt, shows,
// waits until each output k with an expected<k>.ppm shows it (at most 20 s in all: a loaded
// machine, a sanitizer build), captures every output into output<k>.ppm, ends procam and
// writes its exit status (143 if it was still showing) and prints its output.
constexpr char kShowScript[] = R"sh(cd "$(dirname "$0")"
./procam show --list >list.txt 2>&1
./procam show "$@" --seconds 60 >show.log 2>&1 &
pid=$!
i=0
for k in 1 2 3; do
  [ -f expected$k.ppm ] || continue
  until grim -t ppm -o HEADLESS-$k output$k.ppm && cmp -s output$k.ppm expected$k.ppm; do
    i=$((i + 1)); [ $i -ge 200 ] && break
    kill -0 $pid 2>/dev/null || break
    sleep 0.1
  done
done
for k in 1 2 3; do grim -t ppm -o HEADLESS-$k output$k.ppm; done
kill $pid 2>/dev/null
wait $pid
echo $? >show.status
cat show.log
)sh";

// Shows the bars on monitor 0 through the window manager (sway puts that window where it
// belongs: monitor 0's output has the focus), then has sway take the window out of fullscreen
// while procam shows; prints procam's stderr and exits with its status.
constexpr char kUnfullscreenScript[] = R"sh(cd "$(dirname "$0")"
./procam show --pattern bars --monitor 0 --placement window-manager --seconds 30 \
  >show.log 2>error.log &
pid=$!
i=0
until grep -q XWAYLAND0 show.log 2>/dev/null; do
  i=$((i + 1)); [ $i -ge 200 ] && break
  kill -0 $pid 2>/dev/null || break
  sleep 0.1
done
swaymsg '[title="procam XWAYLAND0"] fullscreen disable' >/dev/null
wait $pid
status=$?
cat error.log
exit $status
)sh";

class MultiMonitor : public ::testing::Test {
 protected:
  void SetUp() override {
    for (const char* program : {"sway", "Xwayland", "grim"}) {
      if (!Installed(program)) {
        GTEST_SKIP() << program << " is not installed (apt-get install sway xwayland grim)";
      }
    }
    // sway runs as an unprivileged user when the tests run as root: everything it and procam
    // use lives in a directory that user can write, the procam binary copied in (the build
    // tree may be where that user cannot go; procam needs no file beside it).
    std::filesystem::permissions(dir_.path(), std::filesystem::perms::all);
    const char* binary = std::getenv("PROCAM_BINARY");
    ASSERT_NE(binary, nullptr) << "PROCAM_BINARY is not set (run the test through CTest)";
    std::filesystem::copy_file(binary, dir_ / "procam");
  }

  // Runs `procam show ARGUMENTS` (kShowScript) on the three monitors. `expected` maps outputs
  // (1..3) to the image each should show. Returns the run (its output: procam's).
  CommandRun Show(const std::string& arguments, const std::map<int, cv::Mat>& expected) {
    for (const auto& [output, rgb] : expected)
      dir_.Write("expected" + std::to_string(output) + ".ppm", Ppm(rgb));
    dir_.Write("show.sh", kShowScript);
    return OnThreeMonitors("sh " + (dir_ / "show.sh").string() + " " + arguments);
  }

  CommandRun OnThreeMonitors(const std::string& command) {
    return RunShell((testing::SourceDir() / "scripts" / "multi_monitor.sh").string() + " --mode " +
                    std::to_string(kWidth) + "x" + std::to_string(kHeight) + " --timeout 60 " +
                    std::to_string(kOutputs) + " -- " + command);
  }

  // Expects each output in `expected` to show exactly its image and the others to show nothing;
  // procam to have kept showing until it was ended (SIGTERM: 143).
  void ExpectShown(const CommandRun& run, const std::map<int, cv::Mat>& expected) {
    std::ifstream status_file(dir_ / "show.status");
    int status = -1;
    status_file >> status;
    EXPECT_EQ(status, 128 + 15) << "procam show ended early:\n" << run.output;
    for (int k = 1; k <= kOutputs; ++k) {
      const cv::Mat captured = ReadPpm(dir_ / ("output" + std::to_string(k) + ".ppm"));
      ASSERT_EQ(captured.size(), cv::Size(kWidth, kHeight)) << "HEADLESS-" << k << "\n"
                                                            << run.output;
      if (const auto it = expected.find(k); it != expected.end()) {
        EXPECT_EQ(cv::norm(captured, it->second, cv::NORM_INF), 0.0)
            << "HEADLESS-" << k << " does not show its image\n"
            << run.output;
      } else {
        EXPECT_TRUE(Uniform(captured)) << "HEADLESS-" << k << " shows something\n" << run.output;
      }
    }
  }

  // Output (1..3) at monitor `which`'s position, as `procam show --list` reported it in the
  // last Show: the script puts HEADLESS-k at x = (k - 1) · width.
  int OutputOf(const std::string& which) {
    std::ifstream lines(dir_ / "list.txt");
    for (std::string line; std::getline(lines, line);) {
      std::istringstream fields(line);
      std::string index, name;
      fields >> index >> name;
      const size_t at = line.find(" at (");
      if ((index == which || name == which) && at != std::string::npos)
        return std::stoi(line.substr(at + 5)) / kWidth + 1;
    }
    ADD_FAILURE() << "monitor " << which << " not listed";
    return 0;
  }

  testing::TempDir dir_;
};

TEST_F(MultiMonitor, ListsOneMonitorPerOutputSideBySide) {
  const CommandRun list = OnThreeMonitors((dir_ / "procam").string() + " show --list");
  ASSERT_EQ(list.exit_code, 0) << list.output;
  for (int k = 0; k < kOutputs; ++k) {
    EXPECT_NE(list.output.find("XWAYLAND" + std::to_string(k) + " "), std::string::npos)
        << list.output;
    EXPECT_NE(list.output.find("320x240 @ "), std::string::npos) << list.output;
    EXPECT_NE(list.output.find(" at (" + std::to_string(k * kWidth) + ", 0)"), std::string::npos)
        << list.output;
  }
}

TEST_F(MultiMonitor, ShowsThePatternOnTheMonitorGivenByIndex) {
  const cv::Mat bars = Rgb8(MakeTestPattern(TestPattern::kBars, cv::Size(kWidth, kHeight)));
  const CommandRun run = Show("--pattern bars --monitor 1", {{2, bars}});
  EXPECT_EQ(OutputOf("1"), 2);
  ExpectShown(run, {{2, bars}});
  EXPECT_NE(run.output.find("monitor 1 'XWAYLAND1' 320x240 at (320, 0): bars"), std::string::npos)
      << run.output;
}

TEST_F(MultiMonitor, ShowsThePatternOnTheMonitorGivenByName) {
  const cv::Mat grid = Rgb8(MakeTestPattern(TestPattern::kGrid, cv::Size(kWidth, kHeight)));
  const CommandRun run = Show("--pattern grid --monitor XWAYLAND2", {{3, grid}});
  EXPECT_EQ(OutputOf("XWAYLAND2"), 3);
  ExpectShown(run, {{3, grid}});
}

// One image per monitor, each different, in another order than the monitors': every output
// shows its own image exactly, pixel for pixel.
TEST_F(MultiMonitor, ShowsEachImageOnItsMonitor) {
  std::map<int, cv::Mat> expected;
  std::string images, monitors;
  for (const int monitor : {2, 0, 1}) {
    ProjectorImage image;
    image.codes = cv::Mat(kHeight, kWidth, CV_16UC3);
    cv::RNG(monitor + 1)
        .fill(image.codes, cv::RNG::UNIFORM, cv::Scalar::all(0), cv::Scalar::all(256));
    const std::string file = "image" + std::to_string(monitor) + ".png";
    WriteProjectorImage(dir_ / file, image);
    images += file + " ";
    monitors += " --monitor " + std::to_string(monitor);
    expected[monitor + 1] = Rgb8(image);
  }
  ExpectShown(Show(images + monitors, expected), expected);
}

// GLFW's own fullscreen asks sway for fullscreen; sway puts the window on the focused output
// (HEADLESS-1), and procam notices: one line naming the monitor and where the window is.
TEST_F(MultiMonitor, WindowManagerPlacementOnAnotherMonitorIsAnErrorNamingIt) {
  const CommandRun run = OnThreeMonitors(
      "sh -c '" + (dir_ / "procam").string() +
      " show --pattern bars --monitor XWAYLAND1 --placement window-manager --seconds 0.1 2>&1 "
      ">/dev/null'");
  testing::ExpectOneErrorLine(run,
                              "monitor 1 'XWAYLAND1' (320x240 at (320, 0)): its window is 320x240 "
                              "at (0, 0) instead: the window manager put it elsewhere",
                              "window-manager placement on sway");
}

// A window taken off its monitor later, while procam shows (the window manager moves it, resizes
// it or ends its fullscreen): procam notices within a poll and stops with one line naming the
// monitor, both rectangles in it.
TEST_F(MultiMonitor, WindowTakenOffItsMonitorLaterIsAnErrorNamingIt) {
  dir_.Write("unfullscreen.sh", kUnfullscreenScript);
  const CommandRun run = OnThreeMonitors("sh " + (dir_ / "unfullscreen.sh").string());
  testing::ExpectOneErrorLine(run,
                              "glfw:XWAYLAND0: the window left its monitor (320x240 at (0, 0)): "
                              "it is ",
                              "window taken out of fullscreen by sway");
}

}  // namespace
}  // namespace procam
