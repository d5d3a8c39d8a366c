#include "datasets_synthetic/scene_info.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <vector>

#include "base/io.h"
#include "base/option_table.h"
#include "base/output_directory.h"
#include "capture/pixel_format.h"
#include "capture/scene_cameras.h"
#include "compensation/stage.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/scene_files.h"
#include "projection/projector.h"

namespace procam {
namespace {

GeometryStage RunGeometry(const SceneFileOptions& options) {
  GeometryOptions geometry;
  geometry.patches = options.patches;
  geometry.progress = options.progress;
  return RunGeometryStage(options.scene, geometry);
}

}  // namespace

void SceneFileOptions::DeclareInfo(OptionTable* table) {
  table->Text("scene", &scene, "scene JSON, or PREFIX:NAME").Positional().Required();
  table->Integer("patches", &patches, 0, std::numeric_limits<int>::max(), "",
                 "the scene's target patch count instead (0: the scene's)");
}

void SceneFileOptions::DeclareWrite(OptionTable* table) {
  table
      ->Text(
          "scene", &scene,
          "a synthetic scene (" + fmt::format("{}", fmt::join(SyntheticSceneNames(), ", ")) + ")")
      .Positional()
      .Required();
  table->Path("out", &out, "output directory").Required();
  table->Integer("patches", &patches, 0, std::numeric_limits<int>::max(), "",
                 "the scene file's patch target (0: 1000)");
}

void SceneFileOptions::DeclareExport(OptionTable* table) {
  DeclareInfo(table);
  table->Path("out", &out, "output directory").Required();
  table->Number("alpha", &alpha, 1e-9, 1.0, "", "weight of the absolute term");
}

bool SceneFileOptions::Check(std::string* why) const {
  SceneFileOptions copy = *this;
  if (copy.out.empty()) copy.out = ".";  // scene info writes nothing
  OptionTable table("scene");
  copy.DeclareExport(&table);
  return table.Check(why);
}

std::string DescribeGeometry(const GeometryStage& stage) {
  std::string out;
  const Scene& scene = stage.scene;
  out +=
      "scene " + scene.name + (scene.path.empty() ? "" : " (" + scene.path.string() + ")") + "\n";
  std::vector<int> fine_count(scene.surfaces.size(), 0), coarse_count(scene.surfaces.size(), 0);
  for (const Patch& patch : stage.patches.fine.patches) ++fine_count[patch.surface];
  for (const Patch& patch : stage.patches.coarse.patches) ++coarse_count[patch.surface];
  out += fmt::format("  {:<20} {:>6} {:>10} {:>7} {:>7} {:>18} {}\n", "surface", "kind", "area m²",
                     "fine", "coarse", "reflectance", "desired");
  for (size_t s = 0; s < scene.surfaces.size(); ++s) {
    const Surface& surface = scene.surfaces[s];
    const std::string desired =
        surface.desired.HasTexture()
            ? "texture " + surface.desired.texture_path
            : fmt::format("sRGB {:.2f} {:.2f} {:.2f}", surface.desired.srgb[0],
                          surface.desired.srgb[1], surface.desired.srgb[2]);
    out += fmt::format("  {:<20} {:>6} {:>10.3f} {:>7} {:>7}   {:.2f} {:.2f} {:.2f}   {}\n",
                       surface.name, surface.kind == Surface::Kind::kQuad ? "quad" : "mesh",
                       surface.Area(), fine_count[s], coarse_count[s], surface.reflectance[0],
                       surface.reflectance[1], surface.reflectance[2], desired);
  }
  const Eigen::VectorXd areas = stage.patches.fine.Areas();
  const FormFactorSummary& ff = stage.form_factor_summary;
  out += fmt::format(
      "  total area {:.3f} m², {} fine patches (target {}), {} coarse, {} adjacent pairs\n",
      scene.Area(), stage.patches.fine.size(), scene.target_patches, stage.patches.coarse.size(),
      stage.patches.fine.adjacency.size());
  out += fmt::format("  patch area min {:.4g} mean {:.4g} max {:.4g} m² (max/min {:.2f})\n",
                     areas.minCoeff(), areas.mean(), areas.maxCoeff(),
                     areas.maxCoeff() / areas.minCoeff());
  out += fmt::format(
      "  form factor row sums min {:.5f} mean {:.5f} max {:.5f}; reciprocity error {:.1e}\n",
      ff.min_row_sum, ff.mean_row_sum, ff.max_row_sum, ff.max_reciprocity_error);
  out += fmt::format(
      "  form factors: {} facing pairs, {} shadow rays, {:.2f} s; subdivision {:.3f} s\n",
      ff.pairs_evaluated, ff.shadow_rays, ff.seconds, stage.subdivision_seconds);
  return out;
}

std::string DescribeScene(const GeometryStage& stage) {
  std::string text = DescribeGeometry(stage);
  for (const Projector& projector : ReadProjectors(stage.scene)) {
    const ProjectorGeometry& geometry = projector.geometry;
    text += fmt::format("  projector {:<12} {}x{}  {}\n", projector.name, geometry.width(),
                        geometry.height(), projector.model_path.string());
  }
  const Scene& scene = stage.scene;
  for (const SceneCamera& camera :
       ParseSceneCameras(scene.cameras_json, scene.path.string(), scene.path.parent_path())) {
    text += fmt::format("  camera    {:<12} {}x{}  {}  {}\n", camera.name, camera.model.width,
                        camera.model.height, PixelFormatName(camera.settings.pixel_format),
                        camera.model_path.string());
  }
  return text;
}

std::string DescribeSceneFile(const SceneFileOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument(why);
  return DescribeScene(RunGeometry(options));
}

std::filesystem::path WriteSceneFile(const SceneFileOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument(why);
  const std::vector<std::string> names = SyntheticSceneNames();
  if (std::find(names.begin(), names.end(), options.scene) == names.end()) {
    throw std::invalid_argument("scene write: unknown synthetic scene '" + options.scene +
                                "' (scenes: " + fmt::format("{}", fmt::join(names, ", ")) + ")");
  }
  return WriteSyntheticSceneFile(options.scene, options.patches > 0 ? options.patches : 1000,
                                 options.out);
}

std::string ExportSceneProblem(const SceneFileOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument(why);
  CheckNotProcamDirectory(options.out, "scene export",
                          FlagOf(options, &options.out, &SceneFileOptions::DeclareExport));
  const GeometryStage stage = RunGeometry(options);
  const std::string description = DescribeScene(stage);  // checks the projectors first
  ExportGeometryProblem(stage, options.alpha, options.out);
  return description;
}

void CheckNotProcamDirectory(const std::filesystem::path& dir, const std::string& command,
                             const std::string& option) {
  std::error_code error;
  if (std::filesystem::exists(dir, error) && !std::filesystem::is_directory(dir, error)) {
    throw IoError(dir.string() + ": " + option + " must be a directory, and this is a file");
  }
  if (const std::optional<DirectoryKind> found = DirectoryKindOf(dir)) {
    throw IoError(dir.string() + ": " + option + " is " + DirectoryKindName(*found) + "; " +
                  command + " would write its own files into it: give a new directory");
  }
}

}  // namespace procam
