#include "base/json_fields.h"

#include <algorithm>
#include <cmath>

namespace procam {

using nlohmann::json;

namespace {

std::string SyntaxErrorWithLine(const std::string& text, const json::parse_error& error) {
  size_t line = 1, column = 1;
  const size_t end = std::min(text.size(), error.byte > 0 ? error.byte - 1 : 0);
  for (size_t k = 0; k < end; ++k) {
    if (text[k] == '\n') {
      ++line;
      column = 1;
    } else {
      ++column;
    }
  }
  std::string what = error.what();
  const size_t colon = what.rfind(": ");
  if (colon != std::string::npos) what = what.substr(colon + 2);
  return "line " + std::to_string(line) + ", column " + std::to_string(column) +
         ": invalid JSON: " + what;
}

}  // namespace

json ReadJsonFile(const std::filesystem::path& path) {
  const std::string file = path.string();
  constexpr uintmax_t kMaxJsonBytes = uintmax_t{1} << 30;  // scenes, rig.json, result.json
  const std::string text = ReadFile(path, kMaxJsonBytes);
  try {
    return json::parse(text);
  } catch (const json::parse_error& error) {
    throw IoError(file + ": " + SyntaxErrorWithLine(text, error));
  } catch (const json::exception& error) {  // e.g. a number too large for a double
    const std::string what = error.what();
    throw IoError(file + ": invalid JSON: " + what.substr(what.find(']') + 2));
  }
}

JsonFields::JsonFields(const json& object, std::string file, std::string prefix)
    : object_(object), file_(std::move(file)), prefix_(std::move(prefix)) {
  if (!object_.is_object()) throw Error("", "must be an object");
}

IoError JsonFields::Error(const std::string& key, const std::string& what) const {
  const std::string where = key.empty() ? prefix_ : Path(key);
  return IoError(file_ + ": " + (where.empty() ? "" : where + ": ") + what);
}

std::string JsonFields::Path(const std::string& key) const {
  return prefix_.empty() ? key : prefix_ + "." + key;
}

const json& JsonFields::At(const std::string& key) const {
  if (!Has(key)) throw Error(key, "required key is missing");
  return object_.at(key);
}

void JsonFields::RejectUnknown(const std::set<std::string>& known) const {
  for (const auto& item : object_.items()) {
    if (known.count(item.key()) == 0) {
      std::string list;
      for (const auto& name : known) list += (list.empty() ? "" : ", ") + name;
      throw Error(item.key(), "unknown key (known keys: " + list + ")");
    }
  }
}

double JsonFields::Number(const std::string& key) const { return Number(key, At(key)); }

double JsonFields::Number(const std::string& key, const json& value) const {
  if (!value.is_number()) throw Error(key, "must be a number");
  const double number = value.get<double>();
  if (!std::isfinite(number)) throw Error(key, "must be finite");
  return number;
}

std::vector<double> JsonFields::Numbers(const std::string& key, const json& value) const {
  if (!value.is_array()) throw Error(key, "must be an array of numbers");
  std::vector<double> numbers;
  for (const json& item : value) numbers.push_back(Number(key, item));
  return numbers;
}

Eigen::Vector3d JsonFields::Triple(const std::string& key, const json& value) const {
  if (!value.is_array() || value.size() != 3) throw Error(key, "must be an array of 3 numbers");
  Eigen::Vector3d triple;
  for (int c = 0; c < 3; ++c) triple[c] = Number(key + "[" + std::to_string(c) + "]", value[c]);
  return triple;
}

Eigen::Vector3d JsonFields::NumberOrRgb(const std::string& key) const {
  const json& value = At(key);
  if (value.is_number()) return Eigen::Vector3d::Constant(Number(key, value));
  if (!value.is_array() || value.size() != 3) throw Error(key, "must be a number or an RGB triplet");
  return Triple(key, value);
}

std::string JsonFields::String(const std::string& key) const {
  const json& value = At(key);
  if (!value.is_string()) throw Error(key, "must be a string");
  return value.get<std::string>();
}

}  // namespace procam
