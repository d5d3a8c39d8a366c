// procam calibrate camera SESSION_DIR --out RIG_DIR (calibration/camera_stage.h), procam
// calibrate board SESSION... --out RIG_DIR (calibration/board_stage.h) and procam calibrate
// photometric SESSION_DIR --out RIG_DIR (calibration/photometric_stage.h).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "base/output_directory.h"
#include "calibration/board_stage.h"
#include "calibration/camera_stage.h"
#include "calibration/photometric_stage.h"

namespace procam {
namespace {

struct CalibrateCameraArguments {
  std::string session;
  std::string out;
  std::string corners = "9x6";
  double square = 0.03;
  CameraCalibrationOptions options;
};

void RunCalibrateCamera(const CalibrateCameraArguments& args) {
  CameraStageOptions options;
  options.images = args.session;
  options.out = args.out;
  options.board = ParseChessboard(args.corners, args.square);
  options.options = args.options;
  options.progress = PrintProgress();
  RunCameraStage(options);
}

struct CalibrateBoardArguments {
  std::vector<std::string> sessions;
  std::string corners = "9x6";
  double square = 0.03;
  BoardStageOptions options;
};

void RunCalibrateBoard(const CalibrateBoardArguments& args) {
  BoardStageOptions options = args.options;
  options.sessions.assign(args.sessions.begin(), args.sessions.end());
  options.board = ParseChessboard(args.corners, args.square);
  options.progress = PrintProgress();
  CheckOutputDirectory(options.out, DirectoryKind::kRig);
  RunBoardStage(options);
}

void AddCalibrateBoardCommand(CLI::App* calibrate) {
  auto args = std::make_shared<CalibrateBoardArguments>();
  CLI::App* board = calibrate->add_subcommand(
      "board",
      "Camera and projector together from a chessboard held at several poses, one "
      "structured-light session per pose (docs/chessboard.md)");
  board
      ->add_option("sessions", args->sessions,
                   "Capture sessions of `procam capture --sequence structured_light`, one per "
                   "board pose")
      ->required();
  board->add_option("--out", args->options.out,
                    "Rig directory: camera.cameramodel, NAME.cameramodel, result.json")
      ->required();
  board->add_option("--name", args->options.projector, "The projector's name")
      ->capture_default_str();
  board->add_option("--corners", args->corners, "Inner corners, COLUMNSxROWS")
      ->capture_default_str();
  board->add_option("--square", args->square, "Square size, metres")->capture_default_str();
  BoardProjectorOptions& options = args->options.options;
  board->add_option("--lens-model", options.lens_model,
                    "Both lenses: LENSMODEL_OPENCV4, LENSMODEL_OPENCV5 or LENSMODEL_OPENCV8")
      ->capture_default_str();
  board->add_option("--window", options.homography_half_window,
                    "Half side of the window around a corner for its local homography, camera "
                    "pixels [3, 200]")
      ->capture_default_str();
  board->add_option("--min-window-pixels", options.min_window_pixels,
                    "Fewest decoded pixels in a corner's window, >= 8")
      ->capture_default_str();
  board->add_option("--homography-reject", options.homography_reject_px,
                    "Decoded pixels farther than this from a corner's homography are dropped, "
                    "projector pixels")
      ->capture_default_str();
  board->add_option("--min-poses", options.min_poses, "Fewest board poses, >= 2")
      ->capture_default_str();
  board->add_option("--min-tilt-spread", options.min_tilt_spread_deg,
                    "Least angle between two poses' board normals, degrees [0, 90)")
      ->capture_default_str();
  board->add_flag("!--no-outlier-rejection", options.reject_outliers, "Keep every corner");
  board->callback([args] { RunCalibrateBoard(*args); });
}

}  // namespace

void AddPhotometricStageOptions(CLI::App* command, PhotometricStageOptions* options) {
  command->add_option("--projector", options->projector,
                      "Merge the fit into RIG_DIR/rig.json's projector of this name");
  command->add_option("--scene", options->scene,
                      "Scene file: black and max in the scene's units and per-patch reflectance "
                      "(needs the rig's camera registration and the projector's model)");
  command->add_option("--patches", options->patches, "Patch target for --scene (default: the scene's)");
  command->add_option("--camera-scale", options->camera_scale,
                      "Camera value per unit exitance in the scene's units: a number, R,G,B, or "
                      "the synthetic camera's URI (its exposure and gain from session.json)");
  command->add_option_function<double>(
      "--camera-black", [options](double black) { options->camera_black = black; },
      "Camera black level in digital numbers, subtracted before the fit "
      "(default 0, or the synthetic URI's black)");
  command->add_option("--response", options->response, "What rig.json gets: gamma or lut")
      ->check(CLI::IsMember({"gamma", "lut"}))
      ->capture_default_str();
}

void AddCalibrateCommands(CLI::App& app) {
  CLI::App* calibrate = app.add_subcommand("calibrate", "Calibrate the rig from captures");
  calibrate->require_subcommand(1);
  auto args = std::make_shared<CalibrateCameraArguments>();
  CLI::App* camera = calibrate->add_subcommand(
      "camera", "Camera intrinsics from chessboard images (OpenCV detection, mrcal refinement)");
  camera->add_option("session", args->session,
                     "Capture session (its frames/) or a folder of chessboard images")
      ->required();
  camera->add_option("--out", args->out, "Rig directory: camera.cameramodel, result.json")
      ->required();
  camera->add_option("--corners", args->corners, "Inner corners, COLUMNSxROWS")
      ->capture_default_str();
  camera->add_option("--square", args->square, "Square size, metres")->capture_default_str();
  camera->add_option("--lens-model", args->options.lens_model,
                     "LENSMODEL_OPENCV4, LENSMODEL_OPENCV5 or LENSMODEL_OPENCV8")
      ->capture_default_str();
  camera->add_flag("!--no-outlier-rejection", args->options.reject_outliers,
                   "Keep every corner");
  camera->callback([args] {
    CheckOutputDirectory(args->out, DirectoryKind::kRig);
    RunCalibrateCamera(*args);
  });

  auto photometric_args = std::make_shared<PhotometricStageOptions>();
  photometric_args->progress = PrintProgress();
  CLI::App* photometric = calibrate->add_subcommand(
      "photometric",
      "Projector black, max, gamma, response table and mixing from a photometric capture "
      "session (camera units)");
  photometric
      ->add_option("session", photometric_args->session,
                   "Capture session of `procam capture --sequence photometric --channels rgb`")
      ->required();
  photometric
      ->add_option("--out", photometric_args->out, "Rig directory: photometric.json, result.json")
      ->required();
  photometric
      ->add_option("--min-contrast", photometric_args->options.min_contrast,
                   "Pixels used: brightening from black by at least this fraction of the largest")
      ->capture_default_str();
  photometric
      ->add_option("--table-size", photometric_args->options.table_size,
                   "Entries of the response table (lut)")
      ->capture_default_str();
  AddPhotometricStageOptions(photometric, photometric_args.get());
  photometric->callback([photometric_args] {
    CheckOutputDirectory(photometric_args->out, DirectoryKind::kRig);
    RunPhotometricStage(*photometric_args);
  });

  AddCalibrateBoardCommand(calibrate);
  AddCalibrateResponseCommand(*calibrate);
  AddCalibrateAllCommand(*calibrate);
  AddCalibrateProjectorsCommand(*calibrate);
}

}  // namespace procam
