// procam cameras / procam capture.
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "apps/commands.h"
#include "calibration/camera_response.h"
#include "capture/camera.h"
#include "capture/devices.h"
#include "capture/display.h"
#include "procam/config.h"
#if PROCAM_WITH_GLFW
#include "projection/glfw_display.h"
#endif
#include "capture/patterns.h"
#include "capture/session.h"
#include "calibration/structured_light.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "base/io.h"

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
  double gain = -1.0;  // < 0: leave the camera's gain
  std::string axes = "both";
  std::vector<int> levels = PhotometricOptions().levels;
  std::string channels = PhotometricOptions().channels;
  std::vector<std::string> images;
  double projector_gamma = 1.0;
  double pattern_gamma = 1.0;  // structured_light: sinusoids pre-distorted for this gamma
  std::string camera_response;  // camera_response.json: linearise before the HDR merge
};

cv::Size ParseSize(const std::string& text) {
  int width = 0, height = 0;
  char separator = 0;
  if (std::sscanf(text.c_str(), "%d%c%d", &width, &separator, &height) != 3 || separator != 'x' ||
      width <= 0 || height <= 0) {
    throw std::invalid_argument("--projector-size: expected WIDTHxHEIGHT, e.g. 1920x1080, got '" +
                                text + "'");
  }
  return {width, height};
}

CaptureSequence MakeSequence(const CaptureArguments& args, cv::Size projector) {
  if (args.sequence == "graycode") {
    GrayCodeOptions options;
    options.width = projector.width;
    options.height = projector.height;
    options.columns = args.axes != "rows";
    options.rows = args.axes != "columns";
    return MakeGrayCodeSequence(options);
  }
  if (args.sequence == "structured_light") {  // XOR Gray + phase, the robust default
    StructuredLightOptions options;
    options.width = projector.width;
    options.height = projector.height;
    options.columns = args.axes != "rows";
    options.rows = args.axes != "columns";
    options.pattern_gamma = args.pattern_gamma;
    std::string why;
    if (!options.Check(&why)) throw std::invalid_argument("structured_light sequence: " + why);
    return MakeStructuredLightSequence(options);
  }
  if (args.sequence == "photometric") {
    PhotometricOptions options;
    options.width = projector.width;
    options.height = projector.height;
    options.levels = args.levels;
    options.channels = args.channels;
    std::string why;
    if (!options.Check(&why)) throw std::invalid_argument("photometric sequence: " + why);
    return MakePhotometricSequence(options);
  }
  std::vector<std::filesystem::path> images(args.images.begin(), args.images.end());
  if (images.empty())
    throw std::invalid_argument(
        "--sequence verify needs the images to show (positional arguments)");
  return MakeVerifySequence(images, projector);
}

// The display of projector `index` of the synthetic world a "synthetic:" camera URI names.
std::shared_ptr<MemoryDisplay> SyntheticProjectorDisplay(const CaptureArguments& args,
                                                         const SyntheticWorld& world) {
  if (args.display != "memory") {
    throw IoError("display '" + args.display + "': camera '" + args.camera +
                  "' photographs the simulated room, whose projectors show the patterns "
                  "(choose one with --projector)");
  }
  const int count = static_cast<int>(world.displays.size());
  if (args.projector < 0 || args.projector >= count) {
    std::string names;
    for (const Projector& projector : world.rig->projectors())
      names += (names.empty() ? "" : ", ") + projector.name;
    throw IoError("--projector " + std::to_string(args.projector) + ": synthetic scene '" +
                  world.scene + "' has " + std::to_string(count) + " projectors (0.." +
                  std::to_string(count - 1) + ": " + names + ")");
  }
  const std::shared_ptr<MemoryDisplay>& display = world.displays[args.projector];
  if (!args.projector_size.empty() && ParseSize(args.projector_size) != display->Resolution()) {
    throw IoError("--projector-size " + args.projector_size + ": projector " +
                  std::to_string(args.projector) + " of synthetic scene '" + world.scene + "' is " +
                  std::to_string(display->Resolution().width) + "x" +
                  std::to_string(display->Resolution().height));
  }
  return display;
}

void RunCapture(const CaptureArguments& args) {
  RegisterDeviceBackends();
  RegisterSyntheticCameraBackend();
  std::string why;
  if (!args.sequencer.Check(&why)) throw std::invalid_argument("capture: " + why);
  const CameraUri camera_uri = CameraUri::Parse(args.camera);
  // A synthetic camera photographs the simulated room: the patterns go to one of its
  // projectors, whose display the camera (sharing the world) looks at.
  std::shared_ptr<SyntheticWorld> world;
  std::shared_ptr<MemoryDisplay> display;
  if (camera_uri.scheme() == "synthetic") {
    world = OpenSyntheticWorld(camera_uri);
    display = SyntheticProjectorDisplay(args, *world);
  }
  // A real projector: a fullscreen GLFW window on the monitor "glfw:N|NAME" names.
  std::shared_ptr<PatternDisplay> output;
  if (args.display.rfind("glfw:", 0) == 0) {
    if (world) throw IoError("display '" + args.display + "': a synthetic camera looks at its own projectors");
#if PROCAM_WITH_GLFW
    try {
      output = std::make_shared<GlfwDisplay>(FindMonitor(args.display.substr(5)));
    } catch (const IoError& error) {
      throw IoError("display '" + args.display + "': " + error.what());
    }
#else
    throw IoError("display '" + args.display +
                  "': this build has no GLFW output backend (reconfigure with -DPROCAM_WITH_GLFW=ON; "
                  "apt-get install libglfw3-dev libgl-dev)");
#endif
  } else if (args.display != "memory") {
    throw IoError("display '" + args.display + "': unknown; use memory or glfw:N|NAME (procam show --list)");
  }
  const cv::Size projector =
      display ? display->Resolution()
              : output ? output->Resolution()
                       : ParseSize(args.projector_size.empty() ? "1024x768" : args.projector_size);
  // The memory display shows patterns nowhere but to test cameras, which look at it.
  if (!display) display = std::make_shared<MemoryDisplay>(projector, "memory");
  if (!output) output = display;
  LoopbackOptions loopback;
  loopback.projector_gamma = args.projector_gamma;
  OpenCameraOptions open_options;
  open_options.scene_view = MakeLoopbackView(display, loopback);
  std::unique_ptr<Camera> camera = OpenCamera(args.camera, open_options);
  if (camera->Info().backend != "test" && !world && output == display) {
    std::fprintf(
        stderr,
        "procam: warning: display 'memory' shows the patterns nowhere; camera %s photographs the "
        "room as it is (use --display glfw:N to show them on a projector)\n",
        camera->Info().uri.c_str());
  }
  if (args.gain >= 0) camera->SetGain(args.gain);
  const CaptureSequence sequence = MakeSequence(args, projector);

  CaptureSessionOptions options;
  options.directory = args.out;
  options.sequencer = args.sequencer;
  if (!args.camera_response.empty()) {  // a camera that is not linear (procam calibrate response)
    options.sequencer.hdr.inverse_response = ReadInverseResponse(
        args.camera_response, IsColour(camera->Settings().pixel_format) ? 3 : 1);
  }
  const std::filesystem::path result_path = std::filesystem::path(args.out) / "result.json";
  CaptureSummary summary;
  try {
    summary = RunCaptureSession(options, sequence, *camera, *output);
  } catch (const CaptureFault& fault) {  // the session keeps what was captured: say so, then fail
    const nlohmann::json result = {
        {"command", "capture"},
        {"sequence", sequence.kind},
        {"camera", camera->Info().uri},
        {"manifest", (std::filesystem::path(args.out) / "session.json").string()},
        {"complete", false},
        {"error", fault.what()}};
    WriteFileAtomically(result_path, result.dump(2) + "\n");
    throw;
  }
  std::cout << "capture " << sequence.kind << " with " << camera->Info().uri << " into " << args.out
            << ": " << summary.BriefReport() << "\n";

  nlohmann::json result = {{"command", "capture"},
                           {"sequence", sequence.kind},
                           {"camera", camera->Info().uri},
                           {"manifest", summary.manifest.string()},
                           {"complete", true},
                           {"patterns_total", summary.patterns_total},
                           {"patterns_before", summary.patterns_before},
                           {"patterns_captured", summary.patterns_captured},
                           {"retries", summary.retries},
                           {"stale_dropped", summary.stale_dropped},
                           {"seconds", summary.seconds}};
  WriteFileAtomically(result_path, result.dump(2) + "\n");
}

void RunCameras(const CamerasArguments& args) {
  RegisterDeviceBackends();
  RegisterSyntheticCameraBackend();
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
  capture
      ->add_option("--settle-ms", args->sequencer.settle_ms,
                   "Wait after showing a pattern, milliseconds")
      ->capture_default_str();
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
  capture->add_option("--gain", args->gain,
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
  capture->add_option("--levels", args->levels, "photometric: 8-bit levels, comma-separated")
      ->delimiter(',');
  capture->add_option("--channels", args->channels, "photometric: any of r, g, b, w")
      ->capture_default_str();
  capture
      ->add_option("--projector-gamma", args->projector_gamma,
                   "memory display: response exponent the test camera sees")
      ->capture_default_str();
  capture->add_option("images", args->images,
                      "verify: the images to show, each at projector resolution");
  capture->callback([args] { RunCapture(*args); });
}

}  // namespace procam
