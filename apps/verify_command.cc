// procam verify RIG_DIR SOLUTION_DIR --camera URI --out DIR: show the solution, photograph the
// room, compare with the predicted L*a*b* appearance and close the loop
// (verification/verification.h), its options as VerificationOptions declares them.
#include <iostream>
#include <memory>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "apps/stop_signals.h"
#include "base/output_directory.h"
#include "capture/devices.h"
#include "verification/verification.h"

namespace procam {

void AddVerifyCommand(CLI::App& app) {
  CLI::App* cmd = app.add_subcommand(
      "verify",
      "Show a solution, photograph the room, compare with the predicted L*a*b* appearance, and "
      "refine the model in a closed loop");
  const auto options = AddDeclaredOptions<VerificationOptions>(cmd);
  cmd->callback([options] {
    CheckOutputDirectory(options->out, DirectoryKind::kVerificationRun);
    RegisterDeviceBackends();
    options->open_display = OpenMonitorDisplay;
    options->progress = LogProgress();
    // A signal stops it cleanly (apps/stop_signals.h): main says where, exit kStoppedExitCode.
    options->stop = &StopOnSignals();
    const VerificationSummary summary = RunVerification(*options);
    std::cout << summary.BriefReport() << "\nwrote " << options->out.string()
              << "/result.json, report.html, iterations/\n";
  });
}

}  // namespace procam
