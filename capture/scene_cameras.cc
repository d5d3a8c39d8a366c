#include "capture/scene_cameras.h"

#include <algorithm>
#include <cctype>
#include <limits>
#include <set>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "base/io.h"
#include "base/json_fields.h"
#include "capture/pixel_format.h"

namespace procam {
namespace {

using nlohmann::json;

// The entry keys that set a TestCameraOptions field, in TestCameraOptions::Check's words (its
// messages begin with the key they are about): the format and TestCameraSettings().
std::set<std::string> SettingKeys() {
  std::set<std::string> keys = {"format"};
  for (const TestCameraSetting& setting : TestCameraSettings()) keys.insert(setting.key);
  return keys;
}

bool UsableName(const std::string& name) {
  return !name.empty() && std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
}

SceneCamera ParseSceneCamera(const json& object, const std::string& file, const std::string& prefix,
                             const std::filesystem::path& base, int index) {
  const JsonFields fields(object, file, prefix);
  const std::set<std::string> setting_keys = SettingKeys();
  std::set<std::string> known = setting_keys;
  known.insert({"name", "model"});
  fields.RejectUnknown(known);
  SceneCamera camera;
  camera.name = "camera" + std::to_string(index);
  if (fields.Has("name")) {
    camera.name = fields.String("name");
    if (!UsableName(camera.name)) throw fields.Error("name", "must be letters, digits, '_', '-' or '.'");
  }
  if (!fields.At("model").is_string()) throw fields.Error("model", "must be a path to an mrcal .cameramodel");
  camera.model_path = base / fields.At("model").get<std::string>();
  try {
    camera.model = ReadCameraModelFile(camera.model_path);
    LensModel(camera.model.lens_model, camera.model.intrinsics);  // a lens procam can project with
  } catch (const IoError& error) {
    throw fields.Error("model", error.what());
  } catch (const std::invalid_argument& error) {
    throw fields.Error("model", camera.model_path.string() + ": " + error.what());
  }

  TestCameraOptions& settings = camera.settings;
  settings.name = camera.name;
  settings.width = camera.model.width;
  settings.height = camera.model.height;
  settings.pixel_format = PixelFormat::kBGR8;
  if (fields.Has("format")) {
    const std::string name = fields.String("format");
    const auto format = ParsePixelFormat(name);
    if (!format) throw fields.Error("format", "unknown pixel format '" + name + "'");
    settings.pixel_format = *format;
  }
  for (const TestCameraSetting& setting : TestCameraSettings()) {
    if (!fields.Has(setting.key)) continue;
    if (setting.number) {
      settings.*setting.number = fields.Number(setting.key);
    } else {
      const json& value = fields.At(setting.key);
      if (!value.is_number_integer()) throw fields.Error(setting.key, "must be an integer");
      const long long integer = value.get<long long>();
      if (integer < std::numeric_limits<int>::min() || integer > std::numeric_limits<int>::max())
        throw fields.Error(setting.key, "must be an integer in the int range");
      settings.*setting.integer = static_cast<int>(integer);
    }
  }
  std::string why;
  if (!settings.Check(&why)) {
    const std::string key = why.substr(0, why.find(' '));
    if (setting_keys.count(key)) throw fields.Error(key, why.substr(key.size() + 1));
    throw fields.Error("model", camera.model_path.filename().string() + ": " + why);
  }
  return camera;
}

}  // namespace

std::vector<SceneCamera> ParseSceneCameras(const std::string& cameras_json, const std::string& scene_file,
                                           const std::filesystem::path& base) {
  std::vector<SceneCamera> cameras;
  if (cameras_json.empty()) return cameras;
  json array;
  try {
    array = json::parse(cameras_json);
  } catch (const json::exception&) {
    throw IoError(scene_file + ": cameras: invalid JSON");
  }
  if (!array.is_array()) throw IoError(scene_file + ": cameras: must be an array");
  std::set<std::string> names;
  for (size_t k = 0; k < array.size(); ++k) {
    const std::string prefix = "cameras[" + std::to_string(k) + "]";
    cameras.push_back(ParseSceneCamera(array[k], scene_file, prefix, base, static_cast<int>(k)));
    if (!names.insert(cameras.back().name).second) {
      throw IoError(scene_file + ": " + prefix + ".name: '" + cameras.back().name +
                    "' is already the name of another camera");
    }
  }
  return cameras;
}

}  // namespace procam
