#include "geometry/patches.h"

#include <map>
#include <set>

#include <gtest/gtest.h>

#include "datasets_synthetic/rooms.h"

namespace procam {
namespace {

TEST(SubdividePatches, HitsTheTargetWithSimilarAreas) {
  for (const int target : {100, 1000, 4096}) {
    BoxRoomOptions options;
    const Scene scene = MakeBoxRoom(options);
    SubdivisionOptions subdivision;
    subdivision.target_patches = target;
    const PatchHierarchy h = SubdividePatches(scene, subdivision);
    EXPECT_NEAR(h.fine.size(), target, 0.25 * target) << target;
    const Eigen::VectorXd areas = h.fine.Areas();
    EXPECT_NEAR(areas.sum(), scene.Area(), 1e-9 * scene.Area());
    // Small surfaces (the occluder's faces) get at least one coarse patch; from 1000 patches
    // on, every patch is within a factor 3 of every other in area.
    if (target >= 1000) {
      EXPECT_LT(areas.maxCoeff() / areas.minCoeff(), 3.0) << target;
    }
    for (const Patch& patch : h.fine.patches) {
      // Well shaped: no edge more than 3× another.
      double shortest = 1e9, longest = 0;
      for (int k = 0; k < patch.corner_count; ++k) {
        const double length = (patch.corners[(k + 1) % patch.corner_count] - patch.corners[k]).norm();
        shortest = std::min(shortest, length);
        longest = std::max(longest, length);
      }
      ASSERT_LT(longest / shortest, 3.0);
    }
  }
}

TEST(SubdividePatches, CoarsePatchesOwnFourChildrenCoveringThem) {
  const Scene scene = MakeBoxRoom(BoxRoomOptions());
  SubdivisionOptions subdivision;
  subdivision.target_patches = 800;
  const PatchHierarchy h = SubdividePatches(scene, subdivision);
  ASSERT_EQ(h.coarse_of_fine.size(), static_cast<size_t>(h.fine.size()));
  EXPECT_EQ(h.fine.size(), 4 * h.coarse.size());
  std::vector<int> children(h.coarse.size(), 0);
  std::vector<double> child_area(h.coarse.size(), 0.0);
  Eigen::MatrixX3d child_centroid = Eigen::MatrixX3d::Zero(h.coarse.size(), 3);
  for (int i = 0; i < h.fine.size(); ++i) {
    const int parent = h.coarse_of_fine[i];
    ++children[parent];
    child_area[parent] += h.fine.patches[i].area;
    child_centroid.row(parent) += h.fine.patches[i].area * h.fine.patches[i].centroid.transpose();
    EXPECT_EQ(h.fine.patches[i].surface, h.coarse.patches[parent].surface);
  }
  for (int c = 0; c < h.coarse.size(); ++c) {
    EXPECT_EQ(children[c], 4);
    EXPECT_NEAR(child_area[c], h.coarse.patches[c].area, 1e-12);
    EXPECT_LT((child_centroid.row(c).transpose() / child_area[c] - h.coarse.patches[c].centroid).norm(), 1e-12);
  }
}

TEST(FindAdjacency, GridOnOneQuadHasTheClosedFormCount) {
  Scene scene;
  scene.surfaces.push_back(MakeRectangle(Vec3::Zero(), Vec3(3, 0, 0), Vec3(0, 2, 0), 0.5, Vec3::Ones()));
  SubdivisionOptions subdivision;
  subdivision.target_patches = 24;  // 6 coarse → 3×2 coarse, 6×4 fine
  const PatchHierarchy h = SubdividePatches(scene, subdivision);
  ASSERT_EQ(h.fine.size(), 24);
  const int nu = 6, nv = 4;
  EXPECT_EQ(h.fine.adjacency.size(), static_cast<size_t>(2 * nu * nv - nu - nv));
  EXPECT_EQ(h.coarse.adjacency.size(), static_cast<size_t>(2 * 3 * 2 - 3 - 2));
  for (const auto& pair : h.fine.adjacency) {
    EXPECT_LT(pair[0], pair[1]);
    // Neighbours in a grid of 0.5 m cells are 0.5 m apart.
    EXPECT_NEAR((h.fine.patches[pair[0]].centroid - h.fine.patches[pair[1]].centroid).norm(), 0.5, 1e-12);
  }
}

TEST(FindAdjacency, ConnectsSurfacesThatMeetWithDifferentSubdivisions) {
  // A floor and a wall meeting along y ∈ [0, 2]; different sizes give different grids.
  Scene scene;
  scene.surfaces.push_back(MakeRectangle(Vec3::Zero(), Vec3(1, 0, 0), Vec3(0, 2, 0), 0.5, Vec3::Ones()));
  scene.surfaces.push_back(MakeRectangle(Vec3::Zero(), Vec3(0, 2, 0), Vec3(0, 0, 3), 0.5, Vec3::Ones()));
  SubdivisionOptions subdivision;
  subdivision.target_patches = 160;
  const PatchHierarchy h = SubdividePatches(scene, subdivision);
  std::set<int> floor_edge_patches, linked;
  for (int i = 0; i < h.fine.size(); ++i) {
    const Patch& p = h.fine.patches[i];
    if (p.surface == 0 && std::min({p.corners[0].x(), p.corners[1].x(), p.corners[2].x(), p.corners[3].x()}) < 1e-9) {
      floor_edge_patches.insert(i);
    }
  }
  int across = 0;
  for (const auto& pair : h.fine.adjacency) {
    const int a = h.fine.patches[pair[0]].surface, b = h.fine.patches[pair[1]].surface;
    if (a != b) {
      ++across;
      linked.insert(pair[0]);
      // The shared stretch lies on the line x = 0, z = 0.
      const Patch& wall = h.fine.patches[pair[1]];
      EXPECT_EQ(b, 1);
      EXPECT_LT(std::min({wall.corners[0].z(), wall.corners[1].z(), wall.corners[2].z(), wall.corners[3].z()}), 1e-9);
    }
  }
  EXPECT_GT(across, 0);
  EXPECT_EQ(linked, floor_edge_patches);  // every floor patch on the seam has a wall neighbour
}

TEST(SamplePatch, WeightsSumToAreaAndPointsLieInside) {
  Patch quad;
  quad.corner_count = 4;
  quad.corners = {Vec3(0, 0, 0), Vec3(2, 0, 0), Vec3(1.5, 1, 0), Vec3(0.5, 1, 0)};  // trapezoid
  quad.area = 1.5;
  Patch triangle;
  triangle.corner_count = 3;
  triangle.corners = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 1, 0)};
  triangle.area = 0.5;
  std::vector<PatchSample> samples;
  for (const int k : {2, 3, 5}) {
    for (const Patch* patch : {&quad, &triangle}) {
      SamplePatch(*patch, k, &samples);
      ASSERT_EQ(samples.size(), static_cast<size_t>(k * k));
      double total = 0.0;
      Vec3 first_moment = Vec3::Zero();
      for (const PatchSample& sample : samples) {
        total += sample.weight;
        first_moment += sample.weight * sample.point;
        EXPECT_GE(sample.point.y(), 0.0);
      }
      EXPECT_NEAR(total, patch->area, 1e-12);
      // Exact for linear integrands: the first moment is area × centroid.
      const Vec3 centroid = patch == &triangle ? Vec3(1.0 / 3, 1.0 / 3, 0) : Vec3(1.0, 4.0 / 9.0, 0);
      EXPECT_LT((first_moment / total - centroid).norm(), 1e-12) << "k=" << k;
    }
  }
}

TEST(GaussLegendre, IntegratesPolynomialsOfDegreeTwoKMinusOneExactly) {
  for (const int k : {1, 2, 4, 9, 64}) {
    const GaussLegendreRule& rule = GaussLegendre(k);
    const int degree = 2 * k - 1;
    double integral = 0.0, total = 0.0;
    for (int i = 0; i < k; ++i) {
      integral += rule.weights[i] * std::pow(rule.nodes[i], degree);
      total += rule.weights[i];
      EXPECT_GT(rule.nodes[i], 0.0);
      EXPECT_LT(rule.nodes[i], 1.0);
    }
    EXPECT_NEAR(total, 1.0, 1e-13) << k;
    EXPECT_NEAR(integral, 1.0 / (degree + 1), 1e-13) << k;
  }
}

TEST(SubdividePatches, TextureIsAveragedInLinearLight) {
  Scene scene;
  Surface surface = MakeRectangle(Vec3::Zero(), Vec3(1, 0, 0), Vec3(0, 1, 0), 0.5, Vec3::Zero());
  // Left half black, right half white: a patch straddling nothing averages to 0 or 1.
  surface.desired.texture_linear = cv::Mat(1, 64, CV_32FC3, cv::Scalar(0, 0, 0));
  for (int col = 32; col < 64; ++col) surface.desired.texture_linear.at<cv::Vec3f>(0, col) = cv::Vec3f(1, 1, 1);
  scene.surfaces.push_back(surface);
  scene.white = 2.0;
  SubdivisionOptions subdivision;
  subdivision.target_patches = 4;  // 2×2 fine patches
  subdivision.texture_samples = 8;
  const PatchHierarchy h = SubdividePatches(scene, subdivision);
  ASSERT_EQ(h.coarse.size(), 1);
  // The single coarse patch covers both halves: the mean of 0 and white, in linear light.
  EXPECT_NEAR(h.coarse.desired_linear(0, 0), 1.0, 0.02);
  for (int i = 0; i < h.fine.size(); ++i) {
    const double expected = h.fine.patches[i].centroid.x() > 0.5 ? 2.0 : 0.0;
    EXPECT_NEAR(h.fine.desired_linear(i, 1), expected, 0.02);
  }
}

// A printed surface's patches reflect with the texture's mean over each: a texture dark on its
// left half (0.2) and light on its right (0.8), scaled by 0.9, gives the fine patches of either
// half 0.18 or 0.72 and the coarse patch over both their mean, 0.45.
TEST(SubdividePatches, ReflectanceTextureIsAveragedOverEachPatch) {
  Scene scene;
  Surface surface = MakeRectangle(Vec3::Zero(), Vec3(1, 0, 0), Vec3(0, 1, 0), 0.5, Vec3::Zero());
  surface.reflectance_texture.texture_linear = cv::Mat(1, 64, CV_32FC3, cv::Scalar(0.2, 0.2, 0.2));
  for (int col = 32; col < 64; ++col) {
    surface.reflectance_texture.texture_linear.at<cv::Vec3f>(0, col) = cv::Vec3f(0.8, 0.8, 0.8);
  }
  surface.reflectance_texture.scale = 0.9;
  scene.surfaces.push_back(surface);
  SubdivisionOptions subdivision;
  subdivision.target_patches = 4;  // 2×2 fine patches
  subdivision.texture_samples = 8;
  const PatchHierarchy h = SubdividePatches(scene, subdivision);
  ASSERT_EQ(h.coarse.size(), 1);
  ASSERT_EQ(h.fine.size(), 4);
  // The bilinear lookup blurs the step over one texel (1/64 of the width): within 0.01.
  EXPECT_NEAR(h.coarse.reflectance(0, 0), 0.45, 0.01);
  for (int i = 0; i < h.fine.size(); ++i) {
    const double expected = h.fine.patches[i].centroid.x() > 0.5 ? 0.72 : 0.18;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(h.fine.reflectance(i, c), expected, 0.01) << i;
  }
  // A surface without a texture keeps its one reflectance on every patch.
  scene.surfaces[0].reflectance_texture = ReflectanceTexture();
  const PatchHierarchy plain = SubdividePatches(scene, subdivision);
  for (int i = 0; i < plain.fine.size(); ++i) EXPECT_EQ(plain.fine.reflectance(i, 0), 0.5);
}

}  // namespace
}  // namespace procam
