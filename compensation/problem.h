#pragma once
// The compensation problem exactly as DESIGN.md defines it, assembled from a scene's patches
// and form factors, and its export as NumPy files that anyone can check the objective with.

#include <array>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "geometry/compressed_form_factors.h"
#include "geometry/patches.h"
#include "geometry/scene.h"

namespace procam {

struct CompensationProblem {
  Eigen::MatrixXd form_factors;   // (n,n) F, shared by all channels; empty when compressed
  // F compressed (rooms too large for n²): when set, form_factors stays empty and the solver
  // works matrix-free (compensation/radiosity.h).
  std::shared_ptr<const CompressedFormFactors> compressed_form_factors;
  Eigen::VectorXd area;           // (n) A_i, m²
  Eigen::MatrixX3d reflectance;   // (n,3) rho, each in [0,1)
  std::vector<std::array<int, 2>> adjacency;  // (m) pairs i<j sharing an edge, once each
  Eigen::MatrixX3d lower, upper;  // (n,3) direct-light exitance bounds on E
  Eigen::MatrixX3d desired;       // (n,3) desired radiosity Bd, linear RGB
  Eigen::Matrix3d rgb_to_xyz;     // T
  Eigen::Vector3d white_xyz;      // (Xn,Yn,Zn) = T·(w,w,w)
  double alpha = 0.5;             // weight of the absolute term, in (0,1]
  // (n) or empty (all 1): multiplies patch i's absolute term, α (A_i/A_avg) w_i |r_i|² — how much
  // its colour matters beyond its area (e.g. where the audience looks; the evaluation's
  // lowest-mean-ΔE bound reweights with it). DESIGN.md's objective is the empty case.
  Eigen::VectorXd patch_weight;

  int size() const { return static_cast<int>(area.size()); }
  bool compressed() const { return compressed_form_factors != nullptr; }
  // Empty if the problem is consistent; otherwise one line naming what is wrong.
  std::string Validate() const;
};

// Problem for one patch level, with the scene's bounds (no projectors yet) and sRGB primaries.
CompensationProblem MakeProblem(const Scene& scene, const PatchLevel& level,
                                Eigen::MatrixXd form_factors, double alpha);

// Writes F, area, rho, adjacency, centroid, normal, surface, lower, upper, desired_lab, T,
// white_xyz (.npy, float64/int64, C order) and problem.json into `directory` (created if
// needed). Each file is written atomically. `settings` is merged into problem.json.
void ExportProblem(const CompensationProblem& problem, const PatchLevel& level,
                   const std::vector<int>& coarse_of_fine, const std::filesystem::path& directory,
                   const std::string& settings_json);

}  // namespace procam
