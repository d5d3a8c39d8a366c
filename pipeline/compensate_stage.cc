#include "pipeline/compensate_stage.h"

#include <fmt/format.h>

#include <stdexcept>
#include <utility>

#include "base/option_table.h"
#include "base/output_directory.h"
#include "base/progress.h"
#include "compensation/solver.h"

namespace procam {

CompensationRun CompensateRoom(CalibratedRoomOptions room, const CompensationOptions& options,
                               const SolutionOutputOptions& output) {
  CheckOutputDirectory(output.out, DirectoryKind::kSolution);
  if (options.solver.device == Device::kCuda) {
    // Before the form factors: a missing device fails at once, in one line.
    std::string why;
    if (!CudaAvailable(&why))
      throw std::runtime_error(FlagOf(options, &options.solver.device) + " cuda: " + why);
  }
  room.problem = false;  // RunCompensation makes the fine and coarse problems
  RoomSources sources = ReadRoomSources(room);
  if (output.export_problem && room.storage == FormFactorStorage::kCompressed) {
    throw std::invalid_argument(FlagOf(output, &output.export_problem) +
                                " writes the dense F.npy: not with " + FlagOf(room, &room.storage) +
                                " compressed");
  }
  const CalibratedRoom calibrated = BuildCalibratedRoom(room, std::move(sources));
  CompensationOptions solve = options;
  if (calibrated.projectors.empty()) {
    // A scene without projectors (a built-in scene by name, a scene file without "projectors")
    // is solved within its bounds: said before the solve, as project needs projectors to use the
    // solution.
    Report(room.progress,
           fmt::format(
               "warning: compensate: {} lists no projectors and no {} was given: solving within "
               "the scene's bounds; procam project will need {} (or write the scene with its "
               "projectors: procam scene write NAME --out DIR)",
               room.scene, FlagOf(room, &room.rig_dir), FlagOf(room, &room.rig_dir)));
  } else {
    solve.lower = calibrated.projection.lower;
    solve.upper = calibrated.projection.upper;
  }
  CompensationRun run = RunCompensation(calibrated.geometry, solve);
  nlohmann::json extra = nlohmann::json::object();
  if (calibrated.rig) extra["rig"] = calibrated.rig->Describe();
  WriteCompensation(calibrated.geometry, run, output.out, output.export_problem, extra);
  return run;
}

}  // namespace procam
