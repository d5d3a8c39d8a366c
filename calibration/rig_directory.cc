#include "calibration/rig_directory.h"

#include <fstream>
#include <sstream>

#include "base/io.h"

namespace procam {

nlohmann::json ReadRigJson(const std::filesystem::path& rig_dir) {
  const std::filesystem::path path = rig_dir / "rig.json";
  if (!std::filesystem::exists(path)) return nlohmann::json::object();
  std::ifstream in(path);
  if (!in) throw IoError(path.string() + ": cannot open");
  std::stringstream text;
  text << in.rdbuf();
  nlohmann::json rig = nlohmann::json::parse(text.str(), nullptr, /*allow_exceptions=*/false);
  if (rig.is_discarded()) throw IoError(path.string() + ": not valid JSON");
  if (!rig.is_object()) throw IoError(path.string() + ": expected a JSON object");
  return rig;
}

void UpdateRigJson(const std::filesystem::path& rig_dir,
                   const std::function<void(nlohmann::json&)>& update) {
  nlohmann::json rig = ReadRigJson(rig_dir);
  update(rig);
  std::filesystem::create_directories(rig_dir);
  WriteFileAtomically(rig_dir / "rig.json", rig.dump(2) + "\n");
}

void UpdateRigResult(const std::filesystem::path& rig_dir, const std::vector<std::string>& path,
                     const nlohmann::json& section) {
  nlohmann::json result = nlohmann::json::object();
  const std::filesystem::path file = rig_dir / "result.json";
  if (std::filesystem::exists(file)) {
    std::ifstream in(file);
    std::stringstream text;
    text << in.rdbuf();
    result = nlohmann::json::parse(text.str(), nullptr, /*allow_exceptions=*/false);
    if (!result.is_object()) result = nlohmann::json::object();
  }
  nlohmann::json* node = &result;
  for (const std::string& key : path) {
    if (!(*node)[key].is_object()) (*node)[key] = nlohmann::json::object();
    node = &(*node)[key];
  }
  *node = section;
  std::filesystem::create_directories(rig_dir);
  WriteFileAtomically(file, result.dump(2) + "\n");
}

nlohmann::json& RigProjectorEntry(nlohmann::json& rig, const std::string& name) {
  nlohmann::json& projectors = rig["projectors"];
  if (!projectors.is_array()) projectors = nlohmann::json::array();
  for (nlohmann::json& entry : projectors) {
    if (entry.is_object() && entry.value("name", "") == name) return entry;
  }
  projectors.push_back({{"name", name}});
  return projectors.back();
}

}  // namespace procam
