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

void RunCameras(const ListCamerasOptions& options) {
  RegisterDeviceBackends();
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
              << (options.include_virtual ? "" : " (--virtual lists test cameras)") << "\n";
  for (const CameraInfo& camera : cameras) {
    std::cout << "  " << (camera.uri.empty() ? camera.backend + ":" : camera.uri) << "  "
              << camera.description << "\n";
  }
}

}  // namespace

void AddCaptureCommands(CLI::App& app) {
  CLI::App* cameras =
      app.add_subcommand("cameras", "List the cameras procam can open, with their URIs");
  const auto listing = AddDeclaredOptions<ListCamerasOptions>(cameras);
  cameras->callback([listing] { RunCameras(*listing); });

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
