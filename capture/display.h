#pragma once
// Where patterns are shown. The sequencer talks to a PatternDisplay; a fullscreen GLFW window
// on a projector implements it (projection module), and MemoryDisplay keeps the patterns in
// memory so that a test camera can photograph them (MakeLoopbackView).

#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "capture/camera.h"

namespace procam {

class PatternDisplay {
 public:
  virtual ~PatternDisplay() = default;
  // Projector pixels; every pattern shown must have this size.
  virtual cv::Size Resolution() const = 0;
  // A name for manifests and messages ("memory", "glfw:HDMI-1", ...).
  virtual std::string Name() const = 0;
  // Shows `pattern` (CV_8UC1 or CV_8UC3 B, G, R; Resolution() pixels) and returns once it is
  // submitted to the output (buffer swap). The light reaches the room some latency later:
  // the sequencer's settle time covers it. Throws IoError naming the display on failure.
  virtual void Show(const cv::Mat& pattern) = 0;
};

// A display that only remembers what it showed and when (steady clock), for test cameras and
// dry runs. Thread-safe.
class MemoryDisplay : public PatternDisplay {
 public:
  explicit MemoryDisplay(cv::Size resolution, std::string name = "memory");

  cv::Size Resolution() const override { return resolution_; }
  std::string Name() const override { return name_; }
  void Show(const cv::Mat& pattern) override;
  // Shows `pattern` as from steady-clock time `time_ns` (not before the last pattern's time):
  // for a watcher that copies what a real monitor showed when it looked. Same checks as Show.
  void ShowAt(const cv::Mat& pattern, int64_t time_ns);

  // The pattern on screen at steady-clock time `time_ns` (CV_8UC1 or CV_8UC3); black before
  // the first Show(). Only the last 8 patterns are kept; older times give the oldest kept.
  cv::Mat ShownAt(int64_t time_ns) const;
  int shown_count() const;

 private:
  struct Shown {
    int64_t time_ns;
    cv::Mat pattern;
  };
  cv::Size resolution_;
  std::string name_;
  mutable std::mutex mutex_;
  std::deque<Shown> history_;
  int shown_count_ = 0;
};

// How a test camera sees a MemoryDisplay: the projector lights a white screen that fills the
// camera's view, radiance = ambient + (value / 255)^projector_gamma per channel.
struct LoopbackOptions {
  double projector_gamma = 1.0;  // projector response exponent, [0.1, 10]; 1 = linear
  double ambient = 0.0;          // radiance added everywhere, [0, 1]
  bool Check(std::string* why) const;
};

// A SceneView (camera.h) that looks at `display`. Throws std::invalid_argument when
// options.Check() fails.
SceneView MakeLoopbackView(std::shared_ptr<const MemoryDisplay> display,
                           const LoopbackOptions& options = {});

// A set of displays shown as one: a pattern is the displays' images side by side (left to
// right, top-aligned, width = Σ widths, height = the tallest), so the capture sequencer shows
// every projector's image at once. Show() throws IoError naming the projector and its display.
class DisplayWall : public PatternDisplay {
 public:
  DisplayWall(std::vector<std::shared_ptr<PatternDisplay>> displays, std::vector<std::string> names);
  cv::Size Resolution() const override;
  std::string Name() const override;
  void Show(const cv::Mat& pattern) override;
  // The displays' images (CV_8UC3 B, G, R, each its display's size) as one pattern.
  cv::Mat Compose(const std::vector<cv::Mat>& images) const;

 private:
  std::vector<std::shared_ptr<PatternDisplay>> displays_;
  std::vector<std::string> names_;
};

}  // namespace procam
