#include "datasets_synthetic/monitor_watcher.h"

#include <cctype>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

#include <fmt/format.h>

#include "base/io.h"
#include "capture/camera.h"

namespace procam {
namespace {

// Reads a binary PPM (P6, maxval 255) from `file`. Returns an empty image on malformed input.
cv::Mat ReadPpm(std::FILE* file) {
  const auto token = [file]() {
    std::string text;
    int c = std::fgetc(file);
    while (c != EOF && (std::isspace(c) || c == '#')) {
      if (c == '#') while (c != EOF && c != '\n') c = std::fgetc(file);
      c = std::fgetc(file);
    }
    while (c != EOF && !std::isspace(c)) {
      text += static_cast<char>(c);
      c = std::fgetc(file);
    }
    return text;  // the one whitespace after it is consumed
  };
  if (token() != "P6") return {};
  const int width = std::atoi(token().c_str()), height = std::atoi(token().c_str());
  const int maxval = std::atoi(token().c_str());
  if (width <= 0 || height <= 0 || width > 16384 || height > 16384 || maxval != 255) return {};
  cv::Mat rgb(height, width, CV_8UC3);
  if (std::fread(rgb.data, 1, rgb.total() * 3, file) != rgb.total() * 3) return {};
  cv::Mat bgr(height, width, CV_8UC3);
  const int from_to[] = {0, 2, 1, 1, 2, 0};
  cv::mixChannels(&rgb, 1, &bgr, 1, from_to, 3);
  return bgr;
}

bool SafeOutputName(const std::string& name) {
  if (name.empty() || name.size() > 64) return false;
  for (char c : name)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.') return false;
  return true;
}

}  // namespace

cv::Mat CaptureOutput(const std::string& output) {
  if (!SafeOutputName(output)) throw IoError("monitor '" + output + "': not an output name (e.g. HEADLESS-1)");
  const std::string command = "grim -o '" + output + "' -t ppm - 2>/dev/null";
  std::FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) throw IoError("monitor '" + output + "': cannot run grim");
  cv::Mat image = ReadPpm(pipe);
  const int status = ::pclose(pipe);
  if (status != 0 || image.empty()) {
    throw IoError("monitor '" + output + "': grim could not capture it (exit status " + std::to_string(status) +
                  "; is it an output of the running wlroots compositor, is WAYLAND_DISPLAY set, is grim installed?)");
  }
  return image;
}

MonitorWatcher::MonitorWatcher(std::vector<WatchedMonitor> monitors, double max_rate_hz)
    : monitors_(std::move(monitors)), last_(monitors_.size()) {
  if (monitors_.empty()) throw std::invalid_argument("MonitorWatcher: no monitors");
  if (!(max_rate_hz > 0)) throw std::invalid_argument("MonitorWatcher: max_rate_hz must be > 0");
  min_round_ms_ = 1000.0 / max_rate_hz;
  for (const WatchedMonitor& monitor : monitors_)
    if (!monitor.display) throw std::invalid_argument("MonitorWatcher: monitor " + monitor.output + " has no display");
  Round();
  thread_ = std::thread([this] { Run(); });
}

MonitorWatcher::~MonitorWatcher() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

double MonitorWatcher::round_ms() const {
  const int64_t rounds = rounds_;
  return rounds > 0 ? 1e-6 * static_cast<double>(round_ns_total_) / static_cast<double>(rounds) : 0.0;
}

std::string MonitorWatcher::error() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return error_;
}

void MonitorWatcher::Round() {
  const int64_t start = SteadyNowNs();
  for (size_t k = 0; k < monitors_.size(); ++k) {
    const int64_t captured_at = SteadyNowNs();
    const cv::Mat picture = CaptureOutput(monitors_[k].output);
    const cv::Size expected = monitors_[k].display->Resolution();
    if (picture.size() != expected) {
      throw IoError(fmt::format("monitor '{}' is {}x{}, its projector {}x{}", monitors_[k].output, picture.cols,
                                picture.rows, expected.width, expected.height));
    }
    if (last_[k].empty() || cv::norm(picture, last_[k], cv::NORM_INF) != 0.0) {
      monitors_[k].display->ShowAt(picture, captured_at);
      last_[k] = picture;
      ++changes_;
    }
  }
  round_ns_total_ += SteadyNowNs() - start;
  ++rounds_;
}

void MonitorWatcher::Run() {
  while (!stop_) {
    const int64_t start = SteadyNowNs();
    try {
      Round();
    } catch (const std::exception& error) {
      std::lock_guard<std::mutex> lock(mutex_);
      error_ = error.what();
      return;
    }
    const double rest_ms = min_round_ms_ - 1e-6 * static_cast<double>(SteadyNowNs() - start);
    if (rest_ms > 0) std::this_thread::sleep_for(std::chrono::microseconds(static_cast<int64_t>(rest_ms * 1000)));
  }
}

}  // namespace procam
