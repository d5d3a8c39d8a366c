#include "datasets_synthetic/evaluation.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <chrono>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>

#include "base/html_report.h"
#include "base/image_io.h"
#include "base/io.h"
#include "base/timing.h"
#include "compensation/colour.h"
#include "compensation/colour_image.h"
#include "compensation/objective.h"
#include "compensation/solver.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/scene_info.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "projection/camera_rays.h"

namespace procam {

void EvaluationOptions::Declare(OptionTable* table) {
  std::vector<CompensationMethod>* compared = &methods;
  std::string names;
  for (const std::string& name : SyntheticSceneNames()) names += (names.empty() ? "" : ", ") + name;
  // The scenes are required on the command line; EvaluateSyntheticScene takes its own.
  table->Texts("scenes", &scenes, "synthetic scenes (" + names + ") or 'all'").Positional();
  table->Path("out", &out, "output directory");
  table
      ->Integer("patches", &patches, 4, std::numeric_limits<int>::max(), "",
                "solver patches per scene")
      .Integer("world-factor", &world_factor, 1, 1000, "",
               "world mesh patches per solver patch (the simulated room)")
      .Number("alpha", &alpha, 1e-9, 1.0, "", "weight of the absolute term")
      .List(
          "methods",
          [compared] {
            std::vector<std::string> names;
            for (CompensationMethod method : *compared) names.push_back(MethodName(method));
            return names;
          },
          [compared](const std::vector<std::string>& names, std::string* why) {
            std::vector<CompensationMethod> parsed;
            for (const std::string& name : names) {
              CompensationMethod method;
              if (!ParseMethod(name, &method)) {
                *why = "'" + name + "': naive, reverse, linear, perceptual or perceptual2000";
                return false;
              }
              parsed.push_back(method);
            }
            *compared = std::move(parsed);
            return true;
          },
          "methods of naive, reverse, linear, perceptual, perceptual2000", "methods to compare")
      .Sets(compared)
      .Choice("loss", &loss, RobustLossChoices(), "perceptual2000's loss")
      .Number("loss-scale", &loss_scale, 1e-6, 1e6, "ΔE00", "perceptual2000's loss scale")
      .Choice("metric-update", &metric_update, MetricUpdateChoices(),
              "perceptual2000's metric measured again: every_iteration (inside one Gauss-Newton "
              "run) or rounds (each a whole solve)")
      .Choice("light", &render.light,
              {{LightFieldName(LightField::kSmooth), LightField::kSmooth},
               {LightFieldName(LightField::kFlat), LightField::kFlat}},
              "smooth: the light varies smoothly over each surface, stepping only where the "
              "desired appearance does (seamless); flat: one uniform level per patch")
      .Choice<bool>("bounce", &smooth_bounce, {{"smooth", true}, {"patch", false}},
                    "the simulated room's bounce light: smooth (continuous over each surface, as "
                    "in a real room) or patch (constant over each world-mesh patch, whose borders "
                    "then show as steps)");
}

bool EvaluationOptions::Check(std::string* why) const {
  if (!CheckDeclared(*this, why)) return false;
  if (patches < 4 || world_factor < 1 || methods.empty() || !(alpha > 0.0 && alpha <= 1.0)) {
    *why = "need patches >= 4, world_factor >= 1, at least one method, alpha in (0,1]";
    return false;
  }
  if (!render.Check(why)) return false;
  return true;
}

void PixelDeltaE(const cv::Mat& result, const SceneEvaluation& scene, const Eigen::Matrix3d& rgb_to_xyz,
                 const Eigen::Vector3d& white_xyz, MethodEvaluation* evaluation) {
  const LabConverter lab{rgb_to_xyz, white_xyz};
  const cv::Mat lab_result = LabImage(result, lab), lab_desired = LabImage(scene.desired, lab);
  const ImageDeltaE delta_e = CompareLabImages(lab_result, lab_desired, scene.world->coverage());
  evaluation->seams = MeasureSeams(lab_result, lab_desired, scene.camera_patch, scene.rig->surface);
  evaluation->delta_e76 = delta_e.delta_e76;
  evaluation->delta_e2000 = delta_e.delta_e2000;
  evaluation->mean_delta_e76 = delta_e.mean76;
  evaluation->mean_delta_e2000 = delta_e.mean2000;
  evaluation->max_delta_e76 = delta_e.max76;
  evaluation->max_delta_e2000 = delta_e.max2000;
}

SceneEvaluation EvaluateSyntheticScene(const std::string& name, const EvaluationOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("evaluate: " + why);
  const auto start = Clock::now();
  SceneEvaluation evaluation;
  evaluation.name = name;
  // A built-in scene, or a scene file with projectors and a camera (as synthetic:ROOM.json).
  const SyntheticRigSource source = LoadSyntheticRig(name, options.patches);
  Report(options.progress, fmt::format("evaluate {}: geometry ({} patches)", name, options.patches));
  GeometryOptions geometry;
  geometry.patches = options.patches;
  geometry.progress = options.progress;
  Scene scene = source.scene;
  // What solutions record, so that later stages can rebuild it.
  if (scene.path.empty()) scene.path = "synthetic:" + name;
  evaluation.geometry = RunGeometryStage(std::move(scene), geometry);
  const std::vector<Projector>& projectors = source.projectors;
  evaluation.rig = std::make_unique<ProjectionRig>(
      BuildProjectionRig(evaluation.geometry.patches.fine, projectors, ProjectionRigOptions()));
  Report(options.progress, fmt::format("evaluate {}: simulated world ({}× finer mesh, camera {}×{})", name, options.world_factor,
               source.camera.width(), source.camera.height()));
  SimulatedRigOptions world_options;
  world_options.solver_patches = options.patches;
  world_options.world_factor = options.world_factor;
  world_options.albedo_variation = options.albedo_variation;
  world_options.smooth_bounce = options.smooth_bounce;
  evaluation.world = std::make_unique<SimulatedRig>(source.scene, projectors, source.camera,
                                                    world_options);
  evaluation.desired = evaluation.world->RenderDesired();
  const CameraPixelRays camera_rays = CastCameraPixels(evaluation.geometry.scene, evaluation.geometry.patches.fine,
                                                       {}, evaluation.world->camera());
  evaluation.camera_patch =
      cv::Mat(camera_rays.height, camera_rays.width, CV_32SC1, const_cast<int*>(camera_rays.patch.data())).clone();
  for (const CompensationMethod method : options.methods) {
    MethodEvaluation result;
    result.method = method;
    CompensationOptions compensation;
    compensation.solver.method = method;
    compensation.solver.multires = options.multires && (method == CompensationMethod::kPerceptual ||
                                                        method == CompensationMethod::kPerceptual2000);
    compensation.solver.robust_loss = options.loss;
    compensation.solver.robust_scale = options.loss_scale;
    compensation.solver.metric_update = options.metric_update;
    compensation.alpha = options.alpha;
    compensation.lower = evaluation.rig->lower;
    compensation.upper = evaluation.rig->upper;
    compensation.progress = options.progress;
    result.run = RunCompensation(evaluation.geometry, compensation);
    result.images = RenderProjectorImages(*evaluation.rig, result.run.solution.emittance, options.render, &result.render);
    result.radiance = evaluation.world->RenderRadiance(result.images);
    PixelDeltaE(result.radiance, evaluation, result.run.fine.rgb_to_xyz, result.run.fine.white_xyz, &result);
    Report(options.progress,
           fmt::format("evaluate {}: {:<10} mean ΔE76 {:.2f} (max {:.1f}), mean ΔE2000 {:.2f}, seam {:.2f}", name,
                       MethodName(method), result.mean_delta_e76, result.max_delta_e76, result.mean_delta_e2000,
                       result.seams.seam));
    evaluation.methods.push_back(std::move(result));
  }
  const MethodEvaluation* linear = nullptr;
  const MethodEvaluation* perceptual = nullptr;
  for (const MethodEvaluation& m : evaluation.methods) {
    if (m.method == CompensationMethod::kLinear) linear = &m;
    if (m.method == CompensationMethod::kPerceptual) perceptual = &m;
  }
  if (linear != nullptr && perceptual != nullptr) {
    evaluation.model_linear = linear->run.mean_delta_e76;
    evaluation.model_perceptual = perceptual->run.mean_delta_e76;
    evaluation.model_lowest = LowestMeanDeltaE(perceptual->run.fine, perceptual->run.delta_e76);
    Report(options.progress, fmt::format("evaluate {}: per patch mean ΔE76 linear {:.2f}, perceptual {:.2f}, lowest reachable {:.2f}", name,
                 evaluation.model_linear, evaluation.model_perceptual, evaluation.model_lowest));
  }
  if (perceptual != nullptr) {
    // Reweighting from the reverse radiosity finds a local optimum only: where a method's own
    // result is lower, that is the lowest found.
    evaluation.model_lowest2000 = LowestMeanDeltaE2000(perceptual->run.fine);
    for (const MethodEvaluation& m : evaluation.methods)
      evaluation.model_lowest2000 = std::min(evaluation.model_lowest2000, m.run.mean_delta_e2000);
    Report(options.progress, fmt::format("evaluate {}: per patch mean CIEDE2000 lowest reachable {:.2f}",
                                         name, evaluation.model_lowest2000));
  }
  evaluation.seconds = SecondsSince(start);
  return evaluation;
}

double LowestMeanDeltaE(const CompensationProblem& problem, const Eigen::VectorXd& delta_e76, int rounds) {
  CompensationProblem weighted = problem;
  weighted.alpha = 1.0;
  Eigen::VectorXd delta = delta_e76;
  const double total_area = problem.area.sum();
  double lowest = problem.area.dot(delta) / total_area;
  for (int round = 0; round < rounds; ++round) {
    const Eigen::VectorXd w = delta.cwiseMax(0.5).cwiseInverse();
    weighted.patch_weight = w / w.mean();
    SolverSummary summary;
    const CompensationSolution solution = Solve(SolverOptions(), weighted, &summary);
    const CompensationObjective lab(problem, *solution.radiosity_system, ColourModel::kLab);
    Eigen::VectorXd delta_e2000;
    lab.DeltaE(solution.radiosity, &delta, &delta_e2000);
    lowest = std::min(lowest, problem.area.dot(delta) / total_area);
  }
  return lowest;
}


double LowestMeanDeltaE2000(const CompensationProblem& problem, int rounds) {
  CompensationProblem unsmoothed = problem;
  unsmoothed.alpha = 1.0;
  SolverOptions options;
  options.method = CompensationMethod::kPerceptual2000;
  options.robust_loss = SolverOptions::RobustLoss::kSoftL1;
  options.robust_scale = 0.25;
  options.metric_update = SolverOptions::MetricUpdate::kRounds;  // `rounds` reweightings
  options.metric_rounds = rounds;
  SolverSummary summary;
  const CompensationSolution solution = Solve(options, unsmoothed, &summary);
  const CompensationObjective lab(problem, *solution.radiosity_system, ColourModel::kLab);
  Eigen::VectorXd delta_e76, delta_e2000;
  lab.DeltaE(solution.radiosity, &delta_e76, &delta_e2000);
  return problem.area.dot(delta_e2000) / problem.area.sum();
}

std::vector<std::pair<std::string, std::string>> WriteEvaluationPictures(const SceneEvaluation& evaluation,
                                                                          const std::filesystem::path& directory) {
  std::filesystem::create_directories(directory);
  std::vector<std::pair<std::string, std::string>> files;
  WritePng(directory / "desired.png", LinearToDisplay(evaluation.desired));
  files.emplace_back("desired", "desired.png");
  double scale = 10.0;  // one colour bar for every method of the scene: a multiple of 10 above the worst mean × 3
  for (const MethodEvaluation& m : evaluation.methods) scale = std::max(scale, 3.0 * m.mean_delta_e76);
  scale = 10.0 * std::ceil(scale / 10.0);
  for (const MethodEvaluation& m : evaluation.methods) {
    const std::string name = MethodName(m.method);
    WritePng(directory / (name + ".png"), LinearToDisplay(m.radiance));
    WritePng(directory / (name + "_delta_e76.png"), HeatMapWithColourBar(m.delta_e76, scale, "dE76"));
    WritePng(directory / (name + "_delta_e2000.png"), HeatMapWithColourBar(m.delta_e2000, scale / 2, "dE00"));
    files.emplace_back(name, name + ".png");
    files.emplace_back(name + " ΔE76", name + "_delta_e76.png");
    files.emplace_back(name + " CIEDE2000", name + "_delta_e2000.png");
    std::filesystem::create_directories(directory / name);
    for (size_t k = 0; k < m.images.size(); ++k) {
      WriteProjectorImage(directory / name / fmt::format("projector_{}.png", k), m.images[k]);
    }
  }
  return files;
}

std::string EvaluationMarkdown(const std::vector<const SceneEvaluation*>& evaluations) {
  if (evaluations.empty()) return "";
  std::string header = "| scene |", rule = "|---|";
  for (const MethodEvaluation& m : evaluations.front()->methods) {
    header += fmt::format(" {0} ΔE76 mean (max) | {0} ΔE2000 mean (max) | {0} seam |", MethodName(m.method));
    rule += "---|---|---|";
  }
  std::string table = header + "\n" + rule + "\n";
  for (const SceneEvaluation* e : evaluations) {
    table += "| " + e->name + " |";
    for (const MethodEvaluation& m : e->methods) {
      table += fmt::format(" {:.2f} ({:.1f}) | {:.2f} ({:.1f}) | {:.2f} |", m.mean_delta_e76, m.max_delta_e76,
                           m.mean_delta_e2000, m.max_delta_e2000, m.seams.seam);
    }
    table += "\n";
  }
  // Per patch in the solver's model: how far any method could go (LowestMeanDeltaE).
  if (evaluations.front()->model_lowest >= 0) {
    table += "\nPer patch, in the solver's model (area-weighted mean ΔE76): linear, perceptual, and the lowest mean "
             "any emittance within the bounds reaches (reweighted least squares)\n\n"
             "| scene | linear | perceptual | lowest reachable | perceptual / linear | lowest / linear |\n"
             "|---|---|---|---|---|---|\n";
    for (const SceneEvaluation* e : evaluations) {
      table += fmt::format("| {} | {:.2f} | {:.2f} | {:.2f} | {:.2f} | {:.2f} |\n", e->name, e->model_linear,
                           e->model_perceptual, e->model_lowest, e->model_perceptual / e->model_linear,
                           e->model_lowest / e->model_linear);
    }
  }
  if (evaluations.front()->model_lowest2000 >= 0) {
    table += "\nPer patch, in the solver's model (area-weighted mean CIEDE2000): each method, and the lowest "
             "mean any emittance within the bounds reaches (reweighted least squares in CIEDE2000)\n\n| scene |";
    std::string rule = "|---|";
    for (const MethodEvaluation& m : evaluations.front()->methods) {
      table += fmt::format(" {} |", MethodName(m.method));
      rule += "---|";
    }
    table += " lowest reachable |\n" + rule + "---|\n";
    for (const SceneEvaluation* e : evaluations) {
      table += "| " + e->name + " |";
      for (const MethodEvaluation& m : e->methods) table += fmt::format(" {:.2f} |", m.run.mean_delta_e2000);
      table += fmt::format(" {:.2f} |\n", e->model_lowest2000);
    }
  }
  return table;
}

nlohmann::json EvaluationJson(const SceneEvaluation& evaluation) {
  nlohmann::json methods = nlohmann::json::object();
  for (const MethodEvaluation& m : evaluation.methods) {
    nlohmann::json run = CompensationResultJson(evaluation.geometry, m.run);
    run.erase("trace");
    methods[MethodName(m.method)] = {
        {"pixel_delta_e76", {{"mean", m.mean_delta_e76}, {"max", m.max_delta_e76}}},
        {"pixel_delta_e2000", {{"mean", m.mean_delta_e2000}, {"max", m.max_delta_e2000}}},
        {"seam", m.seams.Json()},
        {"solver", run},
        {"render_max_relative_error", m.render.max_relative_error}};
  }
  nlohmann::json model2000 = {{"lowest_reachable", evaluation.model_lowest2000}};
  for (const MethodEvaluation& m : evaluation.methods) model2000[MethodName(m.method)] = m.run.mean_delta_e2000;
  return {{"scene", evaluation.name},
          {"patches", evaluation.geometry.patches.fine.size()},
          {"world_patches", evaluation.world->world().size()},
          {"projectors", evaluation.world->projectors().size()},
          {"camera", {{"width", evaluation.world->camera().width()}, {"height", evaluation.world->camera().height()}}},
          {"seconds", evaluation.seconds},
          {"model_mean_delta_e76",
           {{"linear", evaluation.model_linear},
            {"perceptual", evaluation.model_perceptual},
            {"lowest_reachable", evaluation.model_lowest}}},
          {"model_mean_delta_e2000", model2000},
          {"methods", methods}};
}

namespace {

std::vector<std::pair<std::string, cv::Mat>> ReadFigures(
    const std::filesystem::path& directory,
    const std::vector<std::pair<std::string, std::string>>& files) {
  std::vector<std::pair<std::string, cv::Mat>> figures;
  for (const auto& [caption, name] : files)
    figures.emplace_back(caption, cv::imread((directory / name).string()));
  return figures;
}

// Scenes where the recommended method (perceptual2000) misses the target: the lowest per-pixel
// mean CIEDE2000 of all methods run, and per patch within 10% of the lowest mean CIEDE2000 any
// emittance reaches. Scenes without perceptual2000 are not judged.
std::vector<std::string> ScenesMissingTheTarget(
    const std::vector<const SceneEvaluation*>& evaluations) {
  std::vector<std::string> missed;
  for (const SceneEvaluation* e : evaluations) {
    const MethodEvaluation* recommended = nullptr;
    double others = std::numeric_limits<double>::infinity();
    for (const MethodEvaluation& m : e->methods) {
      if (m.method == CompensationMethod::kPerceptual2000) {
        recommended = &m;
      } else {
        others = std::min(others, m.mean_delta_e2000);
      }
    }
    if (recommended == nullptr || !(e->model_lowest2000 > 0)) continue;
    const double ratio = recommended->run.mean_delta_e2000 / e->model_lowest2000;
    if (!(recommended->mean_delta_e2000 < others && ratio <= 1.1)) missed.push_back(e->name);
  }
  return missed;
}

// One row per method: per-pixel ΔE76 and CIEDE2000 mean (max), the seam, per-patch CIEDE2000;
// then the lowest per-patch CIEDE2000 any emittance reaches.
std::vector<std::vector<std::string>> SceneTableRows(const SceneEvaluation& e) {
  std::vector<std::vector<std::string>> rows;
  for (const MethodEvaluation& m : e.methods) {
    rows.push_back(
        {MethodName(m.method), fmt::format("{:.2f} ({:.1f})", m.mean_delta_e76, m.max_delta_e76),
         fmt::format("{:.2f} ({:.1f})", m.mean_delta_e2000, m.max_delta_e2000),
         fmt::format("{:.2f}", m.seams.seam), fmt::format("{:.2f}", m.run.mean_delta_e2000)});
  }
  if (e.model_lowest2000 > 0)
    rows.push_back({"lowest reachable", "–", "–", "–", fmt::format("{:.2f}", e.model_lowest2000)});
  return rows;
}

}  // namespace

std::string RunEvaluation(const EvaluationOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("evaluate: " + why);
  if (options.scenes.empty())
    throw std::invalid_argument(FlagOf(options, &options.scenes) + " is required");
  std::vector<std::string> scenes = options.scenes;
  if (scenes.size() == 1 && scenes.front() == "all") {
    scenes = SyntheticSceneNames();
    scenes.erase(std::remove(scenes.begin(), scenes.end(), "tiny_box"), scenes.end());
  }
  const std::filesystem::path& out = options.out;
  CheckNotProcamDirectory(out, "evaluate", FlagOf(options, &options.out));
  std::filesystem::create_directories(out);
  std::vector<std::unique_ptr<SceneEvaluation>> evaluations;
  std::vector<const SceneEvaluation*> pointers;
  nlohmann::json all = nlohmann::json::array();
  std::vector<std::vector<std::pair<std::string, cv::Mat>>> figures;  // per scene
  for (const std::string& scene : scenes) {
    evaluations.push_back(
        std::make_unique<SceneEvaluation>(EvaluateSyntheticScene(scene, options)));
    const SceneEvaluation& e = *evaluations.back();
    pointers.push_back(&e);
    const auto files = WriteEvaluationPictures(e, out / scene);
    nlohmann::json result = EvaluationJson(e);
    WriteFileAtomically(out / scene / "result.json", result.dump(2) + "\n");
    all.push_back(result);
    figures.push_back(ReadFigures(out / scene, files));
  }
  const std::string table = EvaluationMarkdown(pointers);
  WriteFileAtomically(out / "table.md", table);
  WriteFileAtomically(out / "result.json", nlohmann::json{{"scenes", all}}.dump(2) + "\n");
  HtmlReport page(
      "procam evaluate: compensation methods on synthetic scenes (Sheng et al. 2011, Table 1)");
  page.Paragraph(fmt::format(
      "{} solver patches per scene, world mesh {}× finer. Per pixel: ΔE between the desired "
      "appearance and the simulated camera's view of each method's result, mean (max); seam: how "
      "visible the patch grid is (mean CIEDE2000 across patch borders minus within patches, on "
      "surfaces whose desired appearance is flat). Per patch: area-weighted mean CIEDE2000 in "
      "the solver's model.",
      options.patches, options.world_factor));
  for (size_t k = 0; k < scenes.size(); ++k) {
    page.Heading(scenes[k]);
    page.Table({"method", "ΔE76 mean (max)", "CIEDE2000 mean (max)", "seam", "per patch CIEDE2000"},
               SceneTableRows(*pointers[k]));
    page.Figures(figures[k]);
  }
  page.Write(out / "report.html");
  const std::vector<std::string> missed = ScenesMissingTheTarget(pointers);
  const std::string verdict =
      missed.empty() ? "yes" : fmt::format("NO ({})", fmt::join(missed, ", "));
  return table +
         "\nperceptual2000 lowest per-pixel mean CIEDE2000 of all methods and within 10% of the "
         "lowest reachable per patch, on every scene: " +
         verdict + "\nwrote " + out.string() +
         "/table.md, result.json, report.html and pictures per scene\n";
}

}  // namespace procam
