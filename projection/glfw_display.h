#pragma once
// Fullscreen output on projectors through GLFW: the optional backend target
// procam_projection_glfw (CMake option PROCAM_WITH_GLFW; procam/config.h says whether it was
// built). One borderless fullscreen window per projector, on the monitor (video output) the
// projector is connected to, at that monitor's current video mode, showing images pixel for
// pixel (no scaling or filtering: image pixel (c, r) lights projector pixel (c, r)).
//
// GLFW's threading rules apply: make, show on and destroy windows on the process's main thread.
//
// A display node draws a frame and presents it separately, so that a frame barrier can sit
// between the two: Draw (a projector image rendered on the GPU from a frame plan, or a CPU image)
// into the back buffer, then Present, which swaps and says when. Show is Draw then Present.

#include <cstdint>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "capture/display.h"
#include "projection/frame_plan.h"
#include "projection/projector_images.h"

namespace procam {

class GlProjectorRenderer;

struct MonitorInfo {
  int index = 0;     // position in GLFW's list; 0 is the primary monitor
  std::string name;  // as the system names it (X11/RandR output, e.g. "HDMI-1")
  int width = 0, height = 0, refresh_hz = 0;  // current video mode
  int x = 0, y = 0;                           // position on the virtual desktop, pixels
};

// Monitors connected now. Throws IoError when no display server can be reached.
std::vector<MonitorInfo> ListMonitors();
// The monitor `which` names: an index ("1") or a name ("HDMI-1", "XWAYLAND1"). Throws IoError
// listing the monitors when none matches.
MonitorInfo FindMonitor(const std::string& which);

// How a projector's window is put on its monitor (X11).
enum class WindowPlacement {
  // kWindowManager where the window manager can be told the monitor (it lists EWMH's
  // _NET_WM_FULLSCREEN_MONITORS in _NET_SUPPORTED) or where there is no window manager; kByHand
  // where it can only be asked for fullscreen and would choose the monitor itself (sway's
  // Xwayland puts a new window on the focused output, whatever its position).
  kAuto,
  // GLFW's fullscreen: the window manager is asked for _NET_WM_STATE_FULLSCREEN on the monitor
  // (_NET_WM_FULLSCREEN_MONITORS); without a window manager GLFW places the window itself.
  kWindowManager,
  // A borderless window the window manager leaves alone (override-redirect), placed by procam
  // over the monitor's rectangle of the virtual desktop.
  kByHand,
};
// "auto", "window-manager", "by-hand"; false for anything else.
bool ParseWindowPlacement(const std::string& text, WindowPlacement* placement);

struct GlfwDisplayOptions {
  WindowPlacement placement = WindowPlacement::kAuto;
  // How long to wait for the window to cover its monitor after it opens, seconds, in (0, 60].
  double placement_seconds = 2.0;

  // "" when valid, else why not.
  std::string Check() const;
};

// A fullscreen window on one monitor, usable as the capture module's PatternDisplay.
class GlfwDisplay : public PatternDisplay {
 public:
  // Opens the window on `monitor` (its current video mode) and waits until it covers exactly the
  // monitor's rectangle of the virtual desktop (the window's position and size as the display
  // server has them). Throws std::invalid_argument for bad options, IoError naming the monitor
  // when the window cannot be opened or is elsewhere after options.placement_seconds (then one
  // line with both rectangles).
  explicit GlfwDisplay(const MonitorInfo& monitor, const GlfwDisplayOptions& options = {});
  ~GlfwDisplay() override;
  GlfwDisplay(const GlfwDisplay&) = delete;
  GlfwDisplay& operator=(const GlfwDisplay&) = delete;

  cv::Size Resolution() const override;
  std::string Name() const override;  // "glfw:NAME"
  // Shows an 8- or 16-bit image, 1 or 3 channels (B, G, R as OpenCV stores them), of exactly
  // Resolution() pixels, and returns after the buffer swap. Throws IoError naming the monitor
  // and both sizes when the size differs, and IoError naming the monitor when the projector is
  // gone: its window was closed (by hand or the window manager), its monitor disconnected (GLFW
  // then drops the window out of fullscreen) or the window no longer covers the monitor.
  void Show(const cv::Mat& pattern) override;
  // Shows a projector image (codes in R, G, B; 10-bit codes scaled to the output's depth).
  void Show(const ProjectorImage& image);
  // Draws a projector image into the back buffer, not shown until Present(). Throws like Show.
  void Draw(const ProjectorImage& image);
  // Renders a frame plan on the GPU into the back buffer (GlProjectorRenderer::Draw, with the
  // window's context current), not shown until Present(). The renderer must have been made with
  // this window's context current (MakeContextCurrent). Throws IoError like Show when the
  // projector is gone or the renderer's image size is not the monitor's.
  void Draw(GlProjectorRenderer& renderer, const FramePlan& plan);
  // Swaps the buffers (waiting for the vertical blank: swap interval 1) and returns the steady
  // clock's time (SteadyNowNs of capture/camera.h) right after the swap returned.
  int64_t Present();
  // Makes the window's OpenGL context current on this thread (for making a GlProjectorRenderer).
  void MakeContextCurrent();
  // What the window shows, read back from its framebuffer (the last image drawn again into the
  // back buffer through the same path, then read): CV_8UC3, R, G, B, row 0 = top.
  cv::Mat ReadBack();
  // Handles window events; false once Esc or Q was pressed or the window was closed.
  bool PollEvents();
  // Closes the window as the window manager does when someone closes it by hand.
  void RequestClose();
  // Handles window events and throws IoError naming the monitor when the projector is gone, as
  // Show does: the window was closed, its monitor disconnected, or the window no longer covers
  // the monitor's rectangle (moved, resized or taken out of fullscreen by the window manager).
  void CheckStillThere();

 private:
  void DrawShown();                                           // shown_ into the back buffer
  void CheckSize(int width, int height) const;                // IoError unless the monitor's
  void OpenWindow(void* monitor, WindowPlacement placement);  // GLFWmonitor; sets window_
  std::string WindowRectangle() const;  // where the window is now: "WxH at (x, y)"
  bool OnMonitor() const;               // whether that is exactly the monitor's rectangle

  MonitorInfo monitor_;
  WindowPlacement placement_ = WindowPlacement::kAuto;  // kWindowManager or kByHand once open
  void* window_ = nullptr;                              // GLFWwindow
  cv::Mat shown_;  // CV_16UC3, R, G, B: what DrawShown() puts on screen
};

}  // namespace procam
