#include "datasets_synthetic/rooms.h"

#include <Eigen/Geometry>

namespace procam {

Surface MakeRectangle(const Vec3& origin, const Vec3& u, const Vec3& v, double reflectance,
                      const Vec3& desired_srgb) {
  Surface surface;
  surface.kind = Surface::Kind::kQuad;
  surface.quad = {origin, origin + u, origin + u + v, origin + v};
  surface.reflectance = Vec3::Constant(reflectance);
  surface.desired.srgb = desired_srgb;
  return surface;
}

Scene MakeBoxRoom(const BoxRoomOptions& options) {
  Scene scene;
  scene.name = options.occluder ? "box room with occluder" : "box room";
  scene.target_patches = options.target_patches;
  const double w = options.size.x(), d = options.size.y(), h = options.size.z();
  const double r = options.reflectance;
  const Vec3 x = Vec3::UnitX(), y = Vec3::UnitY(), z = Vec3::UnitZ();
  // Inward-facing walls: u × v points into the room.
  auto add = [&](const char* name, const Vec3& origin, const Vec3& u, const Vec3& v, const Vec3& colour) {
    Surface surface = MakeRectangle(origin, u, v, r, colour);
    surface.name = name;
    scene.surfaces.push_back(surface);
  };
  add("floor", Vec3::Zero(), w * x, d * y, Vec3(0.55, 0.45, 0.35));
  add("ceiling", h * z, d * y, w * x, Vec3(0.9, 0.9, 0.85));
  add("front", Vec3::Zero(), h * z, w * x, Vec3(0.8, 0.2, 0.2));
  add("back", d * y, w * x, h * z, Vec3(0.2, 0.6, 0.8));
  add("left", Vec3::Zero(), d * y, h * z, Vec3(0.9, 0.8, 0.2));
  add("right", w * x, h * z, d * y, Vec3(0.3, 0.7, 0.3));
  if (options.occluder) {
    const Vec3 lo = options.occluder_min, hi = options.occluder_max;
    const Vec3 e = hi - lo;
    // Outward-facing: u × v points out of the box.
    add("occluder top", Vec3(lo.x(), lo.y(), hi.z()), e.x() * x, e.y() * y, Vec3(0.95, 0.95, 0.95));
    add("occluder front", lo, e.x() * x, e.z() * z, Vec3(0.6, 0.3, 0.7));
    add("occluder back", Vec3(lo.x(), hi.y(), lo.z()), e.z() * z, e.x() * x, Vec3(0.6, 0.3, 0.7));
    add("occluder left", lo, e.z() * z, e.y() * y, Vec3(0.6, 0.3, 0.7));
    add("occluder right", Vec3(hi.x(), lo.y(), lo.z()), e.y() * y, e.z() * z, Vec3(0.6, 0.3, 0.7));
  }
  return scene;
}

SubdividedRoom MakeSubdividedBoxRoom(int target_patches) {
  SubdividedRoom room;
  BoxRoomOptions options;
  options.target_patches = target_patches;
  room.scene = MakeBoxRoom(options);
  SubdivisionOptions subdivision;
  subdivision.target_patches = target_patches;
  room.patches = SubdividePatches(room.scene, subdivision);
  return room;
}

}  // namespace procam
