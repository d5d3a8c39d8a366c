#include "pipeline/capture_stage.h"

#include <array>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>

#include "base/check.h"
#include "base/io.h"
#include "base/parse.h"
#include "base/stop.h"
#include "calibration/camera_response.h"
#include "calibration/structured_light.h"
#include "capture/camera.h"
#include "capture/simulated_camera.h"
#include "capture/test_camera.h"

namespace procam {
namespace {

std::string SizeText(cv::Size size) {
  return std::to_string(size.width) + "x" + std::to_string(size.height);
}

CaptureSequence MakeSequence(const CaptureStageOptions& args, cv::Size projector) {
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
  if (args.sequence != "verify") {
    throw std::invalid_argument(FlagOf(args, &args.sequence) + ": '" + args.sequence +
                                "': graycode, structured_light, photometric or verify");
  }
  const std::vector<std::filesystem::path>& images = args.images;
  if (images.empty())
    throw std::invalid_argument(FlagOf(args, &args.sequence) +
                                " verify needs the images to show (positional arguments)");
  return MakeVerifySequence(images, projector);
}

// The display of projector `options.projector` of a simulated camera's world.
std::shared_ptr<PatternDisplay> SimulatedProjectorDisplay(const CaptureStageOptions& options,
                                                          const SimulatedCamera& simulated) {
  if (options.display) {
    throw IoError(
        "display '" + options.display->Name() + "': camera '" + options.camera +
        "' photographs the simulated room, whose projectors show the patterns (choose one with " +
        FlagOf(options, &options.projector) + ")");
  }
  const int count = static_cast<int>(simulated.displays.size());
  if (options.projector < 0 || options.projector >= count) {
    std::string names;
    for (const std::string& name : simulated.projector_names)
      names += (names.empty() ? "" : ", ") + name;
    throw IoError(FlagOf(options, &options.projector) + " " + std::to_string(options.projector) +
                  ": " + simulated.description + " has " + std::to_string(count) +
                  " projectors (0.." + std::to_string(count - 1) + ": " + names + ")");
  }
  const std::shared_ptr<PatternDisplay>& display = simulated.displays[options.projector];
  if (options.projector_size && *options.projector_size != display->Resolution()) {
    throw IoError(FlagOf(options, &options.projector_size) + " " +
                  SizeText(*options.projector_size) + ": projector " +
                  std::to_string(options.projector) + " of " + simulated.description + " is " +
                  SizeText(display->Resolution()));
  }
  return display;
}

nlohmann::json CaptureResult(const CaptureSequence& sequence, const Camera& camera) {
  return {{"command", "capture"}, {"sequence", sequence.kind}, {"camera", camera.Info().uri}};
}

}  // namespace

void CaptureStageOptions::Declare(OptionTable* table) {
  std::optional<cv::Size>* size = &projector_size;
  table
      ->Text("camera", &camera,
             "camera URI: v4l2:/dev/video0, aravis:<id>, test:loopback?noise=2, "
             "synthetic:c_shaped ...")
      .Required()
      .Text("sequence", &sequence, "graycode, structured_light, photometric or verify")
      .Required()
      .Path("out", &out, "the session directory (created, or resumed when it holds session.json)")
      .Required()
      .Text("display", &display_name,
            "where patterns are shown: memory (seen only by test and synthetic cameras) or "
            "glfw:N|NAME, a fullscreen window on a projector's monitor (procam show --list)")
      .Custom(
          "projector-size", [size] { return *size ? SizeText(**size) : std::string(); },
          [size](const std::string& text, std::string* why) {
            try {
              const std::array<int, 2> sides =
                  ParseSize("projector-size", text, "WIDTHxHEIGHT, e.g. 1920x1080", 1, 16384);
              *size = cv::Size(sides[0], sides[1]);
              return true;
            } catch (const IoError& error) {
              *why = std::string(error.what()).substr(std::string("projector-size: ").size());
              return false;
            }
          },
          "WIDTHxHEIGHT",
          "the projector's resolution (default 1024x768; synthetic cameras: the projector's own)")
      .Sets(size)
      .Integer("projector", &projector, 0, std::numeric_limits<int>::max(), "",
               "synthetic cameras: the rig projector (0-based) that shows the patterns");
  sequencer.Declare(table);
  DeclareSettleOption(table, &sequencer.settle_ms, &measure_latency);
  table
      ->Integer("discard", &sequencer.discard_frames, 0, 1000, "",
                "fresh frames discarded before averaging")
      .Numbers("exposure-us", &sequencer.exposures_us, OptionTable::Interval::AboveMin(0.0, 1e8),
               "µs", "exposure(s); several bracket and merge to HDR")
      .Path("camera-response", &camera_response,
            "camera_response.json (procam calibrate response): linearise a camera that is not "
            "linear before the HDR merge")
      .OptionalNumber("gain", &gain, OptionTable::Interval::Closed(0.0, 1e6), "",
                      "camera gain to set (dB for Aravis/test cameras, driver units for V4L2)")
      .Number("pattern-gamma", &pattern_gamma, OptionTable::Interval::AboveMin(0.0, 10.0), "",
              "structured_light: the projector's gamma, so its sinusoids are sinusoids in light")
      .Choice<std::string>("axes", &axes,
                           {{"both", "both"}, {"columns", "columns"}, {"rows", "rows"}},
                           "graycode, structured_light: the stripes' axes")
      .Integers("levels", &levels, 0, 255, "", "photometric: 8-bit levels")
      .Text("channels", &channels, "photometric: any of r, g, b, w")
      .Number("projector-gamma", &projector_gamma, OptionTable::Interval::AboveMin(0.0, 10.0), "",
              "memory display: the response exponent the test camera sees")
      .Paths("images", &images, "verify: the images to show, each at projector resolution")
      .Positional();
}

bool CaptureStageOptions::Check(std::string* why) const {
  const std::set<std::string> sequences = {"graycode", "structured_light", "photometric", "verify"};
  if (!sequences.count(sequence)) {
    return Fail(why, FlagOf(*this, &sequence) + ": '" + sequence +
                         "': graycode, structured_light, photometric or verify");
  }
  if (!CheckDeclared(*this, why)) return false;
  PhotometricOptions photometric;
  photometric.levels = levels;
  photometric.channels = channels;
  if (!photometric.Check(why))
    return Fail(why, FlagOf(*this, &levels) + "/" + FlagOf(*this, &channels) + ": " + *why);
  if (!sequencer.Check(why)) return Fail(why, "capture: " + *why);
  if (measure_latency && !latency.Check(why)) return Fail(why, "latency: " + *why);
  return true;
}

CaptureSummary RunCaptureStage(const CaptureStageOptions& args) {
  std::string why;
  if (!args.Check(&why)) throw std::invalid_argument(why);
  // A simulated camera photographs its room: the patterns go to one of its projectors, whose
  // display the camera (sharing the world) looks at.
  const std::optional<SimulatedCamera> simulated = FindSimulatedCamera(args.camera);
  std::shared_ptr<PatternDisplay> watched;  // what the camera looks at
  if (simulated) watched = SimulatedProjectorDisplay(args, *simulated);
  std::shared_ptr<PatternDisplay> output = args.display;
  const cv::Size projector = watched  ? watched->Resolution()
                             : output ? output->Resolution()
                                      : args.projector_size.value_or(cv::Size(1024, 768));
  // The memory display shows patterns nowhere but to test cameras, which look at it.
  std::shared_ptr<MemoryDisplay> memory;
  if (!watched) watched = memory = std::make_shared<MemoryDisplay>(projector, "memory");
  if (!output) output = watched;
  LoopbackOptions loopback;
  loopback.projector_gamma = args.projector_gamma;
  OpenCameraOptions open_options;
  if (memory) open_options.scene_view = MakeLoopbackView(memory, loopback);
  std::unique_ptr<Camera> camera = OpenCamera(args.camera, open_options);
  if (camera->Info().backend != "test" && !simulated && output == watched) {
    Report(args.progress,
           "warning: display 'memory' shows the patterns nowhere; camera " + camera->Info().uri +
               " photographs the room as it is (use --display glfw:N to show them on a projector)");
  }
  if (args.gain) camera->SetGain(*args.gain);
  const CaptureSequence sequence = MakeSequence(args, projector);

  CaptureSessionOptions options;
  options.directory = args.out;
  options.sequencer = args.sequencer;
  options.stop = args.stop;
  if (!args.camera_response.empty()) {  // a camera that is not linear (procam calibrate response)
    options.sequencer.hdr.inverse_response = ReadInverseResponse(
        args.camera_response.string(), IsColour(camera->Settings().pixel_format) ? 3 : 1);
  }
  std::optional<LatencyMeasurement> latency;
  if (args.measure_latency) {
    Report(args.progress, "measuring the display-to-camera latency (" +
                              std::to_string(args.latency.edges) + " changes of " + output->Name() +
                              ")");
    try {
      latency = MeasureDisplayLatency(camera.get(), output.get(), args.latency);
      options.sequencer.settle_ms = latency->SettleMs();
      Report(args.progress, latency->Summary());
    } catch (const Stopped&) {
      // Stopped while measuring: the session below records the stop before its first pattern.
      if (args.stop == nullptr) throw;
    }
  }
  const auto latency_json = [&latency]() -> nlohmann::json {
    if (!latency) return nullptr;
    return {{"lower_ms", latency->lower_ms},
            {"upper_ms", latency->upper_ms},
            {"estimate_ms", latency->EstimateMs()},
            {"settle_ms", latency->SettleMs()},
            {"frame_period_ms", latency->frame_period_ms},
            {"edges", latency->edges}};
  };
  const std::filesystem::path result_path = args.out / "result.json";
  CaptureSummary summary;
  try {
    summary = RunCaptureSession(options, sequence, *camera, *output);
  } catch (const CaptureFault& fault) {  // the session keeps what was captured: say so, then fail
    nlohmann::json result = CaptureResult(sequence, *camera);
    result.update({{"manifest", (args.out / "session.json").string()},
                   {"complete", false},
                   {"settle_ms", options.sequencer.settle_ms},
                   {"latency", latency_json()},
                   {"error", fault.what()}});
    WriteFileAtomically(result_path, result.dump(2) + "\n");
    throw;
  }
  summary.camera = camera->Info().uri;
  summary.settle_ms = options.sequencer.settle_ms;
  nlohmann::json result = CaptureResult(sequence, *camera);
  result.update({{"manifest", summary.manifest.string()},
                 {"complete", !summary.stopped},
                 {"stopped", summary.stopped},
                 {"patterns_total", summary.patterns_total},
                 {"patterns_before", summary.patterns_before},
                 {"patterns_captured", summary.patterns_captured},
                 {"retries", summary.retries},
                 {"stale_dropped", summary.stale_dropped},
                 {"settle_ms", options.sequencer.settle_ms},
                 {"latency", latency_json()},
                 {"seconds", summary.seconds}});
  WriteFileAtomically(result_path, result.dump(2) + "\n");
  return summary;
}

std::string CaptureLine(const CaptureStageOptions& options, const CaptureSummary& summary) {
  const std::string line = "capture " + options.sequence + " with " + summary.camera + " into " +
                           options.out.string() + ": ";
  if (summary.stopped) {
    return line + "stopped by a signal: " + summary.BriefReport() +
           "; run the same command again to resume";
  }
  return line + summary.BriefReport();
}

}  // namespace procam
