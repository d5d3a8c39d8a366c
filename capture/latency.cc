#include "capture/latency.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <stdexcept>
#include <thread>
#include <vector>

#include "base/io.h"
#include "base/stop.h"

namespace procam {
namespace {

constexpr double kOld = 0.1, kNew = 0.9;  // how far the lit pixels moved: still old, new

double NsToMs(int64_t ns) { return static_cast<double>(ns) * 1e-6; }

// A frame as one grey float channel, and its full scale.
cv::Mat Grey(const Frame& frame, double* full_scale) {
  cv::Mat grey;
  if (frame.image.channels() == 3) {
    cv::cvtColor(frame.image, grey, cv::COLOR_BGR2GRAY);
  } else {
    grey = frame.image;
  }
  *full_scale = grey.depth() == CV_16U ? 65535.0 : 255.0;
  cv::Mat result;
  grey.convertTo(result, CV_32F);
  return result;
}

class Flasher {
 public:
  Flasher(Camera* camera, PatternDisplay* display, const LatencyOptions& options)
      : camera_(camera), display_(display), options_(options), rng_(options.seed) {
    const cv::Size size = display->Resolution();
    black_ = cv::Mat(size, CV_8UC3, cv::Scalar::all(0));
    white_ = cv::Mat(size, CV_8UC3, cv::Scalar::all(255));
  }

  LatencyMeasurement Measure() {
    LatencyMeasurement result;
    dark_ = Reference(black_);
    bright_ = Reference(white_);
    cv::Mat contrast = bright_ - dark_;
    lit_ = contrast > options_.min_contrast * full_scale_;
    const int lit = cv::countNonZero(lit_);
    result.lit_fraction = static_cast<double>(lit) / static_cast<double>(lit_.total());
    if (lit < std::max<int>(16, static_cast<int>(lit_.total() / 1000))) {
      throw IoError(fmt::format(
          "latency: display '{}' lights nothing camera '{}' sees within {:.0f} ms (white brightens {} of {} "
          "pixels by more than {:.0f}% of full scale): is the camera looking at it, is the latency longer?",
          display_->Name(), camera_->Info().uri, options_.max_latency_ms, lit, lit_.total(),
          100 * options_.min_contrast));
    }
    lit_.convertTo(weight_, CV_32F, 1.0 / 255.0);
    contrast_sum_ = cv::sum(contrast.mul(weight_))[0];
    const double period_ms = Period();
    std::vector<double> middles;
    result.lower_ms = std::numeric_limits<double>::infinity();
    result.upper_ms = -std::numeric_limits<double>::infinity();
    for (int edge = 0; edge < options_.edges; ++edge) {
      const bool rising = edge % 2 == 1;  // the references leave the display white
      std::uniform_real_distribution<double> phase(0.0, period_ms);
      SleepUntil(SteadyNowNs() + MsToNs(phase(rng_)));
      double lower = -std::numeric_limits<double>::infinity(), upper = std::numeric_limits<double>::infinity();
      Edge(rising, &lower, &upper);
      // No frame seen old after the change (the first was new): a period and an exposure before it.
      lower = std::max(lower, upper - period_ms - exposure_ms_);
      lower = std::min(lower, upper);  // a frame seen old after one seen new: the change fell between
      result.lower_ms = std::min(result.lower_ms, lower);
      result.upper_ms = std::max(result.upper_ms, upper);
      middles.push_back(0.5 * (lower + upper));
      ++edges_done_;
    }
    std::nth_element(middles.begin(), middles.begin() + middles.size() / 2, middles.end());
    result.estimate_ms = middles[middles.size() / 2];
    result.frames = frames_;
    display_->Show(black_);
    result.edges = options_.edges;
    result.frame_period_ms = Period();
    result.exposure_ms = exposure_ms_;
    return result;
  }

 private:
  // The mean of two frames begun after `pattern` has shown for max_latency_ms.
  cv::Mat Reference(const cv::Mat& pattern) {
    display_->Show(pattern);
    const int64_t settled = SteadyNowNs() + MsToNs(options_.max_latency_ms);
    SleepUntil(settled);
    camera_->DropBufferedFrames();
    cv::Mat sum;
    for (int frames = 0; frames < 2;) {
      const Frame frame = Next();
      if (frame.exposure_start_ns < settled) continue;
      const cv::Mat grey = Grey(frame, &full_scale_);
      sum = sum.empty() ? grey : sum + grey;
      ++frames;
    }
    return sum / 2.0;
  }

  Frame Next() {
    // A signal (base/stop.h) ends the measurement between frames, however long it has to go.
    if (StopRequested()) {
      throw Stopped(fmt::format("display latency of '{}': stopped after {} of {} changes",
                                display_->Name(), edges_done_, options_.edges));
    }
    const auto timeout = std::chrono::milliseconds(static_cast<int64_t>(
        std::ceil(options_.grab_timeout_ms + exposure_ms_)));
    Frame frame;
    try {
      frame = camera_->Grab(timeout);
    } catch (const IoError&) {
      if (StopRequested()) return Next();  // a grab the signal cut short: the stop, no fault
      throw;
    }
    exposure_ms_ = frame.exposure_us * 1e-3;
    if (last_start_ns_ != 0 && frame.exposure_start_ns > last_start_ns_)
      intervals_ms_.push_back(NsToMs(frame.exposure_start_ns - last_start_ns_));
    last_start_ns_ = frame.exposure_start_ns;
    ++frames_;
    return frame;
  }

  double Period() const {
    if (intervals_ms_.empty()) return 0.0;
    std::vector<double> sorted = intervals_ms_;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    return sorted[sorted.size() / 2];
  }

  // How far a frame's lit pixels are from black towards white, in [0, 1] roughly.
  double Brightness(const Frame& frame) {
    const cv::Mat above = Grey(frame, &full_scale_) - dark_;
    return cv::sum(above.mul(weight_))[0] / contrast_sum_;
  }

  // One change of the display; `lower` and `upper` bound the latency it showed.
  void Edge(bool rising, double* lower, double* upper) {
    display_->Show(rising ? white_ : black_);
    const int64_t shown = SteadyNowNs();
    const int64_t deadline =
        shown + MsToNs(options_.max_latency_ms + 2 * Period() + exposure_ms_ + options_.grab_timeout_ms);
    for (;;) {
      const Frame frame = Next();
      const double brightness = Brightness(frame);
      const double moved = rising ? brightness : 1.0 - brightness;
      const double start_ms = NsToMs(frame.exposure_start_ns - shown);
      if (moved > kNew) {
        if (start_ms < 0.0) continue;  // a frame begun before the change cannot have seen it
        *upper = std::min(*upper, start_ms);
        return;
      }
      *lower = std::max(*lower, start_ms);
      if (moved >= kOld) *upper = std::min(*upper, start_ms + frame.exposure_us * 1e-3);
      if (SteadyNowNs() > deadline) {
        throw IoError(fmt::format(
            "latency: camera '{}' did not see display '{}' change within {:.0f} ms (the lit pixels moved "
            "{:.0f}% of the way); raise max_latency_ms or check that the camera looks at the display",
            camera_->Info().uri, display_->Name(), NsToMs(SteadyNowNs() - shown), 100 * moved));
      }
    }
  }

  Camera* camera_;
  PatternDisplay* display_;
  LatencyOptions options_;
  std::mt19937 rng_;
  cv::Mat black_, white_;
  cv::Mat dark_, bright_, lit_;
  cv::Mat weight_;  // CV_32F: 1 on lit pixels, 0 elsewhere
  double contrast_sum_ = 1.0;
  double full_scale_ = 255.0;
  double exposure_ms_ = 0.0;
  int64_t last_start_ns_ = 0;
  std::vector<double> intervals_ms_;
  int frames_ = 0;
  int edges_done_ = 0;
};

}  // namespace

bool LatencyOptions::Check(std::string* why) const {
  const auto fail = [why](const std::string& text) {
    if (why) *why = text;
    return false;
  };
  if (edges < 1 || edges > 200) return fail("edges must be in [1, 200]");
  if (!(max_latency_ms > 0 && max_latency_ms <= 60000)) return fail("max_latency_ms must be in (0, 60000]");
  if (!(grab_timeout_ms > 0 && grab_timeout_ms <= 600000)) return fail("grab_timeout_ms must be in (0, 600000]");
  if (!(min_contrast > 0 && min_contrast < 1)) return fail("min_contrast must be in (0, 1)");
  return true;
}

double LatencyMeasurement::SettleMs() const {
  const double upper = std::max(upper_ms, 0.0);
  // The margin covers a change slower than the slowest of the few measured: as much again as
  // their spread (a display chain's jitter; a frame period for a steady projector), 10 % or
  // 5 ms, whichever is largest.
  const double spread = std::max(upper_ms - lower_ms, 0.0);
  return std::ceil(upper + std::max({5.0, 0.1 * upper, spread}));
}

std::string LatencyMeasurement::Summary() const {
  return fmt::format(
      "display-to-camera latency {:.1f} ms (every change seen between {:.1f} and {:.1f} ms, {} changes, {} frames at {:.1f} ms, "
      "exposure {:.1f} ms, {:.0f}% of the view lit): settle {:.0f} ms",
      EstimateMs(), lower_ms, upper_ms, edges, frames, frame_period_ms, exposure_ms, 100 * lit_fraction,
      SettleMs());
}

LatencyMeasurement MeasureDisplayLatency(Camera* camera, PatternDisplay* display,
                                         const LatencyOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("LatencyOptions: " + why);
  if (camera == nullptr || display == nullptr) throw std::invalid_argument("MeasureDisplayLatency: no camera or display");
  return Flasher(camera, display, options).Measure();
}

}  // namespace procam
