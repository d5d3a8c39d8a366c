#include "compensation/problem.h"

#include <nlohmann/json.hpp>
#include <gtest/gtest.h>

#include "datasets_synthetic/rooms.h"
#include "geometry/form_factors.h"
#include "base/io.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

TEST(ExportProblem, WritesEveryArrayWithDesignShapes) {
  BoxRoomOptions room;
  room.target_patches = 120;
  Scene scene = MakeBoxRoom(room);
  scene.surfaces[1].desired.srgb = Vec3::Ones();  // a white ceiling → L* = 100, a* = b* = 0
  scene.white = 0.8;
  scene.bounds.upper = Vec3::Constant(0.8);
  SubdivisionOptions subdivision;
  subdivision.target_patches = room.target_patches;
  const PatchHierarchy h = SubdividePatches(scene, subdivision);
  Eigen::MatrixXd f = ComputeFormFactors(scene, h.fine, FormFactorOptions(), nullptr);
  const CompensationProblem problem = MakeProblem(scene, h.fine, f, 0.3);
  EXPECT_EQ(problem.Validate(), "");
  testing::TempDir dir;
  ExportProblem(problem, h.fine, h.coarse_of_fine, dir / "out", R"({"scene": "box"})");
  const int64_t n = h.fine.size();
  const std::map<std::string, std::vector<int64_t>> shapes = {
      {"F", {n, n}},          {"area", {n}},         {"rho", {n, 3}},    {"centroid", {n, 3}},
      {"normal", {n, 3}},     {"surface", {n}},      {"lower", {n, 3}},  {"upper", {n, 3}},
      {"desired_lab", {n, 3}}, {"T", {3, 3}},        {"white_xyz", {3}}, {"parent", {n}},
      {"adjacency", {static_cast<int64_t>(h.fine.adjacency.size()), 2}}};
  for (const auto& [name, shape] : shapes) {
    const NpyArray array = ReadNpy(dir / "out" / (name + ".npy"));
    EXPECT_EQ(array.shape, shape) << name;
  }
  const NpyArray exported_f = ReadNpy(dir / "out" / "F.npy");
  EXPECT_EQ(exported_f.values[1], f(0, 1));  // C order
  EXPECT_EQ(exported_f.values[n], f(1, 0));
  const NpyArray lab = ReadNpy(dir / "out" / "desired_lab.npy");
  const NpyArray surface = ReadNpy(dir / "out" / "surface.npy");
  for (int64_t i = 0; i < n; ++i) {
    if (surface.values[i] != 1) continue;
    EXPECT_NEAR(lab.values[3 * i], 100.0, 1e-9);
    EXPECT_NEAR(lab.values[3 * i + 1], 0.0, 1e-9);
    EXPECT_NEAR(lab.values[3 * i + 2], 0.0, 1e-9);
  }
  const NpyArray white = ReadNpy(dir / "out" / "white_xyz.npy");
  EXPECT_NEAR(white.values[1], 0.8, 1e-12);  // Yn = w for sRGB primaries
  const nlohmann::json meta = nlohmann::json::parse(ReadFile(dir / "out" / "problem.json"));
  EXPECT_EQ(meta["alpha"], 0.3);
  EXPECT_EQ(meta["scene"], "box");
  EXPECT_EQ(meta["patches"], n);
}

TEST(CompensationProblem, ValidateNamesTheProblem) {
  BoxRoomOptions room;
  room.target_patches = 40;
  const Scene scene = MakeBoxRoom(room);
  SubdivisionOptions subdivision;
  subdivision.target_patches = 40;
  const PatchHierarchy h = SubdividePatches(scene, subdivision);
  CompensationProblem problem = MakeProblem(scene, h.fine, Eigen::MatrixXd::Zero(h.fine.size(), h.fine.size()), 0.5);
  EXPECT_EQ(problem.Validate(), "");
  problem.lower(3, 1) = 2.0;
  EXPECT_NE(problem.Validate().find("lower > upper"), std::string::npos);
  problem.lower(3, 1) = 0.0;
  problem.desired(0, 0) = std::nan("");
  EXPECT_NE(problem.Validate().find("NaN"), std::string::npos);
  problem.desired(0, 0) = 0.5;
  problem.alpha = 0.0;
  EXPECT_NE(problem.Validate().find("alpha"), std::string::npos);
}

}  // namespace
}  // namespace procam
