#pragma once
// The board stage of calibration: a camera and a projector calibrated together from a chessboard
// held at several poses, each pose a structured-light capture session (calibration/
// board_projector.h), written into a rig directory: RIG_DIR/camera.cameramodel,
// RIG_DIR/NAME.cameramodel (the projector; its extrinsics projector_from_camera), the section
// "board" → NAME of RIG_DIR/result.json and RIG_DIR/board_report_NAME.html
// (docs/chessboard.md). What `procam calibrate board` runs.

#include <filesystem>
#include <string>
#include <vector>

#include "base/option_table.h"
#include "base/progress.h"
#include "calibration/board_projector.h"

namespace procam {

struct BoardStageOptions {
  // One structured-light capture session per board pose (`procam capture --sequence
  // structured_light`, both axes), the board still while the session ran; at least two.
  std::vector<std::filesystem::path> sessions;
  std::filesystem::path out;            // the rig directory (created)
  std::string projector = "projector";  // the projector's name: NAME.cameramodel; letters,
                                        // digits, '_', '-', '.'
  ChessboardSpec board;                 // inner corners and square size
  BoardProjectorOptions options;
  StructuredLightDecodeOptions decode;
  ProgressCallback progress;  // per pose: corners found; the brief report; files written
  // Declares the sessions (positional), --out, --name, --corners, --square and the board
  // calibration's options (--lens-model, --window, ...) in `table`, bound to these fields.
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
};

struct BoardStageSummary {
  BoardProjectorCalibration calibration;
  BoardProjectorSummary summary;
  std::vector<BoardPoseCorners> corners;  // per pose used
  std::vector<std::string> skipped;       // sessions whose board was not found
  ProjectionUncertaintyMap camera_uncertainty, projector_uncertainty;
  std::string uncertainty_error;  // why the maps are empty, when they are
};

// Reads and decodes every session, calibrates, writes the models, the result section and the
// report. Throws IoError naming the session (not a directory, not a structured-light session,
// incomplete, sizes differ), std::invalid_argument for bad options, std::runtime_error with the
// summary's one line when the calibration does not converge (one pose, parallel poses, ...);
// nothing is written then.
BoardStageSummary RunBoardStage(const BoardStageOptions& options);

}  // namespace procam
