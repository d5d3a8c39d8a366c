// A projector calibrated with a chessboard and structured light (calibration/board_projector.h)
// against the synthetic rig's truth (datasets_synthetic/board_structured_light.h: DefaultBoardRig,
// a 1280×800 OpenCV4 camera and a 1024×768 OpenCV4 projector 0.2 m apart, an 11×8 board of 2.5 cm
// squares at eight poses about 1 m away, rendered with blur and read noise, then decoded by DecodeStructuredLight).
#include "calibration/board_projector.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "base/timing.h"
#include "datasets_synthetic/board_structured_light.h"
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

// The board at `poses` rendered under the structured-light sequence and decoded.
std::vector<BoardPoseCapture> Captures(const BoardRig& rig,
                                       const std::vector<Eigen::Isometry3d>& poses,
                                       const BoardRenderOptions& render) {
  StructuredLightOptions light;
  light.width = rig.projector.width();
  light.height = rig.projector.height();
  const CaptureSequence sequence = MakeStructuredLightSequence(light);
  std::vector<BoardPoseCapture> captures;
  for (size_t k = 0; k < poses.size(); ++k) {
    BoardRenderOptions options = render;
    options.seed = render.seed + static_cast<uint32_t>(k);
    const std::vector<cv::Mat> images =
        RenderBoardUnderPatterns(rig, Board(), poses[k], sequence, options);
    BoardPoseCapture capture;
    capture.name = "pose" + std::to_string(k);
    capture.white = images[0];  // the sequence starts with white
    const auto start = Clock::now();
    capture.map = DecodeStructuredLight(light, images);
    std::printf("%s: decoded %zu patterns in %.3f s\n", capture.name.c_str(), images.size(),
                SecondsSince(start));
    captures.push_back(std::move(capture));
  }
  return captures;
}

double AngleDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a * b.transpose()).angle() * 180.0 / M_PI;
}

TEST(BoardProjector, RenderedPosesMatchTheRigsTruth) {
  const BoardRig rig = DefaultBoardRig();
  const ChessboardSpec board = Board();
  const std::vector<Eigen::Isometry3d> poses = BoardRigPoses(rig, board, 8, 1.0);
  BoardRenderOptions render;  // blur σ 0.8 px, read noise 0.004 of full scale
  render.supersample = 2;
  const std::vector<BoardPoseCapture> captures = Captures(rig, poses, render);

  BoardProjectorOptions options;
  std::vector<BoardPoseCorners> corners;
  std::vector<double> projector_errors;
  for (size_t v = 0; v < captures.size(); ++v) {
    BoardPoseCorners pose;
    const auto start = Clock::now();
    ASSERT_TRUE(LocateBoardCorners(options, board, captures[v], &pose)) << captures[v].name;
    std::printf("%s: corners located in %.3f s\n", captures[v].name.c_str(), SecondsSince(start));
    // The homography's projector corner against the true corner's projector pixel. OpenCV may
    // number the grid from either end: the true corner is the one nearest the detected pixel.
    for (int k = 0; k < board.CornerCount(); ++k) {
      if (!pose.projector_found[k]) continue;
      double nearest = 1e9;
      Vec2 truth = Vec2::Zero();
      for (int j = 0; j < board.CornerCount(); ++j) {
        const Vec3 corner_in_cam = poses[v] * board.Corner(j);
        Vec2 camera_pixel, projector_pixel;
        ASSERT_TRUE(rig.camera.ProjectFromProj(corner_in_cam, &camera_pixel));
        ASSERT_TRUE(rig.projector.ProjectFromProj(rig.projector_from_camera * corner_in_cam,
                                                  &projector_pixel));
        if ((camera_pixel - pose.camera[k]).norm() < nearest) {
          nearest = (camera_pixel - pose.camera[k]).norm();
          truth = projector_pixel;
        }
      }
      EXPECT_LT(nearest, 0.5) << captures[v].name << " camera corner " << k;
      projector_errors.push_back((pose.projector[k] - truth).norm());
    }
    corners.push_back(pose);
  }
  ASSERT_GT(projector_errors.size(), 0.9 * corners.size() * board.CornerCount());
  std::sort(projector_errors.begin(), projector_errors.end());
  const double median = projector_errors[projector_errors.size() / 2];
  std::printf("projector corners: %zu, median error %.4f px, 90th percentile %.4f px\n",
              projector_errors.size(), median,
              projector_errors[projector_errors.size() * 9 / 10]);
  EXPECT_LT(median, 0.15);

  BoardProjectorCalibration calibration;
  BoardProjectorSummary summary;
  ASSERT_TRUE(CalibrateBoardProjector(options, board, corners, rig.camera.width(),
                                      rig.camera.height(), rig.projector.width(),
                                      rig.projector.height(), &calibration, &summary))
      << summary.BriefReport();
  std::printf("%s\n", summary.BriefReport().c_str());
  const auto check_lens = [](const char* device, const std::vector<double>& estimate,
                             const std::vector<double>& truth) {
    std::printf("%s: fx %.3f (%.1f) fy %.3f (%.1f) cx %.3f (%.1f) cy %.3f (%.1f)\n", device,
                estimate[0], truth[0], estimate[1], truth[1], estimate[2], truth[2], estimate[3],
                truth[3]);
    EXPECT_LT(std::abs(estimate[0] / truth[0] - 1.0), 0.002) << device;
    EXPECT_LT(std::abs(estimate[1] / truth[1] - 1.0), 0.002) << device;
    EXPECT_LT(std::abs(estimate[2] - truth[2]), 1.0) << device;
    EXPECT_LT(std::abs(estimate[3] - truth[3]), 1.0) << device;
  };
  check_lens("camera", calibration.camera_intrinsics, rig.camera.intrinsics());
  check_lens("projector", calibration.projector_intrinsics, rig.projector.intrinsics());
  const double translation_mm = 1000.0 * (calibration.projector_from_camera.translation() -
                                          rig.projector_from_camera.translation())
                                             .norm();
  const double rotation_deg =
      AngleDeg(calibration.projector_from_camera.linear(), rig.projector_from_camera.linear());
  std::printf("projector_from_camera: translation error %.3f mm, rotation error %.4f°\n",
              translation_mm, rotation_deg);
  EXPECT_LT(translation_mm, 1.0);
  EXPECT_LT(rotation_deg, 0.02);
  ASSERT_EQ(summary.camera_residuals.size(), poses.size());
  ASSERT_EQ(summary.projector_residuals[0].size(), static_cast<size_t>(board.CornerCount()));

  // Both uncertainty maps exist; the projector's, from fewer and noisier corners seen through
  // a longer lens, is larger than the camera's at the image centre.
  ProjectionUncertaintyMap camera_map, projector_map;
  std::string why;
  ASSERT_TRUE(BoardProjectorUncertainty(calibration, &camera_map, &projector_map, &why)) << why;
  std::printf("camera %s\nprojector %s\n", camera_map.BriefReport().c_str(),
              projector_map.BriefReport().c_str());
  EXPECT_GT(camera_map.centre, 0.0);
  EXPECT_GT(projector_map.centre, 0.0);
  EXPECT_LT(camera_map.centre, 1.0);
  EXPECT_LT(projector_map.centre, 1.0);

  // Both models written and parsed back by libmrcal, each with the solve's inputs.
  const testing::TempDir dir;
  const CameraModel projector_model = calibration.ProjectorModelOut();
  EXPECT_EQ(projector_model.icam_intrinsics, 1);
  EXPECT_FALSE(projector_model.optimization_inputs.empty());
  WriteCameraModelFile(dir.path() / "projector.cameramodel", projector_model, "test");
  const CameraModel back = ReadCameraModelFile(dir.path() / "projector.cameramodel");
  EXPECT_NEAR(back.intrinsics[0], calibration.projector_intrinsics[0], 1e-9);
  EXPECT_TRUE(back.cam_from_ref.isApprox(calibration.projector_from_camera, 1e-12));
}

// Corners projected exactly from the truth (no render): the refusals.
std::vector<BoardPoseCorners> ExactCorners(const BoardRig& rig,
                                           const std::vector<Eigen::Isometry3d>& poses) {
  const ChessboardSpec board = Board();
  std::vector<BoardPoseCorners> out;
  for (const Eigen::Isometry3d& cam_from_board : poses) {
    BoardPoseCorners pose;
    pose.name = "pose" + std::to_string(out.size());
    for (int k = 0; k < board.CornerCount(); ++k) {
      const Vec3 corner_in_cam = cam_from_board * board.Corner(k);
      Vec2 camera_pixel, projector_pixel;
      rig.camera.ProjectFromProj(corner_in_cam, &camera_pixel);
      rig.projector.ProjectFromProj(rig.projector_from_camera * corner_in_cam, &projector_pixel);
      pose.camera.push_back(camera_pixel);
      pose.projector.push_back(projector_pixel);
      pose.projector_found.push_back(true);
      pose.window_pixels.push_back(100);
    }
    out.push_back(pose);
  }
  return out;
}

TEST(BoardProjector, OnePoseAndParallelPosesAreRefused) {
  const BoardRig rig = DefaultBoardRig();
  const ChessboardSpec board = Board();
  std::vector<Eigen::Isometry3d> poses = BoardRigPoses(rig, board, 1, 1.0);
  BoardProjectorCalibration calibration;
  BoardProjectorSummary summary;
  EXPECT_FALSE(CalibrateBoardProjector({}, board, ExactCorners(rig, poses), 1280, 800, 1024, 768,
                                       &calibration, &summary));
  EXPECT_EQ(summary.termination, BoardProjectorSummary::kTooFewPoses);
  EXPECT_NE(summary.message.find("1 board pose,"), std::string::npos) << summary.message;

  // Five poses, all with the first pose's orientation, moved about.
  for (int k = 1; k < 5; ++k) {
    Eigen::Isometry3d moved = poses[0];
    moved.translation() += Vec3(0.02 * (k % 2 ? 1 : -1), 0.015 * (k - 2), 0.05 * k);
    poses.push_back(moved);
  }
  EXPECT_FALSE(CalibrateBoardProjector({}, board, ExactCorners(rig, poses), 1280, 800, 1024, 768,
                                       &calibration, &summary));
  EXPECT_EQ(summary.termination, BoardProjectorSummary::kParallelPoses) << summary.BriefReport();
  EXPECT_NE(summary.message.find("parallel"), std::string::npos);
  EXPECT_EQ(summary.message.find('\n'), std::string::npos);

  // The same five positions with the tilts of BoardRigPoses converge on exact corners.
  EXPECT_TRUE(CalibrateBoardProjector({}, board, ExactCorners(rig, BoardRigPoses(rig, board, 5, 1.0)),
                                      1280, 800, 1024, 768, &calibration, &summary))
      << summary.BriefReport();
}

TEST(BoardProjector, OptionsAreChecked) {
  std::string why;
  BoardProjectorOptions options;
  EXPECT_TRUE(options.Check(&why));
  options.lens_model = "LENSMODEL_PINHOLE";
  EXPECT_FALSE(options.Check(&why));
  options = {};
  options.homography_half_window = 2;
  EXPECT_FALSE(options.Check(&why));
  options = {};
  options.min_poses = 1;
  EXPECT_FALSE(options.Check(&why));
  options = {};
  options.min_tilt_spread_deg = 95;
  EXPECT_FALSE(options.Check(&why));
}

}  // namespace
}  // namespace procam
