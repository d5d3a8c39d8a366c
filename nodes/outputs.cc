#include "nodes/outputs.h"

#include <stdexcept>

#include "procam/config.h"
#if PROCAM_WITH_GLFW
#include "projection/glfw_display.h"
#endif

namespace procam {
namespace {

#if PROCAM_WITH_GLFW
// A projector's fullscreen window.
class GlfwOutput : public NodeOutput {
 public:
  explicit GlfwOutput(const std::string& monitor) : display_(FindMonitor(monitor)) {}
  std::string Describe() const override { return display_.Name(); }
  void Draw(const ProjectorImage& image) override { image_ = image; }
  void Present(uint64_t) override { display_.Show(image_); }
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
  ProjectorImage image_;
};
#endif

}  // namespace

NodeOutputFactory MakeNodeOutputs(const std::vector<std::string>& display) {
  if (display.empty()) throw std::invalid_argument("--display: give one output per projector");
  for (const std::string& entry : display) {
    const bool known = entry == "memory" || entry.starts_with("record:") || entry.starts_with("glfw:");
    if (!known) throw std::invalid_argument("--display: '" + entry + "' is not glfw:MONITOR, record:DIR or memory");
#if !PROCAM_WITH_GLFW
    if (entry.starts_with("glfw:"))
      throw std::invalid_argument("--display " + entry + ": this procam was built without the GLFW backend");
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
      if (entry == "memory") {
        outputs.push_back(std::make_unique<RecordOutput>());
      } else if (entry.starts_with("record:")) {
        const std::filesystem::path dir = entry.substr(7);
        std::filesystem::create_directories(dir);
        outputs.push_back(std::make_unique<RecordOutput>(dir / (projectors[k].name + ".png")));
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
