#pragma once
// `procam calibrate photometric ... --projector NAME [--scene SCENE --camera-scale S]`: the
// part that merges the fit into RIG_DIR/rig.json and, when the rig holds the projector's
// geometry and the camera's registration, converts black and max to the scene's units and
// estimates per-patch reflectance (apps/rig_stage.h has the model). Used by
// calibrate_command.cc; kept apart so that file's other commands stay untouched.

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "calibration/photometric.h"

namespace procam {

struct PhotometricRigArguments {
  std::string projector;     // rig.json projectors[] entry to fill; empty: rig.json untouched
  std::string scene;         // scene file: convert to scene units (needs the rig's geometry)
  int patches = 0;           // patch target for the scene (0: the scene's)
  std::string camera_scale;  // k: number, "R,G,B", or the synthetic camera's URI
  double camera_black = -1;  // camera black level, digital numbers (< 0: 0, or the URI's)
  std::string response = "gamma";  // what rig.json gets: "gamma" or "lut"
  int min_patch_pixels = 4;        // camera pixels a patch needs for its reflectance
};

// Registers --projector, --scene, --patches, --camera-scale, --camera-black, --response.
void AddPhotometricRigOptions(CLI::App* command, PhotometricRigArguments* args);

class PhotometricRigStage {
 public:
  // Checks the arguments and, with a scene, the rig's geometry (rig.json camera.model,
  // registration, projectors[NAME].model), and computes the per-pixel transfer. Throws IoError
  // naming RIG_DIR/rig.json and the key, or the option.
  PhotometricRigStage(const PhotometricRigArguments& args, const std::filesystem::path& rig_dir,
                      const std::filesystem::path& session_dir, cv::Size image_size, bool hdr,
                      double full_scale);
  ~PhotometricRigStage();

  bool scene_units() const;
  // Scene units: sets the transfer and the camera black (as ambient), and keeps only pixels
  // that see a patch. Camera units: nothing.
  void Configure(PhotometricCalibrationOptions* options) const;
  // After the fit: the reflectance (scene units) and the rig.json update, nothing written yet;
  // `photometric` and `result` (the command's JSON) get the units and the numbers.
  void Prepare(const PhotometricModel& model, const std::vector<FlatField>& fields,
               const cv::Mat& mask, nlohmann::json* photometric, nlohmann::json* result);
  // Writes RIG_DIR/reflectance.npy (scene units) and rig.json, each atomically.
  void Commit() const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace procam
