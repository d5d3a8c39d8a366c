#pragma once
// The capture stage: one pattern sequence shown and photographed into a capture session
// (capture/session.h), resumable. The sequences calibration and verification use: Gray code,
// structured light (XOR Gray code with phase shifting), photometric flat fields, or given
// images. What `procam capture` runs, and `calibrate all` per projector.

#include <atomic>
#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/option_table.h"
#include "base/progress.h"
#include "capture/display.h"
#include "capture/latency.h"
#include "capture/patterns.h"
#include "capture/sequencer.h"
#include "capture/session.h"

namespace procam {

struct CaptureStageOptions {
  std::string camera;    // camera URI (camera.h): v4l2:..., aravis:..., test:..., synthetic:...
  std::string sequence;  // "graycode", "structured_light", "photometric" or "verify"
  std::filesystem::path out;  // the session directory (created, or resumed)
  // Where the patterns are shown, e.g. a fullscreen window on a projector's monitor. Unset: a
  // simulated camera's projector `projector` (capture/simulated_camera.h), else the memory
  // display, which only test cameras see.
  std::shared_ptr<PatternDisplay> display;
  // `display` as the command line names it: memory, or glfw:N|NAME, a projector's monitor
  // (procam show --list); the caller opens it (the equivalent command shows it).
  std::string display_name = "memory";
  int projector = 0;  // simulated cameras: which of their world's projectors shows the patterns
  // The projector's resolution with the memory display (unset: 1024x768); a display's own
  // resolution wins; given with a simulated projector, it must match the projector's.
  std::optional<cv::Size> projector_size;
  SequencerOptions sequencer;  // frames, exposures (several: HDR), settle, retries
  // Measure the display-to-camera latency first (capture/latency.h) and use its settle time
  // instead of sequencer.settle_ms.
  bool measure_latency = false;
  LatencyOptions latency;
  std::optional<double> gain;  // camera gain to set, [0, 1e6] (unset: leave it)
  std::string axes = "both";   // graycode, structured_light: "columns", "rows" or "both"
  double pattern_gamma = 1.0;  // structured_light: sinusoids pre-distorted for this gamma
  std::vector<int> levels = PhotometricOptions().levels;  // photometric: 8-bit levels
  std::string channels = PhotometricOptions().channels;   // photometric: of r, g, b, w
  std::vector<std::filesystem::path> images;              // verify: the images to show
  double projector_gamma = 1.0;           // memory display: the response the test camera sees
  std::filesystem::path camera_response;  // camera_response.json: linearise before HDR merges
  ProgressCallback progress;              // a warning when nothing shows the patterns
  // Set (by a signal handler) to stop cleanly before the next pattern (CaptureSessionOptions):
  // result.json then says complete false, stopped true; the same call again resumes.
  const std::atomic<bool>* stop = nullptr;

  // Declares --camera, --sequence, --out, --display, --projector-size, --projector, the
  // sequencer's (--frames, --settle-ms, --discard, --exposure-us, --timeout-ms, --retries,
  // --retry-delay-ms), --camera-response, --gain, --pattern-gamma, --axes, --levels,
  // --channels, --projector-gamma and the images (positional) in `table`, bound to these fields
  // (base/option_table.h).
  void Declare(OptionTable* table);
  // Checks every value, whichever sequence uses it, so that a typing error is refused before
  // anything is shown or written: the sequence, the declared values (the projector >= 0, the
  // gain, the gammas in (0, 10], ...), levels and channels (PhotometricOptions) and the
  // sequencer's.
  bool Check(std::string* why) const;
};

// Captures what the session does not hold yet and writes OUT/result.json (also when the camera
// fails: complete false and the error; then the CaptureFault is rethrown). Throws IoError naming
// the camera, display, option or file for bad input, before anything is shown.
CaptureSummary RunCaptureStage(const CaptureStageOptions& options);

// The line `procam capture` prints: what was captured with which camera into where (stopped:
// how many patterns are kept, and that the same command resumes).
std::string CaptureLine(const CaptureStageOptions& options, const CaptureSummary& summary);

}  // namespace procam
