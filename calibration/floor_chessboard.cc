#include "calibration/floor_chessboard.h"

#include <fmt/format.h>

#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "base/image_io.h"
#include "base/io.h"

namespace procam {

std::string FloorChessboard::BriefReport() const {
  return fmt::format(
      "floor chessboard: camera {:.4f} m above the floor (board {:.3f} m away, view {:.1f} deg "
      "above the floor plane, reprojection RMS {:.3f} px)",
      camera_height, cam_from_board.translation().norm(), tilt_deg, rms_px);
}

namespace {

// A board on the floor is seen obliquely: far rows of squares a few pixels tall. OpenCV's
// sector-based detector (findChessboardCornersSB, exhaustive) finds such boards where the classic
// one (DetectChessboard) gives up; the classic one is tried when it fails.
bool DetectFloorChessboard(const cv::Mat& image, const ChessboardSpec& board,
                           std::vector<Vec2>* corners) {
  const cv::Mat grey = ChessboardGrey(image);
  std::vector<cv::Point2f> found;
  if (cv::findChessboardCornersSB(grey, cv::Size(board.corners_x, board.corners_y), found,
                                  cv::CALIB_CB_EXHAUSTIVE | cv::CALIB_CB_ACCURACY)) {
    corners->resize(found.size());
    for (size_t k = 0; k < found.size(); ++k) (*corners)[k] = Vec2(found[k].x, found[k].y);
    return true;
  }
  return DetectChessboard(image, board, corners);
}

}  // namespace

FloorChessboard MeasureFloorChessboard(const CameraModel& camera, const ChessboardSpec& board,
                                       const std::filesystem::path& photo,
                                       double board_thickness) {
  const std::string name = photo.string();
  std::string why;
  if (!board.Check(&why)) throw IoError(name + ": " + why);
  if (!(board_thickness >= 0.0) || !std::isfinite(board_thickness))
    throw IoError(name + ": the board's thickness must be a non-negative number of metres");
  const cv::Mat image = ReadImage(photo, cv::IMREAD_UNCHANGED);
  if (image.cols != camera.width || image.rows != camera.height)
    throw IoError(fmt::format("{}: {}x{}, the camera model is {}x{}", name, image.cols, image.rows,
                              camera.width, camera.height));
  std::vector<Vec2> corners;
  if (!DetectFloorChessboard(image, board, &corners))
    throw IoError(fmt::format(
        "{}: no chessboard of {}x{} inner corners found (lay the whole board flat on the floor "
        "in the camera's view; --corners gives its inner corners)",
        name, board.corners_x, board.corners_y));

  // The corners' directions through the lens, as points on the plane z = 1.
  const LensModel lens(camera.lens_model, camera.intrinsics);
  std::vector<Vec3> directions(corners.size());
  if (!lens.Unproject(corners.data(), static_cast<int>(corners.size()), directions.data()))
    throw IoError(name + ": the lens model cannot unproject the board's corners");
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> normalised;
  for (size_t k = 0; k < corners.size(); ++k) {
    const Vec3 corner = board.Corner(static_cast<int>(k));
    object.emplace_back(corner.x(), corner.y(), corner.z());
    if (!(directions[k].z() > 0.0))
      throw IoError(name + ": a board corner lies outside the lens's forward field of view");
    normalised.emplace_back(directions[k].x() / directions[k].z(),
                            directions[k].y() / directions[k].z());
  }
  // IPPE is exact for a plane; the Levenberg-Marquardt refinement polishes it.
  cv::Mat rvec, tvec;
  const cv::Mat identity = cv::Mat::eye(3, 3, CV_64F);
  if (!cv::solvePnP(object, normalised, identity, cv::noArray(), rvec, tvec, false,
                    cv::SOLVEPNP_IPPE))
    throw IoError(name + ": no board pose fits the corners");
  cv::solvePnPRefineLM(object, normalised, identity, cv::noArray(), rvec, tvec);
  cv::Mat rotation;
  cv::Rodrigues(rvec, rotation);
  Eigen::Matrix3d r;
  Eigen::Vector3d t;
  cv::cv2eigen(rotation, r);
  cv::cv2eigen(tvec, t);

  FloorChessboard result;
  result.cam_from_board.linear() = r;
  result.cam_from_board.translation() = t;
  double squares = 0.0;
  for (size_t k = 0; k < corners.size(); ++k) {
    const Vec2 predicted = lens.Project(result.cam_from_board * board.Corner(static_cast<int>(k)));
    squares += (predicted - corners[k]).squaredNorm();
  }
  result.rms_px = std::sqrt(squares / (2.0 * corners.size()));
  // The board plane n·p = n·t in the camera frame; the camera's centre is at its distance |n·t|.
  Vec3 normal = r.col(2);
  double distance = normal.dot(t);
  if (distance > 0.0) {  // orient the normal from the board towards the camera
    normal = -normal;
    distance = -distance;
  }
  result.floor_normal_in_cam = normal;
  result.camera_height = -distance + board_thickness;
  result.tilt_deg = std::asin(std::min(1.0, std::abs(normal.z()))) * 180.0 / M_PI;
  if (!(result.rms_px <= 2.0))
    throw IoError(fmt::format(
        "{}: the board's corners fit no flat board ({:.2f} px RMS; is it lying flat?)", name,
        result.rms_px));
  // The floor is below the camera: its normal towards the camera points along image-up (−y).
  if (!(result.floor_normal_in_cam.y() < 0.0))
    throw IoError(name +
                  ": the board's plane is not below the camera (is the photo upside down, or "
                  "the board on a wall?)");
  return result;
}

}  // namespace procam
