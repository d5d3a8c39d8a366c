#pragma once
// The dense K⁻¹ product's device code, shared by cuda_dense.cu (one kernel per product) and
// cuda_solver.cu (the fused loop, which runs the same code inside its one cooperative kernel).
// Included by .cu files only.
#include <cuda_fp16.h>
#include <cuda_runtime.h>

namespace procam::cuda::product {

constexpr int kProductThreads = 256;  // threads of a block forming one group of outputs

// y = post · diag(left) Aᵀ diag(right) x for an n×n A (column-major float64 or float32, or the
// float16 quads below) and an n×columns x (columns ≤ 3; left/right null: ones). The transposed product reads
// A's columns, which are contiguous, so each output is one coalesced pass and no product needs a
// second reduction kernel: K⁻ᵀx is it with no scaling, and K⁻¹x on the Cholesky path too, through
// K⁻¹ = diag(s²) K⁻ᵀ diag(s⁻²) (K⁻¹ = S M⁻¹ S⁻¹ with M⁻¹ symmetric). Each block forms kRows
// outputs; its threads stride over the sum (one matrix load, reused for every column) and
// combine their partials in a fixed order (WriteRows); a Rows type (ColumnRows, HalfQuadRows)
// says how a block's rows are stored. cuBLAS's GEMM with three columns was measured slower
// (docs/gpu.md).

// The block's partial sums of outputs first … first + kRows − 1 combined (warp shuffles, then the
// warps in order) and written, times post and left.
template <typename T, int kRows>
__device__ inline void WriteRows(T (&sum)[kRows][3], int first, int n, int columns, const T* left, T post, T* y) {
  constexpr int kWarps = kProductThreads / 32;
  __shared__ T partial[kRows * 3][kWarps];
  const int lane = threadIdx.x % 32, warp = threadIdx.x / 32;
#pragma unroll
  for (int r = 0; r < kRows; ++r) {
#pragma unroll
    for (int c = 0; c < 3; ++c) {
      T value = sum[r][c];
      for (int offset = 16; offset > 0; offset /= 2) value += __shfl_down_sync(0xffffffffu, value, offset);
      if (lane == 0) partial[3 * r + c][warp] = value;
    }
  }
  __syncthreads();
  const int r = threadIdx.x / 3, c = threadIdx.x % 3;
  if (r < kRows && c < columns && first + r < n) {
    T value = 0;
    for (int w = 0; w < kWarps; ++w) value += partial[3 * r + c][w];
    const int i = first + r;
    y[static_cast<size_t>(c) * n + i] = post * (left != nullptr ? left[i] * value : value);
  }
}

// x_j · right_j for the columns there are (zeros beyond).
template <typename T>
__device__ inline void ScaledEntry(const T* __restrict__ x, const T* __restrict__ right, int n, int columns, int j, T (&v)[3]) {
  const T scale = right != nullptr ? right[j] : T(1);
#pragma unroll
  for (int c = 0; c < 3; ++c) v[c] = c < columns ? scale * x[static_cast<size_t>(c) * n + j] : T(0);
}

// A block's kRows rows of Aᵀ (columns of A) stored as T: entry j of each, one load per row.
template <typename T, int kRows>
struct ColumnRows {
  using Value = T;
  static constexpr int kCount = kRows;
  const T* row[kRows];
  __device__ ColumnRows(const T* matrix, int n, int first) {
    for (int r = 0; r < kRows; ++r) row[r] = matrix + static_cast<size_t>(min(first + r, n - 1)) * n;
  }
  __device__ void Load(int j, T (&m)[kRows]) const {
#pragma unroll
    for (int r = 0; r < kRows; ++r) m[r] = row[r][j];
  }
};

// The float16 copy of A: its columns in groups of four, interleaved, so that one 8-byte load
// gives four outputs' terms and a warp's load is 256 contiguous bytes (a column-major float16
// matrix would give 64): entry (j, 4q + t) at quads[q n + j], element t (columns past n: zeros).
struct alignas(8) HalfQuad {
  __half2 low, high;
};

// A block's 4·kQuads rows of Aᵀ from the float16 quads, widened to float32.
template <int kQuads>
struct HalfQuadRows {
  using Value = float;
  static constexpr int kCount = 4 * kQuads;
  const HalfQuad* quad[kQuads];
  __device__ HalfQuadRows(const HalfQuad* matrix, int n, int first) {
    const int quads = (n + 3) / 4;
    for (int q = 0; q < kQuads; ++q) quad[q] = matrix + static_cast<size_t>(min(first / 4 + q, quads - 1)) * n;
  }
  __device__ void Load(int j, float (&m)[4 * kQuads]) const {
#pragma unroll
    for (int q = 0; q < kQuads; ++q) {
      const HalfQuad h = quad[q][j];
      const float2 low = __half22float2(h.low), high = __half22float2(h.high);
      m[4 * q] = low.x;
      m[4 * q + 1] = low.y;
      m[4 * q + 2] = high.x;
      m[4 * q + 3] = high.y;
    }
  }
};

// Outputs group·kRows … group·kRows + kRows − 1 of y = post · diag(left) Aᵀ diag(right) x (the
// whole block takes part; every thread of it must call this).
template <typename Rows, typename S>
__device__ inline void TransposedProductGroup(int group, int n, int columns, const S* __restrict__ matrix,
                                              const typename Rows::Value* __restrict__ left,
                                              const typename Rows::Value* __restrict__ right,
                                              typename Rows::Value post, const typename Rows::Value* __restrict__ x,
                                              typename Rows::Value* __restrict__ y) {
  using T = typename Rows::Value;
  constexpr int kRows = Rows::kCount;
  const int first = group * kRows;
  const Rows rows(matrix, n, first);
  T sum[kRows][3] = {};
  for (int j = threadIdx.x; j < n; j += kProductThreads) {
    T v[3], m[kRows];
    ScaledEntry(x, right, n, columns, j, v);
    rows.Load(j, m);
#pragma unroll
    for (int r = 0; r < kRows; ++r) {
#pragma unroll
      for (int c = 0; c < 3; ++c) sum[r][c] += m[r] * v[c];
    }
  }
  WriteRows(sum, first, n, columns, left, post, y);
}

// The default shapes: 4 outputs per block on a float64 or float32 K⁻¹, 8 (two quads) on the
// float16 quads.
template <typename T>
using DenseRows = ColumnRows<T, 4>;
using HalfRows = HalfQuadRows<2>;

// Groups of outputs of an n-long product.
template <typename Rows>
__host__ __device__ inline int ProductGroups(int n) {
  return (n + Rows::kCount - 1) / Rows::kCount;
}

}  // namespace procam::cuda::product
