// procam verify RIG_DIR SOLUTION_DIR --camera URI --out DIR: show the solution, photograph the
// room, compare with the predicted L*a*b* appearance and close the loop (apps/verification.h).
#include <iostream>
#include <memory>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "apps/stop_signals.h"
#include "base/io.h"
#include "base/output_directory.h"
#include "capture/camera.h"
#include "capture/devices.h"
#include "procam/config.h"
#include "verification/verification.h"
#if PROCAM_WITH_GLFW
#include "projection/glfw_display.h"
#endif

namespace procam {
namespace {

struct VerifyArguments {
  std::string rig, solution, out, camera, camera_response, camera_scale;
  std::vector<std::string> displays;
  VerificationOptions options;  // the closed loop's and the sequencer's declared options
  SettleSetting settle{false, SequencerOptions().settle_ms};
  OptionTable table{"verify"};
};

void RunVerify(VerifyArguments& args) {
  RegisterDeviceBackends();
  VerificationOptions options = args.options;
  options.rig_dir = args.rig;
  options.solution_dir = args.solution;
  options.out = args.out;
  options.camera = args.camera;
  options.camera_response = args.camera_response;
  options.sequencer.settle_ms = args.settle.ms;
  options.measure_latency = args.settle.measure;
  if (!args.camera_scale.empty()) options.camera_scale = ParsePositiveRgb("--camera-scale", args.camera_scale);
  options.progress = LogProgress();
  // A signal stops it cleanly (apps/stop_signals.h): main says where, exit kStoppedExitCode.
  options.stop = &StopOnSignals();
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("verify: " + why);
  if (!args.displays.empty() && CameraUri::Parse(options.camera).scheme() == "synthetic") {
    throw IoError("--display: camera '" + options.camera +
                  "' photographs the simulated room, whose own projectors show the images");
  }
  for (const std::string& display : args.displays) options.displays.push_back(OpenMonitorDisplay(display));
  const VerificationSummary summary = RunVerification(options);
  std::cout << summary.BriefReport() << "\nwrote " << args.out << "/result.json, report.html, iterations/\n";
}

}  // namespace

void AddVerifyCommand(CLI::App& app) {
  auto args = std::make_shared<VerifyArguments>();
  CLI::App* cmd = app.add_subcommand(
      "verify",
      "Show a solution, photograph the room, compare with the predicted L*a*b* appearance, and "
      "refine the model in a closed loop");
  cmd->add_option("rig", args->rig, "Rig directory (rig.json: camera.model, projectors[])")->required();
  cmd->add_option("solution", args->solution,
                  "Solution directory (procam compensate SCENE --rig RIG_DIR --out DIR)")
      ->required();
  cmd->add_option("--camera", args->camera, "Camera URI: synthetic:SCENE?..., aravis:<id>, v4l2:/dev/video0")
      ->required();
  cmd->add_option("--out", args->out, "Output directory")->required();
  cmd->add_option("--display", args->displays,
                  "Per projector, in rig.json's order: glfw:N|NAME, its monitor (procam show "
                  "--list); not for synthetic cameras");
  args->options.Declare(&args->table);
  AddOptions(cmd, args->table);
  cmd->add_option("--camera-scale", args->camera_scale,
                  "Camera value per unit exitance (scene units), number or R,G,B; default: "
                  "rig.json camera.colour, or the synthetic camera's own");
  cmd->add_option("--camera-black", args->options.camera_black,
                  "Camera black level in DN (default: rig.json camera.colour.black, the synthetic "
                  "URI's, or 0)");
  cmd->add_option("--camera-response", args->camera_response,
                  "camera_response.json (procam calibrate response) for a camera that is not "
                  "linear; needs --exposure-us bracketing");
  cmd->add_option("--gain", args->options.gain, "Camera gain (dB for Aravis/test cameras)");
  AddSettleOption(cmd, &args->settle);
  cmd->add_option("--exposure-us", args->options.sequencer.exposures_us,
                  "Exposure(s), microseconds; several bracket and merge to HDR")
      ->delimiter(',');
  cmd->callback([args] {
    CheckOutputDirectory(args->out, DirectoryKind::kVerificationRun);
    RunVerify(*args);
  });
}

}  // namespace procam
