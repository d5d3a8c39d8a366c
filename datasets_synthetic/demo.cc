#include "datasets_synthetic/demo.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>

#include "base/camera_model.h"
#include "base/html_report.h"
#include "base/image_io.h"
#include "base/io.h"
#include "calibration/calibrate_all_stage.h"
#include "calibration/rig_directory.h"
#include "compensation/colour_image.h"
#include "compensation/stage.h"
#include "verification/verification.h"

namespace procam {
namespace {

// The demo's calibration stage: the synthetic rig calibrated from its own simulated captures
// (`procam calibrate all`), its accuracy against the ground truth, and the perceptual
// compensation redone with the recovered rig, photographed in the true world.
struct CalibrationStage {
  std::string camera;                              // the synthetic camera's URI
  std::vector<std::vector<std::string>> accuracy;  // table rows
  GeometryStage geometry;                          // the patches with the rig's reflectance
  MethodEvaluation perceptual;                     // with the recovered rig
  nlohmann::json json;
};

CalibrationStage RunCalibrationStage(const SceneEvaluation& evaluation,
                                     const EvaluationOptions& options,
                                     const std::filesystem::path& rig_dir,
                                     const ProgressCallback& progress,
                                     const ProgressCallback& steps) {
  CalibrationStage stage;
  const std::string camera = stage.camera = fmt::format(
      "synthetic:{}?patches={}&albedo={}&fps=500&exposure_us=1000&reference_exposure_us=1000&black="
      "8&noise=1",
      evaluation.name, options.patches, options.albedo_variation);
  Report(
      steps,
      fmt::format("\n$ procam calibrate all --camera {} --out {} --frames 2 --settle-ms 1 --levels "
                  "0,32,64,128,192,255",
                  camera, rig_dir.string()));
  CalibrateAllOptions calibrate;
  calibrate.camera = camera;
  calibrate.out = rig_dir;
  calibrate.frames = 2;
  calibrate.settle_ms = 1;
  calibrate.levels = {0, 32, 64, 128, 192, 255};
  calibrate.progress = steps;
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
    if (found == rig.projectors.end())
      throw IoError((rig_dir / "rig.json").string() + ": no projector " + truth.name);
    const ProjectorGeometry& a = found->geometry;
    const ProjectorGeometry& b = truth.geometry;
    const double focal = 100.0 * (a.intrinsics()[0] / b.intrinsics()[0] - 1.0);
    const double position = 1e3 * (a.CentreInWorld() - b.CentreInWorld()).norm();
    const double orientation =
        angle_deg(a.proj_from_world().linear(), b.proj_from_world().linear());
    const Vec3 max_error =
        (found->photometry.max.array() / truth.photometry.max.array() - 1.0) * 100.0;
    const double gamma = found->photometry.response[1].Drive(0.5);  // drive giving half light
    const double true_gamma = truth.photometry.response[1].Drive(0.5);
    stage.accuracy.push_back(
        {truth.name, fmt::format("{:+.3f}%", focal), fmt::format("{:.2f} mm", position),
         fmt::format("{:.3f}°", orientation),
         fmt::format("{:+.2f}% / {:+.2f}% / {:+.2f}%", max_error[0], max_error[1], max_error[2]),
         fmt::format("{:+.4f}", gamma - true_gamma)});
    accuracy.push_back({{"projector", truth.name},
                        {"focal_error_percent", focal},
                        {"position_error_mm", position},
                        {"orientation_error_deg", orientation},
                        {"max_error_percent", {max_error[0], max_error[1], max_error[2]}},
                        {"half_light_drive_error", gamma - true_gamma}});
  }
  const CameraModel camera_model = ReadCameraModelFile(rig_dir / "camera.cameramodel");
  const CameraGeometry& true_camera = evaluation.world->camera();
  const double camera_focal =
      100.0 * (camera_model.intrinsics[0] / true_camera.intrinsics()[0] - 1.0);
  const double camera_position =
      1e3 *
      (camera_model.cam_from_ref.inverse().translation() - true_camera.CentreInWorld()).norm();
  const double camera_orientation =
      angle_deg(camera_model.cam_from_ref.linear(), true_camera.proj_from_world().linear());
  stage.accuracy.push_back({"camera", fmt::format("{:+.3f}%", camera_focal),
                            fmt::format("{:.2f} mm", camera_position),
                            fmt::format("{:.3f}°", camera_orientation), "", ""});
  stage.json = {{"rig", rig_dir.string()},
                {"projectors", accuracy},
                {"camera",
                 {{"focal_error_percent", camera_focal},
                  {"position_error_mm", camera_position},
                  {"orientation_error_deg", camera_orientation}}}};

  // Perceptual compensation with the recovered rig (projectors, photometry, reflectance), shown
  // by the true projectors in the true world.
  GeometryStage& geometry = stage.geometry = evaluation.geometry;
  ApplyRigReflectance(rig, &geometry.patches);
  const ProjectionRig recovered =
      BuildProjectionRig(geometry.patches.fine, rig.projectors, ProjectionRigOptions());
  MethodEvaluation& result = stage.perceptual;
  CompensationOptions compensation;
  compensation.solver.method = CompensationMethod::kPerceptual;
  compensation.solver.multires = options.multires;
  compensation.alpha = options.alpha;
  compensation.lower = recovered.lower;
  compensation.upper = recovered.upper;
  compensation.progress = progress;
  result.run = RunCompensation(geometry, compensation);
  result.images = RenderProjectorImages(recovered, result.run.solution.emittance, options.render,
                                        &result.render);
  result.radiance = evaluation.world->RenderRadiance(result.images);
  PixelDeltaE(result.radiance, evaluation, result.run.fine.rgb_to_xyz, result.run.fine.white_xyz,
              &result);
  stage.json["perceptual_with_calibrated_rig"] = {{"mean_delta_e76", result.mean_delta_e76},
                                                  {"max_delta_e76", result.max_delta_e76},
                                                  {"mean_delta_e2000", result.mean_delta_e2000},
                                                  {"max_delta_e2000", result.max_delta_e2000},
                                                  {"seam", result.seams.Json()}};
  return stage;
}

}  // namespace

SyntheticDemoSummary RunSyntheticDemo(const SyntheticDemoOptions& demo) {
  const std::string& scene = demo.scene;
  const std::filesystem::path& out = demo.out;
  EvaluationOptions options;
  options.patches = demo.patches;
  options.render.light = demo.light;
  options.progress = demo.progress;
  Report(
      demo.progress,
      fmt::format("procam demo on the synthetic '{}' rig ({} patches): geometry → compensation (4 "
                  "methods) → projector images → simulated photos → ΔE → report",
                  scene, demo.patches));
  const SceneEvaluation evaluation = EvaluateSyntheticScene(scene, options);
  const auto files = WriteEvaluationPictures(evaluation, out);
  WriteFormFactorImage(evaluation.geometry.form_factors, out / "form_factors.png");
  ExportGeometryProblem(evaluation.geometry, options.alpha, out / "problem");
  for (const MethodEvaluation& m : evaluation.methods) {
    WriteCompensation(evaluation.geometry, m.run, out / MethodName(m.method), false);
  }
  Report(demo.progress,
         "demo: calibration stage — the rig calibrated from its own simulated captures (procam "
         "calibrate all)");
  const CalibrationStage calibration =
      RunCalibrationStage(evaluation, options, out / "rig", demo.progress, demo.steps);
  // Verification: the calibrated solution photographed, compared with its prediction, and the
  // model refined from the photos (procam verify).
  Report(demo.progress,
         "demo: verification stage — photos against the predicted L*a*b*, the closed loop (procam "
         "verify)");
  WriteCompensation(calibration.geometry, calibration.perceptual.run, out / "perceptual_calibrated",
                    false);
  VerificationOptions verification;
  verification.rig_dir = out / "rig";
  verification.solution_dir = out / "perceptual_calibrated";
  verification.out = out / "verify";
  verification.camera = calibration.camera;
  verification.scene = evaluation.geometry.scene;
  verification.sequencer.frames_per_pattern = 2;
  verification.sequencer.settle_ms = 0;
  verification.iterations = 4;
  verification.light = demo.light;
  verification.progress = demo.progress;
  const VerificationSummary verified = RunVerification(verification);
  WritePng(out / "perceptual_calibrated.png", LinearToDisplay(calibration.perceptual.radiance));
  WritePng(out / "perceptual_calibrated_delta_e76.png",
           HeatMapWithColourBar(calibration.perceptual.delta_e76, 30.0, "dE76"));
  nlohmann::json result = EvaluationJson(evaluation);
  result["calibration"] = calibration.json;
  result["verification"] = {{"summary", verified.BriefReport()},
                            {"best_iteration", verified.best},
                            {"result", (out / "verify" / "result.json").string()}};
  WriteFileAtomically(out / "result.json", result.dump(2) + "\n");

  HtmlReport report("procam demo: " + scene);
  report.Paragraph(fmt::format(
      "{} solver patches ({} variables), {} projectors, a {}×{} camera; the simulated room uses a "
      "{}-patch mesh, exact "
      "direct light per camera pixel and its own radiosity solution, so the solver's model is not "
      "the world.",
      evaluation.geometry.patches.fine.size(), 3 * evaluation.geometry.patches.fine.size(),
      evaluation.world->projectors().size(), evaluation.world->camera().width(),
      evaluation.world->camera().height(), evaluation.world->world().size()));
  std::vector<std::vector<std::string>> rows;
  std::vector<HtmlReport::Series> traces;
  for (const MethodEvaluation& m : evaluation.methods) {
    rows.push_back({MethodName(m.method), fmt::format("{:.2f}", m.mean_delta_e76),
                    fmt::format("{:.1f}", m.max_delta_e76),
                    fmt::format("{:.2f}", m.mean_delta_e2000),
                    fmt::format("{:.1f}", m.max_delta_e2000), fmt::format("{:.2f}", m.seams.seam),
                    fmt::format("{:.4g}", m.run.perceptual_objective),
                    std::to_string(m.run.summary.iterations),
                    fmt::format("{:.3f}", m.run.summary.solve_seconds),
                    TerminationName(m.run.summary.termination)});
    if (m.run.summary.trace.size() > 1) {
      std::vector<std::pair<double, double>> points;
      for (const IterationRecord& record : m.run.summary.trace)
        points.emplace_back(record.iteration, record.cost);
      traces.emplace_back(std::string(MethodName(m.method)) + " (own objective)", points);
    }
  }
  report.Heading("Colour error per camera pixel");
  report.Paragraph(
      "Seam: mean CIEDE2000 between neighbouring camera pixels across patch borders minus the same "
      "within patches, where the desired appearance is flat (how visible the patch grid is).");
  report.Table({"method", "mean ΔE76", "max ΔE76", "mean ΔE2000", "max ΔE2000", "seam (ΔE2000)",
                "objective (L*a*b*)", "iterations", "solve s", "termination"},
               rows);
  report.Heading("Calibration (the rig recovered from its own simulated captures)");
  report.Paragraph(
      "procam calibrate all: chessboard photos → camera intrinsics (mrcal); per projector "
      "structured light (XOR Gray "
      "+ phase) and flat fields; projectors and the camera's pose in the room jointly (Ceres), "
      "checked by triangulation "
      "and ICP; photometry in scene units and per-patch reflectance. Errors against the simulated "
      "rig's ground truth:");
  report.Table({"device", "focal length", "position", "orientation", "max (R / G / B)",
                "drive for half light"},
               calibration.accuracy);
  report.Paragraph(fmt::format(
      "Perceptual compensation computed with the calibrated rig instead of the ground truth, shown "
      "by the true "
      "projectors: mean ΔE76 {:.2f} (max {:.1f}), mean ΔE2000 {:.2f}, seam {:.2f}; with the true "
      "rig: mean ΔE76 {:.2f}.",
      calibration.perceptual.mean_delta_e76, calibration.perceptual.max_delta_e76,
      calibration.perceptual.mean_delta_e2000, calibration.perceptual.seams.seam,
      evaluation.methods.back().mean_delta_e76));
  report.Figures(
      {{"perceptual, calibrated rig", cv::imread((out / "perceptual_calibrated.png").string())},
       {"ΔE76, calibrated rig",
        cv::imread((out / "perceptual_calibrated_delta_e76.png").string())}});
  AddVerificationReport(verified, &report);  // its own heading
  report.Heading("Pictures");
  std::vector<std::pair<std::string, cv::Mat>> figures;
  for (const auto& [caption, name] : files)
    figures.emplace_back(caption, cv::imread((out / name).string()));
  report.Figures(figures);
  report.Heading("Solver convergence");
  report.Plot("objective per outer iteration", "iteration", "objective", traces);
  report.Heading("Projector images (perceptual)");
  std::vector<std::pair<std::string, cv::Mat>> projector_images;
  for (size_t k = 0; k < evaluation.world->projectors().size(); ++k) {
    projector_images.emplace_back(
        evaluation.world->projectors()[k].name,
        cv::imread((out / "perceptual" / fmt::format("projector_{}.png", k)).string()));
  }
  report.Figures(projector_images);
  report.Heading("Form factors");
  report.Figures({{"log10 F (rows: emitting patch, columns: receiving patch)",
                   cv::imread((out / "form_factors.png").string())}});
  report.Write(out / "report.html");
  SyntheticDemoSummary summary;
  summary.methods = evaluation.methods;
  summary.calibrated = calibration.perceptual;
  summary.verification = verified.BriefReport();
  return summary;
}

}  // namespace procam
