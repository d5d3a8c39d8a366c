#pragma once
// Fullscreen output on projectors through GLFW: the optional backend target
// procam_projection_glfw (CMake option PROCAM_WITH_GLFW; procam/config.h says whether it was
// built). One borderless fullscreen window per projector, on the monitor (video output) the
// projector is connected to, at that monitor's current video mode, showing images pixel for
// pixel (no scaling or filtering: image pixel (c, r) lights projector pixel (c, r)).
//
// GLFW's threading rules apply: make, show on and destroy windows on the process's main thread.

#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "capture/display.h"
#include "projection/projector_images.h"

namespace procam {

struct MonitorInfo {
  int index = 0;     // position in GLFW's list; 0 is the primary monitor
  std::string name;  // as the system names it (X11/RandR output, e.g. "HDMI-1")
  int width = 0, height = 0, refresh_hz = 0;  // current video mode
  int x = 0, y = 0;                           // position on the virtual desktop, pixels
};

// Monitors connected now. Throws IoError when no display server can be reached.
std::vector<MonitorInfo> ListMonitors();
// The monitor `which` names: an index ("1") or a name ("HDMI-1"). Throws IoError listing the
// monitors when none matches.
MonitorInfo FindMonitor(const std::string& which);

// A fullscreen window on one monitor, usable as the capture module's PatternDisplay.
class GlfwDisplay : public PatternDisplay {
 public:
  // Opens the window on `monitor` (its current video mode). Throws IoError naming the monitor.
  explicit GlfwDisplay(const MonitorInfo& monitor);
  ~GlfwDisplay() override;
  GlfwDisplay(const GlfwDisplay&) = delete;
  GlfwDisplay& operator=(const GlfwDisplay&) = delete;

  cv::Size Resolution() const override;
  std::string Name() const override;  // "glfw:NAME"
  // Shows an 8- or 16-bit image, 1 or 3 channels (B, G, R as OpenCV stores them), of exactly
  // Resolution() pixels, and returns after the buffer swap. Throws IoError naming the monitor
  // and both sizes when the size differs, and IoError naming the monitor when the projector is
  // gone: its window was closed (by hand or the window manager) or its monitor disconnected
  // (GLFW then drops the window out of fullscreen).
  void Show(const cv::Mat& pattern) override;
  // Shows a projector image (codes in R, G, B; 10-bit codes scaled to the output's depth).
  void Show(const ProjectorImage& image);
  // What the window shows, read back from its framebuffer (the last image drawn again into the
  // back buffer through the same path, then read): CV_8UC3, R, G, B, row 0 = top.
  cv::Mat ReadBack();
  // Handles window events; false once Esc or Q was pressed or the window was closed.
  bool PollEvents();
  // Closes the window as the window manager does when someone closes it by hand.
  void RequestClose();

 private:
  void Draw();
  void CheckStillThere();  // throws IoError when the window was closed or left its monitor

  MonitorInfo monitor_;
  void* window_ = nullptr;  // GLFWwindow
  cv::Mat shown_;           // CV_16UC3, R, G, B: what Draw() puts on screen
};

}  // namespace procam
