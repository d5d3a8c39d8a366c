#pragma once
// The built-in synthetic scenes as scene files (docs/scene_format.md): a starting point for a
// room of one's own, opened as a synthetic rig with `synthetic:DIR/NAME.json`.

#include <Eigen/Geometry>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "calibration/camera_calibration.h"
#include "datasets_synthetic/paper_scenes.h"

namespace procam {

// A scene file's "chessboard" (docs/scene_format.md#a-chessboard-in-front-of-the-rig): a printed
// board held at several poses in front of the rig's camera, for calibrating a projector on it
// (docs/chessboard.md). The synthetic camera photographs pose K with `board_pose=K`.
//
//   "chessboard": {"corners": [9, 6], "square_m": 0.04, "reflectance": [0.1, 0.85],
//                  "poses": [{"rotation_deg": [30, 0, 0], "translation_m": [0.05, 0, 1.0]}]}
//
// Each pose places the board in the frame of the camera that photographs it (x right, y down, z
// out of the lens, metres): `translation_m` is the board's centre (the middle of its inner
// corners), `rotation_deg` = [a, b, c] turns the board as Rx(a)·Ry(b)·Rz(c) from facing the
// camera squarely with its rows along the image's rows (board frame as in camera_calibration.h:
// origin at the first inner corner, x along a row, z into the board).
struct SceneChessboard {
  ChessboardSpec board;             // inner corners and square size, metres
  double dark_reflectance = 0.1;    // the dark squares, [0, 1]
  double light_reflectance = 0.85;  // the light squares and a one-square margin, [0, 1]
  struct Pose {
    Vec3 rotation_deg = Vec3::Zero();
    Vec3 translation_m = Vec3(0.0, 0.0, 1.0);
  };
  std::vector<Pose> poses;  // at least one
  // Pose k as cam_from_board (the board frame's origin at its first inner corner).
  Eigen::Isometry3d CamFromBoard(size_t k) const;
  nlohmann::json Json() const;  // the key's value, as ReadSceneChessboard reads it
};

// The "chessboard" key of `scene_file`, or nullopt when it has none. Throws IoError naming the
// file and the key ("room.json: chessboard.poses[1].translation_m: ...").
std::optional<SceneChessboard> ReadSceneChessboard(const std::filesystem::path& scene_file);

// Writes synthetic scene `name` (SyntheticSceneNames()) with `patches` as its patch target into
// `dir`: NAME.json with its surfaces, projectors and camera; a .cameramodel per projector and
// for the camera (NAME_camera.cameramodel); an OBJ per mesh surface; a 16-bit sRGB PNG per
// textured surface and a `NAME_SURFACE_reflectance.png` (with its scale) per printed surface
// (Surface::reflectance_texture). The projectors' photometry is ProjectorFromPlacement's, the
// camera entry the synthetic camera's (BGR8, the test camera's defaults), so
// `synthetic:DIR/NAME.json` photographs what `synthetic:NAME` does. Returns the scene file's path.
// Throws std::invalid_argument for an unknown scene, IoError naming a file that cannot be written.
std::filesystem::path WriteSyntheticSceneFile(const std::string& name, int patches,
                                              const std::filesystem::path& dir);

// The same for a scene made in code (its placements, patch target `synthetic.scene.target_patches`),
// written as NAME.json with `description`: the one writer of scene files with their devices.
std::filesystem::path WriteSyntheticSceneFile(const SyntheticScene& synthetic,
                                              const std::string& name,
                                              const std::string& description,
                                              const std::filesystem::path& dir);

}  // namespace procam
