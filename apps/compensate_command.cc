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

// Everything compensate reads: the room's and the solve's options (each declared once by its
// struct) and the command's own.
struct CompensateArguments {
  CalibratedRoomOptions room;
  CompensationOptions compensation;
  std::filesystem::path out;
  bool export_problem = false;
  OptionTable room_table{"room"}, compensation_table{"compensate"};
};

}  // namespace

void AddCompensationCommands(CLI::App& app) {
  auto args = std::make_shared<CompensateArguments>();
  CLI::App* cmd = app.add_subcommand("compensate", "Compute the emittance that makes the room look as desired");
  cmd->add_option("scene", args->room.scene, "Scene JSON")->required();
  args->compensation.Declare(&args->compensation_table);
  args->room.Declare(&args->room_table);
  AddOptions(cmd, args->compensation_table);
  AddOptions(cmd, args->room_table);
  cmd->add_flag("--export", args->export_problem,
                "Also write the whole problem (F.npy, ...) into --out");
  cmd->add_option("--out", args->out, "Output directory")->required();
  cmd->callback([args] {
    CheckOutputDirectory(args->out, DirectoryKind::kSolution);
    CompensationOptions options = args->compensation;
    if (options.solver.device == Device::kCuda) {
      // Before the form factors: a missing device fails at once, in one line.
      std::string why;
      if (!CudaAvailable(&why)) throw std::runtime_error("--device cuda: " + why);
    }
    CalibratedRoomOptions room_options = args->room;
    room_options.problem = false;  // RunCompensation makes the fine and coarse problems
    room_options.progress = LogProgress();
    // The rig is read first: a bad rig.json fails before the form factors are computed.
    RoomSources sources = ReadRoomSources(room_options);
    if (args->export_problem && room_options.storage == FormFactorStorage::kCompressed) {
      throw std::invalid_argument("--export writes the dense F.npy: not with --form-factors compressed");
    }
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
          room_options.scene);
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
              << "objective (L*a*b*) " << run.perceptual_objective << "; ΔE76 mean "
              << run.mean_delta_e76 << " max " << run.max_delta_e76 << "; ΔE2000 mean "
              << run.mean_delta_e2000 << " max " << run.max_delta_e2000 << "\nwrote "
              << args->out.string() << "/result.json, E.npy, B.npy\n";
  });
}

}  // namespace procam
