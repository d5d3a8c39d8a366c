#pragma once
// The device-resident GPU solver (built with PROCAM_WITH_CUDA; procam/config.h says whether):
// Alg. 1 (active-set Gauss–Newton) with Alg. 2 (modified projected Newton) and the Armijo search
// of MinimiseBounded (solver.h), for the perceptual and linear methods, with the whole loop on the
// device. Solve calls it for SolverOptions::device = Device::kCuda unless device_host_loop.
//
// What runs where (cuda_solver.cu; docs/gpu.md has the measurements):
//   device  K⁻¹ and K⁻ᵀ (the dense K⁻¹ of cuda_radiosity.h, float64 and float16 copies,
//           or the matrix-free CG of cuda_compressed.h), per-patch colour, residual, Jacobian
//           and second-order term, products with W (the adjacency in CSR form), objective,
//           gradient, projected gradient and active set, CG on the free variables, its
//           preconditioner, Alg. 2's projected step and the Armijo trials;
//   host    the control flow (MinimiseBoundedDriver, solver_driver.h, the CPU's as well),
//           reading back a few scalars per step (costs, slopes, CG's state),
//           and the records of the summary; except for small problems on the dense K⁻¹
//           (below 4096 patches, every K⁻¹ on the Cholesky path), where one cooperative kernel
//           runs the whole loop, control flow included, and the host reads the result and the
//           records once (SolverOptions::device_fused, on by default; SolverSummary::
//           device_fused says which ran): the same driver then runs in every thread of the
//           kernel. The progress callback is then called after the kernel.
// The algorithm and its stopping rules are MinimiseBounded's (one driver), with one difference:
// CG is preconditioned by the inverses of the 3×3 diagonal blocks of M_FF with one Neumann term
// for their coupling through W (z = D⁻¹r + D⁻¹ N D⁻¹ r; SolverOptions::device_preconditioner =
// kBlockJacobi drops the term) instead of a sparse factorisation of M_FF, whatever
// SolverOptions::preconditioner says.
// Values, gradients and line searches are float64; the Hessian products of CG use
// reduced-precision solves (the dense K⁻¹ in float16 with float32 vectors and sums; the
// matrix-free CG at its fast tolerance). SolverOptions::device_float32 is not used (the host
// loop's option).

#include <Eigen/Core>

#include "compensation/objective.h"
#include "compensation/solver.h"

namespace procam {

// MinimiseBounded on the device: the same outer iterations, stopping rules and summary records
// (trace, counters, termination), added to `summary` as MinimiseBounded adds them.
// `objective.radiosity()` must have been built with a CUDA backend (MakeCudaRadiosityBackend or
// MakeCudaCompressedRadiosityBackend), else std::invalid_argument. Throws std::runtime_error at
// device errors (naming the CUDA call). Calls from several threads run at once, each on
// device memory and a stream of its own (cuda_solver_device.h); they may share a RadiositySystem
// with the dense backend, not one with the matrix-free backend (whose CG keeps its vectors in the
// backend). `radiosity` (if not null) gets the result's K⁻¹E from the device (its last
// evaluation), which spares the caller a product.
Eigen::MatrixX3d MinimiseBoundedOnGpu(const SolverOptions& options, const CompensationObjective& objective,
                                      const Eigen::MatrixX3d& initial, SolverSummary* summary,
                                      Eigen::MatrixX3d* radiosity = nullptr);

}  // namespace procam
