#pragma once
// The camera stage of calibration: camera intrinsics from chessboard photos, written into a rig
// directory (RIG_DIR/camera.cameramodel and the "camera" section of RIG_DIR/result.json;
// docs/calibration.md). What `procam calibrate camera` runs.

#include <filesystem>

#include "base/option_table.h"
#include "base/progress.h"
#include "calibration/camera_calibration.h"
#include "calibration/projection_uncertainty.h"

namespace procam {

struct CameraStageOptions {
  // A capture session (its frames/) or a folder of chessboard photos (png, jpg, tiff, bmp), read
  // in name order.
  std::filesystem::path images;
  std::filesystem::path out;  // the rig directory (created)
  ChessboardSpec board;       // inner corners and square size
  CameraCalibrationOptions options;
  ProgressCallback progress;  // boards found, the calibration's brief report, files written

  // Declares the session (positional), --out, --corners, --square, --lens-model and
  // --no-outlier-rejection in `table`, bound to these fields (base/option_table.h).
  void Declare(OptionTable* table);
  // The declared options, the board and the calibration's options; `*why` names the option.
  bool Check(std::string* why) const;
};

struct CameraStageSummary {
  CameraCalibration calibration;
  CameraCalibrationSummary summary;  // termination, residuals: summary.BriefReport()
  // The projection uncertainty at infinity over the image (result.json's
  // camera.projection_uncertainty); empty grid when it could not be computed, then
  // `uncertainty_error` says why.
  ProjectionUncertaintyMap uncertainty;
  std::string uncertainty_error;
  // The lens's covariance from the chessboard alone (ProjectionUncertainty::
  // IntrinsicsCovariance; result.json's camera.intrinsics_covariance): the prior with which a
  // scan refines the lens (calibration/self_calibration.h). Empty with `uncertainty_error`.
  Eigen::MatrixXd intrinsics_covariance;
};

// Detects the board in every photo, calibrates, and writes the model and the result section.
// Throws IoError naming the image or folder (unreadable, sizes differ, no images),
// std::invalid_argument for bad options, std::runtime_error when the calibration fails.
CameraStageSummary RunCameraStage(const CameraStageOptions& options);

}  // namespace procam
