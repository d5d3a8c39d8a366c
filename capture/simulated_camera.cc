#include "capture/simulated_camera.h"

#include <map>
#include <mutex>

#include "base/json_fields.h"
#include "capture/camera.h"

namespace procam {
namespace {

struct SimulatedCameraSources {
  std::mutex mutex;
  std::map<std::string, SimulatedCameraSource> sources;
};
SimulatedCameraSources& SimulatedSources() {
  static SimulatedCameraSources sources;
  return sources;
}

}  // namespace

std::optional<SimulatedCamera> FindSimulatedCamera(const std::string& text) {
  const CameraUri uri = CameraUri::Parse(text);
  SimulatedCameraSource source;
  {
    SimulatedCameraSources& registry = SimulatedSources();
    const std::lock_guard<std::mutex> lock(registry.mutex);
    const auto found = registry.sources.find(uri.scheme());
    if (found == registry.sources.end()) return std::nullopt;
    source = found->second;
  }
  return source(text);
}

void RegisterSimulatedCameraSource(const std::string& scheme, SimulatedCameraSource source) {
  SimulatedCameraSources& registry = SimulatedSources();
  const std::lock_guard<std::mutex> lock(registry.mutex);
  registry.sources[scheme] = std::move(source);
}

nlohmann::json CameraColour::Json() const {
  nlohmann::json m = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) m.push_back(JsonTriple(to_exitance.row(r).transpose()));
  return {{"to_exitance", m}, {"black", black}, {"source", source}};
}

CameraColour SimulatedColour(const SimulatedCamera& camera, const nlohmann::json& manifest, bool hdr,
                             double full_scale, double black_override) {
  const double black = black_override >= 0 ? black_override : camera.black_level;
  CameraColour colour;
  colour.black = hdr ? 0.0 : black;
  colour.to_exitance = camera.value_per_exitance(manifest, hdr, full_scale, black).cwiseInverse().asDiagonal();
  colour.source = "simulated camera: " + camera.description;
  return colour;
}

}  // namespace procam
