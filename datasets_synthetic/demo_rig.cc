// procam demo beyond the synthetic rig (demo.h): the pipeline on a rig, each stage printed as the
// command a person would run, and a scene file without devices (geometry and compensation).
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "base/io.h"
#include "base/option_table.h"
#include "base/parse.h"
#include "compensation/stage.h"
#include "datasets_synthetic/demo.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/scene_info.h"
#include "geometry/stage.h"
#include "pipeline/calibrate_all_stage.h"
#include "pipeline/compensate_stage.h"
#include "projection/calibrated_room.h"
#include "projection/stage.h"
#include "verification/verification.h"

namespace procam {
namespace {

// calibrate → compensate → project → photograph → verify → refine, each stage a library call
// given to options.steps as the command a person would run (`$ procam ...`), on whatever the
// camera URI names; `scene` is the room model.
std::string RunRigDemo(const SyntheticDemoOptions& options, const std::string& scene) {
  const std::filesystem::path out = options.out, rig_dir = out / "rig",
                              solution_dir = out / "solution", images = out / "images";
  Report(options.progress, "demo on a rig: stage 1/4 calibration");
  CalibrateAllOptions calibrate;
  calibrate.camera = options.camera;
  calibrate.scene = scene;
  calibrate.out = rig_dir;
  calibrate.patches = options.patches;
  calibrate.frames = options.frames;
  calibrate.settle_ms = options.settle_ms;
  calibrate.measure_settle = options.measure_settle;
  calibrate.chessboard = options.chessboard;
  calibrate.camera_model = options.camera_model;
  calibrate.camera_scale = options.camera_scale;
  calibrate.camera_guess = options.camera_guess;
  calibrate.names = options.names;
  calibrate.display_names = options.displays;
  calibrate.open_display = options.open_display;
  calibrate.progress = options.steps;
  Report(options.steps,
         fmt::format("\n$ procam calibrate all {}", fmt::join(ChangedArgumentsOf(calibrate), " ")));
  RunCalibrateAll(calibrate);

  Report(options.progress, "stage 2/4 compensation with the calibrated rig");
  CalibratedRoomOptions room_options;
  room_options.scene = scene;
  room_options.rig_dir = rig_dir;
  room_options.patches = options.patches;
  room_options.progress = options.progress;
  CompensationOptions compensation;
  compensation.solver.method = options.method;
  compensation.solver.multires = true;
  compensation.progress = options.progress;
  SolutionOutputOptions solution;
  solution.out = solution_dir;
  Report(options.steps, fmt::format("\n$ procam compensate {} {} {}",
                                    fmt::join(ChangedArgumentsOf(room_options), " "),
                                    fmt::join(ChangedArgumentsOf(compensation), " "),
                                    fmt::join(ChangedArgumentsOf(solution), " ")));
  CompensateRoom(room_options, compensation, solution);

  Report(options.progress, "stage 3/4 projector images");
  ProjectionStageOptions projection;
  projection.solution = solution_dir;
  projection.out = images;
  projection.light = options.light;
  projection.progress = options.steps;
  Report(options.steps,
         fmt::format("\n$ procam project {}", fmt::join(ChangedArgumentsOf(projection), " ")));
  ProjectSolution(projection);

  Report(options.progress, "stage 4/4 photographs, verification and the closed loop");
  VerificationOptions verify;
  verify.rig_dir = rig_dir;
  verify.solution_dir = solution_dir;
  verify.out = out / "verify";
  verify.camera = options.camera;
  verify.display_names = options.displays;
  verify.open_display = options.open_display;
  verify.iterations = options.iterations;
  verify.light = options.light;
  verify.sequencer.frames_per_pattern = options.frames;
  verify.sequencer.settle_ms = options.settle_ms;
  verify.measure_latency = options.measure_settle;
  if (!options.camera_scale.empty())
    verify.camera_scale =
        ParsePositiveRgb(FlagOf(options, &options.camera_scale), options.camera_scale);
  verify.progress = options.progress;
  Report(options.steps,
         fmt::format("\n$ procam verify {}", fmt::join(ChangedArgumentsOf(verify), " ")));
  const VerificationSummary verified = RunVerification(verify);
  return verified.BriefReport() + "\n\nwrote " + out.string() +
         "/: rig/ (the calibration), solution/ (E.npy, B.npy), images/ (one PNG per projector), "
         "verify/report.html (photos, ΔE per iteration)\n";
}

// A scene file without a camera: geometry and compensation, numbers per patch.
std::string RunSceneFileDemo(const SyntheticDemoOptions& options) {
  const std::filesystem::path& out = options.out;
  Report(options.progress, fmt::format("procam demo on {}: stage 1/2 geometry", options.scene));
  GeometryOptions geometry;
  geometry.patches = options.patches;
  geometry.progress = options.progress;
  const GeometryStage stage = RunGeometryStage(options.scene, geometry);
  ExportGeometryProblem(stage, 0.5, out / "problem");
  WriteFormFactorImage(stage.form_factors, out / "form_factors.png");
  std::string description = DescribeGeometry(stage);
  description.pop_back();  // its last line's end: a progress line has none
  Report(options.steps, description);
  Report(options.progress, "stage 2/2: compensation (naive, reverse, linear, perceptual)");
  nlohmann::json methods = nlohmann::json::object();
  std::string table =
      "\n  method        mean ΔE76  max ΔE76  mean ΔE2000  objective      solve s\n";
  for (const CompensationMethod method :
       {CompensationMethod::kNaive, CompensationMethod::kReverse, CompensationMethod::kLinear,
        CompensationMethod::kPerceptual}) {
    CompensationOptions compensation;
    compensation.solver.method = method;
    compensation.solver.multires = method == CompensationMethod::kPerceptual;
    compensation.progress = options.progress;
    const CompensationRun run = RunCompensation(stage, compensation);
    WriteCompensation(stage, run, out / MethodName(method), false);
    methods[MethodName(method)] = CompensationResultJson(stage, run);
    table += fmt::format("  {:<12} {:>10.2f} {:>9.2f} {:>12.2f}  {:<13.6e} {:.3f}\n",
                         MethodName(method), run.mean_delta_e76, run.max_delta_e76,
                         run.mean_delta_e2000, run.perceptual_objective, run.summary.solve_seconds);
  }
  const nlohmann::json result = {
      {"scene", options.scene}, {"patches", stage.patches.fine.size()}, {"methods", methods}};
  WriteFileAtomically(out / "result.json", result.dump(2) + "\n");
  return table + "\nwrote " + out.string() +
         "/: problem/, form_factors.png, result.json, per method E.npy, B.npy\n(this scene file "
         "has no camera or no projectors: ΔE here is per patch, in the solver's model)\n";
}

}  // namespace

std::string SyntheticDemoSummary::Report() const {
  std::string text = "\n  method            mean ΔE76  max ΔE76  mean ΔE2000  max ΔE2000   seam\n";
  const auto row = [&text](const std::string& name, const MethodEvaluation& m, const char* note) {
    text += fmt::format("  {:<16} {:>10.2f} {:>9.1f} {:>12.2f} {:>11.1f} {:>6.2f}{}\n", name,
                        m.mean_delta_e76, m.max_delta_e76, m.mean_delta_e2000, m.max_delta_e2000,
                        m.seams.seam, note);
  };
  for (const MethodEvaluation& m : methods) row(MethodName(m.method), m, "");
  row(MethodName(calibrated.method), calibrated, "   (calibrated rig)");
  if (scanned) row(MethodName(scanned->method), *scanned, "   (scanned room, no model)");
  return text + "\nverification (closed loop, calibrated rig): " + verification + "\n\nwrote " +
         (out / "report.html").string() +
         " (open it in a browser), pictures, result.json, problem/ and per method E.npy, B.npy "
         "and projector images\n";
}

std::string RunDemo(const SyntheticDemoOptions& options) {
  std::string why;
  if (!CheckDeclared(options, &why)) throw std::invalid_argument("demo: " + why);
  std::filesystem::create_directories(options.out);
  if (!options.camera.empty()) {
    const std::vector<std::string> synthetic = SyntheticSceneNames();
    const bool named =
        std::find(synthetic.begin(), synthetic.end(), options.scene) != synthetic.end();
    return RunRigDemo(options, named ? "synthetic:" + options.scene : options.scene);
  }
  // A scene file without projectors and a camera: geometry and compensation only. With them it
  // is a synthetic rig (synthetic:ROOM.json), and the demo runs every stage on it.
  const std::string& scene = options.scene;
  if (scene.size() > 5 && scene.substr(scene.size() - 5) == ".json") {
    const Scene loaded = LoadScene(scene);
    if (loaded.cameras_json.empty() || loaded.projectors_json.empty())
      return RunSceneFileDemo(options);
  }
  return RunSyntheticDemo(options).Report();
}

}  // namespace procam
