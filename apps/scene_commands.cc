// procam scene info / scene export / demo.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include "base/camera_model.h"
#include "apps/command_line.h"
#include "apps/commands.h"
#include "calibration/calibrate_all_stage.h"
#include "capture/devices.h"
#include "projection/stage.h"
#include <fmt/ranges.h>
#include "compensation/stage.h"
#include "datasets_synthetic/evaluation.h"
#include "geometry/stage.h"
#include "base/html_report.h"
#include "calibration/rig_directory.h"
#include "verification/verification.h"
#include "datasets_synthetic/paper_scenes.h"
#include "calibration/registration.h"
#include "projection/projector_images.h"
#include "compensation/problem.h"
#include "base/io.h"
#include "procam/config.h"

namespace procam {
namespace {

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

// The demo on a rig: a camera (real, or a synthetic one treated like a real one), the projectors'
// monitors and the room model.
struct RigDemoArguments {
  std::string camera;
  std::vector<std::string> displays;
  std::string chessboard, camera_model, camera_scale, camera_guess;
  std::vector<std::string> names;
  int frames = 4;
  double settle_ms = 150.0;
  int iterations = 4;
};

// calibrate → compensate → project → photograph → verify → refine, each stage a library call
// printed as the command a user would run (`$ procam ...`), on whatever the camera URI names.
void RunRigDemo(const std::string& scene, int patches, const RigDemoArguments& rig,
                const std::filesystem::path& out) {
  RegisterDeviceBackends();
  const std::filesystem::path rig_dir = out / "rig", solution_dir = out / "solution", images = out / "images";
  spdlog::info("demo on a rig: stage 1/4 calibration");
  CalibrateAllOptions calibrate;
  calibrate.camera = rig.camera;
  calibrate.scene = scene;
  calibrate.out = rig_dir;
  calibrate.patches = patches;
  calibrate.frames = rig.frames;
  calibrate.settle_ms = rig.settle_ms;
  calibrate.chessboard = rig.chessboard;
  calibrate.camera_model = rig.camera_model;
  calibrate.camera_scale = rig.camera_scale;
  calibrate.camera_guess = rig.camera_guess;
  calibrate.names = rig.names;
  std::vector<std::shared_ptr<PatternDisplay>> displays;
  for (const std::string& display : rig.displays) displays.push_back(OpenMonitorDisplay(display));
  calibrate.displays = displays;
  calibrate.display_names = rig.displays;
  calibrate.progress = PrintProgress();
  std::printf("\n$ procam calibrate all --camera %s --scene %s --out %s --patches %d --frames %d --settle-ms %g%s\n",
              rig.camera.c_str(), scene.c_str(), rig_dir.c_str(), patches, rig.frames, rig.settle_ms,
              rig.displays.empty() ? "" : (" --display " + fmt::format("{}", fmt::join(rig.displays, ","))).c_str());
  RunCalibrateAll(calibrate);

  spdlog::info("stage 2/4 compensation with the calibrated rig");
  std::printf("\n$ procam compensate %s --method perceptual --multires --patches %d --rig %s --out %s\n",
              scene.c_str(), patches, rig_dir.c_str(), solution_dir.c_str());
  const RigDirectory rig_directory = ReadRigDirectory(rig_dir);
  GeometryStage geometry = RunGeometryStage(scene, GeometryArguments(patches));
  ApplyRigReflectance(rig_directory, &geometry.patches);
  const ProjectionRig projection_rig =
      BuildProjectionRig(geometry.patches.fine, rig_directory.projectors, ProjectionRigOptions());
  CompensationOptions compensation;
  compensation.solver.method = CompensationMethod::kPerceptual;
  compensation.solver.multires = true;
  compensation.lower = projection_rig.lower;
  compensation.upper = projection_rig.upper;
  compensation.progress = LogProgress();
  const CompensationRun run = RunCompensation(geometry, compensation);
  WriteCompensation(geometry, run, solution_dir, false, {{"rig", rig_directory.Describe()}});

  spdlog::info("stage 3/4 projector images");
  std::printf("\n$ procam project %s --out %s\n", solution_dir.c_str(), images.c_str());
  const SolutionDirectory solution = ReadSolutionDirectory(solution_dir);
  SolutionGeometry solution_geometry = ReadSolutionGeometry(solution);
  SolutionProjectors projectors = ProjectorsForSolution(solution, {}, solution_geometry.scene, &solution_geometry.patches);
  ProjectionStageOptions projection;
  projection.out = images;
  projection.progress = PrintProgress();
  RunProjectionStage(solution, solution_geometry, std::move(projectors.projectors), projectors.rig_description,
                     projection);

  spdlog::info("stage 4/4 photographs, verification and the closed loop");
  std::printf("\n$ procam verify %s %s --camera %s --out %s --iterations %d --frames %d --settle-ms %g\n",
              rig_dir.c_str(), solution_dir.c_str(), rig.camera.c_str(), (out / "verify").c_str(), rig.iterations,
              rig.frames, rig.settle_ms);
  VerificationOptions verify;
  verify.rig_dir = rig_dir;
  verify.solution_dir = solution_dir;
  verify.out = out / "verify";
  verify.camera = rig.camera;
  verify.displays = displays;
  verify.iterations = rig.iterations;
  verify.sequencer.frames_per_pattern = rig.frames;
  verify.sequencer.settle_ms = rig.settle_ms;
  if (!rig.camera_scale.empty()) verify.camera_scale = ParsePositiveRgb("--camera-scale", rig.camera_scale);
  verify.progress = LogProgress();
  const VerificationSummary verified = RunVerification(verify);
  std::cout << verified.BriefReport() << "\n";
  std::cout << "\nwrote " << out.string() << "/: rig/ (the calibration), solution/ (E.npy, B.npy), images/ (one PNG "
            << "per projector), verify/report.html (photos, ΔE per iteration)\n";
}

// A scene file without a camera: geometry and compensation, numbers per patch.
void RunJsonDemo(const std::string& scene_path, int patches, const std::filesystem::path& out) {
  spdlog::info("procam demo on {}: stage 1/2 geometry", scene_path);
  const GeometryStage stage = RunGeometryStage(scene_path, GeometryArguments(patches));
  ExportStage(stage, 0.5, out / "problem");
  WriteFormFactorImage(stage.form_factors, out / "form_factors.png");
  std::cout << DescribeGeometry(stage);
  spdlog::info("stage 2/2: compensation (naive, reverse, linear, perceptual)");
  nlohmann::json methods = nlohmann::json::object();
  std::cout << "\n  method        mean ΔE76  max ΔE76  mean ΔE2000  objective      solve s\n";
  for (const CompensationMethod method : {CompensationMethod::kNaive, CompensationMethod::kReverse,
                                          CompensationMethod::kLinear, CompensationMethod::kPerceptual}) {
    CompensationOptions options;
    options.solver.method = method;
    options.solver.multires = method == CompensationMethod::kPerceptual;
    options.progress = LogProgress();
    const CompensationRun run = RunCompensation(stage, options);
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

// The demo's calibration stage: the synthetic rig calibrated from its own simulated captures
// (`procam calibrate all`), its accuracy against the ground truth, and the perceptual
// compensation redone with the recovered rig, photographed in the true world.
struct CalibrationStage {
  std::string camera;                               // the synthetic camera's URI
  std::vector<std::vector<std::string>> accuracy;  // table rows
  GeometryStage geometry;                           // the patches with the rig's reflectance
  MethodEvaluation perceptual;                      // with the recovered rig
  nlohmann::json json;
};

CalibrationStage RunCalibrationStage(const SceneEvaluation& evaluation, const EvaluationOptions& options,
                                     const std::filesystem::path& rig_dir) {
  CalibrationStage stage;
  const std::string camera = stage.camera = fmt::format(
      "synthetic:{}?patches={}&albedo={}&fps=500&exposure_us=1000&reference_exposure_us=1000&black=8&noise=1",
      evaluation.name, options.patches, options.albedo_variation);
  std::printf("\n$ procam calibrate all --camera %s --out %s --frames 2 --settle-ms 1 --levels 0,32,64,128,192,255\n",
              camera.c_str(), rig_dir.c_str());
  CalibrateAllOptions calibrate;
  calibrate.camera = camera;
  calibrate.out = rig_dir;
  calibrate.frames = 2;
  calibrate.settle_ms = 1;
  calibrate.levels = {0, 32, 64, 128, 192, 255};
  calibrate.progress = PrintProgress();
  RunCalibrateAll(calibrate);
  const RigDirectory rig = ReadRigDirectory(rig_dir);

  // Accuracy against the world's true projectors and camera.
  const auto angle_deg = [](const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
    return Eigen::AngleAxisd(a * b.transpose()).angle() * 180.0 / M_PI;
  };
  nlohmann::json accuracy = nlohmann::json::array();
  for (const Projector& truth : evaluation.world->projectors()) {
    const auto found = std::find_if(rig.projectors.begin(), rig.projectors.end(),
                                    [&](const Projector& p) { return p.name == truth.name; });
    if (found == rig.projectors.end()) throw IoError((rig_dir / "rig.json").string() + ": no projector " + truth.name);
    const ProjectorGeometry& a = found->geometry;
    const ProjectorGeometry& b = truth.geometry;
    const double focal = 100.0 * (a.intrinsics()[0] / b.intrinsics()[0] - 1.0);
    const double position = 1e3 * (a.CentreInWorld() - b.CentreInWorld()).norm();
    const double orientation = angle_deg(a.proj_from_world().linear(), b.proj_from_world().linear());
    const Vec3 max_error = (found->photometry.max.array() / truth.photometry.max.array() - 1.0) * 100.0;
    const double gamma = found->photometry.response[1].Drive(0.5);  // drive giving half light
    const double true_gamma = truth.photometry.response[1].Drive(0.5);
    stage.accuracy.push_back({truth.name, fmt::format("{:+.3f}%", focal), fmt::format("{:.2f} mm", position),
                              fmt::format("{:.3f}°", orientation),
                              fmt::format("{:+.2f}% / {:+.2f}% / {:+.2f}%", max_error[0], max_error[1], max_error[2]),
                              fmt::format("{:+.4f}", gamma - true_gamma)});
    accuracy.push_back({{"projector", truth.name}, {"focal_error_percent", focal}, {"position_error_mm", position},
                        {"orientation_error_deg", orientation},
                        {"max_error_percent", {max_error[0], max_error[1], max_error[2]}},
                        {"half_light_drive_error", gamma - true_gamma}});
  }
  const CameraModel camera_model = ReadCameraModelFile(rig_dir / "camera.cameramodel");
  const CameraGeometry& true_camera = evaluation.world->camera();
  const double camera_focal = 100.0 * (camera_model.intrinsics[0] / true_camera.intrinsics()[0] - 1.0);
  const double camera_position =
      1e3 * (camera_model.cam_from_ref.inverse().translation() - true_camera.CentreInWorld()).norm();
  const double camera_orientation =
      angle_deg(camera_model.cam_from_ref.linear(), true_camera.proj_from_world().linear());
  stage.accuracy.push_back({"camera", fmt::format("{:+.3f}%", camera_focal), fmt::format("{:.2f} mm", camera_position),
                            fmt::format("{:.3f}°", camera_orientation), "", ""});
  stage.json = {{"rig", rig_dir.string()},
                {"projectors", accuracy},
                {"camera", {{"focal_error_percent", camera_focal},
                            {"position_error_mm", camera_position},
                            {"orientation_error_deg", camera_orientation}}}};

  // Perceptual compensation with the recovered rig (projectors, photometry, reflectance), shown
  // by the true projectors in the true world.
  GeometryStage& geometry = stage.geometry = evaluation.geometry;
  ApplyRigReflectance(rig, &geometry.patches);
  const ProjectionRig recovered = BuildProjectionRig(geometry.patches.fine, rig.projectors, ProjectionRigOptions());
  MethodEvaluation& result = stage.perceptual;
  CompensationOptions compensation;
  compensation.solver.method = CompensationMethod::kPerceptual;
  compensation.solver.multires = options.multires;
  compensation.alpha = options.alpha;
  compensation.lower = recovered.lower;
  compensation.upper = recovered.upper;
  compensation.progress = LogProgress();
  result.run = RunCompensation(geometry, compensation);
  result.images = RenderProjectorImages(recovered, result.run.solution.emittance, RenderOptions(), &result.render);
  result.radiance = evaluation.world->RenderRadiance(result.images);
  PixelDeltaE(result.radiance, evaluation.desired, evaluation.world->coverage(), result.run.fine.rgb_to_xyz,
              result.run.fine.white_xyz, &result);
  stage.json["perceptual_with_calibrated_rig"] = {{"mean_delta_e76", result.mean_delta_e76},
                                                  {"max_delta_e76", result.max_delta_e76},
                                                  {"mean_delta_e2000", result.mean_delta_e2000},
                                                  {"max_delta_e2000", result.max_delta_e2000}};
  return stage;
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
  spdlog::info("demo: calibration stage — the rig calibrated from its own simulated captures (procam calibrate all)");
  const CalibrationStage calibration = RunCalibrationStage(evaluation, options, out / "rig");
  // Verification: the calibrated solution photographed, compared with its prediction, and the
  // model refined from the photos (procam verify).
  spdlog::info("demo: verification stage — photos against the predicted L*a*b*, the closed loop (procam verify)");
  WriteCompensation(calibration.geometry, calibration.perceptual.run, out / "perceptual_calibrated", false);
  VerificationOptions verification;
  verification.rig_dir = out / "rig";
  verification.solution_dir = out / "perceptual_calibrated";
  verification.out = out / "verify";
  verification.camera = calibration.camera;
  verification.scene = evaluation.geometry.scene;
  verification.sequencer.frames_per_pattern = 2;
  verification.sequencer.settle_ms = 0;
  verification.iterations = 4;
  const VerificationSummary verified = RunVerification(verification);
  cv::imwrite((out / "perceptual_calibrated.png").string(), LinearToDisplay(calibration.perceptual.radiance));
  cv::imwrite((out / "perceptual_calibrated_delta_e76.png").string(),
              HeatMapWithColourBar(calibration.perceptual.delta_e76, 30.0, "dE76"));
  nlohmann::json result = EvaluationJson(evaluation);
  result["calibration"] = calibration.json;
  result["verification"] = {{"summary", verified.BriefReport()},
                            {"best_iteration", verified.best},
                            {"result", (out / "verify" / "result.json").string()}};
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
  report.Heading("Calibration (the rig recovered from its own simulated captures)");
  report.Paragraph(
      "procam calibrate all: chessboard photos → camera intrinsics (mrcal); per projector structured light (XOR Gray "
      "+ phase) and flat fields; projectors and the camera's pose in the room jointly (Ceres), checked by triangulation "
      "and ICP; photometry in scene units and per-patch reflectance. Errors against the simulated rig's ground truth:");
  report.Table({"device", "focal length", "position", "orientation", "max (R / G / B)", "drive for half light"},
               calibration.accuracy);
  report.Paragraph(fmt::format(
      "Perceptual compensation computed with the calibrated rig instead of the ground truth, shown by the true "
      "projectors: mean ΔE76 {:.2f} (max {:.1f}), mean ΔE2000 {:.2f}; with the true rig: mean ΔE76 {:.2f}.",
      calibration.perceptual.mean_delta_e76, calibration.perceptual.max_delta_e76,
      calibration.perceptual.mean_delta_e2000, evaluation.methods.back().mean_delta_e76));
  report.Figures({{"perceptual, calibrated rig", cv::imread((out / "perceptual_calibrated.png").string())},
                  {"ΔE76, calibrated rig", cv::imread((out / "perceptual_calibrated_delta_e76.png").string())}});
  report.Heading("Verification: photos against the prediction, and the closed loop");
  AddVerificationReport(verified, &report);
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
  std::cout << fmt::format("  {:<12} {:>10.2f} {:>9.1f} {:>12.2f} {:>11.1f}   (calibrated rig)\n", "perceptual",
                           calibration.perceptual.mean_delta_e76, calibration.perceptual.max_delta_e76,
                           calibration.perceptual.mean_delta_e2000, calibration.perceptual.max_delta_e2000);
  std::cout << "\nverification (closed loop, calibrated rig): " << verified.BriefReport() << "\n";
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
    const GeometryStage stage = RunGeometryStage(args->scene, GeometryArguments(args->patches));
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
    const GeometryStage stage = RunGeometryStage(args->scene, GeometryArguments(args->patches));
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
  auto rig = std::make_shared<RigDemoArguments>();
  demo->add_option("--camera", rig->camera,
                   "Run the pipeline on a rig instead: the camera URI (v4l2:..., aravis:..., or synthetic:SCENE?...); "
                   "--scene is then the room model (a scene file, or synthetic:NAME)");
  demo->add_option("--display", rig->displays,
                   "With --camera: each projector's monitor, in order (glfw:N|NAME, comma-separated)")
      ->delimiter(',');
  demo->add_option("--names", rig->names, "With --camera: projector names, comma-separated")->delimiter(',');
  demo->add_option("--chessboard", rig->chessboard, "With --camera: chessboard photos of the camera");
  demo->add_option("--camera-model", rig->camera_model, "With --camera: a calibrated camera.cameramodel instead");
  demo->add_option("--camera-scale", rig->camera_scale,
                   "With --camera: camera value per unit exitance (number or R,G,B; synthetic cameras: automatic)");
  demo->add_option("--camera-guess", rig->camera_guess,
                   "With --camera: camera position and a point it looks at, x,y,z,look_x,look_y,look_z");
  demo->add_option("--frames", rig->frames, "With --camera: frames averaged per pattern")->capture_default_str();
  demo->add_option("--settle-ms", rig->settle_ms, "With --camera: wait after each pattern, milliseconds")
      ->capture_default_str();
  demo->add_option("--iterations", rig->iterations, "With --camera: closed-loop photos at most")
      ->capture_default_str();
  demo->callback([args, rig] {
    const std::filesystem::path out = args->out;
    std::filesystem::create_directories(out);
    if (!rig->camera.empty()) {
      const std::vector<std::string> synthetic = SyntheticSceneNames();
      const bool named = std::find(synthetic.begin(), synthetic.end(), args->scene) != synthetic.end();
      RunRigDemo(named ? "synthetic:" + args->scene : args->scene, args->patches, *rig, out);
      return;
    }
    if (args->scene.size() > 5 && args->scene.substr(args->scene.size() - 5) == ".json") {
      RunJsonDemo(args->scene, args->patches, out);
      return;
    }
    RunSyntheticDemo(args->scene, args->patches, out);
  });
}

}  // namespace procam
