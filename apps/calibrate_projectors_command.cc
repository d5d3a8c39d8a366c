// procam calibrate projectors SESSION_DIR... --scene SCENE --out RIG_DIR, or without --scene
// (the room scanned: --floor-chessboard PHOTO or --camera-height M) (calibration/projectors_stage.h).
#include <filesystem>
#include <string>
#include <vector>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "base/io.h"
#include "base/output_directory.h"
#include "calibration/projectors_stage.h"
#include "geometry/stage.h"

namespace procam {
namespace {

struct CalibrateProjectorsArguments {
  std::vector<std::string> sessions;
  std::string scene;
  std::string out;
  std::string camera_guess;  // "x,y,z,look_x,look_y,look_z" in the room frame
  std::string camera_up = "0,0,1";
  std::vector<std::string> names;
  std::vector<std::string> held_lenses;  // NAME=FILE
  bool refine_camera_aspect = false;
  RoomCalibrationOptions options;
  // Scanning (no --scene).
  std::string floor_chessboard;
  double camera_height = 0.0;
  std::string corners = "9x6";
  double square = 0.03;
  double board_thickness = 0.0;
  int patches = SceneFromPointsOptions().target_patches;
  int max_correspondences = 0;  // 0: each path's own default
};

// A scene file, or a synthetic scene by name ("c_shaped" or "synthetic:c_shaped").
std::string ResolveScene(const std::string& text) {
  if (std::filesystem::is_regular_file(text)) return text;
  const std::string named = text.rfind("synthetic:", 0) == 0 ? text : "synthetic:" + text;
  try {
    LoadSceneArgument(named);
  } catch (const IoError& error) {
    throw IoError("--scene " + text + ": no such file, nor a synthetic scene (" + error.what() + ")");
  }
  return named;
}

void RunCalibrateProjectors(const CalibrateProjectorsArguments& args) {
  ProjectorsStageOptions options;
  options.sessions.assign(args.sessions.begin(), args.sessions.end());
  if (!args.scene.empty()) {
    options.scene = ResolveScene(args.scene);
    if (!args.floor_chessboard.empty() || args.camera_height != 0.0)
      throw std::invalid_argument(
          "--floor-chessboard, --camera-height: only without --scene (scanning the room)");
  } else {
    if (!args.camera_guess.empty())
      throw std::invalid_argument("--camera-guess: only with --scene (a scan needs no guess)");
    options.floor_chessboard = args.floor_chessboard;
    if (args.camera_height != 0.0) options.camera_height = args.camera_height;
    options.board = ParseChessboard(args.corners, args.square);
    options.board_thickness = args.board_thickness;
    options.scan.target_patches = args.patches;
    if (args.max_correspondences > 0)
      options.self_calibration.max_correspondences = args.max_correspondences;
  }
  options.out = args.out;
  if (!args.camera_guess.empty()) options.room_from_camera_guess = RoomFromCameraGuess(args.camera_guess, args.camera_up);
  options.names = args.names;
  options.held_lenses = ParseHeldLenses(args.held_lenses);
  options.refine_camera_aspect = args.refine_camera_aspect;
  options.options = args.options;
  if (args.max_correspondences > 0) options.options.max_correspondences = args.max_correspondences;
  options.progress = PrintProgress();
  RunProjectorsStage(options);
}

}  // namespace

void AddCalibrateProjectorsCommand(CLI::App& calibrate) {
  auto args = std::make_shared<CalibrateProjectorsArguments>();
  CLI::App* command = calibrate.add_subcommand(
      "projectors",
      "Projectors' intrinsics and poses and the camera's pose in the room, from structured-light "
      "sessions (one per projector) and the scene model, or without --scene from the structured "
      "light alone (the room scanned into RIG_DIR/room.json); camera intrinsics held fixed unless "
      "--refine-camera");
  command
      ->add_option("sessions", args->sessions,
                   "Capture sessions of `procam capture --sequence structured_light`, one per "
                   "projector")
      ->required();
  command->add_option("--scene", args->scene,
                      "Scene JSON, or a synthetic scene name; without it the room is scanned");
  command->add_option("--floor-chessboard", args->floor_chessboard,
                      "Scanning: a photo of the chessboard lying flat on the floor, taken by the "
                      "camera from where it stands (the scan's metric scale)");
  command->add_option("--camera-height", args->camera_height,
                      "Scanning: the camera's height above the floor, metres, instead of "
                      "--floor-chessboard");
  command->add_option("--corners", args->corners, "Scanning: chessboard inner corners, COLUMNSxROWS")
      ->capture_default_str();
  command->add_option("--square", args->square, "Scanning: chessboard square size, metres")
      ->capture_default_str();
  command->add_option("--board-thickness", args->board_thickness,
                      "Scanning: height of the board's printed face above the floor, metres")
      ->capture_default_str();
  command->add_option("--patches", args->patches, "Scanning: patch target written into room.json")
      ->capture_default_str();
  command
      ->add_option("--out", args->out,
                   "Rig directory holding camera.cameramodel; gets NAME.cameramodel, rig.json, "
                   "result.json")
      ->required();
  command->add_option(
      "--camera-guess", args->camera_guess,
      "Camera position and a point it looks at, x,y,z,look_x,look_y,look_z (metres, scene frame; "
      "a few cm and degrees off is fine); default: camera.cameramodel's pose");
  command->add_option("--camera-up", args->camera_up, "The scene's up direction, x,y,z")
      ->capture_default_str();
  command->add_option("--names", args->names,
                      "Projector names, one per session (default: the session's display name)")
      ->delimiter(',');
  command->add_option("--hold-lens", args->held_lenses,
                      "NAME=FILE: hold projector NAME's lens (intrinsics and distortion) from "
                      "FILE, a .cameramodel (e.g. `procam calibrate board`'s NAME.cameramodel), "
                      "and solve only its pose in the room; repeat per projector; with --scene");
  command->add_flag("--refine-distortion", args->options.refine_distortion,
                    "Refine projector k1, k2 (LENSMODEL_OPENCV4); default pinhole");
  command->add_flag("--refine-camera", args->options.refine_camera_intrinsics,
                    "Refine the camera's focal length (fy / fx kept), cx, cy jointly (distortion "
                    "kept) and write them into camera.cameramodel; before/after in result.json. "
                    "Scanning (no --scene): the whole lens, with the chessboard's (result.json "
                    "camera.intrinsics_covariance) as the prior");
  command->add_flag("--refine-camera-aspect", args->refine_camera_aspect,
                    "With --refine-camera: fx and fy free independently (weakly pinned by walls "
                    "and a floor; see the reported 1 sigma)");
  command
      ->add_option("--max-correspondences", args->max_correspondences,
                   "Per projector, decoded pixels used (thinned evenly); default " +
                       std::to_string(RoomCalibrationOptions().max_correspondences) +
                       " with --scene, " +
                       std::to_string(SelfCalibrationOptions().max_correspondences) +
                       " scanning the room")
      ->check(FinitePositive());
  command->callback([args] {
    CheckOutputDirectory(args->out, DirectoryKind::kRig);
    RunCalibrateProjectors(*args);
  });
}

}  // namespace procam
