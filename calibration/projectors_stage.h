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

#include <Eigen/Geometry>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "base/progress.h"
#include "calibration/registration.h"

namespace procam {

struct ProjectorsStageOptions {
  std::vector<std::filesystem::path> sessions;  // structured-light sessions, one per projector
  std::string scene;                            // the room model: a scene file or PREFIX:NAME
  std::filesystem::path out;                    // the rig directory holding camera.cameramodel
  // The camera's pose in the room to start from (a few cm and degrees off is fine); unset:
  // the pose camera.cameramodel already holds (an error if it holds none).
  std::optional<Eigen::Isometry3d> room_from_camera_guess;
  std::vector<std::string> names;     // one per session; empty: each session's display name
  bool refine_camera_aspect = false;  // with options.refine_camera_intrinsics: fx, fy free
  RoomCalibrationOptions options;
  ProgressCallback progress;  // decoding per session, the solve, the scan check, files written
};

struct ProjectorsStageSummary {
  RoomCalibration calibration;
  RoomCalibrationSummary summary;  // termination and residuals: summary.BriefReport()
};

// room_from_camera of a camera at x,y,z looking at look_x,look_y,look_z (`guess`, metres, the
// --camera-guess text) with image up as close to `up` ("x,y,z") as possible. Throws IoError
// naming --camera-guess or --camera-up.
Eigen::Isometry3d RoomFromCameraGuess(const std::string& guess, const std::string& up = "0,0,1");

// Throws IoError naming the session, camera.cameramodel or rig.json and the key;
// std::invalid_argument for bad options or names; std::runtime_error when the solve fails.
// Nothing is written unless everything was computed.
ProjectorsStageSummary RunProjectorsStage(const ProjectorsStageOptions& options);

}  // namespace procam
