// procam calibrate projectors, end to end without hardware: `procam capture --sequence
// structured_light` with the synthetic camera photographing the tiny box lit by each of its two
// projectors, then the command on the two sessions with a camera guess 5 cm and about 2° off,
// compared with the simulated rig. `procam calibrate camera` is skipped: the test writes the
// synthetic camera's true lens as RIG_DIR/camera.cameramodel (extrinsics zero, as `calibrate
// camera` writes it), so only the projectors and the camera's pose are estimated.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <string>

#include "base/camera_model.h"
#include "calibration/registration.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "base/io.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::CommandRun;
using testing::RunProcam;

nlohmann::json ReadJson(const std::filesystem::path& path) {
  std::ifstream file(path);
  return nlohmann::json::parse(file);
}

const std::string kSyntheticCamera =
    "'synthetic:tiny_box?patches=20&fps=500&exposure_us=1000&reference_exposure_us=1000"
    "&noise=1'";
// The true camera is at (0.5, −1.4, 0.8) looking at (0.5, 0.6, 0.45): the guess is 5.4 cm and
// about 2° off.
const std::string kGuess = "0.54,-1.37,0.82,0.55,0.6,0.5";

// Two sessions (projectors 0 and 1) and a rig directory with the true camera lens, shared by
// the tests of this file.
class CalibrateProjectorsCommand : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    for (int k = 0; k < 2; ++k) {
      const CommandRun capture =
          RunProcam("capture --camera " + kSyntheticCamera + " --projector " + std::to_string(k) +
                    " --sequence structured_light --pattern-gamma 2.2 --frames 1 --settle-ms 1 "
                    "--out " + Session(k));
      ASSERT_EQ(capture.exit_code, 0) << capture.output;
    }
    world_ = MakeSyntheticWorld("tiny_box", 20);
  }
  static void TearDownTestSuite() {
    world_.reset();
    delete dir_;
  }
  static std::string Session(int k) { return (*dir_ / ("sl" + std::to_string(k))).string(); }
  static void WriteTrueCamera(const std::filesystem::path& rig) {
    std::filesystem::create_directories(rig);
    const CameraGeometry& camera = world_->rig->camera();
    CameraModel model;
    model.lens_model = camera.lens_model();
    model.intrinsics = camera.intrinsics();
    model.width = camera.width();
    model.height = camera.height();
    WriteCameraModelFile(rig / "camera.cameramodel", model, "true synthetic camera (test)");
  }
  static testing::TempDir* dir_;
  static std::shared_ptr<SyntheticWorld> world_;
};
testing::TempDir* CalibrateProjectorsCommand::dir_ = nullptr;
std::shared_ptr<SyntheticWorld> CalibrateProjectorsCommand::world_;

TEST_F(CalibrateProjectorsCommand, RecoversTheSyntheticRig) {
  const std::filesystem::path rig = *dir_ / "rig";
  WriteTrueCamera(rig);
  // What other commands wrote survives (right's black, from calibrate photometric); a projector
  // of an earlier calibration that this one does not name is dropped.
  {
    std::ofstream file(rig / "rig.json");
    file << R"({"format_version": 1, "projectors": [{"name": "right", "black": 0.01},
                                                     {"name": "stale", "model": "stale.cameramodel"}]})";
  }
  const CommandRun run = RunProcam("calibrate projectors " + Session(0) + " " + Session(1) +
                                   " --scene synthetic:tiny_box --out " + rig.string() +
                                   " --camera-guess " + kGuess);
  std::printf("%s", run.output.c_str());
  ASSERT_EQ(run.exit_code, 0) << run.output;

  const SimulatedRig& truth = *world_->rig;
  const Eigen::Isometry3d room_from_camera = truth.camera().proj_from_world().inverse();
  const CameraModel camera = ReadCameraModelFile(rig / "camera.cameramodel");
  EXPECT_EQ(camera.intrinsics, truth.camera().intrinsics());  // held fixed
  const Eigen::Isometry3d estimate = camera.cam_from_ref.inverse();
  const double camera_mm = 1e3 * (estimate.translation() - room_from_camera.translation()).norm();
  const double camera_deg =
      Eigen::AngleAxisd(estimate.linear() * room_from_camera.linear().transpose()).angle() * 180 /
      std::numbers::pi;
  std::printf("camera: position %.3f mm, orientation %.4f deg\n", camera_mm, camera_deg);
  EXPECT_LT(camera_mm, 5.0);
  EXPECT_LT(camera_deg, 0.2);  // see the projectors' orientation below

  const nlohmann::json rig_json = ReadJson(rig / "rig.json");
  EXPECT_EQ(rig_json["camera"]["model"], "camera.cameramodel");
  ASSERT_EQ(rig_json["projectors"].size(), 2u);
  for (int k = 0; k < 2; ++k) {
    const Projector& projector = truth.projectors()[k];
    const nlohmann::json* entry = nullptr;
    for (const nlohmann::json& e : rig_json["projectors"])
      if (e["name"] == projector.name) entry = &e;
    ASSERT_NE(entry, nullptr) << projector.name;
    ASSERT_EQ((*entry)["model"], projector.name + ".cameramodel");
    const CameraModel model = ReadCameraModelFile(rig / (projector.name + ".cameramodel"));
    const ProjectorGeometry& g = projector.geometry;
    const double fx = std::abs(model.intrinsics[0] / g.intrinsics()[0] - 1.0);
    const double fy = std::abs(model.intrinsics[1] / g.intrinsics()[1] - 1.0);
    const double position_mm = 1e3 * (model.cam_from_ref.inverse().translation() -
                                      g.proj_from_world().inverse().translation())
                                         .norm();
    const double orientation_deg =
        Eigen::AngleAxisd(model.cam_from_ref.linear() * g.proj_from_world().linear().transpose())
            .angle() * 180 / std::numbers::pi;
    std::printf("%s: fx %.4f%%, fy %.4f%%, position %.3f mm, orientation %.4f deg\n",
                projector.name.c_str(), 100 * fx, 100 * fy, position_mm, orientation_deg);
    EXPECT_EQ(model.width, g.width());
    EXPECT_LT(fx, 0.005);
    EXPECT_LT(fy, 0.005);
    EXPECT_LT(position_mm, 5.0);
    // The issue's 0.1° is stated for a room (c_shaped: 0.007°, registration_test); in this 1 m
    // box with 320 × 200 projectors the decoded rows carry a bias of about 0.2 px that the free
    // camera pose turns into 0.07–0.13° (the same with the library path, CalibrateRoom.
    // TinyBoxDecoded), so the bound here is 0.2°.
    EXPECT_LT(orientation_deg, 0.2);
  }
  EXPECT_EQ(rig_json["projectors"][0]["black"], nlohmann::json({0.01, 0.01, 0.01}));  // "right", written before

  const nlohmann::json& registration = rig_json["registration"];
  EXPECT_EQ(registration["projectors"].size(), 2u);
  EXPECT_LT(registration["projectors"][0]["rms_px_per_coordinate"].get<double>(), 0.5);
  // What the joint solve is sure of, per projector, and the report that draws it.
  for (const nlohmann::json& projector : registration["projectors"]) {
    const nlohmann::json& uncertainty = projector["projection_uncertainty"];
    ASSERT_TRUE(uncertainty.is_object()) << projector.dump();
    EXPECT_GT(uncertainty["centre_px"].get<double>(), 0.0);
    EXPECT_EQ(uncertainty["grid_px"].size(), 12u);
    EXPECT_GT(uncertainty["distance_m"].get<double>(), 0.3);
  }
  EXPECT_TRUE(std::filesystem::exists(rig / "projectors_report.html"));
  const nlohmann::json& residual = registration["residual"];
  // Triangulation noise sets these: 320-pixel projectors (f = 343 px) 0.45 m from the camera
  // put 0.34 px of decoding error at about 9 mm in depth 2 m away; the guess was 41 mm RMS off.
  EXPECT_GT(residual["inlier_fraction"].get<double>(), 0.7);
  EXPECT_LT(residual["inliers"]["median_mm"].get<double>(), 4.0);
  EXPECT_LT(residual["icp_vs_joint_mm"].get<double>(), 5.0);
  EXPECT_LT(residual["icp_vs_joint_deg"].get<double>(), 0.2);
  const nlohmann::json result = ReadJson(rig / "result.json");
  EXPECT_GE(result["projectors"]["planes_from_scan"]["planes"].size(), 3u);
}

// A projector calibrated on a chessboard joins the rig: its lens held from its .cameramodel
// (--hold-lens NAME=FILE), its pose alone solved. The held lens is the truth with a board
// calibration's errors (docs/chessboard.md: focal lengths 0.02% off, the principal point 0.5 and
// 0.7 px off at f = 1500 px; here the same angles, scaled to this 320-pixel projector's f of
// 343 px: a principal point off by 0.7 px would turn it by 0.12° alone); it is written unchanged
// into the rig, and the pose lands within the bounds of the free solve above.
TEST_F(CalibrateProjectorsCommand, AHeldLensIsWrittenUnchangedAndThePoseSolved) {
  const std::filesystem::path rig = *dir_ / "held_rig";
  WriteTrueCamera(rig);
  const Projector& truth = world_->rig->projectors()[0];
  const ProjectorGeometry& g = truth.geometry;
  CameraModel lens = g.Model();
  lens.intrinsics[0] *= 1.0002;
  lens.intrinsics[1] *= 0.99985;
  lens.intrinsics[2] += 0.5 * lens.intrinsics[0] / 1500.0;
  lens.intrinsics[3] -= 0.7 * lens.intrinsics[1] / 1500.0;
  lens.cam_from_ref = Eigen::Isometry3d::Identity();  // a board calibration's: camera-relative
  const std::filesystem::path lens_file = *dir_ / "board" / (truth.name + ".cameramodel");
  std::filesystem::create_directories(lens_file.parent_path());
  WriteCameraModelFile(lens_file, lens, "a board calibration's lens (test)");
  const CameraModel given = ReadCameraModelFile(lens_file);

  const CommandRun run =
      RunProcam("calibrate projectors " + Session(0) + " " + Session(1) +
                " --scene synthetic:tiny_box --out " + rig.string() + " --camera-guess " + kGuess +
                " --hold-lens " + truth.name + "=" + lens_file.string());
  std::printf("%s", run.output.c_str());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_NE(run.output.find("lens held from " + lens_file.string()), std::string::npos);

  const CameraModel model = ReadCameraModelFile(rig / (truth.name + ".cameramodel"));
  EXPECT_EQ(model.lens_model, given.lens_model);
  EXPECT_EQ(model.intrinsics, given.intrinsics);  // unchanged, to the last bit
  const double position_mm = 1e3 * (model.cam_from_ref.inverse().translation() -
                                    g.proj_from_world().inverse().translation())
                                       .norm();
  const double orientation_deg =
      Eigen::AngleAxisd(model.cam_from_ref.linear() * g.proj_from_world().linear().transpose())
          .angle() *
      180 / std::numbers::pi;
  std::printf("%s, lens held: position %.3f mm, orientation %.4f deg\n", truth.name.c_str(),
              position_mm, orientation_deg);
  EXPECT_LT(position_mm, 5.0);
  EXPECT_LT(orientation_deg, 0.2);
  // The other projector's lens is solved as before.
  const CameraModel other =
      ReadCameraModelFile(rig / (world_->rig->projectors()[1].name + ".cameramodel"));
  EXPECT_LT(
      std::abs(other.intrinsics[0] / world_->rig->projectors()[1].geometry.intrinsics()[0] - 1.0),
      0.005);
  const nlohmann::json result = ReadJson(rig / "result.json");
  for (const nlohmann::json& entry : result["projectors"]["projectors"])
    EXPECT_EQ(entry["lens_held"].get<bool>(), entry["name"] == truth.name) << entry.dump();
  const nlohmann::json rig_json = ReadJson(rig / "rig.json");
  EXPECT_EQ(rig_json["registration"]["projectors"][0]["lens"].get<std::string>(),
            truth.name == rig_json["registration"]["projectors"][0]["name"]
                ? "held from " + lens_file.string()
                : "solved");

  // Refusals, one line each naming the file or the option, nothing written.
  const std::filesystem::path bad_rig = *dir_ / "held_bad_rig";
  WriteTrueCamera(bad_rig);
  CameraModel wrong_size = lens;
  wrong_size.width = 640;
  WriteCameraModelFile(*dir_ / "board" / "wrong_size.cameramodel", wrong_size, "wrong size");
  const std::string sessions = Session(0) + " " + Session(1);
  const std::string room = " --scene synthetic:tiny_box --camera-guess " + kGuess;
  struct Case {
    std::string arguments, expected;
  };
  for (const Case& c : {
           Case{sessions + room + " --hold-lens " + truth.name + "=" +
                    (*dir_ / "board" / "wrong_size.cameramodel").string(),
                "wrong_size.cameramodel: imagersize 640x"},
           Case{sessions + room + " --hold-lens nobody=" + lens_file.string(),
                "no session's projector is named 'nobody'"},
           Case{sessions + room + " --hold-lens " + truth.name, "NAME=FILE"},
           Case{sessions + room + " --hold-lens " + truth.name + "=" +
                    (*dir_ / "board" / "missing.cameramodel").string(),
                "missing.cameramodel"},
           Case{sessions + " --camera-height 0.8 --hold-lens " + truth.name + "=" +
                    (*dir_ / "board" / "wrong_size.cameramodel").string(),
                "wrong_size.cameramodel: imagersize 640x"},
       }) {
    testing::ExpectOneErrorLine(testing::RunProcamStderr("calibrate projectors " + c.arguments +
                                                         " --out " + bad_rig.string()),
                                c.expected, c.arguments);
  }
  EXPECT_FALSE(std::filesystem::exists(bad_rig / "rig.json"));
}

// The scan (no room model, the scale from the camera's true height above the box's floor) holds a
// lens as the registration does: written unchanged, bit for bit, the pose solved, and result.json
// says where the lens came from. The scan's room frame is its own (z up from the scanned floor),
// so the pose is compared relative to the camera.
TEST_F(CalibrateProjectorsCommand, TheScanHoldsALensAndSolvesThePose) {
  const std::filesystem::path rig = *dir_ / "scan_held_rig";
  WriteTrueCamera(rig);
  const SimulatedRig& truth = *world_->rig;
  const Projector& held = truth.projectors()[0];
  CameraModel lens = held.geometry.Model();
  lens.cam_from_ref = Eigen::Isometry3d::Identity();  // a board calibration's: camera-relative
  const std::filesystem::path lens_file = *dir_ / "board_scan" / (held.name + ".cameramodel");
  std::filesystem::create_directories(lens_file.parent_path());
  WriteCameraModelFile(lens_file, lens, "a board calibration's lens (test)");
  const CameraModel given = ReadCameraModelFile(lens_file);
  const Eigen::Isometry3d world_from_camera = truth.camera().proj_from_world().inverse();

  const CommandRun run =
      RunProcam("calibrate projectors " + Session(0) + " " + Session(1) + " --camera-height " +
                std::to_string(world_from_camera.translation().z()) + " --out " + rig.string() +
                " --hold-lens " + held.name + "=" + lens_file.string());
  std::printf("%s", run.output.c_str());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_NE(run.output.find("lens held from " + lens_file.string()), std::string::npos);

  const CameraModel camera = ReadCameraModelFile(rig / "camera.cameramodel");
  const Eigen::Isometry3d room_from_camera = camera.cam_from_ref.inverse();
  for (int k = 0; k < 2; ++k) {
    const Projector& projector = truth.projectors()[k];
    const CameraModel model = ReadCameraModelFile(rig / (projector.name + ".cameramodel"));
    if (k == 0) {
      EXPECT_EQ(model.lens_model, given.lens_model);
      EXPECT_EQ(model.intrinsics, given.intrinsics);  // unchanged, to the last bit
    } else {
      EXPECT_LT(std::abs(model.intrinsics[0] / projector.geometry.intrinsics()[0] - 1.0), 0.01);
    }
    const Eigen::Isometry3d proj_from_cam = model.cam_from_ref * room_from_camera;
    const Eigen::Isometry3d true_proj_from_cam =
        projector.geometry.proj_from_world() * world_from_camera;
    const double position_mm =
        1e3 *
        (proj_from_cam.inverse().translation() - true_proj_from_cam.inverse().translation()).norm();
    const double orientation_deg =
        Eigen::AngleAxisd(proj_from_cam.linear() * true_proj_from_cam.linear().transpose())
            .angle() *
        180 / std::numbers::pi;
    std::printf("scan, %s%s: position %.3f mm, orientation %.4f deg\n", projector.name.c_str(),
                k == 0 ? " (lens held)" : "", position_mm, orientation_deg);
    // The scan's bounds through the command on this box (CalibrateAll.ScansTheRoomWithoutAModel:
    // 8 mm) and this file's 0.2° (the decoded rows' bias, above). Measured over two captures:
    // held 2.2–3.7 mm, 0.013–0.025°; the other 2.8–4.0 mm, 0.05–0.065°; the same sessions with
    // every lens solved 2.3 mm, 0.030° (held 2.2 mm, 0.025°).
    EXPECT_LT(position_mm, 8.0) << projector.name;
    EXPECT_LT(orientation_deg, 0.2) << projector.name;
  }
  const nlohmann::json result = ReadJson(rig / "result.json");
  for (const nlohmann::json& entry : result["projectors"]["projectors"])
    EXPECT_EQ(entry["lens_held"].get<bool>(), entry["name"] == held.name) << entry.dump();
  // Where the lens came from, and an uncertainty of the held lens's pose alone.
  for (const nlohmann::json& entry :
       result["projectors"]["registration"]["self_calibration"]["projectors"]) {
    EXPECT_EQ(entry["lens"].get<std::string>(),
              entry["name"] == held.name ? "held from " + lens_file.string() : "solved")
        << entry.dump();
    EXPECT_EQ(entry["projection_uncertainty"]["pose_only"].get<bool>(), entry["name"] == held.name)
        << entry.dump();
  }
}

// Bad input: one line naming the file or option, exit code 1, nothing written.
TEST_F(CalibrateProjectorsCommand, BadInputIsRefusedAndNothingIsWritten) {
  const std::filesystem::path rig = *dir_ / "bad_rig";
  const std::string sessions = Session(0) + " " + Session(1);
  // No camera.cameramodel.
  CommandRun run = RunProcam("calibrate projectors " + sessions +
                             " --scene synthetic:tiny_box --out " + rig.string() +
                             " --camera-guess " + kGuess);
  EXPECT_EQ(run.exit_code, 1);
  EXPECT_NE(run.output.find("camera.cameramodel: file not found"), std::string::npos)
      << run.output;
  WriteTrueCamera(rig);
  const auto files_before = std::distance(std::filesystem::directory_iterator(rig),
                                          std::filesystem::directory_iterator());
  struct Case {
    std::string arguments, expected;
  };
  for (const Case& c : {
           Case{sessions + " --scene synthetic:tiny_box", "--camera-guess: required"},
           Case{sessions + " --scene synthetic:tiny_box --camera-guess 1,2,3", "--camera-guess"},
           Case{sessions + " --scene nowhere.json --camera-guess " + kGuess, "--scene nowhere.json"},
           Case{Session(0) + " " + (*dir_ / "missing").string() +
                    " --scene synthetic:tiny_box --camera-guess " + kGuess,
                "missing: not a directory"},
           Case{Session(0) + " " + Session(0) + " --scene synthetic:tiny_box --camera-guess " +
                    kGuess,
                "used twice"},
       }) {
    run = RunProcam("calibrate projectors " + c.arguments + " --out " + rig.string());
    EXPECT_EQ(run.exit_code, 1) << c.arguments;
    EXPECT_NE(run.output.find(c.expected), std::string::npos) << c.arguments << "\n"
                                                              << run.output;
  }
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(rig),
                          std::filesystem::directory_iterator()),
            files_before);
  EXPECT_FALSE(std::filesystem::exists(rig / "rig.json"));
}

}  // namespace
}  // namespace procam
