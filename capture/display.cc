#include "capture/display.h"

#include <cmath>
#include <stdexcept>

namespace procam {
namespace {
constexpr size_t kHistory = 8;
}  // namespace

MemoryDisplay::MemoryDisplay(cv::Size resolution, std::string name)
    : resolution_(resolution), name_(std::move(name)) {
  if (resolution.width <= 0 || resolution.height <= 0)
    throw std::invalid_argument("MemoryDisplay: empty resolution");
}

void MemoryDisplay::Show(const cv::Mat& pattern) {
  if (pattern.size() != resolution_ || (pattern.type() != CV_8UC1 && pattern.type() != CV_8UC3)) {
    throw IoError("display '" + name_ + "': pattern must be " + std::to_string(resolution_.width) +
                  "x" + std::to_string(resolution_.height) + " 8-bit grey or BGR, got " +
                  std::to_string(pattern.cols) + "x" + std::to_string(pattern.rows) + " type " +
                  std::to_string(pattern.type()));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  history_.push_back({SteadyNowNs(), pattern.clone()});
  while (history_.size() > kHistory) history_.pop_front();
  ++shown_count_;
}

cv::Mat MemoryDisplay::ShownAt(int64_t time_ns) const {
  std::lock_guard<std::mutex> lock(mutex_);
  if (history_.empty() ||
      (shown_count_ <= static_cast<int>(kHistory) && time_ns < history_.front().time_ns)) {
    return cv::Mat::zeros(resolution_, CV_8UC1);
  }
  for (auto it = history_.rbegin(); it != history_.rend(); ++it) {
    if (it->time_ns <= time_ns) return it->pattern;
  }
  return history_.front().pattern;
}

int MemoryDisplay::shown_count() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return shown_count_;
}

bool LoopbackOptions::Check(std::string* why) const {
  if (!(projector_gamma >= 0.1 && projector_gamma <= 10)) {
    if (why) *why = "projector_gamma must be in [0.1, 10]";
    return false;
  }
  if (!(ambient >= 0 && ambient <= 1)) {
    if (why) *why = "ambient must be in [0, 1]";
    return false;
  }
  return true;
}

SceneView MakeLoopbackView(std::shared_ptr<const MemoryDisplay> display,
                           const LoopbackOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("LoopbackOptions: " + why);
  if (!display) throw std::invalid_argument("MakeLoopbackView: no display");
  // Lookup table from 8-bit value to radiance.
  cv::Mat table(1, 256, CV_32FC1);
  for (int value = 0; value < 256; ++value) {
    table.at<float>(value) =
        static_cast<float>(options.ambient + std::pow(value / 255.0, options.projector_gamma));
  }
  return [display, table](int64_t exposure_start_ns) {
    const cv::Mat shown = display->ShownAt(exposure_start_ns);
    cv::Mat radiance(shown.size(), CV_MAKETYPE(CV_32F, shown.channels()));
    const int values = shown.cols * shown.channels();
    for (int y = 0; y < shown.rows; ++y) {
      const uint8_t* in = shown.ptr<uint8_t>(y);
      float* out = radiance.ptr<float>(y);
      for (int i = 0; i < values; ++i) out[i] = table.at<float>(in[i]);
    }
    return radiance;
  };
}

}  // namespace procam
