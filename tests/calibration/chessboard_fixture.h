#pragma once
// The chessboard calibration problem both camera-calibration tests solve: a true OpenCV4 lens of
// 640×480 pixels, a 9×6 board of 4 cm squares, board poses 0.6–1.0 m away tilted up to ±35° and
// spread over the image (corners reach the image edges, where distortion is largest), and their
// corners projected exactly through the true lens plus Gaussian noise.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "base/camera_model.h"
#include "calibration/camera_calibration.h"

namespace procam::testing {

constexpr int kWidth = 640, kHeight = 480;
inline const std::vector<double> kTrueIntrinsics = {520.0, 515.0, 322.3, 241.7,
                                                    -0.12, 0.05,  0.001, -0.0005};

inline ChessboardSpec Board() {
  ChessboardSpec board;
  board.corners_x = 9;
  board.corners_y = 6;
  board.square_size = 0.04;
  return board;
}

// The first `count` (at most 12) board poses, cam_from_board.
inline std::vector<Eigen::Isometry3d> BoardPoses(const ChessboardSpec& board, int count) {
  struct Placement {
    double x, y, z, tilt_x_deg, tilt_y_deg, roll_deg;
  };
  const Placement placements[] = {
      {0.00, 0.00, 0.80, 0, 0, 0},       {-0.20, -0.12, 0.85, 20, -25, 5},
      {0.20, -0.12, 0.85, -20, 25, -5},  {-0.20, 0.14, 0.90, -25, -20, 10},
      {0.20, 0.14, 0.90, 25, 20, -10},   {0.00, 0.00, 0.60, 35, 0, 15},
      {0.00, 0.00, 0.65, 0, 35, -15},    {-0.10, 0.05, 1.00, -30, 10, 30},
      {0.12, -0.05, 0.95, 10, -30, -25}, {0.00, 0.10, 0.70, -15, -15, 90},
      {-0.15, 0.00, 0.75, 10, 30, 45},   {0.15, 0.05, 0.80, -10, -30, -45},
  };
  EXPECT_LE(count, 12);
  const Vec3 board_centre((board.corners_x - 1) * board.square_size / 2,
                          (board.corners_y - 1) * board.square_size / 2, 0.0);
  std::vector<Eigen::Isometry3d> poses;
  for (int k = 0; k < count && k < 12; ++k) {
    const Placement& p = placements[k];
    const double deg = M_PI / 180.0;
    Eigen::Isometry3d cam_from_board = Eigen::Isometry3d::Identity();
    cam_from_board.linear() = (Eigen::AngleAxisd(p.tilt_x_deg * deg, Vec3::UnitX()) *
                               Eigen::AngleAxisd(p.tilt_y_deg * deg, Vec3::UnitY()) *
                               Eigen::AngleAxisd(p.roll_deg * deg, Vec3::UnitZ()))
                                  .toRotationMatrix();
    cam_from_board.translation() = Vec3(p.x, p.y, p.z) - cam_from_board.linear() * board_centre;
    poses.push_back(cam_from_board);
  }
  return poses;
}

// The corners of the first `poses` board poses through the true lens plus N(0, sigma²) per
// coordinate; every corner must lie in front of the camera and inside the image.
inline std::vector<ChessboardView> NoisyCorners(double sigma, uint32_t seed, int poses) {
  const ChessboardSpec board = Board();
  const LensModel lens("LENSMODEL_OPENCV4", kTrueIntrinsics);
  std::mt19937 random(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  std::vector<ChessboardView> views;
  for (const Eigen::Isometry3d& cam_from_board : BoardPoses(board, poses)) {
    ChessboardView view;
    view.name = "pose" + std::to_string(views.size());
    for (int k = 0; k < board.CornerCount(); ++k) {
      const Vec3 corner_in_cam = cam_from_board * board.Corner(k);
      EXPECT_GT(corner_in_cam.z(), 0.0);
      const Vec2 pixel = lens.Project(corner_in_cam);
      EXPECT_TRUE(pixel.x() > 0 && pixel.x() < kWidth - 1 && pixel.y() > 0 &&
                  pixel.y() < kHeight - 1)
          << view.name << " corner " << k << " at " << pixel.transpose();
      view.corners.push_back(pixel + Vec2(noise(random), noise(random)));
    }
    views.push_back(view);
  }
  return views;
}

}  // namespace procam::testing
