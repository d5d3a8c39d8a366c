// procam cameras / procam capture.
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "apps/stop_signals.h"
#include "base/io.h"
#include "base/output_directory.h"
#include "capture/camera.h"
#include "capture/devices.h"
#include "capture/simulated_camera.h"
#include "pipeline/capture_stage.h"
#include "procam/config.h"

namespace procam {
namespace {

struct CamerasArguments {
  bool no_gige = false;
  bool include_virtual = false;
};

// --display: memory (nothing but test cameras sees it), else a projector's monitor.
std::shared_ptr<PatternDisplay> CaptureDisplay(const std::string& text, const std::string& camera) {
  if (text == "memory") return nullptr;
  if (FindSimulatedCamera(camera)) {
    throw IoError("display '" + text + "': camera '" + camera +
                  "' photographs the simulated room, whose projectors show the patterns (choose one with --projector)");
  }
  if (text.rfind("glfw:", 0) != 0) {
    throw IoError("display '" + text + "': unknown; use memory or glfw:N|NAME (procam show --list)");
  }
  return OpenMonitorDisplay(text);
}

void RunCapture(CaptureStageOptions options) {
  RegisterDeviceBackends();
  options.stop = &StopOnSignals();  // before the display and camera open: a stop releases them
  options.display = CaptureDisplay(options.display_name, options.camera);
  options.progress = [](const std::string& line) { std::fprintf(stderr, "procam: %s\n", line.c_str()); };
  const CaptureSummary summary = RunCaptureStage(options);
  std::cout << CaptureLine(options, summary) << "\n";
}

void RunCameras(const CamerasArguments& args) {
  RegisterDeviceBackends();
  ListCamerasOptions options;
  options.gige_discovery = !args.no_gige;
  options.include_virtual = args.include_virtual;
  std::string backends;
  for (const std::string& scheme : RegisteredCameraBackends())
    backends += (backends.empty() ? "" : ", ") + scheme;
  std::cout << "camera backends in this build: " << backends << "\n";
  if (!PROCAM_WITH_V4L2) std::cout << "  (no V4L2: install libv4l-dev and reconfigure)\n";
  if (!PROCAM_WITH_ARAVIS)
    std::cout << "  (no Aravis: install libaravis-dev libusb-1.0-0-dev and reconfigure)\n";
  const std::vector<CameraInfo> cameras = ListCameras(options);
  if (cameras.empty())
    std::cout << "no cameras found"
              << (args.include_virtual ? "" : " (--virtual lists test cameras)") << "\n";
  for (const CameraInfo& camera : cameras) {
    std::cout << "  " << (camera.uri.empty() ? camera.backend + ":" : camera.uri) << "  "
              << camera.description << "\n";
  }
}

}  // namespace

void AddCaptureCommands(CLI::App& app) {
  auto cameras_args = std::make_shared<CamerasArguments>();
  CLI::App* cameras =
      app.add_subcommand("cameras", "List the cameras procam can open, with their URIs");
  cameras->add_flag("--no-gige", cameras_args->no_gige,
                    "Skip GigE Vision discovery (it broadcasts on every network interface)");
  cameras->add_flag("--virtual", cameras_args->include_virtual,
                    "Also list virtual cameras (Aravis Fake_1, test:, synthetic:<scene>)");
  cameras->callback([cameras_args] { RunCameras(*cameras_args); });

  CLI::App* capture = app.add_subcommand(
      "capture",
      "Show a pattern sequence and capture it into a session directory; rerun to resume");
  const auto options = AddDeclaredOptions<CaptureStageOptions>(capture);
  capture->callback([options] {
    CheckOutputDirectory(options->out, DirectoryKind::kCaptureSession);
    RunCapture(*options);
  });
}

}  // namespace procam
