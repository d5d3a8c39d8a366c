#pragma once
// The emulated room's eyes: what real monitors of a wlroots display server (sway) show, copied
// into in-memory displays, so that a synthetic world lit by those displays (synthetic_camera.h)
// is lit by whatever procam — or any program — puts on the monitors.
//
// Each round captures every output in turn with grim (`grim -o OUTPUT -t ppm -`, wlroots'
// screencopy: what the compositor shows, windows, borders and all) and, where the picture
// changed, shows it on the output's display timed at the capture's start. A change on a monitor
// therefore reaches the display between 0 and one round later; the round's duration is measured
// (round_ms()) so that a latency measured through the room can be judged against it.

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

#include "capture/display.h"

namespace procam {

struct WatchedMonitor {
  std::string output;                      // the compositor's output name, e.g. "HEADLESS-1"
  std::shared_ptr<MemoryDisplay> display;  // what it shows goes here; sizes must match
};

// One capture of `output` with grim as an 8-bit B, G, R image. Throws IoError naming the output
// (grim missing or failing, e.g. no such output or no WAYLAND_DISPLAY; output not PPM).
cv::Mat CaptureOutput(const std::string& output);

class MonitorWatcher {
 public:
  // Captures once synchronously (so that a wrong output name or size fails here, with one
  // IoError naming the output), then keeps watching on a thread, at most `max_rate_hz` rounds
  // per second.
  explicit MonitorWatcher(std::vector<WatchedMonitor> monitors, double max_rate_hz = 200.0);
  ~MonitorWatcher();  // stops and joins
  MonitorWatcher(const MonitorWatcher&) = delete;
  MonitorWatcher& operator=(const MonitorWatcher&) = delete;

  int64_t rounds() const { return rounds_; }
  int64_t changes() const { return changes_; }  // pictures that differed from the one before
  double round_ms() const;                      // mean duration of a round so far
  // The first failure of the watching thread (it stops then); empty while it runs.
  std::string error() const;

 private:
  void Round();  // captures every output once; throws IoError
  void Run();

  std::vector<WatchedMonitor> monitors_;
  std::vector<cv::Mat> last_;
  double min_round_ms_ = 0.0;
  std::atomic<bool> stop_{false};
  std::atomic<int64_t> rounds_{0}, changes_{0}, round_ns_total_{0};
  mutable std::mutex mutex_;
  std::string error_;
  std::thread thread_;
};

}  // namespace procam
