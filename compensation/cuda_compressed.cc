#include "compensation/cuda_compressed.h"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "compensation/cuda_compressed_device.h"
#include "compensation/cuda_dense.h"

namespace procam {

CudaCompressedRadiosity::CudaCompressedRadiosity(const CompressedFormFactors& form_factors,
                                                 const Eigen::MatrixX3d& reflectance,
                                                 const IterativeRadiosityOptions& options)
    : options_(options), patches_(form_factors.size()) {
  std::string why;
  if (!cuda::DeviceAvailable(&why)) throw std::runtime_error("--device cuda: " + why);
  if (reflectance.rows() != patches_) {
    throw std::invalid_argument("compressed radiosity on the GPU: reflectance has " +
                                std::to_string(reflectance.rows()) + " rows for " + std::to_string(patches_) +
                                " patches");
  }
  grey_ = (reflectance.col(0) == reflectance.col(1)) && (reflectance.col(0) == reflectance.col(2));
  // CompressedFormFactors' constructor compresses the near part; copied only where that is not so.
  CompressedFormFactors::SparseRows near_copy;
  const CompressedFormFactors::SparseRows* near = &form_factors.near();
  if (!near->isCompressed()) {
    near_copy = *near;
    near_copy.makeCompressed();
    near = &near_copy;
  }
  const FarBlocks& far = form_factors.far();
  cuda::CompressedParts parts;
  parts.patches = patches_;
  parts.clusters = form_factors.clusters();
  parts.area = form_factors.area().data();
  parts.order = form_factors.order().data();
  parts.begin = form_factors.begin().data();
  parts.end = form_factors.end().data();
  parts.near_offsets = near->outerIndexPtr();
  parts.near_columns = near->innerIndexPtr();
  parts.near_values = near->valuePtr();
  parts.far_blocks = far.size();
  parts.far_rows = far.rows.data();
  parts.far_columns = far.columns.data();
  parts.far_column_offset = far.column_offset.data();
  parts.far_row_offset = far.row_offset.data();
  parts.far_scale = far.scale.data();
  parts.far_values = far.values.data();
  parts.far_value_count = static_cast<int64_t>(far.values.size());
  device_ = cuda::CompressedRadiosity::Create(parts, reflectance.data());
}

CudaCompressedRadiosity::~CudaCompressedRadiosity() = default;

Eigen::MatrixX3d CudaCompressedRadiosity::Solve(const Eigen::MatrixX3d& y, bool transposed, bool fast) const {
  if (y.rows() != patches_) throw std::invalid_argument("compressed radiosity on the GPU: y has the wrong size");
  Eigen::MatrixX3d x(patches_, 3);
  solve_iterations_ += device_->Solve(y.data(), transposed, fast ? options_.fast_tolerance : options_.tolerance,
                                      options_.max_iterations, x.data());
  return x;
}

const cuda::CompressedRadiosity& CudaCompressedRadiosity::device() const { return *device_; }

int CudaCompressedRadiosity::SolveOnDevice(const double* y, bool transposed, bool fast, double* x) const {
  const int iterations = device_->SolveOnDevice(y, transposed, fast ? options_.fast_tolerance : options_.tolerance,
                                                options_.max_iterations, x);
  solve_iterations_ += iterations;
  return iterations;
}

Eigen::MatrixXd CudaCompressedRadiosity::Multiply(const Eigen::MatrixXd& x) const {
  if (x.rows() != patches_) throw std::invalid_argument("compressed radiosity on the GPU: x has the wrong size");
  Eigen::MatrixXd y(patches_, x.cols());
  // The device works on three columns at a time; a last partial group is padded with zeros.
  Eigen::MatrixX3d in(patches_, 3), out(patches_, 3);
  for (Eigen::Index first = 0; first < x.cols(); first += 3) {
    const Eigen::Index columns = std::min<Eigen::Index>(3, x.cols() - first);
    in.setZero();
    in.leftCols(columns) = x.middleCols(first, columns);
    device_->Multiply(in.data(), out.data());
    y.middleCols(first, columns) = out.leftCols(columns);
  }
  return y;
}

std::shared_ptr<const RadiosityBackend> MakeCudaCompressedRadiosityBackend(const CompressedFormFactors& form_factors,
                                                                           const Eigen::MatrixX3d& reflectance,
                                                                           const IterativeRadiosityOptions& options) {
  return std::make_shared<const CudaCompressedRadiosity>(form_factors, reflectance, options);
}

Eigen::MatrixXd CudaCompressedMultiply(const CompressedFormFactors& form_factors, const Eigen::MatrixXd& x) {
  const CudaCompressedRadiosity device(form_factors, Eigen::MatrixX3d::Zero(form_factors.size(), 3),
                                       IterativeRadiosityOptions());
  return device.Multiply(x);
}

}  // namespace procam
