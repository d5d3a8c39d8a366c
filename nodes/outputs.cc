#include "nodes/outputs.h"

#include <stdexcept>

#include "procam/config.h"
#if PROCAM_WITH_GLFW
#include "projection/gl_renderer.h"
#include "projection/glfw_display.h"
#include "projection/offscreen_gl.h"
#endif

namespace procam {
namespace {

#if PROCAM_WITH_GLFW
// A projector's fullscreen window: CPU images or GPU-rendered plans into its back buffer, shown
// at Present.
class GlfwOutput : public NodeOutput {
 public:
  explicit GlfwOutput(const std::string& monitor) : display_(FindMonitor(monitor)) {}
  ~GlfwOutput() override {
    if (!renderer_) return;
    try {
      display_.MakeContextCurrent();
      renderer_.reset();
    } catch (const std::exception&) {  // the GL objects go with the window's context
    }
  }
  std::string Describe() const override { return display_.Name(); }
  void Draw(const ProjectorImage& image) override { display_.Draw(image); }
  bool PrepareGpu(const FramePlanner& planner, int projector) override {
    display_.MakeContextCurrent();
    renderer_.reset();
    renderer_ = std::make_unique<GlProjectorRenderer>(planner, projector);
    return true;
  }
  void DrawPlan(const FramePlan& plan) override { display_.Draw(*renderer_, plan); }
  void Present(uint64_t) override { display_.Present(); }
  std::string Fault() override {
    try {
      display_.PollEvents();
      display_.CheckStillThere();
    } catch (const std::exception& e) {
      return e.what();
    }
    return "";
  }

 private:
  GlfwDisplay display_;
  std::unique_ptr<GlProjectorRenderer> renderer_;
};

// record:DIR or memory rendered on the GPU without a window (EGL, projection/offscreen_gl.h):
// the image read back from the GPU is what is kept and written. Where no EGL context can be
// made it declines the GPU and the CPU's images come through Draw.
class GpuRecordOutput : public RecordOutput {
 public:
  explicit GpuRecordOutput(std::filesystem::path path) : RecordOutput(std::move(path)) {}
  ~GpuRecordOutput() override {
    if (!renderer_) return;
    try {
      context_->MakeCurrent();
      renderer_.reset();
    } catch (const std::exception&) {  // the GL objects go with the context
    }
  }
  bool PrepareGpu(const FramePlanner& planner, int projector) override {
    try {
      const ProjectorGeometry& geometry = planner.rig().projectors[projector].geometry;
      if (renderer_) context_->MakeCurrent();
      renderer_.reset();
      context_ = std::make_unique<OffscreenGl>(geometry.width(), geometry.height());
      renderer_ = std::make_unique<GlProjectorRenderer>(planner, projector);
      return true;
    } catch (const std::exception&) {
      renderer_.reset();
      context_.reset();
      return false;
    }
  }
  void DrawPlan(const FramePlan& plan) override {
    context_->MakeCurrent();
    renderer_->Draw(plan);
    Draw(renderer_->ReadBack());
  }

 private:
  std::unique_ptr<OffscreenGl> context_;
  std::unique_ptr<GlProjectorRenderer> renderer_;
};
#endif

}  // namespace

NodeOutputFactory MakeNodeOutputs(const std::vector<std::string>& display) {
  if (display.empty()) throw std::invalid_argument("--display: give one output per projector");
  for (const std::string& entry : display) {
    const bool known =
        entry == "memory" || entry.starts_with("record:") || entry.starts_with("glfw:");
    if (!known)
      throw std::invalid_argument("--display: '" + entry +
                                  "' is not glfw:MONITOR, record:DIR or memory");
#if !PROCAM_WITH_GLFW
    if (entry.starts_with("glfw:"))
      throw std::invalid_argument("--display " + entry +
                                  ": this procam was built without the GLFW backend");
#endif
  }
  return [display](const std::vector<Projector>& projectors) {
    const bool shared = display.size() == 1 && !display[0].starts_with("glfw:");
    if (!shared && display.size() != projectors.size()) {
      throw std::invalid_argument("--display: " + std::to_string(display.size()) + " outputs for " +
                                  std::to_string(projectors.size()) + " projectors");
    }
    std::vector<std::unique_ptr<NodeOutput>> outputs;
    for (size_t k = 0; k < projectors.size(); ++k) {
      const std::string& entry = shared ? display[0] : display[k];
      if (entry == "memory" || entry.starts_with("record:")) {
        std::filesystem::path path;
        if (entry != "memory") {
          const std::filesystem::path dir = entry.substr(7);
          std::filesystem::create_directories(dir);
          path = dir / (projectors[k].name + ".png");
        }
#if PROCAM_WITH_GLFW
        outputs.push_back(std::make_unique<GpuRecordOutput>(path));
#else
        outputs.push_back(std::make_unique<RecordOutput>(path));
#endif
      } else {
#if PROCAM_WITH_GLFW
        outputs.push_back(std::make_unique<GlfwOutput>(entry.substr(5)));
#endif
      }
    }
    return outputs;
  };
}

}  // namespace procam
