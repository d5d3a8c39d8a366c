#include "datasets_synthetic/paper_scenes.h"

#include <cmath>
#include <optional>
#include <stdexcept>
#include <vector>

#include <opencv2/core.hpp>

#include "datasets_synthetic/rooms.h"
#include "geometry/srgb.h"

namespace procam {
namespace {

constexpr double kPi = 3.14159265358979323846;

Vec3 Srgb(double r, double g, double b) { return Vec3(r, g, b); }

// A quad from its corner, its two edges (u × v is the lit side), reflectance and colour.
Surface Quad(const char* name, const Vec3& origin, const Vec3& u, const Vec3& v, double reflectance,
             const Vec3& srgb) {
  Surface surface = MakeRectangle(origin, u, v, reflectance, srgb);
  surface.name = name;
  return surface;
}

// High-frequency detail texture, linear RGB: a base colour modulated by stripes and a fine
// checker (the paper's Fig. 2 combines such detail with per-patch radiosity).
cv::Mat DetailTexture(const Vec3& base_srgb, const Vec3& accent_srgb, int size, int period) {
  cv::Mat texture(size, size, CV_32FC3);
  for (int row = 0; row < size; ++row) {
    for (int col = 0; col < size; ++col) {
      const bool stripe = ((col / period) % 2) == 0;
      const bool check = (((row / (period / 2 + 1)) + (col / (period / 2 + 1))) % 2) == 0;
      const double mix = stripe ? (check ? 1.0 : 0.7) : (check ? 0.15 : 0.0);
      cv::Vec3f& texel = texture.at<cv::Vec3f>(row, col);
      for (int c = 0; c < 3; ++c) {
        const double srgb = (1 - mix) * base_srgb[c] + mix * accent_srgb[c];
        texel[c] = static_cast<float>(SrgbToLinear(srgb));
      }
    }
  }
  return texture;
}

// A smooth two-colour gradient texture (left → right), linear RGB.
cv::Mat GradientTexture(const Vec3& left_srgb, const Vec3& right_srgb, int width, int height) {
  cv::Mat texture(height, width, CV_32FC3);
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      const double t = double(col) / (width - 1);
      cv::Vec3f& texel = texture.at<cv::Vec3f>(row, col);
      for (int c = 0; c < 3; ++c) {
        texel[c] = static_cast<float>(SrgbToLinear((1 - t) * left_srgb[c] + t * right_srgb[c]));
      }
    }
  }
  return texture;
}

// A rectangular stage w × d (x, y) with walls h high: the floor, the back wall (y = d) and,
// when their colours are given, the left (x = 0) and right (x = w) walls, all lit from inside.
struct StageColours {
  Vec3 floor, back;
  std::optional<Vec3> left, right;
};
void AddStage(Scene* scene, double w, double d, double h, const StageColours& colours) {
  scene->surfaces.push_back(Quad("floor", Vec3::Zero(), w * Vec3::UnitX(), d * Vec3::UnitY(), 0.8, colours.floor));
  scene->surfaces.push_back(Quad("back wall", Vec3(w, d, 0), h * Vec3::UnitZ(), -w * Vec3::UnitX(), 0.9, colours.back));
  if (colours.left) {
    scene->surfaces.push_back(Quad("left wall", Vec3::Zero(), d * Vec3::UnitY(), h * Vec3::UnitZ(), 0.9, *colours.left));
  }
  if (colours.right) {
    scene->surfaces.push_back(Quad("right wall", Vec3(w, d, 0), -d * Vec3::UnitY(), h * Vec3::UnitZ(), 0.9, *colours.right));
  }
}

// A vertical box column standing on the floor: four outward faces (no top or bottom).
void AddColumn(Scene* scene, const char* name, const Vec3& corner, double width, double depth, double height,
               double reflectance, const Vec3& srgb) {
  const Vec3 x = width * Vec3::UnitX(), y = depth * Vec3::UnitY(), z = height * Vec3::UnitZ();
  const std::string base = name;
  scene->surfaces.push_back(Quad((base + " front").c_str(), corner, x, z, reflectance, srgb));
  scene->surfaces.push_back(Quad((base + " back").c_str(), corner + y, z, x, reflectance, srgb));
  scene->surfaces.push_back(Quad((base + " left").c_str(), corner, z, y, reflectance, srgb));
  scene->surfaces.push_back(Quad((base + " right").c_str(), corner + x, y, z, reflectance, srgb));
}

// A free-standing partition: two faces back to back, `thickness` apart. The front face, at
// `origin`, faces z × along; the back face the other way.
void AddPartition(Scene* scene, const char* name, const Vec3& origin, const Vec3& along, double height,
                  double thickness, double reflectance, const Vec3& front_srgb, const Vec3& back_srgb) {
  const Vec3 z = height * Vec3::UnitZ();
  const Vec3 back_offset = thickness * along.cross(Vec3::UnitZ()).normalized();
  const std::string base = name;
  scene->surfaces.push_back(Quad((base + " front").c_str(), origin, z, along, reflectance, front_srgb));
  scene->surfaces.push_back(Quad((base + " back").c_str(), origin + back_offset, along, z, reflectance, back_srgb));
}

// The floor inside a cylindrical wall: a polar mesh (a fan at the centre, then rings of
// planar quads) from angle a0 to a1, lit from above.
Surface PolarFloor(const char* name, const Vec3& axis, const std::vector<double>& radii, double a0, double a1,
                   int segments, double reflectance, const Vec3& srgb) {
  Surface surface;
  surface.name = name;
  surface.kind = Surface::Kind::kMesh;
  surface.reflectance = Vec3::Constant(reflectance);
  surface.desired.srgb = srgb;
  surface.mesh_vertices.push_back(axis);
  auto vertex = [&](int ring, int k) { return 1 + ring * (segments + 1) + k; };
  for (const double radius : radii) {
    for (int k = 0; k <= segments; ++k) {
      const double a = a0 + (a1 - a0) * k / segments;
      surface.mesh_vertices.push_back(axis + radius * Vec3(std::cos(a), std::sin(a), 0.0));
    }
  }
  auto uv = [&](int index) {
    const Vec3 p = surface.mesh_vertices[index] - axis;
    return Vec2(0.5 + 0.5 * p.x() / radii.back(), 0.5 + 0.5 * p.y() / radii.back());
  };
  for (int k = 0; k < segments; ++k) {
    surface.mesh_triangles.push_back({{0, vertex(0, k), vertex(0, k + 1)}, {uv(0), uv(vertex(0, k)), uv(vertex(0, k + 1))}});
    for (size_t ring = 1; ring < radii.size(); ++ring) {
      const int a = vertex(ring - 1, k), b = vertex(ring, k), c = vertex(ring, k + 1), e = vertex(ring - 1, k + 1);
      surface.mesh_triangles.push_back({{a, b, c}, {uv(a), uv(b), uv(c)}});
      surface.mesh_triangles.push_back({{a, c, e}, {uv(a), uv(c), uv(e)}});
    }
  }
  return surface;
}

// A cylindrical wall (concave side lit) as a mesh: centre of curvature `axis` on the floor,
// radius, from angle a0 to a1 (radians, counter-clockwise seen from above), height.
Surface CurvedWall(const char* name, const Vec3& axis, double radius, double a0, double a1, double height,
                   int segments, double reflectance, const Vec3& srgb) {
  Surface surface;
  surface.name = name;
  surface.kind = Surface::Kind::kMesh;
  surface.reflectance = Vec3::Constant(reflectance);
  surface.desired.srgb = srgb;
  for (int k = 0; k <= segments; ++k) {
    const double a = a0 + (a1 - a0) * k / segments;
    const Vec3 p = axis + radius * Vec3(std::cos(a), std::sin(a), 0.0);
    surface.mesh_vertices.push_back(p);
    surface.mesh_vertices.push_back(p + height * Vec3::UnitZ());
  }
  for (int k = 0; k < segments; ++k) {
    const int b0 = 2 * k, t0 = 2 * k + 1, b1 = 2 * k + 2, t1 = 2 * k + 3;
    const double u0 = double(k) / segments, u1 = double(k + 1) / segments;
    // Counter-clockwise seen from the axis (inside): b0 → t0 → t1 and b0 → t1 → b1.
    surface.mesh_triangles.push_back({{b0, t0, t1}, {Vec2(u0, 0), Vec2(u0, 1), Vec2(u1, 1)}});
    surface.mesh_triangles.push_back({{b0, t1, b1}, {Vec2(u0, 0), Vec2(u1, 1), Vec2(u1, 0)}});
  }
  return surface;
}

DevicePlacement Projector(const char* name, const Vec3& centre, const Vec3& target, double fov_deg = 72.0) {
  return MakeDevicePlacement(name, centre, target, fov_deg, 1280, 800);
}

DevicePlacement Camera(const Vec3& centre, const Vec3& target, double fov_deg = 70.0) {
  return MakeDevicePlacement("camera", centre, target, fov_deg, 960, 640);
}

SyntheticScene LShaped() {
  SyntheticScene s;
  s.scene.name = "l_shaped";
  const double w = 3.0, d = 3.0, h = 2.4;
  AddStage(&s.scene, w, d, h, {Srgb(0.55, 0.5, 0.42), Srgb(0.9, 0.45, 0.15), Srgb(0.1, 0.55, 0.6), std::nullopt});
  s.scene.surfaces[1].desired.texture_linear = DetailTexture(Srgb(0.92, 0.45, 0.12), Srgb(0.98, 0.85, 0.55), 256, 8);
  s.projectors = {Projector("left", Vec3(2.6, -1.6, 2.3), Vec3(0.6, 2.0, 0.9)),
                  Projector("right", Vec3(0.4, -1.8, 2.4), Vec3(2.2, 2.4, 1.0))};
  s.camera = Camera(Vec3(1.6, -2.2, 1.6), Vec3(1.2, 1.8, 0.8));
  return s;
}

SyntheticScene Columns() {
  SyntheticScene s;
  s.scene.name = "columns";
  const double w = 4.0, d = 3.0, h = 2.5;
  AddStage(&s.scene, w, d, h, {Srgb(0.15, 0.2, 0.45), Srgb(0.5, 0.2, 0.6), std::nullopt, std::nullopt});
  s.scene.surfaces[1].desired.texture_linear = DetailTexture(Srgb(0.45, 0.15, 0.55), Srgb(0.95, 0.75, 0.95), 256, 6);
  AddColumn(&s.scene, "column 1", Vec3(1.0, 1.6, 0), 0.4, 0.4, h, 0.9, Srgb(0.95, 0.8, 0.15));
  AddColumn(&s.scene, "column 2", Vec3(2.6, 1.6, 0), 0.4, 0.4, h, 0.9, Srgb(0.85, 0.15, 0.15));
  s.projectors = {Projector("left", Vec3(0.8, -1.8, 2.4), Vec3(2.0, 2.2, 1.0)),
                  Projector("centre", Vec3(2.0, -2.2, 2.6), Vec3(2.0, 2.0, 0.9)),
                  Projector("right", Vec3(3.2, -1.8, 2.4), Vec3(2.0, 2.2, 1.0))};
  s.camera = Camera(Vec3(2.0, -2.5, 1.6), Vec3(2.0, 2.0, 1.0));
  return s;
}

SyntheticScene GreenTrapezoid() {
  SyntheticScene s;
  s.scene.name = "green_trapezoid";
  // A trapezoidal floor, narrower at the back, with walls splayed outwards to the audience.
  const Vec3 front_left(0, 0, 0), front_right(4, 0, 0), back_right(3.1, 3, 0), back_left(0.9, 3, 0);
  const Vec3 up(0, 0, 2.4);
  Surface floor;
  floor.name = "floor";
  floor.quad = {front_left, front_right, back_right, back_left};
  floor.reflectance = Vec3::Constant(0.8);
  floor.desired.srgb = Srgb(0.25, 0.45, 0.2);
  s.scene.surfaces.push_back(floor);
  s.scene.surfaces.push_back(Quad("back wall", back_right, up, back_left - back_right, 0.9, Srgb(0.35, 0.75, 0.3)));
  s.scene.surfaces.push_back(Quad("left wall", front_left, back_left - front_left, up, 0.9, Srgb(0.65, 0.85, 0.25)));
  s.scene.surfaces.push_back(Quad("right wall", back_right, front_right - back_right, up, 0.9, Srgb(0.1, 0.5, 0.35)));
  s.projectors = {Projector("left", Vec3(1.2, -1.6, 2.3), Vec3(2.3, 2.5, 0.8)),
                  Projector("right", Vec3(2.8, -1.6, 2.3), Vec3(1.7, 2.5, 0.8))};
  s.camera = Camera(Vec3(2.0, -2.0, 1.6), Vec3(2.0, 2.0, 0.9));
  return s;
}

SyntheticScene InteriorPartitions() {
  SyntheticScene s;
  s.scene.name = "interior_partitions";
  const double w = 5.0, d = 4.0, h = 2.5;
  AddStage(&s.scene, w, d, h, {Srgb(0.6, 0.58, 0.55), Srgb(0.2, 0.35, 0.75), Srgb(0.85, 0.75, 0.3), Srgb(0.75, 0.3, 0.35)});
  // Two partitions facing the audience (front faces toward −y), 1.6 m tall.
  AddPartition(&s.scene, "partition 1", Vec3(2.3, 2.0, 0), -1.4 * Vec3::UnitX(), 1.6, 0.05, 0.9,
               Srgb(0.3, 0.7, 0.45), Srgb(0.9, 0.9, 0.9));
  AddPartition(&s.scene, "partition 2", Vec3(4.1, 2.6, 0), -1.2 * Vec3::UnitX(), 1.6, 0.05, 0.9,
               Srgb(0.95, 0.55, 0.2), Srgb(0.9, 0.9, 0.9));
  s.projectors = {Projector("front left", Vec3(1.0, -1.8, 2.4), Vec3(2.0, 3.0, 1.0)),
                  Projector("front right", Vec3(4.0, -1.8, 2.4), Vec3(3.0, 3.0, 1.0)),
                  Projector("left side", Vec3(0.5, 0.3, 2.45), Vec3(4.0, 3.5, 0.8)),
                  Projector("right side", Vec3(4.5, 0.3, 2.45), Vec3(1.0, 3.5, 0.8))};
  s.camera = Camera(Vec3(2.5, -2.6, 1.7), Vec3(2.5, 2.4, 1.0));
  return s;
}

SyntheticScene CShaped() {
  SyntheticScene s;
  s.scene.name = "c_shaped";
  const double w = 4.0, d = 3.0, h = 2.5;
  AddStage(&s.scene, w, d, h, {Srgb(0.5, 0.4, 0.3), Srgb(0.85, 0.2, 0.25), Srgb(0.95, 0.8, 0.2), Srgb(0.2, 0.45, 0.85)});
  s.projectors = {Projector("left", Vec3(1.0, -1.6, 2.4), Vec3(3.2, 2.0, 1.0)),
                  Projector("centre", Vec3(2.0, -2.0, 2.6), Vec3(2.0, 2.6, 0.9)),
                  Projector("right", Vec3(3.0, -1.6, 2.4), Vec3(0.8, 2.0, 1.0))};
  s.camera = Camera(Vec3(2.0, -2.4, 1.6), Vec3(2.0, 1.8, 1.0));
  return s;
}

SyntheticScene BlueCurves() {
  SyntheticScene s;
  s.scene.name = "blue_curves";
  const Vec3 axis(2.0, 0.5, 0.0);
  const double radius = 2.6, h = 2.5;
  // The floor inside the curve (a half disc), lit from above.
  s.scene.surfaces.push_back(PolarFloor("floor", axis, {0.9, 1.75, radius}, 0.0, kPi, 24, 0.8, Srgb(0.12, 0.2, 0.4)));
  Surface curve = CurvedWall("curved wall", axis, radius, 0.0, kPi, h, 24, 0.9, Srgb(0.2, 0.45, 0.85));
  curve.desired.texture_linear = GradientTexture(Srgb(0.1, 0.25, 0.7), Srgb(0.45, 0.8, 0.95), 256, 16);
  s.scene.surfaces.push_back(curve);
  s.projectors = {Projector("left", Vec3(0.6, -1.8, 2.4), Vec3(3.0, 2.5, 1.0)),
                  Projector("centre", Vec3(2.0, -2.2, 2.6), Vec3(2.0, 3.0, 1.0)),
                  Projector("right", Vec3(3.4, -1.8, 2.4), Vec3(1.0, 2.5, 1.0))};
  s.camera = Camera(Vec3(2.0, -2.6, 1.7), Vec3(2.0, 2.0, 1.0));
  return s;
}

SyntheticScene TinyBox() {
  SyntheticScene s;
  s.scene.name = "tiny_box";
  AddStage(&s.scene, 1.0, 1.0, 1.0, {Srgb(0.6, 0.5, 0.4), Srgb(0.8, 0.3, 0.3), Srgb(0.3, 0.6, 0.8), Srgb(0.5, 0.8, 0.3)});
  s.projectors = {Projector("left", Vec3(0.25, -1.2, 1.1), Vec3(0.6, 0.7, 0.4), 50.0),
                  Projector("right", Vec3(0.75, -1.2, 1.1), Vec3(0.4, 0.7, 0.4), 50.0)};
  for (DevicePlacement& projector : s.projectors) {
    projector.width = 320;
    projector.height = 200;
  }
  s.camera = Camera(Vec3(0.5, -1.4, 0.8), Vec3(0.5, 0.6, 0.45), 60.0);
  s.camera.width = 240;
  s.camera.height = 160;
  return s;
}

}  // namespace

DevicePlacement MakeDevicePlacement(const std::string& name, const Vec3& centre, const Vec3& target,
                                    double fov_deg, int width, int height) {
  DevicePlacement device;
  device.name = name;
  device.centre = centre;
  device.target = target;
  device.horizontal_fov_deg = fov_deg;
  device.width = width;
  device.height = height;
  return device;
}

std::vector<std::string> SyntheticSceneNames() {
  return {"l_shaped", "columns", "green_trapezoid", "interior_partitions", "c_shaped", "blue_curves", "tiny_box"};
}

SyntheticScene MakeSyntheticScene(const std::string& name, int target_patches) {
  SyntheticScene s;
  if (name == "l_shaped") s = LShaped();
  else if (name == "columns") s = Columns();
  else if (name == "green_trapezoid") s = GreenTrapezoid();
  else if (name == "interior_partitions") s = InteriorPartitions();
  else if (name == "c_shaped") s = CShaped();
  else if (name == "blue_curves") s = BlueCurves();
  else if (name == "tiny_box") s = TinyBox();
  else throw std::invalid_argument("unknown synthetic scene '" + name + "' (known: l_shaped, columns, "
                                   "green_trapezoid, interior_partitions, c_shaped, blue_curves, tiny_box)");
  s.scene.target_patches = target_patches;
  s.scene.white = 1.0;
  s.scene.bounds.lower = Vec3::Zero();
  s.scene.bounds.upper = Vec3::Ones();
  return s;
}

}  // namespace procam
