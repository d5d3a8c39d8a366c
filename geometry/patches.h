#pragma once
// Subdivision of a scene's surfaces into patches, on two levels: fine patches (what the
// solver computes on) and coarse patches that each own 4 fine children (the multi-resolution
// solver's first level). Quads become grids of near-square cells; mesh triangles are split
// uniformly at their edge midpoints.

#include <array>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "geometry/scene.h"

namespace procam {

// A planar triangle or convex quadrilateral of one surface.
struct Patch {
  int surface = -1;
  int corner_count = 4;             // 3 or 4
  std::array<Vec3, 4> corners;      // counter-clockwise seen from the lit side
  std::array<Vec2, 4> uv;           // texture coordinates of the corners
  Vec3 centroid = Vec3::Zero();
  Vec3 normal = Vec3::UnitZ();      // unit, lit side
  double area = 0.0;                // m²
};

// One level of patches with everything the solver needs per patch.
struct PatchLevel {
  std::vector<Patch> patches;
  // Pairs (i, j), i < j, of patches sharing an edge (also across surfaces that meet), each
  // unordered pair once.
  std::vector<std::array<int, 2>> adjacency;
  Eigen::MatrixX3d reflectance;     // (n,3) rho per patch and channel
  Eigen::MatrixX3d desired_linear;  // (n,3) desired radiosity: sRGB → linear, × white

  int size() const { return static_cast<int>(patches.size()); }
  Eigen::VectorXd Areas() const;
};

struct PatchHierarchy {
  PatchLevel fine;
  PatchLevel coarse;
  std::vector<int> coarse_of_fine;  // parent coarse patch of each fine patch
};

struct SubdivisionOptions {
  // Fine patches wanted in total (≥ 4); each surface gets a share proportional to its area,
  // at least 4 (one coarse patch).
  int target_patches = 1000;
  // Gauss–Legendre points per patch side used to average a texture (desired or reflectance)
  // over a patch (SamplePatch), in [1, 64].
  int texture_samples = 4;
  bool Check(std::string* why) const;
};

PatchHierarchy SubdividePatches(const Scene& scene, const SubdivisionOptions& options);

// Per-patch values of the coarse level from the fine one: each coarse patch gets the area-weighted
// mean of its children's, which is exact for quantities per unit area (exitance bounds: a coarse
// patch receives its children's flux; reflectance under even light). Rows whose children have no
// area are 0.
Eigen::MatrixX3d CoarsenPatchValues(const Eigen::MatrixX3d& fine_values, const Eigen::VectorXd& fine_area,
                               const std::vector<int>& coarse_of_fine, int coarse_count);

// A quadrature point on a patch: position, texture coordinate and the area it stands for.
struct PatchSample {
  Vec3 point;
  Vec2 uv;
  double weight;  // m²; a patch's weights sum to its area
};

// k² Gauss–Legendre points on the patch: the tensor rule on the bilinear map of the unit square
// (quads) or on Duffy's collapsed square (triangles). For k ≥ 2, exact for integrands that are
// polynomials of degree ≤ 2k − 3 in position; weights are positive and sum to the area.
void SamplePatch(const Patch& patch, int k, std::vector<PatchSample>* samples);

// Gauss–Legendre nodes (ascending) and weights on [0, 1], k in [1, kMaxQuadratureOrder].
constexpr int kMaxQuadratureOrder = 64;
struct GaussLegendreRule {
  std::vector<double> nodes, weights;
};
const GaussLegendreRule& GaussLegendre(int k);

// Adjacency of a set of patches: shared edges, where edges of different patches count as
// shared when they are collinear within `tolerance` and overlap by more than it.
std::vector<std::array<int, 2>> FindAdjacency(const std::vector<Patch>& patches,
                                              double tolerance);

}  // namespace procam
