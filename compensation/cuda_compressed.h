#pragma once
// RadiositySystem's CUDA backend for a compressed F (compressed_form_factors.h), built with
// PROCAM_WITH_CUDA: the matrix-free solves of RadiositySystem::SolveIteratively (radiosity.h),
// K b = e and Kᵀ x = y by conjugate gradients on M = I − D^½ A^½ F A^-½ D^½, run on the device.
//
// F (near CSR, far blocks, tree order, areas) and the reflectance are uploaded once; a solve
// copies n×3 doubles each way and reads the three residual norms back once every few
// iterations. The product with F is CompressedFormFactors::Multiply on the device, in tree
// order: a sparse product for the near part; for the far part one warp per block side forms
// the coefficient s vᵀ x_J of its rank-1 block, and every position gathers u_p times the
// coefficients of the blocks that cover it. All arithmetic is float64, the fast solves
// included (at the looser tolerance).

#include <cstdint>
#include <memory>

#include <Eigen/Core>

#include "compensation/radiosity.h"
#include "geometry/compressed_form_factors.h"

namespace procam {

namespace cuda {
class CompressedRadiosity;
}  // namespace cuda

class CudaCompressedRadiosity : public RadiosityBackend {
 public:
  // `reflectance` (n×3, each in [0,1)); `options`: the CG tolerances and iteration limit, as
  // the CPU's matrix-free RadiositySystem takes them. Nothing is kept of the arguments on the
  // host. Throws std::runtime_error without a CUDA device ("--device cuda: ...") or at device
  // errors (naming the CUDA call, or the memory needed).
  CudaCompressedRadiosity(const CompressedFormFactors& form_factors, const Eigen::MatrixX3d& reflectance,
                          const IterativeRadiosityOptions& options);
  ~CudaCompressedRadiosity() override;

  // K⁻¹ Y or K⁻ᵀ Y to options.tolerance (options.fast_tolerance when `fast`). Throws
  // std::runtime_error when CG has not converged in options.max_iterations. One call at a time.
  Eigen::MatrixX3d Solve(const Eigen::MatrixX3d& y, bool transposed, bool fast) const override;
  // 1 when every patch reflects the three channels alike, else 3 (as the dense backend).
  int factorisations() const override { return grey_ ? 1 : 3; }

  // Solve on device memory (n×3 column-major, patch order), on device().stream(), for the
  // resident solver (cuda_solver.h); counted in solve_iterations() as Solve is.
  int SolveOnDevice(const double* y, bool transposed, bool fast, double* x) const;
  // The device side (its stream: device().stream()).
  const cuda::CompressedRadiosity& device() const;

  // F X on the device (X n×c, any c ≥ 1), for tests and benchmarks.
  Eigen::MatrixXd Multiply(const Eigen::MatrixXd& x) const;
  // RadiositySystem's products with F (K·Bd of the solver's start, Multiply*) on the device.
  bool MultiplyF(const Eigen::MatrixX3d& x, Eigen::MatrixX3d* fx) const override {
    *fx = Multiply(x);
    return true;
  }
  // CG iterations of every solve so far.
  int64_t solve_iterations() const { return solve_iterations_; }

 private:
  std::unique_ptr<cuda::CompressedRadiosity> device_;
  IterativeRadiosityOptions options_;
  int patches_ = 0;
  bool grey_ = true;
  mutable int64_t solve_iterations_ = 0;
};

// The backend for RadiositySystem's matrix-free constructor (pass it the same `options`).
std::shared_ptr<const RadiosityBackend> MakeCudaCompressedRadiosityBackend(const CompressedFormFactors& form_factors,
                                                                           const Eigen::MatrixX3d& reflectance,
                                                                           const IterativeRadiosityOptions& options);

// F X computed on the device (uploads F for this call): tests against
// CompressedFormFactors::Multiply.
Eigen::MatrixXd CudaCompressedMultiply(const CompressedFormFactors& form_factors, const Eigen::MatrixXd& x);

}  // namespace procam
