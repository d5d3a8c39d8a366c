#pragma once
// The rig directory (docs/rig_format.md): what calibration writes and compensate, project and
// verify consume instead of the scene's ground truth.
//
//   RIG_DIR/rig.json            RigFile below
//   RIG_DIR/camera.cameramodel  mrcal; extrinsics = rt_cam_room once registered (zero before)
//   RIG_DIR/NAME.cameramodel    mrcal; extrinsics = rt_proj_room (ref = the scene's frame)

#include <Eigen/Core>
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>
#include <optional>
#include <string>
#include <vector>

#include "compensation/stage.h"
#include "geometry/patches.h"
#include "projection/projector.h"

namespace procam {

// rig.json's format (docs/rig_format.md); written into every rig.json, required when one is read.
constexpr int kRigFormatVersion = 1;

// rig.json's camera.colour: how verify turns the camera's values into exitance. One of `scale`
// (camera value per unit exitance, per channel) and `matrix` (camera RGB → exitance).
struct RigCameraColour {
  std::optional<Eigen::Vector3d> scale;
  std::optional<Eigen::Matrix3d> matrix;
  std::optional<double> black;  // the camera's black level, in its values
};

// rig.json's camera.
struct RigCamera {
  std::string model;     // the .cameramodel, relative to the rig directory; "" until calibrated
  std::string response;  // camera_response.json, or ""
  std::optional<RigCameraColour> colour;
};

// One entry of rig.json's projectors[]: the scene file's projector keys (docs/scene_format.md),
// whose values ParseProjectors checks in full when the rig is used.
struct RigProjector {
  std::string name;
  std::string model;  // relative to the rig directory; "" until calibrate projectors
  std::optional<Eigen::Vector3d> black, max;
  nlohmann::json response;  // {"gamma": g} or {"lut": table}; {} until calibrate photometric
  std::optional<Eigen::Matrix3d> mixing;
  std::optional<int> bits;
};

// rig.json's photometric.NAME: how a projector's photometry was measured.
struct RigPhotometry {
  std::string units;                            // "scene" or "camera"
  std::string session;                          // the capture session it was fitted on
  std::string scene;                            // the scene file, for units "scene"
  std::optional<Eigen::Vector3d> camera_scale;  // camera value per unit exitance (units "scene")
  double camera_black = 0.0;
};

// rig.json's reflectance: the per-patch reflectance estimated by calibrate photometric --scene.
struct RigReflectance {
  std::string file;  // .npy, relative to the rig directory
  int target_patches = 0;
  std::string projector, scene;
  int patches = 0, patches_seen = 0;
};

// rig.json's reflectance_maps.NAME: projector NAME's per-pixel reflectance, measured by
// calibrate photometric --scene (projection/reflectance_map.h, which owns the file).
struct RigReflectanceMap {
  std::string file;           // 16-bit PNG, relative to the rig directory
  int width = 0, height = 0;  // the projector's image size
  int target_patches = 0;     // the patch target of the estimate it is normalised to
  int lit_pixels = 0, measured_pixels = 0;
};

// RIG_DIR/rig.json (docs/rig_format.md).
struct RigFile {
  RigCamera camera;
  std::vector<RigProjector> projectors;
  // The camera's registration in the room, as calibrate projectors reports it (room_from_camera,
  // the guess, residuals, the scan check); a record for people, null until registered.
  nlohmann::json registration;
  std::map<std::string, RigPhotometry> photometric;
  std::optional<RigReflectance> reflectance;
  std::map<std::string, RigReflectanceMap> reflectance_maps;  // by projector name

  // The entry named `name`, added at the end when missing.
  RigProjector& Projector(const std::string& name);
  // projectors[] as a scene file writes them, for ParseProjectors.
  nlohmann::json ProjectorsJson() const;
};

// RIG_DIR/rig.json; an empty RigFile when the file does not exist. Throws IoError naming the file
// and the key when it exists but is not JSON, its format_version is missing or not
// kRigFormatVersion, a key is unknown or a value has the wrong type. The one reader of rig.json.
RigFile ReadRigFile(const std::filesystem::path& rig_dir);

// Writes RIG_DIR/rig.json atomically with its format_version (creating `rig_dir`). The one
// writer of rig.json.
void WriteRigFile(const std::filesystem::path& rig_dir, const RigFile& rig);

// Several commands each fill their part of rig.json (calibrate camera, projectors, photometric,
// response): reads it (or an empty one), lets `update` change it, writes it back. Nothing is
// written when `update` throws.
void UpdateRigFile(const std::filesystem::path& rig_dir,
                   const std::function<void(RigFile&)>& update);

// RIG_DIR/result.json gathers what every calibrate command reports, one section each
// ("camera", "projectors", "photometric" → {NAME: ...}, "response"), so that one command never
// drops another's report. Sets the section at `path` (object keys, outermost first), keeping the
// rest; a result.json that is not a JSON object is replaced. Written atomically.
void UpdateRigResult(const std::filesystem::path& rig_dir, const std::vector<std::string>& path,
                     const nlohmann::json& section);
// RIG_DIR/result.json as an object: empty when there is none or it is not a JSON object.
nlohmann::json ReadRigResult(const std::filesystem::path& rig_dir);

// RIG_DIR/rig.json read for compensate and project.
struct RigDirectory {
  std::filesystem::path dir;
  RigFile file;                       // rig.json as read
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
// NAME.units, written by `calibrate photometric` without --scene), every error of a scene
// file's projectors (missing model file, no `max`, bad mixing, ...), and the parts that do not
// agree with each other: two projectors given one model, the camera's model given for a
// projector, and, where the registration record has them, a model that puts its projector (or
// the camera) more than 1 cm from where the registration did or is of another image size (two
// projectors' models swapped, a rig.json of another rig).
RigDirectory ReadRigDirectory(const std::filesystem::path& rig_dir);

// The room a rig is registered in, as `calibrate projectors` records it in rig.json's
// registration.room: per surface its name, centroid (m, area-weighted), area (m²) and, for a
// quad, its unit normal.
nlohmann::json RegisteredRoomJson(const Scene& scene);

// Throws IoError (one line naming the scene file, the surface and rig.json's key) when `scene`
// is not the room the rig was registered in: a surface of a recorded name whose centroid is more
// than 5 cm from the record's, whose area differs by more than 5%, or a quad whose normal turned
// by more than 10° (a wall moved, resized or flipped since the calibration). Surfaces named in
// only one of the two are not compared; rigs without the record (older ones) pass.
void CheckRegisteredRoom(const RigDirectory& rig, const Scene& scene);

// The registration records the checks above read (registration.camera_centre_m,
// camera_imagersize, each projector's centre_m and imagersize, room) that `rig` lacks, by key;
// empty when it has them all. Rigs registered before procam recorded them lack some, and are read
// without those checks.
std::vector<std::string> MissingRegistrationRecords(const RigDirectory& rig);

// One line for a rig that lacks some of them (empty when it lacks none): what is missing, what
// goes unchecked, and the command that records them (registering the rig again).
std::string MissingRegistrationWarning(const RigDirectory& rig);

// Replaces the fine level's reflectance by the rig's (and the coarse level's by the area-weighted
// mean of its children). Throws IoError naming RIG_DIR/rig.json when the rig's reflectance was
// estimated for another patch count. Does nothing when the rig has none.
void ApplyRigReflectance(const RigDirectory& rig, PatchHierarchy* patches);

// The projectors that show a solution, and what result files record about their rig: `rig_dir`
// when given, else the rig the solution was computed with (its result.json "rig"), else the
// scene's own projectors (rig_description null). A rig's per-patch reflectance replaces the
// patches' (ApplyRigReflectance), and its per-pixel reflectance maps, where every projector has
// one, are read (ReadRigReflectanceMaps, projection/reflectance_map.h). Throws IoError like
// ReadRigDirectory, ReadProjectors and ReadRigReflectanceMaps.
struct SolutionProjectors {
  std::vector<Projector> projectors;
  nlohmann::json rig_description;  // RigDirectory::Describe(), or null
  // One per projector (CV_32FC3 linear R, G, B, for AttachReflectanceMaps), or none.
  std::vector<cv::Mat> reflectance_maps;
};
SolutionProjectors ProjectorsForSolution(const SolutionDirectory& solution,
                                         const std::filesystem::path& rig_dir, const Scene& scene,
                                         PatchHierarchy* patches);

}  // namespace procam
