// procam compensate: the room (CalibratedRoomOptions), the solve (CompensationOptions) and where
// the solution goes (SolutionOutputOptions), each as its struct declares its options.
#include <iostream>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "pipeline/compensate_stage.h"

namespace procam {

void AddCompensationCommands(CLI::App& app) {
  CLI::App* cmd = app.add_subcommand("compensate", "Compute the emittance that makes the room look as desired");
  const auto compensation = AddDeclaredOptions<CompensationOptions>(cmd);
  const auto room = AddDeclaredOptions<CalibratedRoomOptions>(cmd);
  const auto output = AddDeclaredOptions<SolutionOutputOptions>(cmd);
  cmd->callback([compensation, room, output] {
    CalibratedRoomOptions room_options = *room;
    room_options.progress = LogProgress();
    CompensationOptions options = *compensation;
    options.progress = LogProgress();
    const CompensationRun run = CompensateRoom(room_options, options, *output);
    std::cout << run.summary.BriefReport() << "\n"
              << "objective (L*a*b*) " << run.perceptual_objective << "; ΔE76 mean "
              << run.mean_delta_e76 << " max " << run.max_delta_e76 << "; ΔE2000 mean "
              << run.mean_delta_e2000 << " max " << run.max_delta_e2000 << "\nwrote "
              << output->out.string() << "/result.json, E.npy, B.npy\n";
  });
}

}  // namespace procam
