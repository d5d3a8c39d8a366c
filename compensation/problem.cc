#include "compensation/problem.h"

#include <cmath>

#include <nlohmann/json.hpp>

#include "compensation/colour.h"
#include "base/io.h"

namespace procam {

CompensationProblem MakeProblem(const Scene& scene, const PatchLevel& level,
                                Eigen::MatrixXd form_factors, double alpha) {
  CompensationProblem problem;
  const int n = level.size();
  problem.form_factors = std::move(form_factors);
  problem.area = level.Areas();
  problem.reflectance = level.reflectance;
  problem.adjacency = level.adjacency;
  problem.lower = scene.bounds.lower.transpose().replicate(n, 1);
  problem.upper = scene.bounds.upper.transpose().replicate(n, 1);
  problem.desired = level.desired_linear;
  problem.rgb_to_xyz = SrgbToXyzMatrix();
  problem.white_xyz = problem.rgb_to_xyz * Eigen::Vector3d::Constant(scene.white);
  problem.alpha = alpha;
  return problem;
}

void ExportProblem(const CompensationProblem& problem, const PatchLevel& level,
                   const std::vector<int>& coarse_of_fine, const std::filesystem::path& directory,
                   const std::string& settings_json) {
  std::error_code error;
  std::filesystem::create_directories(directory, error);
  if (error) throw IoError(directory.string() + ": cannot create directory: " + error.message());
  const int n = problem.size();
  auto write = [&](const char* name, const RowMatrixXd& array, bool as_vector = false) {
    WriteNpy(directory / name, array, as_vector);
  };
  RowMatrixXd centroid(n, 3), normal(n, 3), desired_lab(n, 3);
  RowMatrixXi64 surface(n, 1), adjacency(static_cast<int64_t>(problem.adjacency.size()), 2);
  const LabConverter lab{problem.rgb_to_xyz, problem.white_xyz};
  for (int i = 0; i < n; ++i) {
    centroid.row(i) = level.patches[i].centroid.transpose();
    normal.row(i) = level.patches[i].normal.transpose();
    surface(i, 0) = level.patches[i].surface;
    desired_lab.row(i) = lab.Lab(problem.desired.row(i).transpose()).transpose();
  }
  for (size_t k = 0; k < problem.adjacency.size(); ++k) {
    adjacency(k, 0) = problem.adjacency[k][0];
    adjacency(k, 1) = problem.adjacency[k][1];
  }
  write("F.npy", problem.form_factors);
  write("area.npy", problem.area, true);
  write("rho.npy", problem.reflectance);
  WriteNpy(directory / "adjacency.npy", adjacency);
  write("centroid.npy", centroid);
  write("normal.npy", normal);
  WriteNpy(directory / "surface.npy", surface, true);
  if (!coarse_of_fine.empty()) {
    RowMatrixXi64 parent(n, 1);
    for (int i = 0; i < n; ++i) parent(i, 0) = coarse_of_fine[i];
    WriteNpy(directory / "parent.npy", parent, true);
  }
  write("lower.npy", problem.lower);
  write("upper.npy", problem.upper);
  write("desired_lab.npy", desired_lab);
  write("T.npy", problem.rgb_to_xyz);
  write("white_xyz.npy", problem.white_xyz.transpose(), true);
  nlohmann::json meta = nlohmann::json::parse(settings_json.empty() ? "{}" : settings_json);
  meta["alpha"] = problem.alpha;
  meta["patches"] = n;
  meta["variables"] = 3 * n;
  meta["adjacent_pairs"] = problem.adjacency.size();
  meta["objective"] =
      "f = alpha * sum_i (A_i/A_avg) |r_i|^2 + (1-alpha) * sum_(i,j) in adjacency |r_i - r_j|^2, "
      "r_i = Lab(B_i) - desired_lab_i, B_c = (I - diag(rho_c) F)^-1 E_c, Lab relative to white_xyz";
  WriteFileAtomically(directory / "problem.json", meta.dump(2) + "\n");
}

}  // namespace procam
