#pragma once
// The matrix-free radiosity solves of cuda_compressed.h behind a plain C++ interface (no CUDA or
// Eigen types, host pointers in and out), so that only cuda_compressed.cu is compiled by nvcc.
//
// Everything on the device lives in tree order (compressed_form_factors.h: position p holds
// patch order[p]) with the three channels interleaved (value 3p + c): every far block then
// reads and writes contiguous ranges, the near part's entries (renumbered once at upload) fall
// into blocks of neighbouring positions, and one gather reads a patch's three channels
// together. Inputs are permuted in and results out once per call.

#include <cstdint>
#include <memory>

// The CUDA runtime's stream handle (driver_types.h declares it the same way).
typedef struct CUstream_st* cudaStream_t;

namespace procam::cuda {

// The parts of a CompressedFormFactors (host memory, read during Create only).
struct CompressedParts {
  int patches = 0;
  int clusters = 0;
  const double* area = nullptr;   // patches
  const int* order = nullptr;     // patches: tree position → patch
  const int* begin = nullptr;     // clusters: first tree position
  const int* end = nullptr;       // clusters: one past the last tree position
  // near: patches × patches CSR of F in patch indices (patches + 1 row offsets).
  const int* near_offsets = nullptr;
  const int* near_columns = nullptr;
  const double* near_values = nullptr;
  // far: FarBlocks of compressed_form_factors.h, `far_blocks` blocks.
  int64_t far_blocks = 0;
  const int* far_rows = nullptr;
  const int* far_columns = nullptr;
  const int64_t* far_column_offset = nullptr;
  const int64_t* far_row_offset = nullptr;
  const double* far_scale = nullptr;
  const double* far_values = nullptr;
  int64_t far_value_count = 0;
};

// F and the reflectance on the device, with the conjugate-gradient solves of
// RadiositySystem::SolveIteratively (radiosity.h). One call at a time: the device buffers are
// shared by the calls.
class CompressedRadiosity {
 public:
  virtual ~CompressedRadiosity() = default;
  // `reflectance`: patches × 3, column-major. Throws std::runtime_error naming the CUDA call
  // that failed, or the device memory needed when it does not fit.
  static std::unique_ptr<CompressedRadiosity> Create(const CompressedParts& parts, const double* reflectance);
  // y = F x; x and y patches × 3, column-major, host memory.
  virtual void Multiply(const double* x, double* y) const = 0;
  // x = K⁻¹ y (K⁻ᵀ y when `transposed`), y and x patches × 3, column-major, host memory; CG
  // stops a channel at relative residual `tolerance` of the symmetric system. Returns the
  // iterations. Throws std::runtime_error when a channel has not converged in `max_iterations`.
  virtual int Solve(const double* y, bool transposed, double tolerance, int max_iterations, double* x) const = 0;
  // The same on device memory (y and x patches × 3, column-major, patch order; they may be the
  // same array), on stream(): work on other streams must be ordered against it by the caller.
  // Blocks the host only where CG reads its residual norms; x is ready on stream() when it
  // returns.
  virtual int SolveOnDevice(const double* y, bool transposed, double tolerance, int max_iterations,
                            double* x) const = 0;
  // The stream every call runs on.
  virtual cudaStream_t stream() const = 0;
};

}  // namespace procam::cuda
