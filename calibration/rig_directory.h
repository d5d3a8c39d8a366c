#pragma once
// The rig directory (issue 7): what calibration writes and `compensate`/`project` consume
// instead of the scene's ground truth.
//
//   RIG_DIR/rig.json            {"camera": {"model": "camera.cameramodel"},
//                                "projectors": [ {name, model, black, max, gamma|lut, mixing,
//                                                 bits}, ... ],   (scene-file projector keys,
//                                                                  docs/scene_format.md; paths
//                                                                  relative to RIG_DIR)
//                                "registration": {...}}          (room_from_camera, residuals)
//   RIG_DIR/camera.cameramodel  mrcal; extrinsics = rt_cam_room once registered (zero before)
//   RIG_DIR/NAME.cameramodel    mrcal; extrinsics = rt_proj_room (ref = the scene's frame)
//
// Several commands each fill their part of rig.json (`calibrate camera`, `calibrate projectors`,
// `calibrate photometric`), so it is updated by read-modify-write, written atomically.

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "compensation/stage.h"
#include "geometry/patches.h"
#include "projection/projector.h"

namespace procam {

// rig.json's format (docs/rig_format.md); written into every rig.json, required when one is read.
constexpr int kRigFormatVersion = 1;

// rig.json of `rig_dir` as JSON; an empty object when the file does not exist. Throws IoError
// naming the file (and the key) when it exists but is not a JSON object, or its format_version is
// missing or not kRigFormatVersion. The one reader of rig.json.
nlohmann::json ReadRigJson(const std::filesystem::path& rig_dir);

// Reads rig.json (or {}), lets `update` change it, writes it back atomically with its
// format_version (creating `rig_dir`). Nothing is written when `update` throws. The one writer of
// rig.json.
void UpdateRigJson(const std::filesystem::path& rig_dir,
                   const std::function<void(nlohmann::json&)>& update);

// RIG_DIR/result.json gathers what every calibrate command reports, one section each
// ("camera", "projectors", "photometric" → {NAME: ...}, "response"), so that one command never
// drops another's report. Sets the section at `path` (object keys, outermost first), keeping the
// rest; a result.json that is not a JSON object is replaced. Written atomically.
void UpdateRigResult(const std::filesystem::path& rig_dir, const std::vector<std::string>& path,
                     const nlohmann::json& section);

// The entry of projectors[] named `name` in `rig`, created (with "name") at the end of the array
// when missing.
nlohmann::json& RigProjectorEntry(nlohmann::json& rig, const std::string& name);

// RIG_DIR/rig.json read for compensate and project.
struct RigDirectory {
  std::filesystem::path dir;
  nlohmann::json json;                // rig.json as read
  std::vector<Projector> projectors;  // rig.json's projectors[], paths relative to dir
  // RIG_DIR/reflectance.npy (n,3) when rig.json has "reflectance", with the patch target it was
  // estimated for; empty otherwise.
  Eigen::MatrixX3d reflectance;
  int reflectance_target_patches = 0;
  // What result.json records about the rig.
  nlohmann::json Describe() const;
};

// Reads RIG_DIR/rig.json. Throws IoError naming RIG_DIR/rig.json and the key: no file, no
// non-empty "projectors", a projector whose photometry is in camera units ("photometric"
// NAME.units, written by `calibrate photometric` without --scene), and every error of a scene
// file's projectors (missing model file, no `max`, bad mixing, ...).
RigDirectory ReadRigDirectory(const std::filesystem::path& rig_dir);

// Replaces the fine level's reflectance by the rig's (and the coarse level's by the area-weighted
// mean of its children). Throws IoError naming RIG_DIR/rig.json when the rig's reflectance was
// estimated for another patch count. Does nothing when the rig has none.
void ApplyRigReflectance(const RigDirectory& rig, PatchHierarchy* patches);

// The projectors that show a solution, and what result files record about their rig: `rig_dir`
// when given, else the rig the solution was computed with (its result.json "rig"), else the
// scene's own projectors (rig_description null). A rig's per-patch reflectance replaces the
// patches' (ApplyRigReflectance). Throws IoError like ReadRigDirectory and ReadProjectors.
struct SolutionProjectors {
  std::vector<Projector> projectors;
  nlohmann::json rig_description;  // RigDirectory::Describe(), or null
};
SolutionProjectors ProjectorsForSolution(const SolutionDirectory& solution, const std::filesystem::path& rig_dir,
                                         const Scene& scene, PatchHierarchy* patches);

}  // namespace procam
