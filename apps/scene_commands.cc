// procam scene info / scene export / demo.
#include <filesystem>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "apps/commands.h"
#include "apps/compensation_stage.h"
#include "apps/geometry_stage.h"
#include "compensation/problem.h"
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

struct SceneArguments {
  std::string scene;
  std::string out;
  int patches = 0;
  double alpha = 0.5;
};

}  // namespace

void AddSceneCommands(CLI::App& app) {
  CLI::App* scene = app.add_subcommand("scene", "Inspect and export scenes");
  scene->require_subcommand(1);
  auto args = std::make_shared<SceneArguments>();

  CLI::App* info = scene->add_subcommand("info", "Print surfaces, areas, patches and form-factor statistics");
  info->add_option("scene", args->scene, "Scene JSON")->required();
  info->add_option("--patches", args->patches, "Override the scene's target patch count");
  info->callback([args] {
    const GeometryStage stage = RunGeometryStage(args->scene, OptionalPatches(args->patches));
    std::cout << DescribeGeometry(stage);
  });

  CLI::App* export_cmd = scene->add_subcommand("export", "Write the problem as NumPy .npy files and problem.json");
  export_cmd->add_option("scene", args->scene, "Scene JSON")->required();
  export_cmd->add_option("--out", args->out, "Output directory")->required();
  export_cmd->add_option("--patches", args->patches, "Override the scene's target patch count");
  export_cmd->add_option("--alpha", args->alpha, "Weight of the absolute term, in (0,1]")
      ->check(CLI::Range(1e-9, 1.0))
      ->capture_default_str();
  export_cmd->callback([args] {
    const GeometryStage stage = RunGeometryStage(args->scene, OptionalPatches(args->patches));
    ExportStage(stage, args->alpha, args->out);
    std::cout << DescribeGeometry(stage) << "exported to " << args->out << "\n";
  });
}

void AddDemoCommand(CLI::App& app) {
  auto args = std::make_shared<SceneArguments>();
  args->scene = std::string(PROCAM_SOURCE_DIR) + "/data/scenes/room.json";
  args->out = "out/demo";
  CLI::App* demo = app.add_subcommand("demo", "Run every pipeline stage that exists on a bundled scene");
  demo->add_option("--scene", args->scene, "Scene JSON")->capture_default_str();
  demo->add_option("--patches", args->patches, "Override the scene's target patch count");
  demo->add_option("--out", args->out, "Output directory")->capture_default_str();
  demo->callback([args] {
    const std::filesystem::path out = args->out;
    spdlog::info("procam demo on {}", args->scene);
    spdlog::info("stage 1/2: geometry (patches, form factors)");
    const GeometryStage stage = RunGeometryStage(args->scene, OptionalPatches(args->patches));
    std::filesystem::create_directories(out);
    ExportStage(stage, 0.5, out / "problem");
    WriteFormFactorImage(stage.form_factors, out / "form_factors.png");
    std::cout << DescribeGeometry(stage);
    spdlog::info("stage 2/2: compensation (naive, reverse, linear, perceptual)");
    nlohmann::json methods = nlohmann::json::object();
    std::cout << "\n  method        mean ΔE76  max ΔE76  mean ΔE2000  objective      solve s\n";
    for (const CompensationMethod method : {CompensationMethod::kNaive, CompensationMethod::kReverse,
                                            CompensationMethod::kLinear, CompensationMethod::kPerceptual}) {
      SolverOptions options;
      options.method = method;
      options.multires = method == CompensationMethod::kPerceptual;
      const CompensationRun run = RunCompensation(stage, options, 0.5);
      WriteCompensation(stage, run, out / MethodName(method), false);
      methods[MethodName(method)] = CompensationResultJson(stage, run);
      std::cout << fmt::format("  {:<12} {:>10.2f} {:>9.2f} {:>12.2f}  {:<13.6e} {:.3f}\n", MethodName(method),
                               run.mean_delta_e76, run.max_delta_e76, run.mean_delta_e2000,
                               run.perceptual_objective, run.summary.solve_seconds);
    }
    nlohmann::json result;
    result["scene"] = args->scene;
    result["patches"] = stage.patches.fine.size();
    result["coarse_patches"] = stage.patches.coarse.size();
    result["adjacent_pairs"] = stage.patches.fine.adjacency.size();
    result["form_factor_seconds"] = stage.form_factor_summary.seconds;
    result["row_sum"] = {{"min", stage.form_factor_summary.min_row_sum},
                         {"mean", stage.form_factor_summary.mean_row_sum},
                         {"max", stage.form_factor_summary.max_row_sum}};
    result["methods"] = methods;
    WriteFileAtomically(out / "result.json", result.dump(2) + "\n");
    std::cout << "\nwrote " << out.string() << "/: problem/ (NumPy export), form_factors.png, result.json, "
              << "and per method E.npy, B.npy, result.json\n"
              << "(ΔE per patch against the desired appearance, in the solver's model; the simulated "
                 "camera and projector images join the demo as they land)\n";
  });
}

}  // namespace procam
