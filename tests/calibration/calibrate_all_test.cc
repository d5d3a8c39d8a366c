// procam calibrate all, end to end on the synthetic tiny box: chessboard photos of the simulated
// camera, structured light and flat fields per projector through the capture module, the joint
// projector/camera-pose refinement and the photometry in scene units — the recovered rig against
// the simulated rig's ground truth.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "base/camera_model.h"
#include "base/image_io.h"
#include "base/io.h"
#include "calibration/floor_chessboard.h"
#include "calibration/registration.h"
#include "capture/simulated_camera.h"
#include "datasets_synthetic/chessboard_views.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/scan_accuracy.h"
#include "datasets_synthetic/simulated_rig.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "geometry/scene.h"
#include "pipeline/projectors_stage.h"
#include "projection/rig_directory.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

double AngleDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a * b.transpose()).angle() * 180.0 / M_PI;
}

TEST(CalibrateAll, RecoversTheSyntheticRig) {
  testing::TempDir dir;
  const std::string camera =
      "'synthetic:tiny_box?patches=150&fps=500&exposure_us=1000&reference_exposure_us=1000"
      "&black=8&noise=1'";
  const testing::CommandRun run = testing::RunProcam(
      "calibrate all --camera " + camera + " --frames 2 --settle-ms 1 --out " +
      (dir / "rig").string());
  ASSERT_EQ(run.exit_code, 0) << run.output;

  const SyntheticScene truth = MakeSyntheticScene("tiny_box", 150);
  const RigDirectory rig = ReadRigDirectory(dir / "rig");
  ASSERT_EQ(rig.projectors.size(), truth.projectors.size());
  for (const DevicePlacement& placement : truth.projectors) {
    const Projector expected = ProjectorFromPlacement(placement);
    const Projector* found = nullptr;
    for (const Projector& p : rig.projectors) {
      if (p.name == expected.name) found = &p;
    }
    ASSERT_NE(found, nullptr) << expected.name;
    const double focal = std::abs(found->geometry.intrinsics()[0] / expected.geometry.intrinsics()[0] - 1);
    const double position =
        (found->geometry.CentreInWorld() - expected.geometry.CentreInWorld()).norm();
    const double orientation = AngleDeg(found->geometry.proj_from_world().linear(),
                                        expected.geometry.proj_from_world().linear());
    std::printf("%s: focal %.3f%%, position %.2f mm, orientation %.3f deg, max %.2f%%, "
                "half-light drive %.4f (true %.4f)\n",
                expected.name.c_str(), 100 * focal, 1e3 * position, orientation,
                100 * (found->photometry.max[1] / expected.photometry.max[1] - 1),
                found->photometry.response[1].Drive(0.5), expected.photometry.response[1].Drive(0.5));
    EXPECT_LT(focal, 0.005);
    // End to end the whole rig shifts with the camera's registration: the tiny box's short
    // baselines turn its ~0.2 px decoding bias into up to 0.13° and ~6 mm (measured 6.4–6.6 mm,
    // camera 5.8 mm; docs/calibration.md). The 5 mm / 0.1° are met by the joint
    // refinement on c_shaped with the true camera lens (tests/calibration/registration_test);
    // here the bound is 1 cm, which a wrong registration or a swapped projector far exceeds.
    EXPECT_LT(position, 0.01);
    EXPECT_LT(orientation, 0.2);
    for (int c = 0; c < 3; ++c) {
      EXPECT_LT(std::abs(found->photometry.max[c] / expected.photometry.max[c] - 1), 0.02);
    }
    EXPECT_NEAR(found->photometry.response[1].Drive(0.5), expected.photometry.response[1].Drive(0.5),
                0.01);
    // Black, separated from the other projector's (each alone reads both: +97%). Its light is
    // ~0.2 DN against 1 DN of read noise and 8-bit steps with 2 frames: noise-limited (16
    // frames bring it within 3%; docs/calibration.md).
    for (int c = 0; c < 3; ++c) {
      std::printf("  black %c: %.5f (true %.5f)\n", "RGB"[c], found->photometry.black[c],
                  expected.photometry.black[c]);
      EXPECT_LT(std::abs(found->photometry.black[c] / expected.photometry.black[c] - 1), 0.15);
    }
  }
  const CameraModel model = ReadCameraModelFile(dir / "rig/camera.cameramodel");
  const CameraGeometry true_camera = CameraFromPlacement(truth.camera);
  const double camera_position =
      (model.cam_from_ref.inverse().translation() - true_camera.CentreInWorld()).norm();
  std::printf("camera: focal %.3f%%, position %.2f mm\n",
              100 * (model.intrinsics[0] / true_camera.intrinsics()[0] - 1), 1e3 * camera_position);
  EXPECT_LT(std::abs(model.intrinsics[0] / true_camera.intrinsics()[0] - 1), 0.005);
  EXPECT_LT(camera_position, 0.01);
  EXPECT_GT(rig.reflectance.rows(), 0);
}

// The metric scale of a scan: the synthetic camera's photo of a board lying on its floor (z = 0),
// rendered at a pose the test does not know, gives the camera's true height back (the board
// rendered through the camera's distorted lens; independent truth: the camera's placement).
TEST(FloorChessboard, GivesTheCameraHeightFromOnePhoto) {
  RegisterSyntheticWorld();
  testing::TempDir dir;
  for (const std::string name : {"tiny_box", "c_shaped"}) {
    const SyntheticScene scene = MakeSyntheticScene(name, 20);
    const CameraGeometry camera = CameraFromPlacement(scene.camera);
    const std::optional<SimulatedCamera> simulated =
        FindSimulatedCamera("synthetic:" + name + "?patches=20");
    ASSERT_TRUE(simulated.has_value());
    ChessboardSpec board;
    const std::filesystem::path photo = dir / (name + "_floor.png");
    board.square_size = simulated->render_floor_chessboard(board.corners_x, board.corners_y, photo);
    const double thickness = 0.004;  // the photo shows the board's face on the floor itself
    const FloorChessboard floor = MeasureFloorChessboard(camera.Model(), board, photo, thickness);
    const double height = camera.CentreInWorld().z();
    std::printf("%s: %s (true %.4f m, squares %.2f m)\n", name.c_str(),
                floor.BriefReport().c_str(), height, board.square_size);
    EXPECT_NEAR(floor.camera_height - thickness, height, 0.01 * height) << name;
    EXPECT_LT(floor.rms_px, 0.5) << name;  // measured 0.13 (tiny_box), 0.35 (c_shaped, 8° grazing)
    EXPECT_LT(floor.floor_normal_in_cam.y(), 0.0) << name;  // the floor's normal is image-up

    // A board of other corners, a photo of another size: one line naming the photo.
    ChessboardSpec other = board;
    other.corners_x = 7;
    EXPECT_THROW(MeasureFloorChessboard(camera.Model(), other, photo), IoError);
    CameraModel small = camera.Model();
    small.width /= 2;
    try {
      MeasureFloorChessboard(small, board, photo);
      ADD_FAILURE() << "a photo of another size was accepted";
    } catch (const IoError& error) {
      EXPECT_NE(std::string(error.what()).find(photo.filename().string()), std::string::npos)
          << error.what();
    }
  }
}

// No room model and no guess: calibrate all --scan on the tiny box self-calibrates from the
// structured light, takes the metric scale from the synthetic camera's photo of a chessboard on
// the floor, writes the scanned room as RIG_DIR/room.json and does the photometry on it. Checked
// against the simulated rig's truth: the camera's height, every projector relative to the camera,
// every true surface found and the scanned surfaces on the true ones.
//
// The camera's lens is given (--camera-model, the simulated camera's true lens): the tiny box's
// 240 × 160 camera calibrates from its chessboard photos with fy/fx 0.4% off, and a scan is
// sensitive to the camera's aspect ratio (measured: the back wall 5.7% too close and 3.4° off
// vertical, docs/scan.md). The chessboard path itself is RecoversTheSyntheticRig's.
TEST(CalibrateAll, ScansTheRoomWithoutAModel) {
  testing::TempDir dir;
  const SyntheticScene truth = MakeSyntheticScene("tiny_box", 150);
  const CameraGeometry true_camera = CameraFromPlacement(truth.camera);
  WriteCameraModelFile(dir / "lens.cameramodel", true_camera.Model(), "the true lens");
  const std::string camera =
      "'synthetic:tiny_box?patches=150&fps=500&exposure_us=1000&reference_exposure_us=1000"
      "&black=8&noise=1'";
  const testing::CommandRun run = testing::RunProcam(
      "calibrate all --camera " + camera + " --camera-model " +
      (dir / "lens.cameramodel").string() + " --scan --frames 2 --settle-ms 1 --out " +
      (dir / "rig").string());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_NE(run.output.find("$ procam calibrate projectors"), std::string::npos);
  EXPECT_NE(run.output.find("--floor-chessboard"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("the projectors' uncertainty leaves the lens's out"), std::string::npos)
      << run.output;
  ASSERT_TRUE(std::filesystem::exists(dir / "rig/room.json"));
  const Scene room = LoadScene(dir / "rig/room.json");

  const CameraModel model = ReadCameraModelFile(dir / "rig/camera.cameramodel");
  const Eigen::Isometry3d cam_from_room = model.cam_from_ref;
  const Eigen::Isometry3d world_from_room = true_camera.proj_from_world().inverse() * cam_from_room;

  // The scale: the camera's height above the floor (z = 0 in both frames).
  const double true_height = true_camera.CentreInWorld().z();
  const double height = cam_from_room.inverse().translation().z();
  std::printf("camera height %.4f m (true %.4f m)\n", height, true_height);
  // Measured −0.41% (the floor photo's corners at this 240 × 160 camera; FloorChessboard).
  EXPECT_NEAR(height, true_height, 0.01 * true_height);

  // Projectors relative to the camera (the room frames differ by a turn about the vertical).
  const RigDirectory rig = ReadRigDirectory(dir / "rig");
  ASSERT_EQ(rig.projectors.size(), truth.projectors.size());
  for (const DevicePlacement& placement : truth.projectors) {
    const Projector expected = ProjectorFromPlacement(placement);
    const Projector* found = nullptr;
    for (const Projector& p : rig.projectors)
      if (p.name == expected.name) found = &p;
    ASSERT_NE(found, nullptr) << expected.name;
    const Vec3 centre = world_from_room * found->geometry.CentreInWorld();
    const double position = (centre - expected.geometry.CentreInWorld()).norm();
    const double focal =
        std::abs(found->geometry.intrinsics()[0] / expected.geometry.intrinsics()[0] - 1);
    std::printf("%s: focal %.3f%%, position %.2f mm\n", expected.name.c_str(), 100 * focal,
                1e3 * position);
    EXPECT_LT(focal, 0.005);    // measured 0.009–0.071%
    EXPECT_LT(position, 0.008);  // measured 2.1–2.7 mm
  }

  // Every true surface found, each scanned surface on a true one.
  const RoomModel true_model(truth.scene);
  const RoomModel scanned_model(room);
  std::vector<bool> found(truth.scene.surfaces.size(), false);
  for (size_t s = 0; s < room.surfaces.size(); ++s) {
    const ScannedSurfaceAccuracy accuracy =
        MeasureScannedSurface(true_model, scanned_model, static_cast<int>(s), world_from_room);
    const double rms = accuracy.RmsMetres(), area = accuracy.area_m2;
    // The true surfaces under the scanned surface: its facets' centroids vote for the nearest;
    // every true surface with a quarter of some scanned surface's votes is found.
    const std::vector<int>& votes = accuracy.votes;
    const int facets = accuracy.facets;
    const int true_surface = accuracy.TrueSurface();
    for (size_t t = 0; t < votes.size(); ++t)
      if (4 * votes[t] >= facets) found[t] = true;
    std::printf("scanned %s (%.3f m²) -> true %s: corners and centroids %.1f mm RMS from it\n",
                room.surfaces[s].name.c_str(), area,
                truth.scene.surfaces[true_surface].name.c_str(), 1e3 * rms);
    // The tiny box (240 × 160 camera, baselines of a few dm) triangulates the back wall, 2.4 m
    // away, with about 9–11 mm of noise: measured 3.5–3.7 mm for the side walls and the floor,
    // 9.0 mm for the back wall (a plane flat within its noise; a mesh 13 mm off before
    // SceneFromPoints took such planes). That noise can also leave a small piece of plane on the
    // back wall (0.02–0.04 m² measured): pieces under 0.1 m² are held only to lie near a true
    // surface.
    const bool curved = room.surfaces[s].name.rfind("mesh_", 0) == 0;
    EXPECT_LT(rms, area < 0.1 ? 0.1 : curved ? 0.04 : 0.015) << room.surfaces[s].name;
    // Its reflectance: the photometry's, averaged over the patches the camera saw.
    const Vec3 rho = room.surfaces[s].reflectance, true_rho = truth.scene.surfaces[true_surface].reflectance;
    std::printf("  reflectance (%.3f, %.3f, %.3f), true (%.3f, %.3f, %.3f)\n", rho.x(), rho.y(),
                rho.z(), true_rho.x(), true_rho.y(), true_rho.z());
    // Measured 0.006–0.025 above the truth (the world's paint varies by 5%; the scanned
    // geometry's errors move the light each patch is thought to get). The nominal 0.9 of a
    // surface the photometry did not reach would fail on the floor (0.8).
    if (area >= 0.1) {
      EXPECT_LT((rho - true_rho).cwiseAbs().maxCoeff(), 0.04) << room.surfaces[s].name;
    }
  }
  for (size_t s = 0; s < found.size(); ++s)
    EXPECT_TRUE(found[s]) << truth.scene.surfaces[s].name << " not found";
  EXPECT_GT(rig.reflectance.rows(), 0);  // the photometry ran on the scanned room

  // result.json says where the scale came from.
  const nlohmann::json result = nlohmann::json::parse(ReadFile(dir / "rig/result.json"));
  const nlohmann::json& scale = result["projectors"]["registration"]["scale"];
  EXPECT_EQ(scale["source"], "floor chessboard");
  std::printf("board plane to the scanned floor: %.2f deg\n",
              scale["board_to_scanned_floor_deg"].get<double>());
  EXPECT_LT(scale["board_to_scanned_floor_deg"].get<double>(), 1.0);
  // How many of the scan's points came from one axis alone: a count among its points.
  const nlohmann::json& scan = result["projectors"]["scan"];
  std::printf("scan: %d points, %d from one axis alone\n", scan["points"].get<int>(),
              scan["one_axis_pixels"].get<int>());
  EXPECT_GE(scan["one_axis_pixels"].get<int>(), 0);
  EXPECT_LE(scan["one_axis_pixels"].get<int>(), scan["points"].get<int>());
  // Each projector's projection uncertainty: its map in result.json (16 × 12, corners equal to
  // the grid's), and drawn in projectors_report.html, a picture per projector beside it.
  const std::string report = ReadFile(dir / "rig/projectors_report.html");
  for (const nlohmann::json& p : result["projectors"]["registration"]["self_calibration"]["projectors"]) {
    const nlohmann::json& u = p["projection_uncertainty"];
    ASSERT_TRUE(u.is_object()) << p.dump();
    // The lens came with --camera-model: no chessboard covariance to fold in, and the run says so.
    EXPECT_FALSE(u["includes_camera_lens"].get<bool>());
    ASSERT_EQ(u["grid_px"].size(), 12u);
    ASSERT_EQ(u["grid_px"][0].size(), 16u);
    EXPECT_DOUBLE_EQ(u["grid_px"][0][0].get<double>(), u["corners_px"]["top_left"].get<double>());
    EXPECT_DOUBLE_EQ(u["grid_px"][11][15].get<double>(), u["corners_px"]["bottom_right"].get<double>());
    EXPECT_GT(u["centre_px"].get<double>(), 0.0);
    const std::string name = p["name"];
    EXPECT_TRUE(std::filesystem::exists(dir / "rig" / ("projector_uncertainty_" + name + ".png"))) << name;
    EXPECT_NE(report.find(name + ": projection uncertainty"), std::string::npos) << name;
  }

  // The same captures with the floor photo turned by 5° about the board (which lies along the
  // photo's bottom edge; moved up 20 px to stay whole in view): the board's plane is then about
  // 5° off the scanned floor, and the scan stops naming the photo, writing no room.
  const cv::Mat photo = ReadImage(dir / "rig/captures/floor_chessboard.png", cv::IMREAD_UNCHANGED);
  cv::Mat turn = cv::getRotationMatrix2D(
      cv::Point2f(0.5f * photo.cols, 0.83f * photo.rows), 5.0, 1.0);
  turn.at<double>(1, 2) -= 20.0;
  cv::Mat turned;
  cv::warpAffine(photo, turned, turn, photo.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  WritePng(dir / "turned.png", turned);
  std::filesystem::create_directories(dir / "rig2");
  std::filesystem::copy_file(dir / "lens.cameramodel", dir / "rig2/camera.cameramodel");
  const testing::CommandRun tilted = testing::RunProcam(
      "calibrate projectors " + (dir / "rig/captures/structured_light_left").string() + " " +
      (dir / "rig/captures/structured_light_right").string() + " --names left,right --out " +
      (dir / "rig2").string() + " --floor-chessboard " + (dir / "turned.png").string() +
      " --corners 9x6 --square 0.14 --max-correspondences 1000");
  EXPECT_EQ(tilted.exit_code, 1) << tilted.output;
  // --max-correspondences reaches the scan's self-calibration (4000 by default above).
  for (const char* projector : {"projector 0: ", "projector 1: "}) {
    const size_t at = tilted.output.find(projector);
    ASSERT_NE(at, std::string::npos) << tilted.output;
    const int used = std::stoi(tilted.output.substr(at + std::strlen(projector)));
    EXPECT_LE(used, 1000) << tilted.output.substr(at, 80);
    EXPECT_GT(used, 500) << tilted.output.substr(at, 80);
  }
  const size_t error_line = tilted.output.find("procam: error");
  if (error_line != std::string::npos) std::printf("%s", tilted.output.c_str() + error_line);
  EXPECT_NE(tilted.output.find("turned.png: the board's plane is"), std::string::npos)
      << tilted.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "rig2/room.json"));
}

// A scan needs its scale, and is not a registration.
TEST(CalibrateAll, ScanRefusals) {
  testing::TempDir dir;
  const testing::CommandRun no_scale = testing::RunProcam(
      "calibrate all --camera test:loopback --display glfw:1 --camera-model x --camera-scale 1 "
      "--out " + (dir / "rig").string());
  EXPECT_EQ(no_scale.exit_code, 1);
  EXPECT_NE(no_scale.output.find("--floor-chessboard"), std::string::npos) << no_scale.output;
  const testing::CommandRun both = testing::RunProcam(
      "calibrate all --camera synthetic:tiny_box?patches=20 --scan --scene synthetic:tiny_box "
      "--out " + (dir / "rig").string());
  EXPECT_EQ(both.exit_code, 1);
  EXPECT_NE(both.output.find("--scan"), std::string::npos) << both.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "rig"));  // refused before anything is written

  // calibrate projectors: a scan fits no projector distortion, and refines the camera's lens
  // only with the chessboard's covariance (result.json, from calibrate camera).
  std::filesystem::create_directories(dir / "rig2");
  WriteCameraModelFile(dir / "rig2/camera.cameramodel",
                       CameraFromPlacement(MakeSyntheticScene("tiny_box", 20).camera).Model(),
                       "test");
  const testing::CommandRun refine = testing::RunProcam(
      "calibrate projectors " + (dir / "no_session").string() + " --refine-camera --out " +
      (dir / "rig2").string());
  EXPECT_EQ(refine.exit_code, 1);
  EXPECT_NE(refine.output.find("result.json: camera.intrinsics_covariance: missing"),
            std::string::npos)
      << refine.output;
  const testing::CommandRun distortion = testing::RunProcam(
      "calibrate projectors " + (dir / "no_session").string() + " --refine-distortion --out " +
      (dir / "rig2").string());
  EXPECT_EQ(distortion.exit_code, 1);
  EXPECT_NE(distortion.output.find("only with --scene"), std::string::npos) << distortion.output;
}

// Projector names become file names and rig.json keys: a name with other characters is refused
// by name before anything is written, and a synthetic rig's own names ("front left") are made
// valid ("front_left") rather than replaced.
TEST(CalibrateAll, ProjectorNamesAreValidFileNames) {
  testing::TempDir dir;
  testing::ExpectOneErrorLine(
      testing::RunProcamStderr("calibrate all --camera synthetic:tiny_box?patches=20 --scene "
                               "synthetic:tiny_box --names 'left one,right' --out " +
                               (dir / "rig").string()),
      "--names: 'left one'", "a projector name with a space");
  EXPECT_FALSE(std::filesystem::exists(dir / "rig"));
  EXPECT_EQ(ProjectorNameFrom("front left"), "front_left");
  EXPECT_EQ(ProjectorNameFrom("left-2.b"), "left-2.b");
  EXPECT_TRUE(ValidProjectorName(ProjectorNameFrom("a/b c:d")));
  EXPECT_FALSE(ValidProjectorName("front left"));
  EXPECT_FALSE(ValidProjectorName(""));
}

// --hold-lens (a board-calibrated projector joining the rig, with a room model or scanning) is
// checked before anything is captured: the name must be a projector's, the file must exist.
TEST(CalibrateAll, HeldLensRefusals) {
  testing::TempDir dir;
  const std::string camera = "calibrate all --camera synthetic:tiny_box?patches=20 --names a,b ";
  const std::string out = " --out " + (dir / "rig").string();
  testing::ExpectOneErrorLine(
      testing::RunProcamStderr(camera +
                               "--scan --hold-lens a=" + (dir / "lens.cameramodel").string() + out),
      "lens.cameramodel: file not found (--hold-lens a)", "scanning, missing file");
  testing::ExpectOneErrorLine(
      testing::RunProcamStderr(camera + "--hold-lens nobody=lens.cameramodel" + out),
      "no projector is named 'nobody' (projectors: a, b)", "unknown name");
  testing::ExpectOneErrorLine(testing::RunProcamStderr(camera + "--hold-lens a=" +
                                                       (dir / "lens.cameramodel").string() + out),
                              "lens.cameramodel: file not found (--hold-lens a)", "missing file");
  testing::ExpectOneErrorLine(testing::RunProcamStderr(camera + "--hold-lens a" + out),
                              "--hold-lens: 'a': NAME=FILE", "no file");
  EXPECT_FALSE(std::filesystem::exists(dir / "rig"));
}

TEST(CalibrateAll, RefusesWhatItCannotDo) {
  testing::TempDir dir;
  // A real camera needs chessboard photos or a model, and one display per projector.
  const testing::CommandRun no_board = testing::RunProcam(
      "calibrate all --camera test:loopback --display glfw:1 --scene x.json --out " +
      (dir / "rig").string());
  EXPECT_EQ(no_board.exit_code, 1);
  EXPECT_NE(no_board.output.find("--chessboard"), std::string::npos) << no_board.output;
  const testing::CommandRun no_display = testing::RunProcam(
      "calibrate all --camera test:loopback --out " + (dir / "rig").string());
  EXPECT_EQ(no_display.exit_code, 1);
  EXPECT_NE(no_display.output.find("--display"), std::string::npos) << no_display.output;
  const testing::CommandRun synthetic_display = testing::RunProcam(
      "calibrate all --camera synthetic:tiny_box?patches=20 --display glfw:1 --out " +
      (dir / "rig").string());
  EXPECT_EQ(synthetic_display.exit_code, 1);
  EXPECT_NE(synthetic_display.output.find("looks at its own projectors"), std::string::npos)
      << synthetic_display.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "rig"));  // refused before anything is written
}

}  // namespace
}  // namespace procam
