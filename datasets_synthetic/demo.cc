#include "datasets_synthetic/demo.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <numbers>
#include <opencv2/imgcodecs.hpp>
#include <optional>

#include "base/camera_model.h"
#include "base/html_report.h"
#include "base/image_io.h"
#include "base/io.h"
#include "base/option_table.h"
#include "calibration/camera_report.h"
#include "calibration/registration.h"
#include "capture/sequencer.h"
#include "compensation/colour_image.h"
#include "compensation/stage.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/scan_accuracy.h"
#include "geometry/stage.h"
#include "pipeline/calibrate_all_stage.h"
#include "pipeline/projectors_stage.h"
#include "projection/calibrated_room.h"
#include "projection/camera_rays.h"
#include "projection/rig_directory.h"
#include "projection/stage.h"
#include "verification/verification.h"

namespace procam {
namespace {

// The demo's calibration stage: the synthetic rig calibrated from its own simulated captures
// (`procam calibrate all`), its accuracy against the ground truth, and the compensation (the
// demo's method) redone with the recovered rig, photographed in the true world.
struct CalibrationStage {
  std::string camera;                              // the synthetic camera's URI
  std::vector<std::vector<std::string>> accuracy;  // table rows
  CalibratedRoom room;  // the evaluation's patches with the rig's reflectance, its projectors
  MethodEvaluation perceptual;                     // with the recovered rig
  nlohmann::json json;
};

// The synthetic camera of the evaluated scene, as `calibrate all --camera` takes it.
std::string SyntheticCameraUri(const SceneEvaluation& evaluation, const EvaluationOptions& options) {
  return fmt::format(
      "synthetic:{}?patches={}&albedo={}&fps=500&exposure_us=1000&reference_exposure_us=1000&black="
      "8&noise=1",
      evaluation.name, options.patches, options.albedo_variation);
}

// `procam calibrate all --camera CAMERA [--scan] --out RIG_DIR` (the command line printed to
// `steps`), and the rig directory it wrote.
RigDirectory CalibrateSyntheticRig(const std::string& camera, bool scan,
                                   const std::filesystem::path& rig_dir,
                                   const ProgressCallback& steps) {
  CalibrateAllOptions calibrate;
  calibrate.camera = camera;
  calibrate.scan = scan;
  calibrate.out = rig_dir;
  calibrate.frames = 2;
  calibrate.settle_ms = 1;
  calibrate.measure_settle = false;
  calibrate.levels = {0, 32, 64, 128, 192, 255};
  calibrate.progress = steps;
  Report(steps,
         fmt::format("\n$ procam calibrate all {}", fmt::join(ChangedArgumentsOf(calibrate), " ")));
  RunCalibrateAll(calibrate);
  return ReadRigDirectory(rig_dir);
}

// Compensation by `method` of `room` (the patches the rig's projectors light, with the rig's
// reflectance, within its projection rig's bounds), its images shown by the world's true
// projectors and photographed in the true world; ΔE against the true desired appearance.
MethodEvaluation CompensateAndPhotograph(const CalibratedRoom& room,
                                         const SceneEvaluation& evaluation,
                                         const EvaluationOptions& options,
                                         CompensationMethod method,
                                         const ProgressCallback& progress) {
  const ProjectionRig& recovered = room.projection;
  MethodEvaluation result;
  result.method = method;
  CompensationOptions compensation;  // perceptual2000's loss and schedule: the recommended ones
  compensation.solver.method = method;
  compensation.solver.multires = options.multires;
  compensation.alpha = options.alpha;
  compensation.lower = recovered.lower;
  compensation.upper = recovered.upper;
  compensation.progress = progress;
  result.run = RunCompensation(room.geometry, compensation);
  result.images = RenderProjectorImages(recovered, result.run.solution.emittance, options.render,
                                        &result.render);
  result.radiance = evaluation.world->RenderRadiance(result.images);
  PixelDeltaE(result.radiance, evaluation, result.run.fine.rgb_to_xyz, result.run.fine.white_xyz,
              &result);
  return result;
}

// The room as the recovered rig `rig` calibrates it: `geometry` when given (the evaluation's),
// else `scene` subdivided at `patches`; with the rig's camera's rays when there is no geometry
// (the scanned room, whose desired appearance comes through the camera).
CalibratedRoom RecoveredRoom(const RigDirectory& rig, std::optional<GeometryStage> geometry,
                             const std::string& scene, int patches) {
  CalibratedRoomOptions room;
  room.scene = scene;
  room.rig_dir = rig.dir;
  room.patches = patches;
  room.problem = false;  // RunCompensation makes the problems
  room.camera_rays = !geometry;
  RoomSources sources;
  sources.rig = rig;
  sources.geometry = std::move(geometry);
  return BuildCalibratedRoom(room, ReadRoomSources(room, std::move(sources)));
}

nlohmann::json DeltaEJson(const MethodEvaluation& result) {
  return {
      {"method", MethodName(result.method)},       {"mean_delta_e76", result.mean_delta_e76},
      {"max_delta_e76", result.max_delta_e76},     {"mean_delta_e2000", result.mean_delta_e2000},
      {"max_delta_e2000", result.max_delta_e2000}, {"seam", result.seams.Json()}};
}

CalibrationStage RunCalibrationStage(const SceneEvaluation& evaluation,
                                     const EvaluationOptions& options, CompensationMethod method,
                                     const std::filesystem::path& rig_dir,
                                     const ProgressCallback& progress,
                                     const ProgressCallback& steps) {
  CalibrationStage stage;
  stage.camera = SyntheticCameraUri(evaluation, options);
  const RigDirectory rig = CalibrateSyntheticRig(stage.camera, false, rig_dir, steps);

  // Accuracy against the world's true projectors and camera.
  const auto angle_deg = [](const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
    return Eigen::AngleAxisd(a * b.transpose()).angle() * 180.0 / std::numbers::pi;
  };
  nlohmann::json accuracy = nlohmann::json::array();
  for (const Projector& truth : evaluation.world->projectors()) {
    const auto found = std::find_if(rig.projectors.begin(), rig.projectors.end(),
                                    [&](const Projector& p) {
                                      return p.name == ProjectorNameFrom(truth.name);
                                    });
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

  // The compensation with the recovered rig (projectors, photometry, reflectance), shown
  // by the true projectors in the true world.
  stage.room = RecoveredRoom(rig, evaluation.geometry, "", options.patches);
  stage.perceptual = CompensateAndPhotograph(stage.room, evaluation, options, method, progress);
  stage.json["perceptual_with_calibrated_rig"] = DeltaEJson(stage.perceptual);
  return stage;
}

// The demo's scan stage: the rig calibrated without the room model (`calibrate all --scan`),
// the room from its own scan (RIG_DIR/room.json), the desired appearance carried onto the
// scanned patches through the camera's view (each patch takes the mean of the true desired
// picture over the camera pixels that see it), the compensation computed on the
// scanned room and shown by the true projectors in the true world.
struct ScanStage {
  std::vector<std::vector<std::string>> surfaces;  // table rows, one per scanned surface
  std::vector<std::vector<std::string>> areas;     // table rows, one per true surface found
  MethodEvaluation perceptual;                     // on the scanned room
  cv::Mat surfaces_picture;  // camera view: true surfaces | scanned surfaces, by colour
  nlohmann::json json;
};

// A distinct display colour (BGR) per index; grey for −1.
cv::Vec3b SurfaceColour(int index) {
  if (index < 0) return cv::Vec3b(40, 40, 40);
  static const cv::Vec3b kColours[] = {{60, 180, 75},  {75, 25, 230},  {25, 225, 255},
                                       {200, 130, 0},  {48, 130, 245}, {180, 30, 145},
                                       {240, 240, 70}, {230, 50, 240}, {60, 245, 210},
                                       {190, 190, 250}, {128, 128, 0}, {255, 190, 220}};
  return kColours[index % (sizeof(kColours) / sizeof(kColours[0]))];
}

ScanStage RunScanStage(const SceneEvaluation& evaluation, const EvaluationOptions& options,
                       CompensationMethod method, const std::filesystem::path& rig_dir,
                       const ProgressCallback& progress, const ProgressCallback& steps) {
  ScanStage stage;
  const RigDirectory rig =
      CalibrateSyntheticRig(SyntheticCameraUri(evaluation, options), true, rig_dir, steps);

  CalibratedRoom room =
      RecoveredRoom(rig, std::nullopt, (rig_dir / "room.json").string(), options.patches);
  GeometryStage& geometry = room.geometry;
  const ProjectorGeometry& rig_camera = room.camera;

  // The desired appearance through the camera: the true desired picture averaged per scanned
  // patch over the pixels that see it; a patch no pixel sees takes the picture's mean.
  PatchLevel& fine = geometry.patches.fine;
  const CameraPixelRays& rays = room.camera_rays;
  const cv::Mat& desired = evaluation.desired;
  Vec3 mean = Vec3::Zero();
  int seen = 0;
  const PatchPixelSums sums = SumPixelsPerPatch(
      rays.patch, rays.width, rays.height, fine.size(), [&](int x, int y, Eigen::RowVector3d* rgb) {
        if (x >= desired.cols || y >= desired.rows) return false;
        const cv::Vec3f& value = desired.at<cv::Vec3f>(y, x);
        *rgb = Eigen::RowVector3d(value[0], value[1], value[2]);  // linear R, G, B (RenderDesired)
        if (!(rgb->maxCoeff() > 0.0)) return false;
        mean += rgb->transpose();
        ++seen;
        return true;
      });
  if (seen == 0) throw std::runtime_error("demo: the camera sees none of the scanned room");
  mean /= seen;
  fine.desired_linear =
      sums.Means(mean.transpose().replicate(fine.size(), 1));
  const int unseen = static_cast<int>((sums.count.array() == 0).count());
  geometry.patches.coarse.desired_linear =
      CoarsenPatchValues(fine.desired_linear, fine.Areas(), geometry.patches.coarse_of_fine,
                         geometry.patches.coarse.size());
  room.projection.desired = fine.desired_linear;  // the projection rig's copy (seamless light)
  stage.perceptual = CompensateAndPhotograph(room, evaluation, options, method, progress);

  // The scanned surfaces against the true ones: the frames differ by the camera's pose (true
  // in the world, calibrated in the scanned room).
  const Eigen::Isometry3d world_from_room =
      evaluation.world->camera().proj_from_world().inverse() * rig_camera.proj_from_world();
  const Scene& true_scene = evaluation.geometry.scene;
  const RoomModel true_model(true_scene);
  const RoomModel scanned_model(geometry.scene);
  // The same with the scanned room laid on the true one as well as it goes (the shape alone).
  const Eigen::Isometry3d world_from_room_fitted =
      FitScannedRoom(true_model, scanned_model, world_from_room);
  const nlohmann::json scan_json =
      nlohmann::json::parse(ReadFile(rig_dir / "result.json"))["projectors"]["scan"];
  nlohmann::json surfaces = nlohmann::json::array();
  std::vector<double> scanned_on(true_scene.surfaces.size(), 0.0);  // m² per true surface
  for (size_t s = 0; s < geometry.scene.surfaces.size(); ++s) {
    const ScannedSurfaceAccuracy accuracy = MeasureScannedSurface(
        true_model, scanned_model, static_cast<int>(s), world_from_room);
    const int true_surface = accuracy.TrueSurface();
    const double rms_mm = 1e3 * accuracy.RmsMetres(), area = accuracy.area_m2;
    const double fitted_rms_mm =
        1e3 * MeasureScannedSurface(true_model, scanned_model, static_cast<int>(s), world_from_room_fitted)
                  .RmsMetres();
    scanned_on[true_surface] += area;
    const std::string& name = geometry.scene.surfaces[s].name;
    std::string kind = "?";
    for (const nlohmann::json& entry : scan_json["surfaces"])
      if (entry["name"] == name) kind = entry["kind"].get<std::string>();
    stage.surfaces.push_back({name, kind, true_scene.surfaces[true_surface].name,
                              fmt::format("{:.1f}", rms_mm), fmt::format("{:.1f}", fitted_rms_mm),
                              fmt::format("{:.3f}", area)});
    surfaces.push_back({{"name", name},
                        {"kind", kind},
                        {"true_surface", true_scene.surfaces[true_surface].name},
                        {"corners_and_centroids_rms_mm", rms_mm},
                        {"after_best_rigid_fit_rms_mm", fitted_rms_mm},
                        {"area_m2", area}});
  }

  // Areas, per true surface: the scanned surfaces lying on it against what of it the camera
  // sees and a projector lights (what a scan can rebuild).
  const RayScene true_rays(true_scene);
  std::vector<ProjectorGeometry> true_projectors;
  for (const Projector& p : evaluation.world->projectors()) true_projectors.push_back(p.geometry);
  nlohmann::json areas = nlohmann::json::array();
  for (size_t t = 0; t < true_scene.surfaces.size(); ++t) {
    if (scanned_on[t] <= 0.0) continue;
    const double seen = SeenAndLitArea(true_model, true_rays, static_cast<int>(t),
                                       evaluation.world->camera(), true_projectors);
    const double error = seen > 0.0 ? 100.0 * (scanned_on[t] / seen - 1.0) : 0.0;
    stage.areas.push_back({true_scene.surfaces[t].name, fmt::format("{:.3f}", scanned_on[t]),
                           fmt::format("{:.3f}", seen), fmt::format("{:+.2f}", error)});
    areas.push_back({{"true_surface", true_scene.surfaces[t].name},
                     {"scanned_m2", scanned_on[t]},
                     {"seen_and_lit_m2", seen},
                     {"error_percent", error}});
  }

  // The picture: each camera pixel coloured by the true surface it sees (left) and by the
  // scanned surface it sees through the calibrated camera (right); a true surface's colour is
  // that of the scanned surface lying on it, so that matching regions match in colour.
  std::vector<int> colour_of_true(true_scene.surfaces.size(), -1);
  for (size_t s = 0; s < stage.surfaces.size(); ++s)
    for (size_t t = 0; t < true_scene.surfaces.size(); ++t)
      if (true_scene.surfaces[t].name == stage.surfaces[s][2] && colour_of_true[t] < 0)
        colour_of_true[t] = static_cast<int>(s);
  const cv::Mat& true_patch = evaluation.camera_patch;
  cv::Mat picture(rays.height, 2 * rays.width + 4, CV_8UC3, cv::Scalar(255, 255, 255));
  for (int y = 0; y < rays.height; ++y) {
    for (int x = 0; x < rays.width; ++x) {
      int t = -1;
      if (y < true_patch.rows && x < true_patch.cols) {
        const int patch = true_patch.at<int32_t>(y, x);
        if (patch >= 0) t = evaluation.geometry.patches.fine.patches[patch].surface;
      }
      picture.at<cv::Vec3b>(y, x) = SurfaceColour(t < 0 ? -1 : colour_of_true[t]);
      const int scanned = rays.patch[static_cast<size_t>(y) * rays.width + x];
      picture.at<cv::Vec3b>(y, rays.width + 4 + x) =
          SurfaceColour(scanned < 0 ? -1 : fine.patches[scanned].surface);
    }
  }
  stage.surfaces_picture = picture;
  stage.json = {{"rig", rig_dir.string()},
                {"surfaces", surfaces},
                {"areas", areas},
                {"patches", fine.size()},
                {"patches_unseen_by_the_camera", unseen},
                {"perceptual_on_scanned_room", DeltaEJson(stage.perceptual)}};
  return stage;
}

// out/report.html: the methods' colour errors and convergence, the calibration's errors against
// the truth, the scan's surfaces, the closed loop and the pictures written before.
void WriteDemoReport(const SyntheticDemoOptions& demo, const SceneEvaluation& evaluation,
                     const CalibrationStage& calibration, const std::optional<ScanStage>& scan,
                     const VerificationSummary& verified,
                     const std::vector<std::pair<std::string, std::string>>& files) {
  const std::string& scene = demo.scene;
  const std::filesystem::path& out = demo.out;
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
  // The same method's result with the true rig, where the evaluation ran it.
  const MethodEvaluation* true_rig = &evaluation.methods.back();
  for (const MethodEvaluation& m : evaluation.methods)
    if (m.method == demo.method) true_rig = &m;
  report.Paragraph(fmt::format(
      "Compensation ({}) computed with the calibrated rig instead of the ground truth, shown "
      "by the true "
      "projectors: mean ΔE76 {:.2f} (max {:.1f}), mean ΔE2000 {:.2f}, seam {:.2f}; {} with the "
      "true rig: mean ΔE76 {:.2f}, mean ΔE2000 {:.2f}.",
      MethodName(demo.method), calibration.perceptual.mean_delta_e76,
      calibration.perceptual.max_delta_e76, calibration.perceptual.mean_delta_e2000,
      calibration.perceptual.seams.seam, MethodName(true_rig->method), true_rig->mean_delta_e76,
      true_rig->mean_delta_e2000));
  report.Figures({{std::string(MethodName(demo.method)) + ", calibrated rig",
                   cv::imread((out / "perceptual_calibrated.png").string())},
                  {"ΔE76, calibrated rig",
                   cv::imread((out / "perceptual_calibrated_delta_e76.png").string())}});
  if (scan) {
    report.Heading("The room from its own scan");
    const MethodEvaluation& on_model = calibration.perceptual;
    report.Paragraph(fmt::format(
        "procam calibrate all --scan: no room model and no guess; the projectors' lenses and "
        "poses from the structured light alone, the scale from a photo of the chessboard on the "
        "floor, the room's surfaces from the triangulated points (RIG_DIR/room.json), the "
        "desired appearance carried onto them through the camera's view. Compensation ({}) "
        "computed on the scanned room, shown by the true projectors in the true "
        "room: mean ΔE2000 {:.2f} (ΔE76 {:.2f}, seam {:.2f}); computed on the true model with "
        "the calibrated rig: mean ΔE2000 {:.2f} (ΔE76 {:.2f}): {:+.2f} ΔE2000 from the scan.",
        MethodName(demo.method), scan->perceptual.mean_delta_e2000, scan->perceptual.mean_delta_e76,
        scan->perceptual.seams.seam, on_model.mean_delta_e2000, on_model.mean_delta_e76,
        scan->perceptual.mean_delta_e2000 - on_model.mean_delta_e2000));
    report.Table({"scanned surface", "kind", "lies on (true)", "corners and centroids from the "
                  "truth, RMS mm (frames by the camera's pose)", "the same after the best rigid fit of the "
                  "whole room (shape alone)", "area m²"},
                 scan->surfaces);
    report.Paragraph(
        "Areas per true surface: the scanned surfaces lying on it against what of it the camera "
        "sees and a projector lights (1 cm cells), which is all a scan can rebuild.");
    report.Table({"true surface", "scanned m²", "seen and lit m²", "error %"}, scan->areas);
    report.Figures(
        {{"camera view: the true surfaces (left) and the scanned ones (right), a scanned "
          "surface in the colour of the true one it lies on",
          scan->surfaces_picture},
         {std::string(MethodName(demo.method)) + ", computed on the scanned room",
          cv::imread((out / "perceptual_scanned.png").string())}});
    // Where the self-calibration is sure of each projector (rig_scan/projectors_report.html).
    std::vector<std::pair<std::string, cv::Mat>> uncertainty;
    for (const Projector& projector : evaluation.world->projectors()) {
      const std::string name = ProjectorNameFrom(projector.name);
      const std::filesystem::path picture = ProjectorUncertaintyPicture(out / "rig_scan", name);
      if (std::filesystem::exists(picture))
        uncertainty.emplace_back(name + ": projection uncertainty (scale in rig_scan/projectors_report.html)",
                                 cv::imread(picture.string()));
    }
    if (!uncertainty.empty()) report.Figures(uncertainty);
  }
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
}

}  // namespace

void SyntheticDemoOptions::Declare(OptionTable* table) {
  table
      ->Text("scene", &scene,
             "a synthetic scene (" + fmt::format("{}", fmt::join(SyntheticSceneNames(), ", ")) +
                 ") or a scene JSON file: with projectors and a camera a synthetic rig (every "
                 "stage, as synthetic:ROOM.json), else geometry and compensation only")
      .Integer("patches", &patches, 4, std::numeric_limits<int>::max(), "", "solver patches")
      .Path("out", &out, "output directory")
      .Choice("method", &method, MethodChoices(),
              "the compensation of the calibrated and scanned stages and of the closed loop "
              "(the true rig's table compares every method)")
      .Text("camera", &camera,
            "run the pipeline on a rig instead: the camera URI (v4l2:..., aravis:..., or "
            "synthetic:SCENE?...); --scene is then the room model (a scene file, or "
            "synthetic:NAME)")
      .Texts("display", &displays,
             "with --camera: each projector's monitor, in order (glfw:N|NAME)")
      .Texts("names", &names, "with --camera: projector names")
      .Text("chessboard", &chessboard, "with --camera: chessboard photos of the camera")
      .Text("camera-model", &camera_model, "with --camera: a calibrated camera.cameramodel instead")
      .Text("camera-scale", &camera_scale,
            "with --camera: camera value per unit exitance (number or R,G,B; synthetic cameras: "
            "automatic)")
      .Text("camera-guess", &camera_guess,
            "with --camera: camera position and a point it looks at, "
            "x,y,z,look_x,look_y,look_z")
      .Integer("frames", &frames, 1, 1000, "", "with --camera: frames averaged per pattern");
  DeclareSettleOption(table, &settle_ms, &measure_settle);
  table->Integer("iterations", &iterations, 1, 50, "", "with --camera: closed-loop photos at most")
      .Choice("light", &light, LightFieldChoices(),
              "smooth: the light varies smoothly over each surface, stepping only where the "
              "desired appearance does, each patch's flux kept (seamless); flat: one uniform "
              "level per patch")
      .NegatedFlag("no-scan", &scan,
                   "synthetic rig: skip the scan stage (the rig calibrated and the room scanned "
                   "without the model, compensated on the scan)");
}

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
      RunCalibrationStage(evaluation, options, demo.method, out / "rig", demo.progress, demo.steps);
  std::optional<ScanStage> scan;
  if (demo.scan) {
    Report(demo.progress,
           "demo: scan stage — the rig calibrated without the room model, the room from its own "
           "scan (procam calibrate all --scan), compensation on the scanned room");
    scan =
        RunScanStage(evaluation, options, demo.method, out / "rig_scan", demo.progress, demo.steps);
    WritePng(out / "scanned_surfaces.png", scan->surfaces_picture);
    WritePng(out / "perceptual_scanned.png", LinearToDisplay(scan->perceptual.radiance));
  }
  // Verification: the calibrated solution photographed, compared with its prediction, and the
  // model refined from the photos (procam verify).
  Report(demo.progress,
         "demo: verification stage — photos against the predicted L*a*b*, the closed loop (procam "
         "verify)");
  WriteCompensation(calibration.room.geometry, calibration.perceptual.run,
                    out / "perceptual_calibrated", false);
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
  if (scan) result["scan"] = scan->json;
  result["verification"] = {{"summary", verified.BriefReport()},
                            {"best_iteration", verified.best},
                            {"result", (out / "verify" / "result.json").string()}};
  WriteFileAtomically(out / "result.json", result.dump(2) + "\n");

  WriteDemoReport(demo, evaluation, calibration, scan, verified, files);
  SyntheticDemoSummary summary;
  summary.methods = evaluation.methods;
  summary.calibrated = calibration.perceptual;
  summary.verification = verified.BriefReport();
  if (scan) summary.scanned = scan->perceptual;
  summary.out = out;
  return summary;
}

}  // namespace procam
