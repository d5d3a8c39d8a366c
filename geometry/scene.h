#pragma once
// The room model: surfaces, their reflectance and the desired appearance, read from a scene
// JSON file (format: docs/scene_format.md). Units are metres; every surface is lit from the side
// its corners wind counter-clockwise around (right-hand rule gives the lit-side normal).

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core/mat.hpp>

#include "base/vector.h"

namespace procam {

// What a surface should look like: one sRGB colour, or a texture mapped through the surface's
// UV coordinates (quads: u along corner 0→1, v along corner 0→3; UV (0,0) is the image's
// bottom-left corner, as in OBJ).
struct DesiredAppearance {
  Vec3 srgb = Vec3::Zero();      // gamma-encoded sRGB in [0,1]; used when `texture` is empty
  std::string texture_path;      // as written in the scene, resolved against the scene file
  cv::Mat texture_linear;        // CV_32FC3, linear RGB in [0,1], row 0 = top of the image

  bool HasTexture() const { return !texture_linear.empty(); }
  // Linear RGB at a UV coordinate (bilinear, clamped at the borders; the colour if no texture).
  Vec3 LinearAt(const Vec2& uv) const;
};

// A surface that is not evenly painted (a printed poster, stains): its diffuse reflectance per
// point is `scale` × the texture's linear RGB at the point's UV coordinate, mapped as the desired
// texture is (bilinear, clamped at the borders). Every value it gives is in [0,1): LoadScene and
// ValidateScene refuse a brightest texel × scale ≥ 1.
struct ReflectanceTexture {
  std::string texture_path;  // as written in the scene, resolved against the scene file
  cv::Mat texture_linear;    // CV_32FC3, linear RGB in [0,1], row 0 = top of the image
  double scale = 1.0;        // multiplies every texel, in (0, 1]

  bool HasTexture() const { return !texture_linear.empty(); }
  // scale × the texture at `uv` (bilinear, clamped at the borders). Needs HasTexture().
  Vec3 At(const Vec2& uv) const;
  // scale × the texture's mean over its texels (the surface's mean reflectance when the surface
  // maps its UV square evenly, as a parallelogram does).
  Vec3 Mean() const;
  // scale × the brightest texel value over all channels.
  double Max() const;
};

// One triangle of a mesh surface: vertex indices and per-corner UV coordinates.
struct MeshTriangle {
  std::array<int, 3> vertex;
  std::array<Vec2, 3> uv;
};

struct Surface {
  enum class Kind { kQuad, kMesh };
  std::string name;
  Kind kind = Kind::kQuad;
  std::array<Vec3, 4> quad;                // kQuad: planar, convex, counter-clockwise
  std::vector<Vec3> mesh_vertices;         // kMesh: welded vertex positions
  std::vector<MeshTriangle> mesh_triangles;  // kMesh: each counter-clockwise from the lit side
  std::string mesh_path;                   // kMesh: as written in the scene
  // Diffuse reflectance per channel, each in [0,1); with a reflectance texture, its Mean().
  Vec3 reflectance = Vec3::Constant(0.9);
  ReflectanceTexture reflectance_texture;  // empty: `reflectance` everywhere on the surface
  DesiredAppearance desired;

  double Area() const;
  // The reflectance at a UV coordinate: the texture's when there is one, else `reflectance`.
  Vec3 ReflectanceAt(const Vec2& uv) const {
    return reflectance_texture.HasTexture() ? reflectance_texture.At(uv) : reflectance;
  }
};

// Direct-light exitance limits per channel (linear, same units as the white radiosity) used
// when the scene has no projectors: every patch gets lower ≤ E ≤ upper.
struct LightBounds {
  Vec3 lower = Vec3::Zero();
  Vec3 upper = Vec3::Ones();
};

struct Scene {
  std::filesystem::path path;  // the file it was read from (empty for generated scenes)
  std::string name;
  std::vector<Surface> surfaces;
  int target_patches = 1000;   // fine patches wanted in total, ≥ 1
  double white = 1.0;          // reference white radiosity w, > 0
  LightBounds bounds;          // default: lower 0, upper = white
  double weld_tolerance = 1e-3;  // metres; points closer than this are the same point
  // The scene's "projectors" and "cameras" arrays as JSON text ("" when absent), parsed by the
  // projection and capture modules (geometry does not know their models).
  std::string projectors_json;
  std::string cameras_json;

  double Area() const;
};

// Reads and validates a scene file. Throws IoError with one line naming the file and the key
// (e.g. "room.json: surfaces[2].reflectance: each value must be in [0,1), got 1.2") or, for
// syntax errors, the line and column.
Scene LoadScene(const std::filesystem::path& path);

// Validates a scene made in code (same rules as LoadScene). Throws IoError naming the surface.
void ValidateScene(const Scene& scene);

// Loads an OBJ mesh into `surface` (kMesh). Throws IoError naming the file and line.
void LoadObjMesh(const std::filesystem::path& path, double weld_tolerance, Surface* surface);

// A mesh surface as OBJ text that LoadObjMesh reads back: a comment line (`# NAME, comment`),
// its vertices (17 significant digits), one `vt` per triangle corner, faces `v/vt`.
std::string ObjMeshText(const Surface& surface, const std::string& comment);

// Loads an 8- or 16-bit image as linear RGB (sRGB-decoded). Throws IoError naming the file.
cv::Mat LoadSrgbTextureAsLinear(const std::filesystem::path& path);

}  // namespace procam
