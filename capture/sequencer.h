#pragma once
// The pattern sequencer: shows a pattern, waits for it to settle, drops frames exposed before
// it settled, captures N frames per exposure and averages them, and with several exposures
// merges them into one linear HDR image. Camera faults are retried; past the retry budget it
// throws CaptureFault, and what was captured before stays with the caller (see session.h).

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "capture/camera.h"
#include "capture/display.h"

namespace procam {

class OptionTable;

// A camera kept failing (timeouts or disconnection) past SequencerOptions::max_retries.
class CaptureFault : public IoError {
 public:
  using IoError::IoError;
};

// Linear HDR merge of frames taken at several exposures (Debevec & Malik's weighted average for
// a linear sensor): radiance = Σ_i w_i (z_i − black) / t_i / Σ_i w_i over the exposures whose
// normalised value z_i = (DN − black)/(full scale − black) lies in [min_signal, saturation],
// with w_i = t_i (longer exposures carry more photons, hence less relative noise). A pixel with
// no such exposure takes the shortest exposure if it is saturated everywhere, else the longest.
struct HdrMergeOptions {
  double black_level = 0.0;  // digital numbers of a dark pixel, [0, full scale)
  double saturation = 0.95;  // normalised value from which a pixel counts as clipped, (0, 1]
  double min_signal =
      0.01;  // normalised value under which a pixel is too dark to trust, [0, saturation)
  // A camera that is not linear (calibration/camera_response.h): per channel of the images (one
  // table for all, or one per channel in the images' order, e.g. B, G, R), the linear signal at
  // evenly spaced normalised values z = (DN − black)/(full scale − black) from 0 to 1, each
  // table ≥ 2 entries, non-decreasing, from 0 to 1. Empty: the sensor is linear. The
  // saturation and min_signal tests stay on z; the merge averages the linearised values.
  std::vector<std::vector<double>> inverse_response;
  bool Check(std::string* why) const;
};

// `means` are CV_32FC1 or CV_32FC3 images of digital numbers (same size and type), one per
// exposure in `exposures_us` (microseconds). Returns CV_32F of the same channels in units of
// full scale per second: (DN − black) / (full_scale − black) / t[s]. Throws
// std::invalid_argument on mismatched inputs or options that fail Check().
cv::Mat MergeExposures(const std::vector<cv::Mat>& means, const std::vector<double>& exposures_us,
                       double full_scale, const HdrMergeOptions& options = {});

struct SequencerOptions {
  double settle_ms = 150.0;    // wait after Show() before frames count: projector latency plus
                               // camera pipeline, milliseconds, [0, 60000]
  int frames_per_pattern = 4;  // frames averaged per exposure, [1, 1000]
  int discard_frames = 0;      // further fresh frames discarded before averaging, [0, 1000]
  std::vector<double> exposures_us;  // empty: keep the camera's exposure; one: set it; several:
                                     // exposure bracketing merged to HDR. Each in (0, 1e8] us.
  double grab_timeout_ms = 2000.0;   // per frame, milliseconds, (0, 600000]; the exposure is added
  int max_retries = 3;               // consecutive failed grabs tolerated per pattern, [0, 100]
  double retry_delay_ms = 200.0;     // pause before a retry, milliseconds, [0, 60000]
  int max_stale_frames = 200;        // stale frames tolerated in a row before giving up, [1, 1e6]
  // A display whose change reaches the camera later than settle_ms (a compositor's hiccup)
  // leaves the first frames of a pattern showing the previous one. With two frames or more per
  // exposure, the first and last averaged frames are compared: when more than this fraction of
  // their pixel values differ by over a tenth of full scale, the picture was still changing, and
  // the exposure's frames are taken again (a retry, counted with max_retries), [0, 1]; 1: never.
  // Camera noise does not reach a tenth of full scale; a Gray-code stripe flipping does, and so
  // does a person walking through the view (past max_retries the capture stops saying so).
  double max_changed_fraction = 0.005;
  HdrMergeOptions hdr;
  // Declares --frames, --retries, --retry-delay-ms and --timeout-ms in `table`, bound to these
  // fields (base/option_table.h). --settle-ms (auto|MS) and --exposure-us (a list) stay with
  // the commands that take them.
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
};

// Declares --settle-ms auto|MS in `table`, bound to `*settle_ms` (SequencerOptions::settle_ms)
// and `*measure`: "auto" sets *measure (the display-to-camera latency measured first,
// capture/latency.h, gives the settle time), a number of milliseconds in [0, 60000] clears it.
void DeclareSettleOption(OptionTable* table, double* settle_ms, bool* measure);

struct ExposureCapture {
  double exposure_us = 0.0;         // as the frames report it, microseconds
  double gain = 0.0;                // as the frames report it, camera units
  cv::Mat mean;                     // CV_32FC1 or CV_32FC3, mean digital numbers
  int frames = 0;                   // averaged
  int buffered_dropped = 0;         // frames waiting in buffers when the pattern settled, dropped
  int stale_dropped = 0;            // frames grabbed but exposed before the pattern settled
  int discarded = 0;                // fresh frames discarded (SequencerOptions::discard_frames)
  std::vector<uint64_t> sequences;  // device frame counters of the averaged frames
  int64_t first_exposure_start_ns = 0;  // steady clock
  int64_t last_arrival_ns = 0;          // steady clock
};

struct PatternCapture {
  int64_t shown_ns = 0;    // steady clock when Show() returned
  int64_t settled_ns = 0;  // shown_ns + settle time
  double full_scale = 255.0;
  std::vector<ExposureCapture> exposures;
  cv::Mat hdr;      // MergeExposures of all exposures; empty with a single exposure
  int retries = 0;  // failed grabs that were retried
  std::vector<std::string> retry_reasons;
};

class PatternSequencer {
 public:
  // `camera` and `display` must outlive the sequencer. Throws std::invalid_argument when
  // options.Check() fails.
  PatternSequencer(const SequencerOptions& options, Camera* camera, PatternDisplay* display);

  // Shows `pattern` and captures it. A timeout or disconnection is retried (after a pause, the
  // camera is stopped and restarted) up to max_retries times in a row; past that, throws
  // CaptureFault naming the camera and the last error. Frames whose exposure began before the
  // pattern (or a new exposure setting) settled are never averaged.
  PatternCapture Capture(const cv::Mat& pattern);

 private:
  ExposureCapture CaptureExposure(int64_t settled_ns, double exposure_us, PatternCapture* capture);
  void Retry(const std::exception& error, PatternCapture* capture, int* consecutive_failures);
  // Runs `action` (a camera call), retrying it like a failed grab.
  template <typename Action>
  void WithRetries(PatternCapture* capture, Action action);

  SequencerOptions options_;
  Camera* camera_;
  PatternDisplay* display_;
};

}  // namespace procam
