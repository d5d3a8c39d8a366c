#include "projection/offscreen_gl.h"

#include <epoxy/egl.h>
#include <epoxy/gl.h>

#include <string>
#include <vector>

#include "base/io.h"

namespace procam {

struct OffscreenGl::State {
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext context = EGL_NO_CONTEXT;
  GLuint framebuffer = 0, colour = 0;
  std::string description;
};

namespace {

// A display on the first EGL device, or on Mesa's surfaceless platform; EGL_NO_DISPLAY if
// neither can be initialised.
EGLDisplay OpenDisplay(std::string* kind) {
  if (epoxy_has_egl_extension(EGL_NO_DISPLAY, "EGL_EXT_platform_device") &&
      epoxy_has_egl_extension(EGL_NO_DISPLAY, "EGL_EXT_device_enumeration")) {
    EGLDeviceEXT devices[8];
    EGLint count = 0;
    if (eglQueryDevicesEXT(8, devices, &count) && count > 0) {
      for (EGLint k = 0; k < count; ++k) {
        EGLDisplay display = eglGetPlatformDisplayEXT(EGL_PLATFORM_DEVICE_EXT, devices[k], nullptr);
        EGLint major = 0, minor = 0;
        if (display != EGL_NO_DISPLAY && eglInitialize(display, &major, &minor)) {
          *kind = "EGL device " + std::to_string(k);
          return display;
        }
      }
    }
  }
  if (epoxy_has_egl_extension(EGL_NO_DISPLAY, "EGL_MESA_platform_surfaceless")) {
    EGLDisplay display =
        eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    EGLint major = 0, minor = 0;
    if (display != EGL_NO_DISPLAY && eglInitialize(display, &major, &minor)) {
      *kind = "EGL surfaceless";
      return display;
    }
  }
  return EGL_NO_DISPLAY;
}

}  // namespace

OffscreenGl::OffscreenGl(int width, int height) : state_(std::make_unique<State>()) {
  std::string kind;
  state_->display = OpenDisplay(&kind);
  if (state_->display == EGL_NO_DISPLAY) {
    throw IoError("offscreen OpenGL: no EGL device and no surfaceless EGL platform");
  }
  const EGLint config_attributes[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE,
                                      EGL_OPENGL_BIT, EGL_NONE};
  EGLConfig config;
  EGLint configs = 0;
  if (!eglChooseConfig(state_->display, config_attributes, &config, 1, &configs) || configs < 1) {
    // Surfaceless displays may offer no pbuffer config; a context needs no surface there.
    const EGLint any[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
    if (!eglChooseConfig(state_->display, any, &config, 1, &configs) || configs < 1)
      throw IoError("offscreen OpenGL (" + kind + "): no OpenGL config");
  }
  if (!eglBindAPI(EGL_OPENGL_API))
    throw IoError("offscreen OpenGL (" + kind + "): cannot bind the OpenGL API");
  // 4.3 core where the driver has it (compute shaders: gl_renderer.h), else 3.3 core.
  for (const EGLint version : {43, 33}) {
    const EGLint context_attributes[] = {EGL_CONTEXT_MAJOR_VERSION,
                                         version / 10,
                                         EGL_CONTEXT_MINOR_VERSION,
                                         version % 10,
                                         EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                         EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                         EGL_NONE};
    state_->context =
        eglCreateContext(state_->display, config, EGL_NO_CONTEXT, context_attributes);
    if (state_->context != EGL_NO_CONTEXT) break;
  }
  if (state_->context == EGL_NO_CONTEXT)
    throw IoError("offscreen OpenGL (" + kind + "): no OpenGL 3.3 core context");
  if (!eglMakeCurrent(state_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, state_->context)) {
    throw IoError("offscreen OpenGL (" + kind +
                  "): cannot make the context current without a surface");
  }
  glGenFramebuffers(1, &state_->framebuffer);
  glGenRenderbuffers(1, &state_->colour);
  glBindRenderbuffer(GL_RENDERBUFFER, state_->colour);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
  glBindFramebuffer(GL_FRAMEBUFFER, state_->framebuffer);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, state_->colour);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
    throw IoError("offscreen OpenGL (" + kind + "): the " + std::to_string(width) + "x" +
                  std::to_string(height) + " framebuffer is not complete");
  }
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  state_->description = kind + ", " + reinterpret_cast<const char*>(glGetString(GL_RENDERER));
}

OffscreenGl::~OffscreenGl() {
  if (state_->context != EGL_NO_CONTEXT &&
      eglMakeCurrent(state_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, state_->context)) {
    glDeleteFramebuffers(1, &state_->framebuffer);
    glDeleteRenderbuffers(1, &state_->colour);
    eglMakeCurrent(state_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(state_->display, state_->context);
  }
  // The display is not terminated: EGL hands every OffscreenGl of a process the same one, and
  // terminating it would end the others' contexts too.
}

const std::string& OffscreenGl::description() const { return state_->description; }

void OffscreenGl::MakeCurrent() {
  if (!eglMakeCurrent(state_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, state_->context))
    throw IoError("offscreen OpenGL: cannot make the context current");
  glBindFramebuffer(GL_FRAMEBUFFER, state_->framebuffer);
  glReadBuffer(GL_COLOR_ATTACHMENT0);
}

}  // namespace procam
