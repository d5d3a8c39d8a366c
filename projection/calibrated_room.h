#pragma once
// The calibrated room, built once: "this room, calibrated by this rig, at this patch count,
// optionally with this solution". Its pieces are the geometry with the rig's reflectance, the
// projectors and the projection rig with its direct-light bounds, the fine level's compensation
// problem within those bounds, and the registered camera's rays into the room. `procam play`,
// the display nodes, `procam verify`, `procam compensate`, `procam demo room` and the synthetic
// demo build their room here; the consistency checks (the solution's patch count against the
// scene's, the rig's reflectance against the patches, a camera where one is needed) are made
// here, each with one wording.
//
// It lives in projection/, with the rig directory (rig_directory.h): it combines geometry/ and
// compensation/ with the rig's projectors, and is used by nodes/, verification/,
// datasets_synthetic/ and apps/, all above projection/ (docs/architecture.md).

#include <Eigen/Core>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "base/progress.h"
#include "compensation/problem.h"
#include "compensation/stage.h"
#include "geometry/stage.h"
#include "projection/rig_directory.h"

namespace procam {
class OptionTable;
}  // namespace procam
#include "projection/camera_rays.h"
#include "projection/projection_rig.h"
#include "projection/projector.h"

namespace procam {

// What the room is built from and which of its pieces are made.
struct ProjectionStageOptions;
struct ProjectionStageSummary;

struct CalibratedRoomOptions {
  // The room (LoadSceneArgument: a scene file or PREFIX:NAME); empty: the solution's scene.
  std::string scene;
  // The rig directory (rig.json): projectors, per-patch reflectance, registered camera. Empty:
  // the scene's own projectors and reflectance (and no camera).
  std::filesystem::path rig_dir;
  // A solution directory (procam compensate's): its patch count must be the room's. Optional.
  std::filesystem::path solution_dir;
  // Target patch count of the fine level, 0 or ≥ 4 (checked by the geometry stage, naming
  // --patches). 0: the solution's target_patches (with a solution), else the scene's `patches`.
  int patches = 0;
  // Fine patches the room must subdivide into, as another process counted them (a display node:
  // the controller's room); 0: no such count. With `expected_by` naming who counted them and
  // `mismatch_hint` what a difference means.
  int expected_patches = 0;
  std::string expected_by = "the controller's room";
  std::string mismatch_hint = "the display PC's copy of the room differs";
  // The fine level's form factors (dense or compressed); false: the patches only, no form
  // factors and no problem (a display node renders, it does not solve).
  bool form_factors = true;
  FormFactorStorage storage = FormFactorStorage::kDense;
  // The fine level's CompensationProblem within the projection rig's bounds (dense form factors
  // only). Off where a stage makes its own problems (RunCompensation).
  bool problem = true;
  double alpha = 0.5;  // the problem's weight of the absolute term, (0, 1]
  // The projection rig's options (feather, texture coordinates, ...).
  ProjectionRigOptions projection;
  // Attach the rig's per-pixel reflectance maps (rig.json's reflectance_maps, where every
  // projector has one) to the projection rig, so that rendering (RenderOptions::reflectance) and
  // the per-pixel prediction use them (HasReflectanceMaps); false: one reflectance per patch.
  bool reflectance_maps = true;
  // Projectors whose photometry says another bit depth are rendered at this one (the displays'),
  // with a progress line each; 0: as the rig says. 0, 8 or 10.
  int display_bits = 0;
  // The registered camera's pixels cast into the room (needs a rig with camera.model): which
  // patch each sees (camera_rays.patch), and with `camera_lighting` how each projector lights
  // it (gain, projector pixel: CastCameraPixels with the projectors).
  bool camera_rays = false;
  bool camera_lighting = false;
  // The geometry stage's progress (patch counts, form factors every 10%) and the room's lines.
  ProgressCallback progress;
  // Declares what a person chooses of the room — --rig, --patches, --form-factors — in `table`,
  // bound to this struct's fields (base/option_table.h).
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
};

// What the room is read from, before anything is computed: read by ReadRoomSources (cheap: a
// caller can check more of its input before the form factors are computed), or given.
struct RoomSources {
  std::optional<RigDirectory> rig;            // with options.rig_dir
  std::optional<SolutionDirectory> solution;  // with options.solution_dir
  // The registered camera (with options.camera_rays): RIG_DIR/camera.model and its geometry.
  std::filesystem::path camera_model_path;
  ProjectorGeometry camera;
  // The scene itself (e.g. made in memory), instead of options.scene or the solution's.
  std::optional<Scene> scene;
  // The geometry already computed (e.g. an evaluation's), used instead of running the geometry
  // stage; the rig's reflectance is applied to it.
  std::optional<GeometryStage> geometry;
};

// The room, assembled.
struct CalibratedRoom {
  std::optional<RigDirectory> rig;
  std::optional<SolutionDirectory> solution;
  // Scene, patches (their reflectance the rig's where it has one), form factors.
  GeometryStage geometry;
  // The rig's projectors (the scene's without a rig), at options.display_bits where given.
  std::vector<Projector> projectors;
  // Maps, blending weights and direct-light bounds (lower, upper) of `projectors` on the fine
  // patches, with the rig's reflectance maps attached (options.reflectance_maps); empty (size()
  // 0) when there are no projectors.
  ProjectionRig projection;
  // The fine level's problem with the projection rig's bounds (the scene's "bounds" without
  // projectors); empty unless options.problem.
  CompensationProblem problem;
  std::filesystem::path camera_model_path;
  ProjectorGeometry camera;
  // The camera's pixels in the room (options.camera_rays); width 0 otherwise.
  CameraPixelRays camera_rays;

  const PatchLevel& fine() const { return geometry.patches.fine; }
  int size() const { return geometry.patches.fine.size(); }
};

// Reads what `given` lacks of the rig (rig.json), the registered camera (when camera rays are
// asked for) and the solution, in that order. Throws std::invalid_argument for options failing
// Check(), IoError naming the file and key: every error of ReadRigDirectory and
// ReadSolutionDirectory, a rig without camera.model or whose camera model file is missing when
// the camera is needed.
RoomSources ReadRoomSources(const CalibratedRoomOptions& options, RoomSources given = {});

// Builds the room from its sources. Throws IoError: a solution whose patch count is not the
// room's (one wording, PatchCountMismatch), a count other than options.expected_patches (the
// same wording), the rig's reflectance estimated for another patch count
// (ApplyRigReflectance), every error of the geometry stage, the projection rig and the camera,
// and of the rig's reflectance maps (ReadRigReflectanceMaps).
CalibratedRoom BuildCalibratedRoom(const CalibratedRoomOptions& options, RoomSources sources);

// ReadRoomSources, then BuildCalibratedRoom.
CalibratedRoom LoadCalibratedRoom(const CalibratedRoomOptions& options);

// `procam project`: options.solution read (its scene at its patch count), the projectors that
// show it (ProjectorsForSolution: options.rig, else the solution's rig, else the scene's), and
// the projection stage run on them. Throws std::invalid_argument for options failing Check(),
// IoError like ReadSolutionDirectory, ProjectorsForSolution and RunProjectionStage.
ProjectionStageSummary ProjectSolution(const ProjectionStageOptions& options);

// The one wording of "the room subdivides into another patch count than X says":
//   SCENE: subdivides into FOUND patches for target TARGET, BY into EXPECTED: HINT
std::string PatchCountMismatch(const std::string& scene, int found, int target,
                               const std::string& by, int expected, const std::string& hint);

}  // namespace procam
