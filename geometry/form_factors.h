#pragma once
// Patch-to-patch form factors with visibility (paper Eq. 1's F).
//
// F_ij = (1/A_i) ∫_i ∫_j V(x,y) cosθ_x cosθ_y / (π |x−y|²) dy dx is computed per unordered pair
// by quadrature over both patches: at each of k² points x_s on patch i the inner integral over
// patch j is evaluated in closed form (the point-to-polygon contour formula, with the polygon
// clipped to x's hemisphere), and multiplied by the visibility of one shadow ray from x_s to a
// paired point on j (Embree). The same rays serve the mirrored estimate from j's side; the two
// estimates of the exchange area A_i F_ij = A_j F_ji are averaged, so reciprocity holds to
// rounding. k grows for near pairs, where the integrand varies fastest.

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "geometry/compressed_form_factors.h"
#include "geometry/patches.h"
#include "geometry/scene.h"

namespace procam {

struct FormFactorOptions {
  // Quadrature points per patch side for well-separated pairs (k, giving k² points), ≥ 1.
  int far_samples = 2;
  // Most quadrature points per side, used for touching pairs, ≥ far_samples.
  int near_samples = 10;
  // k = clamp(near_scale · (√A_i + √A_j) / distance, far_samples, near_samples), > 0.
  double near_scale = 3.0;
  // Cast shadow rays. Off: every pair of facing patches sees each other (convex rooms only).
  bool visibility = true;
  // Worker threads (0: all cores).
  int threads = 0;
  // Called now and then with the fraction done, from one thread.
  std::function<void(double)> progress;

  bool Check(std::string* why) const;
};

struct FormFactorSummary {
  double seconds = 0.0;
  int64_t pairs_evaluated = 0;  // unordered pairs that face each other
  int64_t shadow_rays = 0;
  double min_row_sum = 0.0, mean_row_sum = 0.0, max_row_sum = 0.0;
  // max over i,j of |A_i F_ij − A_j F_ji| / max(A_i F_ij, tiny)
  double max_reciprocity_error = 0.0;
  // Largest relative cut LimitRowSums made to a row (0: no row exceeded 1).
  double max_row_correction = 0.0;
};

// Dense n×n F of one patch level. Throws IoError if Embree fails.
Eigen::MatrixXd ComputeFormFactors(const Scene& scene, const PatchLevel& level,
                                   const FormFactorOptions& options, FormFactorSummary* summary);

// The same form factors compressed (compressed_form_factors.h): near pairs by the quadrature
// above, far cluster pairs by their representatives, with shadow rays when
// options.visibility. Memory and time grow about as n log n instead of n². Throws IoError if
// Embree fails, std::invalid_argument for bad options.
CompressedFormFactors ComputeCompressedFormFactors(const Scene& scene, const PatchLevel& level,
                                                   const FormFactorOptions& options,
                                                   const ClusterOptions& clusters,
                                                   CompressedBuildSummary* summary);

// Quadrature and shadow-ray noise can push a row sum slightly above 1 next to occluders.
// Scales F symmetrically, F_ij ← s_i F_ij s_j with s_i = min(1, 1/rowsum_i), which keeps
// reciprocity exact and brings every row sum to ≤ 1. Returns the largest cut, 1 − min s_i.
double LimitRowSums(Eigen::MatrixXd* f);

// Form factors of a coarser level from a finer one: F_IJ = Σ_{i∈I} Σ_{j∈J} A_i F_ij / A_I
// (exact: the coarse patch is the union of its children).
Eigen::MatrixXd AggregateFormFactors(const Eigen::MatrixXd& fine_f, const Eigen::VectorXd& fine_area,
                                     const std::vector<int>& coarse_of_fine, int coarse_count);

// Row sums, reciprocity error into `summary` (seconds, pairs and rays untouched).
void SummariseFormFactors(const Eigen::MatrixXd& f, const Eigen::VectorXd& area,
                          FormFactorSummary* summary);

// Form factor from a differential area at `x` with unit normal `normal` to a planar convex
// polygon (counter-clockwise from its lit side), unoccluded: the part of the polygon below x's
// tangent plane or seen from its back side contributes nothing.
double PointToPolygonFormFactor(const Vec3& x, const Vec3& normal, const Vec3* polygon, int count);

}  // namespace procam
