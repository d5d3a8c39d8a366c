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

#include "base/image_io.h"
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

// Bilinear lookup of a CV_32FC3 texture at UV (UV (0,0) = the image's bottom-left corner),
// clamped at the borders.
Vec3 TextureAt(const cv::Mat& texture_linear, const Vec2& uv) {
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

// Why a reflectance texture cannot be a surface's reflectance, as "KEY: why" ("" when it can).
std::string ReflectanceTextureProblem(const ReflectanceTexture& texture) {
  if (!(texture.scale > 0.0 && texture.scale <= 1.0)) {
    std::ostringstream why;
    why << "scale: must be in (0, 1], got " << texture.scale;
    return why.str();
  }
  const double brightest = texture.Max();
  if (!(brightest < 1.0)) {
    std::ostringstream why;
    why << "texture: " << texture.texture_path << ": its brightest texel times scale is "
        << brightest << ", a reflectance must be < 1 (give a scale below "
        << texture.scale / brightest << ")";
    return why.str();
  }
  return "";
}

// "reflectance": a number, [r, g, b], or {"texture": PATH, "scale": S} (ReflectanceTexture).
void ReadReflectance(const JsonFields& fields, const std::string& file,
                     const std::filesystem::path& base, Surface* surface) {
  const json& value = fields.At("reflectance");
  if (!value.is_object()) {
    surface->reflectance = fields.NumberOrRgb("reflectance");
    CheckReflectance(fields, "reflectance", surface->reflectance);
    return;
  }
  JsonFields reflectance(value, file, fields.Path("reflectance"));
  reflectance.RejectUnknown({"texture", "scale"});
  ReflectanceTexture& texture = surface->reflectance_texture;
  texture.texture_path = reflectance.String("texture");
  if (reflectance.Has("scale")) texture.scale = reflectance.Number("scale");
  if (!(texture.scale > 0.0 && texture.scale <= 1.0)) {
    throw reflectance.Error("scale", "must be in (0, 1]");
  }
  try {
    texture.texture_linear = LoadSrgbTextureAsLinear(base / texture.texture_path);
  } catch (const IoError& error) {
    throw reflectance.Error("texture", error.what());
  }
  const std::string problem = ReflectanceTextureProblem(texture);
  if (!problem.empty()) throw IoError(file + ": " + reflectance.prefix() + "." + problem);
  surface->reflectance = texture.Mean();
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
  if (!HasTexture())
    return Vec3(SrgbToLinear(srgb[0]), SrgbToLinear(srgb[1]), SrgbToLinear(srgb[2]));
  return TextureAt(texture_linear, uv);
}

Vec3 ReflectanceTexture::At(const Vec2& uv) const { return scale * TextureAt(texture_linear, uv); }

Vec3 ReflectanceTexture::Mean() const {
  const cv::Scalar mean = cv::mean(texture_linear);
  return scale * Vec3(mean[0], mean[1], mean[2]);
}

double ReflectanceTexture::Max() const {
  double brightest = 0.0;
  cv::minMaxLoc(texture_linear.reshape(1), nullptr, &brightest);
  return scale * brightest;
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
  constexpr uintmax_t kMaxTextureBytes = uintmax_t{256} << 20;
  cv::Mat image = ReadImage(path, cv::IMREAD_COLOR | cv::IMREAD_ANYDEPTH, kMaxTextureBytes);
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
    if (surface.reflectance_texture.HasTexture()) {
      const std::string problem = ReflectanceTextureProblem(surface.reflectance_texture);
      if (!problem.empty()) throw IoError(file + ": " + key + ".reflectance." + problem);
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
                     "weld_tolerance", "projectors", "cameras", "chessboard"});
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
  // A chessboard held in front of the rig's camera: the synthetic world's alone (it reads the key
  // itself, datasets_synthetic/scene_files.h); the room's model has no use for it.
  if (top.Has("chessboard") && !top.At("chessboard").is_object())
    throw top.Error("chessboard", "must be an object");
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
    // Surfaces are told apart by name (reports, the scan's registration, per-surface results).
    for (size_t other = 0; other < scene.surfaces.size(); ++other) {
      if (scene.surfaces[other].name == surface.name) {
        throw fields.Error("name", "'" + surface.name + "' is already the name of surfaces[" +
                                       std::to_string(other) + "]");
      }
    }
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
    ReadReflectance(fields, file, base, &surface);
    surface.desired = ReadDesired(fields, base);
    scene.surfaces.push_back(std::move(surface));
  }
  return scene;
}

}  // namespace procam
