#pragma once
// The chessboard solve in libmrcal's terms, shared by the solve (camera_calibration.cc) and what
// evaluates it again (projection_uncertainty.cc), so that both describe one problem to libmrcal:
// one camera at the reference frame (no extrinsics), the board poses as mrcal's frames
// (rt_ref_frame = rt_cam_board), one board observation per view. The board-and-structured-light
// solve (board_projector.cc) adds a second camera, the projector, with extrinsics: the same arrays
// with cameras = 2. Internal to calibration/: include it from .cc files only (it includes mrcal.h).

#include <string>
#include <vector>

#include "calibration/camera_calibration.h"

extern "C" {
#include <mrcal/mrcal.h>
}

namespace procam {

// What mrcal optimises: the whole lens and the board poses. do_optimize_extrinsics is true as
// mrcal's own tools set it for a one-camera solve (there are no extrinsics to optimise, so it
// changes nothing here); mrcal 2.2's projection_uncertainty refuses inputs without it.
mrcal_problem_selections_t ChessboardSelections(bool regularization, bool reject_outliers);

// mrcal_optimize's range limits of discrete points (the solve has none).
constexpr mrcal_problem_constants_t kChessboardConstants{0.0, 1e6};

// A calibration's solve as libmrcal's arrays, at the optimum the calibration holds.
struct MrcalChessboardProblem {
  mrcal_lensmodel_t lens;
  int cameras = 1;                   // cameras with intrinsics (all share `lens`)
  std::vector<double> intrinsics;    // cameras × the lens's parameter count
  std::vector<mrcal_pose_t> extrinsics;  // rt_cam_ref of cameras 1.. (camera 0 is the reference)
  std::vector<mrcal_pose_t> frames;  // rt_ref_frame per view
  std::vector<mrcal_observation_board_t> observations;
  std::vector<mrcal_point3_t> pool;  // x, y, weight per corner, observations × corners_y × corners_x
  mrcal_problem_selections_t selections;
  std::vector<int> imager_sizes;     // width, height per camera
  double spacing;  // square size, metres
  int corners_x, corners_y;

  int Frames() const { return static_cast<int>(frames.size()); }
  int Observations() const { return static_cast<int>(observations.size()); }
  int Extrinsics() const { return static_cast<int>(extrinsics.size()); }
  // mrcal's sizes and offsets of this problem's state vector b and measurement vector x.
  int StateCount() const;
  int MeasurementCount() const;
  int BoardMeasurementCount() const;  // the leading x entries: 2 per corner
  int StateIndexIntrinsics() const;
  int StateIndexFrames() const;
  int JacobianNonZeros() const;
  // Camera `camera`'s offsets in the state vector (the intrinsics; the extrinsics of cameras ≥ 1).
  int StateIndexIntrinsics(int camera) const;
  int StateIndexExtrinsics(int camera) const;
  // mrcal_optimizer_callback at the arrays' values: the measurements x and Jᵀ (state × measurements,
  // compressed columns: column_starts, rows, values) in mrcal's packed state. False when libmrcal
  // refuses the problem.
  bool Evaluate(std::vector<double>* x, std::vector<int>* column_starts, std::vector<int>* rows,
                std::vector<double>* values) const;
};

// Throws std::invalid_argument when the calibration has no solve (solve.corners does not match
// the board poses) or an unknown lens model.
MrcalChessboardProblem ToMrcal(const CameraCalibration& calibration);

// mrcal.optimize()'s keyword arguments for the solve of `calibration` at its optimum, in the
// encoding of a .cameramodel's `optimization_inputs` (mrcal 2.2, cameramodel.py
// _serialize_optimization_inputs): a NumPy .npz archive of one .npy per argument (None stored
// as the empty string), written here uncompressed, in base-85 text (Python's b85encode alphabet).
std::string MrcalOptimizationInputs(const CameraCalibration& calibration);
// The same for any problem in libmrcal's arrays, its lens named `lens_model`.
std::string MrcalOptimizationInputs(const MrcalChessboardProblem& problem,
                                    const std::string& lens_model);

}  // namespace procam
