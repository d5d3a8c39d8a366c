#pragma once
// Reading a problem directory written by `procam compensate ROOM --export` (compensation/problem.h,
// ExportProblem) back into a CompensationProblem, with base/io.h's ReadNpy only: the device
// machine's tests (no Embree, no OpenCV) and the CPU benchmarks solve real rooms with it.
#include <filesystem>
#include <fstream>

#include <Eigen/Core>
#include <Eigen/LU>
#include <nlohmann/json.hpp>

#include "base/io.h"
#include "compensation/colour.h"
#include "compensation/problem.h"

namespace procam::testing {

// A problem written by `procam compensate ... --export` (F from Embree's shadow rays, the
// projectors' bounds): real rooms on a machine that has no Embree. The desired radiosity comes
// back from desired_lab.npy through LabToXyz and T⁻¹.
inline CompensationProblem ReadExportedProblem(const std::filesystem::path& directory) {
  const auto matrix = [&](const char* name) {
    const NpyArray array = ReadNpy(directory / name);
    const int64_t rows = array.shape.at(0), columns = array.shape.size() > 1 ? array.shape[1] : 1;
    Eigen::MatrixXd m(rows, columns);
    for (int64_t i = 0; i < rows; ++i) {
      for (int64_t j = 0; j < columns; ++j) m(i, j) = array.values[i * columns + j];
    }
    return m;
  };
  CompensationProblem p;
  p.form_factors = matrix("F.npy");
  p.area = matrix("area.npy").col(0);
  p.reflectance = matrix("rho.npy");
  p.lower = matrix("lower.npy");
  p.upper = matrix("upper.npy");
  p.rgb_to_xyz = matrix("T.npy");
  p.white_xyz = matrix("white_xyz.npy").col(0);
  const Eigen::MatrixXd adjacency = matrix("adjacency.npy");
  for (int k = 0; k < adjacency.rows(); ++k) {
    p.adjacency.push_back({static_cast<int>(adjacency(k, 0)), static_cast<int>(adjacency(k, 1))});
  }
  const Eigen::MatrixXd lab = matrix("desired_lab.npy");
  const Eigen::Matrix3d to_rgb = p.rgb_to_xyz.inverse();
  p.desired.resize(lab.rows(), 3);
  for (int i = 0; i < lab.rows(); ++i) {
    p.desired.row(i) = (to_rgb * LabToXyz(lab.row(i).transpose(), p.white_xyz)).transpose();
  }
  std::ifstream meta(directory / "problem.json");
  p.alpha = nlohmann::json::parse(meta).at("alpha").get<double>();
  return p;
}

}  // namespace procam::testing
