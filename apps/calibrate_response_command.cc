// procam calibrate response SESSION_DIR --out RIG_DIR: a camera's inverse response (camera
// linearity) from one still pattern captured at several exposures (pipeline/response_stage.h),
// its options as ResponseStageOptions declares them.
#include <memory>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "base/output_directory.h"
#include "pipeline/response_stage.h"

namespace procam {

void AddCalibrateResponseCommand(CLI::App& calibrate) {
  CLI::App* response = calibrate.add_subcommand(
      "response",
      "Camera linearity: the inverse response from one still pattern at several exposures");
  const auto options = AddDeclaredOptions<ResponseStageOptions>(response);
  response->callback([options] {
    CheckOutputDirectory(options->out, DirectoryKind::kRig);
    options->progress = PrintProgress();
    RunResponseStage(*options);
  });
}

}  // namespace procam
