// procam scene info / scene export / demo.
#include <filesystem>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include "apps/commands.h"
#include "apps/compensation_stage.h"
#include "apps/evaluation.h"
#include "apps/geometry_stage.h"
#include "apps/report.h"
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


// A scene file without a camera: geometry and compensation, numbers per patch.
void RunJsonDemo(const std::string& scene_path, int patches, const std::filesystem::path& out) {
  spdlog::info("procam demo on {}: stage 1/2 geometry", scene_path);
  const GeometryStage stage = RunGeometryStage(scene_path, OptionalPatches(patches));
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
                             run.mean_delta_e76, run.max_delta_e76, run.mean_delta_e2000, run.perceptual_objective,
                             run.summary.solve_seconds);
  }
  nlohmann::json result = {{"scene", scene_path}, {"patches", stage.patches.fine.size()}, {"methods", methods}};
  WriteFileAtomically(out / "result.json", result.dump(2) + "\n");
  std::cout << "\nwrote " << out.string() << "/: problem/, form_factors.png, result.json, per method E.npy, B.npy\n"
            << "(a scene file has no camera: ΔE here is per patch, in the solver's model)\n";
}

// The whole pipeline on the synthetic rig, ending in report.html.
void RunSyntheticDemo(const std::string& scene, int patches, const std::filesystem::path& out) {
  EvaluationOptions options;
  options.patches = patches;
  spdlog::info("procam demo on the synthetic '{}' rig ({} patches): geometry → compensation (4 methods) → "
               "projector images → simulated photos → ΔE → report",
               scene, patches);
  const SceneEvaluation evaluation = EvaluateSyntheticScene(scene, options);
  const auto files = WriteEvaluationPictures(evaluation, out);
  WriteFormFactorImage(evaluation.geometry.form_factors, out / "form_factors.png");
  ExportStage(evaluation.geometry, options.alpha, out / "problem");
  for (const MethodEvaluation& m : evaluation.methods) {
    WriteCompensation(evaluation.geometry, m.run, out / MethodName(m.method), false);
  }
  const nlohmann::json result = EvaluationJson(evaluation);
  WriteFileAtomically(out / "result.json", result.dump(2) + "\n");

  HtmlReport report("procam demo: " + scene);
  report.Paragraph(fmt::format(
      "{} solver patches ({} variables), {} projectors, a {}×{} camera; the simulated room uses a {}-patch mesh, exact "
      "direct light per camera pixel and its own radiosity solution, so the solver's model is not the world.",
      evaluation.geometry.patches.fine.size(), 3 * evaluation.geometry.patches.fine.size(),
      evaluation.world->projectors().size(), evaluation.world->camera().width(), evaluation.world->camera().height(),
      evaluation.world->world().size()));
  std::vector<std::vector<std::string>> rows;
  std::vector<HtmlReport::Series> traces;
  for (const MethodEvaluation& m : evaluation.methods) {
    rows.push_back({MethodName(m.method), fmt::format("{:.2f}", m.mean_delta_e76), fmt::format("{:.1f}", m.max_delta_e76),
                    fmt::format("{:.2f}", m.mean_delta_e2000), fmt::format("{:.1f}", m.max_delta_e2000),
                    fmt::format("{:.4g}", m.run.perceptual_objective), std::to_string(m.run.summary.iterations),
                    fmt::format("{:.3f}", m.run.summary.solve_seconds), TerminationName(m.run.summary.termination)});
    if (m.run.summary.trace.size() > 1) {
      std::vector<std::pair<double, double>> points;
      for (const IterationRecord& record : m.run.summary.trace) points.emplace_back(record.iteration, record.cost);
      traces.emplace_back(std::string(MethodName(m.method)) + " (own objective)", points);
    }
  }
  report.Heading("Colour error per camera pixel");
  report.Table({"method", "mean ΔE76", "max ΔE76", "mean ΔE2000", "max ΔE2000", "objective (L*a*b*)", "iterations",
                "solve s", "termination"},
               rows);
  report.Heading("Pictures");
  std::vector<std::pair<std::string, cv::Mat>> figures;
  for (const auto& [caption, name] : files) figures.emplace_back(caption, cv::imread((out / name).string()));
  report.Figures(figures);
  report.Heading("Solver convergence");
  report.Plot("objective per outer iteration", "iteration", "objective", traces);
  report.Heading("Projector images (perceptual)");
  std::vector<std::pair<std::string, cv::Mat>> projector_images;
  for (size_t k = 0; k < evaluation.world->projectors().size(); ++k) {
    projector_images.emplace_back(evaluation.world->projectors()[k].name,
                                  cv::imread((out / "perceptual" / fmt::format("projector_{}.png", k)).string()));
  }
  report.Figures(projector_images);
  report.Heading("Form factors");
  report.Figures({{"log10 F (rows: emitting patch, columns: receiving patch)", cv::imread((out / "form_factors.png").string())}});
  report.Write(out / "report.html");
  std::cout << "\n  method        mean ΔE76  max ΔE76  mean ΔE2000  max ΔE2000\n";
  for (const MethodEvaluation& m : evaluation.methods) {
    std::cout << fmt::format("  {:<12} {:>10.2f} {:>9.1f} {:>12.2f} {:>11.1f}\n", MethodName(m.method), m.mean_delta_e76,
                             m.max_delta_e76, m.mean_delta_e2000, m.max_delta_e2000);
  }
  std::cout << "\nwrote " << (out / "report.html").string() << " (open it in a browser), pictures, result.json, "
            << "problem/ and per method E.npy, B.npy and projector images\n";
}

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
  args->scene = "c_shaped";
  args->out = "out/demo";
  args->patches = 600;
  CLI::App* demo = app.add_subcommand(
      "demo", "Every pipeline stage on the synthetic rig: geometry, compensation (4 methods), projector images, "
              "simulated photos, ΔE, report.html");
  demo->add_option("--scene", args->scene,
                   "A synthetic scene (c_shaped, l_shaped, columns, green_trapezoid, interior_partitions, blue_curves, "
                   "tiny_box) or a scene JSON file (geometry and compensation only)")
      ->capture_default_str();
  demo->add_option("--patches", args->patches, "Solver patches")->capture_default_str();
  demo->add_option("--out", args->out, "Output directory")->capture_default_str();
  demo->callback([args] {
    const std::filesystem::path out = args->out;
    std::filesystem::create_directories(out);
    if (args->scene.size() > 5 && args->scene.substr(args->scene.size() - 5) == ".json") {
      RunJsonDemo(args->scene, args->patches, out);
      return;
    }
    RunSyntheticDemo(args->scene, args->patches, out);
  });
}

}  // namespace procam
