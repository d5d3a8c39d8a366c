#include "projection/show.h"

#include <fmt/format.h>

#include <chrono>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <thread>

#include "base/image_io.h"
#include "base/io.h"
#include "base/timing.h"
#include "projection/glfw_display.h"

namespace procam {
namespace {

// Which monitor each output goes to: as given, else image k on monitor k, or a pattern on all.
std::vector<MonitorInfo> ChooseMonitors(const ShowOptions& options) {
  std::vector<MonitorInfo> monitors;
  if (!options.monitors.empty()) {
    for (const std::string& which : options.monitors) monitors.push_back(FindMonitor(which));
    return monitors;
  }
  const std::vector<MonitorInfo> all = ListMonitors();
  if (options.images.size() > all.size()) {
    throw IoError(std::to_string(options.images.size()) + " images but only " +
                  std::to_string(all.size()) + " monitor(s) connected");
  }
  monitors.assign(all.begin(),
                  options.images.empty() ? all.end() : all.begin() + options.images.size());
  return monitors;
}

cv::Mat ReadImageFor(const std::filesystem::path& path, const MonitorInfo& monitor) {
  const std::string file = path.string();
  cv::Mat image = ReadImage(path, cv::IMREAD_UNCHANGED);
  if (image.channels() == 4) cv::cvtColor(image, image, cv::COLOR_BGRA2BGR);
  if (image.cols != monitor.width || image.rows != monitor.height) {
    throw IoError(file + ": image is " + std::to_string(image.cols) + "x" +
                  std::to_string(image.rows) + ", but monitor " + std::to_string(monitor.index) +
                  " '" + monitor.name + "' runs at " + std::to_string(monitor.width) + "x" +
                  std::to_string(monitor.height));
  }
  return image;
}

}  // namespace

std::string ShowOptions::Check() const {
  if (images.empty() == !pattern.has_value())
    return "give either images to show or a pattern (not both)";
  if (!images.empty() && !monitors.empty() && monitors.size() != images.size()) {
    return std::to_string(images.size()) + " images but " + std::to_string(monitors.size()) +
           " --monitor options (one per image)";
  }
  return display.Check();
}

void RunShow(const ShowOptions& options) {
  if (options.list) {
    for (const MonitorInfo& m : ListMonitors()) {
      Report(options.progress, fmt::format("{}  {:<16} {}x{} @ {} Hz at ({}, {})", m.index, m.name,
                                           m.width, m.height, m.refresh_hz, m.x, m.y));
    }
    return;
  }
  if (const std::string why = options.Check(); !why.empty()) throw std::invalid_argument(why);
  const std::vector<MonitorInfo> monitors = ChooseMonitors(options);
  std::vector<cv::Mat> images;  // read and checked before any window opens
  for (size_t k = 0; k < options.images.size(); ++k)
    images.push_back(ReadImageFor(options.images[k], monitors[k]));

  std::vector<std::unique_ptr<GlfwDisplay>> displays;
  for (size_t k = 0; k < monitors.size(); ++k) {
    displays.push_back(std::make_unique<GlfwDisplay>(monitors[k], options.display));
    if (images.empty()) {
      displays.back()->Show(MakeTestPattern(*options.pattern, displays.back()->Resolution()));
    } else {
      displays.back()->Show(images[k]);
    }
    Report(options.progress,
           "monitor " + std::to_string(monitors[k].index) + " '" + monitors[k].name + "' " +
               std::to_string(monitors[k].width) + "x" + std::to_string(monitors[k].height) +
               " at (" + std::to_string(monitors[k].x) + ", " + std::to_string(monitors[k].y) +
               "): " + (images.empty() ? TestPatternName(*options.pattern)
                                       : options.images[k].string()));
  }
  if (!options.readback.empty()) {
    std::filesystem::create_directories(options.readback);
    for (size_t k = 0; k < displays.size(); ++k) {
      cv::Mat bgr;
      cv::cvtColor(displays[k]->ReadBack(), bgr, cv::COLOR_RGB2BGR);
      std::vector<uchar> bytes;
      cv::imencode(".png", bgr, bytes);
      WriteFileAtomically(options.readback / ("monitor" + std::to_string(monitors[k].index) + ".png"),
                          std::string(bytes.begin(), bytes.end()));
    }
  }
  if (options.seconds <= 0.0) Report(options.progress, "Esc or Q in a window ends");
  const auto start = Clock::now();
  while (options.seconds <= 0.0 || SecondsSince(start) < options.seconds) {
    bool open = true;
    for (const auto& display : displays) open &= display->PollEvents();
    if (!open) break;
    // Still where they were put: a window manager may move a window or take it out of
    // fullscreen later, and a monitor may be unplugged.
    for (const auto& display : displays) display->CheckStillThere();
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

}  // namespace procam
