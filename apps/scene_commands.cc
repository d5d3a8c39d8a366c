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
#include "capture/pixel_format.h"
#include "capture/scene_cameras.h"
#include "datasets_synthetic/random_rooms.h"
#include "datasets_synthetic/scan_judge.h"
#include "datasets_synthetic/scene_files.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "projection/projector.h"
#include "projection/stage.h"
#include <fmt/ranges.h>
#include "compensation/stage.h"
#include "datasets_synthetic/demo.h"
#include "datasets_synthetic/evaluation.h"
#include "geometry/stage.h"
#include "base/html_report.h"
#include "calibration/calibrated_room.h"
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

// The scene's geometry and its projectors, each read and checked in full (models included), so
// that a scene `scene info` accepts is one every other command accepts.
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

struct SceneArguments {
  std::string scene;
  std::string out;
  int patches = 0;
  double alpha = 0.5;
  bool no_scan = false;  // demo: skip the scan stage
};

// The demo on a rig: a camera (real, or a synthetic one treated like a real one), the projectors'
// monitors and the room model.
struct RigDemoArguments {
  std::string camera;
  std::vector<std::string> displays;
  std::string chessboard, camera_model, camera_scale, camera_guess;
  std::vector<std::string> names;
  int frames = 4;
  SettleSetting settle{true, 150.0};  // default: measured
  int iterations = 4;
  LightField light = LightField::kSmooth;  // --light, also without --camera
};

// calibrate → compensate → project → photograph → verify → refine, each stage a library call
// printed as the command a user would run (`$ procam ...`), on whatever the camera URI names.
void RunRigDemo(const std::string& scene, int patches, CompensationMethod method,
                const RigDemoArguments& rig, const std::filesystem::path& out) {
  RegisterDeviceBackends();
  const std::filesystem::path rig_dir = out / "rig", solution_dir = out / "solution", images = out / "images";
  spdlog::info("demo on a rig: stage 1/4 calibration");
  CalibrateAllOptions calibrate;
  calibrate.camera = rig.camera;
  calibrate.scene = scene;
  calibrate.out = rig_dir;
  calibrate.patches = patches;
  calibrate.frames = rig.frames;
  calibrate.settle_ms = rig.settle.ms;
  calibrate.measure_settle = rig.settle.measure;
  calibrate.chessboard = rig.chessboard;
  calibrate.camera_model = rig.camera_model;
  calibrate.camera_scale = rig.camera_scale;
  calibrate.camera_guess = rig.camera_guess;
  calibrate.names = rig.names;
  calibrate.display_names = rig.displays;
  calibrate.open_display = OpenMonitorDisplay;
  calibrate.progress = PrintProgress();
  std::printf("\n$ procam calibrate all %s\n",
              fmt::format("{}", fmt::join(ChangedArgumentsOf(calibrate), " ")).c_str());
  RunCalibrateAll(calibrate);

  spdlog::info("stage 2/4 compensation with the calibrated rig");
  std::printf("\n$ procam compensate %s --method %s --multires --patches %d --rig %s --out %s\n",
              scene.c_str(), MethodName(method), patches, rig_dir.c_str(), solution_dir.c_str());
  CalibratedRoomOptions room_options;
  room_options.scene = scene;
  room_options.rig_dir = rig_dir;
  room_options.patches = patches;
  room_options.problem = false;  // RunCompensation makes the fine and coarse problems
  room_options.progress = LogProgress();
  const CalibratedRoom room = LoadCalibratedRoom(room_options);
  CompensationOptions compensation;
  compensation.solver.method = method;
  compensation.solver.multires = true;
  compensation.lower = room.projection.lower;
  compensation.upper = room.projection.upper;
  compensation.progress = LogProgress();
  const CompensationRun run = RunCompensation(room.geometry, compensation);
  WriteCompensation(room.geometry, run, solution_dir, false, {{"rig", room.rig->Describe()}});

  spdlog::info("stage 3/4 projector images");
  std::printf("\n$ procam project %s --out %s --light %s\n", solution_dir.c_str(), images.c_str(),
              LightFieldName(rig.light));
  const SolutionDirectory solution = ReadSolutionDirectory(solution_dir);
  SolutionGeometry solution_geometry = ReadSolutionGeometry(solution);
  SolutionProjectors projectors = ProjectorsForSolution(solution, {}, solution_geometry.scene, &solution_geometry.patches);
  ProjectionStageOptions projection;
  projection.out = images;
  projection.progress = PrintProgress();
  projection.light = rig.light;
  RunProjectionStage(solution, solution_geometry, std::move(projectors.projectors),
                     projectors.rig_description, projection, projectors.reflectance_maps);

  spdlog::info("stage 4/4 photographs, verification and the closed loop");
  std::printf("\n$ procam verify %s %s --camera %s --out %s --iterations %d --frames %d --settle-ms %s\n",
              rig_dir.c_str(), solution_dir.c_str(), rig.camera.c_str(), (out / "verify").c_str(), rig.iterations,
              rig.frames, rig.settle.Text().c_str());
  VerificationOptions verify;
  verify.rig_dir = rig_dir;
  verify.solution_dir = solution_dir;
  verify.out = out / "verify";
  verify.camera = rig.camera;
  for (const std::string& display : rig.displays) verify.displays.push_back(OpenMonitorDisplay(display));
  verify.iterations = rig.iterations;
  verify.light = rig.light;
  verify.sequencer.frames_per_pattern = rig.frames;
  verify.sequencer.settle_ms = rig.settle.ms;
  verify.measure_latency = rig.settle.measure;
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
  ExportGeometryProblem(stage, 0.5, out / "problem");
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
            << "(this scene file has no camera or no projectors: ΔE here is per patch, in the solver's model)\n";
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
    std::cout << DescribeScene(stage);
  });

  CLI::App* write = scene->add_subcommand(
      "write", "Write a built-in synthetic scene as a scene file with its projectors and camera (open it as a "
               "synthetic rig: --camera synthetic:DIR/NAME.json)");
  write->add_option("scene", args->scene, "A synthetic scene (" + fmt::format("{}", fmt::join(SyntheticSceneNames(), ", ")) + ")")
      ->required();
  write->add_option("--out", args->out, "Output directory")->required();
  write->add_option("--patches", args->patches, "The scene file's patch target (default 1000)");
  write->callback([args] {
    const std::vector<std::string> names = SyntheticSceneNames();
    if (std::find(names.begin(), names.end(), args->scene) == names.end()) {
      throw std::invalid_argument("scene write: unknown synthetic scene '" + args->scene + "' (scenes: " +
                                  fmt::format("{}", fmt::join(names, ", ")) + ")");
    }
    const std::filesystem::path path =
        WriteSyntheticSceneFile(args->scene, args->patches > 0 ? args->patches : 1000, args->out);
    std::cout << "wrote " << path.string() << " with its projectors' and camera's models; open it as a rig with "
              << "--camera synthetic:" << path.string() << "\n";
  });

  CLI::App* random_cmd = scene->add_subcommand(
      "random", "Write a room made at random from a seed as a scene file with its projectors and camera "
                "(docs/synthetic.md#rooms-made-at-random)");
  const auto random = AddDeclaredOptions<RandomRoomOptions>(random_cmd);
  random_cmd->add_option("--out", args->out, "Output directory")->required();
  random_cmd->callback([random, args] {
    const std::filesystem::path path = WriteRandomRoom(*random, args->out);
    std::cout << "wrote " << path.string() << "; open it as a rig with --camera synthetic:" << path.string()
              << "\n";
  });

  auto judge_json = std::make_shared<std::string>();
  CLI::App* judge_cmd = scene->add_subcommand(
      "judge-scan", "Scan a scene file's rig without its model (exact correspondences plus decoding noise) and "
                    "judge the scanned room against the file (docs/scan.md#rooms-made-at-random)");
  judge_cmd->add_option("scene", args->scene, "Scene JSON with projectors and a camera")->required();
  const auto judge = AddDeclaredOptions<ScanJudgeOptions>(judge_cmd);
  judge_cmd->add_option("--json", *judge_json, "Also write the judgement as JSON to this file");
  judge_cmd->callback([judge, judge_json, args] {
    const ScanJudgement judgement = ScanAndJudge(args->scene, *judge);
    std::cout << judgement.calibration_report << "\n" << judgement.Report() << "\n"
              << fmt::format("judged {} calibrated {} found {} expected {} planar_rms_mm {:.2f} curved_rms_mm {:.2f} "
                             "area_percent {:+.2f} spurious_percent {:.2f} delta_e2000_model {:.2f} delta_e2000_scan {:.2f} "
                             "seam_scan {:.2f} seconds {:.1f}\n",
                             judgement.room, judgement.calibrated ? 1 : 0, judgement.found, judgement.expected,
                             judgement.worst_planar_rms_mm, judgement.worst_curved_rms_mm,
                             judgement.worst_area_error_percent, judgement.largest_spurious_percent,
                             judgement.model_delta_e2000, judgement.scan_delta_e2000, judgement.scan_seam,
                             judgement.seconds);
    if (!judge_json->empty()) WriteFileAtomically(*judge_json, judgement.Json().dump(2) + "\n");
  });

  CLI::App* export_cmd = scene->add_subcommand("export", "Write the problem as NumPy .npy files and problem.json");
  export_cmd->add_option("scene", args->scene, "Scene JSON")->required();
  export_cmd->add_option("--out", args->out, "Output directory")->required();
  export_cmd->add_option("--patches", args->patches, "Override the scene's target patch count");
  export_cmd->add_option("--alpha", args->alpha, "Weight of the absolute term, in (0,1]")
      ->check(FiniteRange(1e-9, 1.0))
      ->capture_default_str();
  export_cmd->callback([args] {
    CheckNotProcamDirectory(args->out, "scene export");
    const GeometryStage stage = RunGeometryStage(args->scene, GeometryArguments(args->patches));
    const std::string description = DescribeScene(stage);  // checks the projectors first
    ExportGeometryProblem(stage, args->alpha, args->out);
    std::cout << description << "exported to " << args->out << "\n";
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
                   "tiny_box) or a scene JSON file: with projectors and a camera a synthetic rig (every stage, "
                   "as synthetic:ROOM.json), else geometry and compensation only")
      ->capture_default_str();
  demo->add_option("--patches", args->patches, "Solver patches")->capture_default_str();
  demo->add_option("--out", args->out, "Output directory")->capture_default_str();
  // --method: the compensation of the calibrated (and scanned) stages, declared by the demo's
  // options (base/option_table.h).
  auto synthetic = std::make_shared<SyntheticDemoOptions>();
  auto synthetic_table = std::make_shared<OptionTable>("demo");
  synthetic->Declare(synthetic_table.get());
  AddOptions(demo, *synthetic_table);
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
  AddSettleOption(demo, &rig->settle);
  demo->add_option("--iterations", rig->iterations, "With --camera: closed-loop photos at most")
      ->capture_default_str();
  AddLightOption(demo, &rig->light);
  demo->add_flag("--no-scan", args->no_scan,
                 "Synthetic rig: skip the scan stage (the rig calibrated and the room scanned "
                 "without the model, compensated on the scan)");
  demo->callback([args, rig, demo_options = synthetic, synthetic_table] {
    const std::filesystem::path out = args->out;
    std::filesystem::create_directories(out);
    if (!rig->camera.empty()) {
      const std::vector<std::string> synthetic = SyntheticSceneNames();
      const bool named = std::find(synthetic.begin(), synthetic.end(), args->scene) != synthetic.end();
      RunRigDemo(named ? "synthetic:" + args->scene : args->scene, args->patches,
                 demo_options->method, *rig, out);
      return;
    }
    // A scene file without projectors and a camera: geometry and compensation only. With them it
    // is a synthetic rig (synthetic:ROOM.json), and the demo runs every stage on it.
    if (args->scene.size() > 5 && args->scene.substr(args->scene.size() - 5) == ".json") {
      const Scene scene = LoadScene(args->scene);
      if (scene.cameras_json.empty() || scene.projectors_json.empty()) {
        RunJsonDemo(args->scene, args->patches, out);
        return;
      }
    }
    SyntheticDemoOptions demo = *demo_options;
    demo.scene = args->scene;
    demo.patches = args->patches;
    demo.light = rig->light;
    demo.scan = !args->no_scan;
    demo.out = out;
    demo.progress = LogProgress();
    demo.steps = PrintProgress();
    const SyntheticDemoSummary summary = RunSyntheticDemo(demo);
    std::cout << "\n  method            mean ΔE76  max ΔE76  mean ΔE2000  max ΔE2000   seam\n";
    const auto row = [](const std::string& name, const MethodEvaluation& m, const char* note) {
      std::cout << fmt::format("  {:<16} {:>10.2f} {:>9.1f} {:>12.2f} {:>11.1f} {:>6.2f}{}\n", name, m.mean_delta_e76,
                               m.max_delta_e76, m.mean_delta_e2000, m.max_delta_e2000, m.seams.seam, note);
    };
    for (const MethodEvaluation& m : summary.methods) row(MethodName(m.method), m, "");
    row(MethodName(summary.calibrated.method), summary.calibrated, "   (calibrated rig)");
    if (summary.scanned)
      row(MethodName(summary.scanned->method), *summary.scanned, "   (scanned room, no model)");
    std::cout << "\nverification (closed loop, calibrated rig): " << summary.verification << "\n";
    std::cout << "\nwrote " << (out / "report.html").string() << " (open it in a browser), pictures, result.json, "
              << "problem/ and per method E.npy, B.npy and projector images\n";
  });
}

}  // namespace procam
