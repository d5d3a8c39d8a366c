#include "geometry/scene.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <unordered_map>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <tiny_obj_loader.h>

#include "base/io.h"
#include "base/json_fields.h"
#include "geometry/polygon.h"
#include "geometry/srgb.h"

namespace procam {
namespace {

using nlohmann::json;

void CheckReflectance(const JsonFields& fields, const std::string& key, const Vec3& rho) {
  for (int c = 0; c < 3; ++c) {
    if (!(rho[c] >= 0.0 && rho[c] < 1.0)) {
      std::ostringstream why;
      why << "each value must be in [0,1), got " << rho[c];
      throw fields.Error(key, why.str());
    }
  }
}

DesiredAppearance ReadDesired(const JsonFields& fields, const std::filesystem::path& base) {
  DesiredAppearance desired;
  const json& value = fields.At("desired");
  if (value.is_object()) {
    for (const auto& item : value.items()) {
      if (item.key() != "texture") throw fields.Error("desired." + item.key(), "unknown key (known keys: texture)");
    }
    if (!value.contains("texture") || !value["texture"].is_string()) {
      throw fields.Error("desired.texture", "must be a string (an image path)");
    }
    desired.texture_path = value["texture"].get<std::string>();
    try {
      desired.texture_linear = LoadSrgbTextureAsLinear(base / desired.texture_path);
    } catch (const IoError& error) {
      throw fields.Error("desired.texture", error.what());
    }
    return desired;
  }
  desired.srgb = fields.Triple("desired", value);
  for (int c = 0; c < 3; ++c) {
    if (!(desired.srgb[c] >= 0.0 && desired.srgb[c] <= 1.0)) {
      throw fields.Error("desired", "sRGB values must be in [0,1]");
    }
  }
  return desired;
}

void CheckQuad(const std::array<Vec3, 4>& quad, double tolerance, const std::string& file,
               const std::string& key) {
  std::string why;
  if (!CheckPlanarConvexPolygon(quad.data(), 4, tolerance, &why)) {
    throw IoError(file + ": " + key + ": " + why);
  }
}

}  // namespace

Vec3 DesiredAppearance::LinearAt(const Vec2& uv) const {
  if (!HasTexture()) return Vec3(SrgbToLinear(srgb[0]), SrgbToLinear(srgb[1]), SrgbToLinear(srgb[2]));
  const int width = texture_linear.cols, height = texture_linear.rows;
  const double x = std::clamp(uv[0] * width - 0.5, 0.0, width - 1.0);
  const double y = std::clamp((1.0 - uv[1]) * height - 0.5, 0.0, height - 1.0);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const int x1 = std::min(x0 + 1, width - 1), y1 = std::min(y0 + 1, height - 1);
  const double fx = x - x0, fy = y - y0;
  auto texel = [&](int row, int col) {
    const cv::Vec3f& value = texture_linear.at<cv::Vec3f>(row, col);
    return Vec3(value[0], value[1], value[2]);
  };
  return (1 - fy) * ((1 - fx) * texel(y0, x0) + fx * texel(y0, x1)) +
         fy * ((1 - fx) * texel(y1, x0) + fx * texel(y1, x1));
}

double Surface::Area() const {
  if (kind == Kind::kQuad) return PolygonArea(quad.data(), 4);
  double area = 0.0;
  for (const MeshTriangle& triangle : mesh_triangles) {
    const Vec3 corners[3] = {mesh_vertices[triangle.vertex[0]], mesh_vertices[triangle.vertex[1]],
                             mesh_vertices[triangle.vertex[2]]};
    area += PolygonArea(corners, 3);
  }
  return area;
}

double Scene::Area() const {
  double area = 0.0;
  for (const Surface& surface : surfaces) area += surface.Area();
  return area;
}

cv::Mat LoadSrgbTextureAsLinear(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) throw IoError(path.string() + ": file not found");
  cv::Mat image = cv::imread(path.string(), cv::IMREAD_COLOR | cv::IMREAD_ANYDEPTH);
  if (image.empty()) throw IoError(path.string() + ": not a readable image");
  const double scale = image.depth() == CV_16U ? 1.0 / 65535.0 : 1.0 / 255.0;
  if (image.depth() != CV_8U && image.depth() != CV_16U) {
    throw IoError(path.string() + ": only 8- and 16-bit images are supported");
  }
  cv::Mat rgb;
  cv::cvtColor(image, rgb, cv::COLOR_BGR2RGB);
  cv::Mat linear;
  rgb.convertTo(linear, CV_32FC3, scale);
  linear.forEach<cv::Vec3f>([](cv::Vec3f& texel, const int*) {
    for (int c = 0; c < 3; ++c) texel[c] = static_cast<float>(SrgbToLinear(texel[c]));
  });
  return linear;
}

void LoadObjMesh(const std::filesystem::path& path, double weld_tolerance, Surface* surface) {
  const std::string file = path.string();
  if (!std::filesystem::exists(path)) throw IoError(file + ": file not found");
  // Line of each face statement, so that errors can point at it.
  std::vector<int> face_lines;
  {
    std::ifstream in(path);
    std::string line;
    for (int number = 1; std::getline(in, line); ++number) {
      const size_t start = line.find_first_not_of(" \t");
      if (start != std::string::npos && line.compare(start, 2, "f ") == 0) face_lines.push_back(number);
    }
  }
  tinyobj::ObjReaderConfig config;
  config.triangulate = false;
  config.vertex_color = false;
  tinyobj::ObjReader reader;
  if (!reader.ParseFromFile(file, config)) {
    throw IoError(file + ": invalid OBJ: " + reader.Error());
  }
  const tinyobj::attrib_t& attrib = reader.GetAttrib();
  for (const tinyobj::real_t value : attrib.vertices) {
    if (!std::isfinite(value)) throw IoError(file + ": vertex coordinate is not finite");
  }
  surface->kind = Surface::Kind::kMesh;
  surface->mesh_vertices.clear();
  surface->mesh_triangles.clear();
  // Weld vertices closer than the tolerance so that shared edges are recognised.
  PointWelder welder(weld_tolerance);
  std::unordered_map<int, int> welded_of_obj;
  auto weld = [&](int obj_index) {
    auto found = welded_of_obj.find(obj_index);
    if (found != welded_of_obj.end()) return found->second;
    const int index = welder.Weld(Vec3(attrib.vertices[3 * obj_index], attrib.vertices[3 * obj_index + 1],
                                       attrib.vertices[3 * obj_index + 2]));
    if (index == static_cast<int>(surface->mesh_vertices.size())) {
      surface->mesh_vertices.push_back(welder.points()[index]);
    }
    welded_of_obj[obj_index] = index;
    return index;
  };
  size_t face_counter = 0;
  for (const tinyobj::shape_t& shape : reader.GetShapes()) {
    size_t offset = 0;
    for (const unsigned char corner_count : shape.mesh.num_face_vertices) {
      const std::string where =
          file + ":" + (face_counter < face_lines.size() ? std::to_string(face_lines[face_counter]) : "?");
      ++face_counter;
      if (corner_count < 3) throw IoError(where + ": face with fewer than 3 corners");
      std::vector<Vec3> corners;
      std::vector<int> vertices;
      std::vector<Vec2> uvs;
      for (size_t k = 0; k < corner_count; ++k) {
        const tinyobj::index_t index = shape.mesh.indices[offset + k];
        vertices.push_back(weld(index.vertex_index));
        corners.push_back(surface->mesh_vertices[vertices.back()]);
        if (index.texcoord_index >= 0) {
          uvs.emplace_back(attrib.texcoords[2 * index.texcoord_index],
                           attrib.texcoords[2 * index.texcoord_index + 1]);
        } else {
          uvs.emplace_back(0.0, 0.0);
        }
      }
      offset += corner_count;
      std::string why;
      if (!CheckPlanarConvexPolygon(corners.data(), static_cast<int>(corners.size()),
                                    weld_tolerance, &why)) {
        throw IoError(where + ": " + why);
      }
      for (size_t k = 1; k + 1 < corners.size(); ++k) {  // fan over a convex planar face
        surface->mesh_triangles.push_back(
            {{vertices[0], vertices[k], vertices[k + 1]}, {uvs[0], uvs[k], uvs[k + 1]}});
      }
    }
  }
  if (surface->mesh_triangles.empty()) throw IoError(file + ": mesh has no faces");
}

void ValidateScene(const Scene& scene) {
  const std::string file = scene.path.empty() ? std::string("scene") : scene.path.string();
  if (scene.surfaces.empty()) throw IoError(file + ": surfaces: at least one surface is required");
  if (scene.target_patches < 1) throw IoError(file + ": patches: must be at least 1");
  if (!(scene.white > 0.0) || !std::isfinite(scene.white)) {
    throw IoError(file + ": white: must be a positive finite number");
  }
  for (int c = 0; c < 3; ++c) {
    if (!(scene.bounds.lower[c] >= 0.0 && scene.bounds.lower[c] <= scene.bounds.upper[c]) ||
        !std::isfinite(scene.bounds.upper[c])) {
      throw IoError(file + ": bounds: need 0 <= lower <= upper, finite");
    }
  }
  for (size_t s = 0; s < scene.surfaces.size(); ++s) {
    const Surface& surface = scene.surfaces[s];
    const std::string key = "surfaces[" + std::to_string(s) + "]";
    for (int c = 0; c < 3; ++c) {
      if (!(surface.reflectance[c] >= 0.0 && surface.reflectance[c] < 1.0)) {
        throw IoError(file + ": " + key + ".reflectance: each value must be in [0,1)");
      }
    }
    if (surface.kind == Surface::Kind::kQuad) CheckQuad(surface.quad, scene.weld_tolerance, file, key + ".quad");
    if (surface.kind == Surface::Kind::kMesh && surface.mesh_triangles.empty()) {
      throw IoError(file + ": " + key + ".mesh: no triangles");
    }
  }
}

Scene LoadScene(const std::filesystem::path& path) {
  const std::string file = path.string();
  if (!std::filesystem::exists(path)) throw IoError(file + ": file not found");
  const json root = ReadJsonFile(path);
  const std::filesystem::path base = path.parent_path();
  JsonFields top(root, file, "");
  top.RejectUnknown({"name", "description", "patches", "white", "bounds", "surfaces",
                     "weld_tolerance", "projectors", "cameras"});
  Scene scene;
  scene.path = path;
  scene.name = top.Has("name") ? top.String("name") : path.stem().string();
  if (top.Has("description")) top.String("description");
  const json& patches = top.At("patches");
  if (!patches.is_number_integer() || patches.get<int64_t>() < 1 || patches.get<int64_t>() > 10000000) {
    throw top.Error("patches", "must be an integer in [1, 10000000]");
  }
  scene.target_patches = patches.get<int>();
  if (top.Has("white")) {
    scene.white = top.Number("white");
    if (!(scene.white > 0.0)) throw top.Error("white", "must be positive");
  }
  scene.bounds.upper = Vec3::Constant(scene.white);
  if (top.Has("weld_tolerance")) {
    scene.weld_tolerance = top.Number("weld_tolerance");
    if (!(scene.weld_tolerance > 0.0)) throw top.Error("weld_tolerance", "must be positive (metres)");
  }
  if (top.Has("bounds")) {
    JsonFields bounds(top.At("bounds"), file, "bounds");
    bounds.RejectUnknown({"lower", "upper"});
    if (bounds.Has("lower")) scene.bounds.lower = bounds.NumberOrRgb("lower");
    if (bounds.Has("upper")) scene.bounds.upper = bounds.NumberOrRgb("upper");
    for (int c = 0; c < 3; ++c) {
      if (scene.bounds.lower[c] < 0.0) throw bounds.Error("lower", "must be >= 0");
      if (scene.bounds.lower[c] > scene.bounds.upper[c]) {
        throw bounds.Error("lower", "lower is greater than upper");
      }
    }
  }
  for (const char* key : {"projectors", "cameras"}) {
    if (!top.Has(key)) continue;
    if (!top.At(key).is_array()) throw top.Error(key, "must be an array");
    (std::string(key) == "projectors" ? scene.projectors_json : scene.cameras_json) = top.At(key).dump();
  }
  const json& surfaces = top.At("surfaces");
  if (!surfaces.is_array() || surfaces.empty()) {
    throw top.Error("surfaces", "must be a non-empty array");
  }
  for (size_t s = 0; s < surfaces.size(); ++s) {
    JsonFields fields(surfaces[s], file, "surfaces[" + std::to_string(s) + "]");
    fields.RejectUnknown({"name", "quad", "mesh", "reflectance", "desired"});
    Surface surface;
    surface.name = fields.Has("name") ? fields.String("name") : "surface" + std::to_string(s);
    if (fields.Has("quad") == fields.Has("mesh")) {
      throw fields.Error("", "needs exactly one of 'quad' and 'mesh'");
    }
    if (fields.Has("quad")) {
      const json& quad = fields.At("quad");
      if (!quad.is_array() || quad.size() != 4) throw fields.Error("quad", "must be 4 corners");
      for (int k = 0; k < 4; ++k) surface.quad[k] = fields.Triple("quad[" + std::to_string(k) + "]", quad[k]);
      CheckQuad(surface.quad, scene.weld_tolerance, file, fields.Path("quad"));
    } else {
      surface.mesh_path = fields.String("mesh");
      try {
        LoadObjMesh(base / surface.mesh_path, scene.weld_tolerance, &surface);
      } catch (const IoError& error) {
        throw fields.Error("mesh", error.what());
      }
    }
    surface.reflectance = fields.NumberOrRgb("reflectance");
    CheckReflectance(fields, "reflectance", surface.reflectance);
    surface.desired = ReadDesired(fields, base);
    scene.surfaces.push_back(std::move(surface));
  }
  return scene;
}

}  // namespace procam
