// procam compensate: the room (CalibratedRoomOptions), the solve (CompensationOptions) and where
// the solution goes (SolutionOutputOptions), each as its struct declares its options.
#include <spdlog/spdlog.h>

#include <iostream>
#include <memory>
#include <stdexcept>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "base/output_directory.h"
#include "compensation/stage.h"
#include "geometry/stage.h"
#include "projection/calibrated_room.h"

namespace procam {

void AddCompensationCommands(CLI::App& app) {
  CLI::App* cmd = app.add_subcommand("compensate", "Compute the emittance that makes the room look as desired");
  const auto compensation = AddDeclaredOptions<CompensationOptions>(cmd);
  const auto room = AddDeclaredOptions<CalibratedRoomOptions>(cmd);
  const auto output = AddDeclaredOptions<SolutionOutputOptions>(cmd);
  cmd->callback([compensation, room, output] {
    CheckOutputDirectory(output->out, DirectoryKind::kSolution);
    CompensationOptions options = *compensation;
    if (options.solver.device == Device::kCuda) {
      // Before the form factors: a missing device fails at once, in one line.
      std::string why;
      if (!CudaAvailable(&why)) throw std::runtime_error("--device cuda: " + why);
    }
    CalibratedRoomOptions room_options = *room;
    room_options.problem = false;  // RunCompensation makes the fine and coarse problems
    room_options.progress = LogProgress();
    // The rig is read first: a bad rig.json fails before the form factors are computed.
    RoomSources sources = ReadRoomSources(room_options);
    if (output->export_problem && room_options.storage == FormFactorStorage::kCompressed) {
      throw std::invalid_argument("--export writes the dense F.npy: not with --form-factors compressed");
    }
    options.progress = LogProgress();
    CalibratedRoom calibrated = BuildCalibratedRoom(room_options, std::move(sources));
    // With projectors (the rig's or the scene's), their light sets the bounds; otherwise the
    // scene's "bounds".
    if (calibrated.projectors.empty()) {
      // A scene without projectors (a built-in scene by name, a scene file without
      // "projectors") is solved within its bounds: said before the solve, as project needs
      // projectors to use the solution.
      spdlog::warn(
          "compensate: {} lists no projectors and no --rig was given: solving within the scene's "
          "bounds; procam project will need --rig (or write the scene with its projectors: procam "
          "scene write NAME --out DIR)",
          room_options.scene);
    } else {
      options.lower = calibrated.projection.lower;
      options.upper = calibrated.projection.upper;
    }
    const GeometryStage& stage = calibrated.geometry;
    const CompensationRun run = RunCompensation(stage, options);
    nlohmann::json extra = nlohmann::json::object();
    if (calibrated.rig) extra["rig"] = calibrated.rig->Describe();
    WriteCompensation(stage, run, output->out, output->export_problem, extra);
    std::cout << run.summary.BriefReport() << "\n"
              << "objective (L*a*b*) " << run.perceptual_objective << "; ΔE76 mean "
              << run.mean_delta_e76 << " max " << run.max_delta_e76 << "; ΔE2000 mean "
              << run.mean_delta_e2000 << " max " << run.max_delta_e2000 << "\nwrote "
              << output->out.string() << "/result.json, E.npy, B.npy\n";
  });
}

}  // namespace procam
