#pragma once
// Reading one JSON object of a human-written file (scenes, projectors) with every problem
// reported as one line "file: key.path: what" (an IoError), so that users can find it.

#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "base/io.h"

namespace procam {

// The JSON document in `path`. Throws IoError naming the file: missing, unreadable, or not JSON
// ("line 3, column 7: invalid JSON: ...").
nlohmann::json ReadJsonFile(const std::filesystem::path& path);

class JsonFields {
 public:
  // `object` must outlive this reader; `prefix` is the object's key path ("surfaces[2]").
  // Throws if `object` is not a JSON object.
  JsonFields(const nlohmann::json& object, std::string file, std::string prefix);

  // The error for `key` of this object ("" for the object itself).
  IoError Error(const std::string& key, const std::string& what) const;
  // "prefix.key".
  std::string Path(const std::string& key) const;
  const std::string& prefix() const { return prefix_; }

  bool Has(const std::string& key) const { return object_.contains(key); }
  // The value of a required key.
  const nlohmann::json& At(const std::string& key) const;
  // Rejects keys outside `known`, listing the known ones.
  void RejectUnknown(const std::set<std::string>& known) const;

  // A finite number (the value of `key`, or `value` reported as `key`).
  double Number(const std::string& key) const;
  double Number(const std::string& key, const nlohmann::json& value) const;
  // An array of finite numbers.
  std::vector<double> Numbers(const std::string& key, const nlohmann::json& value) const;
  // Exactly three finite numbers.
  Eigen::Vector3d Triple(const std::string& key, const nlohmann::json& value) const;
  // A number (all channels equal) or an RGB triplet.
  Eigen::Vector3d NumberOrRgb(const std::string& key) const;
  std::string String(const std::string& key) const;

 private:
  const nlohmann::json& object_;
  std::string file_;
  std::string prefix_;
};

// [x, y, z], as every file writes a triple.
inline nlohmann::json JsonTriple(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

}  // namespace procam
