#include "datasets_synthetic/paper_scenes.h"

#include <gtest/gtest.h>

#include "geometry/form_factors.h"
#include "base/io.h"
#include "geometry/patches.h"
#include "geometry/polygon.h"

namespace procam {
namespace {

// Centroid and lit-side normal of a surface (area-weighted over its triangles for meshes).
void SurfaceFrame(const Surface& surface, Vec3* centroid, Vec3* normal) {
  if (surface.kind == Surface::Kind::kQuad) {
    *centroid = PolygonCentroid(surface.quad.data(), 4);
    *normal = NewellNormal(surface.quad.data(), 4).normalized();
    return;
  }
  Vec3 weighted = Vec3::Zero(), sum = Vec3::Zero();
  double area = 0.0;
  for (const MeshTriangle& t : surface.mesh_triangles) {
    const Vec3 p[3] = {surface.mesh_vertices[t.vertex[0]], surface.mesh_vertices[t.vertex[1]],
                       surface.mesh_vertices[t.vertex[2]]};
    const double a = PolygonArea(p, 3);
    weighted += a * (p[0] + p[1] + p[2]) / 3.0;
    sum += NewellNormal(p, 3);
    area += a;
  }
  *centroid = weighted / area;
  *normal = sum.normalized();
}

TEST(SyntheticScenes, AreValidLitFromTheDevicesSideAndWellFormed) {
  for (const std::string& name : SyntheticSceneNames()) {
    const SyntheticScene s = MakeSyntheticScene(name, 400);
    ASSERT_NO_THROW(ValidateScene(s.scene)) << name;
    EXPECT_GE(s.projectors.size(), 2u) << name;
    EXPECT_LE(s.projectors.size(), 6u) << name;
    for (const Surface& surface : s.scene.surfaces) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_GE(surface.reflectance[c], 0.75) << name << " " << surface.name;  // white or light grey
        EXPECT_LT(surface.reflectance[c], 1.0);
      }
      const std::string& n = surface.name;
      if (n.size() > 5 && n.compare(n.size() - 5, 5, " back") == 0) {
        continue;  // the far sides of columns and partitions are lit by bounces only
      }
      // Some projector stands on the lit side (the surface faces the installation).
      Vec3 centroid, normal;
      SurfaceFrame(surface, &centroid, &normal);
      bool faced = false;
      for (const DevicePlacement& projector : s.projectors) faced |= normal.dot(projector.centre - centroid) > 0.0;
      EXPECT_TRUE(faced) << name << ": " << surface.name << " faces away from every projector";
    }
    // Colourful: the desired colours are not all grey.
    double chroma = 0.0;
    for (const Surface& surface : s.scene.surfaces) {
      const Vec3 c = surface.desired.HasTexture() ? surface.desired.LinearAt(Vec2(0.5, 0.5)) : surface.desired.srgb;
      chroma = std::max(chroma, c.maxCoeff() - c.minCoeff());
    }
    EXPECT_GT(chroma, 0.3) << name;
    // Open rooms: light escapes, but every row sum stays at most 1.
    SubdivisionOptions subdivision;
    subdivision.target_patches = 200;
    const PatchHierarchy patches = SubdividePatches(s.scene, subdivision);
    FormFactorSummary summary;
    ComputeFormFactors(s.scene, patches.fine, FormFactorOptions(), &summary);
    EXPECT_LE(summary.max_row_sum, 1.0 + 1e-12) << name;
    EXPECT_GT(summary.mean_row_sum, 0.2) << name;  // surfaces do see each other
    EXPECT_GT(patches.fine.adjacency.size(), 0u) << name;
  }
}

TEST(SyntheticScenes, TwoHaveDetailTexturesAndUnknownNamesAreRejected) {
  int textured = 0;
  for (const std::string& name : SyntheticSceneNames()) {
    bool has = false;
    for (const Surface& surface : MakeSyntheticScene(name).scene.surfaces) has |= surface.desired.HasTexture();
    textured += has;
  }
  EXPECT_GE(textured, 2);
  EXPECT_THROW(MakeSyntheticScene("cathedral"), std::invalid_argument);
}

}  // namespace
}  // namespace procam
