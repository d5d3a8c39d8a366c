// CompensationProblem::Validate, apart from problem.cc: the solver needs it, and keeping it out
// of problem.cc (which builds problems from scenes) lets a binary that links only the solver
// leave geometry's image and mesh libraries out (tests/compensation/solver_cuda_device_test.cc).
#include "compensation/problem.h"

namespace procam {

std::string CompensationProblem::Validate() const {
  const int n = size();
  if (compressed()) {
    if (compressed_form_factors->size() != n) return "compressed F does not have n patches";
    if (form_factors.size() != 0) return "both a dense and a compressed F";
  } else if (form_factors.rows() != n || form_factors.cols() != n) {
    return "F is not n×n";
  }
  if (reflectance.rows() != n || lower.rows() != n || upper.rows() != n || desired.rows() != n) {
    return "per-patch arrays do not all have n rows";
  }
  if (!(alpha > 0.0 && alpha <= 1.0)) return "alpha must be in (0,1]";
  if (!form_factors.allFinite() || !desired.allFinite() || !lower.allFinite() || !upper.allFinite()) {
    return "NaN or infinite values in F, desired or bounds";
  }
  if ((reflectance.array() < 0.0).any() || (reflectance.array() >= 1.0).any()) {
    return "reflectance must be in [0,1)";
  }
  if ((lower.array() > upper.array()).any()) return "lower > upper for some patch";
  if ((area.array() <= 0.0).any()) return "non-positive patch area";
  if (patch_weight.size() != 0 &&
      (patch_weight.size() != n || !patch_weight.allFinite() || (patch_weight.array() <= 0.0).any())) {
    return "patch weights must be n positive numbers (or none)";
  }
  for (const auto& pair : adjacency) {
    if (pair[0] < 0 || pair[1] >= n || pair[0] >= pair[1]) return "adjacency pair out of range";
  }
  return "";
}

}  // namespace procam
