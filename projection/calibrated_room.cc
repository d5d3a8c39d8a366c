#include "projection/calibrated_room.h"

#include <fmt/format.h>

#include <limits>
#include <stdexcept>

#include "base/io.h"
#include "base/option_table.h"
#include "base/timing.h"
#include "projection/reflectance_map.h"
#include "projection/stage.h"

namespace procam {

void CalibratedRoomOptions::Declare(OptionTable* table) {
  table->Text("scene", &scene, "scene JSON, or PREFIX:NAME").Positional().Required();
  table
      ->Path("rig", &rig_dir,
             "rig directory (rig.json from procam calibrate): its projectors replace the scene's, "
             "its reflectance.npy the scene's reflectance")
      .Integer("patches", &patches, 0, std::numeric_limits<int>::max(), "",
               "target patch count of the fine level, ≥ 4 (0: the scene's)")
      .Choice(
          "form-factors", &storage,
          {{"dense", FormFactorStorage::kDense}, {"compressed", FormFactorStorage::kCompressed}},
          "dense (n² doubles) or compressed (near pairs exact, far cluster pairs rank-1: rooms "
          "of 10k–100k+ patches, solved matrix-free; docs/gpu.md)");
}

bool CalibratedRoomOptions::Check(std::string* why) const {
  if (expected_patches < 0) {
    *why = "expected_patches must be ≥ 0, got " + std::to_string(expected_patches);
    return false;
  }
  if (problem && !form_factors) {
    *why = "the problem needs the form factors";
    return false;
  }
  if (problem && storage != FormFactorStorage::kDense) {
    *why = "the problem is made with dense form factors";
    return false;
  }
  if (!(alpha > 0.0 && alpha <= 1.0)) {
    *why = "alpha must be in (0, 1], got " + std::to_string(alpha);
    return false;
  }
  if (display_bits != 0 && display_bits != 8 && display_bits != 10) {
    *why = "display_bits must be 0, 8 or 10, got " + std::to_string(display_bits);
    return false;
  }
  if ((camera_rays || camera_lighting) && rig_dir.empty()) {
    *why = "the camera's rays need a rig (its registered camera)";
    return false;
  }
  return projection.Check(why);
}

std::string PatchCountMismatch(const std::string& scene, int found, int target,
                               const std::string& by, int expected, const std::string& hint) {
  return fmt::format("{}: subdivides into {} patches for target {}, {} into {}: {}", scene, found,
                     target, by, expected, hint);
}

RoomSources ReadRoomSources(const CalibratedRoomOptions& options, RoomSources given) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("room: " + why);
  RoomSources sources = std::move(given);
  if (!options.rig_dir.empty() && !sources.rig) sources.rig = ReadRigDirectory(options.rig_dir);
  if ((options.camera_rays || options.camera_lighting) && sources.camera_model_path.empty()) {
    const std::string rig_file = (options.rig_dir / "rig.json").string();
    if (sources.rig->file.camera.model.empty()) {
      throw IoError(rig_file +
                    ": camera.model: the rig has no registered camera, which maps camera pixels "
                    "onto the room (procam calibrate all, or calibrate projectors)");
    }
    sources.camera_model_path = options.rig_dir / sources.rig->file.camera.model;
    if (!std::filesystem::exists(sources.camera_model_path)) {
      throw IoError(rig_file + ": camera.model: " + sources.camera_model_path.string() +
                    ": file not found");
    }
    sources.camera = ReadCameraModel(sources.camera_model_path);
    if (sources.camera.width() <= 0 || sources.camera.height() <= 0)
      throw IoError(sources.camera_model_path.string() + ": bad size");
  }
  if (!options.solution_dir.empty() && !sources.solution)
    sources.solution = ReadSolutionDirectory(options.solution_dir);
  return sources;
}

namespace {

// The geometry stage's patches, and with options.form_factors its form factors, of `scene`.
GeometryStage RoomGeometry(const CalibratedRoomOptions& options, Scene scene, int target) {
  if (options.form_factors) {
    GeometryOptions geometry;
    geometry.patches = target;
    geometry.storage = options.storage;
    geometry.progress = options.progress;
    return RunGeometryStage(std::move(scene), geometry);
  }
  GeometryStage geometry;
  geometry.scene = std::move(scene);
  if (target > 0) geometry.scene.target_patches = target;
  SubdivisionOptions subdivision;
  subdivision.target_patches = geometry.scene.target_patches;
  std::string why;
  if (!subdivision.Check(&why))  // as the geometry stage
    throw IoError(FlagOf(options, &options.patches) + ": " + why);
  geometry.patches = SubdividePatches(geometry.scene, subdivision);
  return geometry;
}

}  // namespace

CalibratedRoom BuildCalibratedRoom(const CalibratedRoomOptions& options, RoomSources sources) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("room: " + why);
  if (!options.solution_dir.empty() && !sources.solution)
    throw std::invalid_argument("room: the solution was not read (ReadRoomSources)");
  if (!options.rig_dir.empty() && !sources.rig)
    throw std::invalid_argument("room: the rig was not read (ReadRoomSources)");
  CalibratedRoom room;
  room.rig = std::move(sources.rig);
  // A rig without the records its checks read is used as before, but not silently.
  if (room.rig) {
    if (const std::string warning = MissingRegistrationWarning(*room.rig); !warning.empty())
      Report(options.progress, warning);
  }
  room.solution = std::move(sources.solution);
  room.camera_model_path = sources.camera_model_path;
  room.camera = sources.camera;
  const int target =
      options.patches > 0 ? options.patches : (room.solution ? room.solution->target_patches : 0);
  if (!sources.geometry && !sources.scene && options.scene.empty() && !room.solution)
    throw std::invalid_argument("room: no scene: give a scene or a solution (whose scene it is)");
  if (sources.geometry) {
    room.geometry = std::move(*sources.geometry);
    if (room.rig) CheckRegisteredRoom(*room.rig, room.geometry.scene);
  } else {
    Scene scene = sources.scene ? std::move(*sources.scene)
                                : LoadSceneArgument(options.scene.empty() ? room.solution->scene
                                                                          : options.scene);
    // Before the form factors: a room changed since the rig's calibration is one line at once.
    if (room.rig) CheckRegisteredRoom(*room.rig, scene);
    room.geometry = RoomGeometry(options, std::move(scene), target);
  }
  const int n = room.size();
  const std::string scene = room.geometry.scene.path.string();
  if (room.solution && room.solution->patches != n) {
    throw IoError(PatchCountMismatch(
        scene, n, room.geometry.scene.target_patches,
        "the solution (" + (room.solution->dir / "result.json").string() + ")",
        room.solution->patches,
        "the scene changed since `procam compensate` ran (or give --patches as compensate was "
        "given it)"));
  }
  if (options.expected_patches > 0 && options.expected_patches != n) {
    throw IoError(PatchCountMismatch(scene, n, room.geometry.scene.target_patches,
                                     options.expected_by, options.expected_patches,
                                     options.mismatch_hint));
  }
  if (room.rig) ApplyRigReflectance(*room.rig, &room.geometry.patches);

  room.projectors = room.rig ? room.rig->projectors : ReadProjectors(room.geometry.scene);
  if (options.display_bits > 0) {
    for (Projector& projector : room.projectors) {
      if (projector.photometry.bits == options.display_bits) continue;
      Report(options.progress,
             fmt::format("room: projector '{}' is {}-bit; the displays show {} bits, rendering "
                         "at {}",
                         projector.name, projector.photometry.bits, options.display_bits,
                         options.display_bits));
      projector.photometry.bits = options.display_bits;
    }
  }
  if (!room.projectors.empty()) {
    room.projection = BuildProjectionRig(room.fine(), room.projectors, options.projection);
    if (room.rig && options.reflectance_maps && !room.rig->file.reflectance_maps.empty()) {
      const std::vector<cv::Mat> maps = ReadRigReflectanceMaps(*room.rig);
      if (maps.empty()) {
        Report(options.progress,
               fmt::format("room: rig.json has reflectance maps for {} of {} projectors: one "
                           "reflectance per patch",
                           room.rig->file.reflectance_maps.size(), room.projectors.size()));
      } else {
        AttachReflectanceMaps(maps, &room.projection);
        Report(options.progress, "room: each projector pixel's reflectance from the rig's maps");
      }
    }
  }
  if (options.problem) {
    room.problem =
        MakeProblem(room.geometry.scene, room.fine(), room.geometry.form_factors, options.alpha);
    if (room.projection.size() > 0) {
      room.problem.lower = room.projection.lower;
      room.problem.upper = room.projection.upper;
    }
  }
  if (options.camera_rays || options.camera_lighting) {
    Report(options.progress, fmt::format("room: casting the camera's {}x{} rays",
                                         room.camera.width(), room.camera.height()));
    room.camera_rays = CastCameraPixels(
        room.geometry.scene, room.fine(),
        options.camera_lighting ? room.projectors : std::vector<Projector>(), room.camera);
  }
  return room;
}

CalibratedRoom LoadCalibratedRoom(const CalibratedRoomOptions& options) {
  return BuildCalibratedRoom(options, ReadRoomSources(options));
}

ProjectionStageSummary ProjectSolution(const ProjectionStageOptions& options) {
  const auto start = Clock::now();
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("project: " + why);
  const SolutionDirectory solution = ReadSolutionDirectory(options.solution);
  SolutionGeometry geometry = ReadSolutionGeometry(solution, options.patches);
  SolutionProjectors projectors =
      ProjectorsForSolution(solution, options.rig, geometry.scene, &geometry.patches);
  ProjectionStageOptions stage = options;
  stage.load_seconds = SecondsSince(start);
  return RunProjectionStage(solution, geometry, std::move(projectors.projectors),
                            projectors.rig_description, stage, projectors.reflectance_maps);
}

}  // namespace procam
