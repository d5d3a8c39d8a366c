// procam: one binary, one subcommand per pipeline stage. Errors from files and devices are
// caught here once and turned into one line on stderr and a non-zero exit.

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "apps/geometry_stage.h"
#include "compensation/problem.h"
#include "datasets_synthetic/rooms.h"
#include "geometry/io.h"
#include "procam/config.h"

namespace procam {
namespace {

std::optional<int> OptionalPatches(int patches) {
  return patches > 0 ? std::optional<int>(patches) : std::nullopt;
}

void ExportStage(const GeometryStage& stage, double alpha, const std::filesystem::path& out) {
  const CompensationProblem problem = MakeProblem(stage.scene, stage.patches.fine, stage.form_factors, alpha);
  const std::string invalid = problem.Validate();
  if (!invalid.empty()) throw IoError(stage.scene.path.string() + ": " + invalid);
  nlohmann::json settings;
  settings["scene"] = stage.scene.path.string();
  settings["scene_name"] = stage.scene.name;
  settings["white"] = stage.scene.white;
  settings["form_factor_seconds"] = stage.form_factor_summary.seconds;
  ExportProblem(problem, stage.patches.fine, stage.patches.coarse_of_fine, out, settings.dump());
}

int RunSceneInfo(const std::string& scene_path, int patches) {
  const GeometryStage stage = RunGeometryStage(scene_path, OptionalPatches(patches));
  std::cout << DescribeGeometry(stage);
  return 0;
}

int RunSceneExport(const std::string& scene_path, int patches, double alpha, const std::string& out) {
  const GeometryStage stage = RunGeometryStage(scene_path, OptionalPatches(patches));
  ExportStage(stage, alpha, out);
  std::cout << DescribeGeometry(stage) << "exported to " << out << "\n";
  return 0;
}

int RunDemo(const std::string& scene_path, int patches, const std::string& out) {
  spdlog::info("procam demo: geometry stage on {}", scene_path);
  const GeometryStage stage = RunGeometryStage(scene_path, OptionalPatches(patches));
  std::filesystem::create_directories(out);
  ExportStage(stage, 0.5, std::filesystem::path(out) / "problem");
  WriteFormFactorImage(stage.form_factors, std::filesystem::path(out) / "form_factors.png");
  nlohmann::json result;
  result["stage"] = "geometry";
  result["scene"] = scene_path;
  result["patches"] = stage.patches.fine.size();
  result["coarse_patches"] = stage.patches.coarse.size();
  result["adjacent_pairs"] = stage.patches.fine.adjacency.size();
  result["form_factor_seconds"] = stage.form_factor_summary.seconds;
  result["row_sum"] = {{"min", stage.form_factor_summary.min_row_sum},
                       {"mean", stage.form_factor_summary.mean_row_sum},
                       {"max", stage.form_factor_summary.max_row_sum}};
  WriteFileAtomically(std::filesystem::path(out) / "result.json", result.dump(2) + "\n");
  std::cout << DescribeGeometry(stage);
  std::cout << "wrote " << out << "/problem/ (NumPy export), " << out << "/form_factors.png, " << out
            << "/result.json\n"
            << "next stages (compensation, projection, simulated photo) join the demo as they land\n";
  return 0;
}

int RunBenchFormFactors(int patches, int threads, const std::string& json_path) {
  BoxRoomOptions room;
  room.target_patches = patches;
  room.occluder = true;
  Scene scene = MakeBoxRoom(room);
  SubdivisionOptions subdivision;
  subdivision.target_patches = patches;
  const PatchHierarchy hierarchy = SubdividePatches(scene, subdivision);
  FormFactorOptions options;
  options.threads = threads;
  FormFactorSummary summary;
  ComputeFormFactors(scene, hierarchy.fine, options, &summary);
  std::printf("form factors, closed room with occluder: %d patches, %lld facing pairs, %lld shadow rays\n",
              hierarchy.fine.size(), static_cast<long long>(summary.pairs_evaluated),
              static_cast<long long>(summary.shadow_rays));
  std::printf("  time %.3f s (%d threads); row sums min %.5f mean %.5f max %.5f\n", summary.seconds,
              threads, summary.min_row_sum, summary.mean_row_sum, summary.max_row_sum);
  if (!json_path.empty()) {
    nlohmann::json result = {{"benchmark", "form_factors"}, {"patches", hierarchy.fine.size()},
                             {"seconds", summary.seconds}, {"threads", threads},
                             {"pairs", summary.pairs_evaluated}, {"shadow_rays", summary.shadow_rays},
                             {"min_row_sum", summary.min_row_sum}, {"max_row_sum", summary.max_row_sum}};
    WriteFileAtomically(json_path, result.dump(2) + "\n");
  }
  return 0;
}

}  // namespace
}  // namespace procam

int main(int argc, char** argv) {
  using namespace procam;
  CLI::App app{"procam: make a white room look like a desired scene with projectors, "
               "interreflections included (Sheng et al., EGSR 2011)"};
  app.set_version_flag("--version", PROCAM_VERSION);
  app.require_subcommand(1);

  const std::string default_scene = std::string(PROCAM_SOURCE_DIR) + "/data/scenes/room.json";
  std::string scene_path = default_scene, out = "out/demo";
  int patches = 0;
  double alpha = 0.5;
  int threads = 0;
  std::string json_path;

  CLI::App* demo = app.add_subcommand("demo", "Run every pipeline stage that exists on a bundled scene");
  demo->add_option("--scene", scene_path, "Scene JSON")->capture_default_str();
  demo->add_option("--patches", patches, "Override the scene's target patch count");
  demo->add_option("--out", out, "Output directory")->capture_default_str();

  CLI::App* scene = app.add_subcommand("scene", "Inspect and export scenes");
  scene->require_subcommand(1);
  CLI::App* info = scene->add_subcommand("info", "Print surfaces, areas, patches and form-factor statistics");
  info->add_option("scene", scene_path, "Scene JSON")->required();
  info->add_option("--patches", patches, "Override the scene's target patch count");
  CLI::App* export_cmd = scene->add_subcommand("export", "Write the problem as NumPy .npy files and problem.json");
  export_cmd->add_option("scene", scene_path, "Scene JSON")->required();
  export_cmd->add_option("--out", out, "Output directory")->required();
  export_cmd->add_option("--patches", patches, "Override the scene's target patch count");
  export_cmd->add_option("--alpha", alpha, "Weight of the absolute term, in (0,1]")
      ->check(CLI::Range(1e-9, 1.0))->capture_default_str();

  CLI::App* bench = app.add_subcommand("bench", "Benchmarks");
  bench->require_subcommand(1);
  int bench_patches = 4096;
  CLI::App* bench_ff = bench->add_subcommand("formfactors", "Form factors of a closed room with an occluder");
  bench_ff->add_option("--patches", bench_patches, "Target patch count")->capture_default_str();
  bench_ff->add_option("--threads", threads, "Worker threads (0: all cores)")->capture_default_str();
  bench_ff->add_option("--json", json_path, "Also write the result as JSON here");

  CLI11_PARSE(app, argc, argv);
  try {
    if (*demo) return RunDemo(scene_path, patches, out);
    if (*info) return RunSceneInfo(scene_path, patches);
    if (*export_cmd) return RunSceneExport(scene_path, patches, alpha, out);
    if (*bench_ff) return RunBenchFormFactors(bench_patches, threads, json_path);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "procam: error: %s\n", error.what());
    return 1;
  }
  return 1;
}
