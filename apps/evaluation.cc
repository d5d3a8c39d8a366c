#include "apps/evaluation.h"

#include <algorithm>
#include <chrono>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include "compensation/colour.h"
#include "compensation/objective.h"
#include "compensation/solver.h"
#include "base/io.h"

namespace procam {

bool EvaluationOptions::Check(std::string* why) const {
  if (patches < 4 || world_factor < 1 || methods.empty() || !(alpha > 0.0 && alpha <= 1.0)) {
    *why = "need patches >= 4, world_factor >= 1, at least one method, alpha in (0,1]";
    return false;
  }
  return true;
}

void PixelDeltaE(const cv::Mat& result, const cv::Mat& desired, const cv::Mat& mask, const Eigen::Matrix3d& rgb_to_xyz,
                 const Eigen::Vector3d& white_xyz, MethodEvaluation* evaluation) {
  evaluation->delta_e76 = cv::Mat(result.rows, result.cols, CV_32FC1, cv::Scalar(0));
  evaluation->delta_e2000 = cv::Mat(result.rows, result.cols, CV_32FC1, cv::Scalar(0));
  double sum76 = 0, sum2000 = 0, max76 = 0, max2000 = 0;
  long long count = 0;
  for (int row = 0; row < result.rows; ++row) {
    for (int col = 0; col < result.cols; ++col) {
      if (mask.at<uchar>(row, col) == 0) continue;
      const cv::Vec3f& r = result.at<cv::Vec3f>(row, col);
      const cv::Vec3f& d = desired.at<cv::Vec3f>(row, col);
      const Eigen::Vector3d lab_result = XyzToLab(rgb_to_xyz * Eigen::Vector3d(r[0], r[1], r[2]), white_xyz);
      const Eigen::Vector3d lab_desired = XyzToLab(rgb_to_xyz * Eigen::Vector3d(d[0], d[1], d[2]), white_xyz);
      const double e76 = DeltaE76(lab_result, lab_desired), e2000 = DeltaE2000(lab_result, lab_desired);
      evaluation->delta_e76.at<float>(row, col) = static_cast<float>(e76);
      evaluation->delta_e2000.at<float>(row, col) = static_cast<float>(e2000);
      sum76 += e76;
      sum2000 += e2000;
      max76 = std::max(max76, e76);
      max2000 = std::max(max2000, e2000);
      ++count;
    }
  }
  evaluation->mean_delta_e76 = count ? sum76 / count : 0.0;
  evaluation->mean_delta_e2000 = count ? sum2000 / count : 0.0;
  evaluation->max_delta_e76 = max76;
  evaluation->max_delta_e2000 = max2000;
}

SceneEvaluation EvaluateSyntheticScene(const std::string& name, const EvaluationOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("evaluate: " + why);
  const auto start = std::chrono::steady_clock::now();
  SceneEvaluation evaluation;
  evaluation.name = name;
  const SyntheticScene synthetic = MakeSyntheticScene(name, options.patches);
  spdlog::info("evaluate {}: geometry ({} patches)", name, options.patches);
  evaluation.geometry = RunGeometryStage(synthetic.scene, options.patches);
  std::vector<Projector> projectors;
  for (const DevicePlacement& placement : synthetic.projectors) projectors.push_back(ProjectorFromPlacement(placement));
  evaluation.rig = std::make_unique<ProjectionRig>(
      BuildProjectionRig(evaluation.geometry.patches.fine, projectors, ProjectionRigOptions()));
  spdlog::info("evaluate {}: simulated world ({}× finer mesh, camera {}×{})", name, options.world_factor,
               synthetic.camera.width, synthetic.camera.height);
  SimulatedRigOptions world_options;
  world_options.solver_patches = options.patches;
  world_options.world_factor = options.world_factor;
  world_options.albedo_variation = options.albedo_variation;
  evaluation.world = std::make_unique<SimulatedRig>(synthetic.scene, projectors,
                                                    CameraFromPlacement(synthetic.camera), world_options);
  evaluation.desired = evaluation.world->RenderDesired();
  for (const CompensationMethod method : options.methods) {
    MethodEvaluation result;
    result.method = method;
    SolverOptions solver;
    solver.method = method;
    solver.multires = options.multires && method == CompensationMethod::kPerceptual;
    result.run = RunCompensation(evaluation.geometry, solver, options.alpha, evaluation.rig.get());
    result.images = RenderProjectorImages(*evaluation.rig, result.run.solution.emittance, RenderOptions(), &result.render);
    result.radiance = evaluation.world->RenderRadiance(result.images);
    PixelDeltaE(result.radiance, evaluation.desired, evaluation.world->coverage(), result.run.fine.rgb_to_xyz,
                result.run.fine.white_xyz, &result);
    spdlog::info("evaluate {}: {:<10} mean ΔE76 {:.2f} (max {:.1f}), mean ΔE2000 {:.2f}", name, MethodName(method),
                 result.mean_delta_e76, result.max_delta_e76, result.mean_delta_e2000);
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
    spdlog::info("evaluate {}: per patch mean ΔE76 linear {:.2f}, perceptual {:.2f}, lowest reachable {:.2f}", name,
                 evaluation.model_linear, evaluation.model_perceptual, evaluation.model_lowest);
  }
  evaluation.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
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

cv::Mat LinearToDisplay(const cv::Mat& linear) {
  cv::Mat display(linear.rows, linear.cols, CV_8UC3);
  for (int row = 0; row < linear.rows; ++row) {
    for (int col = 0; col < linear.cols; ++col) {
      const cv::Vec3f& v = linear.at<cv::Vec3f>(row, col);
      cv::Vec3b& out = display.at<cv::Vec3b>(row, col);
      for (int c = 0; c < 3; ++c) {
        out[2 - c] = static_cast<uchar>(std::lround(255.0 * LinearToSrgb(std::clamp(double(v[c]), 0.0, 1.0))));
      }
    }
  }
  return display;
}

cv::Mat HeatMapWithColourBar(const cv::Mat& delta_e, double max_value, const std::string& label) {
  cv::Mat scaled;
  delta_e.convertTo(scaled, CV_8UC1, 255.0 / max_value);
  cv::Mat heat;
  cv::applyColorMap(scaled, heat, cv::COLORMAP_INFERNO);
  const int bar_width = 70, bar_left = 12, bar_thickness = 18;
  cv::Mat canvas(heat.rows, heat.cols + bar_width, CV_8UC3, cv::Scalar(255, 255, 255));
  heat.copyTo(canvas(cv::Rect(0, 0, heat.cols, heat.rows)));
  const int top = 20, bottom = heat.rows - 20;
  cv::Mat ramp(bottom - top, 1, CV_8UC1);
  for (int k = 0; k < ramp.rows; ++k) ramp.at<uchar>(k, 0) = static_cast<uchar>(255 - 255 * k / std::max(1, ramp.rows - 1));
  cv::Mat ramp_colour;
  cv::applyColorMap(ramp, ramp_colour, cv::COLORMAP_INFERNO);
  cv::resize(ramp_colour, ramp_colour, cv::Size(bar_thickness, ramp.rows), 0, 0, cv::INTER_NEAREST);
  ramp_colour.copyTo(canvas(cv::Rect(heat.cols + bar_left, top, bar_thickness, ramp.rows)));
  const double font = 0.35;
  for (int tick = 0; tick <= 4; ++tick) {
    const int y = bottom - (bottom - top) * tick / 4;
    cv::putText(canvas, fmt::format("{:.0f}", max_value * tick / 4), cv::Point(heat.cols + bar_left + bar_thickness + 3, y + 4),
                cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  cv::putText(canvas, label, cv::Point(heat.cols + 4, 12), cv::FONT_HERSHEY_SIMPLEX, font, cv::Scalar(0, 0, 0), 1,
              cv::LINE_AA);
  return canvas;
}

namespace {

void WritePng(const std::filesystem::path& path, const cv::Mat& image) {
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", image, bytes)) throw IoError(path.string() + ": cannot encode PNG");
  WriteFileAtomically(path, std::string(bytes.begin(), bytes.end()));
}

}  // namespace

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
    header += fmt::format(" {} ΔE76 mean (max) | {} ΔE2000 mean (max) |", MethodName(m.method), MethodName(m.method));
    rule += "---|---|";
  }
  std::string table = header + "\n" + rule + "\n";
  for (const SceneEvaluation* e : evaluations) {
    table += "| " + e->name + " |";
    for (const MethodEvaluation& m : e->methods) {
      table += fmt::format(" {:.2f} ({:.1f}) | {:.2f} ({:.1f}) |", m.mean_delta_e76, m.max_delta_e76,
                           m.mean_delta_e2000, m.max_delta_e2000);
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
        {"solver", run},
        {"render_max_relative_error", m.render.max_relative_error}};
  }
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
          {"methods", methods}};
}

}  // namespace procam
