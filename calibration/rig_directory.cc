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
  if (!rig.contains("format_version") || !rig["format_version"].is_number_integer()) {
    throw IoError(path.string() + ": format_version: required key is missing (an integer; written by an older "
                                  "procam? calibrate the rig again)");
  }
  if (rig["format_version"].get<int64_t>() != kRigFormatVersion) {
    throw IoError(path.string() + ": format_version: " + rig["format_version"].dump() +
                  " is not supported (this procam reads version " + std::to_string(kRigFormatVersion) + ")");
  }
  return rig;
}

void UpdateRigJson(const std::filesystem::path& rig_dir,
                   const std::function<void(nlohmann::json&)>& update) {
  nlohmann::json rig = ReadRigJson(rig_dir);
  update(rig);
  rig["format_version"] = kRigFormatVersion;
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

nlohmann::json RigDirectory::Describe() const {
  nlohmann::json names = nlohmann::json::array();
  for (const Projector& projector : projectors) names.push_back(projector.name);
  nlohmann::json description = {{"dir", dir.string()}, {"projectors", names}};
  description["reflectance"] = reflectance.rows() > 0;
  return description;
}

RigDirectory ReadRigDirectory(const std::filesystem::path& rig_dir) {
  const std::filesystem::path path = rig_dir / "rig.json";
  const std::string file = path.string();
  if (!std::filesystem::is_directory(rig_dir)) {
    throw IoError(rig_dir.string() + ": not a directory (--rig takes a rig directory)");
  }
  if (!std::filesystem::exists(path)) {
    throw IoError(file + ": file not found (the rig directory's rig.json, written by procam "
                         "calibrate)");
  }
  RigDirectory rig;
  rig.dir = rig_dir;
  rig.json = ReadRigJson(rig_dir);
  if (!rig.json.contains("projectors") || !rig.json["projectors"].is_array() ||
      rig.json["projectors"].empty()) {
    throw IoError(file + ": projectors: required key is missing (a non-empty array, run procam "
                         "calibrate projectors and calibrate photometric)");
  }
  // Photometry still in camera units cannot light a scene: say so before the parser's plainer
  // "max: required key is missing".
  const nlohmann::json& photometric = rig.json.value("photometric", nlohmann::json::object());
  const nlohmann::json& entries = rig.json["projectors"];
  for (size_t k = 0; k < entries.size(); ++k) {
    if (!entries[k].is_object() || !entries[k].contains("name") || !entries[k]["name"].is_string())
      continue;
    const std::string name = entries[k]["name"].get<std::string>();
    if (!photometric.is_object() || !photometric.contains(name)) continue;
    const nlohmann::json& info = photometric[name];
    if (info.is_object() && info.value("units", "") == "camera" && !entries[k].contains("max")) {
      throw IoError(file + ": projectors[" + std::to_string(k) + "].max: the photometry of '" +
                    name +
                    "' is in camera units (photometric." + name +
                    ".units); compensate needs scene units: run procam calibrate photometric "
                    "with --scene once the projector's geometry and the camera's registration "
                    "are in the rig");
    }
  }
  rig.projectors = ParseProjectors(entries.dump(), file, rig_dir);

  if (rig.json.contains("reflectance")) {
    const nlohmann::json& info = rig.json["reflectance"];
    if (!info.is_object() || !info.contains("file") || !info["file"].is_string()) {
      throw IoError(file + ": reflectance.file: required key is missing (a .npy file)");
    }
    if (!info.contains("target_patches") || !info["target_patches"].is_number_integer()) {
      throw IoError(file + ": reflectance.target_patches: required key is missing (an integer)");
    }
    const std::filesystem::path npy = rig_dir / info["file"].get<std::string>();
    if (!std::filesystem::exists(npy)) {
      throw IoError(file + ": reflectance.file: " + npy.string() + ": file not found");
    }
    const NpyArray array = ReadNpy(npy);
    if (array.shape.size() != 2 || array.shape[1] != 3 || array.shape[0] < 1) {
      throw IoError(npy.string() + ": expected shape (n,3)");
    }
    rig.reflectance.resize(array.shape[0], 3);
    for (int64_t i = 0; i < array.shape[0]; ++i) {
      for (int c = 0; c < 3; ++c) {
        const double value = array.values[3 * i + c];
        if (!(value >= 0.0 && value < 1.0)) {
          throw IoError(npy.string() + ": row " + std::to_string(i) +
                        ": reflectance must be in [0,1)");
        }
        rig.reflectance(i, c) = value;
      }
    }
    rig.reflectance_target_patches = info["target_patches"].get<int>();
  }
  return rig;
}

void ApplyRigReflectance(const RigDirectory& rig, PatchHierarchy* patches) {
  if (rig.reflectance.rows() == 0) return;
  const int n = patches->fine.size();
  if (rig.reflectance.rows() != n) {
    throw IoError((rig.dir / "rig.json").string() + ": reflectance: estimated for " +
                  std::to_string(rig.reflectance.rows()) + " patches (target " +
                  std::to_string(rig.reflectance_target_patches) + "), this run has " +
                  std::to_string(n) + ": give --patches " +
                  std::to_string(rig.reflectance_target_patches));
  }
  patches->fine.reflectance = rig.reflectance;
  patches->coarse.reflectance = CoarsenPatchValues(rig.reflectance, patches->fine.Areas(),
                                              patches->coarse_of_fine, patches->coarse.size());
}

SolutionProjectors ProjectorsForSolution(const SolutionDirectory& solution, const std::filesystem::path& rig_dir,
                                         const Scene& scene, PatchHierarchy* patches) {
  SolutionProjectors result;
  const std::filesystem::path dir = rig_dir.empty() ? solution.rig_dir : rig_dir;
  if (dir.empty()) {
    result.projectors = ReadProjectors(scene);
    return result;
  }
  const RigDirectory rig = ReadRigDirectory(dir);
  ApplyRigReflectance(rig, patches);
  result.projectors = rig.projectors;
  result.rig_description = rig.Describe();
  return result;
}

}  // namespace procam
