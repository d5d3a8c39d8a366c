// procam: one binary, one subcommand per pipeline stage. Errors from files and devices are
// caught here once and turned into one line on stderr and a non-zero exit.

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <string>

#include "apps/commands.h"
#include "apps/stop_signals.h"
#include "base/stop.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "procam/config.h"

namespace {

// Every error is one line on stderr: a message that spans lines (a library's) is joined.
int PrintError(const char* message) {
  std::string line = message;
  for (char& c : line) {
    if (c == '\n' || c == '\r') c = ' ';
  }
  std::fprintf(stderr, "procam: error: %s\n", line.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"procam: make a white room look like a desired scene with projectors, "
               "interreflections included (Sheng et al., EGSR 2011)"};
  app.set_version_flag("--version", PROCAM_VERSION);
  // The simulated world (synthetic:NAME scenes and cameras) reaches the libraries through their
  // registries; the libraries never include it.
  procam::RegisterSyntheticWorld();
  app.require_subcommand(1);
  procam::AddDemoCommand(app);
  procam::AddSceneCommands(app);
  procam::AddCompensationCommands(app);
  procam::AddEvaluationCommands(app);
  procam::AddBenchCommands(app);
  procam::AddCaptureCommands(app);
  procam::AddStructuredLightCommands(app);
  procam::AddVerifyCommand(app);
  procam::AddEmulateCommand(app);
  procam::AddCalibrateCommands(app);
  procam::AddProjectionCommands(app);
  procam::AddNodeCommands(app);
  procam::AddOptionsCommand(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& error) {
    // --help and --version print and succeed; a bad option is an error like any other: one line.
    if (error.get_exit_code() == 0) return app.exit(error);
    return PrintError(error.what());
  } catch (const procam::Stopped& stopped) {
    // A command stopped by a signal before its work was done: one line, where it stopped and how
    // to go on (the message's), and its own exit status.
    std::fprintf(stderr, "procam: stopped: %s\n", stopped.what());
    return procam::kStoppedExitCode;
  } catch (const std::exception& error) {
    return PrintError(error.what());
  }
  return 0;
}
