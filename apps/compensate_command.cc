// procam compensate.
#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>
#include <optional>
#include <stdexcept>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "base/output_directory.h"
#include "compensation/stage.h"
#include "calibration/calibrated_room.h"
#include "geometry/stage.h"

namespace procam {
namespace {

struct CompensateArguments {
  std::string scene, out, rig, method = "perceptual", device = "cpu", loss = "soft_l1";
  double alpha = 0.5, loss_scale = SolverOptions().robust_scale;
  int patches = 0, metric_rounds = SolverOptions().metric_rounds;
  bool multires = false, export_problem = false;
  std::string form_factors = "dense";
};

}  // namespace

void AddCompensationCommands(CLI::App& app) {
  auto args = std::make_shared<CompensateArguments>();
  CLI::App* cmd = app.add_subcommand("compensate", "Compute the emittance that makes the room look as desired");
  cmd->add_option("scene", args->scene, "Scene JSON")->required();
  cmd->add_option("--method", args->method,
                  "naive | reverse | linear | perceptual (the paper's, CIE76) | perceptual2000 (the "
                  "objective in CIEDE2000 with a robust loss; docs/solver.md)")
      ->check(CLI::IsMember({"naive", "reverse", "linear", "perceptual", "perceptual2000"}))
      ->capture_default_str();
  cmd->add_option("--loss", args->loss,
                  "perceptual2000: loss on each patch's ΔE00²: squared | soft_l1 | huber | cauchy")
      ->check(CLI::IsMember({"squared", "soft_l1", "huber", "cauchy"}))
      ->capture_default_str();
  cmd->add_option("--loss-scale", args->loss_scale, "perceptual2000: the loss's scale, ΔE00 units")
      ->check(FiniteRange(1e-6, 1e6))
      ->capture_default_str();
  cmd->add_option("--metric-rounds", args->metric_rounds,
                  "perceptual2000: reweighting rounds (CIEDE2000's metric and the loss's weights "
                  "re-evaluated at the last round's result)")
      ->check(FiniteRange(1, 100))
      ->capture_default_str();
  cmd->add_option("--alpha", args->alpha, "Weight of the absolute term against the spatial term, in (0,1]")
      ->check(FiniteRange(1e-9, 1.0))
      ->capture_default_str();
  cmd->add_option("--patches", args->patches, "Override the scene's target patch count");
  cmd->add_option("--device", args->device,
                  "cpu | cuda: where K^-1 is applied (cuda needs a CUDA build and a GPU; docs/gpu.md)")
      ->check(CLI::IsMember({"cpu", "cuda"}))
      ->capture_default_str();
  cmd->add_flag("--multires", args->multires, "Solve the coarse patch level first and start from it");
  cmd->add_flag("--export", args->export_problem, "Also write the whole problem (F.npy, ...) into --out");
  cmd->add_option("--form-factors", args->form_factors,
                  "dense (n² doubles) | compressed (near pairs exact, far cluster pairs rank-1: rooms of "
                  "10k–100k+ patches, solved matrix-free; docs/gpu.md)")
      ->check(CLI::IsMember({"dense", "compressed"}))
      ->capture_default_str();
  cmd->add_option("--rig", args->rig,
                  "Rig directory (rig.json from procam calibrate): its projectors replace the "
                  "scene's, its reflectance.npy the scene's reflectance");
  cmd->add_option("--out", args->out, "Output directory")->required();
  cmd->callback([args] {
    CheckOutputDirectory(args->out, DirectoryKind::kSolution);
    Device device = Device::kCpu;
    ParseDevice(args->device, &device);
    if (device == Device::kCuda) {
      // Before the form factors: a missing device fails at once, in one line.
      std::string why;
      if (!CudaAvailable(&why)) throw std::runtime_error("--device cuda: " + why);
    }
    CalibratedRoomOptions room_options;
    room_options.scene = args->scene;
    room_options.rig_dir = args->rig;
    room_options.patches = args->patches;
    room_options.storage =
        args->form_factors == "compressed" ? FormFactorStorage::kCompressed : FormFactorStorage::kDense;
    room_options.problem = false;  // RunCompensation makes the fine and coarse problems
    room_options.progress = LogProgress();
    // The rig is read first: a bad rig.json fails before the form factors are computed.
    RoomSources sources = ReadRoomSources(room_options);
    if (args->export_problem && args->form_factors == "compressed") {
      throw std::invalid_argument("--export writes the dense F.npy: not with --form-factors compressed");
    }
    CompensationOptions options;
    ParseMethod(args->method, &options.solver.method);
    ParseRobustLoss(args->loss, &options.solver.robust_loss);
    options.solver.robust_scale = args->loss_scale;
    options.solver.metric_rounds = args->metric_rounds;
    options.solver.multires = args->multires;
    options.solver.device = device;
    options.alpha = args->alpha;
    options.progress = LogProgress();
    CalibratedRoom room = BuildCalibratedRoom(room_options, std::move(sources));
    // With projectors (the rig's or the scene's), their light sets the bounds; otherwise the
    // scene's "bounds".
    if (room.projectors.empty()) {
      // A scene without projectors (a built-in scene by name, a scene file without
      // "projectors") is solved within its bounds: said before the solve, as project needs
      // projectors to use the solution.
      spdlog::warn(
          "compensate: {} lists no projectors and no --rig was given: solving within the scene's "
          "bounds; procam project will need --rig (or write the scene with its projectors: procam "
          "scene write NAME --out DIR)",
          args->scene);
    } else {
      options.lower = room.projection.lower;
      options.upper = room.projection.upper;
    }
    const GeometryStage& stage = room.geometry;
    const CompensationRun run = RunCompensation(stage, options);
    nlohmann::json extra = nlohmann::json::object();
    if (room.rig) extra["rig"] = room.rig->Describe();
    WriteCompensation(stage, run, args->out, args->export_problem, extra);
    std::cout << run.summary.BriefReport() << "\n"
              << "objective (L*a*b*) " << run.perceptual_objective << "; ΔE76 mean " << run.mean_delta_e76
              << " max " << run.max_delta_e76 << "; ΔE2000 mean " << run.mean_delta_e2000 << " max "
              << run.max_delta_e2000 << "\nwrote " << args->out << "/result.json, E.npy, B.npy\n";
  });
}

}  // namespace procam
