#include "projection/stage.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <limits>

#include "base/io.h"
#include "base/option_table.h"
#include "base/output_directory.h"
#include "base/timing.h"
#include "geometry/stage.h"

namespace procam {

std::vector<std::pair<std::string, LightField>> LightFieldChoices() {
  return {{LightFieldName(LightField::kSmooth), LightField::kSmooth},
          {LightFieldName(LightField::kFlat), LightField::kFlat}};
}

std::vector<std::pair<std::string, DitherMethod>> DitherChoices() {
  std::vector<std::pair<std::string, DitherMethod>> dithers;
  for (DitherMethod method :
       {DitherMethod::kNone, DitherMethod::kOrdered, DitherMethod::kErrorDiffusion}) {
    dithers.emplace_back(DitherName(method), method);
  }
  return dithers;
}

void ProjectionStageOptions::Declare(OptionTable* table) {
  table->Path("solution", &solution, "directory written by `procam compensate SCENE --out DIR`")
      .Positional()
      .Required();
  table->Path("out", &out, "output directory (PNG per projector, result.json)").Required();
  table->Path("rig", &rig,
              "rig directory whose projectors (and reflectance) to use; default: the rig the "
              "solution was computed with (compensate --rig), else the scene's");
  table->Integer("patches", &patches, 0, std::numeric_limits<int>::max(), "",
                 "patch target given to compensate with --patches, if any (0: the solution's)");
  table
      ->Choice("dither", &dither, DitherChoices(),
               "none (nearest code value), ordered (8×8 Bayer) or error-diffusion "
               "(Floyd–Steinberg), in linear light")
      .Number("feather", &feather, 0.0, 0.5, "of the image size",
              "blending ramp at the image borders")
      .Choice("light", &light, LightFieldChoices(),
              "smooth: the light varies smoothly over each surface, stepping only where the "
              "desired appearance does, each patch's flux kept (seamless); flat: one uniform "
              "level per patch")
      .Flag("detail", &detail,
            "modulate the light within each patch by the desired texture's detail (patch totals "
            "unchanged; untextured surfaces as without)")
      .NegatedFlag("no-reflectance-maps", &reflectance_maps,
                   "leave the rig's per-pixel reflectance maps unused: one level per patch as "
                   "without maps, instead of each pixel's light divided by its point's "
                   "reflectance relative to its patch's");
}

bool ProjectionStageOptions::Check(std::string* why) const {
  if (out.empty()) {
    *why = FlagOf(*this, &out) + ": the images directory is required";
    return false;
  }
  // The table only reads the fields here.
  OptionTable table("project");
  const_cast<ProjectionStageOptions*>(this)->Declare(&table);
  return table.Check(why);
}

SolutionGeometry ReadSolutionGeometry(const SolutionDirectory& solution, int patches_override) {
  SolutionGeometry geometry;
  geometry.scene = LoadSceneArgument(solution.scene);
  const int n = solution.patches;
  // SubdividePatches is deterministic: the target that gave n fine patches gives them again.
  std::vector<int> targets;
  if (patches_override > 0) {
    targets = {patches_override};
  } else {
    targets.push_back(solution.target_patches);
    targets.push_back(geometry.scene.target_patches);
    targets.push_back(n);
  }
  std::string tried;
  for (const int target : targets) {
    SubdivisionOptions subdivision;
    subdivision.target_patches = std::max(target, 4);
    geometry.patches = SubdividePatches(geometry.scene, subdivision);
    if (geometry.patches.fine.size() == n) {
      geometry.scene.target_patches = target;
      return geometry;
    }
    tried += (tried.empty() ? "" : ", ") + std::to_string(geometry.patches.fine.size()) +
             " for target " + std::to_string(target);
  }
  throw IoError((solution.dir / "result.json").string() + ": the solution has " +
                std::to_string(n) + " patches but " + geometry.scene.path.string() +
                " subdivides into " + tried +
                ": the scene changed since `procam compensate` ran (or give --patches as it was "
                "given to compensate)");
}

ProjectionStageSummary RunProjectionStage(const SolutionDirectory& solution,
                                          const SolutionGeometry& geometry,
                                          std::vector<Projector> projectors,
                                          const nlohmann::json& rig_description,
                                          const ProjectionStageOptions& args,
                                          const std::vector<cv::Mat>& reflectance_maps) {
  const auto start = Clock::now();
  std::string why;
  if (!args.Check(&why)) throw std::invalid_argument("project: " + why);
  if (projectors.empty()) {
    throw IoError(geometry.scene.path.string() +
                  ": projectors: the scene lists no projectors (add a \"projectors\" array: "
                  "docs/scene_format.md)");
  }
  ProjectionStageSummary result_summary;
  ProjectionRigOptions rig_options;
  rig_options.feather = args.feather;
  rig_options.texture_coordinates = args.detail;
  ProjectionRigSummary& rig_summary = result_summary.rig;
  Report(args.progress, fmt::format("project: casting rays for {} projector(s) over {} patches",
                                    projectors.size(), geometry.patches.fine.size()));
  ProjectionRig rig =
      BuildProjectionRig(geometry.patches.fine, std::move(projectors), rig_options, &rig_summary);
  if (args.reflectance_maps && !reflectance_maps.empty())
    AttachReflectanceMaps(reflectance_maps, &rig);
  RenderOptions render_options;
  render_options.dither = args.dither;
  render_options.detail = args.detail;
  render_options.light = args.light;
  render_options.reflectance = HasReflectanceMaps(rig);
  RenderSummary& summary = result_summary.render;
  const std::vector<ProjectorImage> images =
      RenderProjectorImages(rig, geometry.scene, solution.emittance, render_options, &summary);

  const auto write_start = Clock::now();
  const std::filesystem::path& out = args.out;
  CheckOutputDirectory(out, DirectoryKind::kProjectorImages);
  // Written beside `out`, then swapped in: the directory holds the earlier images or these.
  ReplacedDirectory replaced(out);
  const std::filesystem::path& dir = replaced.staging();
  double write_seconds = 0.0;
  try {
    const std::vector<std::string> encoded = EncodeProjectorImages(images);
    nlohmann::json projector_json = nlohmann::json::array();
    for (size_t k = 0; k < images.size(); ++k) {
      const Projector& projector = rig.projectors[k];
      const std::string image_name = projector.name + ".png";
      WriteFileAtomically(dir / image_name, encoded[k]);
      projector_json.push_back({{"name", projector.name},
                                {"image", image_name},
                                {"model", projector.model_path.string()},
                                {"width", projector.geometry.width()},
                                {"height", projector.geometry.height()},
                                {"bits", images[k].bits},
                                {"lit_pixels", rig.maps[k].lit_pixels},
                                {"patches_reached", rig.maps[k].patches_reached},
                                {"saturated_pixels", summary.saturated_pixels[k]},
                                {"detail_saturated_pixels", summary.detail_saturated_pixels[k]},
                                {"clipped_pixels", summary.clipped_pixels[k]}});
    }
    WriteNpy(dir / "E_delivered.npy", RowMatrixXd(summary.delivered));
    WriteNpy(dir / "lower.npy", RowMatrixXd(rig.lower));
    WriteNpy(dir / "upper.npy", RowMatrixXd(rig.upper));
    write_seconds = SecondsSince(write_start);
    nlohmann::json result = {{"solution", solution.dir.string()},
                             {"scene", geometry.scene.path.string()},
                             {"patches", rig.size()},
                             {"target_patches", geometry.scene.target_patches},
                             {"projectors", projector_json},
                             {"dither", DitherName(args.dither)},
                             {"feather", args.feather},
                             {"detail", args.detail},
                             {"light", LightFieldName(args.light)},
                             {"reflectance_maps", render_options.reflectance},
                             {"reflectance_pixels", summary.reflectance_pixels},
                             {"reflectance_saturated_pixels", summary.reflectance_saturated_pixels},
                             {"detail_pixels", summary.detail_pixels},
                             {"patches_reached", rig_summary.patches_reached},
                             {"patches_unreached", summary.patches_unreached},
                             {"patches_below_lower", summary.patches_below_lower},
                             {"patches_above_upper", summary.patches_above_upper},
                             {"level_passes", summary.level_passes},
                             {"max_relative_error", summary.max_relative_error},
                             {"seconds",
                              {{"load", args.load_seconds},
                               {"maps", rig_summary.seconds},
                               {"render", summary.seconds},
                               {"write", write_seconds},
                               {"total", args.load_seconds + SecondsSince(start)}}}};
    if (!rig_description.is_null()) result["rig"] = rig_description;
    WriteFileAtomically(dir / "result.json", result.dump(2) + "\n");
  } catch (const IoError& error) {
    throw IoError(out.string() + ": left as it was; writing the new images beside it failed: " +
                  error.what());
  }
  replaced.Commit();

  for (size_t k = 0; k < images.size(); ++k) {
    Report(args.progress,
           fmt::format("{:<12} {}x{}, {}-bit: {} lit pixels, {} patches, {} saturated",
                       rig.projectors[k].name, rig.projectors[k].geometry.width(),
                       rig.projectors[k].geometry.height(), images[k].bits, rig.maps[k].lit_pixels,
                       rig.maps[k].patches_reached, summary.saturated_pixels[k]));
  }
  Report(
      args.progress,
      fmt::format("patches: {}, {} reached by no projector; E outside the projectors' bounds on {} "
                  "(below) / {} (above)",
                  rig.size(), summary.patches_unreached, summary.patches_below_lower,
                  summary.patches_above_upper));
  if (summary.patches_below_lower + summary.patches_above_upper > 0) {
    Report(args.progress,
           "  (clipped: was the solution computed with the scene's `bounds` instead of its "
           "projectors?)");
  }
  if (args.detail) {
    long long clipped = 0;
    for (const long long count : summary.detail_saturated_pixels) clipped += count;
    Report(args.progress,
           fmt::format(
               "detail: {} lit pixels on textured surfaces, {} with highlights clipped at full "
               "drive",
               summary.detail_pixels, clipped));
    if (summary.detail_pixels == 0)
      Report(args.progress, "  (no surface the projectors light has a texture)");
  }
  if (render_options.reflectance) {
    Report(args.progress,
           fmt::format("reflectance: {} lit pixels shaped by their point's measured reflectance, "
                       "{} ({:.2f}%) at full drive where their point is too dark for the "
                       "projectors' range",
                       summary.reflectance_pixels, summary.reflectance_saturated_pixels,
                       100.0 * summary.reflectance_saturated_pixels /
                           std::max<long long>(1, summary.reflectance_pixels)));
  }
  Report(
      args.progress,
      fmt::format("largest error of the delivered emittance {:.2e} (relative to the largest upper "
                  "bound)",
                  summary.max_relative_error));
  Report(
      args.progress,
      fmt::format("maps {:.3f} s, images {:.3f} s, writing {:.3f} s\nwrote {}/result.json and {} "
                  "image(s)",
                  rig_summary.seconds, summary.seconds, write_seconds, args.out.string(),
                  images.size()));
  result_summary.images = images;
  return result_summary;
}

}  // namespace procam
