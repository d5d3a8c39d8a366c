#pragma once
// The metric scale of a scan from one photo: the chessboard lying flat on the floor, photographed
// by the camera from the pose it has during the structured light. The board's corners and its
// square size give the board's pose in the camera frame (PnP on the corners undistorted through
// the camera's lens), so the floor plane in the camera frame in metres; the camera's height above
// the floor is that plane's distance from the camera's centre plus the board's thickness. It is
// the one length the self-calibration (self_calibration.h) needs: everything else the structured
// light gives only up to scale.

#include <Eigen/Geometry>
#include <filesystem>
#include <string>

#include "base/camera_model.h"
#include "calibration/camera_calibration.h"

namespace procam {

struct FloorChessboard {
  double camera_height = 0.0;  // camera centre to the floor plane, metres
  Eigen::Isometry3d cam_from_board = Eigen::Isometry3d::Identity();
  Vec3 floor_normal_in_cam = Vec3::Zero();  // unit, pointing from the floor towards the camera
  double rms_px = 0.0;    // corners' reprojection RMS (per coordinate) through the lens, pixels
  double tilt_deg = 0.0;  // angle between the camera's optical axis and the floor plane
  std::string BriefReport() const;
};

// Finds `board` in `photo` (an image file) and computes the camera's height above the plane the
// board lies on. `camera`: the calibrated camera (its lens; its pose is not used) of the photo's
// size. `board_thickness`: metres from the floor to the board's printed face, ≥ 0. Throws IoError
// naming the photo: unreadable, of another size than the camera model, the board not found, or a
// pose that makes no sense (the camera below the board or the fit's RMS above 2 px).
FloorChessboard MeasureFloorChessboard(const CameraModel& camera, const ChessboardSpec& board,
                                       const std::filesystem::path& photo,
                                       double board_thickness = 0.0);

}  // namespace procam
