// `procam cameras` and `procam capture` run as a user would: exit codes, one-line errors, the
// session written, and an interrupted capture resumed by running the same command again.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "base/io.h"
#include "procam/config.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::CommandRun;

CommandRun Procam(const std::string& arguments) { return testing::RunProcam(arguments); }

int Lines(const std::string& text) {
  return static_cast<int>(std::count(text.begin(), text.end(), '\n'));
}

const std::string kTestCamera =
    "'test:loopback?width=64&height=48&fps=500&exposure_us=1000&reference_exposure_us=1000";

TEST(CaptureCli, HelpOnEverySubcommand) {
  for (const char* command : {"cameras --help", "capture --help"}) {
    const CommandRun run = Procam(command);
    EXPECT_EQ(run.exit_code, 0) << command;
    EXPECT_NE(run.output.find("Usage"), std::string::npos) << command << ": " << run.output;
  }
}

TEST(CaptureCli, CamerasListsBackendsAndVirtualCamerasWithoutBroadcasting) {
  const CommandRun run = Procam("cameras --no-gige --virtual");
  EXPECT_EQ(run.exit_code, 0) << run.output;
  EXPECT_NE(run.output.find("camera backends in this build:"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("test:loopback"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("synthetic:c_shaped"), std::string::npos) << run.output;
  if (PROCAM_WITH_ARAVIS) {
    EXPECT_NE(run.output.find("aravis:Fake_1"), std::string::npos) << run.output;
  }
}

TEST(CaptureCli, GrayCodeCaptureWritesASession) {
  testing::TempDir dir;
  const CommandRun run = Procam("capture --camera " + kTestCamera +
                                "' --sequence graycode --projector-size 128x96 "
                                "--frames 1 --settle-ms 1 --out " +
                                (dir / "gray").string());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_NE(run.output.find("30/30 patterns captured"), std::string::npos)
      << run.output;  // 2 + 2·(7 + 7)
  const nlohmann::json manifest = nlohmann::json::parse(ReadFile(dir / "gray" / "session.json"));
  EXPECT_TRUE(manifest["complete"].get<bool>());
  EXPECT_EQ(manifest["sequence"]["parameters"]["width"], 128);
  const nlohmann::json result = nlohmann::json::parse(ReadFile(dir / "gray" / "result.json"));
  EXPECT_EQ(result["patterns_captured"], 30);
  // The white pattern's frame reads full scale everywhere (16-bit PNG, 255 · 257).
  const cv::Mat white =
      cv::imread((dir / "gray" /
                  manifest["patterns"][0]["captured"]["exposures"][0]["file"].get<std::string>())
                     .string(),
                 cv::IMREAD_UNCHANGED);
  ASSERT_EQ(white.type(), CV_16UC1);
  double low = 0;
  cv::minMaxLoc(white, &low);
  EXPECT_EQ(low, 65535.0);
}

TEST(CaptureCli, SyntheticCameraCapturesTheSimulatedRoomThroughOneOfItsProjectors) {
  testing::TempDir dir;
  const CommandRun run = Procam(
      "capture --camera "
      "'synthetic:tiny_box?patches=20&fps=500&exposure_us=1000&reference_exposure_us=1000' "
      "--projector 1 --sequence photometric --levels 0,255 --channels w --frames 1 "
      "--settle-ms 1 --out " +
      (dir / "flat").string());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_EQ(run.output.find("warning"), std::string::npos) << run.output;
  const nlohmann::json manifest = nlohmann::json::parse(ReadFile(dir / "flat" / "session.json"));
  EXPECT_EQ(manifest["camera"]["device"], "synthetic:tiny_box");
  EXPECT_EQ(manifest["display"]["name"], "synthetic:tiny_box/right");
  EXPECT_EQ(manifest["display"]["width"], 320);  // the projector's own size
  // Full white on the right projector brightens the room it lights (BGR frames, 16-bit PNG).
  auto frame = [&](int pattern) {
    return cv::imread(
        (dir / "flat" /
         manifest["patterns"][pattern]["captured"]["exposures"][0]["file"].get<std::string>())
            .string(),
        cv::IMREAD_UNCHANGED);
  };
  const cv::Mat black = frame(0), white = frame(1);
  ASSERT_EQ(white.type(), CV_16UC3);
  EXPECT_GT(cv::mean(white)[1], 2 * cv::mean(black)[1] + 1000);
}

TEST(CaptureCli, AnInterruptedCaptureResumesWhenRunAgain) {
  testing::TempDir dir;
  const std::string common =
      " --sequence photometric --levels 0,128,255 --channels rgb --projector-size 32x24 "
      "--frames 2 --settle-ms 1 --retries 1 --retry-delay-ms 1 --out " +
      (dir / "flat").string();
  const CommandRun failed =
      Procam("capture --camera " + kTestCamera + "&fault=disconnect&fault_after=5'" + common);
  EXPECT_EQ(failed.exit_code, 1) << failed.output;
  EXPECT_EQ(Lines(failed.output), 1) << failed.output;
  EXPECT_NE(failed.output.find("procam: error: camera 'test:loopback': device disappeared"),
            std::string::npos)
      << failed.output;
  EXPECT_NE(failed.output.find("run the same command again to resume"), std::string::npos)
      << failed.output;

  const CommandRun resumed = Procam("capture --camera " + kTestCamera + "'" + common);
  EXPECT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("7/7 patterns captured"), std::string::npos) << resumed.output;
  EXPECT_EQ(resumed.output.find("0 already there"), std::string::npos) << resumed.output;
}

// A frame overwritten with junk (or cut short) is not trusted on resume: that pattern is
// captured again, so the finished session holds only frames that decode.
TEST(CaptureCli, ResumeRecapturesAFrameThatDoesNotDecode) {
  testing::TempDir dir;
  const std::string command = "capture --camera " + kTestCamera +
                              "' --sequence photometric --levels 0,255 --channels rgb "
                              "--projector-size 32x24 --frames 1 --settle-ms 1 --out " +
                              (dir / "flat").string();
  ASSERT_EQ(Procam(command).exit_code, 0);
  const nlohmann::json manifest = nlohmann::json::parse(ReadFile(dir / "flat" / "session.json"));
  const std::filesystem::path frame =
      dir / "flat" / manifest["patterns"][1]["captured"]["exposures"][0]["file"].get<std::string>();
  WriteFileAtomically(frame, "\x89PNG\r\n junk, not a picture");
  const CommandRun resumed = Procam(command);
  EXPECT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("(1 this run, 3 already there)"), std::string::npos)
      << resumed.output;
  EXPECT_EQ(cv::imread(frame.string(), cv::IMREAD_UNCHANGED).depth(), CV_16U);
}

TEST(CaptureCli, ASyntheticCameraThatTimesOutMidSessionKeepsItsFramesAndResumes) {
  testing::TempDir dir;
  const std::string camera =
      "'synthetic:tiny_box?patches=20&fps=500&exposure_us=1000&reference_exposure_us=1000";
  const std::string common = " --projector 1 --sequence photometric --levels 0,255 --channels rgb --frames 2 "
                             "--settle-ms 1 --retries 2 --retry-delay-ms 1 --timeout-ms 50 --out " +
                             (dir / "flat").string();
  const CommandRun failed = Procam("capture --camera " + camera + "&fault=timeout&fault_after=5'" + common);
  EXPECT_EQ(failed.exit_code, 1) << failed.output;
  EXPECT_EQ(Lines(failed.output), 1) << failed.output;
  EXPECT_NE(failed.output.find("synthetic:tiny_box"), std::string::npos) << failed.output;
  EXPECT_NE(failed.output.find("run the same command again to resume"), std::string::npos) << failed.output;
  int kept = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir / "flat" / "frames")) kept += entry.is_regular_file();
  EXPECT_GT(kept, 0);  // what was captured before the fault stays

  const CommandRun resumed = Procam("capture --camera " + camera + "'" + common);
  EXPECT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("patterns captured"), std::string::npos) << resumed.output;
  EXPECT_EQ(resumed.output.find(" 0 already there"), std::string::npos) << resumed.output;
}

TEST(CaptureCli, MistakesGetOneLineNamingTheCulprit) {
  testing::TempDir dir;
  struct Case {
    std::string arguments, expected;
  };
  ASSERT_TRUE(cv::imwrite((dir / "small.png").string(), cv::Mat(3, 4, CV_8UC3, cv::Scalar(0))));
  const std::string out = " --out " + (dir / "out").string();
  for (const Case& c :
       {Case{"capture --camera synthetic:room --sequence graycode" + out,
             "camera 'synthetic:room': unknown synthetic scene 'room' (scenes: "},
        Case{"capture --camera synthetic:room.json --sequence graycode" + out,
             "camera 'synthetic:room.json': room.json: file not found"},
        Case{"capture --camera synthetic:tiny_box?patches=20 --projector 2 --sequence graycode" +
                 out,
             "--projector 2: synthetic scene 'tiny_box' has 2 projectors (0..1: left, right)"},
        Case{"capture --camera 'test:x?nosie=1' --sequence graycode" + out,
             "unknown parameter 'nosie'"},
        Case{"capture --camera test:x --sequence verify --projector-size 8x6 " +
                 (dir / "small.png").string() + out,
             "small.png: image is 4x3, the projector is 8x6"},
        Case{"capture --camera test:x --sequence graycode --display glfw:1" + out,
             "display 'glfw:1': "},  // no X display in tests (GLFW windows: tests/projection)
        Case{"capture --camera test:x --sequence graycode --display projector9" + out,
             "display 'projector9': unknown"},
        Case{"capture --camera test:x --sequence graycode --projector-size 12by8" + out,
             "--projector-size: expected WIDTHxHEIGHT"}}) {
    const CommandRun run = Procam(c.arguments);
    EXPECT_EQ(run.exit_code, 1) << c.arguments << "\n" << run.output;
    EXPECT_EQ(Lines(run.output), 1) << run.output;
    EXPECT_NE(run.output.find(c.expected), std::string::npos) << c.arguments << "\n" << run.output;
  }
}

TEST(CaptureCli, CapturesFromTheAravisFakeCamera) {
  if (!PROCAM_WITH_ARAVIS) GTEST_SKIP() << "built without Aravis";
  testing::TempDir dir;
  const CommandRun run = Procam(
      "capture --camera aravis:Fake_1?format=Mono8 --sequence photometric --levels 0,255 "
      "--channels w --projector-size 16x8 --frames 1 --settle-ms 0 --exposure-us 20000 "
      "--out " +
      (dir / "fake").string());
  EXPECT_EQ(run.exit_code, 0) << run.output;
  EXPECT_NE(run.output.find("display 'memory' shows the patterns nowhere"), std::string::npos)
      << run.output;
  const nlohmann::json manifest = nlohmann::json::parse(ReadFile(dir / "fake" / "session.json"));
  EXPECT_EQ(manifest["camera"]["model"], "Fake");
  EXPECT_EQ(manifest["patterns"][1]["captured"]["exposures"][0]["exposure_us"], 20000.0);
}

}  // namespace
}  // namespace procam
