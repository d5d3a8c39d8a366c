#pragma once
// RadiositySystem's CUDA backend (built with PROCAM_WITH_CUDA; procam/config.h says whether).
//
// K⁻¹ is formed once on the GPU per distinct channel reflectance (cuda_dense.h: cuSOLVER
// Cholesky of the symmetric form, or LU when a patch is black) and kept there in float64 and
// float32 (and float16 for CG's products); every solve is then one product with three (grey room)
// or one column. Through
// RadiosityBackend the solves take host matrices (the host loop, SolverOptions::device_host_loop);
// the resident solver (cuda_solver.h) applies the same K⁻¹ to device vectors
// (CudaInverseRadiosities, InverseRadiosity::ApplyOnDevice).

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "compensation/cuda_dense.h"
#include "compensation/radiosity.h"

namespace procam {

// True when a CUDA device can be used (also creates its context and library handles, so that
// later timings exclude them); `description` gets the device, or why there is none.
bool CudaDeviceAvailable(std::string* description);

// The backend for F (n×n), area (n) and reflectance (n×3). `float32`: the solves for objective
// values, gradients and line searches also use the float32 K⁻¹ (the Fast solves always do).
// `products`: how the device products are formed (SolverOptions::device_product_rows and
// device_cg_matrix). Throws std::runtime_error at device errors (no device, too little device
// memory).
std::shared_ptr<const RadiosityBackend> MakeCudaRadiosityBackend(const Eigen::MatrixXd& form_factors,
                                                                 const Eigen::VectorXd& area,
                                                                 const Eigen::MatrixX3d& reflectance,
                                                                 bool float32,
                                                                 const cuda::DenseProductSettings& products = {});

// The device K⁻¹ of a backend made by MakeCudaRadiosityBackend, for the resident solver
// (cuda_solver.h): one per group of channels sharing a reflectance, with the group's channels
// ({0, 1, 2} once for a grey room, else {0}, {1}, {2}). False, filling nothing, for any other
// backend. The pointers live as long as the backend.
bool CudaInverseRadiosities(const RadiosityBackend& backend, std::vector<const cuda::InverseRadiosity*>* inverses,
                            std::vector<std::vector<int>>* channels);

}  // namespace procam
