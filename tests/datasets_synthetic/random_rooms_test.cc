// Rooms made at random: the same seed gives the same files; the written file is a rig; walls meet
// at other than 90°; the projectors and the camera stand inside the room; the share of the room
// seen and lit, recomputed from the written file, is what the generator reports.
#include "datasets_synthetic/random_rooms.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <regex>

#include "base/io.h"
#include "calibration/registration.h"
#include "datasets_synthetic/rooms.h"
#include "datasets_synthetic/scan_accuracy.h"
#include "datasets_synthetic/scan_judge.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "geometry/ray_scene.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::map<std::string, std::string> FilesIn(const std::filesystem::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    files[entry.path().filename().string()] = ReadFile(entry.path());
  return files;
}

// Whether p lies over the floor (inside one of its triangles, seen from above).
bool OverFloor(const Surface& floor, const Vec3& p) {
  for (const MeshTriangle& t : floor.mesh_triangles) {
    bool inside = true;
    for (int k = 0; k < 3 && inside; ++k) {
      const Vec3& a = floor.mesh_vertices[t.vertex[k]];
      const Vec3& b = floor.mesh_vertices[t.vertex[(k + 1) % 3]];
      inside = (b - a).cross(p - a).z() >= 0.0;
    }
    if (inside) return true;
  }
  return false;
}

Vec3 QuadNormal(const Surface& surface) {
  return (surface.quad[1] - surface.quad[0]).cross(surface.quad[3] - surface.quad[0]).normalized();
}

TEST(RandomRoom, TheSameSeedWritesTheSameFiles) {
  const testing::TempDir temp;
  RandomRoomOptions options;
  options.seed = 7;
  const std::filesystem::path a = WriteRandomRoom(options, temp.path() / "a");
  WriteRandomRoom(options, temp.path() / "b");
  EXPECT_EQ(a.filename(), "random_7.json");
  const auto files_a = FilesIn(temp.path() / "a"), files_b = FilesIn(temp.path() / "b");
  EXPECT_EQ(files_a, files_b);
  EXPECT_GE(files_a.size(), 4u);  // the scene, the camera's and at least two projectors' models
  options.seed = 8;
  WriteRandomRoom(options, temp.path() / "c");
  EXPECT_NE(ReadFile(temp.path() / "c" / "random_8.json"), files_a.at("random_7.json"));

  options.patches = 0;
  EXPECT_THROW(MakeRandomRoom(options), std::invalid_argument);
}

class RandomRoomSeed : public ::testing::TestWithParam<int> {};

TEST_P(RandomRoomSeed, IsARigWhoseWallsAreNotSquareAndWhoseDevicesStandInside) {
  const testing::TempDir temp;
  RandomRoomOptions options;
  options.seed = GetParam();
  const RandomRoom room = MakeRandomRoom(options);
  std::printf("%s\n", room.description.c_str());
  const std::filesystem::path path = WriteRandomRoom(options, temp.path());
  const SyntheticRigSource rig = LoadSceneFileRig(path, "", 300);
  const Scene& scene = rig.scene;
  ASSERT_EQ(scene.surfaces.size(), room.synthetic.scene.surfaces.size());
  EXPECT_GE(rig.projectors.size(), 2u);
  EXPECT_LE(rig.projectors.size(), 3u);

  // The floor plan's walls: 4–7, each neighbour at least 8° from a right angle (the generator's
  // margin), and so are a recess's sides to its wall.
  std::map<int, Vec3> wall_normal;
  double height = 0.0;
  const std::regex wall_name(R"(wall (\d+)( left of opening)?)");
  for (const Surface& surface : scene.surfaces) {
    std::smatch match;
    if (surface.kind == Surface::Kind::kQuad && std::regex_match(surface.name, match, wall_name)) {
      wall_normal[std::stoi(match[1])] = QuadNormal(surface);
      for (const Vec3& c : surface.quad) height = std::max(height, c.z());
    }
  }
  EXPECT_EQ(static_cast<int>(wall_normal.size()), room.walls);
  EXPECT_GE(room.walls, 4);
  EXPECT_LE(room.walls, 7);
  const double sin8 = std::sin(8.0 * kPi / 180.0);
  for (int k = 1; k < room.walls; ++k) {
    EXPECT_NEAR(wall_normal[k].z(), 0.0, 1e-9);
    EXPECT_GT(std::abs(wall_normal[k].dot(wall_normal[k + 1])), sin8) << "walls " << k << " and " << k + 1;
  }
  for (const Surface& surface : scene.surfaces) {
    std::smatch match;
    if (!std::regex_match(surface.name, match, std::regex(R"(wall (\d+) (recess|alcove) (left|right) side)"))) continue;
    EXPECT_GT(std::abs(QuadNormal(surface).dot(wall_normal[std::stoi(match[1])])), sin8) << surface.name;
  }

  // Inside: over the floor, below the walls' top.
  const Surface& floor = scene.surfaces.front();
  ASSERT_EQ(floor.name, "floor");
  std::vector<Vec3> centres = {rig.camera.CentreInWorld()};
  for (const Projector& p : rig.projectors) centres.push_back(p.geometry.CentreInWorld());
  for (const Vec3& c : centres) {
    EXPECT_TRUE(OverFloor(floor, c)) << c.transpose();
    EXPECT_GT(c.z(), 0.0);
    EXPECT_LT(c.z(), height);
  }

  // The share seen and lit, from the written file (its camera and projectors read back), as the
  // generator computed it from its placements.
  const RoomModel truth(scene);
  const RayScene rays(scene);
  std::vector<ProjectorGeometry> projectors;
  for (const Projector& p : rig.projectors) projectors.push_back(p.geometry);
  double seen = 0.0, area = 0.0;
  for (size_t s = 0; s < scene.surfaces.size(); ++s) {
    if (scene.surfaces[s].name == "ceiling") continue;
    seen += SeenAndLitArea(truth, rays, static_cast<int>(s), rig.camera, projectors, 0.05);
    area += scene.surfaces[s].Area();
  }
  EXPECT_NEAR(seen / area, room.coverage, 1e-3);
  // What the placement reaches (measured over seeds 1–20: 24–45%): a fifth of the room at least.
  EXPECT_GT(seen / area, 0.2);
}

INSTANTIATE_TEST_SUITE_P(Seeds, RandomRoomSeed, ::testing::Values(1, 2, 3, 4, 5));

// Coplanar pieces that touch are one physical surface; coplanar pieces apart, or touching
// pieces at an angle, are not.
TEST(PhysicalSurfaces, CoplanarPiecesThatTouchAreOneSurface) {
  Scene scene;
  const auto rectangle = [&](const char* name, const Vec3& origin, const Vec3& u, const Vec3& v) {
    Surface surface = MakeRectangle(origin, u, v, 0.9, Vec3(0.5, 0.5, 0.5));
    surface.name = name;
    scene.surfaces.push_back(surface);
  };
  const Vec3 x = Vec3::UnitX(), z = Vec3::UnitZ();
  // A wall 4 m long split round an opening from 1.5 to 2.5 m and 0.8 to 1.8 m high.
  rectangle("left", Vec3(0, 0, 0), 2.5 * z, 1.5 * x);
  rectangle("right", Vec3(2.5, 0, 0), 2.5 * z, 1.5 * x);
  rectangle("below", Vec3(1.5, 0, 0), 0.8 * z, 1.0 * x);
  rectangle("above", Vec3(1.5, 0, 1.8), 0.7 * z, 1.0 * x);
  // The opening's back 30 cm behind (parallel, not coplanar), a wall in the same plane 1 m
  // beyond the right piece (coplanar, apart), and the floor (touching, at 90°).
  rectangle("back", Vec3(1.5, 0.3, 0.8), 1.0 * z, 1.0 * x);
  rectangle("far", Vec3(5.0, 0, 0), 2.5 * z, 1.0 * x);
  rectangle("floor", Vec3(0, 0, 0), 4.0 * x, 3.0 * Vec3::UnitY());
  const std::vector<std::vector<int>> groups = PhysicalSurfaces(scene);
  ASSERT_EQ(groups.size(), 4u);
  EXPECT_EQ(groups[0], (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(groups[1], (std::vector<int>{4}));
  EXPECT_EQ(groups[2], (std::vector<int>{5}));
  EXPECT_EQ(groups[3], (std::vector<int>{6}));
}

}  // namespace
}  // namespace procam
