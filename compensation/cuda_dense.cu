// cuda_dense.h on cuBLAS and cuSOLVER.
#include "compensation/cuda_dense.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include <cublas_v2.h>
#include <cuda_fp16.h>
#include <cuda_runtime.h>
#include <cusolverDn.h>

#include "compensation/cuda_common.cuh"
#include "compensation/cuda_product.cuh"

namespace procam::cuda {
namespace {

using namespace product;  // NOLINT: the product kernel's own header

// The library statuses beside cuda_common.cuh's cudaError_t check, all found by PROCAM_CUDA.
using ::procam::cuda::Check;
void Check(cublasStatus_t status, const char* call) {
  if (status != CUBLAS_STATUS_SUCCESS) Throw(call, "cuBLAS status " + std::to_string(static_cast<int>(status)));
}
void Check(cusolverStatus_t status, const char* call) {
  if (status != CUSOLVER_STATUS_SUCCESS) Throw(call, "cuSOLVER status " + std::to_string(static_cast<int>(status)));
}

// One cuBLAS and one cuSOLVER handle for the process, made on first use (handle creation costs
// milliseconds; DeviceAvailable makes them, so benchmarks time neither). Never destroyed: the
// runtime may be torn down before static destructors run.
// `device_blas` serves ApplyOnDevice: its stream is set per call, so that the host API's handle
// keeps the default stream that its synchronous copies rely on. It has a workspace of its own, so
// that cuBLAS allocates nothing while the resident solver captures its products into CUDA graphs.
constexpr size_t kDeviceBlasWorkspace = size_t{4} << 20;
struct Handles {
  cublasHandle_t blas = nullptr;
  cublasHandle_t device_blas = nullptr;
  void* device_blas_workspace = nullptr;
  cusolverDnHandle_t solver = nullptr;
};
// cuBLAS and cuSOLVER handles may not be used from two threads at once (a stream set by one
// thread would carry the other's work): every use holds this lock. The products of the resident
// loops run the own kernel and take it only on the LU path's K⁻¹x.
std::mutex& HandlesMutex() {
  static std::mutex* mutex = new std::mutex;
  return *mutex;
}
const Handles& GetHandles() {
  static const Handles* handles = [] {
    auto* h = new Handles;
    PROCAM_CUDA(cublasCreate(&h->blas));
    PROCAM_CUDA(cublasCreate(&h->device_blas));
    PROCAM_CUDA(cudaMalloc(&h->device_blas_workspace, kDeviceBlasWorkspace));
    PROCAM_CUDA(cublasSetWorkspace(h->device_blas, h->device_blas_workspace, kDeviceBlasWorkspace));
    PROCAM_CUDA(cusolverDnCreate(&h->solver));
    return h;
  }();
  return *handles;
}

constexpr int kThreads = 256;
int Blocks(long count) { return static_cast<int>((count + kThreads - 1) / kThreads); }

// out(i,j) = δij − ½ (l_i F_ij r_j + l_j F_ji r_i): the symmetric M (column-major, n×n).
__global__ void SymmetricFormKernel(const double* f, const double* left, const double* right, int n, double* out) {
  const long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x;
  if (k >= static_cast<long>(n) * n) return;
  const int i = static_cast<int>(k % n), j = static_cast<int>(k / n);
  const double value = 0.5 * (left[i] * f[k] * right[j] + left[j] * f[static_cast<long>(i) * n + j] * right[i]);
  out[k] = (i == j ? 1.0 : 0.0) - value;
}

// out(i,j) = δij − rho_i F_ij: K itself, for the LU path.
__global__ void RadiosityMatrixKernel(const double* f, const double* rho, int n, double* out) {
  const long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x;
  if (k >= static_cast<long>(n) * n) return;
  const int i = static_cast<int>(k % n), j = static_cast<int>(k / n);
  out[k] = (i == j ? 1.0 : 0.0) - rho[i] * f[k];
}

__global__ void IdentityKernel(int n, double* out) {
  const long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x;
  if (k >= static_cast<long>(n) * n) return;
  out[k] = (k % n == k / n) ? 1.0 : 0.0;
}

// a(i,j) *= s_i / s_j.
__global__ void ScaleKernel(const double* s, int n, double* a) {
  const long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x;
  if (k >= static_cast<long>(n) * n) return;
  a[k] *= s[k % n] / s[k / n];
}

template <typename From, typename To>
__global__ void ConvertKernel(const From* in, long count, To* out) {
  const long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x;
  if (k < count) out[k] = static_cast<To>(in[k]);
}

// Outputs per block of the product by default: 4 on the float64 and float32 K⁻¹, 8 on the float16
// quads (DenseRows and HalfRows of cuda_product.cuh; the fastest at 9800 patches, docs/gpu.md).
constexpr int kDoubleRows = DenseRows<double>::kCount;
constexpr int kHalfRows = HalfRows::kCount;

// One group of outputs per block (cuda_product.cuh has the product and its layouts).
template <typename Rows, typename S>
__global__ void __launch_bounds__(kProductThreads)
    TransposedProductKernel(int n, int columns, const S* __restrict__ matrix,
                            const typename Rows::Value* __restrict__ left,
                            const typename Rows::Value* __restrict__ right, typename Rows::Value post,
                            const typename Rows::Value* __restrict__ x, typename Rows::Value* __restrict__ y) {
  TransposedProductGroup<Rows>(blockIdx.x, n, columns, matrix, left, right, post, x, y);
}

__global__ void ToHalfQuadsKernel(const double* in, int n, double scale, HalfQuad* out) {
  const long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x;
  const long quads = (n + 3) / 4;
  if (k >= quads * n) return;
  const int q = static_cast<int>(k / n), j = static_cast<int>(k % n);
  __half v[4];
  for (int t = 0; t < 4; ++t) {
    const int column = 4 * q + t;
    v[t] = column < n ? __double2half(scale * in[static_cast<size_t>(column) * n + j]) : __double2half(0.0);
  }
  out[k] = {__halves2half2(v[0], v[1]), __halves2half2(v[2], v[3])};
}

template <typename Rows, typename S, typename T>
void LaunchProduct(int n, int columns, const S* matrix, const T* left, const T* right, T post, const T* x, T* y,
                   cudaStream_t stream) {
  TransposedProductKernel<Rows><<<ProductGroups<Rows>(n), kProductThreads, 0, stream>>>(n, columns, matrix, left, right, post, x, y);
  PROCAM_CUDA_LAUNCHED("TransposedProductKernel");
}

// Enqueues TransposedProductKernel with `rows` outputs per block (1, 2, 4 or 8).
template <typename T>
void TransposedProduct(int n, int columns, int rows, const T* matrix, const T* left, const T* right, T post,
                       const T* x, T* y, cudaStream_t stream) {
  switch (rows) {
    case 1: LaunchProduct<ColumnRows<T, 1>>(n, columns, matrix, left, right, post, x, y, stream); break;
    case 2: LaunchProduct<ColumnRows<T, 2>>(n, columns, matrix, left, right, post, x, y, stream); break;
    case 4: LaunchProduct<ColumnRows<T, 4>>(n, columns, matrix, left, right, post, x, y, stream); break;
    default: LaunchProduct<ColumnRows<T, 8>>(n, columns, matrix, left, right, post, x, y, stream); break;
  }
}

// The same on the float16 quads: 8 outputs per block (two quads), 4 where `rows` is below 8.
void TransposedProduct(int n, int columns, int rows, const HalfQuad* matrix, const float* left, const float* right,
                       float post, const float* x, float* y, cudaStream_t stream) {
  if (rows >= 8) {
    LaunchProduct<HalfQuadRows<2>>(n, columns, matrix, left, right, post, x, y, stream);
  } else {
    LaunchProduct<HalfQuadRows<1>>(n, columns, matrix, left, right, post, x, y, stream);
  }
}

class InverseRadiosityImpl : public InverseRadiosity {
 public:
  InverseRadiosityImpl(const double* form_factors, const double* area, const double* reflectance, int n,
                       const DenseProductSettings& settings)
      : n_(n) {
    const std::lock_guard<std::mutex> lock(HandlesMutex());
    const int rows = settings.rows;
    if (rows != -1 && rows != 0 && rows != 1 && rows != 2 && rows != 4 && rows != 8) {
      throw std::invalid_argument("InverseRadiosity: product rows " + std::to_string(settings.rows) +
                                  " is not -1 (default), 0 (cuBLAS), 1, 2, 4 or 8");
    }
    const Handles& handles = GetHandles();
    const size_t n2 = static_cast<size_t>(n) * n;
    size_t free_bytes = 0, total_bytes = 0;
    PROCAM_CUDA(cudaMemGetInfo(&free_bytes, &total_bytes));
    // F, M, K⁻¹, float32 and float16 K⁻¹
    const size_t needed = n2 * (3 * sizeof(double) + sizeof(float) + sizeof(uint16_t));
    if (needed > free_bytes) {
      throw std::runtime_error("CUDA: the dense K^-1 of " + std::to_string(n) + " patches needs " +
                               std::to_string(needed >> 20) + " MiB of device memory, " +
                               std::to_string(free_bytes >> 20) + " MiB are free");
    }
    double min_rho = reflectance[0];
    for (int i = 1; i < n; ++i) min_rho = std::min(min_rho, reflectance[i]);
    DeviceArray<double> f(n2), m(n2);
    inverse_ = DeviceArray<double>(n2);
    PROCAM_CUDA(cudaMemcpy(f.get(), form_factors, n2 * sizeof(double), cudaMemcpyHostToDevice));
    DeviceArray<int> info(1);
    int host_info = 0;
    cholesky_ = min_rho > 0.0;
    std::vector<double> scale(n);
    DeviceArray<double> d_scale(n);
    if (cholesky_) {
      std::vector<double> left(n), right(n);
      for (int i = 0; i < n; ++i) {
        left[i] = std::sqrt(reflectance[i]) * std::sqrt(area[i]);
        right[i] = std::sqrt(reflectance[i]) / std::sqrt(area[i]);
        scale[i] = right[i];  // s = D^½ A^-½
      }
      DeviceArray<double> d_left(n);
      PROCAM_CUDA(cudaMemcpy(d_left.get(), left.data(), n * sizeof(double), cudaMemcpyHostToDevice));
      PROCAM_CUDA(cudaMemcpy(d_scale.get(), right.data(), n * sizeof(double), cudaMemcpyHostToDevice));
      SymmetricFormKernel<<<Blocks(n2), kThreads>>>(f.get(), d_left.get(), d_scale.get(), n, m.get());
      PROCAM_CUDA_LAUNCHED("SymmetricFormKernel");
      int work_size = 0;
      PROCAM_CUDA(cusolverDnDpotrf_bufferSize(handles.solver, CUBLAS_FILL_MODE_LOWER, n, m.get(), n, &work_size));
      DeviceArray<double> work(std::max(work_size, 1));
      PROCAM_CUDA(cusolverDnDpotrf(handles.solver, CUBLAS_FILL_MODE_LOWER, n, m.get(), n, work.get(), work_size,
                                   info.get()));
      PROCAM_CUDA(cudaMemcpy(&host_info, info.get(), sizeof(int), cudaMemcpyDeviceToHost));
      cholesky_ = host_info == 0;  // not positive definite (cannot happen in exact arithmetic): LU
    }
    if (cholesky_) {
      IdentityKernel<<<Blocks(n2), kThreads>>>(n, inverse_.get());
      PROCAM_CUDA_LAUNCHED("IdentityKernel");
      PROCAM_CUDA(cusolverDnDpotrs(handles.solver, CUBLAS_FILL_MODE_LOWER, n, n, m.get(), n, inverse_.get(), n,
                                   info.get()));
      ScaleKernel<<<Blocks(n2), kThreads>>>(d_scale.get(), n, inverse_.get());
      PROCAM_CUDA_LAUNCHED("ScaleKernel");
    } else {
      DeviceArray<double> rho(n);
      PROCAM_CUDA(cudaMemcpy(rho.get(), reflectance, n * sizeof(double), cudaMemcpyHostToDevice));
      RadiosityMatrixKernel<<<Blocks(n2), kThreads>>>(f.get(), rho.get(), n, m.get());
      PROCAM_CUDA_LAUNCHED("RadiosityMatrixKernel");
      int work_size = 0;
      PROCAM_CUDA(cusolverDnDgetrf_bufferSize(handles.solver, n, n, m.get(), n, &work_size));
      DeviceArray<double> work(std::max(work_size, 1));
      DeviceArray<int> pivots(n);
      PROCAM_CUDA(cusolverDnDgetrf(handles.solver, n, n, m.get(), n, work.get(), pivots.get(), info.get()));
      PROCAM_CUDA(cudaMemcpy(&host_info, info.get(), sizeof(int), cudaMemcpyDeviceToHost));
      if (host_info != 0) Throw("cusolverDnDgetrf", "K is singular (info " + std::to_string(host_info) + ")");
      IdentityKernel<<<Blocks(n2), kThreads>>>(n, inverse_.get());
      PROCAM_CUDA_LAUNCHED("IdentityKernel");
      PROCAM_CUDA(cusolverDnDgetrs(handles.solver, CUBLAS_OP_N, n, n, m.get(), n, pivots.get(), inverse_.get(), n,
                                   info.get()));
    }
    if (cholesky_) {
      // K⁻¹x = diag(s²) K⁻ᵀ diag(s⁻²) x (TransposedProductKernel).
      std::vector<double> square(n), inverse_square(n);
      for (int i = 0; i < n; ++i) {
        square[i] = scale[i] * scale[i];
        inverse_square[i] = 1.0 / square[i];
      }
      square_ = Upload(square);
      inverse_square_ = Upload(inverse_square);
      square_single_ = Upload(std::vector<float>(square.begin(), square.end()));
      inverse_square_single_ = Upload(std::vector<float>(inverse_square.begin(), inverse_square.end()));
    }
    product_rows_ = settings.rows < 0 ? kDoubleRows : settings.rows;
    half_rows_ = settings.rows < 0 ? kHalfRows : settings.rows;
    inverse_single_ = DeviceArray<float>(n2);
    ConvertKernel<<<Blocks(n2), kThreads>>>(inverse_.get(), static_cast<long>(n2), inverse_single_.get());
    PROCAM_CUDA_LAUNCHED("ConvertKernel");
    if (product_rows_ > 0 && settings.half_cg_matrix) {
      // K⁻¹ · 2^k in float16, 2^k the largest power of two that keeps max |K⁻¹| under 2^15 (the
      // format's largest is 65504): entries down to 6e-5 · 2^-k keep 11 significant bits.
      int64_t largest = 0;
      PROCAM_CUDA(cublasIdamax_64(handles.blas, static_cast<int64_t>(n2), inverse_.get(), 1, &largest));
      double peak = 0.0;
      PROCAM_CUDA(cudaMemcpy(&peak, inverse_.get() + (largest - 1), sizeof(double), cudaMemcpyDeviceToHost));
      const double power = std::floor(std::log2(32768.0 / std::max(std::abs(peak), 1e-300)));
      const double factor = std::ldexp(1.0, static_cast<int>(std::min(power, 60.0)));
      half_post_ = static_cast<float>(1.0 / factor);
      const long quads = static_cast<long>((n + 3) / 4) * n;
      inverse_half_ = DeviceArray<HalfQuad>(quads);
      ToHalfQuadsKernel<<<Blocks(quads), kThreads>>>(inverse_.get(), n, factor, inverse_half_.get());
      PROCAM_CUDA_LAUNCHED("ToHalfQuadsKernel");
    }
    x_ = DeviceArray<double>(3 * static_cast<size_t>(n));
    y_ = DeviceArray<double>(3 * static_cast<size_t>(n));
    x_single_ = DeviceArray<float>(3 * static_cast<size_t>(n));
    y_single_ = DeviceArray<float>(3 * static_cast<size_t>(n));
    PROCAM_CUDA(cudaDeviceSynchronize());
  }

  void Apply(const double* x, int columns, bool transposed, bool single, double* y) const override {
    if (columns < 1 || columns > 3) throw std::invalid_argument("InverseRadiosity::Apply: 1 to 3 columns");
    const std::lock_guard<std::mutex> lock(HandlesMutex());
    const Handles& handles = GetHandles();
    const long count = static_cast<long>(n_) * columns;
    const cublasOperation_t op = transposed ? CUBLAS_OP_T : CUBLAS_OP_N;
    PROCAM_CUDA(cudaMemcpy(x_.get(), x, count * sizeof(double), cudaMemcpyHostToDevice));
    if (single) {
      const float one = 1.0f, zero = 0.0f;
      ConvertKernel<<<Blocks(count), kThreads>>>(x_.get(), count, x_single_.get());
      PROCAM_CUDA_LAUNCHED("ConvertKernel");
      PROCAM_CUDA(cublasSgemm(handles.blas, op, CUBLAS_OP_N, n_, columns, n_, &one, inverse_single_.get(), n_,
                              x_single_.get(), n_, &zero, y_single_.get(), n_));
      ConvertKernel<<<Blocks(count), kThreads>>>(y_single_.get(), count, y_.get());
      PROCAM_CUDA_LAUNCHED("ConvertKernel");
    } else {
      const double one = 1.0, zero = 0.0;
      PROCAM_CUDA(cublasDgemm(handles.blas, op, CUBLAS_OP_N, n_, columns, n_, &one, inverse_.get(), n_, x_.get(),
                              n_, &zero, y_.get(), n_));
    }
    PROCAM_CUDA(cudaMemcpy(y, y_.get(), count * sizeof(double), cudaMemcpyDeviceToHost));
  }

  void ApplyOnDevice(const double* x, int columns, bool transposed, double* y, cudaStream_t stream) const override {
    ApplyOnDevice(inverse_.get(), 1.0, square_.get(), inverse_square_.get(), x, columns, transposed, y, stream);
  }

  void ApplyOnDevice(const float* x, int columns, bool transposed, float* y, cudaStream_t stream) const override {
    if (inverse_half_.size() > 0 && OwnKernel(transposed)) {
      ApplyOnDevice(inverse_half_.get(), half_post_, square_single_.get(), inverse_square_single_.get(), x, columns,
                    transposed, y, stream);
    } else {
      ApplyOnDevice(inverse_single_.get(), 1.0f, square_single_.get(), inverse_square_single_.get(), x, columns,
                    transposed, y, stream);
    }
  }

  bool cholesky() const override { return cholesky_; }

  bool View(DenseInverseView* view) const override {
    if (!cholesky_ || inverse_half_.size() == 0 || product_rows_ != kDoubleRows || half_rows_ != kHalfRows) {
      return false;
    }
    view->inverse = inverse_.get();
    view->half_quads = inverse_half_.get();
    view->half_post = half_post_;
    view->square = square_.get();
    view->inverse_square = inverse_square_.get();
    view->square_single = square_single_.get();
    view->inverse_square_single = inverse_square_single_.get();
    return true;
  }

 private:
  // Whether TransposedProductKernel serves this direction: K⁻ᵀx always, K⁻¹x on the Cholesky path
  // (K⁻¹ = diag(s²) K⁻ᵀ diag(s⁻²)); not where DenseProductSettings::rows is 0 (cuBLAS).
  bool OwnKernel(bool transposed) const { return product_rows_ > 0 && (transposed || cholesky_); }

  // y = K⁻¹x or K⁻ᵀx with `inverse` (post · K⁻¹ stored as S) and the Cholesky path's s², s⁻² in
  // T: own kernel, or cuBLAS's GEMM (S = T) for K⁻¹x on the LU path and where
  // DenseProductSettings::rows is 0.
  template <typename S, typename T>
  void ApplyOnDevice(const S* inverse, T post, const T* square, const T* inverse_square, const T* x, int columns,
                     bool transposed, T* y, cudaStream_t stream) const {
    if (columns < 1 || columns > 3) throw std::invalid_argument("InverseRadiosity::ApplyOnDevice: 1 to 3 columns");
    if (OwnKernel(transposed)) {
      const int rows = std::is_same_v<S, HalfQuad> ? half_rows_ : product_rows_;
      TransposedProduct(n_, columns, rows, inverse, transposed ? nullptr : square,
                        transposed ? nullptr : inverse_square, post, x, y, stream);
      return;
    }
    if constexpr (std::is_same_v<S, T>) {
      const std::lock_guard<std::mutex> lock(HandlesMutex());
      const Handles& handles = GetHandles();
      PROCAM_CUDA(cublasSetStream(handles.device_blas, stream));
      const T one = 1, zero = 0;
      const cublasOperation_t op = transposed ? CUBLAS_OP_T : CUBLAS_OP_N;
      if constexpr (std::is_same_v<T, double>) {
        PROCAM_CUDA(cublasDgemm(handles.device_blas, op, CUBLAS_OP_N, n_, columns, n_, &one, inverse, n_, x, n_,
                                &zero, y, n_));
      } else {
        PROCAM_CUDA(cublasSgemm(handles.device_blas, op, CUBLAS_OP_N, n_, columns, n_, &one, inverse, n_, x, n_,
                                &zero, y, n_));
      }
    } else {
      throw std::logic_error("InverseRadiosity: K^-1 x on the LU path needs the float32 or float64 copy");
    }
  }

  int n_ = 0;
  bool cholesky_ = true;
  DeviceArray<double> inverse_;        // K⁻¹, column-major
  DeviceArray<float> inverse_single_;  // the same in float32
  // Cholesky path: s² and s⁻² (s = D^½ A^-½), float64 and float32.
  DeviceArray<double> square_, inverse_square_;
  DeviceArray<float> square_single_, inverse_square_single_;
  int product_rows_ = 0, half_rows_ = 0;
  // 2^k K⁻¹ in float16, as quads of columns (empty: not used), and 2^-k.
  DeviceArray<HalfQuad> inverse_half_;
  float half_post_ = 1.0f;
  // Staging for Apply (n×3 each).
  DeviceArray<double> x_, y_;
  DeviceArray<float> x_single_, y_single_;
};

}  // namespace

bool DeviceAvailable(std::string* description) {
  int count = 0;
  const cudaError_t status = cudaGetDeviceCount(&count);
  if (status != cudaSuccess || count == 0) {
    *description = std::string("no usable CUDA device (") +
                   (status != cudaSuccess ? cudaGetErrorString(status) : "none found") + ")";
    cudaGetLastError();  // clear the sticky error for later calls
    return false;
  }
  cudaDeviceProp properties;
  if (cudaGetDeviceProperties(&properties, 0) != cudaSuccess || cudaFree(nullptr) != cudaSuccess) {
    *description = "CUDA device 0 could not be initialised";
    return false;
  }
  GetHandles();
  char text[256];
  std::snprintf(text, sizeof text, "%s (compute capability %d.%d, %.1f GiB, %d multiprocessors)", properties.name,
                properties.major, properties.minor, properties.totalGlobalMem / double(1 << 30),
                properties.multiProcessorCount);
  *description = text;
  return true;
}

class DeviceMatrixImpl : public DeviceMatrix {
 public:
  // The staging vectors are allocated here, with the matrix: a cudaMalloc in the first Apply
  // would land in the solve's time.
  DeviceMatrixImpl(const double* matrix, int n)
      : n_(n), matrix_(static_cast<size_t>(n) * n), in_(3 * static_cast<size_t>(n)), out_(3 * static_cast<size_t>(n)) {
    GetHandles();
    PROCAM_CUDA(cudaMallocHost(&staging_, 3 * static_cast<size_t>(n) * sizeof(double)));
    PROCAM_CUDA(cudaMemcpy(matrix_.get(), matrix, matrix_.size() * sizeof(double), cudaMemcpyHostToDevice));
  }

  void Apply(const double* x, int columns, double* y) const override {
    if (columns < 1 || columns > 3) throw std::invalid_argument("DeviceMatrix::Apply: 1 to 3 columns");
    const size_t bytes = static_cast<size_t>(n_) * columns * sizeof(double);
    const std::lock_guard<std::mutex> lock(HandlesMutex());
    std::memcpy(staging_, x, bytes);
    PROCAM_CUDA(cudaMemcpy(in_.get(), staging_, bytes, cudaMemcpyHostToDevice));
    const double one = 1.0, zero = 0.0;
    PROCAM_CUDA(cublasDgemm(GetHandles().blas, CUBLAS_OP_N, CUBLAS_OP_N, n_, columns, n_, &one, matrix_.get(), n_,
                            in_.get(), n_, &zero, out_.get(), n_));
    PROCAM_CUDA(cudaMemcpy(staging_, out_.get(), bytes, cudaMemcpyDeviceToHost));
    std::memcpy(y, staging_, bytes);
  }

  ~DeviceMatrixImpl() override { cudaFreeHost(staging_); }
  DeviceMatrixImpl(const DeviceMatrixImpl&) = delete;
  DeviceMatrixImpl& operator=(const DeviceMatrixImpl&) = delete;

 private:
  int n_;
  DeviceArray<double> matrix_;
  DeviceArray<double> in_, out_;
  double* staging_ = nullptr;  // pinned, n×3: the copies skip the driver's bounce buffer
};

std::unique_ptr<DeviceMatrix> DeviceMatrix::Create(const double* matrix, int n) {
  return std::make_unique<DeviceMatrixImpl>(matrix, n);
}

std::unique_ptr<InverseRadiosity> InverseRadiosity::Create(const double* form_factors, const double* area,
                                                           const double* reflectance, int n,
                                                           const DenseProductSettings& settings) {
  return std::make_unique<InverseRadiosityImpl>(form_factors, area, reflectance, n, settings);
}

}  // namespace procam::cuda
