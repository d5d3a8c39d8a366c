#include "capture/sequencer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <thread>

#include "base/check.h"
#include "base/option_table.h"

namespace procam {

bool HdrMergeOptions::Check(std::string* why) const {
  if (!(black_level >= 0)) return Fail(why, "hdr.black_level must be >= 0");
  if (!(saturation > 0 && saturation <= 1)) return Fail(why, "hdr.saturation must be in (0, 1]");
  if (!(min_signal >= 0 && min_signal < saturation))
    return Fail(why, "hdr.min_signal must be in [0, saturation)");
  if (inverse_response.size() != 0 && inverse_response.size() != 1 && inverse_response.size() != 3)
    return Fail(why, "hdr.inverse_response must hold 0, 1 or 3 tables");
  for (const std::vector<double>& table : inverse_response) {
    if (table.size() < 2) return Fail(why, "hdr.inverse_response tables need at least 2 entries");
    for (size_t k = 1; k < table.size(); ++k) {
      if (!(table[k] >= table[k - 1]))
        return Fail(why, "hdr.inverse_response tables must be non-decreasing");
    }
  }
  return true;
}

namespace {

// Linear signal at normalised value z through `table` (evenly spaced over [0, 1]), linear
// interpolation, extrapolated flat outside.
double Linearise(const std::vector<double>& table, double z) {
  const double position = std::clamp(z, 0.0, 1.0) * static_cast<double>(table.size() - 1);
  const size_t below = std::min(static_cast<size_t>(position), table.size() - 2);
  const double t = position - static_cast<double>(below);
  return table[below] + t * (table[below + 1] - table[below]);
}

}  // namespace

cv::Mat MergeExposures(const std::vector<cv::Mat>& means, const std::vector<double>& exposures_us,
                       double full_scale, const HdrMergeOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("HdrMergeOptions: " + why);
  if (means.empty() || means.size() != exposures_us.size()) {
    throw std::invalid_argument("MergeExposures: need one image per exposure");
  }
  if (!(full_scale > options.black_level))
    throw std::invalid_argument("MergeExposures: full scale must exceed black");
  const int type = means[0].type();
  if (type != CV_32FC1 && type != CV_32FC3)
    throw std::invalid_argument("MergeExposures: images must be CV_32FC1/3");
  for (size_t i = 0; i < means.size(); ++i) {
    if (means[i].type() != type || means[i].size() != means[0].size()) {
      throw std::invalid_argument("MergeExposures: images differ in size or type");
    }
    if (!(exposures_us[i] > 0))
      throw std::invalid_argument("MergeExposures: exposures must be > 0");
  }
  const size_t shortest =
      std::min_element(exposures_us.begin(), exposures_us.end()) - exposures_us.begin();
  const size_t longest =
      std::max_element(exposures_us.begin(), exposures_us.end()) - exposures_us.begin();
  const double range = full_scale - options.black_level;
  const int channels = means[0].channels();
  const int values = means[0].cols * channels;
  if (options.inverse_response.size() == 3 && channels != 3) {
    throw std::invalid_argument("MergeExposures: 3 response tables for a 1-channel image");
  }
  // The linear signal of normalised value z in channel c.
  const auto linear = [&](double z, int c) {
    if (options.inverse_response.empty()) return z;
    return Linearise(options.inverse_response[options.inverse_response.size() == 3 ? c : 0], z);
  };

  cv::Mat merged(means[0].size(), type);
  std::vector<const float*> rows(means.size());
  for (int y = 0; y < merged.rows; ++y) {
    for (size_t i = 0; i < means.size(); ++i) rows[i] = means[i].ptr<float>(y);
    float* out = merged.ptr<float>(y);
    for (int v = 0; v < values; ++v) {
      double weighted = 0.0;
      double weights = 0.0;
      bool saturated_everywhere = true;
      for (size_t i = 0; i < means.size(); ++i) {
        const double z = (rows[i][v] - options.black_level) / range;
        if (z < options.saturation) saturated_everywhere = false;
        if (z < options.min_signal || z > options.saturation) continue;
        const double seconds = exposures_us[i] * 1e-6;
        weighted += seconds * (linear(z, v % channels) / seconds);
        weights += seconds;
      }
      if (weights > 0) {
        out[v] = static_cast<float>(weighted / weights);
      } else {
        const size_t pick = saturated_everywhere ? shortest : longest;
        out[v] = static_cast<float>(
            linear((rows[pick][v] - options.black_level) / range, v % channels) /
            (exposures_us[pick] * 1e-6));
      }
    }
  }
  return merged;
}

void SequencerOptions::Declare(OptionTable* table) {
  table->Integer("frames", &frames_per_pattern, 1, 1000, "", "frames averaged per photo")
      .Integer("retries", &max_retries, 0, 100, "",
               "failed grabs retried in a row before giving up")
      .Number("retry-delay-ms", &retry_delay_ms, 0.0, 60000.0, "ms", "pause before a retry")
      .Number("timeout-ms", &grab_timeout_ms, OptionTable::Interval::AboveMin(0.0, 600000.0), "ms",
              "grab timeout per frame (the exposure is added)");
}

void DeclareSettleOption(OptionTable* table, double* ms, bool* measure) {
  table->Custom(
      "settle-ms", [ms, measure] { return *measure ? std::string("auto") : OptionNumberText(*ms); },
      [ms, measure](const std::string& text, std::string* why) {
        if (text == "auto") {
          *measure = true;
          return true;
        }
        char* end = nullptr;
        const double value = std::strtod(text.c_str(), &end);
        if (text.empty() || *end != '\0' || !(value >= 0.0 && value <= 60000.0)) {
          *why = "'" + text + "': auto, or milliseconds in [0, 60000]";
          return false;
        }
        *measure = false;
        *ms = value;
        return true;
      },
      "auto, or ms in [0, 60000]",
      "wait after each pattern before frames count: auto measures the display-to-camera latency "
      "first with a flash sequence");
}

bool SequencerOptions::Check(std::string* why) const {
  if (!(settle_ms >= 0 && settle_ms <= 60000)) return Fail(why, "settle_ms must be in [0, 60000]");
  if (frames_per_pattern < 1 || frames_per_pattern > 1000)
    return Fail(why, "frames_per_pattern must be in [1, 1000]");
  if (discard_frames < 0 || discard_frames > 1000)
    return Fail(why, "discard_frames must be in [0, 1000]");
  for (double exposure : exposures_us) {
    if (!(exposure > 0 && exposure <= 1e8))
      return Fail(why, "exposures must be in (0, 1e8] microseconds");
  }
  if (!(grab_timeout_ms > 0 && grab_timeout_ms <= 600000))
    return Fail(why, "grab_timeout_ms must be in (0, 600000]");
  if (max_retries < 0 || max_retries > 100) return Fail(why, "max_retries must be in [0, 100]");
  if (!(retry_delay_ms >= 0 && retry_delay_ms <= 60000))
    return Fail(why, "retry_delay_ms must be in [0, 60000]");
  if (max_stale_frames < 1 || max_stale_frames > 1000000)
    return Fail(why, "max_stale_frames must be in [1, 1e6]");
  if (!(max_changed_fraction >= 0.0 && max_changed_fraction <= 1.0))
    return Fail(why, "max_changed_fraction must be in [0, 1]");
  return hdr.Check(why);
}

PatternSequencer::PatternSequencer(const SequencerOptions& options, Camera* camera,
                                   PatternDisplay* display)
    : options_(options), camera_(camera), display_(display) {
  std::string why;
  if (!options_.Check(&why)) throw std::invalid_argument("SequencerOptions: " + why);
  if (camera_ == nullptr || display_ == nullptr)
    throw std::invalid_argument("PatternSequencer: no camera or display");
}

void PatternSequencer::Retry(const std::exception& error, PatternCapture* capture,
                             int* consecutive_failures) {
  ++*consecutive_failures;
  if (*consecutive_failures > options_.max_retries) {
    throw CaptureFault(std::string(error.what()) + "; gave up after " +
                       std::to_string(options_.max_retries) +
                       (options_.max_retries == 1 ? " retry" : " retries"));
  }
  ++capture->retries;
  capture->retry_reasons.push_back(error.what());
  std::this_thread::sleep_for(std::chrono::nanoseconds(MsToNs(options_.retry_delay_ms)));
  try {  // a restart clears a wedged stream; a vanished device fails again on the next grab
    camera_->Stop();
    camera_->Start();
  } catch (const IoError&) {
  }
}

template <typename Action>
void PatternSequencer::WithRetries(PatternCapture* capture, Action action) {
  int consecutive_failures = 0;
  for (;;) {
    try {
      action();
      return;
    } catch (const CameraTimeout& error) {
      Retry(error, capture, &consecutive_failures);
    } catch (const CameraDisconnected& error) {
      Retry(error, capture, &consecutive_failures);
    }
  }
}

namespace {

// The fraction of `a`'s values (every channel) that differ from `b`'s by more than `threshold`.
double ChangedFraction(const cv::Mat& a, const cv::Mat& b, double threshold) {
  cv::Mat difference, changed;
  cv::absdiff(a, b, difference);
  cv::compare(difference.reshape(1), threshold, changed, cv::CMP_GT);
  return static_cast<double>(cv::countNonZero(changed)) / static_cast<double>(changed.total());
}

}  // namespace

ExposureCapture PatternSequencer::CaptureExposure(int64_t settled_ns, double exposure_us,
                                                  PatternCapture* capture) {
  ExposureCapture result;
  cv::Mat sum, first, last;
  int consecutive_failures = 0;
  int stale_in_a_row = 0;
  int still_changing = 0;
  bool drop_buffered = true;
  const auto timeout = std::chrono::milliseconds(
      static_cast<int64_t>(std::ceil(options_.grab_timeout_ms + exposure_us * 1e-3)));
  for (;;) {
    while (result.frames < options_.frames_per_pattern) {
      try {
        if (drop_buffered) {
          result.buffered_dropped += camera_->DropBufferedFrames();
          drop_buffered = false;
        }
        Frame frame = camera_->Grab(timeout);
        consecutive_failures = 0;
        if (frame.exposure_start_ns < settled_ns) {
          ++result.stale_dropped;
          if (++stale_in_a_row > options_.max_stale_frames) {
            throw CaptureFault(
                "camera '" + camera_->Info().uri + "': " + std::to_string(stale_in_a_row) +
                " frames in a row were exposed before the pattern settled (frame clock not in step "
                "with the host?)");
          }
          continue;
        }
        stale_in_a_row = 0;
        if (result.discarded < options_.discard_frames) {
          ++result.discarded;
          continue;
        }
        cv::Mat value;
        frame.image.convertTo(value, CV_32F);
        last = value;
        if (sum.empty()) {
          first = value;  // each frame converts into a new matrix
          sum = value.clone();
          result.exposure_us = frame.exposure_us;
          result.gain = frame.gain;
          result.first_exposure_start_ns = frame.exposure_start_ns;
        } else if (value.size() != sum.size() || value.type() != sum.type()) {
          throw CaptureFault("camera '" + camera_->Info().uri +
                             "': frame size or format changed within a pattern");
        } else {
          sum += value;
        }
        result.last_arrival_ns = frame.arrival_ns;
        result.sequences.push_back(frame.sequence);
        ++result.frames;
      } catch (const CameraTimeout& error) {
        Retry(error, capture, &consecutive_failures);
        drop_buffered = true;
      } catch (const CameraDisconnected& error) {
        Retry(error, capture, &consecutive_failures);
        drop_buffered = true;
      }
    }
    // Had the picture settled? The first and the last frame must show the same one.
    const double changed = result.frames >= 2 && options_.max_changed_fraction < 1.0
                               ? ChangedFraction(first, last, 0.1 * capture->full_scale)
                               : 0.0;
    if (changed <= options_.max_changed_fraction) break;
    char percent[32];
    std::snprintf(percent, sizeof(percent), "%.1f%%", 100.0 * changed);
    const std::string reason = "camera '" + camera_->Info().uri +
                               "': the picture was still changing during a pattern's frames (" +
                               percent +
                               " of the pixel values changed by over a tenth of full scale "
                               "between the first and the last)";
    if (++still_changing > options_.max_retries)
      throw CaptureFault(reason + ", " + std::to_string(still_changing) +
                         " times in a row: the display reaches the camera later than the settle "
                         "time (raise --settle-ms), or something moves in the camera's view");
    ++capture->retries;
    capture->retry_reasons.push_back(reason + "; taken again");
    // Frames from now on see the settled picture (a change lasts less than one frame).
    settled_ns = SteadyNowNs();
    result.frames = 0;
    result.sequences.clear();
    sum = cv::Mat();
    drop_buffered = true;
  }
  result.mean = sum / static_cast<double>(result.frames);
  return result;
}

PatternCapture PatternSequencer::Capture(const cv::Mat& pattern) {
  PatternCapture capture;
  CameraSettings settings;
  WithRetries(&capture, [&] { settings = camera_->Settings(); });
  capture.full_scale = FullScale(settings.pixel_format);
  display_->Show(pattern);
  capture.shown_ns = SteadyNowNs();
  capture.settled_ns = capture.shown_ns + MsToNs(options_.settle_ms);
  const size_t exposure_count = std::max<size_t>(1, options_.exposures_us.size());
  for (size_t i = 0; i < exposure_count; ++i) {
    int64_t settled_ns = capture.settled_ns;
    double exposure_us = settings.exposure_us;
    if (!options_.exposures_us.empty()) {
      exposure_us = options_.exposures_us[i];
      WithRetries(&capture, [&] { camera_->SetExposure(exposure_us); });
      settled_ns = std::max(settled_ns, SteadyNowNs());  // frames begun before the change are stale
    }
    SleepUntil(settled_ns);
    capture.exposures.push_back(CaptureExposure(settled_ns, exposure_us, &capture));
  }
  if (capture.exposures.size() > 1) {
    std::vector<cv::Mat> means;
    std::vector<double> exposures;
    for (const ExposureCapture& exposure : capture.exposures) {
      means.push_back(exposure.mean);
      exposures.push_back(exposure.exposure_us);
    }
    capture.hdr = MergeExposures(means, exposures, capture.full_scale, options_.hdr);
  }
  return capture;
}

}  // namespace procam
