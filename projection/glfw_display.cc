#include "projection/glfw_display.h"

// libepoxy loads the OpenGL functions (legacy ones too, for glDrawPixels); GLFW brings none.
#include <epoxy/gl.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include <chrono>
#include <mutex>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <thread>

#include "base/io.h"
#include "capture/camera.h"
#include "projection/gl_renderer.h"

// Last: Xlib's macros (None, Status, Bool, ...) would clash with names in the headers above.
#define GLFW_EXPOSE_NATIVE_X11
#include <GLFW/glfw3native.h>
#include <X11/Xatom.h>

namespace procam {
namespace {

// GLFW is initialised on first use and terminated when the last window closes (so that a
// later use, possibly on another DISPLAY, starts afresh).
std::mutex glfw_mutex;
int open_windows = 0;

std::string GlfwErrorText() {
  const char* description = nullptr;
  glfwGetError(&description);
  return description ? description : "unknown error";
}

void InitGlfw() {
  if (!glfwInit()) throw IoError("GLFW: cannot connect to a display: " + GlfwErrorText());
}

void ReleaseGlfwIfIdle() {
  if (open_windows == 0) glfwTerminate();
}

std::vector<MonitorInfo> ListMonitorsLocked() {
  InitGlfw();
  int count = 0;
  GLFWmonitor** monitors = glfwGetMonitors(&count);
  std::vector<MonitorInfo> list;
  for (int k = 0; k < count; ++k) {
    MonitorInfo info;
    info.index = k;
    info.name = glfwGetMonitorName(monitors[k]) ? glfwGetMonitorName(monitors[k]) : "";
    if (const GLFWvidmode* mode = glfwGetVideoMode(monitors[k])) {
      info.width = mode->width;
      info.height = mode->height;
      info.refresh_hz = mode->refreshRate;
    }
    glfwGetMonitorPos(monitors[k], &info.x, &info.y);
    list.push_back(info);
  }
  return list;
}

std::string Describe(const std::vector<MonitorInfo>& monitors) {
  std::string text;
  for (const MonitorInfo& m : monitors) {
    text += (text.empty() ? "" : ", ") + std::to_string(m.index) + " '" + m.name + "' " +
            std::to_string(m.width) + "x" + std::to_string(m.height);
  }
  return text.empty() ? "none" : text;
}

std::string Rectangle(int width, int height, int x, int y) {
  return std::to_string(width) + "x" + std::to_string(height) + " at (" + std::to_string(x) + ", " +
         std::to_string(y) + ")";
}

// Whether the X11 window manager can be told on which monitor a fullscreen window belongs. GLFW
// asks for _NET_WM_STATE_FULLSCREEN and names the monitor through _NET_WM_FULLSCREEN_MONITORS; a
// window manager that supports only the former fullscreens the window wherever it chose to put
// it (sway's Xwayland: on the focused output). Without _NET_WM_STATE_FULLSCREEN (no window
// manager) GLFW places the window over the monitor itself.
bool WindowManagerTakesTheMonitor() {
  Display* display = glfwGetX11Display();
  if (display == nullptr) return true;
  const Atom supported = XInternAtom(display, "_NET_SUPPORTED", False);
  const Atom fullscreen = XInternAtom(display, "_NET_WM_STATE_FULLSCREEN", False);
  const Atom fullscreen_monitors = XInternAtom(display, "_NET_WM_FULLSCREEN_MONITORS", False);
  Atom type = 0;
  int format = 0;
  unsigned long count = 0, remaining = 0;
  unsigned char* data = nullptr;
  if (XGetWindowProperty(display, DefaultRootWindow(display), supported, 0, 1 << 16, False, XA_ATOM,
                         &type, &format, &count, &remaining, &data) != Success ||
      data == nullptr) {
    return true;
  }
  bool has_fullscreen = false, has_monitors = false;
  const Atom* atoms = reinterpret_cast<const Atom*>(data);  // format 32 comes as longs
  for (unsigned long k = 0; k < count; ++k) {
    has_fullscreen |= atoms[k] == fullscreen;
    has_monitors |= atoms[k] == fullscreen_monitors;
  }
  XFree(data);
  return !has_fullscreen || has_monitors;
}

}  // namespace

bool ParseWindowPlacement(const std::string& text, WindowPlacement* placement) {
  if (text == "auto") {
    *placement = WindowPlacement::kAuto;
  } else if (text == "window-manager") {
    *placement = WindowPlacement::kWindowManager;
  } else if (text == "by-hand") {
    *placement = WindowPlacement::kByHand;
  } else {
    return false;
  }
  return true;
}

std::string GlfwDisplayOptions::Check() const {
  if (!(placement_seconds > 0.0 && placement_seconds <= 60.0))
    return "placement_seconds must be in (0, 60], not " + std::to_string(placement_seconds);
  return "";
}

std::vector<MonitorInfo> ListMonitors() {
  std::lock_guard<std::mutex> lock(glfw_mutex);
  std::vector<MonitorInfo> list = ListMonitorsLocked();
  ReleaseGlfwIfIdle();
  return list;
}

MonitorInfo FindMonitor(const std::string& which) {
  const std::vector<MonitorInfo> monitors = ListMonitors();
  for (const MonitorInfo& monitor : monitors) {
    if (monitor.name == which || std::to_string(monitor.index) == which) return monitor;
  }
  throw IoError("monitor '" + which + "' not found (monitors: " + Describe(monitors) + ")");
}

GlfwDisplay::GlfwDisplay(const MonitorInfo& monitor, const GlfwDisplayOptions& options)
    : monitor_(monitor) {
  if (const std::string why = options.Check(); !why.empty()) throw std::invalid_argument(why);
  std::lock_guard<std::mutex> lock(glfw_mutex);
  InitGlfw();
  int count = 0;
  GLFWmonitor** monitors = glfwGetMonitors(&count);
  if (monitor.index < 0 || monitor.index >= count) {
    ReleaseGlfwIfIdle();
    throw IoError("monitor " + std::to_string(monitor.index) + " '" + monitor.name +
                  "' is not connected");
  }
  GLFWmonitor* target = monitors[monitor.index];
  const GLFWvidmode* mode = glfwGetVideoMode(target);
  monitor_.width = mode->width;
  monitor_.height = mode->height;
  monitor_.refresh_hz = mode->refreshRate;
  glfwGetMonitorPos(target, &monitor_.x, &monitor_.y);
  placement_ = options.placement;
  if (placement_ == WindowPlacement::kAuto) {
    placement_ =
        WindowManagerTakesTheMonitor() ? WindowPlacement::kWindowManager : WindowPlacement::kByHand;
  }
  OpenWindow(target, placement_);
  if (window_ == nullptr) {
    const std::string error = GlfwErrorText();
    ReleaseGlfwIfIdle();
    throw IoError("monitor " + std::to_string(monitor.index) + " '" + monitor.name +
                  "': cannot open a window: " + error);
  }
  ++open_windows;
  GLFWwindow* window = static_cast<GLFWwindow*>(window_);
  glfwMakeContextCurrent(window);
  glfwSwapInterval(1);
  glfwSetInputMode(window, GLFW_CURSOR, GLFW_CURSOR_HIDDEN);
  shown_ = cv::Mat(mode->height, mode->width, CV_16UC3, cv::Scalar::all(0));
  DrawShown();
  glfwSwapBuffers(window);
  // The window manager and the server move and map the window asynchronously: wait until the
  // server has it over the monitor, and say where it is if it never gets there.
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::duration<double>(options.placement_seconds);
  while (true) {
    glfwPollEvents();
    if (OnMonitor()) break;
    if (std::chrono::steady_clock::now() > deadline) {
      const std::string message =
          "monitor " + std::to_string(monitor_.index) + " '" + monitor_.name + "' (" +
          Rectangle(monitor_.width, monitor_.height, monitor_.x, monitor_.y) + "): its window is " +
          WindowRectangle() +
          (placement_ == WindowPlacement::kWindowManager
               ? " instead: the window manager put it elsewhere"
               : " instead, though placed there by hand");
      glfwDestroyWindow(window);  // the destructor does not run for a constructor that throws
      --open_windows;
      ReleaseGlfwIfIdle();
      throw IoError(message);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

void GlfwDisplay::OpenWindow(void* target_monitor, WindowPlacement placement) {
  GLFWmonitor* target = static_cast<GLFWmonitor*>(target_monitor);
  const GLFWvidmode* mode = glfwGetVideoMode(target);
  const std::string title = "procam " + monitor_.name;
  // Hints persist between windows: start from GLFW's defaults each time. Keep the current mode
  // (no mode switch), no decorations, stay up when focus moves to another projector's window.
  glfwDefaultWindowHints();
  glfwWindowHint(GLFW_RED_BITS, mode->redBits);
  glfwWindowHint(GLFW_GREEN_BITS, mode->greenBits);
  glfwWindowHint(GLFW_BLUE_BITS, mode->blueBits);
  glfwWindowHint(GLFW_REFRESH_RATE, mode->refreshRate);
  glfwWindowHint(GLFW_AUTO_ICONIFY, GLFW_FALSE);
  glfwWindowHint(GLFW_CLIENT_API, GLFW_OPENGL_API);
  if (placement == WindowPlacement::kWindowManager) {
    window_ = glfwCreateWindow(mode->width, mode->height, title.c_str(), target, nullptr);
    return;
  }
  // By hand: an unmapped borderless window, made override-redirect before it is first mapped
  // (ICCCM: the window manager then neither manages, moves nor resizes it), over the monitor.
  glfwWindowHint(GLFW_VISIBLE, GLFW_FALSE);
  glfwWindowHint(GLFW_DECORATED, GLFW_FALSE);
  GLFWwindow* window = glfwCreateWindow(mode->width, mode->height, title.c_str(), nullptr, nullptr);
  window_ = window;
  if (window == nullptr) return;
  Display* display = glfwGetX11Display();
  const Window handle = glfwGetX11Window(window);
  XSetWindowAttributes attributes = {};
  attributes.override_redirect = True;
  XChangeWindowAttributes(display, handle, CWOverrideRedirect, &attributes);
  XMoveResizeWindow(display, handle, monitor_.x, monitor_.y, static_cast<unsigned>(mode->width),
                    static_cast<unsigned>(mode->height));
  glfwShowWindow(window);
  XRaiseWindow(display, handle);
  XFlush(display);
}

std::string GlfwDisplay::WindowRectangle() const {
  GLFWwindow* window = static_cast<GLFWwindow*>(window_);
  int x = 0, y = 0, width = 0, height = 0;
  glfwGetWindowPos(window, &x, &y);
  glfwGetWindowSize(window, &width, &height);
  return Rectangle(width, height, x, y);
}

bool GlfwDisplay::OnMonitor() const {
  return WindowRectangle() == Rectangle(monitor_.width, monitor_.height, monitor_.x, monitor_.y);
}

GlfwDisplay::~GlfwDisplay() {
  std::lock_guard<std::mutex> lock(glfw_mutex);
  glfwDestroyWindow(static_cast<GLFWwindow*>(window_));
  --open_windows;
  ReleaseGlfwIfIdle();
}

cv::Size GlfwDisplay::Resolution() const { return {monitor_.width, monitor_.height}; }

std::string GlfwDisplay::Name() const { return "glfw:" + monitor_.name; }

void GlfwDisplay::CheckStillThere() {
  GLFWwindow* window = static_cast<GLFWwindow*>(window_);
  glfwPollEvents();
  if (glfwWindowShouldClose(window)) {
    throw IoError(Name() + ": the projector's window was closed");
  }
  int count = 0;
  GLFWmonitor** monitors = glfwGetMonitors(&count);
  bool connected = false;
  for (int k = 0; k < count; ++k) {
    const char* name = glfwGetMonitorName(monitors[k]);
    connected |= name != nullptr && monitor_.name == name;
  }
  if (!connected ||
      (placement_ == WindowPlacement::kWindowManager && glfwGetWindowMonitor(window) == nullptr)) {
    throw IoError(Name() + ": the monitor was disconnected (the window is no longer fullscreen)");
  }
  if (!OnMonitor()) {
    throw IoError(Name() + ": the window left its monitor (" +
                  Rectangle(monitor_.width, monitor_.height, monitor_.x, monitor_.y) + "): it is " +
                  WindowRectangle() + " now");
  }
}

void GlfwDisplay::RequestClose() {
  glfwSetWindowShouldClose(static_cast<GLFWwindow*>(window_), GLFW_TRUE);
}

void GlfwDisplay::CheckSize(int width, int height) const {
  if (width != monitor_.width || height != monitor_.height) {
    throw IoError(Name() + ": image is " + std::to_string(width) + "x" + std::to_string(height) +
                  ", the monitor runs at " + std::to_string(monitor_.width) + "x" +
                  std::to_string(monitor_.height));
  }
}

void GlfwDisplay::Show(const cv::Mat& pattern) {
  CheckStillThere();
  CheckSize(pattern.cols, pattern.rows);
  cv::Mat rgb;
  if (pattern.channels() == 1) {
    cv::cvtColor(pattern, rgb, cv::COLOR_GRAY2RGB);
  } else if (pattern.channels() == 3) {
    cv::cvtColor(pattern, rgb, cv::COLOR_BGR2RGB);
  } else {
    throw IoError(Name() + ": images must have 1 or 3 channels");
  }
  if (rgb.depth() == CV_8U) {
    rgb.convertTo(shown_, CV_16UC3, 257.0);  // 8-bit v → 16-bit v · 257: the same fraction
  } else if (rgb.depth() == CV_16U) {
    shown_ = rgb;
  } else {
    throw IoError(Name() + ": images must be 8- or 16-bit");
  }
  DrawShown();
  Present();
}

void GlfwDisplay::Show(const ProjectorImage& image) {
  Draw(image);
  Present();
}

void GlfwDisplay::Draw(const ProjectorImage& image) {
  CheckStillThere();
  CheckSize(image.codes.cols, image.codes.rows);
  image.codes.convertTo(shown_, CV_16UC3, 65535.0 / ((1 << image.bits) - 1));
  DrawShown();
}

void GlfwDisplay::Draw(GlProjectorRenderer& renderer, const FramePlan& plan) {
  CheckStillThere();
  CheckSize(renderer.width(), renderer.height());
  MakeContextCurrent();
  renderer.Draw(plan);
}

int64_t GlfwDisplay::Present() {
  glfwSwapBuffers(static_cast<GLFWwindow*>(window_));
  return SteadyNowNs();
}

void GlfwDisplay::MakeContextCurrent() {
  glfwMakeContextCurrent(static_cast<GLFWwindow*>(window_));
}

void GlfwDisplay::DrawShown() {
  GLFWwindow* window = static_cast<GLFWwindow*>(window_);
  glfwMakeContextCurrent(window);
  int width = 0, height = 0;
  glfwGetFramebufferSize(window, &width, &height);
  glViewport(0, 0, width, height);
  glMatrixMode(GL_PROJECTION);
  glLoadIdentity();
  glOrtho(0.0, width, 0.0, height, -1.0, 1.0);
  glMatrixMode(GL_MODELVIEW);
  glLoadIdentity();
  glClearColor(0.0f, 0.0f, 0.0f, 1.0f);
  glClear(GL_COLOR_BUFFER_BIT);
  // Pixel for pixel, row 0 at the top: start just below the top edge and draw downwards.
  glRasterPos2d(0.0, height - 1e-3);
  glPixelZoom(1.0f, -1.0f);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, static_cast<GLint>(shown_.step1() / 3));
  glDrawPixels(shown_.cols, shown_.rows, GL_RGB, GL_UNSIGNED_SHORT, shown_.data);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
  glFinish();
}

cv::Mat GlfwDisplay::ReadBack() {
  GLFWwindow* window = static_cast<GLFWwindow*>(window_);
  glfwMakeContextCurrent(window);
  int width = 0, height = 0;
  glfwGetFramebufferSize(window, &width, &height);
  // The front buffer cannot be read on every driver (Mesa under Xvfb returns black): draw the
  // shown image into the back buffer again, exactly as Show() did, and read that.
  DrawShown();
  cv::Mat bottom_up(height, width, CV_8UC3);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadBuffer(GL_BACK);
  glReadPixels(0, 0, width, height, GL_RGB, GL_UNSIGNED_BYTE, bottom_up.data);
  cv::Mat top_down;
  cv::flip(bottom_up, top_down, 0);
  return top_down;
}

bool GlfwDisplay::PollEvents() {
  GLFWwindow* window = static_cast<GLFWwindow*>(window_);
  glfwPollEvents();
  if (glfwWindowShouldClose(window) || glfwGetKey(window, GLFW_KEY_ESCAPE) == GLFW_PRESS ||
      glfwGetKey(window, GLFW_KEY_Q) == GLFW_PRESS) {
    return false;
  }
  return true;
}

}  // namespace procam
