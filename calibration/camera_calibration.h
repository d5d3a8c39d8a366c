#pragma once
// Camera intrinsics from views of a planar chessboard (issue 7, "Geometry"): OpenCV finds the
// corners (findChessboardCorners + cornerSubPix) and seeds the lens (calibrateCamera); mrcal's
// optimiser (libmrcal's mrcal_optimize) refines intrinsics and board poses together, rejects
// outliers, and the result is written as an mrcal .cameramodel.
//
// Conventions (as in projection/projector.h): pixel coordinates (x right, y down) with the CENTRE
// of the top-left pixel at (0, 0) — OpenCV's and mrcal's convention; intrinsics in mrcal's
// order (fx, fy, cx, cy, then OpenCV's distortion k1, k2, p1, p2[, k3[, k4, k5, k6]]). The board
// frame has its origin at the first inner corner, x along a row of corners, y down the columns,
// z into the board; `cam_from_board` maps board points into the camera frame (x right, y down,
// z forward, metres). mrcal's rt_cam_ref / rt_ref_frame appear only in camera_calibration.cc.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "base/camera_model.h"
#include "geometry/scene.h"

namespace procam {

class OptionTable;

// A planar chessboard: its inner-corner grid and square size.
struct ChessboardSpec {
  int corners_x = 9;          // inner corners along a row (OpenCV's pattern width), [2, 100]
  int corners_y = 6;          // inner corners along a column (pattern height), [2, 100]
  double square_size = 0.03;  // side of one square, metres, > 0
  // Declares --corners COLUMNSxROWS and --square (metres) in `table`, bound to these fields;
  // `what` begins their help (e.g. "scanning: the floor chessboard's").
  void Declare(OptionTable* table, const std::string& what = "the chessboard's");
  bool Check(std::string* why) const;
  int CornerCount() const { return corners_x * corners_y; }
  // Corner k (row-major: k = row · corners_x + column) in the board frame, metres.
  Vec3 Corner(int k) const;
};

// Finds the inner corners of `board` in an 8- or 16-bit grey or colour image; false when the
// whole grid is not found. Corners come row-major as in ChessboardSpec::Corner (OpenCV may
// start at either end of the grid, i.e. the board turned by 180°, which is just another pose).
bool DetectChessboard(const cv::Mat& image, const ChessboardSpec& board,
                      std::vector<Vec2>* corners);
// An 8- or 16-bit grey or colour image as the 8-bit grey image the corner detectors take
// (16-bit stretched over its own range).
cv::Mat ChessboardGrey(const cv::Mat& image);

// The corners seen in one image.
struct ChessboardView {
  std::string name;          // where the view came from (a file name), for reports
  std::vector<Vec2> corners;  // board.CornerCount() pixels, row-major
};

struct CameraCalibrationOptions {
  // mrcal lens model: LENSMODEL_OPENCV4 (k1, k2, p1, p2), LENSMODEL_OPENCV5 (+ k3) or
  // LENSMODEL_OPENCV8 (rational k1..k6, p1, p2).
  std::string lens_model = "LENSMODEL_OPENCV4";
  bool reject_outliers = true;  // mrcal's outlier rejection (corners far out in the residual
                                // distribution are given weight −1 and refitted without)
  bool regularization = true;   // mrcal's light regularisation of distortion and the centre
  int min_views = 3;            // fewest views with a detected board, ≥ 3
  bool verbose = false;         // mrcal prints its solver's progress to stderr
  // Declares --lens-model and --no-outlier-rejection in `table`, bound to these fields.
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
};

// The chessboard solve as mrcal_optimize left it, beyond the lens and the board poses: what
// re-evaluating the solve needs (its projection uncertainty, calibration/projection_uncertainty.h,
// and the optimization inputs written for mrcal's own tools).
struct ChessboardSolve {
  ChessboardSpec board;
  // Every view's corners, view after view, row-major within a view: the observed pixel (x, y)
  // and mrcal's weight z (1; −1 marks a corner mrcal rejected as an outlier). mrcal's pool.
  std::vector<Vec3> corners;
  bool regularization = true;    // CameraCalibrationOptions::regularization of the solve
  bool reject_outliers = true;   // CameraCalibrationOptions::reject_outliers of the solve
};

// A calibrated camera: the lens (mrcal model name and intrinsics), image size, and the pose of
// the board in every view that was used (same order as the views given).
struct CameraCalibration {
  std::string lens_model;
  std::vector<double> intrinsics;  // mrcal order, pixels (distortion unitless)
  int width = 0, height = 0;
  std::vector<Eigen::Isometry3d> cam_from_board;
  ChessboardSolve solve;
  // As a .cameramodel: the camera is the reference frame (extrinsics zero); with the solve's
  // optimization inputs (CameraModel::optimization_inputs) when `solve` has corners.
  CameraModel Model() const;
};

struct CameraCalibrationSummary {
  enum Termination {
    kConverged,      // mrcal_optimize returned a finite RMS; the values below are its optimum
    kTooFewViews,    // fewer than options.min_views views with a complete board
    kSeedFailed,     // cv::calibrateCamera threw or returned a non-finite error
    kSolverFailed,   // mrcal_optimize failed (negative or non-finite RMS)
  };
  Termination termination = kSolverFailed;
  int views = 0;             // views used
  int corners = 0;           // corner observations used (views × corners per board)
  int outliers = 0;          // corners mrcal rejected as outliers
  double seed_rms = 0.0;     // OpenCV's RMS reprojection error of the seed, px
  double rms = 0.0;          // RMS over inlier corners of |q_observed − q_model| / √2, px
                             // (per coordinate, so it equals σ for corner noise N(0, σ²) per axis)
  double rms_norm = 0.0;     // RMS of |q_observed − q_model| over inliers, px
  double median_norm = 0.0;  // median of |q_observed − q_model| over inliers, px
  double max_norm = 0.0;     // largest inlier residual norm, px
  std::vector<double> view_rms;  // per view, per coordinate, inliers only, px
  double time_s = 0.0;
  std::string message;
  std::string BriefReport() const;
};

// Calibrates one camera of `width` × `height` pixels from chessboard views (views whose corner
// count is wrong are refused by std::invalid_argument; the options must pass Check()). Returns
// true when summary->termination is kConverged.
bool CalibrateCamera(const CameraCalibrationOptions& options, const ChessboardSpec& board,
                     const std::vector<ChessboardView>& views, int width, int height,
                     CameraCalibration* calibration, CameraCalibrationSummary* summary);

// Writes the calibration's .cameramodel (Model()) atomically after libmrcal has parsed it
// back, every number with 17 significant digits. Throws IoError.
void WriteCalibrationModel(const std::filesystem::path& path, const CameraCalibration& calibration);

}  // namespace procam
