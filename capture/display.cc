#include "capture/display.h"

#include <algorithm>

#include <cmath>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

#include "base/io.h"

namespace procam {
namespace {
constexpr size_t kHistory = 8;
}  // namespace

MemoryDisplay::MemoryDisplay(cv::Size resolution, std::string name)
    : resolution_(resolution), name_(std::move(name)) {
  if (resolution.width <= 0 || resolution.height <= 0)
    throw std::invalid_argument("MemoryDisplay: empty resolution");
}

void MemoryDisplay::Show(const cv::Mat& pattern) { ShowAt(pattern, SteadyNowNs()); }

void MemoryDisplay::ShowAt(const cv::Mat& pattern, int64_t time_ns) {
  if (pattern.size() != resolution_ || (pattern.type() != CV_8UC1 && pattern.type() != CV_8UC3)) {
    throw IoError("display '" + name_ + "': pattern must be " + std::to_string(resolution_.width) +
                  "x" + std::to_string(resolution_.height) + " 8-bit grey or BGR, got " +
                  std::to_string(pattern.cols) + "x" + std::to_string(pattern.rows) + " type " +
                  std::to_string(pattern.type()));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (!history_.empty()) time_ns = std::max(time_ns, history_.back().time_ns);
  history_.push_back({time_ns, pattern.clone()});
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

DisplayWall::DisplayWall(std::vector<std::shared_ptr<PatternDisplay>> displays,
                         std::vector<std::string> names)
    : displays_(std::move(displays)), names_(std::move(names)) {
  if (displays_.empty() || displays_.size() != names_.size())
    throw std::invalid_argument("DisplayWall: one name per display, at least one display");
}

cv::Size DisplayWall::Resolution() const {
  cv::Size size(0, 0);
  for (const auto& display : displays_) {
    size.width += display->Resolution().width;
    size.height = std::max(size.height, display->Resolution().height);
  }
  return size;
}

std::string DisplayWall::Name() const {
  std::string name;
  for (const auto& display : displays_) {
    if (!name.empty()) name += '+';
    name += display->Name();
  }
  return name;
}

cv::Mat DisplayWall::Compose(const std::vector<cv::Mat>& images) const {
  if (images.size() != displays_.size())
    throw std::invalid_argument("DisplayWall: one image per display");
  cv::Mat wall(Resolution(), CV_8UC3, cv::Scalar::all(0));
  int x = 0;
  for (size_t k = 0; k < displays_.size(); ++k) {
    const cv::Size size = displays_[k]->Resolution();
    if (images[k].size() != size || images[k].type() != CV_8UC3)
      throw std::invalid_argument("DisplayWall: image " + std::to_string(k) + " does not fit");
    images[k].copyTo(wall(cv::Rect(x, 0, size.width, size.height)));
    x += size.width;
  }
  return wall;
}

void DisplayWall::Show(const cv::Mat& pattern) {
  if (pattern.size() != Resolution())
    throw IoError("display wall " + Name() + ": pattern of the wrong size");
  cv::Mat colour = pattern;
  if (pattern.type() == CV_8UC1) cv::cvtColor(pattern, colour, cv::COLOR_GRAY2BGR);
  int x = 0;
  for (size_t k = 0; k < displays_.size(); ++k) {
    const cv::Size size = displays_[k]->Resolution();
    try {
      displays_[k]->Show(colour(cv::Rect(x, 0, size.width, size.height)).clone());
    } catch (const std::exception& error) {
      // Displays' own messages usually start with their name (capture/display.h).
      const std::string display = displays_[k]->Name(), what = error.what();
      throw IoError("projector '" + names_[k] + "'" +
                    (what.rfind(display, 0) == 0 ? "" : " (display " + display + ")") + ": " + what);
    }
    x += size.width;
  }
}

}  // namespace procam
