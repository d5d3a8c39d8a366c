#pragma once
// Seamless light: the light within each patch shaped so that it varies smoothly across patch
// borders, instead of one uniform level per patch whose steps show the patch grid.
//
// The renderer (projector_images.h) gives every patch i a uniform irradiance level τ_i above
// black. Here that level becomes τ_i · m_p per lit pixel p, m_p a factor per channel whose
// weighted mean over the patch is 1 (weights w a, the flux bookkeeping's, projection_rig.h), so
// the patch still receives exactly the flux its E asks for, and the light it receives follows a
// smooth field v(x) over the surface:
//
//   v(x) = Σ_j K_j(x) v̂_j / Σ_j K_j(x),  K_j(x) = (1 − |x − c_j|² / r_j²)²  for |x − c_j| < r_j,
//
// a partition of unity of compactly supported (C¹) bumps at the patch centroids c_j, radius
// r_j = radius · √A_j. The nodes j that take part at a point of patch i are the patches within
// `rings` adjacency steps of i on the same surface whose desired colour is close to i's (each
// channel within `tolerance`, relative): the field is continuous across borders between such
// patches and steps only where the surface or the desired appearance does. The node values v̂
// start at the patches' exitance above black (ρ τ) and are corrected `iterations` times,
// v̂_j ← v̂_j · v_j / mean_j(v), so that the field's mean over each patch is close to the patch's
// own value before the per-patch normalisation: the normalisation then hardly changes the field
// and leaves no visible step. m_p = v(x_p) / mean_i(v).

#include <Eigen/Core>
#include <array>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "projection/projection_rig.h"

namespace procam {

struct SeamlessLightOptions {
  // Radius of each patch's bump in patch sides (√A), in [0.5, 5]: 1.5 reaches the centroids of a
  // square grid's 8 neighbours from every point of a patch.
  double radius = 1.5;
  // Adjacency steps searched for the patches that share the field, in [1, 8].
  int rings = 3;
  // Corrections of the node values, in [0, 50] (0: the patches' own values).
  int iterations = 10;
  // Neighbours share the field where each channel of their desired colours differs by at most
  // this fraction of the larger, in [0, 1].
  double tolerance = 0.05;
  bool Check(std::string* why) const;
};

// The field's static part for one rig and options: per patch its node list (FieldNodes, then
// DropNodesOutOfReach in seamless_light.cc), each node's bump radius² and the matrix A whose row i
// is the mean of the normalised bumps over patch i's pixels (weights w a), so that the field's
// patch means are A v̂. Building it visits every lit pixel once; afterwards the node values
// (NodeValues), the means (PatchMeans) and the factor at any point (Factor) cost O(nodes) each,
// which is what a frame plan (frame_plan.h) and a GPU shader (gl_renderer.h) need. Keeps a
// reference to the rig.
class SeamlessField {
 public:
  // Throws std::invalid_argument if the options fail Check() or the rig has no centroids, hit
  // points or a valid adjacency.
  SeamlessField(const ProjectionRig& rig, const SeamlessLightOptions& options);
  ~SeamlessField();
  SeamlessField(const SeamlessField&) = delete;
  SeamlessField& operator=(const SeamlessField&) = delete;

  // Node values v̂ (n,3) for patches whose exitance above black is `exitance` (n,3, ≥ 0): the
  // exitance corrected `iterations` times (header comment).
  Eigen::MatrixX3d NodeValues(const Eigen::MatrixX3d& exitance) const;
  // mean_i(v) = (A v̂)_i per patch and channel (n,3).
  Eigen::MatrixX3d PatchMeans(const Eigen::MatrixX3d& node_value) const;
  // m at `point` (metres, on patch i): v(point) / mean_i(v) per channel, in single precision as
  // SeamlessLightFactors gives it; 1 on flat patches and on channels whose mean is 0.
  Eigen::Vector3f Factor(int i, const Eigen::Vector3f& point, const Eigen::MatrixX3d& node_value,
                         const Eigen::MatrixX3d& means) const;
  // Factor at every lit pixel of the rig (per projector, in pixels_by_patch order); with
  // `projectors` (one flag per projector) only theirs, the others' lists left empty.
  std::vector<std::vector<Eigen::Vector3f>> Factors(
      const Eigen::MatrixX3d& node_value, const Eigen::MatrixX3d& means,
      const std::vector<char>* projectors = nullptr) const;
  // Factor at patch i's lit pixels of projector k: factors[position − patch_begin[i]] for its
  // positions in pixels_by_patch order. From the cached bumps where CacheBumps has cached
  // projector k's, else evaluated; the same bits either way.
  void PatchFactors(int i, size_t k, const Eigen::MatrixX3d& node_value,
                    const Eigen::MatrixX3d& means, Eigen::Vector3f* factors) const;
  // Keeps every lit pixel's bumps of the projectors flagged (null: all), so that the factors of
  // later frames sum them instead of evaluating every node's bump at every pixel: a display
  // node's CPU shading, frame after frame. Costs 2 bytes a lit pixel and 6 a bump (about 7 a
  // pixel at the default radius: some 90 MB for a 1080p projector).
  void CacheBumps(const std::vector<char>* projectors = nullptr);
  bool BumpsCached(size_t k) const { return k < cached_.size() && !cached_[k].count.empty(); }
  // The bumps at `point` on patch i, normalised to sum 1 (K̃_j), each by its node's position in
  // i's node list (node_list()[node_begin()[i] + first]). Only where a patch is so elongated
  // that no bump reaches (outside the designed range): the patch's own value (its list starts
  // with i), weight 1.
  void Bumps(int i, const Eigen::Vector3f& point, std::vector<std::pair<int, double>>* bumps) const;
  // (1 − |x − c_j|²/r_j²)² of node_list()[node] at x, or −1 where x is outside its radius.
  double BumpSquared(int node, const Eigen::Vector3d& x) const {
    const Eigen::Vector4d& bump = node_bump_[node];
    const double d2 = (x - bump.head<3>()).squaredNorm();
    if (d2 >= bump[3]) return -1.0;
    const double t = 1.0 - d2 / bump[3];
    return t * t;
  }
  // Whether patch i's field is its own value alone (m = 1 over it).
  bool Flat(int i) const { return node_begin_[i + 1] - node_begin_[i] <= 1; }

  // Patch i's nodes are node_list()[node_begin()[i] .. node_begin()[i + 1]), i itself first.
  const std::vector<int>& node_begin() const { return node_begin_; }  // (n + 1)
  const std::vector<int>& node_list() const { return node_list_; }
  const std::vector<double>& radius2() const { return radius2_; }  // (n) r_j², m²
  // Aligned with node_list(): the largest share_p · K̃_j(x_p) over patch i's pixels p of every
  // projector (share: ProjectorMap::share, w a / Ω; K̃_j = K_j / Σ K the normalised bump). They
  // bound the light within a patch without visiting its pixels (frame_plan.h).
  const std::vector<double>& node_share_reach() const { return node_share_reach_; }
  const ProjectionRig& rig() const { return rig_; }

 private:
  // Calls visit(i, k, position, bumps) for every lit pixel of every patch that is not flat.
  template <typename Visit>
  void ForEachPixel(Visit visit) const;
  void FormPatchMeans();
  // The normalised bumps at `point` on patch i as Factor sums them: Bumps, nodes by their
  // position in i's list, weights K̃_j rounded to single precision (what the cache keeps).
  void FactorBumps(int i, const Eigen::Vector3f& point, std::vector<uint16_t>* node,
                   std::vector<float>* weight) const;
  // The node values of patch i's list in list order over the patch's means, in single
  // precision, four to a node (R, G, B, 0: what SumFactor reads, 16-byte aligned); true for the
  // channels whose mean is not positive (factor 1).
  using FactorValues = std::vector<float, Eigen::aligned_allocator<float>>;
  std::array<bool, 3> ListValues(int i, const Eigen::MatrixX3d& node_value,
                                 const Eigen::MatrixX3d& means, FactorValues* values) const;

  const ProjectionRig& rig_;
  SeamlessLightOptions options_;
  std::vector<int> node_begin_, node_list_;
  std::vector<double> radius2_;
  // Aligned with node_list_: the node's centroid (xyz) and r² (w), side by side for the per-pixel
  // loops (the rig's centroids are stored by column).
  std::vector<Eigen::Vector4d> node_bump_;
  std::vector<double> node_share_reach_;
  struct Means;  // A (sparse, row-major)
  std::unique_ptr<Means> means_;
  // CacheBumps' per projector: per patch its first bump (n + 1), per lit pixel its count, and
  // per bump its node's position in the patch's list and its weight. Empty: not cached.
  struct PixelBumps {
    std::vector<int64_t> patch_first;
    std::vector<uint16_t> count, node;
    std::vector<float> weight;
  };
  std::vector<PixelBumps> cached_;
};

// The factors m (header comment) per projector, lit pixel (in pixels_by_patch order) and channel,
// for patches whose exitance above black is `exitance` (n,3, ≥ 0, e.g. ρ τ): exactly 1 on patches
// whose field is flat. Needs the rig's point_by_patch, centroid and adjacency. Throws
// std::invalid_argument if the options fail Check() or the rig or `exitance` do not fit.
std::vector<std::vector<Eigen::Vector3f>> SeamlessLightFactors(const ProjectionRig& rig,
                                                               const Eigen::MatrixX3d& exitance,
                                                               const SeamlessLightOptions& options);

}  // namespace procam
