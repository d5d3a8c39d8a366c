#pragma once
// A projector calibrated with a printed chessboard and structured light, as a camera is (Moreno &
// Taubin, "Simple, accurate, and robust projector-camera calibration", 3DIMPVT 2012).
//
// For every pose of the board in front of the rig the camera photographs the board lit white
// (its corners, DetectChessboard) and under a structured-light sequence (a decoded map: the
// projector column and row each camera pixel sees, calibration/structured_light.h). Around each
// corner the board is a plane, so camera and projector pixels are related there by a homography;
// it is fitted to the decoded pixels in a window around the corner (least squares with the
// decoded pixels that disagree with it rejected and the fit repeated, Moreno & Taubin §3.2) and
// carries the camera corner into the projector: the corner "seen" by the projector. Then the
// camera and the projector are two cameras observing the same board poses, one mrcal solve
// (mrcal_optimize): camera 0 at the reference frame, the projector camera 1 with extrinsics
// (rt_cam_ref = projector_from_camera), the board poses mrcal's frames, both lenses the same
// mrcal lens model, outliers rejected by mrcal. Each lens gets mrcal's projection uncertainty,
// and each .cameramodel carries the solve's optimization inputs, so mrcal's own tools
// (mrcal-show-projection-uncertainty) read either.
//
// Pixels as in base/camera_model.h (centre of the top-left pixel at (0, 0)), in both devices;
// the board frame as in camera_calibration.h (origin at the first inner corner, z into the board);
// `cam_from_board` maps board points into the camera frame, `projector_from_camera` camera points
// into the projector's (x right, y down, z out of the lens, metres).

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "base/camera_model.h"
#include "calibration/camera_calibration.h"
#include "calibration/projection_uncertainty.h"
#include "calibration/structured_light.h"

namespace procam {

struct BoardProjectorOptions {
  // The mrcal lens model of both the camera and the projector (libmrcal solves cameras of one
  // model together): LENSMODEL_OPENCV4, LENSMODEL_OPENCV5 or LENSMODEL_OPENCV8.
  std::string lens_model = "LENSMODEL_OPENCV4";
  // Half the side of the window around a corner whose decoded pixels fit its local homography,
  // camera pixels, [3, 200]. Moreno & Taubin use 47 × 47 pixels; it must hold enough decoded
  // pixels and stay within a plane (the board).
  int homography_half_window = 15;
  // Fewest decoded pixels in a corner's window for a homography, [8, ∞). A corner with fewer is
  // not observed by the projector (weight −1 in mrcal's pool).
  int min_window_pixels = 40;
  // A decoded pixel farther than this from the homography's projector pixel is rejected and the
  // homography refitted without it, projector pixels, > 0.
  double homography_reject_px = 1.0;
  bool reject_outliers = true;  // mrcal's outlier rejection of corners
  bool regularization = true;   // mrcal's light regularisation of distortion and the centre
  // Fewest board poses, ≥ 2 (and two differently tilted ones at least: see min_tilt_spread_deg).
  int min_poses = 3;
  // The board's normals in the camera frame must spread by at least this angle, degrees, [0, 90):
  // poses all parallel to one another leave the focal length and the distance unseparated
  // (Zhang 2000, §3.3).
  double min_tilt_spread_deg = 5.0;
  bool verbose = false;  // mrcal prints its solver's progress to stderr
  bool Check(std::string* why) const;
};

// One pose of the board: what the camera saw.
struct BoardPoseCapture {
  std::string name;        // for reports (a session's directory)
  cv::Mat white;           // the camera's photo under the projector's full white, any depth
  StructuredLightMap map;  // the decoded structured light, camera-sized
};

// The corners of one pose in both devices.
struct BoardPoseCorners {
  std::string name;
  std::vector<Vec2> camera;     // board.CornerCount(), row-major (ChessboardSpec::Corner)
  std::vector<Vec2> projector;  // the same corners in projector pixels
  std::vector<bool> projector_found;  // false where the window held too few decoded pixels
  std::vector<int> window_pixels;     // decoded pixels each corner's homography kept
};

// The camera's corners of `capture` (DetectChessboard on its white photo; false when the board is
// not found) and, per corner, its projector pixel from the local homography.
bool LocateBoardCorners(const BoardProjectorOptions& options, const ChessboardSpec& board,
                        const BoardPoseCapture& capture, BoardPoseCorners* corners);

// The fitted rig.
struct BoardProjectorCalibration {
  std::string lens_model;
  std::vector<double> camera_intrinsics, projector_intrinsics;  // mrcal order
  int camera_width = 0, camera_height = 0, projector_width = 0, projector_height = 0;
  Eigen::Isometry3d projector_from_camera = Eigen::Isometry3d::Identity();
  std::vector<Eigen::Isometry3d> cam_from_board;  // per pose used
  ChessboardSpec board;
  // mrcal's pool after the solve: per pose the camera's corners then the projector's, (x, y,
  // weight; −1 an outlier or a corner the projector did not see).
  std::vector<Vec3> pool;
  bool regularization = true, reject_outliers = true;
  // The .cameramodel files: the camera at the reference (extrinsics zero), the projector with
  // cam_from_ref = projector_from_camera; both with the solve's optimization inputs
  // (icam_intrinsics 0 and 1).
  CameraModel CameraModelOut() const;
  CameraModel ProjectorModelOut() const;
};

struct BoardProjectorSummary {
  enum Termination {
    kConverged,     // mrcal_optimize returned a finite RMS; the values below are its optimum
    kTooFewPoses,   // fewer than options.min_poses poses with a detected board
    kParallelPoses, // every pair of board normals within options.min_tilt_spread_deg
    kSeedFailed,    // OpenCV's seed of either lens failed or gave a non-finite error
    kSolverFailed,  // mrcal_optimize failed (negative or non-finite RMS, non-finite values)
  };
  Termination termination = kSolverFailed;
  int poses = 0;
  int camera_corners = 0, projector_corners = 0;    // observations given to mrcal
  int camera_outliers = 0, projector_outliers = 0;  // mrcal's (and unseen projector corners)
  double tilt_spread_deg = 0.0;  // largest angle between two poses' board normals
  // RMS over inlier corners of |q_observed − q_model| / √2 (per coordinate), px.
  double camera_rms = 0.0, projector_rms = 0.0;
  double camera_max_norm = 0.0, projector_max_norm = 0.0;  // largest inlier residual, px
  std::vector<double> pose_camera_rms, pose_projector_rms;  // per pose, per coordinate, px
  // Per pose, per corner (row-major): the residual vector q_observed − q_model, px; NaN for a
  // corner the projector did not see. Outliers keep their residual, flagged by pool weight < 0.
  std::vector<std::vector<Vec2>> camera_residuals, projector_residuals;
  double time_s = 0.0;
  std::string message;  // one line: why it stopped, when it did not converge
  std::string BriefReport() const;
};

// Calibrates the camera and the projector (`projector_width` × `projector_height`) together
// from per-pose corners (LocateBoardCorners). Options must pass Check() (std::invalid_argument
// otherwise). True when summary->termination is kConverged.
bool CalibrateBoardProjector(const BoardProjectorOptions& options, const ChessboardSpec& board,
                             const std::vector<BoardPoseCorners>& poses, int camera_width,
                             int camera_height, int projector_width, int projector_height,
                             BoardProjectorCalibration* calibration,
                             BoardProjectorSummary* summary);

// mrcal's projection uncertainty at infinity (projection_uncertainty.h's definition: the
// worst-direction 1σ, the point riding with the boards' mean, corner noise σ from the inlier
// residuals of both devices) over the camera's and the projector's image. False with `why`
// when JᵀJ is singular.
bool BoardProjectorUncertainty(const BoardProjectorCalibration& calibration,
                               ProjectionUncertaintyMap* camera_map,
                               ProjectionUncertaintyMap* projector_map, std::string* why);

}  // namespace procam
