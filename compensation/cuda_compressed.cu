// cuda_compressed_device.h on CUDA kernels.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <cuda_runtime.h>

#include "compensation/cuda_common.cuh"
#include "compensation/cuda_compressed_device.h"

namespace procam::cuda {
namespace {

constexpr int kThreads = 256;  // per block; BlockSum assumes exactly this
constexpr int kWarpsPerBlock = kThreads / 32;
// Blocks of a kernel that leaves per-block partial sums: a fixed grid (grid-stride loops), so
// that the sums are formed in the same order on every call (deterministic results).
constexpr int kMaxPartials = 1024;
// Iterations between two reads of the residual norms: each read stalls the device for a host
// round trip; iterations done after every channel converged do nothing (their kernels return
// at once) but still cost their launches.
constexpr int kCheckInterval = 4;

int Blocks(long count) { return static_cast<int>(std::max(1L, (count + kThreads - 1) / kThreads)); }
int ReductionBlocks(long count) { return std::min(kMaxPartials, Blocks(count)); }

// The scalars of the three side-by-side conjugate-gradient solves, kept on the device so that
// an iteration needs no host round trip.
struct CgState {
  double rr[3];    // rᵀr per channel
  double goal[3];  // tolerance² · rhsᵀrhs: the channel has converged once rr ≤ goal
  double step[3];
  double beta[3];
  int updating[3];  // the channel takes part in the current iteration
  int iterations;   // iterations in which some channel took part
};

__device__ bool Unconverged(const CgState* state) {
  return state->rr[0] > state->goal[0] || state->rr[1] > state->goal[1] || state->rr[2] > state->goal[2];
}
// Kernels of an iteration take the state as a gate: once every channel has converged they
// return at once (the whole block alike, before any barrier).
__device__ bool Closed(const CgState* gate) { return gate != nullptr && !Unconverged(gate); }
__device__ bool AnyUpdating(const CgState* state) {
  return state->updating[0] != 0 || state->updating[1] != 0 || state->updating[2] != 0;
}

// Sums value[0..2] over the block (blockDim.x == kThreads) in a fixed order; every thread gets
// the sums.
__device__ void BlockSum(double value[3]) {
  __shared__ double shared[3][kThreads];
  const int t = threadIdx.x;
  for (int c = 0; c < 3; ++c) shared[c][t] = value[c];
  __syncthreads();
  for (int half = kThreads / 2; half > 0; half /= 2) {
    if (t < half) {
      for (int c = 0; c < 3; ++c) shared[c][t] += shared[c][t + half];
    }
    __syncthreads();
  }
  for (int c = 0; c < 3; ++c) value[c] = shared[c][0];
}

// The sums of `count` per-block partials (3 each), for a one-block kernel.
__device__ void SumPartials(const double* partials, int count, double total[3]) {
  total[0] = total[1] = total[2] = 0.0;
  for (int b = threadIdx.x; b < count; b += blockDim.x) {
    for (int c = 0; c < 3; ++c) total[c] += partials[3 * b + c];
  }
  BlockSum(total);
}

// tree[3p + c] = columns[c n + order[p]].
__global__ void ToTreeOrderKernel(int n, const int* order, const double* columns, double* tree) {
  const int p = blockIdx.x * blockDim.x + threadIdx.x;
  if (p >= n) return;
  const int patch = order[p];
  for (int c = 0; c < 3; ++c) tree[3 * p + c] = columns[static_cast<long>(c) * n + patch];
}

// The inverse of ToTreeOrderKernel.
__global__ void FromTreeOrderKernel(int n, const int* order, const double* tree, double* columns) {
  const int p = blockIdx.x * blockDim.x + threadIdx.x;
  if (p >= n) return;
  const int patch = order[p];
  for (int c = 0; c < 3; ++c) columns[static_cast<long>(c) * n + patch] = tree[3 * p + c];
}

// out = x ∘ scale, element by element.
__global__ void ScaleKernel(long count, const double* x, const double* scale, const CgState* gate, double* out) {
  if (Closed(gate)) return;
  const long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x;
  if (k < count) out[k] = x[k] * scale[k];
}

// out = a + b, element by element.
__global__ void AddKernel(long count, const double* a, const double* b, double* out) {
  const long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x;
  if (k < count) out[k] = a[k] + b[k];
}

// out[3p + c] = y[3p + c] + area[p] f[3p + c].
__global__ void AddAreaWeightedKernel(int n, const double* y, const double* area, const double* f, double* out) {
  const int p = blockIdx.x * blockDim.x + threadIdx.x;
  if (p >= n) return;
  for (int c = 0; c < 3; ++c) out[3 * p + c] = y[3 * p + c] + area[p] * f[3 * p + c];
}

// One side of a far block (FarBlocks of compressed_form_factors.h): G_KL ≈ u vᵀ s between
// clusters K (the receiver) and L (the source) gives G x on K as u (s vᵀ x_L). Each block is
// two halves, (K, L) = (I, J) and (J, I); u and v are contiguous in the block's values, over
// the clusters' contiguous tree positions.
struct FarHalf {
  long long source_offset;    // v = values[source_offset + q − source_begin], q ∈ L
  long long receiver_offset;  // u = values[receiver_offset + p − receiver_begin], p ∈ K
  int source_begin, source_length;
  int receiver_begin;
  double scale;
};

// coefficient[h] = s_h v_hᵀ x_L for every half h: one warp per half (the whole warp takes the
// same halves, as the full-mask shuffles need).
__global__ void FarCoefficientKernel(int halves, const FarHalf* half, const double* values, const double* x,
                                     const CgState* gate, double* coefficient) {
  if (Closed(gate)) return;
  const int lane = threadIdx.x % 32;
  const long warps = static_cast<long>(gridDim.x) * blockDim.x / 32;
  for (long h = (static_cast<long>(blockIdx.x) * blockDim.x + threadIdx.x) / 32; h < halves; h += warps) {
    const FarHalf side = half[h];
    double sum[3] = {0.0, 0.0, 0.0};
    for (int k = lane; k < side.source_length; k += 32) {
      const double v = values[side.source_offset + k];
      const double* xq = x + 3L * (side.source_begin + k);
      for (int c = 0; c < 3; ++c) sum[c] += v * xq[c];
    }
    for (int offset = 16; offset > 0; offset /= 2) {
      for (int c = 0; c < 3; ++c) sum[c] += __shfl_down_sync(0xffffffffu, sum[c], offset);
    }
    if (lane == 0) {
      for (int c = 0; c < 3; ++c) coefficient[3 * h + c] = side.scale * sum[c];
    }
  }
}

// far[p] = (Σ_h u_h[p] coefficient[h]) / A_p over the halves whose receiver holds p: F x's far
// part (G x / A). Positions between two consecutive cluster boundaries share their list of
// halves (a segment); gathered per position, so no atomics and the same order on every call.
__global__ void FarGatherKernel(int n, const int* segment_of, const int* segment_offsets, const int* segment_halves,
                                const FarHalf* half, const double* values, const double* coefficient,
                                const double* area, const CgState* gate, double* far) {
  if (Closed(gate)) return;
  const int p = blockIdx.x * blockDim.x + threadIdx.x;
  if (p >= n) return;
  const int segment = segment_of[p];
  double sum[3] = {0.0, 0.0, 0.0};
  for (int e = segment_offsets[segment]; e < segment_offsets[segment + 1]; ++e) {
    const int h = segment_halves[e];
    const double u = values[half[h].receiver_offset + (p - half[h].receiver_begin)];
    for (int c = 0; c < 3; ++c) sum[c] += u * coefficient[3 * h + c];
  }
  for (int c = 0; c < 3; ++c) far[3 * p + c] = sum[c] / area[p];
}

// y = S x (+ far) for a CSR matrix S and three interleaved channels, kLanes threads per row
// (a power of two ≤ 32, about the mean row length).
// kOperatorM: y = direction − from_f ∘ (S x + far), CG's M p, with per-block partial sums of
// directionᵀ y (pᵀ M p) in `partials`.
template <int kLanes, bool kOperatorM>
__global__ void SparseProductKernel(int rows, const int* offsets, const int* columns, const double* values,
                                    const double* x, const double* far, const double* direction,
                                    const double* from_f, const CgState* gate, double* y, double* partials) {
  if (Closed(gate)) return;
  constexpr int kRowsPerWarp = 32 / kLanes;
  const int lane = threadIdx.x % kLanes;
  const int row_in_warp = (threadIdx.x % 32) / kLanes;
  const long warp = (static_cast<long>(blockIdx.x) * blockDim.x + threadIdx.x) / 32;
  const long warps = static_cast<long>(gridDim.x) * blockDim.x / 32;
  double dot[3] = {0.0, 0.0, 0.0};
  // The loop is uniform across each warp (`first` is the warp's), as the full-mask shuffles
  // below need every lane; rows past the end contribute zeros.
  for (long first = warp * kRowsPerWarp; first < rows; first += warps * kRowsPerWarp) {
    const long row = first + row_in_warp;
    double sum[3] = {0.0, 0.0, 0.0};
    if (row < rows) {
      for (int e = offsets[row] + lane; e < offsets[row + 1]; e += kLanes) {
        const double value = values[e];
        const double* xq = x + 3L * columns[e];
        for (int c = 0; c < 3; ++c) sum[c] += value * xq[c];
      }
    }
    for (int offset = kLanes / 2; offset > 0; offset /= 2) {
      for (int c = 0; c < 3; ++c) sum[c] += __shfl_down_sync(0xffffffffu, sum[c], offset, kLanes);
    }
    if (lane == 0 && row < rows) {
      for (int c = 0; c < 3; ++c) {
        const long k = 3 * row + c;
        double result = sum[c] + (far != nullptr ? far[k] : 0.0);
        if constexpr (kOperatorM) {
          result = direction[k] - from_f[k] * result;
          dot[c] += direction[k] * result;
        }
        y[k] = result;
      }
    }
  }
  if constexpr (kOperatorM) {
    BlockSum(dot);
    if (threadIdx.x == 0) {
      for (int c = 0; c < 3; ++c) partials[3 * blockIdx.x + c] = dot[c];
    }
  }
}

// Per-block partial sums of aᵀb per channel.
__global__ void DotKernel(int n, const double* a, const double* b, double* partials) {
  double dot[3] = {0.0, 0.0, 0.0};
  for (long p = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; p < n;
       p += static_cast<long>(gridDim.x) * blockDim.x) {
    for (int c = 0; c < 3; ++c) dot[c] += a[3 * p + c] * b[3 * p + c];
  }
  BlockSum(dot);
  if (threadIdx.x == 0) {
    for (int c = 0; c < 3; ++c) partials[3 * blockIdx.x + c] = dot[c];
  }
}

// One block: rr = rᵀr = rhsᵀrhs (the partials), goal = tolerance² rr.
__global__ void StartKernel(const double* partials, int count, double tolerance, CgState* state) {
  double rr[3];
  SumPartials(partials, count, rr);
  if (threadIdx.x != 0) return;
  for (int c = 0; c < 3; ++c) {
    state->rr[c] = rr[c];
    state->goal[c] = tolerance * tolerance * rr[c];
    state->step[c] = state->beta[c] = 0.0;
    state->updating[c] = 0;
  }
  state->iterations = 0;
}

// One block, after M p: which channels take part (rr > goal, as the CPU's loop decides), and
// their steps rr / pᵀMp.
__global__ void StepKernel(const double* partials, int count, CgState* state) {
  double curvature[3];
  SumPartials(partials, count, curvature);
  if (threadIdx.x != 0) return;
  bool any = false;
  for (int c = 0; c < 3; ++c) {
    const bool updating = state->rr[c] > state->goal[c];
    state->updating[c] = updating ? 1 : 0;
    state->step[c] = updating ? state->rr[c] / curvature[c] : 0.0;
    any = any || updating;
  }
  if (any) ++state->iterations;
}

// w += step p, r −= step M p for the channels taking part; per-block partial sums of rᵀr.
__global__ void UpdateKernel(int n, const double* direction, const double* product, const CgState* state,
                             double* solution, double* residual, double* partials) {
  if (!AnyUpdating(state)) return;
  bool updating[3];
  double step[3];
  for (int c = 0; c < 3; ++c) {
    updating[c] = state->updating[c] != 0;
    step[c] = state->step[c];
  }
  double rr[3] = {0.0, 0.0, 0.0};
  for (long p = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; p < n;
       p += static_cast<long>(gridDim.x) * blockDim.x) {
    for (int c = 0; c < 3; ++c) {
      const long k = 3 * p + c;
      if (updating[c]) {
        solution[k] += step[c] * direction[k];
        residual[k] -= step[c] * product[k];
      }
      rr[c] += residual[k] * residual[k];
    }
  }
  BlockSum(rr);
  if (threadIdx.x == 0) {
    for (int c = 0; c < 3; ++c) partials[3 * blockIdx.x + c] = rr[c];
  }
}

// One block: the new rᵀr, and beta = new / old, for the channels taking part.
__global__ void DirectionScalarsKernel(const double* partials, int count, CgState* state) {
  if (!AnyUpdating(state)) return;
  double rr[3];
  SumPartials(partials, count, rr);
  if (threadIdx.x != 0) return;
  for (int c = 0; c < 3; ++c) {
    if (state->updating[c] == 0) continue;
    state->beta[c] = rr[c] / state->rr[c];
    state->rr[c] = rr[c];
  }
}

// p = r + beta p for the channels taking part.
__global__ void DirectionKernel(int n, const double* residual, const CgState* state, double* direction) {
  if (!AnyUpdating(state)) return;
  const int p = blockIdx.x * blockDim.x + threadIdx.x;
  if (p >= n) return;
  for (int c = 0; c < 3; ++c) {
    if (state->updating[c] == 0) continue;
    const long k = 3L * p + c;
    direction[k] = residual[k] + state->beta[c] * direction[k];
  }
}

// A CSR matrix on the device and the threads per row its products use.
struct DeviceCsr {
  int rows = 0;
  long entries = 0;
  int lanes = 1;
  DeviceArray<int> offsets, columns;
  DeviceArray<double> values;

  // Blocks of a product: enough warps for every row, at most kMaxPartials.
  int blocks() const {
    const long rows_per_block = static_cast<long>(kWarpsPerBlock) * (32 / lanes);
    return static_cast<int>(std::min<long>(kMaxPartials, std::max(1L, (rows + rows_per_block - 1) / rows_per_block)));
  }
};

DeviceCsr UploadCsr(int rows, const std::vector<int>& offsets, const std::vector<int>& columns,
                    const std::vector<double>& values) {
  DeviceCsr csr;
  csr.rows = rows;
  csr.entries = static_cast<long>(values.size());
  // A power of two near the mean row length: short rows waste no lanes, long rows are read by
  // whole warps in coalesced runs.
  const double mean = rows > 0 ? static_cast<double>(csr.entries) / rows : 0.0;
  while (csr.lanes < 32 && csr.lanes < mean) csr.lanes *= 2;
  csr.offsets = Upload(offsets);
  csr.columns = Upload(columns);
  csr.values = Upload(values);
  return csr;
}

template <bool kOperatorM>
void LaunchSparseProduct(const DeviceCsr& s, const double* x, const double* far, const double* direction,
                         const double* from_f, const CgState* gate, double* y, double* partials,
                         cudaStream_t stream) {
  const int blocks = s.blocks();
  const int* offsets = s.offsets.get();
  const int* columns = s.columns.get();
  const double* values = s.values.get();
  const auto launch = [&](auto kernel) {
    kernel<<<blocks, kThreads, 0, stream>>>(s.rows, offsets, columns, values, x, far, direction, from_f, gate, y,
                                            partials);
  };
  switch (s.lanes) {
    case 1: launch(SparseProductKernel<1, kOperatorM>); break;
    case 2: launch(SparseProductKernel<2, kOperatorM>); break;
    case 4: launch(SparseProductKernel<4, kOperatorM>); break;
    case 8: launch(SparseProductKernel<8, kOperatorM>); break;
    case 16: launch(SparseProductKernel<16, kOperatorM>); break;
    default: launch(SparseProductKernel<32, kOperatorM>); break;
  }
  PROCAM_CUDA_LAUNCHED("SparseProductKernel");
}

class CompressedRadiosityImpl : public CompressedRadiosity {
 public:
  CompressedRadiosityImpl(const CompressedParts& parts, const double* reflectance)
      : n_(parts.patches) {
    const int n = n_;
    if (n <= 0) throw std::invalid_argument("compressed radiosity on the GPU: no patches");
    const long near_entries = parts.near_offsets[n];
    halves_count_ = static_cast<int>(2 * parts.far_blocks);

    // Device memory: the near CSR, the far values and halves, the per-position arrays and the
    // n×3 working vectors (the segment lists are at most a few per far value, left out).
    const size_t vectors = 3 * static_cast<size_t>(n) * sizeof(double);
    const size_t needed = static_cast<size_t>(near_entries) * (sizeof(double) + sizeof(int)) +
                          static_cast<size_t>(parts.far_value_count) * sizeof(double) +
                          static_cast<size_t>(halves_count_) * (sizeof(FarHalf) + 3 * sizeof(double)) +
                          static_cast<size_t>(n) * (4 * sizeof(int) + sizeof(double)) + 10 * vectors;
    size_t free_bytes = 0, total_bytes = 0;
    PROCAM_CUDA(cudaMemGetInfo(&free_bytes, &total_bytes));
    if (needed > free_bytes) {
      throw std::runtime_error("CUDA: the compressed F of " + std::to_string(n) + " patches needs " +
                               std::to_string(needed >> 20) + " MiB of device memory, " +
                               std::to_string(free_bytes >> 20) + " MiB are free");
    }

    std::vector<int> order(parts.order, parts.order + n), position(n);
    for (int p = 0; p < n; ++p) position[order[p]] = p;
    // The near part renumbered to tree positions (rows and columns), columns sorted per row.
    {
      std::vector<int> offsets(n + 1, 0), columns(near_entries);
      std::vector<double> values(near_entries);
      std::vector<std::pair<int, double>> row;
      for (int p = 0; p < n; ++p) {
        const int patch = order[p];
        row.clear();
        for (int e = parts.near_offsets[patch]; e < parts.near_offsets[patch + 1]; ++e) {
          row.emplace_back(position[parts.near_columns[e]], parts.near_values[e]);
        }
        std::sort(row.begin(), row.end());
        offsets[p + 1] = offsets[p] + static_cast<int>(row.size());
        for (size_t e = 0; e < row.size(); ++e) {
          columns[offsets[p] + e] = row[e].first;
          values[offsets[p] + e] = row[e].second;
        }
      }
      near_ = UploadCsr(n, offsets, columns, values);
    }
    // The far blocks as two halves each, and for FarGatherKernel the halves whose receiver holds
    // each segment (the positions between two consecutive boundaries of receiving clusters).
    if (halves_count_ > 0) {
      std::vector<FarHalf> halves;
      std::vector<std::pair<int, int>> receiver;  // each half's receiving range of positions
      halves.reserve(halves_count_);
      receiver.reserve(halves_count_);
      std::vector<int> cuts = {0, n};
      for (int64_t b = 0; b < parts.far_blocks; ++b) {
        const int i = parts.far_rows[b], j = parts.far_columns[b];
        const int64_t column = parts.far_column_offset[b], row = parts.far_row_offset[b];  // over I, over J
        const int size_i = parts.end[i] - parts.begin[i], size_j = parts.end[j] - parts.begin[j];
        halves.push_back({row, column, parts.begin[j], size_j, parts.begin[i], parts.far_scale[b]});  // into I
        receiver.emplace_back(parts.begin[i], parts.end[i]);
        halves.push_back({column, row, parts.begin[i], size_i, parts.begin[j], parts.far_scale[b]});  // into J
        receiver.emplace_back(parts.begin[j], parts.end[j]);
        for (const int k : {i, j}) {
          cuts.push_back(parts.begin[k]);
          cuts.push_back(parts.end[k]);
        }
      }
      std::sort(cuts.begin(), cuts.end());
      cuts.erase(std::unique(cuts.begin(), cuts.end()), cuts.end());
      const int segments = static_cast<int>(cuts.size()) - 1;
      const auto segment_at = [&](int cut) {  // the segment that starts at position `cut`
        return static_cast<int>(std::lower_bound(cuts.begin(), cuts.end(), cut) - cuts.begin());
      };
      std::vector<int> segment_of(n);
      for (int k = 0; k < segments; ++k) std::fill(segment_of.begin() + cuts[k], segment_of.begin() + cuts[k + 1], k);
      std::vector<int> segment_offsets(segments + 1, 0);
      for (const auto& [first, last] : receiver) {
        for (int k = segment_at(first); k < segment_at(last); ++k) ++segment_offsets[k + 1];
      }
      for (int k = 0; k < segments; ++k) segment_offsets[k + 1] += segment_offsets[k];
      std::vector<int> segment_halves(segment_offsets[segments]);
      std::vector<int> fill(segment_offsets.begin(), segment_offsets.end() - 1);
      for (int h = 0; h < halves_count_; ++h) {
        for (int k = segment_at(receiver[h].first); k < segment_at(receiver[h].second); ++k) {
          segment_halves[fill[k]++] = h;
        }
      }
      halves_ = Upload(halves);
      far_values_ = Upload(parts.far_values, static_cast<size_t>(parts.far_value_count));
      segment_of_ = Upload(segment_of);
      segment_offsets_ = Upload(segment_offsets);
      segment_halves_ = Upload(segment_halves);
      coefficients_ = DeviceArray<double>(3 * static_cast<size_t>(halves_count_));
      far_term_ = DeviceArray<double>(3 * static_cast<size_t>(n));
    }
    // Per position: A, and the two diagonal scalings of M = I − D^½ A^½ F A^-½ D^½ (per channel).
    {
      std::vector<double> area(n), to_inner(3 * static_cast<size_t>(n)), from_f(3 * static_cast<size_t>(n));
      for (int p = 0; p < n; ++p) {
        const int patch = order[p];
        area[p] = parts.area[patch];
        const double sqrt_area = std::sqrt(area[p]);
        for (int c = 0; c < 3; ++c) {
          const double sqrt_rho = std::sqrt(reflectance[static_cast<size_t>(c) * n + patch]);
          to_inner[3 * p + c] = sqrt_rho / sqrt_area;  // A^-½ D^½
          from_f[3 * p + c] = sqrt_area * sqrt_rho;    // D^½ A^½
        }
      }
      area_ = Upload(area);
      to_inner_ = Upload(to_inner);
      from_f_ = Upload(from_f);
    }
    order_ = Upload(order);

    const size_t count = 3 * static_cast<size_t>(n);
    staging_ = DeviceArray<double>(count);
    y_ = DeviceArray<double>(count);
    solution_ = DeviceArray<double>(count);
    residual_ = DeviceArray<double>(count);
    direction_ = DeviceArray<double>(count);
    product_ = DeviceArray<double>(count);
    inner_ = DeviceArray<double>(count);
    partials_ = DeviceArray<double>(3 * static_cast<size_t>(kMaxPartials));
    state_ = DeviceArray<CgState>(1);
    PROCAM_CUDA(cudaStreamCreateWithFlags(&stream_, cudaStreamNonBlocking));
    PROCAM_CUDA(cudaDeviceSynchronize());
  }

  ~CompressedRadiosityImpl() override {
    if (stream_ != nullptr) cudaStreamDestroy(stream_);
  }

  void Multiply(const double* x, double* y) const override {
    const size_t bytes = 3 * static_cast<size_t>(n_) * sizeof(double);
    PROCAM_CUDA(cudaMemcpyAsync(staging_.get(), x, bytes, cudaMemcpyHostToDevice, stream_));
    ToTreeOrderKernel<<<Blocks(n_), kThreads, 0, stream_>>>(n_, order_.get(), staging_.get(), y_.get());
    PROCAM_CUDA_LAUNCHED("ToTreeOrderKernel");
    ProductF(y_.get(), product_.get(), nullptr, nullptr);
    CopyOut(product_.get(), y);
  }

  int Solve(const double* y, bool transposed, double tolerance, int max_iterations, double* x) const override {
    PROCAM_CUDA(cudaMemcpyAsync(staging_.get(), y, 3 * static_cast<size_t>(n_) * sizeof(double),
                                cudaMemcpyHostToDevice, stream_));
    const int iterations = SolveTree(staging_.get(), transposed, tolerance, max_iterations);
    CopyOut(residual_.get(), x);
    return iterations;
  }

  int SolveOnDevice(const double* y, bool transposed, double tolerance, int max_iterations,
                    double* x) const override {
    const int iterations = SolveTree(y, transposed, tolerance, max_iterations);
    FromTreeOrderKernel<<<Blocks(n_), kThreads, 0, stream_>>>(n_, order_.get(), residual_.get(), x);
    PROCAM_CUDA_LAUNCHED("FromTreeOrderKernel");
    return iterations;
  }

  cudaStream_t stream() const override { return stream_; }

 private:
  // The solve of Solve and SolveOnDevice: `columns` (n×3 column-major, patch order, device) in,
  // the result in residual_ (tree order). Returns the iterations.
  int SolveTree(const double* columns, bool transposed, double tolerance, int max_iterations) const {
    const long count = 3L * n_;
    ToTreeOrderKernel<<<Blocks(n_), kThreads, 0, stream_>>>(n_, order_.get(), columns, y_.get());
    PROCAM_CUDA_LAUNCHED("ToTreeOrderKernel");
    // The right-hand side of M w = rhs (radiosity.h): D^½ A^-½ y for Kᵀ, D^½ A^½ F y for K.
    if (transposed) {
      ScaleKernel<<<Blocks(count), kThreads, 0, stream_>>>(count, y_.get(), to_inner_.get(), nullptr,
                                                           residual_.get());
    } else {
      ProductF(y_.get(), product_.get(), nullptr, nullptr);
      ScaleKernel<<<Blocks(count), kThreads, 0, stream_>>>(count, product_.get(), from_f_.get(), nullptr,
                                                           residual_.get());
    }
    PROCAM_CUDA_LAUNCHED("ScaleKernel");
    PROCAM_CUDA(cudaMemcpyAsync(direction_.get(), residual_.get(), count * sizeof(double), cudaMemcpyDeviceToDevice,
                                stream_));
    PROCAM_CUDA(cudaMemsetAsync(solution_.get(), 0, count * sizeof(double), stream_));
    const int blocks = ReductionBlocks(n_);
    DotKernel<<<blocks, kThreads, 0, stream_>>>(n_, residual_.get(), residual_.get(), partials_.get());
    PROCAM_CUDA_LAUNCHED("DotKernel");
    StartKernel<<<1, kThreads, 0, stream_>>>(partials_.get(), blocks, tolerance, state_.get());
    PROCAM_CUDA_LAUNCHED("StartKernel");

    // The first read comes after as many iterations as the last solve of the same kind took
    // (right-hand sides of one solver run need similar counts), the later ones every
    // kCheckInterval.
    int& expected = ExpectedIterations(transposed, tolerance);
    Iterate(std::min(std::max(1, expected), std::max(0, max_iterations)));
    CgState state;
    for (;;) {
      PROCAM_CUDA(cudaMemcpyAsync(&state, state_.get(), sizeof state, cudaMemcpyDeviceToHost, stream_));
      PROCAM_CUDA(cudaStreamSynchronize(stream_));
      const bool converged = !(state.rr[0] > state.goal[0] || state.rr[1] > state.goal[1] ||
                               state.rr[2] > state.goal[2]);
      if (converged) break;
      // Until every channel has converged each iteration counts, so state.iterations is
      // exactly the number launched: the CPU's limit, to the iteration.
      if (state.iterations >= max_iterations) {
        throw std::runtime_error("radiosity (CUDA GPU): conjugate gradients did not converge in " +
                                 std::to_string(max_iterations) + " iterations");
      }
      Iterate(std::min(kCheckInterval, max_iterations - state.iterations));
    }
    expected = state.iterations;

    // w → A^-½ D^½ w; x = y + that for K, y + A F (that) for Kᵀ.
    ScaleKernel<<<Blocks(count), kThreads, 0, stream_>>>(count, solution_.get(), to_inner_.get(), nullptr,
                                                         inner_.get());
    PROCAM_CUDA_LAUNCHED("ScaleKernel");
    if (transposed) {
      ProductF(inner_.get(), product_.get(), nullptr, nullptr);
      AddAreaWeightedKernel<<<Blocks(n_), kThreads, 0, stream_>>>(n_, y_.get(), area_.get(), product_.get(),
                                                                  residual_.get());
      PROCAM_CUDA_LAUNCHED("AddAreaWeightedKernel");
    } else {
      AddKernel<<<Blocks(count), kThreads, 0, stream_>>>(count, y_.get(), inner_.get(), residual_.get());
      PROCAM_CUDA_LAUNCHED("AddKernel");
    }
    return state.iterations;
  }

  // y = F x, both in tree order (n×3 interleaved, device). With `direction`: y = M direction
  // (x must then be A^-½ D^½ direction) and partials_ of directionᵀ y. `gate`: the kernels
  // do nothing once every channel of the CG state has converged.
  void ProductF(const double* x, double* y, const double* direction, const CgState* gate) const {
    const double* far_term = nullptr;
    if (halves_count_ > 0) {
      const long threads = 32L * halves_count_;  // a warp per half
      FarCoefficientKernel<<<std::min(Blocks(threads), 4 * kMaxPartials), kThreads, 0, stream_>>>(
          halves_count_, halves_.get(), far_values_.get(), x, gate, coefficients_.get());
      PROCAM_CUDA_LAUNCHED("FarCoefficientKernel");
      FarGatherKernel<<<Blocks(n_), kThreads, 0, stream_>>>(n_, segment_of_.get(), segment_offsets_.get(),
                                                            segment_halves_.get(), halves_.get(), far_values_.get(),
                                                            coefficients_.get(), area_.get(), gate, far_term_.get());
      PROCAM_CUDA_LAUNCHED("FarGatherKernel");
      far_term = far_term_.get();
    }
    if (direction != nullptr) {
      LaunchSparseProduct<true>(near_, x, far_term, direction, from_f_.get(), gate, y, partials_.get(), stream_);
    } else {
      LaunchSparseProduct<false>(near_, x, far_term, nullptr, nullptr, gate, y, nullptr, stream_);
    }
  }

  // `iterations` CG iterations (Alg. of RadiositySystem::SolveIteratively), three channels side
  // by side: one product with F, per-channel steps, converged channels left as they are.
  void Iterate(int iterations) const {
    const long count = 3L * n_;
    const int blocks = ReductionBlocks(n_);
    for (int i = 0; i < iterations; ++i) {
      ScaleKernel<<<Blocks(count), kThreads, 0, stream_>>>(count, direction_.get(), to_inner_.get(), state_.get(),
                                                           inner_.get());
      PROCAM_CUDA_LAUNCHED("ScaleKernel");
      ProductF(inner_.get(), product_.get(), direction_.get(), state_.get());
      StepKernel<<<1, kThreads, 0, stream_>>>(partials_.get(), near_.blocks(), state_.get());
      PROCAM_CUDA_LAUNCHED("StepKernel");
      UpdateKernel<<<blocks, kThreads, 0, stream_>>>(n_, direction_.get(), product_.get(), state_.get(),
                                                     solution_.get(), residual_.get(), partials_.get());
      PROCAM_CUDA_LAUNCHED("UpdateKernel");
      DirectionScalarsKernel<<<1, kThreads, 0, stream_>>>(partials_.get(), blocks, state_.get());
      PROCAM_CUDA_LAUNCHED("DirectionScalarsKernel");
      DirectionKernel<<<Blocks(n_), kThreads, 0, stream_>>>(n_, residual_.get(), state_.get(), direction_.get());
      PROCAM_CUDA_LAUNCHED("DirectionKernel");
    }
  }

  // `tree` (n×3 interleaved, device) to `host` (n×3 column-major).
  void CopyOut(const double* tree, double* host) const {
    FromTreeOrderKernel<<<Blocks(n_), kThreads, 0, stream_>>>(n_, order_.get(), tree, staging_.get());
    PROCAM_CUDA_LAUNCHED("FromTreeOrderKernel");
    PROCAM_CUDA(cudaMemcpyAsync(host, staging_.get(), 3 * static_cast<size_t>(n_) * sizeof(double),
                                cudaMemcpyDeviceToHost, stream_));
    PROCAM_CUDA(cudaStreamSynchronize(stream_));
  }

  // Iterations of the last solve with these settings (the solver alternates a few kinds: K and
  // Kᵀ, at the normal and the fast tolerance).
  int& ExpectedIterations(bool transposed, double tolerance) const {
    for (Expectation& e : expected_) {
      if (e.transposed == transposed && e.tolerance == tolerance) return e.iterations;
    }
    expected_.push_back({transposed, tolerance, kCheckInterval});
    return expected_.back().iterations;
  }

  struct Expectation {
    bool transposed;
    double tolerance;
    int iterations;
  };

  int n_ = 0;
  int halves_count_ = 0;  // two per far block
  DeviceCsr near_;        // n×n, tree positions
  DeviceArray<int> order_;
  // The far part: FarCoefficientKernel's and FarGatherKernel's inputs, and their outputs.
  DeviceArray<FarHalf> halves_;
  DeviceArray<double> far_values_;
  DeviceArray<int> segment_of_, segment_offsets_, segment_halves_;
  DeviceArray<double> coefficients_, far_term_;  // halves × 3, n×3
  DeviceArray<double> area_, to_inner_, from_f_;  // tree order
  // Working vectors, n×3 interleaved in tree order (staging_: column-major, patch order).
  DeviceArray<double> staging_, y_, solution_, residual_, direction_, product_, inner_;
  DeviceArray<double> partials_;  // kMaxPartials × 3
  DeviceArray<CgState> state_;
  cudaStream_t stream_ = nullptr;
  mutable std::vector<Expectation> expected_;
};

}  // namespace

std::unique_ptr<CompressedRadiosity> CompressedRadiosity::Create(const CompressedParts& parts,
                                                                 const double* reflectance) {
  return std::make_unique<CompressedRadiosityImpl>(parts, reflectance);
}

}  // namespace procam::cuda
