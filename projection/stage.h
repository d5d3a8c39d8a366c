#pragma once
// The projection stage: a compensation solution (compensation/stage.h) → one image per projector,
// blended where projectors overlap and dithered (projector_images.h), written into an images
// directory: NAME.png per projector, E_delivered.npy (the emittance the images deliver),
// lower.npy / upper.npy (the projectors' bounds) and result.json. What `procam project` runs.

#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>
#include <string>
#include <utility>
#include <vector>

#include "base/progress.h"
#include "compensation/stage.h"
#include "geometry/patches.h"
#include "geometry/scene.h"
#include "projection/projection_rig.h"
#include "projection/projector_images.h"

namespace procam {

class OptionTable;

// The scene and patches a solution was computed on: its scene (LoadSceneArgument) subdivided by
// the patch target that gives the solution's patch count (`patches_override` > 0: that target;
// else the solution's target_patches, the scene's, or the count itself).
struct SolutionGeometry {
  Scene scene;
  PatchHierarchy patches;
};
// Throws IoError naming the solution's result.json when no target reproduces its patches (the
// scene changed since), and every error of the scene.
SolutionGeometry ReadSolutionGeometry(const SolutionDirectory& solution, int patches_override = 0);

// The names --light and --dither take (OptionTable::Choice), for every command that declares
// them.
std::vector<std::pair<std::string, LightField>> LightFieldChoices();
std::vector<std::pair<std::string, DitherMethod>> DitherChoices();

struct ProjectionStageOptions {
  // What `procam project` reads (ProjectSolution, projection/calibrated_room.h): the solution
  // directory, the rig whose projectors show it (empty: the rig the solution was computed with,
  // else the scene's projectors) and the patch target compensate was given (0: the solution's).
  std::filesystem::path solution, rig;
  int patches = 0;
  std::filesystem::path out;  // the images directory (created)
  DitherMethod dither = DitherMethod::kOrdered;
  double feather = 0.1;  // blending ramp at the edge of each projector's image, (0, 1]
  bool detail = false;   // the desired texture's detail within patches (projector_images.h)
  LightField light = LightField::kSmooth;  // seamless light, or flat per patch (projector_images.h)
  // Divide each pixel's light by its point's measured reflectance relative to its patch's when
  // the rig has reflectance maps (RenderOptions::reflectance); false: per patch, as without maps.
  bool reflectance_maps = true;
  double load_seconds = 0.0;               // what reading the inputs took, for result.json
  ProgressCallback progress;  // per projector: pixels lit, patches, saturation; bounds; times
  // Declares the solution (positional), --out, --rig, --patches, --dither, --feather, --light,
  // --detail and --no-reflectance-maps in `table`, bound to these fields (base/option_table.h).
  void Declare(OptionTable* table);
  // The declared options within their ranges and choices, an output directory and a solution.
  bool Check(std::string* why) const;
};

struct ProjectionStageSummary {
  ProjectionRigSummary rig;
  RenderSummary render;
  std::vector<ProjectorImage> images;  // in the projectors' order
};

// Renders `solution.emittance` with `projectors` on `geometry` (whose fine reflectance the
// projectors' bounds use) and writes the images directory. `rig_description` (may be null) is
// recorded in result.json as "rig". `reflectance_maps`: one per projector (the rig's,
// SolutionProjectors::reflectance_maps) or none; with them (and options.reflectance_maps) each
// pixel's light is divided by its point's reflectance relative to its patch's. Throws IoError
// naming the projector or the file.
ProjectionStageSummary RunProjectionStage(const SolutionDirectory& solution,
                                          const SolutionGeometry& geometry,
                                          std::vector<Projector> projectors,
                                          const nlohmann::json& rig_description,
                                          const ProjectionStageOptions& options,
                                          const std::vector<cv::Mat>& reflectance_maps = {});

}  // namespace procam
