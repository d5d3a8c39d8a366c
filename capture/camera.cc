#include "capture/camera.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <mutex>
#include <sstream>
#include <thread>

#include "base/option_table.h"
#include "capture/test_camera.h"
#include "procam/config.h"

namespace procam {

void ListCamerasOptions::Declare(OptionTable* table) {
  table->NegatedFlag("no-gige", &gige_discovery,
                     "Skip GigE Vision discovery (it broadcasts on every network interface)");
  table->Flag("virtual", &include_virtual,
              "Also list virtual cameras (Aravis Fake_1, test:, synthetic:<scene>)");
}
namespace {

struct Registry {
  std::mutex mutex;
  std::map<std::string, CameraBackend> backends;
};

Registry& TheRegistry() {
  static Registry* registry = [] {
    auto* created = new Registry;  // never destroyed: backends may be used during exit
    CameraBackend test = TestCameraBackend();
    created->backends.emplace(test.scheme, std::move(test));
    return created;
  }();
  return *registry;
}

// Why a scheme has no backend, in one line.
std::string MissingBackendMessage(const std::string& scheme, const std::string& uri) {
  const std::string head = "camera '" + uri + "': ";
  auto built_but_unregistered = [&](const char* name) {
    return head + "the " + std::string(name) +
           " backend is built but not registered (call RegisterDeviceBackends() from "
           "capture/devices.h)";
  };
  if (scheme == "v4l2") {
    if (PROCAM_WITH_V4L2) return built_but_unregistered("V4L2");
    return head +
           "this procam was built without the V4L2 backend (install libv4l-dev and reconfigure "
           "with -DPROCAM_WITH_V4L2=ON)";
  }
  if (scheme == "aravis") {
    if (PROCAM_WITH_ARAVIS) return built_but_unregistered("Aravis");
    return head +
           "this procam was built without the Aravis backend (install libaravis-dev "
           "libusb-1.0-0-dev and reconfigure with -DPROCAM_WITH_ARAVIS=ON)";
  }
  if (scheme == "synthetic") {
    return head +
           "the simulated camera backend 'synthetic' is not available in this program "
           "(RegisterSyntheticCameraBackend() of datasets_synthetic/synthetic_camera.h registers "
           "it; procam does); use 'test:' for the software test camera";
  }
  std::string known;
  for (const std::string& name : RegisteredCameraBackends())
    known += (known.empty() ? "" : ", ") + name;
  return head + "unknown camera backend '" + scheme + "' (known: " + known +
         ", v4l2, aravis, synthetic)";
}

}  // namespace

int64_t SteadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

void SleepUntil(int64_t steady_ns) {
  const int64_t wait = steady_ns - SteadyNowNs();
  if (wait > 0) std::this_thread::sleep_for(std::chrono::nanoseconds(wait));
}

int64_t MsToNs(double ms) { return static_cast<int64_t>(std::llround(ms * 1e6)); }

CameraUri CameraUri::Parse(const std::string& text) {
  CameraUri uri;
  uri.text_ = text;
  const size_t colon = text.find(':');
  if (colon == std::string::npos || colon == 0) {
    throw IoError(
        "camera '" + text +
        "': expected <backend>:<device>, e.g. v4l2:/dev/video0, aravis:Fake_1, test:loopback");
  }
  uri.scheme_ = text.substr(0, colon);
  for (char c : uri.scheme_) {
    if (!std::islower(static_cast<unsigned char>(c)) &&
        !std::isdigit(static_cast<unsigned char>(c)) && c != '_') {
      throw IoError("camera '" + text + "': backend name '" + uri.scheme_ +
                    "' must be lower-case letters, digits or _");
    }
  }
  const size_t question = text.find('?', colon + 1);
  uri.path_ = text.substr(colon + 1,
                          question == std::string::npos ? std::string::npos : question - colon - 1);
  if (question == std::string::npos) return uri;
  std::stringstream query(text.substr(question + 1));
  std::string pair;
  while (std::getline(query, pair, '&')) {
    if (pair.empty()) continue;
    const size_t equals = pair.find('=');
    if (equals == std::string::npos || equals == 0) {
      throw IoError("camera '" + text + "': parameter '" + pair + "' is not key=value");
    }
    const std::string key = pair.substr(0, equals);
    if (uri.params_.count(key))
      throw IoError("camera '" + text + "': parameter '" + key + "' given twice");
    uri.params_[key] = pair.substr(equals + 1);
  }
  return uri;
}

std::string CameraUri::GetString(const std::string& key, const std::string& fallback) const {
  const auto found = params_.find(key);
  if (found == params_.end()) return fallback;
  read_[key] = true;
  return found->second;
}

double CameraUri::GetDouble(const std::string& key, double fallback) const {
  const auto found = params_.find(key);
  if (found == params_.end()) return fallback;
  read_[key] = true;
  size_t used = 0;
  double value = 0.0;
  try {
    value = std::stod(found->second, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != found->second.size() || !std::isfinite(value)) {
    throw IoError("camera '" + text_ + "': " + key + "=" + found->second + " is not a number");
  }
  return value;
}

int CameraUri::GetInt(const std::string& key, int fallback) const {
  const double value = GetDouble(key, fallback);
  if (value != std::floor(value) || std::abs(value) > 2e9) {
    throw IoError("camera '" + text_ + "': " + key + "=" + params_.at(key) + " is not an integer");
  }
  return static_cast<int>(value);
}

void CameraUri::CheckAllRead() const {
  for (const auto& [key, value] : params_) {
    if (!read_.count(key))
      throw IoError("camera '" + text_ + "': unknown parameter '" + key + "' for backend " +
                    scheme_);
  }
}

void RegisterCameraBackend(CameraBackend backend) {
  Registry& registry = TheRegistry();
  std::lock_guard<std::mutex> lock(registry.mutex);
  const std::string scheme = backend.scheme;
  registry.backends[scheme] = std::move(backend);
}

std::vector<std::string> RegisteredCameraBackends() {
  Registry& registry = TheRegistry();
  std::lock_guard<std::mutex> lock(registry.mutex);
  std::vector<std::string> schemes;
  for (const auto& [scheme, backend] : registry.backends) schemes.push_back(scheme);
  return schemes;
}

std::unique_ptr<Camera> OpenCamera(const std::string& text, const OpenCameraOptions& options) {
  const CameraUri uri = CameraUri::Parse(text);
  CameraBackend backend;
  {
    Registry& registry = TheRegistry();
    std::lock_guard<std::mutex> lock(registry.mutex);
    const auto found = registry.backends.find(uri.scheme());
    if (found != registry.backends.end()) backend = found->second;
  }
  if (!backend.open) throw IoError(MissingBackendMessage(uri.scheme(), text));
  return backend.open(uri, options);
}

std::vector<CameraInfo> ListCameras(const ListCamerasOptions& options) {
  std::vector<CameraBackend> backends;
  {
    Registry& registry = TheRegistry();
    std::lock_guard<std::mutex> lock(registry.mutex);
    for (const auto& [scheme, backend] : registry.backends) backends.push_back(backend);
  }
  std::vector<CameraInfo> cameras;
  for (const CameraBackend& backend : backends) {
    if (!backend.list) continue;
    try {
      for (CameraInfo& info : backend.list(options)) cameras.push_back(std::move(info));
    } catch (const std::exception& error) {
      CameraInfo failure;
      failure.backend = backend.scheme;
      failure.description = std::string("listing failed: ") + error.what();
      cameras.push_back(failure);
    }
  }
  return cameras;
}

}  // namespace procam
