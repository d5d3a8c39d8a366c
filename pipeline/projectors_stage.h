#pragma once
// The projectors stage of calibration: every projector's intrinsics and pose and the camera's
// pose in the room, from one structured-light capture session per projector and the scene model
// (registration.h). The camera's intrinsics come from RIG_DIR/camera.cameramodel (the camera
// stage) and are held fixed, or refined jointly (options.refine_camera_intrinsics: focal length
// with the aspect ratio kept, cx, cy; refine_camera_aspect frees fy too; distortion kept).
// Checked independently against the scan: the triangulated points registered to the model by
// ICP from the same guess, and RANSAC planes. Writes RIG_DIR/NAME.cameramodel per projector,
// rewrites RIG_DIR/camera.cameramodel with its pose in the room (and refined intrinsics), and
// updates RIG_DIR/rig.json and RIG_DIR/result.json. What `procam calibrate projectors` runs.
// A projector calibrated on a chessboard (board_stage.h) joins the room with its lens held
// (options.held_lenses), with a room model or scanning: its pose in the room alone is solved, its
// lens written unchanged.
//
// Without a room model (`scene` empty) the room is scanned instead: the projectors' intrinsics and
// poses and the camera's pose from the structured light alone (self_calibration.h), the metric
// scale from the camera's height above the floor (given, or measured from a photo of the
// chessboard lying on the floor: floor_chessboard.h), the room frame z up from the floor, and
// the room built from the triangulated points (scene_from_points.h) and written as
// RIG_DIR/room.json (with its meshes), the scene the later stages use.

#include <Eigen/Geometry>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "base/option_table.h"
#include "base/progress.h"
#include "calibration/camera_calibration.h"
#include "calibration/registration.h"
#include "calibration/self_calibration.h"
#include "geometry/scene_from_points.h"

namespace procam {

struct ProjectorsStageOptions {
  std::vector<std::filesystem::path> sessions;  // structured-light sessions, one per projector
  std::string scene;          // the room model: a scene file or PREFIX:NAME; empty: scan the room
  std::filesystem::path out;  // the rig directory holding camera.cameramodel
  // The camera's pose in the room to start from (a few cm and degrees off is fine); unset:
  // `camera_guess`, else the pose camera.cameramodel already holds (an error if it holds none).
  std::optional<Eigen::Isometry3d> room_from_camera_guess;
  // The guess as written: the camera's position and a point it looks at,
  // "x,y,z,look_x,look_y,look_z" (metres, the scene's frame), image up as close to `camera_up`
  // ("x,y,z") as possible (RoomFromCameraGuess). Empty: none.
  std::string camera_guess;
  std::string camera_up = "0,0,1";
  std::vector<std::string> names;  // one per session; empty: each session's display name
  // Projectors whose lens (intrinsics and distortion) is held from a .cameramodel — the board
  // calibration's NAME.cameramodel (board_stage.h), LENSMODEL_PINHOLE or LENSMODEL_OPENCV4, its
  // imagersize the session's projector size — so that only their pose in the room is solved:
  // projector name → file. With a room model (`scene`) or scanning (SelfCalibrateRoom holds it
  // and solves the pose alone); the others' lenses are solved.
  std::map<std::string, std::filesystem::path> held_lenses;
  bool refine_camera_aspect = false;  // with options.refine_camera_intrinsics: fx, fy free
  RoomCalibrationOptions options;
  // Scanning (no scene). The metric scale: the camera centre's height above the floor, metres,
  // or a photo of `board` lying flat on the floor taken from the structured-light pose (its
  // printed face `board_thickness` metres above the floor); one of the two is required.
  std::optional<double> camera_height;
  std::filesystem::path floor_chessboard;
  ChessboardSpec board;
  double board_thickness = 0.0;
  // The floor chessboard's plane and the scan's floor may differ by at most this, degrees:
  // more stops the scan with one line naming the photo (the board not flat on the floor, or the
  // photo taken from another pose). Measured 0.08–0.10° on the synthetic tiny box.
  double max_board_floor_angle_deg = 3.0;
  SelfCalibrationOptions self_calibration;  // its camera_height is set from the above
  SceneFromPointsOptions scan;  // the written room: reflectance, desired colour, patch target
  // Per projector, decoded pixels used (thinned evenly), >= 0; 0: each path's own default
  // (options.max_correspondences with a scene, self_calibration.max_correspondences scanning).
  int max_correspondences = 0;
  ProgressCallback progress;  // decoding per session, the solve, the scan check, files written

  // Declares the sessions (positional), --scene, the scan's --floor-chessboard, --camera-height,
  // --corners, --square, --board-thickness and --patches, --out, --camera-guess, --camera-up,
  // --names, --hold-lens, --refine-distortion, --refine-camera, --refine-camera-aspect and
  // --max-correspondences in `table`, bound to these fields (base/option_table.h).
  void Declare(OptionTable* table);
  // The declared values, and the options of one path not given with the other (the scan's
  // without a scene, --camera-guess with one); `*why` names the option.
  bool Check(std::string* why) const;
};

struct ProjectorsStageSummary {
  RoomCalibration calibration;
  RoomCalibrationSummary summary;  // termination and residuals: summary.BriefReport()
  // Scanned rooms only: the self-calibration's summary, the room built and where it was written.
  std::optional<SelfCalibrationSummary> self_calibration;
  std::optional<ScannedScene> scanned;
  std::filesystem::path room;  // RIG_DIR/room.json
};

// room_from_camera of a camera at x,y,z looking at look_x,look_y,look_z (`guess`, metres, the
// --camera-guess text) with image up as close to `up` ("x,y,z") as possible. Throws IoError
// naming --camera-guess or --camera-up.
// A projector's name as rig.json and file names take it: letters, digits, '_', '-' and '.'.
bool ValidProjectorName(const std::string& name);
// `name` with every other character replaced by '_' ("front left" → "front_left").
std::string ProjectorNameFrom(const std::string& name);

Eigen::Isometry3d RoomFromCameraGuess(const std::string& guess, const std::string& up = "0,0,1");

// Declares --hold-lens NAME=FILE (one per flag) in `table`, bound to `held_lenses`
// (ProjectorsStageOptions::held_lenses): an entry without '=', with an empty name or file, or a
// name given twice is refused.
void DeclareHeldLenses(OptionTable* table,
                       std::map<std::string, std::filesystem::path>* held_lenses,
                       const std::string& help);

// Throws IoError naming the session, camera.cameramodel or rig.json and the key;
// std::invalid_argument for bad options or names; std::runtime_error when the solve fails.
// Nothing is written unless everything was computed.
ProjectorsStageSummary RunProjectorsStage(const ProjectorsStageOptions& options);

}  // namespace procam
