#pragma once
// Dense linear algebra of the CUDA backend behind a plain C++ interface (no CUDA types, host
// pointers in and out), so that only cuda_dense.cu is compiled by nvcc.
//
// For one colour channel (or several sharing a reflectance) it forms K⁻¹ = (I − diag(rho) F)⁻¹
// explicitly on the device, once: the symmetric form M = I − D^½ A^½ F A^-½ D^½ (D = diag rho,
// SPD by reciprocity, eigenvalues in [1 − max rho, 1 + max rho]) is factorised by cuSOLVER
// (potrf) and inverted (potrs on the identity, 2n³ flops), and K⁻¹ = diag(s) M⁻¹ diag(1/s) with
// s = D^½ A^-½; a channel with a black patch (rho = 0) takes pivoted LU (getrf, getrs). Every
// later K⁻¹x or K⁻ᵀx is then one product with a few columns, fully parallel and bandwidth-bound,
// instead of two latency-bound triangular solves: cuBLAS's GEMM for the host API, an own kernel
// for device vectors (ApplyOnDevice: one coalesced pass over K⁻¹'s columns for both directions,
// 1.5–2× faster than GEMM at three columns). cond(K) ≤ (1 + max rho) / (1 − max rho) (19 at
// rho = 0.9), so the explicit inverse loses nothing measurable.

#include <memory>
#include <string>

// The CUDA runtime's stream handle (driver_types.h declares it the same way), so that this header
// needs no CUDA include.
typedef struct CUstream_st* cudaStream_t;

namespace procam::cuda {

// True when a CUDA device can be used (its context is created here, so later timings exclude
// it); `description` gets the device's name and memory, or why none can be used.
bool DeviceAvailable(std::string* description);

// The dense K⁻¹'s device arrays as the fused resident loop reads them (cuda_solver.cu runs the
// product of cuda_product.cuh inside its own kernel): K⁻ᵀx = Aᵀx and, on the Cholesky path,
// K⁻¹x = diag(s²) Aᵀ diag(s⁻²) x for A = K⁻¹ (column-major), in float64 or from the float16
// quads of 2^k K⁻¹ (times 2^-k) with float32 vectors. Device pointers, owned by the
// InverseRadiosity.
struct DenseInverseView {
  const double* inverse = nullptr;
  const void* half_quads = nullptr;  // cuda_product.cuh's HalfQuad
  float half_post = 1.0f;            // 2^-k
  const double* square = nullptr;    // s²
  const double* inverse_square = nullptr;
  const float* square_single = nullptr;
  const float* inverse_square_single = nullptr;
};

// How ApplyOnDevice forms its products (SolverOptions::device_product_rows and device_cg_matrix;
// the defaults are the measured best, docs/gpu.md).
struct DenseProductSettings {
  // Outputs per block of the own product kernel: 1, 2, 4 or 8; 0: cuBLAS's GEMM instead; -1: the
  // default (4 for float64 and float32 K⁻¹, 8 for the float16 copy).
  int rows = -1;
  // CG's float32 products read a float16 copy of 2^k K⁻¹ (half the bytes); false: the float32
  // copy. Not used where `rows` is 0 (cuBLAS has no float16 quads).
  bool half_cg_matrix = true;
};

class InverseRadiosity {
 public:
  virtual ~InverseRadiosity() = default;
  // K⁻¹ of one channel: `form_factors` n×n column-major, `area` and `reflectance` n, host
  // memory. Throws std::runtime_error naming the CUDA call that failed (or the memory needed),
  // std::invalid_argument where `settings.rows` is none of -1, 0, 1, 2, 4, 8.
  static std::unique_ptr<InverseRadiosity> Create(const double* form_factors, const double* area,
                                                  const double* reflectance, int n,
                                                  const DenseProductSettings& settings = {});
  // y = K⁻¹ x (K⁻ᵀ x when `transposed`); x and y are n×columns, column-major, host memory.
  // `single`: with the float32 copy of K⁻¹ (float32 arithmetic), else float64.
  virtual void Apply(const double* x, int columns, bool transposed, bool single, double* y) const = 0;
  // The same on device memory, enqueued on `stream` without copies or synchronisation (the
  // resident solver, cuda_solver.h): float64 with the float64 K⁻¹; float32 vectors (CG's Hessian
  // products) with a float16 copy of 2^k K⁻¹ (half the bytes; within 2^-11 relative, measured
  // ~5e-6), or the float32 copy where settings.half_cg_matrix is false. x and y must not overlap.
  // Callable from several threads at once (the cuBLAS path, K⁻¹x on the LU path, takes a lock).
  virtual void ApplyOnDevice(const double* x, int columns, bool transposed, double* y, cudaStream_t stream) const = 0;
  virtual void ApplyOnDevice(const float* x, int columns, bool transposed, float* y, cudaStream_t stream) const = 0;
  // Whether the Cholesky path was taken (else LU).
  virtual bool cholesky() const = 0;
  // Fills `view` and returns true where ApplyOnDevice runs the own product kernel at its default
  // shape in both directions with the float16 copy for float32 vectors (the Cholesky path, the
  // default DenseProductSettings); else false.
  virtual bool View(DenseInverseView* view) const = 0;
};

// A dense n×n matrix kept on the device for products with a few columns (F, for the solver's
// K·Bd start when K⁻¹ lives on the device: an n² product the CPU would otherwise do).
class DeviceMatrix {
 public:
  virtual ~DeviceMatrix() = default;
  // `matrix` n×n column-major, host memory. Throws std::runtime_error like InverseRadiosity.
  static std::unique_ptr<DeviceMatrix> Create(const double* matrix, int n);
  // y = A x; x and y n×columns (1 to 3), column-major, host memory (copied each way).
  virtual void Apply(const double* x, int columns, double* y) const = 0;
};

}  // namespace procam::cuda
