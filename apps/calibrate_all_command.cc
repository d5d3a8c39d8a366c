// procam calibrate all --camera URI --scene SCENE --out RIG_DIR: a whole rig, end to end
// (pipeline/calibrate_all_stage.h), its options as CalibrateAllOptions declares them.
#include <memory>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "apps/stop_signals.h"
#include "base/output_directory.h"
#include "capture/devices.h"
#include "pipeline/calibrate_all_stage.h"

namespace procam {

void AddCalibrateAllCommand(CLI::App& calibrate) {
  CLI::App* all = calibrate.add_subcommand(
      "all",
      "Capture and calibrate a whole rig: camera, projectors, registration, photometry");
  const auto options = AddDeclaredOptions<CalibrateAllOptions>(all);
  all->callback([options] {
    CheckOutputDirectory(options->out, DirectoryKind::kRig);
    RegisterDeviceBackends();
    options->open_display = OpenMonitorDisplay;
    options->progress = PrintProgress();
    // A signal stops it cleanly (apps/stop_signals.h): main says where, exit kStoppedExitCode.
    options->stop = &StopOnSignals();
    RunCalibrateAll(*options);
  });
}

}  // namespace procam
