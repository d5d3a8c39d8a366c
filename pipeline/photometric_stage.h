#pragma once
// The photometric stage of calibration: one projector's black, max, response and colour mixing
// from a photometric capture session (`procam capture --sequence photometric --channels rgb`),
// in camera units, or — with the rig's geometry (the camera registered in the room, the
// projector's model) and a scene — in the scene's units, with the room's per-patch reflectance
// (photometric_transfer.h). Writes RIG_DIR/NAME.photometric.json (photometric.json without a
// projector name), the "photometric" → NAME section of RIG_DIR/result.json and, for a named
// projector, its rig.json entry (and, in scene units, RIG_DIR/reflectance.npy, the projector's
// per-pixel reflectance map NAME.reflectance_map.png (projection/reflectance_map.h) and its
// report page NAME.photometric_report.html). What `procam
// calibrate photometric` runs; docs/calibration.md.

#include <filesystem>
#include <optional>
#include <string>

#include "base/option_table.h"
#include "base/progress.h"
#include "calibration/photometric.h"

namespace procam {

struct PhotometricStageOptions {
  std::filesystem::path session;          // the photometric capture session
  std::filesystem::path out;              // the rig directory (created)
  PhotometricCalibrationOptions options;  // min_contrast, table_size
  double clip = 0.99;     // fraction of the camera's full scale at which a pixel counts as clipped
  std::string projector;  // rig.json projectors[] entry to fill; empty: rig.json untouched
  std::string scene;      // a scene (file or PREFIX:NAME): scene units; needs the rig's geometry
  int patches = 0;        // patch target for the scene (0: the scene's)
  // With a scene, the camera value per unit exitance: a number, "R,G,B", or a simulated
  // camera's URI (its own calibration for the session's exposure and gain).
  std::string camera_scale;
  // Camera black level, DN, in [0, 1e9] (unset: 0, or the simulated camera's).
  std::optional<double> camera_black;
  std::string response = "gamma";  // what rig.json gets: "gamma" or "lut"
  int min_patch_pixels = 4;        // camera pixels a patch needs for its reflectance
  ProgressCallback progress;       // pixels used, the fit's brief report, files written

  // Declares the session (positional), --out, --min-contrast, --table-size, --projector,
  // --scene, --patches, --camera-scale, --camera-black and --response in `table`, bound to these
  // fields (base/option_table.h).
  void Declare(OptionTable* table);
  // Checks every value (the declared ones, clip in (0, 1], min_patch_pixels >= 1, options); why
  // names the option.
  bool Check(std::string* why) const;
};

// Fits and writes. Throws IoError naming the session, rig.json and the key, or the option, before
// anything is written; std::invalid_argument for bad options.
PhotometricModel RunPhotometricStage(const PhotometricStageOptions& options);

}  // namespace procam
