#include "datasets_synthetic/chessboard_views.h"

#include <cmath>
#include <random>

#include <opencv2/imgproc.hpp>

namespace procam {

std::vector<Eigen::Isometry3d> ChessboardPoses(const CameraGeometry& camera,
                                               const ChessboardSpec& board) {
  // Offsets in units of the distance; tilts and roll in degrees.
  struct Placement {
    double x, y, z, tilt_x_deg, tilt_y_deg, roll_deg;
  };
  const Placement placements[] = {
      {0.00, 0.00, 1.00, 0, 0, 0},       {-0.25, -0.15, 1.06, 20, -25, 5},
      {0.25, -0.15, 1.06, -20, 25, -5},  {-0.25, 0.17, 1.12, -25, -20, 10},
      {0.25, 0.17, 1.12, 25, 20, -10},   {0.00, 0.00, 0.75, 35, 0, 15},
      {0.00, 0.00, 0.81, 0, 35, -15},    {-0.12, 0.06, 1.25, -30, 10, 30},
      {0.15, -0.06, 1.19, 10, -30, -25}, {0.00, 0.12, 0.88, -15, -15, 90},
  };
  const double board_width = (board.corners_x + 1) * board.square_size;
  const double distance = camera.intrinsics()[0] * board_width / (0.45 * camera.width());
  const Vec3 board_centre((board.corners_x - 1) * board.square_size / 2,
                          (board.corners_y - 1) * board.square_size / 2, 0.0);
  // The optical centre's direction, so the poses gather around the image centre.
  const double cx = camera.intrinsics()[2], cy = camera.intrinsics()[3];
  const Vec3 centre((camera.width() / 2.0 - cx) / camera.intrinsics()[0],
                    (camera.height() / 2.0 - cy) / camera.intrinsics()[1], 0.0);
  std::vector<Eigen::Isometry3d> poses;
  const double deg = M_PI / 180.0;
  for (const Placement& p : placements) {
    Eigen::Isometry3d cam_from_board = Eigen::Isometry3d::Identity();
    cam_from_board.linear() = (Eigen::AngleAxisd(p.tilt_x_deg * deg, Vec3::UnitX()) *
                               Eigen::AngleAxisd(p.tilt_y_deg * deg, Vec3::UnitY()) *
                               Eigen::AngleAxisd(p.roll_deg * deg, Vec3::UnitZ()))
                                  .toRotationMatrix();
    const Vec3 where = distance * (Vec3(p.x, p.y, p.z) + p.z * centre);
    cam_from_board.translation() = where - cam_from_board.linear() * board_centre;
    poses.push_back(cam_from_board);
  }
  return poses;
}

cv::Mat RenderChessboard(const CameraGeometry& camera, const ChessboardSpec& board,
                         const Eigen::Isometry3d& cam_from_board, double noise_sigma,
                         uint32_t seed, int supersample) {
  // A camera `supersample` times finer with the same lens: focal lengths scale, and the centre
  // moves so that fine pixel centres tile the coarse pixels.
  std::vector<double> fine = camera.intrinsics();
  for (int k = 0; k < 2; ++k) fine[k] *= supersample;
  for (int k = 2; k < 4; ++k) fine[k] = supersample * fine[k] + (supersample - 1) / 2.0;
  const ProjectorGeometry fine_camera(camera.lens_model(), fine, camera.width() * supersample,
                                      camera.height() * supersample,
                                      Eigen::Isometry3d::Identity());
  std::vector<Vec3> rays;
  std::vector<double> densities;
  fine_camera.UnprojectImage(&rays, &densities);

  const Eigen::Isometry3d board_from_cam = cam_from_board.inverse();
  const Vec3 origin = board_from_cam.translation();
  const double s = board.square_size;
  cv::Mat image(fine_camera.height(), fine_camera.width(), CV_32F);
  for (int row = 0; row < image.rows; ++row) {
    for (int col = 0; col < image.cols; ++col) {
      const Vec3 ray = board_from_cam.linear() * rays[row * image.cols + col];
      float value = 0.35f;  // background
      const double t = -origin.z() / ray.z();
      if (t > 0.0) {
        const Vec3 p = origin + t * ray;
        const double u = p.x() / s + 1.0, v = p.y() / s + 1.0;  // squares from the board's edge
        if (u >= -0.7 && u < board.corners_x + 1.7 && v >= -0.7 && v < board.corners_y + 1.7) {
          const bool inside =
              u >= 0 && u < board.corners_x + 1 && v >= 0 && v < board.corners_y + 1;
          const bool dark = inside && ((static_cast<int>(u) + static_cast<int>(v)) % 2 == 0);
          value = dark ? 0.08f : 0.85f;
        }
      }
      image.at<float>(row, col) = value;
    }
  }
  cv::Mat coarse;
  cv::resize(image, coarse, cv::Size(camera.width(), camera.height()), 0, 0, cv::INTER_AREA);
  std::mt19937 random(seed);
  std::normal_distribution<float> noise(0.0f, static_cast<float>(noise_sigma));
  for (float& value : cv::Mat_<float>(coarse)) value += noise(random);
  cv::Mat eight;
  coarse.convertTo(eight, CV_8U, 255.0);
  return eight;
}

}  // namespace procam
