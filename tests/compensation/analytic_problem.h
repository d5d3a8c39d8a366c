#pragma once
// A dense compensation problem without Embree or scene files: two facing unit plates 0.5 m
// apart, g×g patches each, unoccluded point-to-point form factors F_ij = A_j d²/(π r⁴)
// between the plates (reciprocal by construction: A_i F_ij = A_j F_ji; row sums 0.2–0.5),
// saturated desired colours (bounds [0, 1] bite), grid adjacency, and the 2×2 coarse level
// (F aggregated exactly by area). For the CUDA tests and timings on machines that have the CUDA
// libraries but not procam's desktop dependencies (the device machine, docs/gpu.md).
#include <array>
#include <cmath>
#include <vector>

#include <Eigen/Core>

#include "compensation/colour.h"
#include "compensation/problem.h"

namespace procam::testing {

struct AnalyticProblem {
  CompensationProblem fine, coarse;
  std::vector<int> coarse_of_fine;
};

inline CompensationProblem PlatesProblem(int g, double alpha, double rho, std::vector<int>* cell_of_patch = nullptr) {
  const int n = 2 * g * g;
  const double side = 1.0 / g, distance = 0.5, pi = 3.14159265358979323846;
  CompensationProblem p;
  p.area = Eigen::VectorXd::Constant(n, side * side);
  Eigen::MatrixX2d xy(n, 2);
  for (int plate = 0; plate < 2; ++plate) {
    for (int r = 0; r < g; ++r) {
      for (int c = 0; c < g; ++c) xy.row(plate * g * g + r * g + c) << (c + 0.5) * side, (r + 0.5) * side;
    }
  }
  p.form_factors = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      if ((i < g * g) == (j < g * g)) continue;  // same plate: coplanar, F = 0
      const double r2 = (xy.row(i) - xy.row(j)).squaredNorm() + distance * distance;
      p.form_factors(i, j) = p.area[j] * distance * distance / (pi * r2 * r2);
    }
  }
  p.reflectance = Eigen::MatrixX3d::Constant(n, 3, rho);
  for (int plate = 0; plate < 2; ++plate) {
    for (int r = 0; r < g; ++r) {
      for (int c = 0; c < g; ++c) {
        const int i = plate * g * g + r * g + c;
        if (c + 1 < g) p.adjacency.push_back({i, i + 1});
        if (r + 1 < g) p.adjacency.push_back({i, i + g});
      }
    }
  }
  p.lower = Eigen::MatrixX3d::Zero(n, 3);
  p.upper = Eigen::MatrixX3d::Ones(n, 3);
  // Quadrants of saturated and pale colours: about half the variables end on a bound.
  const Eigen::Vector3d colours[4] = {{0.9, 0.05, 0.05}, {0.05, 0.8, 0.1}, {0.1, 0.1, 0.9}, {0.9, 0.9, 0.85}};
  p.desired.resize(n, 3);
  for (int i = 0; i < n; ++i) {
    const int quadrant = (xy(i, 0) < 0.5 ? 0 : 1) + (xy(i, 1) < 0.5 ? 0 : 2);
    p.desired.row(i) = colours[(quadrant + (i < g * g ? 0 : 1)) % 4].transpose();
  }
  p.rgb_to_xyz = SrgbToXyzMatrix();
  p.white_xyz = p.rgb_to_xyz * Eigen::Vector3d::Ones();
  p.alpha = alpha;
  if (cell_of_patch != nullptr) {
    cell_of_patch->resize(n);
    const int h = g / 2;
    for (int plate = 0; plate < 2; ++plate) {
      for (int r = 0; r < g; ++r) {
        for (int c = 0; c < g; ++c) (*cell_of_patch)[plate * g * g + r * g + c] = plate * h * h + (r / 2) * h + c / 2;
      }
    }
  }
  return p;
}

// g even. The coarse level is the same plates at g/2 with F aggregated from the fine one.
inline AnalyticProblem MakeAnalyticProblem(int g, double alpha = 0.5, double rho = 0.9) {
  AnalyticProblem a;
  a.fine = PlatesProblem(g, alpha, rho, &a.coarse_of_fine);
  a.coarse = PlatesProblem(g / 2, alpha, rho);
  const int nc = a.coarse.size();
  Eigen::MatrixXd by_fine_row = Eigen::MatrixXd::Zero(nc, a.fine.size());  // Σ_{i∈I} A_i F_ij
  for (int i = 0; i < a.fine.size(); ++i) by_fine_row.row(a.coarse_of_fine[i]) += a.fine.area[i] * a.fine.form_factors.row(i);
  Eigen::MatrixXd f = Eigen::MatrixXd::Zero(nc, nc);
  for (int j = 0; j < a.fine.size(); ++j) f.col(a.coarse_of_fine[j]) += by_fine_row.col(j);
  for (int I = 0; I < nc; ++I) f.row(I) /= a.coarse.area[I];
  a.coarse.form_factors = f;
  for (int i = 0; i < a.fine.size(); ++i) a.coarse.desired.row(a.coarse_of_fine[i]) = a.fine.desired.row(i);
  return a;
}

}  // namespace procam::testing
