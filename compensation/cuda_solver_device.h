#pragma once
// The device-resident loop of cuda_solver.h behind a plain C++ interface (no Eigen or CUDA
// runtime types), so that only cuda_solver.cu is compiled by nvcc.
//
// Vectors on the device are n×3, column-major (channel-planar: value c·n + i), in patch order:
// the layout of Eigen::MatrixX3d, so that uploads and downloads are single copies, and the
// layout the dense K⁻¹ multiplies (one product per group of channels).

#include <functional>
#include <string>
#include <vector>

#include "compensation/cuda_dense.h"
#include "compensation/solver_driver.h"
#include "compensation/solver_records.h"

// The CUDA runtime's stream handle (driver_types.h declares it the same way).
typedef struct CUstream_st* cudaStream_t;

namespace procam::cuda {

// One product of the dense K⁻¹ solves: `columns` channels from `first_channel` on (n×3 vectors,
// channel-planar) with one K⁻¹.
struct DenseProduct {
  DenseInverseView inverse;
  int first_channel = 0;
  int columns = 3;
};

// K⁻¹ and K⁻ᵀ of one problem on device memory, as the resident loop uses them.
class DeviceRadiosity {
 public:
  virtual ~DeviceRadiosity() = default;
  // The stream the solves run on, which the loop's kernels then share; null: the solves run on
  // the stream passed to each call (the loop's own).
  virtual cudaStream_t stream() const = 0;
  // x = K⁻¹ y (K⁻ᵀ y when `transposed`) in float64 to full accuracy: objective values and
  // gradients. y and x must not overlap.
  virtual void Solve(const double* y, bool transposed, double* x, cudaStream_t stream) const = 0;
  // The reduced-precision solves of the Hessian products (RadiositySystem::SolveFast):
  // single(): float32 vectors (the dense float32 K⁻¹); else float64 vectors (the matrix-free CG
  // at its fast tolerance). Only the overload that single() names is called.
  virtual bool single() const = 0;
  virtual void SolveFast(const float* y, bool transposed, float* x, cudaStream_t stream) const = 0;
  virtual void SolveFast(const double* y, bool transposed, double* x, cudaStream_t stream) const = 0;
  // True when a solve is itself iterative and reads its convergence on the host (the matrix-free
  // CG): the loop then enqueues no product whose result it might not need.
  virtual bool iterative() const = 0;
  // The dense K⁻¹ products behind the solves, where the fused loop can form them itself
  // (InverseRadiosity::View of every K⁻¹): how many (1 to 3) went into `products`; 0 otherwise.
  virtual int DenseProducts(DenseProduct (& /*products*/)[3]) const { return 0; }
};

// The problem in the loop's terms (host memory, read during the call only).
struct ResidentProblem {
  int patches = 0;
  // W = α diag(A/Ā) + (1−α) L (CompensationObjective::weights()): its diagonal, and its
  // off-diagonal entries in CSR form (row i: the neighbours j and W_ij = −(1−α)).
  const double* weight_diagonal = nullptr;   // patches
  const int* neighbour_offsets = nullptr;    // patches + 1
  const int* neighbours = nullptr;           // neighbour_offsets[patches]
  const double* neighbour_weights = nullptr;  // neighbour_offsets[patches]
  const double* lower = nullptr;            // n×3 column-major: bounds on E
  const double* upper = nullptr;
  const double* desired = nullptr;          // n×3 column-major: Bd, linear RGB
  const double* initial = nullptr;          // n×3 column-major, within the bounds
  // The colour space: L*a*b* of T·rgb relative to `white_xyz`, or linear_colour · rgb.
  bool lab = true;
  double rgb_to_xyz[9] = {};     // T, row-major
  double white_xyz[3] = {};
  double linear_colour[9] = {};  // row-major
  // A colour metric's per-patch factors L_i (ColourMetric::factor, Lab only): each residual and
  // Jacobian is multiplied by L_i. 9n values, entry (a, b) of L_i at [(3a + b)·n + i]; null: none.
  const double* metric_factor = nullptr;
};

// SolverOptions' settings of the loop: Alg. 1 and 2's (solver_driver.h documents them) and the
// device's own (solver.h documents each under its SolverOptions name): plain numbers, which the
// fused loop's kernel takes as they are.
struct ResidentSettings : AlgorithmSettings {
  bool fused = true;     // device_fused
  bool neumann = true;   // device_preconditioner: kBlockJacobiNeumann (else kBlockJacobi)
  bool graphs = true;    // device_graphs
  int fused_blocks = 0;  // device_fused_blocks
  bool profile = false;  // device_profile
};
struct ResidentOptions : ResidentSettings {
  std::function<void(int, double, double)> progress;
};

// What the loop ran: the driver's records, whether it was fused and the trace.
struct ResidentSummary {
  DriverRecords records;
  bool fused = false;    // the loop ran in one cooperative kernel ...
  int fused_blocks = 0;  // ... of this many blocks
  std::vector<IterationRecord> trace;
};

// Alg. 1 with Alg. 2 (MinimiseBoundedDriver, as MinimiseBounded runs it) with every vector on the
// device: the
// per-patch colour, residual, Jacobian and second-order term, W products (CSR), gradient, active
// set, conjugate gradients preconditioned by the inverse 3×3 diagonal blocks of the free
// variables' colour Hessian M_FF, the projected step of Alg. 2 and the Armijo search. The host
// reads back a few scalars per step. `emittance` (n×3 column-major, host) gets the result and
// `radiosity_out` (if not null) its radiosity K⁻¹E, as the last evaluation formed it.
// Throws std::runtime_error at device errors. Calls from several threads run at once: each takes
// a device workspace (the loop's arrays, stream, scalars and pinned staging) from a process-wide
// pool for its duration, so that concurrent calls share nothing, and a thread that solves again
// reuses one (grown as needed, kept between calls, never freed). `radiosity` is only read, but
// its solves must be safe to call from several threads at once where two calls share it (the
// dense K⁻¹'s are; the matrix-free CG keeps its vectors in the backend).
void MinimiseResident(const ResidentOptions& options, const ResidentProblem& problem, const DeviceRadiosity& radiosity,
                      double* emittance, double* radiosity_out, ResidentSummary* summary);

}  // namespace procam::cuda
