// procam calibrate photometric, end to end without hardware: `procam capture --sequence
// photometric` with the synthetic camera photographing the tiny box lit by projector 0, then
// the calibration command on that session, compared with the simulated projector
// (ProjectorFromPlacement: gamma 2.2 on every channel, identity mixing).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::CommandRun;
using testing::RunProcam;

int Lines(const std::string& text) {
  return static_cast<int>(std::count(text.begin(), text.end(), '\n'));
}

nlohmann::json ReadJson(const std::filesystem::path& path) {
  std::ifstream file(path);
  return nlohmann::json::parse(file);
}

// A camera black offset with read noise, averaged over 4 frames: the noise dithers the 8-bit
// quantisation and the offset keeps it from being clipped at 0 (the black field removes it).
const std::string kSyntheticCamera =
    "'synthetic:tiny_box?patches=20&fps=500&exposure_us=1000&reference_exposure_us=1000"
    "&black=8&noise=1'";

TEST(CalibratePhotometricCommand, RecoversTheSyntheticProjectorsGammaAndMixing) {
  testing::TempDir dir;
  const CommandRun capture = RunProcam(
      "capture --camera " + kSyntheticCamera +
      " --projector 0 --sequence photometric --levels 0,32,64,96,128,160,192,224,255"
      " --channels rgb --frames 4 --settle-ms 1 --out " + (dir / "flat").string());
  ASSERT_EQ(capture.exit_code, 0) << capture.output;
  const CommandRun run = RunProcam("calibrate photometric " + (dir / "flat").string() +
                                   " --out " + (dir / "rig").string());
  std::printf("%s", run.output.c_str());
  ASSERT_EQ(run.exit_code, 0) << run.output;

  const nlohmann::json model = ReadJson(dir / "rig/photometric.json");
  for (int c = 0; c < 3; ++c) {
    const double gamma = model["gamma"][c].get<double>();
    std::printf("channel %c: gamma %.4f (true 2.2, error %.3f%%), rms %.2g\n", "RGB"[c], gamma,
                100.0 * std::abs(gamma / 2.2 - 1.0), model["gamma_rms"][c].get<double>());
    EXPECT_LT(std::abs(gamma / 2.2 - 1.0), 0.02) << "channel " << c;
    EXPECT_LT(model["gamma_rms"][c].get<double>(), 0.01);
    double row = 0.0;
    for (int k = 0; k < 3; ++k) {
      const double m = model["mixing"][c][k].get<double>();
      row += m;
      if (k != c) {
        EXPECT_LT(std::abs(m), 0.02) << "mixing " << c << "," << k;
      }
    }
    EXPECT_NEAR(row, 1.0, 1e-9);
    EXPECT_GT(model["max"][c].get<double>(), model["black"][c].get<double>());
    const nlohmann::json& lut = model["lut"][c];
    ASSERT_EQ(lut.size(), 33u);
    EXPECT_EQ(lut.front().get<double>(), 0.0);
    EXPECT_EQ(lut.back().get<double>(), 1.0);
    EXPECT_NEAR(lut[16].get<double>(), std::pow(0.5, 2.2), 0.01);  // drive 1/2
  }
  EXPECT_NE(model["note"].get<std::string>().find("camera units"), std::string::npos);

  // Its section of the rig's result.json ("projector" when --projector does not name it).
  const nlohmann::json result = ReadJson(dir / "rig/result.json")["photometric"]["projector"];
  EXPECT_EQ(result["fields"].size(), 25u);  // black + 3 channels × 8 levels
  EXPECT_GT(result["pixels_used"].get<int>(), 10000);
  EXPECT_NE(result["note"].get<std::string>().find("relative to this camera"), std::string::npos);
  EXPECT_EQ(result["channels_fit"][0]["samples_drive_light"].size(), 9u);
}

// Bad input: one line naming the file, exit code 1, nothing written.
TEST(CalibratePhotometricCommand, BadSessionsGetOneLineNamingTheFile) {
  testing::TempDir dir;
  const std::string test_camera =
      "'test:loopback?width=64&height=48&fps=500&exposure_us=1000&reference_exposure_us=1000"
      "&format=BGR8'";
  const std::string common = " --projector-size 32x24 --frames 1 --settle-ms 1 --out ";
  ASSERT_EQ(RunProcam("capture --camera " + test_camera + " --sequence graycode" + common +
                      (dir / "gray").string())
                .exit_code,
            0);
  ASSERT_EQ(RunProcam("capture --camera " + test_camera +
                      " --sequence photometric --levels 0,128 --channels rgb" + common +
                      (dir / "no255").string())
                .exit_code,
            0);
  ASSERT_EQ(RunProcam("capture --camera " + test_camera +
                      " --sequence photometric --levels 0,128,255 --channels w" + common +
                      (dir / "white").string())
                .exit_code,
            0);
  std::filesystem::create_directories(dir / "empty");
  struct Case {
    std::string session, expected;
  };
  const Case cases[] = {
      {"nowhere", "nowhere: not a directory"},
      {"empty", "empty/session.json"},
      {"gray", "gray/session.json: a 'graycode' session"},
      {"no255", "no255/session.json: levels [0,128] lack 255"},
      {"white", "white/session.json: channels 'w' lack 'r'"},
  };
  for (const Case& c : cases) {
    const CommandRun run = RunProcam("calibrate photometric " + (dir / c.session).string() +
                                     " --out " + (dir / "rig").string());
    EXPECT_EQ(run.exit_code, 1) << c.session << ": " << run.output;
    EXPECT_EQ(Lines(run.output), 1) << run.output;
    EXPECT_NE(run.output.find("procam: error: "), std::string::npos) << run.output;
    EXPECT_NE(run.output.find(c.expected), std::string::npos) << run.output;
    EXPECT_FALSE(std::filesystem::exists(dir / "rig")) << c.session;
  }
}

// Option values that make no sense, and --projector without a rig.json to merge into (it used
// to create one), are refused before anything is fitted or written.
TEST(CalibratePhotometricCommand, RefusesBadOptionsBeforeWriting) {
  testing::TempDir dir;
  const std::string test_camera =
      "'test:loopback?width=64&height=48&fps=500&exposure_us=1000&reference_exposure_us=1000"
      "&format=BGR8'";
  ASSERT_EQ(RunProcam("capture --camera " + test_camera +
                      " --sequence photometric --levels 0,128,255 --channels rgb "
                      "--projector-size 32x24 --frames 1 --settle-ms 1 --out " +
                      (dir / "flat").string())
                .exit_code,
            0);
  const std::string calibrate =
      "calibrate photometric " + (dir / "flat").string() + " --out " + (dir / "rig").string();
  const std::pair<std::string, std::string> cases[] = {
      {" --camera-black nan", "--camera-black"},
      {" --camera-black -1", "--camera-black"},
      {" --projector left", (dir / "rig" / "rig.json").string() + ": not found"},
  };
  for (const auto& [options, expected] : cases) {
    const CommandRun run = RunProcam(calibrate + options);
    EXPECT_EQ(run.exit_code, 1) << options << ": " << run.output;
    EXPECT_EQ(Lines(run.output), 1) << run.output;
    EXPECT_NE(run.output.find("procam: error: "), std::string::npos) << run.output;
    EXPECT_NE(run.output.find(expected), std::string::npos) << run.output;
    EXPECT_FALSE(std::filesystem::exists(dir / "rig")) << options;
  }
}

}  // namespace
}  // namespace procam
