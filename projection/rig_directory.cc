#include "projection/rig_directory.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <numbers>
#include <optional>
#include <sstream>

#include "base/io.h"
#include "base/json_fields.h"
#include "projection/reflectance_map.h"

namespace procam {

namespace {

using nlohmann::json;

std::string OptionalString(const JsonFields& fields, const std::string& key) {
  return fields.Has(key) ? fields.String(key) : std::string();
}

std::optional<Eigen::Vector3d> OptionalRgb(const JsonFields& fields, const std::string& key) {
  if (!fields.Has(key)) return std::nullopt;
  return fields.NumberOrRgb(key);
}

int Integer(const JsonFields& fields, const std::string& key) {
  const json& value = fields.At(key);
  if (!value.is_number_integer() || value.get<int64_t>() < 0 || value.get<int64_t>() > (1 << 30))
    throw fields.Error(key, "must be a non-negative integer");
  return static_cast<int>(value.get<int64_t>());
}

Eigen::Matrix3d Matrix3(const JsonFields& fields, const std::string& key) {
  const json& value = fields.At(key);
  if (!value.is_array() || value.size() != 3)
    throw fields.Error(key, "must be 3 rows of 3 numbers");
  Eigen::Matrix3d matrix;
  for (int r = 0; r < 3; ++r)
    matrix.row(r) = fields.Triple(key + "[" + std::to_string(r) + "]", value[r]).transpose();
  return matrix;
}

json JsonMatrix(const Eigen::Matrix3d& m) {
  json rows = json::array();
  for (int r = 0; r < 3; ++r) rows.push_back(JsonTriple(m.row(r).transpose()));
  return rows;
}

RigCamera ReadCamera(const json& object, const std::string& file) {
  const JsonFields fields(object, file, "camera");
  fields.RejectUnknown({"model", "response", "colour"});
  RigCamera camera;
  camera.model = OptionalString(fields, "model");
  camera.response = OptionalString(fields, "response");
  if (!fields.Has("colour")) return camera;
  const JsonFields colour_fields(fields.At("colour"), file, "camera.colour");
  colour_fields.RejectUnknown({"scale", "matrix", "black"});
  if (colour_fields.Has("scale") == colour_fields.Has("matrix")) {
    throw colour_fields.Error("",
                              "give one of scale (camera value per unit exitance, [R,G,B]) "
                              "and matrix (camera RGB → exitance, 3×3)");
  }
  RigCameraColour colour;
  if (colour_fields.Has("scale")) {
    colour.scale = colour_fields.NumberOrRgb("scale");
    if (!(colour.scale->minCoeff() > 0.0))
      throw colour_fields.Error("scale", "three positive numbers (camera value per unit exitance)");
  } else {
    colour.matrix = Matrix3(colour_fields, "matrix");
    if (!(std::abs(colour.matrix->determinant()) > 1e-300))
      throw colour_fields.Error("matrix", "singular (camera RGB → exitance)");
  }
  if (colour_fields.Has("black")) colour.black = colour_fields.Number("black");
  camera.colour = colour;
  return camera;
}

json CameraJson(const RigCamera& camera) {
  json object = json::object();
  if (!camera.model.empty()) object["model"] = camera.model;
  if (!camera.response.empty()) object["response"] = camera.response;
  if (camera.colour) {
    json colour = json::object();
    if (camera.colour->scale) colour["scale"] = JsonTriple(*camera.colour->scale);
    if (camera.colour->matrix) colour["matrix"] = JsonMatrix(*camera.colour->matrix);
    if (camera.colour->black) colour["black"] = *camera.colour->black;
    object["colour"] = colour;
  }
  return object;
}

RigProjector ReadProjector(const json& object, const std::string& file, size_t index) {
  const JsonFields fields(object, file, "projectors[" + std::to_string(index) + "]");
  fields.RejectUnknown({"name", "model", "black", "max", "gamma", "lut", "mixing", "bits"});
  RigProjector projector;
  projector.name = fields.String("name");
  projector.model = OptionalString(fields, "model");
  projector.black = OptionalRgb(fields, "black");
  projector.max = OptionalRgb(fields, "max");
  projector.response = json::object();
  for (const char* key : {"gamma", "lut"}) {
    if (fields.Has(key)) projector.response[key] = fields.At(key);
  }
  if (fields.Has("mixing")) projector.mixing = Matrix3(fields, "mixing");
  if (fields.Has("bits")) projector.bits = Integer(fields, "bits");
  return projector;
}

json ProjectorJson(const RigProjector& projector) {
  json object = {{"name", projector.name}};
  if (!projector.model.empty()) object["model"] = projector.model;
  if (projector.black) object["black"] = JsonTriple(*projector.black);
  if (projector.max) object["max"] = JsonTriple(*projector.max);
  if (projector.response.is_object()) object.update(projector.response);
  if (projector.mixing) object["mixing"] = JsonMatrix(*projector.mixing);
  if (projector.bits) object["bits"] = *projector.bits;
  return object;
}

RigPhotometry ReadPhotometry(const json& object, const std::string& file, const std::string& name) {
  const JsonFields fields(object, file, "photometric." + name);
  fields.RejectUnknown({"units", "session", "scene", "camera_scale", "camera_black"});
  RigPhotometry photometry;
  photometry.units = fields.String("units");
  if (photometry.units != "scene" && photometry.units != "camera")
    throw fields.Error("units", "must be \"scene\" or \"camera\"");
  photometry.session = OptionalString(fields, "session");
  photometry.scene = OptionalString(fields, "scene");
  photometry.camera_scale = OptionalRgb(fields, "camera_scale");
  if (fields.Has("camera_black")) photometry.camera_black = fields.Number("camera_black");
  return photometry;
}

json PhotometryJson(const RigPhotometry& photometry) {
  json object = {{"units", photometry.units}};
  if (!photometry.session.empty()) object["session"] = photometry.session;
  if (!photometry.scene.empty()) object["scene"] = photometry.scene;
  if (photometry.camera_scale) object["camera_scale"] = JsonTriple(*photometry.camera_scale);
  if (photometry.units == "scene") object["camera_black"] = photometry.camera_black;
  return object;
}

RigReflectance ReadReflectance(const json& object, const std::string& file) {
  const JsonFields fields(object, file, "reflectance");
  fields.RejectUnknown({"file", "target_patches", "projector", "scene", "patches", "patches_seen"});
  RigReflectance reflectance;
  reflectance.file = fields.String("file");
  reflectance.target_patches = Integer(fields, "target_patches");
  reflectance.projector = OptionalString(fields, "projector");
  reflectance.scene = OptionalString(fields, "scene");
  if (fields.Has("patches")) reflectance.patches = Integer(fields, "patches");
  if (fields.Has("patches_seen")) reflectance.patches_seen = Integer(fields, "patches_seen");
  return reflectance;
}

json ReflectanceJson(const RigReflectance& reflectance) {
  return {{"file", reflectance.file},           {"target_patches", reflectance.target_patches},
          {"projector", reflectance.projector}, {"scene", reflectance.scene},
          {"patches", reflectance.patches},     {"patches_seen", reflectance.patches_seen}};
}

RigReflectanceMap ReadReflectanceMapEntry(const json& object, const std::string& file,
                                          const std::string& name) {
  const JsonFields fields(object, file, "reflectance_maps." + name);
  fields.RejectUnknown(
      {"file", "width", "height", "target_patches", "lit_pixels", "measured_pixels"});
  RigReflectanceMap entry;
  entry.file = fields.String("file");
  entry.width = Integer(fields, "width");
  entry.height = Integer(fields, "height");
  if (entry.width < 1 || entry.height < 1)
    throw fields.Error("width", "width and height must be >= 1");
  entry.target_patches = Integer(fields, "target_patches");
  if (fields.Has("lit_pixels")) entry.lit_pixels = Integer(fields, "lit_pixels");
  if (fields.Has("measured_pixels")) entry.measured_pixels = Integer(fields, "measured_pixels");
  return entry;
}

json ReflectanceMapJson(const RigReflectanceMap& entry) {
  return {{"file", entry.file},
          {"width", entry.width},
          {"height", entry.height},
          {"target_patches", entry.target_patches},
          {"lit_pixels", entry.lit_pixels},
          {"measured_pixels", entry.measured_pixels}};
}

}  // namespace

RigProjector& RigFile::Projector(const std::string& name) {
  for (RigProjector& projector : projectors) {
    if (projector.name == name) return projector;
  }
  projectors.push_back(RigProjector{});
  projectors.back().name = name;
  projectors.back().response = json::object();
  return projectors.back();
}

json RigFile::ProjectorsJson() const {
  json entries = json::array();
  for (const RigProjector& projector : projectors) entries.push_back(ProjectorJson(projector));
  return entries;
}

RigFile ReadRigFile(const std::filesystem::path& rig_dir) {
  const std::filesystem::path path = rig_dir / "rig.json";
  const std::string file = path.string();
  RigFile rig;
  if (!std::filesystem::exists(path)) return rig;
  const json object = ReadJsonFile(path);
  const JsonFields fields(object, file, "");
  fields.RejectUnknown({"format_version", "camera", "projectors", "registration", "photometric",
                        "reflectance", "reflectance_maps"});
  if (!fields.Has("format_version") || !object["format_version"].is_number_integer()) {
    throw fields.Error("format_version",
                       "required key is missing (an integer; written by an older procam? "
                       "calibrate the rig again)");
  }
  if (object["format_version"].get<int64_t>() != kRigFormatVersion) {
    throw fields.Error("format_version", object["format_version"].dump() +
                                             " is not supported (this procam reads version " +
                                             std::to_string(kRigFormatVersion) + ")");
  }
  if (fields.Has("camera")) rig.camera = ReadCamera(object["camera"], file);
  if (fields.Has("projectors")) {
    const json& entries = object["projectors"];
    if (!entries.is_array()) throw fields.Error("projectors", "must be an array");
    for (size_t k = 0; k < entries.size(); ++k) {
      rig.projectors.push_back(ReadProjector(entries[k], file, k));
      for (size_t j = 0; j < k; ++j) {
        if (rig.projectors[j].name == rig.projectors[k].name)
          throw fields.Error("projectors[" + std::to_string(k) + "].name",
                             "'" + rig.projectors[k].name + "' appears twice");
      }
    }
  }
  if (fields.Has("registration")) {
    if (!object["registration"].is_object())
      throw fields.Error("registration", "must be an object");
    rig.registration = object["registration"];
  }
  if (fields.Has("photometric")) {
    const JsonFields photometric(object["photometric"], file, "photometric");
    for (const auto& item : object["photometric"].items())
      rig.photometric[item.key()] = ReadPhotometry(item.value(), file, item.key());
  }
  if (fields.Has("reflectance")) rig.reflectance = ReadReflectance(object["reflectance"], file);
  if (fields.Has("reflectance_maps")) {
    const JsonFields maps(object["reflectance_maps"], file, "reflectance_maps");
    for (const auto& item : object["reflectance_maps"].items()) {
      rig.reflectance_maps[item.key()] = ReadReflectanceMapEntry(item.value(), file, item.key());
    }
  }
  return rig;
}

void WriteRigFile(const std::filesystem::path& rig_dir, const RigFile& rig) {
  json object = {{"format_version", kRigFormatVersion}, {"camera", CameraJson(rig.camera)}};
  object["projectors"] = rig.ProjectorsJson();
  if (!rig.registration.is_null()) object["registration"] = rig.registration;
  if (!rig.photometric.empty()) {
    json photometric = json::object();
    for (const auto& [name, entry] : rig.photometric) photometric[name] = PhotometryJson(entry);
    object["photometric"] = photometric;
  }
  if (rig.reflectance) object["reflectance"] = ReflectanceJson(*rig.reflectance);
  if (!rig.reflectance_maps.empty()) {
    json maps = json::object();
    for (const auto& [name, entry] : rig.reflectance_maps) maps[name] = ReflectanceMapJson(entry);
    object["reflectance_maps"] = maps;
  }
  std::filesystem::create_directories(rig_dir);
  WriteFileAtomically(rig_dir / "rig.json", object.dump(2) + "\n");
}

void UpdateRigFile(const std::filesystem::path& rig_dir,
                   const std::function<void(RigFile&)>& update) {
  RigFile rig = ReadRigFile(rig_dir);
  update(rig);
  WriteRigFile(rig_dir, rig);
}

nlohmann::json ReadRigResult(const std::filesystem::path& rig_dir) {
  nlohmann::json result = nlohmann::json::object();
  const std::filesystem::path file = rig_dir / "result.json";
  if (std::filesystem::exists(file)) {
    std::ifstream in(file);
    std::stringstream text;
    text << in.rdbuf();
    result = nlohmann::json::parse(text.str(), nullptr, /*allow_exceptions=*/false);
    if (!result.is_object()) result = nlohmann::json::object();
  }
  return result;
}

void UpdateRigResult(const std::filesystem::path& rig_dir, const std::vector<std::string>& path,
                     const nlohmann::json& section) {
  nlohmann::json result = ReadRigResult(rig_dir);
  const std::filesystem::path file = rig_dir / "result.json";
  nlohmann::json* node = &result;
  for (const std::string& key : path) {
    if (!(*node)[key].is_object()) (*node)[key] = nlohmann::json::object();
    node = &(*node)[key];
  }
  *node = section;
  std::filesystem::create_directories(rig_dir);
  WriteFileAtomically(file, result.dump(2) + "\n");
}

nlohmann::json RigDirectory::Describe() const {
  nlohmann::json names = nlohmann::json::array();
  for (const Projector& projector : projectors) names.push_back(projector.name);
  // Absolute: a solution or run that records it is read from other working directories.
  nlohmann::json description = {{"dir", std::filesystem::absolute(dir).lexically_normal().string()},
                                {"projectors", names}};
  description["reflectance"] = reflectance.rows() > 0;
  return description;
}

namespace {

// registration[key] as a triple of numbers, if it is one.
std::optional<Vec3> RecordedTriple(const nlohmann::json& record, const char* key) {
  if (!record.is_object() || !record.contains(key)) return std::nullopt;
  const nlohmann::json& value = record[key];
  if (!value.is_array() || value.size() != 3) return std::nullopt;
  Vec3 triple;
  for (int c = 0; c < 3; ++c) {
    if (!value[c].is_number()) return std::nullopt;
    triple[c] = value[c].get<double>();
  }
  return triple;
}

// record[key] as an image size [width, height], if it is one.
std::optional<std::array<int, 2>> RecordedSize(const nlohmann::json& record, const char* key) {
  if (!record.is_object() || !record.contains(key)) return std::nullopt;
  const nlohmann::json& value = record[key];
  if (!value.is_array() || value.size() != 2 || !value[0].is_number_integer() ||
      !value[1].is_number_integer())
    return std::nullopt;
  return std::array<int, 2>{value[0].get<int>(), value[1].get<int>()};
}

constexpr double kRegisteredCentreToleranceM = 0.01;  // far above the models' printed precision

// Each projector's model against the registration's record of that projector (by name): where
// it puts the projector and its image size. Two projectors' models swapped, or a model of another
// projector or calibration, put it elsewhere.
void CheckRegisteredProjectors(const RigDirectory& rig, const std::string& file) {
  const nlohmann::json& registration = rig.file.registration;
  if (!registration.is_object() || !registration.contains("projectors") ||
      !registration["projectors"].is_array())
    return;
  const nlohmann::json& recorded = registration["projectors"];
  for (size_t k = 0; k < rig.projectors.size(); ++k) {
    const Projector& projector = rig.projectors[k];
    for (size_t j = 0; j < recorded.size(); ++j) {
      const nlohmann::json& entry = recorded[j];
      if (!entry.is_object() || !entry.contains("name") || entry["name"] != projector.name)
        continue;
      const std::string key = fmt::format("registration.projectors[{}]", j);
      if (const std::optional<std::array<int, 2>> size = RecordedSize(entry, "imagersize");
          size &&
          ((*size)[0] != projector.geometry.width() || (*size)[1] != projector.geometry.height())) {
        throw IoError(
            fmt::format("{}: projectors[{}].model: {} is {}x{}, projector '{}' was registered "
                        "{}x{} ({}.imagersize): "
                        "the model of another device",
                        file, k, projector.model_path.string(), projector.geometry.width(),
                        projector.geometry.height(), projector.name, (*size)[0], (*size)[1], key));
      }
      if (const std::optional<Vec3> centre = RecordedTriple(entry, "centre_m")) {
        const Vec3 found = projector.geometry.CentreInWorld();
        if ((found - *centre).norm() > kRegisteredCentreToleranceM) {
          throw IoError(fmt::format(
              "{}: projectors[{}].model: {} puts '{}' at ({:.3f}, {:.3f}, {:.3f}) m, the "
              "registration at ({:.3f}, {:.3f}, {:.3f}) m ({}.centre_m): the model of another "
              "projector (models swapped?) or of another calibration",
              file, k, projector.model_path.string(), projector.name, found[0], found[1], found[2],
              (*centre)[0], (*centre)[1], (*centre)[2], key));
        }
      }
    }
  }
}

// What can be checked cheaply of a rig's parts against each other: every projector has its own
// model, none is the camera's (the same file, or a copy: the camera's size and intrinsics), and
// the registration record agrees with the camera's model on where the camera is (a rig.json of
// another rig, or a model from another calibration, does not). Throws IoError naming the key.
void CheckRigConsistency(const RigDirectory& rig) {
  const std::string file = (rig.dir / "rig.json").string();
  std::error_code error;
  const auto same_file = [&](const std::filesystem::path& a, const std::filesystem::path& b) {
    return std::filesystem::equivalent(a, b, error) && !error;
  };
  for (size_t k = 0; k < rig.projectors.size(); ++k) {
    for (size_t j = 0; j < k; ++j) {
      if (same_file(rig.projectors[k].model_path, rig.projectors[j].model_path)) {
        throw IoError(file + ": projectors[" + std::to_string(k) + "].model: the same file as " +
                      "projectors[" + std::to_string(j) + "].model (each projector has its own)");
      }
    }
  }
  if (rig.file.camera.model.empty()) return;
  const std::filesystem::path camera_path = rig.dir / rig.file.camera.model;
  if (!std::filesystem::exists(camera_path)) return;  // the commands that need it say so
  const ProjectorGeometry camera = ReadCameraModel(camera_path);
  for (size_t k = 0; k < rig.projectors.size(); ++k) {
    const ProjectorGeometry& projector = rig.projectors[k].geometry;
    if (same_file(rig.projectors[k].model_path, camera_path) ||
        (projector.width() == camera.width() && projector.height() == camera.height() &&
         projector.intrinsics() == camera.intrinsics())) {
      throw IoError(file + ": projectors[" + std::to_string(k) +
                    "].model: " + rig.projectors[k].model_path.string() +
                    " is the camera's model (" + std::to_string(camera.width()) + "x" +
                    std::to_string(camera.height()) + ", the same lens as camera.model)");
    }
  }
  const nlohmann::json& registration = rig.file.registration;
  CheckRegisteredProjectors(rig, file);
  if (const std::optional<std::array<int, 2>> size =
          RecordedSize(registration, "camera_imagersize");
      size && ((*size)[0] != camera.width() || (*size)[1] != camera.height())) {
    throw IoError(fmt::format(
        "{}: camera.model: {} is {}x{}, the camera registered (registration.camera_imagersize) "
        "{}x{}: not the rig's camera",
        file, camera_path.string(), camera.width(), camera.height(), (*size)[0], (*size)[1]));
  }
  if (registration.is_object() && registration.contains("camera_centre_m") &&
      registration["camera_centre_m"].is_array() && registration["camera_centre_m"].size() == 3) {
    Vec3 recorded;
    for (int c = 0; c < 3; ++c) {
      if (!registration["camera_centre_m"][c].is_number()) return;
      recorded[c] = registration["camera_centre_m"][c].get<double>();
    }
    const Vec3 centre = camera.CentreInWorld();
    if ((recorded - centre).norm() > kRegisteredCentreToleranceM) {
      throw IoError(fmt::format(
          "{}: registration.camera_centre_m: ({:.3f}, {:.3f}, {:.3f}) m, but {} puts the camera at "
          "({:.3f}, {:.3f}, {:.3f}) m: rig.json and the camera's model are of different "
          "calibrations (run procam calibrate projectors again)",
          file, recorded[0], recorded[1], recorded[2], camera_path.string(), centre[0], centre[1],
          centre[2]));
    }
  }
}

}  // namespace

namespace {

struct SurfaceShape {
  Vec3 centroid = Vec3::Zero();
  double area = 0.0;
  std::optional<Vec3> normal;  // quads
};

SurfaceShape ShapeOf(const Surface& surface) {
  SurfaceShape shape;
  const auto add_triangle = [&](const Vec3& a, const Vec3& b, const Vec3& c) {
    const double area = 0.5 * (b - a).cross(c - a).norm();
    shape.centroid += area * (a + b + c) / 3.0;
    shape.area += area;
  };
  if (surface.kind == Surface::Kind::kQuad) {
    const std::array<Vec3, 4>& q = surface.quad;
    add_triangle(q[0], q[1], q[2]);
    add_triangle(q[0], q[2], q[3]);
    const Vec3 normal = (q[1] - q[0]).cross(q[2] - q[0]);
    if (normal.norm() > 0) shape.normal = normal.normalized();
  } else {
    for (const MeshTriangle& t : surface.mesh_triangles) {
      add_triangle(surface.mesh_vertices[t.vertex[0]], surface.mesh_vertices[t.vertex[1]],
                   surface.mesh_vertices[t.vertex[2]]);
    }
  }
  if (shape.area > 0) shape.centroid /= shape.area;
  return shape;
}

}  // namespace

nlohmann::json RegisteredRoomJson(const Scene& scene) {
  nlohmann::json surfaces = nlohmann::json::array();
  for (const Surface& surface : scene.surfaces) {
    const SurfaceShape shape = ShapeOf(surface);
    nlohmann::json entry = {{"name", surface.name},
                            {"centroid_m", JsonTriple(shape.centroid)},
                            {"area_m2", shape.area}};
    if (shape.normal) entry["normal"] = JsonTriple(*shape.normal);
    surfaces.push_back(entry);
  }
  return {{"scene", scene.path.filename().string()}, {"surfaces", surfaces}};
}

void CheckRegisteredRoom(const RigDirectory& rig, const Scene& scene) {
  const nlohmann::json& registration = rig.file.registration;
  if (!registration.is_object() || !registration.contains("room") ||
      !registration["room"].is_object() || !registration["room"].contains("surfaces") ||
      !registration["room"]["surfaces"].is_array())
    return;
  const nlohmann::json& recorded = registration["room"]["surfaces"];
  const std::string where = scene.path.empty() ? scene.name : scene.path.string();
  const std::string file = (rig.dir / "rig.json").string();
  constexpr double kCentroidToleranceM = 0.05, kAreaTolerance = 0.05, kNormalToleranceDeg = 10.0;
  for (size_t s = 0; s < scene.surfaces.size(); ++s) {
    const Surface& surface = scene.surfaces[s];
    for (size_t j = 0; j < recorded.size(); ++j) {
      const nlohmann::json& entry = recorded[j];
      if (!entry.is_object() || !entry.contains("name") || entry["name"] != surface.name) continue;
      const SurfaceShape shape = ShapeOf(surface);
      const std::string key = fmt::format("registration.room.surfaces[{}]", j);
      const std::string intro = fmt::format("{}: surfaces[{}] '{}': ", where, s, surface.name);
      const std::string outro = fmt::format(
          " ({} {}): not the room the rig was calibrated in (a wall moved or flipped since? "
          "calibrate projectors again, or give that room)",
          file, key);
      if (const std::optional<Vec3> centroid = RecordedTriple(entry, "centroid_m")) {
        const double moved = (shape.centroid - *centroid).norm();
        if (moved > kCentroidToleranceM) {
          throw IoError(intro +
                        fmt::format("its centre is {:.3f} m from where the rig was "
                                    "registered",
                                    moved) +
                        outro);
        }
      }
      if (entry.contains("area_m2") && entry["area_m2"].is_number()) {
        const double area = entry["area_m2"].get<double>();
        if (std::abs(shape.area - area) > kAreaTolerance * std::max(area, 1e-12)) {
          throw IoError(intro + fmt::format("{:.3f} m², registered {:.3f} m²", shape.area, area) +
                        outro);
        }
      }
      if (const std::optional<Vec3> normal = RecordedTriple(entry, "normal");
          normal && shape.normal && normal->norm() > 0) {
        const double cosine = std::clamp(shape.normal->dot(normal->normalized()), -1.0, 1.0);
        const double degrees = std::acos(cosine) * 180.0 / std::numbers::pi;
        if (degrees > kNormalToleranceDeg) {
          throw IoError(intro +
                        fmt::format("its lit side faces {:.0f}° from the registered one", degrees) +
                        outro);
        }
      }
    }
  }
}

std::vector<std::string> MissingRegistrationRecords(const RigDirectory& rig) {
  const nlohmann::json& registration = rig.file.registration;
  if (!registration.is_object()) return {"registration"};
  std::vector<std::string> missing;
  if (!RecordedTriple(registration, "camera_centre_m"))
    missing.push_back("registration.camera_centre_m");
  if (!RecordedSize(registration, "camera_imagersize"))
    missing.push_back("registration.camera_imagersize");
  const nlohmann::json none = nlohmann::json::array();
  const nlohmann::json& recorded =
      registration.contains("projectors") && registration["projectors"].is_array()
          ? registration["projectors"]
          : none;
  for (const Projector& projector : rig.projectors) {
    bool found = false;
    for (size_t j = 0; j < recorded.size() && !found; ++j) {
      const nlohmann::json& entry = recorded[j];
      if (!entry.is_object() || !entry.contains("name") || entry["name"] != projector.name)
        continue;
      found = true;
      if (!RecordedTriple(entry, "centre_m"))
        missing.push_back(fmt::format("registration.projectors[{}].centre_m", j));
      if (!RecordedSize(entry, "imagersize"))
        missing.push_back(fmt::format("registration.projectors[{}].imagersize", j));
    }
    if (!found) missing.push_back("registration.projectors: '" + projector.name + "'");
  }
  if (!registration.contains("room") || !registration["room"].is_object() ||
      !registration["room"].contains("surfaces") || !registration["room"]["surfaces"].is_array())
    missing.push_back("registration.room");
  return missing;
}

std::string MissingRegistrationWarning(const RigDirectory& rig) {
  const std::vector<std::string> missing = MissingRegistrationRecords(rig);
  if (missing.empty()) return "";
  std::string keys;
  for (size_t k = 0; k < missing.size(); ++k) keys += (k == 0 ? "" : ", ") + missing[k];
  const std::string dir = rig.dir.string();
  return fmt::format(
      "warning: {}: no {} (a rig registered before procam recorded them): its models and the room "
      "given with it are not checked against its registration, so two projectors' models swapped "
      "or a wall moved since would go unnoticed; to record them, register the rig again: procam "
      "calibrate projectors {}/captures/structured_light_* --scene SCENE --out {} (or the same "
      "procam calibrate all, which keeps its captures and redoes the fits)",
      (rig.dir / "rig.json").string(), keys, dir, dir);
}

RigDirectory ReadRigDirectory(const std::filesystem::path& rig_dir) {
  const std::filesystem::path path = rig_dir / "rig.json";
  const std::string file = path.string();
  if (!std::filesystem::is_directory(rig_dir)) {
    throw IoError(rig_dir.string() + ": not a directory (--rig takes a rig directory)");
  }
  if (!std::filesystem::exists(path)) {
    throw IoError(file +
                  ": file not found (the rig directory's rig.json, written by procam "
                  "calibrate)");
  }
  RigDirectory rig;
  rig.dir = rig_dir;
  rig.file = ReadRigFile(rig_dir);
  if (rig.file.projectors.empty()) {
    throw IoError(file +
                  ": projectors: required key is missing (a non-empty array, run procam "
                  "calibrate projectors and calibrate photometric)");
  }
  // Photometry still in camera units cannot light a scene: say so before the parser's plainer
  // "max: required key is missing".
  for (size_t k = 0; k < rig.file.projectors.size(); ++k) {
    const RigProjector& entry = rig.file.projectors[k];
    const auto photometry = rig.file.photometric.find(entry.name);
    if (photometry != rig.file.photometric.end() && photometry->second.units == "camera" &&
        !entry.max) {
      throw IoError(file + ": projectors[" + std::to_string(k) + "].max: the photometry of '" +
                    entry.name + "' is in camera units (photometric." + entry.name +
                    ".units); compensate needs scene units: run procam calibrate photometric "
                    "with --scene once the projector's geometry and the camera's registration "
                    "are in the rig");
    }
  }
  rig.projectors = ParseProjectors(rig.file.ProjectorsJson().dump(), file, rig_dir);
  CheckRigConsistency(rig);

  if (rig.file.reflectance) {
    const RigReflectance& info = *rig.file.reflectance;
    const std::filesystem::path npy = rig_dir / info.file;
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
    rig.reflectance_target_patches = info.target_patches;
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

SolutionProjectors ProjectorsForSolution(const SolutionDirectory& solution,
                                         const std::filesystem::path& rig_dir, const Scene& scene,
                                         PatchHierarchy* patches) {
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
  result.reflectance_maps = ReadRigReflectanceMaps(rig);
  return result;
}

}  // namespace procam
