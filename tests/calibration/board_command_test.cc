// `procam calibrate board` end to end: structured-light sessions captured by the sequencer
// (RunCaptureSession) from a test camera that sees the synthetic board rig
// (datasets_synthetic/board_structured_light.h, a smaller rig than board_projector_test's so the
// sessions are quick to write), then the command as a user runs it: the models, result.json's
// section, the report; mrcal's own tools on the projector's model (skipped without
// python3-mrcal); and the one-line refusals.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>

#include "base/camera_model.h"
#include "base/io.h"
#include "base/timing.h"
#include "calibration/camera_calibration.h"
#include "calibration/structured_light.h"
#include "capture/session.h"
#include "capture/test_camera.h"
#include "datasets_synthetic/board_structured_light.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

// A 640×400 camera and a 512×384 projector, 0.15 m apart, the board (9×6, 3 cm) 1 m away.
BoardRig SmallRig() {
  BoardRig rig;
  rig.camera = ProjectorGeometry("LENSMODEL_OPENCV4", {620.0, 618.0, 321.0, 198.5, -0.05, 0.02,
                                                       0.0, 0.0},
                                 640, 400, Eigen::Isometry3d::Identity());
  rig.projector = ProjectorGeometry("LENSMODEL_OPENCV4", {760.0, 762.0, 257.0, 352.0, 0.0, 0.0,
                                                          0.0, 0.0},
                                    512, 384, Eigen::Isometry3d::Identity());
  Eigen::Isometry3d cam_from_projector = Eigen::Isometry3d::Identity();
  cam_from_projector.linear() = (Eigen::AngleAxisd(-10.0 * M_PI / 180.0, Vec3::UnitY()) *
                                 Eigen::AngleAxisd(-12.0 * M_PI / 180.0, Vec3::UnitX()))
                                    .toRotationMatrix();
  cam_from_projector.translation() = Vec3(0.15, 0.02, 0.0);
  rig.projector_from_camera = cam_from_projector.inverse();
  return rig;
}

ChessboardSpec Board() {
  ChessboardSpec board;
  board.corners_x = 9;
  board.corners_y = 6;
  board.square_size = 0.03;
  return board;
}

// The display the sequencer shows patterns on: it remembers which pattern of the sequence it
// shows, so the camera's view returns that pattern's rendering.
class IndexDisplay : public PatternDisplay {
 public:
  explicit IndexDisplay(const CaptureSequence& sequence) : sequence_(sequence) {}
  cv::Size Resolution() const override { return sequence_.patterns.front().image.size(); }
  std::string Name() const override { return "memory:board"; }
  void Show(const cv::Mat& pattern) override {
    for (size_t k = 0; k < sequence_.patterns.size(); ++k) {
      if (cv::norm(pattern, sequence_.patterns[k].image, cv::NORM_INF) == 0.0) {
        index_ = static_cast<int>(k);
        return;
      }
    }
    FAIL() << "a pattern not in the sequence";
  }
  int index() const { return index_; }

 private:
  const CaptureSequence& sequence_;
  int index_ = 0;
};

// One session per pose in `dir`/pose_K.
std::vector<std::string> CaptureSessions(const testing::TempDir& dir,
                                         const std::vector<Eigen::Isometry3d>& poses) {
  const BoardRig rig = SmallRig();
  StructuredLightOptions light;
  light.width = rig.projector.width();
  light.height = rig.projector.height();
  const CaptureSequence sequence = MakeStructuredLightSequence(light);
  std::vector<std::string> sessions;
  for (size_t k = 0; k < poses.size(); ++k) {
    BoardRenderOptions render;
    render.supersample = 2;
    render.seed = 11 + static_cast<uint32_t>(k);
    const std::vector<cv::Mat> images =
        RenderBoardUnderPatterns(rig, Board(), poses[k], sequence, render);
    IndexDisplay display(sequence);
    TestCameraOptions camera_options;
    camera_options.width = rig.camera.width();
    camera_options.height = rig.camera.height();
    camera_options.pixel_format = PixelFormat::kMono16;
    camera_options.frame_rate = 2000.0;
    camera_options.exposure_us = 100.0;
    camera_options.reference_exposure_us = 100.0;
    TestCamera camera(camera_options, [&](int64_t) { return images[display.index()].clone(); });
    CaptureSessionOptions options;
    options.directory = dir.path() / ("pose_" + std::to_string(k));
    options.sequencer.settle_ms = 0.0;
    options.sequencer.frames_per_pattern = 1;
    RunCaptureSession(options, sequence, camera, display);
    sessions.push_back(options.directory.string());
  }
  return sessions;
}

std::string Join(const std::vector<std::string>& sessions, size_t count) {
  std::string joined;
  for (size_t k = 0; k < count && k < sessions.size(); ++k) joined += " " + sessions[k];
  return joined;
}

TEST(CalibrateBoardCommand, WritesModelsResultAndReport) {
  const testing::TempDir dir;
  const BoardRig rig = SmallRig();
  const std::vector<std::string> sessions =
      CaptureSessions(dir, BoardRigPoses(rig, Board(), 5, 1.0));
  const std::filesystem::path out = dir.path() / "rig";
  const auto start = Clock::now();
  const testing::CommandRun run = testing::RunProcam(
      "calibrate board" + Join(sessions, 5) + " --corners 9x6 --square 0.03 --window 8 "
      "--min-window-pixels 30 --name left --out " + out.string());
  // Measured, not asserted (docs/chessboard.md reports it).
  std::printf("procam calibrate board, 5 sessions: %.2f s wall\n", SecondsSince(start));
  ASSERT_EQ(run.exit_code, 0) << run.output;
  std::printf("%s", run.output.c_str());

  const CameraModel projector = ReadCameraModelFile(out / "left.cameramodel");
  EXPECT_EQ(projector.width, 512);
  // Against the truth (a small rig of few pixels: looser than board_projector_test's bounds).
  EXPECT_LT(std::abs(projector.intrinsics[0] / 760.0 - 1.0), 0.01);
  EXPECT_LT((projector.cam_from_ref.translation() - rig.projector_from_camera.translation()).norm(),
            0.005);
  const CameraModel camera = ReadCameraModelFile(out / "camera.cameramodel");
  EXPECT_LT(std::abs(camera.intrinsics[0] / 620.0 - 1.0), 0.01);

  const nlohmann::json result = nlohmann::json::parse(ReadFile(out / "result.json"));
  const nlohmann::json& section = result.at("board").at("left");
  for (const char* key : {"lens_model", "camera", "projector", "rt_projector_camera", "board",
                          "residuals", "poses", "skipped_sessions", "camera_uncertainty",
                          "projector_uncertainty"}) {
    EXPECT_TRUE(section.contains(key)) << key;
  }
  // A board that leaves the camera's view is skipped, not fatal.
  EXPECT_EQ(section["poses"].size() + section["skipped_sessions"].size(), 5u);
  ASSERT_GE(section["poses"].size(), 4u);
  EXPECT_EQ(section["poses"][0]["projector_residuals_px"].size(), 54u);
  EXPECT_LT(section["residuals"]["projector_rms_px_per_coordinate"].get<double>(), 0.5);
  EXPECT_TRUE(std::filesystem::exists(out / "board_report_left.html"));

  // mrcal's own projection uncertainty of the projector's model, from its optimization inputs.
  if (testing::RunShell("/usr/bin/python3 -c 'import mrcal'").exit_code != 0) {
    GTEST_SKIP() << "python3-mrcal is not installed: mrcal's reading of the model not checked";
  }
  const testing::CommandRun mrcal = testing::RunShell(
      "/usr/bin/python3 " +
      (testing::SourceDir() / "tests/calibration/projection_uncertainty_mrcal.py").string() + " " +
      (out / "left.cameramodel").string() + " 1.0 255.5,191.5");
  ASSERT_EQ(mrcal.exit_code, 0) << mrcal.output;
  const nlohmann::json numbers = nlohmann::json::parse(mrcal.output.substr(mrcal.output.find('{')));
  EXPECT_LT(numbers["resolve_moved_intrinsics"].get<double>(), 1e-4);
  const double procam_centre = section["projector_uncertainty"]["centre_px"].get<double>();
  EXPECT_NEAR(numbers["at_infinity"][0].get<double>(), procam_centre, 0.05 * procam_centre);
}

TEST(CalibrateBoardCommand, OnePoseAndParallelPosesAreOneLine) {
  const testing::TempDir dir;
  const BoardRig rig = SmallRig();
  std::vector<Eigen::Isometry3d> poses = BoardRigPoses(rig, Board(), 1, 1.0);
  Eigen::Isometry3d moved = poses[0];
  moved.translation() += Vec3(0.02, 0.01, 0.05);
  poses.push_back(moved);
  const std::vector<std::string> sessions = CaptureSessions(dir, poses);
  const std::filesystem::path out = dir.path() / "rig";
  testing::ExpectOneErrorLine(
      testing::RunProcamStderr("calibrate board" + Join(sessions, 1) + " --window 8 --out " +
                               out.string()),
      "1 board pose, need at least 3", "one pose");
  testing::ExpectOneErrorLine(
      testing::RunProcamStderr("calibrate board" + Join(sessions, 2) +
                               " --window 8 --min-poses 2 --out " + out.string()),
      "all parallel", "parallel poses");
  EXPECT_FALSE(std::filesystem::exists(out / "projector.cameramodel"));
}

// A pose where OpenCV finds no chessboard in the white photo (the board moved 3 m aside, out of the
// camera's view) is reported in one line naming its session and left out; the calibration goes on
// with the others, and is refused in one line when too few are left.
TEST(CalibrateBoardCommand, APoseWithoutABoardIsReportedAndLeftOut) {
  const testing::TempDir dir;
  const BoardRig rig = SmallRig();
  std::vector<Eigen::Isometry3d> poses = BoardRigPoses(rig, Board(), 5, 1.0);
  Eigen::Isometry3d aside = poses[0];
  aside.translation() += Vec3(3.0, 0.0, 0.0);
  poses.insert(poses.begin(), aside);
  const std::vector<std::string> sessions = CaptureSessions(dir, poses);
  const std::string missing = sessions[0] + ": chessboard not found in the white photo";
  const std::filesystem::path out = dir.path() / "rig";
  const testing::CommandRun run = testing::RunProcam(
      "calibrate board" + Join(sessions, sessions.size()) +
      " --corners 9x6 --square 0.03 --window 8 --min-window-pixels 30 --name left --out " +
      out.string());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  size_t lines = 0;
  for (size_t at = run.output.find(missing); at != std::string::npos;
       at = run.output.find(missing, at + 1))
    ++lines;
  EXPECT_EQ(lines, 1u) << run.output;
  const nlohmann::json result = nlohmann::json::parse(ReadFile(out / "result.json"));
  const nlohmann::json& skipped = result.at("board").at("left").at("skipped_sessions");
  EXPECT_NE(std::find(skipped.begin(), skipped.end(), "pose_0"), skipped.end()) << skipped.dump();

  // The pose without a board and two others: fewer than the three poses needed.
  const std::filesystem::path refused = dir.path() / "refused";
  const testing::CommandRun few = testing::RunProcamStderr(
      "calibrate board" + Join(sessions, 3) +
      " --corners 9x6 --square 0.03 --window 8 --min-window-pixels 30 --out " + refused.string());
  testing::ExpectOneErrorLine(few, "need at least 3", "too few poses left");
  EXPECT_FALSE(std::filesystem::exists(refused / "projector.cameramodel"));
}

}  // namespace
}  // namespace procam
