// cuda_dense.h on cuBLAS and cuSOLVER.
#include "compensation/cuda_dense.h"

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

#include <cublas_v2.h>
#include <cuda_runtime.h>
#include <cusolverDn.h>

#include "compensation/cuda_common.cuh"

namespace procam::cuda {
namespace {

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

class InverseRadiosityImpl : public InverseRadiosity {
 public:
  InverseRadiosityImpl(const double* form_factors, const double* area, const double* reflectance, int n) : n_(n) {
    const Handles& handles = GetHandles();
    const size_t n2 = static_cast<size_t>(n) * n;
    size_t free_bytes = 0, total_bytes = 0;
    PROCAM_CUDA(cudaMemGetInfo(&free_bytes, &total_bytes));
    const size_t needed = n2 * (3 * sizeof(double) + sizeof(float));  // F, M, K⁻¹, float32 K⁻¹
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
    inverse_single_ = DeviceArray<float>(n2);
    ConvertKernel<<<Blocks(n2), kThreads>>>(inverse_.get(), static_cast<long>(n2), inverse_single_.get());
    PROCAM_CUDA_LAUNCHED("ConvertKernel");
    x_ = DeviceArray<double>(3 * static_cast<size_t>(n));
    y_ = DeviceArray<double>(3 * static_cast<size_t>(n));
    x_single_ = DeviceArray<float>(3 * static_cast<size_t>(n));
    y_single_ = DeviceArray<float>(3 * static_cast<size_t>(n));
    PROCAM_CUDA(cudaDeviceSynchronize());
  }

  void Apply(const double* x, int columns, bool transposed, bool single, double* y) const override {
    if (columns < 1 || columns > 3) throw std::invalid_argument("InverseRadiosity::Apply: 1 to 3 columns");
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
    if (columns < 1 || columns > 3) throw std::invalid_argument("InverseRadiosity::ApplyOnDevice: 1 to 3 columns");
    const Handles& handles = GetHandles();
    PROCAM_CUDA(cublasSetStream(handles.device_blas, stream));
    const double one = 1.0, zero = 0.0;
    PROCAM_CUDA(cublasDgemm(handles.device_blas, transposed ? CUBLAS_OP_T : CUBLAS_OP_N, CUBLAS_OP_N, n_, columns, n_,
                            &one, inverse_.get(), n_, x, n_, &zero, y, n_));
  }

  void ApplyOnDevice(const float* x, int columns, bool transposed, float* y, cudaStream_t stream) const override {
    if (columns < 1 || columns > 3) throw std::invalid_argument("InverseRadiosity::ApplyOnDevice: 1 to 3 columns");
    const Handles& handles = GetHandles();
    PROCAM_CUDA(cublasSetStream(handles.device_blas, stream));
    const float one = 1.0f, zero = 0.0f;
    PROCAM_CUDA(cublasSgemm(handles.device_blas, transposed ? CUBLAS_OP_T : CUBLAS_OP_N, CUBLAS_OP_N, n_, columns, n_,
                            &one, inverse_single_.get(), n_, x, n_, &zero, y, n_));
  }

  bool cholesky() const override { return cholesky_; }

 private:
  int n_ = 0;
  bool cholesky_ = true;
  DeviceArray<double> inverse_;        // K⁻¹, column-major
  DeviceArray<float> inverse_single_;  // the same in float32
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
  DeviceMatrixImpl(const double* matrix, int n) : n_(n), matrix_(static_cast<size_t>(n) * n) {
    GetHandles();
    PROCAM_CUDA(cudaMemcpy(matrix_.get(), matrix, matrix_.size() * sizeof(double), cudaMemcpyHostToDevice));
  }

  void Apply(const double* x, int columns, double* y) const override {
    const size_t count = static_cast<size_t>(n_) * columns;
    if (in_.size() < count) {
      in_ = DeviceArray<double>(count);
      out_ = DeviceArray<double>(count);
    }
    PROCAM_CUDA(cudaMemcpy(in_.get(), x, count * sizeof(double), cudaMemcpyHostToDevice));
    const double one = 1.0, zero = 0.0;
    PROCAM_CUDA(cublasDgemm(GetHandles().blas, CUBLAS_OP_N, CUBLAS_OP_N, n_, columns, n_, &one, matrix_.get(), n_,
                            in_.get(), n_, &zero, out_.get(), n_));
    PROCAM_CUDA(cudaMemcpy(y, out_.get(), count * sizeof(double), cudaMemcpyDeviceToHost));
  }

 private:
  int n_;
  DeviceArray<double> matrix_;
  mutable DeviceArray<double> in_, out_;
};

std::unique_ptr<DeviceMatrix> DeviceMatrix::Create(const double* matrix, int n) {
  return std::make_unique<DeviceMatrixImpl>(matrix, n);
}

std::unique_ptr<InverseRadiosity> InverseRadiosity::Create(const double* form_factors, const double* area,
                                                           const double* reflectance, int n) {
  return std::make_unique<InverseRadiosityImpl>(form_factors, area, reflectance, n);
}

}  // namespace procam::cuda
