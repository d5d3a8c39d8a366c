#pragma once
// The camera-response stage of calibration: a camera's inverse response (its linearity) from one
// still pattern of a capture session photographed at several exposures (camera_response.h),
// written as RIG_DIR/camera_response.json and recorded in RIG_DIR/rig.json ("camera"."response").
// What `procam calibrate response` runs.

#include <filesystem>

#include "base/option_table.h"
#include "base/progress.h"
#include "calibration/camera_response.h"

namespace procam {

struct ResponseStageOptions {
  std::filesystem::path session;  // a capture session bracketing exposures (at least 3)
  std::filesystem::path out;      // the rig directory (created)
  int pattern = -1;               // the pattern's index, >= -1; -1: the brightest captured
  CameraResponseOptions options;  // samples, lambda
  ProgressCallback progress;      // the pattern used, the fitted gammas, the file written

  // Declares the session (positional), --out, --pattern, --samples and --lambda in `table`,
  // bound to these fields (base/option_table.h).
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
};

// Fits the response and writes it. Throws IoError naming the session's manifest (no such
// pattern captured, not an 8-bit colour camera, fewer than 3 exposures), std::invalid_argument
// for bad options, std::runtime_error when the fit fails; nothing is written then.
CameraResponse RunResponseStage(const ResponseStageOptions& options);

}  // namespace procam
