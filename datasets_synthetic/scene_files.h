#pragma once
// The built-in synthetic scenes as scene files (docs/scene_format.md): a starting point for a
// room of one's own, opened as a synthetic rig with `synthetic:DIR/NAME.json`.

#include <filesystem>
#include <string>

#include "datasets_synthetic/paper_scenes.h"

namespace procam {

// Writes synthetic scene `name` (SyntheticSceneNames()) with `patches` as its patch target into
// `dir`: NAME.json with its surfaces, projectors and camera; a .cameramodel per projector and
// for the camera (NAME_camera.cameramodel); an OBJ per mesh surface; a 16-bit sRGB PNG per
// textured surface and a `NAME_SURFACE_reflectance.png` (with its scale) per printed surface
// (Surface::reflectance_texture). The projectors' photometry is ProjectorFromPlacement's, the camera entry
// the synthetic camera's (BGR8, the test camera's defaults), so `synthetic:DIR/NAME.json`
// photographs what `synthetic:NAME` does. Returns the scene file's path. Throws
// std::invalid_argument for an unknown scene, IoError naming a file that cannot be written.
std::filesystem::path WriteSyntheticSceneFile(const std::string& name, int patches,
                                              const std::filesystem::path& dir);

// The same for a scene made in code (its placements, patch target `synthetic.scene.target_patches`),
// written as NAME.json with `description`: the one writer of scene files with their devices.
std::filesystem::path WriteSyntheticSceneFile(const SyntheticScene& synthetic,
                                              const std::string& name,
                                              const std::string& description,
                                              const std::filesystem::path& dir);

}  // namespace procam
