// The room as a device, end to end, with no hardware and nothing in-process: a display server
// with one monitor per projector (sway's headless backend, scripts/multi_monitor.sh), `procam
// emulate` playing a scene file's room (watching the monitors through grim, serving its camera
// as a GigE Vision camera on 127.0.0.1), and `procam capture` showing Gray codes fullscreen on
// the projector's monitor and photographing them through Aravis. The in-process synthetic rig
// of the same scene file (`synthetic:ROOM.json`) is the truth: the same patterns must give the
// same photos. Everything runs in a private network namespace (unshare -n), so no packet can
// leave the machine.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "base/image_io.h"
#include "base/json_fields.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::CommandRun;
using testing::RunShell;

// Inside the server, as its user: the emulator (latency $1 ms) and a capture into $2 on the
// first projector's monitor, the settle time measured; capture's exit status into $2.status.
constexpr char kRunScript[] = R"sh(cd "$(dirname "$0")"
./procam emulate room/tiny_box.json --monitors HEADLESS-1,HEADLESS-2 --patches 60 --latency-ms "$1" \
  >"$2.emulate.log" 2>&1 &
emulator=$!
i=0
until grep -q "camera scale" "$2.emulate.log" 2>/dev/null; do
  i=$((i + 1)); [ $i -ge 300 ] && break
  kill -0 $emulator 2>/dev/null || break
  sleep 0.1
done
./procam capture --camera aravis:gv:127.0.0.1 --display glfw:XWAYLAND0 --sequence graycode \
  --settle-ms auto --frames 2 --out "$2" >"$2.capture.log" 2>&1
echo $? >"$2.status"
kill $emulator 2>/dev/null
wait $emulator
cat "$2.emulate.log" "$2.capture.log"
)sh";

// Inside the server: the emulator (latency 50 ms) and the whole demo on the rig it plays —
// calibrate all with the scene's camera model, compensate, project, verify — into demo/.
constexpr char kDemoScript[] = R"sh(cd "$(dirname "$0")"
./procam emulate room/tiny_box.json --monitors HEADLESS-1,HEADLESS-2 --patches 60 --latency-ms 50 \
  >demo.emulate.log 2>&1 &
emulator=$!
i=0
until grep -q "camera scale" demo.emulate.log 2>/dev/null; do
  i=$((i + 1)); [ $i -ge 300 ] && break
  kill -0 $emulator 2>/dev/null || break
  sleep 0.1
done
./procam demo --camera aravis:gv:127.0.0.1 --display glfw:XWAYLAND0,glfw:XWAYLAND1 --names left,right \
  --scene room/tiny_box.json --camera-model room/tiny_box_camera.cameramodel \
  --camera-scale "$(sed -n 's/.*camera scale \([0-9.e+-]*\).*/\1/p' demo.emulate.log)" \
  --camera-guess 0.5,-1.4,0.8,0.5,1.5,0.25 --patches 100 --out demo >demo.log 2>&1
echo $? >demo.status
kill $emulator 2>/dev/null
wait $emulator
cat demo.emulate.log demo.log
)sh";

class EmulatedRoom : public ::testing::Test {
 protected:
  void SetUp() override {
    for (const char* program : {"sway", "Xwayland", "grim"}) {
      if (RunShell(std::string("command -v ") + program + " >/dev/null").exit_code != 0)
        GTEST_SKIP() << program << " is not installed (apt-get install sway xwayland grim)";
    }
    if (RunShell("unshare -n true").exit_code != 0)
      GTEST_SKIP() << "cannot make a private network namespace (unshare -n needs root)";
    // sway runs as an unprivileged user when the tests run as root: it and procam work in a
    // directory that user can write, with the procam binary copied in.
    std::filesystem::permissions(dir_.path(), std::filesystem::perms::all);
    const char* binary = std::getenv("PROCAM_BINARY");
    ASSERT_NE(binary, nullptr) << "PROCAM_BINARY is not set (run the test through CTest)";
    std::filesystem::copy_file(binary, dir_ / "procam");
    ASSERT_EQ(RunShell("cd " + dir_.path().string() + " && ./procam scene write tiny_box --out room --patches 100")
                  .exit_code,
              0);
    nlohmann::json room = ReadJsonFile(dir_ / "room/tiny_box.json");
    room["cameras"][0].merge_patch({{"fps", 60}, {"exposure_us", 2000}, {"reference_exposure_us", 2000}});
    dir_.Write("room/tiny_box.json", room.dump(2));
    RunShell("chmod -R a+rwX " + dir_.path().string());
    dir_.Write("run.sh", kRunScript);
    dir_.Write("demo.sh", kDemoScript);
  }

  // Runs `script ARGUMENTS` on two 320x200 monitors in a private network namespace.
  CommandRun InTheRoom(const std::string& script, const std::string& arguments) {
    const std::string inner = (testing::SourceDir() / "scripts/multi_monitor.sh").string() +
                              " --mode 320x200 --timeout 240 2 -- sh " + (dir_ / script).string() + " " + arguments;
    return RunShell("unshare -n sh -c 'ip link set lo up && " + inner + "'");
  }
  // The emulated capture with the emulator's latency `latency_ms`, into DIR/`name`.
  CommandRun CaptureThroughTheRoom(double latency_ms, const std::string& name) {
    return InTheRoom("run.sh", std::to_string(latency_ms) + " " + name);
  }

  testing::TempDir dir_;
};

// The camera scale `procam emulate` printed into its log.
std::string ScaleFromLog(const std::filesystem::path& log) {
  std::ifstream file(log);
  for (std::string line; std::getline(file, line);) {
    const size_t at = line.find("camera scale ");
    if (at != std::string::npos) return line.substr(at + 13, line.find(' ', at + 13) - at - 13);
  }
  return "0";
}

// Frames of two sessions of the same sequence, file by file: the largest mean absolute
// difference of a frame, in 8-bit digital numbers.
double LargestMeanDifference(const std::filesystem::path& a, const std::filesystem::path& b, int* frames) {
  double largest = 0.0;
  *frames = 0;
  for (const auto& entry : std::filesystem::directory_iterator(a / "frames")) {
    const cv::Mat x = ReadImage(entry.path(), -1), y = ReadImage(b / "frames" / entry.path().filename(), -1);
    EXPECT_EQ(x.size(), y.size()) << entry.path();
    EXPECT_EQ(x.type(), y.type()) << entry.path();
    if (x.size() != y.size() || x.type() != y.type()) continue;
    cv::Mat difference;
    cv::absdiff(x, y, difference);
    const double scale = x.depth() == CV_16U ? 257.0 : 1.0;
    largest = std::max(largest, cv::mean(difference.reshape(1))[0] / scale);
    ++*frames;
  }
  return largest;
}

TEST_F(EmulatedRoom, CaptureThroughTheRoomPhotographsWhatTheInProcessRigDoes) {
  const CommandRun reference = RunShell("cd " + dir_.path().string() +
                                        " && ./procam capture --camera 'synthetic:room/tiny_box.json?patches=60' "
                                        "--projector 0 --sequence graycode --frames 2 --out truth");
  ASSERT_EQ(reference.exit_code, 0) << reference.output;
  for (const double latency_ms : {50.0, 200.0}) {
    const std::string name = "through_" + std::to_string(static_cast<int>(latency_ms));
    const CommandRun run = CaptureThroughTheRoom(latency_ms, name);
    std::ifstream status_file(dir_ / (name + ".status"));
    int status = -1;
    status_file >> status;
    ASSERT_EQ(status, 0) << "capture through the emulated room failed:\n" << run.output;

    int frames = 0;
    const double difference = LargestMeanDifference(dir_ / "truth", dir_ / name, &frames);
    std::printf("latency %.0f ms: %d frames, largest mean |difference| %.3f DN\n", latency_ms, frames, difference);
    EXPECT_EQ(frames, 36) << run.output;
    // Both render the same room from the same patterns; the emulated camera's RGB8 and the
    // synthetic BGR8 quantise alike. A frame taken before its pattern reached the room would
    // differ by tens of DN (a Gray-code stripe flipping half the lit view).
    EXPECT_LT(difference, 0.5) << run.output;

    // The settle time came from the latency procam measured through the monitor, grim and the
    // GigE camera: the emulator's, plus the compositor's and the watcher's delay (each up to a
    // frame of theirs), minus the time procam's Show() spends after the picture is out.
    const nlohmann::json result = ReadJsonFile(dir_ / name / "result.json");
    const double measured = result["latency"]["estimate_ms"].get<double>();
    std::printf("  measured %.1f ms, settle %.0f ms\n", measured, result["settle_ms"].get<double>());
    EXPECT_GT(measured, latency_ms - 15.0) << run.output;
    EXPECT_LT(measured, latency_ms + 35.0) << run.output;
    EXPECT_GE(result["settle_ms"].get<double>(), latency_ms);
  }
}

// The whole pipeline on the emulated room reaches what it reaches on the in-process rig of the
// same scene file: the same projector calibration, registration and verified appearance (the
// camera has no noise, so to rounding).
TEST_F(EmulatedRoom, DemoThroughTheRoomReachesWhatTheInProcessRigDoes) {
  const CommandRun run = InTheRoom("demo.sh", "");
  std::ifstream status_file(dir_ / "demo.status");
  int status = -1;
  status_file >> status;
  ASSERT_EQ(status, 0) << "the demo through the emulated room failed:\n" << run.output;
  const CommandRun reference = RunShell(
      "cd " + dir_.path().string() +
      " && ./procam demo --camera 'synthetic:room/tiny_box.json?patches=60' --scene room/tiny_box.json "
      "--camera-model room/tiny_box_camera.cameramodel --camera-scale " +
      ScaleFromLog(dir_ / "demo.emulate.log") + " --camera-guess 0.5,-1.4,0.8,0.5,1.5,0.25 --patches 100 --out truth_demo");
  ASSERT_EQ(reference.exit_code, 0) << reference.output;

  const nlohmann::json emulated = ReadJsonFile(dir_ / "demo/verify/result.json");
  const nlohmann::json truth = ReadJsonFile(dir_ / "truth_demo/verify/result.json");
  const auto best = [](const nlohmann::json& result) { return result["iterations"][result["best"].get<int>()]; };
  for (const char* key : {"pixel_mean76", "pixel_mean2000", "patch_mean2000"}) {
    const double a = best(emulated)["measured_vs_desired"][key].get<double>();
    const double b = best(truth)["measured_vs_desired"][key].get<double>();
    std::printf("verified %s: emulated room %.4f, in-process %.4f\n", key, a, b);
    EXPECT_NEAR(a, b, 0.01 * b) << key;
  }
  // rig/result.json: the projectors' calibration residuals and the registration's.
  const nlohmann::json rig_a = ReadJsonFile(dir_ / "demo/rig/result.json")["projectors"]["registration"];
  const nlohmann::json rig_b = ReadJsonFile(dir_ / "truth_demo/rig/result.json")["projectors"]["registration"];
  std::vector<double> a, b;
  for (const auto& projector : rig_a["projectors"]) a.push_back(projector["rms_px_per_coordinate"].get<double>());
  for (const auto& projector : rig_b["projectors"]) b.push_back(projector["rms_px_per_coordinate"].get<double>());
  a.push_back(rig_a["residual"]["inliers"]["rms_mm"].get<double>());
  b.push_back(rig_b["residual"]["inliers"]["rms_mm"].get<double>());
  std::printf("projector RMS %.4f %.4f px, registration %.3f mm (in-process %.4f %.4f px, %.3f mm)\n", a[0], a[1], a[2],
              b[0], b[1], b[2]);
  ASSERT_EQ(a.size(), 3u);
  ASSERT_EQ(b.size(), 3u);
  for (size_t k = 0; k < a.size(); ++k) EXPECT_NEAR(a[k], b[k], 0.01 * b[k]) << k;
}

}  // namespace
}  // namespace procam
