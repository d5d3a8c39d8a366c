// A chessboard as a scene-file key, end to end: a scene file holds the rig of DefaultBoardRig()
// (a 1280×800 camera, a 1024×768 projector 0.2 m to its right, both with OpenCV4 distortion), a
// wall behind, and a "chessboard" with seven of the eight poses of BoardRigPoses() about 1 m away;
// `procam capture` records one structured-light session per pose through the synthetic camera
// (`synthetic:board.json?board_pose=K`: the board alone, lit by the projector, through the camera
// entry's ambient light, defocus and read noise); `procam calibrate board` calibrates on them.
// The result is held to the truth the scene file states, within the bounds of
// docs/chessboard.md. And the key's errors name the file and the key.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>

#include "base/camera_model.h"
#include "base/io.h"
#include "base/timing.h"
#include "datasets_synthetic/board_structured_light.h"
#include "datasets_synthetic/scene_files.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

ChessboardSpec Board() {
  ChessboardSpec board;
  board.corners_x = 11;
  board.corners_y = 8;
  board.square_size = 0.025;
  return board;
}

double AngleDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a * b.transpose()).angle() * 180.0 / std::numbers::pi;
}

// The scene file's chessboard key for `poses` (cam_from_board): each pose as rotation_deg =
// the X-Y-Z angles of its rotation and translation_m = the board's centre.
SceneChessboard ChessboardKey(const ChessboardSpec& board,
                              const std::vector<Eigen::Isometry3d>& poses) {
  SceneChessboard key;
  key.board = board;
  const Vec3 centre((board.corners_x - 1) * board.square_size / 2.0,
                    (board.corners_y - 1) * board.square_size / 2.0, 0.0);
  for (const Eigen::Isometry3d& pose : poses) {
    SceneChessboard::Pose entry;
    entry.rotation_deg = pose.linear().eulerAngles(0, 1, 2) * 180.0 / std::numbers::pi;
    entry.translation_m = pose * centre;
    key.poses.push_back(entry);
  }
  return key;
}

// Writes DIR/board.json: the camera at the room's origin, the projector where DefaultBoardRig()
// puts it, a wall 3 m ahead (the projector must light some surface of the room), the chessboard
// key given, the camera entry with `camera_keys` added.
std::filesystem::path WriteScene(const std::filesystem::path& dir, const BoardRig& rig,
                                 const nlohmann::json& chessboard,
                                 const nlohmann::json& camera_keys) {
  std::filesystem::create_directories(dir);
  CameraModel camera = rig.camera.Model();
  camera.cam_from_ref = Eigen::Isometry3d::Identity();
  WriteCameraModelFile(dir / "camera.cameramodel", camera, "the board rig's camera (test)");
  CameraModel projector = rig.projector.Model();
  projector.cam_from_ref = rig.projector_from_camera;  // the room's frame is the camera's
  WriteCameraModelFile(dir / "projector.cameramodel", projector, "the board rig's projector");
  nlohmann::json camera_entry = {{"name", "camera"}, {"model", "camera.cameramodel"}};
  camera_entry.update(camera_keys);
  const nlohmann::json scene = {
      {"name", "board"},
      {"patches", 20},
      {"surfaces",
       {{{"name", "wall"},
         {"quad", {{-3, 2, 3}, {3, 2, 3}, {3, -2, 3}, {-3, -2, 3}}},
         {"reflectance", 0.5},
         {"desired", {0.5, 0.5, 0.5}}}}},
      {"projectors",
       {{{"name", "front"}, {"model", "projector.cameramodel"}, {"max", 1.0}, {"gamma", 2.2}}}},
      {"cameras", {camera_entry}},
      {"chessboard", chessboard}};
  const std::filesystem::path file = dir / "board.json";
  std::ofstream(file) << scene.dump(2);
  return file;
}

// What the camera entry adds to the photographs: the optics of board_projector_test (ambient
// light 2% of the board's brightest white, defocus σ 0.8 px, read noise 0.004 of full scale), as
// 16-bit grey frames.
const nlohmann::json kCameraKeys = {
    {"format", "Mono16"}, {"exposure_us", 1000}, {"reference_exposure_us", 1000}, {"fps", 500},
    {"ambient", 0.02},    {"camera_blur", 0.8},  {"noise", 0.004 * 65535}};

TEST(BoardScene, CapturesOfTheSceneKeyCalibrateToTheTruth) {
  const testing::TempDir dir;
  const BoardRig rig = DefaultBoardRig();
  const ChessboardSpec board = Board();
  // BoardRigPoses' third pose is left out: OpenCV's chessboard detector does not find the board
  // in this world's white photo of it (board_projector_test's direct render finds it), and a
  // failed search costs about 40 s at 1280×800; calibrate board skips such a session.
  std::vector<Eigen::Isometry3d> poses = BoardRigPoses(rig, board, 8, 1.0);
  poses.erase(poses.begin() + 2);
  const SceneChessboard key = ChessboardKey(board, poses);
  const std::filesystem::path scene = WriteScene(dir.path(), rig, key.Json(), kCameraKeys);

  // The key read back places the board where BoardRigPoses did.
  const std::optional<SceneChessboard> read = ReadSceneChessboard(scene);
  ASSERT_TRUE(read);
  ASSERT_EQ(read->poses.size(), poses.size());
  for (size_t k = 0; k < poses.size(); ++k)
    EXPECT_LT(testing::MaxAbsDifference(read->CamFromBoard(k).matrix(), poses[k].matrix()), 1e-9)
        << k;

  std::string sessions;
  const auto start = Clock::now();
  for (size_t k = 0; k < poses.size(); ++k) {
    const std::string session = (dir.path() / ("pose_" + std::to_string(k))).string();
    const testing::CommandRun capture = testing::RunProcam(
        "capture --camera 'synthetic:" + scene.string() + "?board_pose=" + std::to_string(k) +
        "&patches=20&seed=" + std::to_string(20 + k + (k >= 2)) +
        "' --projector 0 --sequence structured_light --pattern-gamma 2.2 --frames 1 "
        "--settle-ms 1 --out " +
        session);
    ASSERT_EQ(capture.exit_code, 0) << capture.output;
    sessions += " " + session;
  }
  std::printf("procam capture, %zu board poses: %.1f s\n", poses.size(), SecondsSince(start));

  const std::filesystem::path out = dir.path() / "rig";
  const auto calibrate_start = Clock::now();
  const testing::CommandRun calibrate =
      testing::RunProcam("calibrate board" + sessions +
                         " --corners 11x8 --square 0.025 --name front --out " + out.string());
  std::printf("procam calibrate board, %zu poses: %.1f s\n%s", poses.size(),
              SecondsSince(calibrate_start), calibrate.output.c_str());
  ASSERT_EQ(calibrate.exit_code, 0) << calibrate.output;
  EXPECT_EQ(calibrate.output.find("chessboard not found"), std::string::npos);

  // Against the truth the scene file states (the bounds of docs/chessboard.md).
  const CameraModel camera = ReadCameraModelFile(out / "camera.cameramodel");
  const CameraModel projector = ReadCameraModelFile(out / "front.cameramodel");
  const auto check_lens = [](const char* device, const std::vector<double>& estimate,
                             const std::vector<double>& truth) {
    std::printf(
        "%s: fx %.3f (%.1f, %+.4f%%) fy %.3f (%.1f, %+.4f%%) cx %.3f (%.1f) cy %.3f "
        "(%.1f)\n",
        device, estimate[0], truth[0], 100 * (estimate[0] / truth[0] - 1), estimate[1], truth[1],
        100 * (estimate[1] / truth[1] - 1), estimate[2], truth[2], estimate[3], truth[3]);
    EXPECT_LT(std::abs(estimate[0] / truth[0] - 1.0), 0.002) << device;
    EXPECT_LT(std::abs(estimate[1] / truth[1] - 1.0), 0.002) << device;
    EXPECT_LT(std::abs(estimate[2] - truth[2]), 1.0) << device;
    EXPECT_LT(std::abs(estimate[3] - truth[3]), 1.0) << device;
  };
  check_lens("camera", camera.intrinsics, rig.camera.intrinsics());
  check_lens("projector", projector.intrinsics, rig.projector.intrinsics());
  const double translation_mm =
      1e3 * (projector.cam_from_ref.translation() - rig.projector_from_camera.translation()).norm();
  const double rotation_deg =
      AngleDeg(projector.cam_from_ref.linear(), rig.projector_from_camera.linear());
  std::printf("projector_from_camera: translation error %.3f mm, rotation error %.4f deg\n",
              translation_mm, rotation_deg);
  EXPECT_LT(translation_mm, 1.0);
  EXPECT_LT(rotation_deg, 0.02);
}

// A bad key stops the capture with one line naming the file and the key; a pose the key does not
// have, and a scene without the key, too.
TEST(BoardScene, BadKeysAreOneLineNamingTheFileAndKey) {
  const testing::TempDir dir;
  const BoardRig rig = DefaultBoardRig();
  const std::vector<Eigen::Isometry3d> poses = BoardRigPoses(rig, Board(), 2, 1.0);
  const nlohmann::json good = ChessboardKey(Board(), poses).Json();
  const auto refused = [&](const nlohmann::json& chessboard, int pose,
                           const std::string& expected) {
    const std::filesystem::path scene = WriteScene(dir.path(), rig, chessboard, kCameraKeys);
    testing::ExpectOneErrorLine(
        testing::RunProcamStderr("capture --camera 'synthetic:" + scene.string() + "?board_pose=" +
                                 std::to_string(pose) + "' --sequence structured_light --out " +
                                 (dir.path() / "session").string()),
        expected, chessboard.dump());
    EXPECT_FALSE(std::filesystem::exists(dir.path() / "session" / "session.json"));
  };
  nlohmann::json bad = good;
  bad["poses"] = nlohmann::json::array();
  refused(bad, 0, "board.json: chessboard.poses: must be a non-empty array");
  bad = good;
  bad["poses"][1]["translation_m"] = {0.0, 0.0, -1.0};
  refused(bad, 0,
          "board.json: chessboard.poses[1].translation_m: the board's centre must be in "
          "front of the camera");
  bad = good;
  bad["corners"] = {9};
  refused(bad, 0, "board.json: chessboard.corners: must be [columns, rows]");
  bad = good;
  bad["tilt"] = 3;
  refused(bad, 0, "board.json: chessboard.tilt: unknown key");
  refused(good, 5, "board.json: chessboard.poses: no pose 5 (it has 2)");
  bad = good;
  bad["poses"][0]["translation_m"] = {5.0, 0.0, 1.0};  // far to the side: out of view
  refused(bad, 0, "board.json: chessboard.poses[0]: the board is not in the camera's view");
}

}  // namespace
}  // namespace procam
