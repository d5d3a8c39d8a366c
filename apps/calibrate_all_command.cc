// procam calibrate all --camera URI --scene SCENE --out RIG_DIR: a whole rig, end to end
// (calibration/calibrate_all_stage.h).
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "apps/stop_signals.h"
#include "base/output_directory.h"
#include "calibration/calibrate_all_stage.h"
#include "calibration/projectors_stage.h"
#include "capture/devices.h"

namespace procam {
namespace {

struct CalibrateAllArguments {
  std::string camera;
  std::string scene;
  std::string out;
  int patches = 0;
  std::string chessboard;    // folder or session of chessboard photos
  std::string camera_model;  // an existing camera.cameramodel instead
  std::string corners = "9x6";
  double square = 0.03;
  std::vector<std::string> displays;  // real rigs: one per projector (glfw:N|NAME)
  std::vector<std::string> names;     // projector names, one per projector
  std::vector<std::string> held_lenses;  // NAME=FILE
  std::string camera_guess;
  std::string camera_scale;
  int frames = 4;
  SettleSetting settle{true, 150.0};  // default: measured
  double timeout_ms = SequencerOptions().grab_timeout_ms;
  std::vector<double> exposures_us;
  std::string levels = "0,32,64,96,128,160,192,224,255";
  bool scan = false;
  std::string floor_chessboard;
  double camera_height = 0.0;
  double board_thickness = 0.0;
};

void CalibrateAll(const CalibrateAllArguments& args) {
  RegisterDeviceBackends();
  CalibrateAllOptions options;
  options.camera = args.camera;
  options.scene = args.scene;
  options.out = args.out;
  options.patches = args.patches;
  options.chessboard = args.chessboard;
  options.camera_model = args.camera_model;
  options.board = ParseChessboard(args.corners, args.square);
  options.display_names = args.displays;
  options.open_display = OpenMonitorDisplay;
  options.names = args.names;
  options.held_lenses = ParseHeldLenses(args.held_lenses);
  options.camera_guess = args.camera_guess;
  options.camera_scale = args.camera_scale;
  options.frames = args.frames;
  options.settle_ms = args.settle.ms;
  options.measure_settle = args.settle.measure;
  options.grab_timeout_ms = args.timeout_ms;
  options.exposures_us = args.exposures_us;
  options.levels = ParseIntegerList("--levels", args.levels, "8-bit levels, comma-separated");
  options.scan = args.scan;
  options.floor_chessboard = args.floor_chessboard;
  options.camera_height = args.camera_height;
  options.board_thickness = args.board_thickness;
  options.progress = PrintProgress();
  // A signal stops it cleanly (apps/stop_signals.h): main says where, exit kStoppedExitCode.
  options.stop = &StopOnSignals();
  RunCalibrateAll(options);
}

}  // namespace

void AddCalibrateAllCommand(CLI::App& calibrate) {
  auto args = std::make_shared<CalibrateAllArguments>();
  CLI::App* all = calibrate.add_subcommand(
      "all",
      "Capture and calibrate a whole rig: camera, projectors, registration, photometry");
  all->add_option("--camera", args->camera,
                  "Camera URI (v4l2:..., aravis:..., synthetic:SCENE for the simulated rig)")
      ->required();
  all->add_option("--scene", args->scene,
                  "The room model (scene JSON, or synthetic:NAME); without it a real camera scans "
                  "the room into RIG_DIR/room.json; a synthetic camera uses its own scene unless "
                  "--scan");
  all->add_flag("--scan", args->scan,
                "Scan the room (no room model, no camera guess): poses and projector lenses from "
                "the structured light, the room written as RIG_DIR/room.json");
  all->add_option("--floor-chessboard", args->floor_chessboard,
                  "Scanning: a photo of the chessboard (--corners, --square) lying flat on the "
                  "floor, taken by the camera from where it stands: the scan's metric scale (a "
                  "synthetic camera takes its own)");
  all->add_option("--camera-height", args->camera_height,
                  "Scanning: the camera's height above the floor, metres, instead of "
                  "--floor-chessboard");
  all->add_option("--board-thickness", args->board_thickness,
                  "Scanning: height of the floor chessboard's printed face above the floor, metres")
      ->capture_default_str();
  all->add_option("--out", args->out, "Rig directory")->required();
  all->add_option("--patches", args->patches,
                  "Patch target the per-patch reflectance is estimated for (default: the scene's; "
                  "synthetic: the camera's patches)");
  all->add_option("--chessboard", args->chessboard,
                  "Chessboard photos of the camera (a folder or a capture session)");
  all->add_option("--camera-model", args->camera_model,
                  "A calibrated camera.cameramodel instead of --chessboard");
  all->add_option("--corners", args->corners, "Chessboard inner corners, COLUMNSxROWS")
      ->capture_default_str();
  all->add_option("--square", args->square, "Chessboard square size, metres")
      ->capture_default_str();
  all->add_option("--display", args->displays,
                  "Real rigs: each projector's monitor, in order (glfw:N|NAME, comma-separated)")
      ->delimiter(',');
  all->add_option("--names", args->names, "Projector names, comma-separated")->delimiter(',');
  all->add_option("--hold-lens", args->held_lenses,
                  "NAME=FILE: hold projector NAME's lens from FILE (a .cameramodel, e.g. `procam "
                  "calibrate board`'s) and solve only its pose in the room; repeat per projector; "
                  "not with --scan");
  all->add_option("--camera-guess", args->camera_guess,
                  "Camera position and a point it looks at, x,y,z,look_x,look_y,look_z (scene "
                  "frame, metres); a synthetic camera's is guessed from its placement");
  all->add_option("--camera-scale", args->camera_scale,
                  "Camera value per unit exitance (number or R,G,B; default for a synthetic "
                  "camera: from its URI)");
  all->add_option("--frames", args->frames, "Frames averaged per pattern")->capture_default_str();
  AddSettleOption(all, &args->settle);
  all->add_option("--timeout-ms", args->timeout_ms,
                  "Grab timeout per frame, milliseconds (a camera that delivers nothing for this long is retried, "
                  "then the capture stops with one line; run the same command again to resume)")
      ->check(FiniteRange(1.0, 600000.0))
      ->capture_default_str();
  all->add_option("--exposure-us", args->exposures_us,
                  "Exposure(s), microseconds; several bracket and merge to HDR")
      ->delimiter(',');
  all->add_option("--levels", args->levels, "Photometric drive levels, comma-separated")
      ->capture_default_str();
  all->callback([args] {
    CheckOutputDirectory(args->out, DirectoryKind::kRig);
    CalibrateAll(*args);
  });
}

}  // namespace procam
