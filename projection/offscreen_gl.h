#pragma once
// An OpenGL context with no window and no display server: EGL on a GPU device
// (EGL_EXT_platform_device, e.g. NVIDIA's driver on a headless server), or Mesa's surfaceless
// platform (llvmpipe), rendering into a framebuffer object of a given size. For rendering
// projector images where no monitor is attached: benchmarks on a compute GPU, headless tests.
// Part of the optional procam_projection_glfw library (OpenGL through libepoxy).

#include <memory>
#include <string>

namespace procam {

class OffscreenGl {
 public:
  // Makes a current OpenGL context (4.3 core profile where the driver has it, else 3.3) with a
  // width × height RGBA8 framebuffer object bound for drawing and reading. Throws IoError with one line saying which step failed
  // (no EGL, no device, no config, no context) when none can be made.
  OffscreenGl(int width, int height);
  ~OffscreenGl();
  OffscreenGl(const OffscreenGl&) = delete;
  OffscreenGl& operator=(const OffscreenGl&) = delete;
  // "EGL device N" or "EGL surfaceless" and the GL renderer string.
  const std::string& description() const;
  // Makes this context (and its framebuffer) current on the calling thread, e.g. when several
  // are used in turn.
  void MakeCurrent();

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace procam
