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
#include "calibration/capture_stage.h"
#include "capture/camera.h"
#include "capture/devices.h"
#include "capture/simulated_camera.h"
#include "procam/config.h"

namespace procam {
namespace {

struct CamerasArguments {
  bool no_gige = false;
  bool include_virtual = false;
};

struct CaptureArguments {
  std::string camera;
  std::string sequence;
  std::string out;
  std::string display = "memory";
  std::string projector_size;  // empty: 1024x768, or the synthetic projector's own
  int projector = 0;           // synthetic cameras: the rig projector that shows the patterns
  SequencerOptions sequencer;
  SettleSetting settle{false, SequencerOptions().settle_ms};
  std::optional<double> gain;  // unset: leave the camera's gain
  std::string axes = "both";
  std::vector<int> levels = PhotometricOptions().levels;
  std::string channels = PhotometricOptions().channels;
  std::vector<std::string> images;
  double projector_gamma = 1.0;
  double pattern_gamma = 1.0;  // structured_light: sinusoids pre-distorted for this gamma
  std::string camera_response;  // camera_response.json: linearise before the HDR merge
};

cv::Size ProjectorSize(const std::string& text) {
  const std::array<int, 2> size =
      ParseSize("--projector-size", text, "WIDTHxHEIGHT, e.g. 1920x1080", 1, 16384);
  return {size[0], size[1]};
}

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

void RunCapture(const CaptureArguments& args) {
  RegisterDeviceBackends();
  CaptureStageOptions options;
  options.stop = &StopOnSignals();  // before the display and camera open: a stop releases them
  options.camera = args.camera;
  options.sequence = args.sequence;
  options.out = args.out;
  options.display = CaptureDisplay(args.display, args.camera);
  options.projector = args.projector;
  if (!args.projector_size.empty()) options.projector_size = ProjectorSize(args.projector_size);
  options.sequencer = args.sequencer;
  options.sequencer.settle_ms = args.settle.ms;
  options.measure_latency = args.settle.measure;
  options.gain = args.gain;
  options.axes = args.axes;
  options.pattern_gamma = args.pattern_gamma;
  options.levels = args.levels;
  options.channels = args.channels;
  options.images.assign(args.images.begin(), args.images.end());
  options.projector_gamma = args.projector_gamma;
  options.camera_response = args.camera_response;
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

  auto args = std::make_shared<CaptureArguments>();
  CLI::App* capture = app.add_subcommand(
      "capture",
      "Show a pattern sequence and capture it into a session directory; rerun to resume");
  capture
      ->add_option("--camera", args->camera,
                   "Camera URI: v4l2:/dev/video0, aravis:<id>, test:loopback?noise=2, "
                   "synthetic:c_shaped ...")
      ->required();
  capture->add_option("--sequence", args->sequence, "graycode, structured_light, photometric or verify")
      ->required()
      ->check(CLI::IsMember({"graycode", "structured_light", "photometric", "verify"}));
  capture
      ->add_option("--out", args->out,
                   "Session directory (created, or resumed when it holds session.json)")
      ->required();
  capture
      ->add_option("--display", args->display,
                   "Where patterns are shown: memory (seen only by test and synthetic cameras) or glfw:N|NAME, a "
                   "fullscreen window on a projector's monitor (procam show --list)")
      ->capture_default_str();
  capture->add_option("--projector-size", args->projector_size,
                      "Projector resolution WIDTHxHEIGHT (default 1024x768; synthetic cameras: "
                      "the projector's own)");
  capture
      ->add_option("--projector", args->projector,
                   "synthetic cameras: the rig projector (0-based) that shows the patterns")
      ->capture_default_str();
  capture
      ->add_option("--frames", args->sequencer.frames_per_pattern,
                   "Frames averaged per pattern and exposure")
      ->capture_default_str();
  AddSettleOption(capture, &args->settle);
  capture
      ->add_option("--discard", args->sequencer.discard_frames,
                   "Fresh frames discarded before averaging")
      ->capture_default_str();
  capture
      ->add_option(
          "--exposure-us", args->sequencer.exposures_us,
          "Exposure(s) in microseconds; several (comma-separated) bracket and merge to HDR")
      ->delimiter(',');
  capture->add_option("--camera-response", args->camera_response,
                      "camera_response.json (procam calibrate response): linearise a camera that "
                      "is not linear before the HDR merge");
  capture->add_option_function<double>(
      "--gain", [args](double gain) { args->gain = gain; },
      "Camera gain (dB for Aravis/test cameras, driver units for V4L2)");
  capture
      ->add_option("--timeout-ms", args->sequencer.grab_timeout_ms,
                   "Grab timeout per frame, milliseconds")
      ->capture_default_str();
  capture
      ->add_option("--retries", args->sequencer.max_retries,
                   "Failed grabs retried in a row before giving up")
      ->capture_default_str();
  capture
      ->add_option("--retry-delay-ms", args->sequencer.retry_delay_ms,
                   "Pause before a retry, milliseconds")
      ->capture_default_str();
  capture
      ->add_option("--pattern-gamma", args->pattern_gamma,
                   "structured_light: the projector's gamma, so its sinusoids are sinusoids in light")
      ->capture_default_str();
  capture->add_option("--axes", args->axes, "graycode, structured_light: columns, rows or both")
      ->check(CLI::IsMember({"both", "columns", "rows"}))
      ->capture_default_str();
  capture->add_option_function<std::string>(
      "--levels",
      [args](const std::string& text) {
        args->levels = ParseIntegerList("--levels", text, "8-bit levels, comma-separated");
      },
      "photometric: 8-bit levels, comma-separated");
  capture->add_option("--channels", args->channels, "photometric: any of r, g, b, w")
      ->capture_default_str();
  capture
      ->add_option("--projector-gamma", args->projector_gamma,
                   "memory display: response exponent the test camera sees")
      ->capture_default_str();
  capture->add_option("images", args->images,
                      "verify: the images to show, each at projector resolution");
  capture->callback([args] {
    CheckOutputDirectory(args->out, DirectoryKind::kCaptureSession);
    RunCapture(*args);
  });
}

}  // namespace procam
