#pragma once
// A whole rig calibrated end to end: the camera, then per projector its captures, then every
// projector and the camera's pose jointly, then the photometry in the scene's units. Each step is
// a stage of its own (camera_stage.h, capture_stage.h, projectors_stage.h, photometric_stage.h)
// writing its part of the rig directory; the progress shows each as the `procam` command line a
// user would type for it:
//
//   1. camera intrinsics: the camera stage on chessboard photos, or a given camera model copied;
//      a simulated camera photographs a simulated chessboard held in front of it;
//   2. per projector: a structured-light and a photometric capture into RIG_DIR/captures/;
//   3. the projectors stage on every structured-light session (joint refinement, registration),
//      or, scanning the room (no room model), the self-calibration and the room built from the
//      scan, written as RIG_DIR/room.json, which the photometry then uses;
//   4. per projector: the photometric stage in the scene's units (per-patch reflectance);
//   5. the projectors' black levels separated from one another (every black field shows all
//      projectors at black).
// What `procam calibrate all` and the demo run.

#include <atomic>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "base/option_table.h"
#include "base/progress.h"
#include "calibration/camera_calibration.h"
#include "capture/display.h"
#include "capture/sequencer.h"

namespace procam {

struct CalibrateAllOptions {
  std::string camera;  // camera URI; a simulated camera's world supplies what a real rig needs
  // The room model (a scene file or PREFIX:NAME); empty: a real camera scans the room, a
  // simulated camera uses its own scene unless `scan`.
  std::string scene;
  // Scan the room instead of registering a model (what a real camera does without `scene`): the
  // metric scale from `floor_chessboard` (a photo of the chessboard, `board`, lying flat on the
  // floor, taken from the camera's pose; a simulated camera takes one itself) or `camera_height`
  // (metres above the floor).
  bool scan = false;
  std::filesystem::path floor_chessboard;
  double camera_height = 0.0;  // 0: unset
  double board_thickness = 0.0;
  std::filesystem::path out;  // the rig directory
  int patches = 0;  // patch target of the reflectance (0: the scene's; simulated: its world's)
  std::filesystem::path chessboard;    // chessboard photos (a folder or a capture session)
  std::filesystem::path camera_model;  // a calibrated camera.cameramodel instead
  ChessboardSpec board;                // of the chessboard photos
  // Real rigs: each projector's display (its monitor, e.g. "glfw:1"), in order, and how to open
  // one; displays are opened once the options have been checked.
  std::vector<std::string> display_names;
  std::function<std::shared_ptr<PatternDisplay>(const std::string& name)> open_display;
  std::vector<std::string> names;  // projector names; empty: the simulated world's, or projectorK
  // Projectors whose lens is held from a .cameramodel (a board calibration's, docs/chessboard.md):
  // name (one of `names`) → file; step 3 solves their pose in the room alone
  // (ProjectorsStageOptions::held_lenses), with a room model or scanning.
  std::map<std::string, std::filesystem::path> held_lenses;
  // The camera's pose guess, "x,y,z,look_x,look_y,look_z" (metres, the scene's frame); empty: a
  // simulated camera's tape-measure guess.
  std::string camera_guess;
  // Camera value per unit exitance (a number or "R,G,B"); empty: a simulated camera's own.
  std::string camera_scale;
  int frames = 4;            // averaged per pattern
  double settle_ms = 150.0;  // wait after each pattern ...
  // ... unless measured (the default): the display-to-camera latency of each projector, measured
  // before its structured light (capture/latency.h), sets the settle time of its captures.
  bool measure_settle = true;
  double grab_timeout_ms = SequencerOptions().grab_timeout_ms;  // per frame, before a retry
  std::vector<double> exposures_us;  // several: bracketed and merged to HDR
  std::vector<int> levels = {0, 32, 64, 96, 128, 160, 192, 224, 255};  // photometric drives
  ProgressCallback progress;  // each step's command line and its report
  // Set (by a signal handler) to stop cleanly: a capture ends after the pattern in hand, a fit
  // or a computation inside a step (form factors) is abandoned, and no further step begins.
  // Null: run to the end.
  const std::atomic<bool>* stop = nullptr;

  // Declares every option above but the callbacks (--camera, --scene, --scan, ..., --levels) in
  // `table`, bound to these fields (base/option_table.h).
  void Declare(OptionTable* table);
  // The declared values and the board; `*why` names the option. What needs the camera (a
  // simulated camera's world) is checked when the run begins.
  bool Check(std::string* why) const;
};

// Runs the five steps. Checks what the later steps need before anything is captured or written.
// Throws IoError naming the option, file or device, std::invalid_argument for bad options.
// Stopped by options.stop, throws Stopped (base/stop.h) saying in which step and what is kept:
// every file written until then is whole (each is written atomically), the captures keep their
// patterns and record the stop, and the same call again resumes (complete captures are kept,
// the fits redone).
void RunCalibrateAll(const CalibrateAllOptions& options);

}  // namespace procam
