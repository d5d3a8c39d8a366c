#include "datasets_synthetic/random_rooms.h"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "calibration/registration.h"
#include "datasets_synthetic/rooms.h"
#include "datasets_synthetic/scan_accuracy.h"
#include "datasets_synthetic/scene_files.h"
#include "datasets_synthetic/simulated_rig.h"
#include "geometry/ray_scene.h"

namespace procam {
namespace {

constexpr double kPi = 3.14159265358979323846;
const Vec3 kUp = Vec3::UnitZ();

// Uniform numbers from the seed alone. Each draw is a statement of its own: the order in which
// a function's arguments are evaluated is unspecified, so draws are never two arguments of one
// call.
class Draw {
 public:
  explicit Draw(uint64_t seed) : engine_(seed) {}
  // In [lo, hi): the top 53 bits of one 64-bit word as a double in [0, 1).
  double Uniform(double lo, double hi) {
    const double unit = static_cast<double>(engine_() >> 11) * 0x1.0p-53;
    return lo + (hi - lo) * unit;
  }
  // In [lo, hi], each value equally likely (to 2⁻⁵³).
  int Integer(int lo, int hi) {
    const int value = lo + static_cast<int>(std::floor(Uniform(0.0, 1.0) * (hi - lo + 1)));
    return std::min(value, hi);
  }
  bool Chance(double p) { return Uniform(0.0, 1.0) < p; }

 private:
  std::mt19937_64 engine_;
};

// What a physical surface looks like: one reflectance and desired colour for all its pieces.
struct Finish {
  Vec3 reflectance;
  Vec3 desired;
};
Finish DrawFinish(Draw& draw) {
  Finish finish;
  const double grey = draw.Uniform(0.55, 0.9);
  for (int c = 0; c < 3; ++c) {
    const double tint = draw.Uniform(0.95, 1.05);
    finish.reflectance[c] = std::min(0.94, grey * tint);
  }
  for (int c = 0; c < 3; ++c) finish.desired[c] = draw.Uniform(0.1, 0.9);
  return finish;
}

Surface Finished(Surface surface, const std::string& name, const Finish& finish) {
  surface.name = name;
  surface.reflectance = finish.reflectance;
  surface.desired.srgb = finish.desired;
  return surface;
}

// A convex planar polygon as a quad (4 corners) or a fan of triangles, its corners given
// counter-clockwise seen from the lit side.
Surface Polygon(const std::vector<Vec3>& corners) {
  Surface surface;
  if (corners.size() == 4) {
    surface.kind = Surface::Kind::kQuad;
    for (int k = 0; k < 4; ++k) surface.quad[k] = corners[k];
    return surface;
  }
  surface.kind = Surface::Kind::kMesh;
  surface.mesh_vertices = corners;
  for (size_t k = 1; k + 1 < corners.size(); ++k)
    surface.mesh_triangles.push_back({{0, static_cast<int>(k), static_cast<int>(k + 1)},
                                      {Vec2(0, 0), Vec2(0, 0), Vec2(0, 0)}});
  return surface;
}

// The polygon's lit side made to face `towards` (a direction).
Surface PolygonFacing(std::vector<Vec3> corners, const Vec3& towards) {
  const Vec3 normal = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
  if (normal.dot(towards) < 0.0) std::reverse(corners.begin(), corners.end());
  return Polygon(corners);
}

// The vertical rectangle over segment a → b from height z0 to z1, lit towards `towards`.
Surface VerticalQuad(const Vec3& a, const Vec3& b, double z0, double z1, const Vec3& towards) {
  return PolygonFacing({a + z0 * kUp, b + z0 * kUp, b + z1 * kUp, a + z1 * kUp}, towards);
}

// Left of the direction d in the floor's plane (the inside of a counter-clockwise outline).
Vec3 LeftOf(const Vec3& d) { return Vec3(-d.y(), d.x(), 0.0).normalized(); }

double CornerAngleDeg(const Vec3& previous, const Vec3& corner, const Vec3& next) {
  const Vec3 a = (previous - corner).normalized(), b = (next - corner).normalized();
  return std::acos(std::clamp(a.dot(b), -1.0, 1.0)) * 180.0 / kPi;
}

// The floor plan: corners counter-clockwise from the front right (W, 0) round the back to the
// front left (0, 0); the front edge between the last and the first is open. Convex, every corner
// between two walls at least 8° from a right angle and at most 165°.
std::vector<Vec3> DrawFloorPlan(Draw& draw, int walls, double width, double depth) {
  for (;;) {
    std::vector<Vec3> corners = {Vec3(width, 0, 0)};
    for (int k = 1; k < walls; ++k) {
      const double angle = kPi * (k + draw.Uniform(-0.3, 0.3)) / walls;
      const double scale = draw.Uniform(0.85, 1.1);
      corners.push_back(Vec3(0.5 * width * (1.0 + scale * std::cos(angle)),
                             depth * scale * std::sin(angle), 0.0));
    }
    corners.push_back(Vec3(0, 0, 0));
    bool good = true;
    for (int k = 1; k < walls && good; ++k) {
      const Vec3 turn = (corners[k] - corners[k - 1]).cross(corners[k + 1] - corners[k]);
      const double angle = CornerAngleDeg(corners[k - 1], corners[k], corners[k + 1]);
      good = turn.z() > 0.0 && std::abs(angle - 90.0) >= 8.0 && angle <= 165.0;
    }
    // The first and last walls leave the open front at angles other than 90° too, and the
    // walls are at least 1 m long.
    for (int k = 0; k < walls && good; ++k) good = (corners[k + 1] - corners[k]).norm() >= 1.0;
    if (good) good = std::abs(CornerAngleDeg(Vec3(0, 0, 0), corners[0], corners[1]) - 90.0) >= 8.0;
    if (good)
      good = std::abs(CornerAngleDeg(corners[walls - 1], corners[walls], Vec3(width, 0, 0)) - 90.0) >= 8.0;
    if (good) return corners;
  }
}

// Whether p (floor plane) lies inside the plan at least `margin` from every wall and the front.
bool InsidePlan(const std::vector<Vec3>& plan, const Vec3& p, double margin) {
  if (p.y() < margin) return false;
  for (size_t k = 0; k + 1 < plan.size(); ++k) {
    const Vec3 d = plan[k + 1] - plan[k];
    if (LeftOf(d).dot(p - plan[k]) < margin) return false;
  }
  return true;
}

// Adds surfaces to the scene under a name, with a finish.
struct RoomBuilder {
  Scene* scene;
  void Add(const Surface& surface, const std::string& name, const Finish& finish) {
    scene->surfaces.push_back(Finished(surface, name, finish));
  }
};

// A wall from a to b (inside on its left), `height` high, with an opening from `t0` to `t0 +
// width` along it and from z0 to z1 that leads into a recess `depth` deep whose sides splay
// inwards by `splay_deg` (so they meet the wall at other than 90°). z0 = 0: an alcove, whose
// floor continues the room's floor. The wall's pieces round the opening are coplanar: one wall.
struct Recess {
  double t0 = 0, width = 0, z0 = 0, z1 = 0, depth = 0, splay_deg = 0;
};
void AddWall(RoomBuilder& room, const std::string& name, const Vec3& a, const Vec3& b, double height,
             const Finish& finish, const Recess* recess, Draw& draw) {
  const Vec3 inside = LeftOf(b - a);
  if (!recess) {
    room.Add(VerticalQuad(a, b, 0.0, height, inside), name, finish);
    return;
  }
  const Vec3 along = (b - a).normalized();
  const Vec3 p0 = a + recess->t0 * along, p1 = p0 + recess->width * along;
  const double narrowing = recess->depth * std::tan(recess->splay_deg * kPi / 180.0);
  const Vec3 q0 = p0 - recess->depth * inside + narrowing * along;
  const Vec3 q1 = p1 - recess->depth * inside - narrowing * along;
  const double z0 = recess->z0, z1 = recess->z1;
  room.Add(VerticalQuad(a, p0, 0.0, height, inside), name + " left of opening", finish);
  room.Add(VerticalQuad(p1, b, 0.0, height, inside), name + " right of opening", finish);
  room.Add(VerticalQuad(p0, p1, z1, height, inside), name + " above opening", finish);
  if (z0 > 0.0) room.Add(VerticalQuad(p0, p1, 0.0, z0, inside), name + " below opening", finish);
  const std::string kind = z0 > 0.0 ? " recess" : " alcove";
  const Finish inner = DrawFinish(draw);
  const Vec3 middle = 0.25 * (p0 + p1 + q0 + q1);
  room.Add(VerticalQuad(q0, q1, z0, z1, inside), name + kind + " back", inner);
  room.Add(VerticalQuad(p0, q0, z0, z1, middle - p0), name + kind + " left side", inner);
  room.Add(VerticalQuad(q1, p1, z0, z1, middle - p1), name + kind + " right side", inner);
  const std::vector<Vec3> bottom = {p0 + z0 * kUp, p1 + z0 * kUp, q1 + z0 * kUp, q0 + z0 * kUp};
  std::vector<Vec3> top = bottom;
  for (Vec3& corner : top) corner.z() = z1;
  if (z0 > 0.0) room.Add(PolygonFacing(bottom, kUp), name + kind + " sill", inner);
  room.Add(PolygonFacing(top, -kUp), name + kind + " top", inner);
}

// The floor of an alcove continues the room's: returned so it can take the floor's finish.
std::vector<Vec3> AlcoveFloor(const Vec3& a, const Vec3& b, const Recess& recess) {
  const Vec3 inside = LeftOf(b - a), along = (b - a).normalized();
  const Vec3 p0 = a + recess.t0 * along, p1 = p0 + recess.width * along;
  const double narrowing = recess.depth * std::tan(recess.splay_deg * kPi / 180.0);
  return {p0, p1, p1 - recess.depth * inside - narrowing * along,
          p0 - recess.depth * inside + narrowing * along};
}

// An upright prism: the outline `corners` (counter-clockwise seen from above) raised to
// `height`, its sides lit outwards, with its top when `top` is set.
void AddPrism(RoomBuilder& room, const std::string& name, const std::vector<Vec3>& corners,
              double height, bool top, const Finish& finish) {
  Vec3 centre = Vec3::Zero();
  for (const Vec3& c : corners) centre += c / corners.size();
  for (size_t k = 0; k < corners.size(); ++k) {
    const Vec3& a = corners[k];
    const Vec3& b = corners[(k + 1) % corners.size()];
    room.Add(VerticalQuad(a, b, 0.0, height, 0.5 * (a + b) - centre), fmt::format("{} side {}", name, k + 1),
             finish);
  }
  if (top) {
    std::vector<Vec3> lid = corners;
    for (Vec3& c : lid) c.z() = height;
    room.Add(PolygonFacing(lid, kUp), name + " top", finish);
  }
}

// A round column as a mesh of `segments` flat strips, lit outwards.
Surface RoundColumn(const Vec3& centre, double radius, double height, int segments) {
  Surface surface;
  surface.kind = Surface::Kind::kMesh;
  for (int k = 0; k <= segments; ++k) {
    const double angle = 2.0 * kPi * k / segments;
    const Vec3 p = centre + radius * Vec3(std::cos(angle), std::sin(angle), 0.0);
    surface.mesh_vertices.push_back(p);
    surface.mesh_vertices.push_back(p + height * kUp);
  }
  surface.mesh_vertices.resize(2 * segments);  // the seam's vertices are the first two
  for (int k = 0; k < segments; ++k) {
    const int b0 = 2 * k, t0 = 2 * k + 1, b1 = (2 * k + 2) % (2 * segments), t1 = (2 * k + 3) % (2 * segments);
    const double u0 = double(k) / segments, u1 = double(k + 1) / segments;
    // Counter-clockwise seen from outside: b0 → b1 → t1 and b0 → t1 → t0.
    surface.mesh_triangles.push_back({{b0, b1, t1}, {Vec2(u0, 0), Vec2(u1, 0), Vec2(u1, 1)}});
    surface.mesh_triangles.push_back({{b0, t1, t0}, {Vec2(u0, 0), Vec2(u1, 1), Vec2(u0, 1)}});
  }
  return surface;
}

Vec3 Turned(double angle, double x, double y) {
  return Vec3(std::cos(angle) * x - std::sin(angle) * y, std::sin(angle) * x + std::cos(angle) * y, 0.0);
}

// A free-standing object: what it is, its drawn sizes, and the radius of its footprint (the
// circle about its centre it stands within), which placing it keeps clear of walls and others.
// Its front faces −y (the audience) turned by `facing` radians.
enum class ObjectKind { kBox, kPlinth, kRoundColumn, kPolygonalColumn, kSlantedPanel, kSteps };

struct Object {
  ObjectKind kind;
  double radius = 0.0;  // of its footprint, metres
  // Drawn sizes.
  double a = 0, b = 0, height = 0, facing = 0, tilt_deg = 0;
  int sides = 0;
};

Object DrawObject(Draw& draw, double room_height) {
  Object object;
  object.kind = static_cast<ObjectKind>(draw.Integer(0, 5));
  object.facing = draw.Uniform(-0.5, 0.5);
  switch (object.kind) {
    case ObjectKind::kBox:
    case ObjectKind::kPlinth:
      object.a = draw.Uniform(0.2, 0.45);
      object.b = draw.Uniform(0.2, 0.45);
      object.height = object.kind == ObjectKind::kBox ? draw.Uniform(0.7, 1.4) : draw.Uniform(0.2, 0.6);
      object.radius = std::hypot(object.a, object.b);
      break;
    case ObjectKind::kRoundColumn:
      object.a = draw.Uniform(0.15, 0.35);
      object.height = room_height;
      object.radius = object.a;
      break;
    case ObjectKind::kPolygonalColumn:
      object.sides = draw.Integer(5, 8);
      object.a = draw.Uniform(0.2, 0.4);
      object.height = room_height;
      object.radius = object.a;
      break;
    case ObjectKind::kSlantedPanel:
      object.a = draw.Uniform(0.4, 0.8);   // half width
      object.b = draw.Uniform(1.0, 1.6);   // length up the slope
      object.tilt_deg = draw.Uniform(25.0, 55.0);  // from the vertical, leaning away
      object.radius = std::hypot(object.a, object.b * std::sin(object.tilt_deg * kPi / 180.0));
      break;
    case ObjectKind::kSteps:
      object.sides = draw.Integer(2, 3);   // steps
      object.a = draw.Uniform(0.4, 0.75);  // half width
      object.b = draw.Uniform(0.25, 0.4);  // tread depth
      object.height = draw.Uniform(0.15, 0.22);  // riser
      object.radius = std::hypot(object.a, 0.5 * object.sides * object.b);
      break;
  }
  return object;
}

void AddObject(RoomBuilder& room, const Object& object, const Vec3& centre, int index, Draw& draw) {
  const Finish finish = DrawFinish(draw);
  const double f = object.facing;
  switch (object.kind) {
    case ObjectKind::kBox:
    case ObjectKind::kPlinth: {
      const std::string name = fmt::format("{} {}", object.kind == ObjectKind::kBox ? "box" : "plinth", index);
      AddPrism(room, name,
               {centre + Turned(f, -object.a, -object.b), centre + Turned(f, object.a, -object.b),
                centre + Turned(f, object.a, object.b), centre + Turned(f, -object.a, object.b)},
               object.height, true, finish);
      break;
    }
    case ObjectKind::kRoundColumn:
      room.Add(RoundColumn(centre, object.a, object.height, 24), fmt::format("round column {}", index),
               finish);
      break;
    case ObjectKind::kPolygonalColumn: {
      std::vector<Vec3> corners;
      for (int k = 0; k < object.sides; ++k)
        corners.push_back(centre + Turned(f + 2.0 * kPi * k / object.sides, object.a, 0.0));
      AddPrism(room, fmt::format("column {}", index), corners, object.height, false, finish);
      break;
    }
    case ObjectKind::kSlantedPanel: {
      // Bottom edge on the floor, the panel leaning away from the audience; front and back 3 cm
      // apart.
      const double tilt = object.tilt_deg * kPi / 180.0;
      const Vec3 across = Turned(f, 1.0, 0.0), back = Turned(f, 0.0, 1.0);
      const Vec3 slope = object.b * (std::sin(tilt) * back + std::cos(tilt) * kUp);
      const Vec3 bottom = centre - 0.5 * std::sin(tilt) * object.b * back;
      const Vec3 l = bottom - object.a * across, r = bottom + object.a * across;
      room.Add(PolygonFacing({l, r, r + slope, l + slope}, -back), fmt::format("slanted panel {} front", index),
               finish);
      const Vec3 shift = 0.03 * back;
      room.Add(PolygonFacing({l + shift, r + shift, r + slope + shift, l + slope + shift}, back),
               fmt::format("slanted panel {} back", index), finish);
      break;
    }
    case ObjectKind::kSteps: {
      const int steps = object.sides;
      const Vec3 across = Turned(f, 1.0, 0.0), back = Turned(f, 0.0, 1.0);
      const Vec3 start = centre - 0.5 * steps * object.b * back;  // front edge's middle
      const Vec3 l = start - object.a * across, r = start + object.a * across;
      const std::string name = fmt::format("steps {}", index);
      for (int s = 0; s < steps; ++s) {
        const Vec3 d0 = s * object.b * back, d1 = (s + 1) * object.b * back;
        const double z0 = s * object.height, z1 = (s + 1) * object.height;
        room.Add(VerticalQuad(l + d0, r + d0, z0, z1, -back), fmt::format("{} riser {}", name, s + 1), finish);
        room.Add(PolygonFacing({l + d0 + z1 * kUp, r + d0 + z1 * kUp, r + d1 + z1 * kUp, l + d1 + z1 * kUp}, kUp),
                 fmt::format("{} tread {}", name, s + 1), finish);
        room.Add(VerticalQuad(l + d0, l + d1, 0.0, z1, -across), fmt::format("{} left {}", name, s + 1), finish);
        room.Add(VerticalQuad(r + d0, r + d1, 0.0, z1, across), fmt::format("{} right {}", name, s + 1), finish);
      }
      const Vec3 d = steps * object.b * back;
      room.Add(VerticalQuad(l + d, r + d, 0.0, steps * object.height, back), name + " back", finish);
      break;
    }
  }
}

// Projectors and camera near the open front, inside the plan, looking in.
void DrawPlacements(Draw& draw, const std::vector<Vec3>& plan, double width, double depth, double height,
                    int projectors, SyntheticScene* synthetic) {
  synthetic->projectors.clear();
  for (int k = 0; k < projectors; ++k) {
    const double share = projectors == 2 ? (k == 0 ? 0.3 : 0.7) : 0.2 + 0.3 * k;
    Vec3 centre;
    int attempts = 0;
    do {
      const double x = width * (attempts++ < 100 ? share + draw.Uniform(-0.08, 0.08) : 0.5);
      const double y = draw.Uniform(0.15, 0.5);
      const double z = std::min(height - 0.15, draw.Uniform(2.2, 2.6));
      centre = Vec3(x, y, z);
    } while (!InsidePlan(plan, Vec3(centre.x(), centre.y(), 0.0), 0.1));
    // Aimed across the room, as installations cross their beams.
    const double tx = width * (1.0 - share + draw.Uniform(-0.1, 0.1));
    const double ty = depth * draw.Uniform(0.55, 0.8);
    const double tz = draw.Uniform(0.3, 0.8);
    synthetic->projectors.push_back(
        MakeDevicePlacement(fmt::format("projector{}", k + 1), centre, Vec3(tx, ty, tz), 72.0, 1280, 800));
  }
  Vec3 centre;
  int attempts = 0;
  do {
    const double x = width * (attempts++ < 100 ? draw.Uniform(0.38, 0.62) : 0.5);
    const double y = draw.Uniform(0.15, 0.5);
    const double z = draw.Uniform(1.6, 2.0);
    centre = Vec3(x, y, z);
  } while (!InsidePlan(plan, Vec3(centre.x(), centre.y(), 0.0), 0.1));
  const double tx = width * draw.Uniform(0.42, 0.58);
  const double ty = depth * draw.Uniform(0.6, 0.8);
  const double tz = draw.Uniform(0.2, 0.6);
  synthetic->camera = MakeDevicePlacement("camera", centre, Vec3(tx, ty, tz), 80.0, 960, 640);
}

double Coverage(const SyntheticScene& synthetic) {
  const RoomModel truth(synthetic.scene);
  const RayScene rays(synthetic.scene);
  std::vector<ProjectorGeometry> projectors;
  for (const DevicePlacement& p : synthetic.projectors) projectors.push_back(ProjectorFromPlacement(p).geometry);
  const CameraGeometry camera = CameraFromPlacement(synthetic.camera);
  double seen = 0.0, area = 0.0;
  for (size_t s = 0; s < synthetic.scene.surfaces.size(); ++s) {
    if (synthetic.scene.surfaces[s].name == "ceiling") continue;
    seen += SeenAndLitArea(truth, rays, static_cast<int>(s), camera, projectors, 0.05);
    area += synthetic.scene.surfaces[s].Area();
  }
  return seen / area;
}

}  // namespace

OptionTable& DeclareSeedOption(OptionTable* table, const std::string& name, uint64_t* seed,
                               const std::string& help) {
  return table->Custom(
      name, [seed] { return std::to_string(*seed); },
      [seed](const std::string& text, std::string* why) {
        uint64_t value = 0;
        const char* end = text.data() + text.size();
        const auto [last, error] = std::from_chars(text.data(), end, value);
        if (error != std::errc() || last != end) {
          *why = "expected a whole number in [0, 2^64), got '" + text + "'";
          return false;
        }
        *seed = value;
        return true;
      },
      "whole number in [0, 2^64)", help);
}

void RandomRoomOptions::Declare(OptionTable* table) {
  DeclareSeedOption(table, "seed", &seed, "the seed: the same seed gives the same room")
      .Required()
      .Integer("patches", &patches, 1, std::numeric_limits<int>::max(), "",
               "the scene file's patch target");
}

bool RandomRoomOptions::Check(std::string* why) const {
  if (patches < 1) {
    *why = fmt::format("patches must be at least 1, got {}", patches);
    return false;
  }
  if (placement_candidates < 1) {
    *why = fmt::format("placement_candidates must be at least 1, got {}", placement_candidates);
    return false;
  }
  return true;
}

RandomRoom MakeRandomRoom(const RandomRoomOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("random room: " + why);
  Draw draw(options.seed);
  RandomRoom room;
  room.name = fmt::format("random_{}", options.seed);
  Scene& scene = room.synthetic.scene;
  scene.name = room.name;
  scene.target_patches = options.patches;
  scene.white = 1.0;
  RoomBuilder builder{&scene};

  const int walls = draw.Integer(4, 7);
  const double width = draw.Uniform(3.5, 6.0);
  const double depth = draw.Uniform(3.0, 5.0);
  const double height = draw.Uniform(2.4, 3.2);
  const bool ceiling = draw.Chance(0.35);
  const int projectors = draw.Integer(2, 3);
  const std::vector<Vec3> plan = DrawFloorPlan(draw, walls, width, depth);
  room.walls = walls;

  // Recesses and alcoves: up to two, in walls at least 1.8 m long, not the same wall twice.
  const int recesses = draw.Integer(0, 2);
  std::vector<std::optional<Recess>> recess_of_wall(walls);
  int made = 0, alcoves = 0;
  for (int r = 0; r < recesses; ++r) {
    const int wall = draw.Integer(0, walls - 1);
    const double length = (plan[wall + 1] - plan[wall]).norm();
    const bool alcove = draw.Chance(0.5);
    Recess recess;
    recess.width = draw.Uniform(0.6, 1.4);
    recess.t0 = draw.Uniform(0.3, std::max(0.3, length - 0.3 - recess.width));
    recess.depth = draw.Uniform(0.25, 0.6);
    recess.splay_deg = draw.Uniform(8.0, 20.0);
    recess.z0 = alcove ? 0.0 : draw.Uniform(0.5, 1.0);
    recess.z1 = alcove ? draw.Uniform(1.8, height - 0.3) : recess.z0 + draw.Uniform(0.6, 1.0);
    if (recess_of_wall[wall] || recess.t0 + recess.width > length - 0.3) continue;
    recess_of_wall[wall] = recess;
    ++made;
    if (alcove) ++alcoves;
  }

  const Finish floor_finish = DrawFinish(draw);
  {
    Surface floor = Polygon(plan);  // counter-clockwise from above: lit upwards
    builder.Add(floor, "floor", floor_finish);
  }
  for (int k = 0; k < walls; ++k) {
    const Finish finish = DrawFinish(draw);
    const Recess* recess = recess_of_wall[k] ? &*recess_of_wall[k] : nullptr;
    const std::string name = fmt::format("wall {}", k + 1);
    AddWall(builder, name, plan[k], plan[k + 1], height, finish, recess, draw);
    if (recess && recess->z0 == 0.0)
      builder.Add(PolygonFacing(AlcoveFloor(plan[k], plan[k + 1], *recess), kUp), name + " alcove floor",
                  floor_finish);
  }
  if (ceiling) {
    std::vector<Vec3> lid = plan;
    for (Vec3& c : lid) c.z() = height;
    builder.Add(PolygonFacing(lid, -kUp), "ceiling", DrawFinish(draw));
  }

  // Free-standing objects, in the back two thirds of the room, apart from each other.
  const int objects = draw.Integer(1, 3);
  std::vector<std::pair<Vec3, double>> footprints;
  std::vector<std::string> kinds;
  const double far = std::max_element(plan.begin(), plan.end(), [](const Vec3& a, const Vec3& b) {
                       return a.y() < b.y();
                     })->y();
  for (int i = 0; i < objects; ++i) {
    const Object object = DrawObject(draw, height);
    for (int attempt = 0; attempt < 200; ++attempt) {
      const double x = draw.Uniform(0.0, width);
      const double y = draw.Uniform(0.35 * far, far);
      const Vec3 centre(x, y, 0.0);
      if (centre.y() < 1.3 || !InsidePlan(plan, centre, object.radius + 0.3)) continue;
      bool apart = true;
      for (const auto& [other, radius] : footprints)
        apart = apart && (other - centre).norm() > radius + object.radius + 0.3;
      if (!apart) continue;
      footprints.emplace_back(centre, object.radius);
      AddObject(builder, object, centre, static_cast<int>(footprints.size()), draw);
      static const char* kNames[] = {"box", "plinth", "round column", "polygonal column", "slanted panel", "steps"};
      kinds.push_back(kNames[static_cast<int>(object.kind)]);
      break;
    }
  }

  // The placements: the best of the candidates by the share of the room seen and lit.
  SyntheticScene best;
  room.coverage = -1.0;
  for (int c = 0; c < options.placement_candidates; ++c) {
    SyntheticScene candidate = room.synthetic;
    DrawPlacements(draw, plan, width, far, height, projectors, &candidate);
    const double coverage = Coverage(candidate);
    if (coverage > room.coverage) {
      room.coverage = coverage;
      best = candidate;
    }
  }
  room.synthetic = best;
  ValidateScene(room.synthetic.scene);
  room.description = fmt::format(
      "{}: {} walls ({:.1f} × {:.1f} m, {:.2f} m high{}), {} recess{} ({} alcove{}), objects: {}; {} projectors; "
      "{:.0f}% of the area seen and lit",
      room.name, walls, width, far, height, ceiling ? ", ceiling" : "", made, made == 1 ? "" : "es", alcoves,
      alcoves == 1 ? "" : "s", kinds.empty() ? std::string("none") : fmt::format("{}", fmt::join(kinds, ", ")),
      projectors, 100.0 * room.coverage);
  return room;
}

std::filesystem::path WriteRandomRoom(const RandomRoomOptions& options, const std::filesystem::path& dir) {
  const RandomRoom room = MakeRandomRoom(options);
  return WriteSyntheticSceneFile(room.synthetic, room.name,
                                 fmt::format("made at random by procam scene random --seed {}: {}",
                                             options.seed, room.description),
                                 dir);
}

}  // namespace procam
