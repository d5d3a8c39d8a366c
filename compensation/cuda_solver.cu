// cuda_solver_device.h on CUDA kernels: Alg. 1 and 2 (MinimiseBoundedDriver of solver_driver.h,
// the control flow the CPU runs too) with every vector on the device.
//
// Each step is a device function (a phase: ResidualPhase, CgUpdatePhase, …) run one thread per
// patch (colour, Jacobians, W products, 3×3 blocks) or per variable (bounds, vector updates),
// with grid-stride loops. Reductions (dot products, maxima) are formed in a fixed order
// (GridReduce) and land in one Scalars struct on the device. Two executors of the driver run the
// phases:
//   - Loop, a kernel per phase (Kernel<Phase>, at most kMaxBlocks blocks each), with the host
//     copying the scalars back where the algorithm branches: two or three times per outer
//     iteration plus about once per CG iteration. CG's own scalars (step, β, convergence) stay
//     on the device, and its kernels do nothing once CG has stopped, so that iterations can be
//     enqueued ahead of a read. On the dense path the fixed sequences are replayed as CUDA graphs
//     (SolverOptions::device_graphs = false turns that off). Large problems and the matrix-free
//     path run this.
//   - the fused loop (FusedLoop): for small problems on the dense K⁻¹, every phase in one
//     cooperative kernel, grid barriers between them and the control flow on the device.
// SolverOptions::device_profile prints where a solve's time went.

// The colour math of colour.h, compiled for the device as well (one definition for both sides).
#include "compensation/colour.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <initializer_list>
#include <mutex>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <cooperative_groups.h>
#include <cuda_runtime.h>

#include "compensation/cuda_common.cuh"
#include "compensation/cuda_product.cuh"
#include "compensation/cuda_solver_device.h"

namespace procam::cuda {
namespace {

constexpr int kThreads = 256;  // per block; the reductions assume exactly this
constexpr int kWarps = kThreads / 32;
// Blocks of a kernel at most (grid-stride loops beyond): bounds the partial sums the last block
// of a reduction combines.
constexpr int kMaxBlocks = 1024;
constexpr int kMaxReduced = 4;  // values one reduction combines at most

int Blocks(long count) {
  return static_cast<int>(std::max(1L, std::min<long>(kMaxBlocks, (count + kThreads - 1) / kThreads)));
}

// ---------------------------------------------------------------------------------------------
// Scalars shared between the kernels and the host.

struct Scalars {
  double value;               // f at the last evaluation
  double projected_gradient;  // ‖x − P(x − g)‖∞
  double free_variables;      // variables not fixed by Eq. 12
  double inner_projected;     // Alg. 2's projected gradient of q at d
  CgState cg;
  // CG's result: curvature of the solution, max |solution|, non-finite entries, qᵀ solution,
  // and Alg. 2's first step length.
  double solution_curvature, solution_max, solution_nonfinite, solution_slope, alpha;
  // A trial of Alg. 2's step: max |δ − α s| (> 0: the projection cut), ∇qᵀδ, δᵀHδ.
  double cut, delta_slope, quadratic;
  // The outer direction: ∇fᵀd and its non-finite entries.
  double direction_slope, direction_nonfinite;
};

// ---------------------------------------------------------------------------------------------
// Reductions.

__device__ double Combine(double a, double b, bool maximum) { return maximum ? fmax(a, b) : a + b; }

template <int K>
__device__ void WarpReduce(double (&value)[K], unsigned max_mask) {
  for (int offset = 16; offset > 0; offset /= 2) {
    for (int k = 0; k < K; ++k) {
      value[k] = Combine(value[k], __shfl_down_sync(0xffffffffu, value[k], offset), (max_mask >> k) & 1u);
    }
  }
}

// Thread 0 gets the block's totals.
template <int K>
__device__ void BlockReduce(double (&value)[K], unsigned max_mask, double (*warp_values)[kWarps]) {
  const int lane = threadIdx.x % 32, warp = threadIdx.x / 32;
  WarpReduce(value, max_mask);
  if (lane == 0) {
    for (int k = 0; k < K; ++k) warp_values[k][warp] = value[k];
  }
  __syncthreads();
  if (warp == 0) {
    for (int k = 0; k < K; ++k) value[k] = lane < kWarps ? warp_values[k][lane] : 0.0;
    WarpReduce(value, max_mask);
  }
  __syncthreads();
}

// Combines each thread's K values over the grid: sums, or maxima where bit k of `max_mask` is set
// (of non-negative values, so 0 is the identity; NaN is dropped, count non-finite values
// separately). Every block forms its partial in a fixed order and the last block to finish
// combines the partials in block order, so results do not depend on scheduling. Returns true in
// thread 0 of that last block, whose `value` then holds the totals. Every thread of the grid must
// call it, once per kernel.
template <int K>
__device__ bool GridReduce(double (&value)[K], unsigned max_mask, double* partials, unsigned* counter) {
  __shared__ double warp_values[K][kWarps];
  __shared__ bool last;
  BlockReduce(value, max_mask, warp_values);
  if (threadIdx.x == 0) {
    for (int k = 0; k < K; ++k) partials[K * blockIdx.x + k] = value[k];
    __threadfence();
    last = atomicAdd(counter, 1u) == gridDim.x - 1;
  }
  __syncthreads();
  if (!last) return false;
  for (int k = 0; k < K; ++k) value[k] = 0.0;
  for (int b = threadIdx.x; b < gridDim.x; b += blockDim.x) {
    for (int k = 0; k < K; ++k) value[k] = Combine(value[k], __ldcg(partials + K * b + k), (max_mask >> k) & 1u);
  }
  BlockReduce(value, max_mask, warp_values);
  if (threadIdx.x == 0) *counter = 0;
  return threadIdx.x == 0;
}

// Where the reductions keep their partials.
struct Reduction {
  double* partials;   // kMaxReduced × kMaxBlocks
  unsigned* counter;  // 0 between kernels
};

// ---------------------------------------------------------------------------------------------
// Per-patch math.

// The colour space (kernel argument).
struct ColourSpace {
  double rgb_to_xyz[9];  // row-major
  double white[3];
  double linear[9];      // row-major
  int lab;
  const double* factor;  // a colour metric's L_i, 9n ((3a + b)·n + i), or null
};

// W: its diagonal and its off-diagonal entries (CSR).
struct Weights {
  const double* diagonal;
  const int* offsets;
  const int* neighbours;
  const double* values;
};

__device__ Eigen::Matrix3d RowMajor(const double* m) {
  Eigen::Matrix3d result;
  result << m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8];
  return result;
}

// Colour of linear RGB and its Jacobian (CompensationObjective::Colour and ColourJacobian).
__device__ void ColourAndJacobian(const ColourSpace& space, const double rgb[3], double colour[3], double* jacobian) {
  const Eigen::Vector3d value(rgb[0], rgb[1], rgb[2]);
  if (space.lab) {
    const Eigen::Matrix3d t = RowMajor(space.rgb_to_xyz);
    const Eigen::Vector3d white(space.white[0], space.white[1], space.white[2]);
    const Eigen::Vector3d xyz = t * value;
    const Eigen::Vector3d lab = XyzToLab(xyz, white);
    const Eigen::Matrix3d j = XyzToLabJacobian(xyz, white) * t;
    for (int a = 0; a < 3; ++a) {
      colour[a] = lab[a];
      if (jacobian != nullptr) {
        for (int b = 0; b < 3; ++b) jacobian[3 * a + b] = j(a, b);
      }
    }
  } else {
    for (int a = 0; a < 3; ++a) {
      colour[a] = space.linear[3 * a] * rgb[0] + space.linear[3 * a + 1] * rgb[1] + space.linear[3 * a + 2] * rgb[2];
      if (jacobian != nullptr) {
        for (int b = 0; b < 3; ++b) jacobian[3 * a + b] = space.linear[3 * a + b];
      }
    }
  }
}

// (W v)_i for an n×3 column-major v.
__device__ void WeightedRow(const Weights& w, const double* v, int n, int i, double out[3]) {
  const double diagonal = w.diagonal[i];
  for (int c = 0; c < 3; ++c) out[c] = diagonal * v[c * n + i];
  for (int e = w.offsets[i]; e < w.offsets[i + 1]; ++e) {
    const int j = w.neighbours[e];
    const double value = w.values[e];
    for (int c = 0; c < 3; ++c) out[c] += value * v[c * n + j];
  }
}

// Patch i's 3×3 Jacobian (stored as nine n-long planes, row-major index).
__device__ void LoadJacobian(const double* jacobian, int n, int i, double j[9]) {
  for (int k = 0; k < 9; ++k) j[k] = jacobian[k * n + i];
}

// std::max / std::min as Eigen's cwiseMax / cwiseMin use them (NaN handling included).
__device__ double Max(double a, double b) { return a < b ? b : a; }
__device__ double Min(double a, double b) { return b < a ? b : a; }
__device__ double Clamp(double x, double lower, double upper) { return Min(Max(x, lower), upper); }

// The preconditioner block of patch i: the inverse of M_ii = 2 W_ii J_iᵀ J_i restricted to the
// patch's free channels (zero rows and columns for the others). M_ii is positive definite in
// theory; where its free block is not numerically (non-positive or non-finite determinant), the
// inverse diagonal stands in.
__device__ void FreeBlockInverse(const double j[9], double weight, const double mask[3], double inverse[9]) {
  double m[9];
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      const double value = 2.0 * weight * (j[a] * j[b] + j[3 + a] * j[3 + b] + j[6 + a] * j[6 + b]);
      m[3 * a + b] = (mask[a] != 0.0 && mask[b] != 0.0) ? value : (a == b ? 1.0 : 0.0);
    }
  }
  const double c00 = m[4] * m[8] - m[5] * m[7], c01 = m[2] * m[7] - m[1] * m[8], c02 = m[1] * m[5] - m[2] * m[4];
  const double c10 = m[5] * m[6] - m[3] * m[8], c11 = m[0] * m[8] - m[2] * m[6], c12 = m[2] * m[3] - m[0] * m[5];
  const double c20 = m[3] * m[7] - m[4] * m[6], c21 = m[1] * m[6] - m[0] * m[7], c22 = m[0] * m[4] - m[1] * m[3];
  const double determinant = m[0] * c00 + m[1] * c10 + m[2] * c20;
  if (determinant > 0.0 && isfinite(determinant)) {
    const double s = 1.0 / determinant;
    const double adjugate[9] = {c00, c01, c02, c10, c11, c12, c20, c21, c22};
    for (int k = 0; k < 9; ++k) inverse[k] = s * adjugate[k];
  } else {
    for (int k = 0; k < 9; ++k) inverse[k] = 0.0;
    for (int a = 0; a < 3; ++a) inverse[4 * a] = m[4 * a] > 0.0 ? 1.0 / m[4 * a] : 1.0;
  }
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) inverse[3 * a + b] *= mask[a] * mask[b];
  }
}

// ---------------------------------------------------------------------------------------------
// The objective (CompensationObjective::Evaluate, Gradient and AddSecondOrder).

__global__ void DesiredColourKernel(int n, ColourSpace space, const double* desired, double* desired_colour) {
  for (int i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
    const double rgb[3] = {desired[i], desired[n + i], desired[2 * n + i]};
    double colour[3];
    ColourAndJacobian(space, rgb, colour, nullptr);
    for (int c = 0; c < 3; ++c) desired_colour[c * n + i] = colour[c];
  }
}

// r_i = C(B_i) − C(Bd_i) and J_i = ∂C/∂B at B_i; with a colour metric L_i r_i and L_i J_i
// (CompensationObjective::Residual and PatchJacobian).
__device__ void ResidualPhase(int n, ColourSpace space, const double* radiosity, const double* desired_colour,
                               double* residual, double* jacobian) {
  for (int i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
    const double rgb[3] = {radiosity[i], radiosity[n + i], radiosity[2 * n + i]};
    double colour[3], j[9];
    ColourAndJacobian(space, rgb, colour, j);
    double r[3];
    for (int c = 0; c < 3; ++c) r[c] = colour[c] - desired_colour[c * n + i];
    if (space.factor != nullptr) {
      double l[9], lr[3], lj[9];
      LoadJacobian(space.factor, n, i, l);  // same layout as the Jacobians
      for (int a = 0; a < 3; ++a) {
        lr[a] = l[3 * a] * r[0] + l[3 * a + 1] * r[1] + l[3 * a + 2] * r[2];
        for (int b = 0; b < 3; ++b) lj[3 * a + b] = l[3 * a] * j[b] + l[3 * a + 1] * j[3 + b] + l[3 * a + 2] * j[6 + b];
      }
      for (int c = 0; c < 3; ++c) r[c] = lr[c];
      for (int k = 0; k < 9; ++k) j[k] = lj[k];
    }
    for (int c = 0; c < 3; ++c) residual[c * n + i] = r[c];
    for (int k = 0; k < 9; ++k) jacobian[k * n + i] = j[k];
  }
}

// f = Σ rᵀ W r; the gradient in B, J_iᵀ (2 W r)_i (K⁻ᵀ of it is ∇f); and the second-order term's
// curvature Σ_k (2WR)_ik ∇²Lab_k, diagonal in XYZ (AddSecondOrder: S_i = Tᵀ diag(·) T).
__device__ void WeightedResidualPhase(int n, ColourSpace space, Weights w, const double* radiosity,
                                       const double* residual, const double* jacobian, double* gradient_b,
                                       double* curvature, Scalars* scalars, Reduction reduction) {
  double value[1] = {0.0};
  for (int i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
    double wr[3], j[9];
    WeightedRow(w, residual, n, i, wr);
    LoadJacobian(jacobian, n, i, j);
    double weighted[3];
    for (int c = 0; c < 3; ++c) {
      value[0] += residual[c * n + i] * wr[c];
      weighted[c] = 2.0 * wr[c];
    }
    for (int b = 0; b < 3; ++b) {
      gradient_b[b * n + i] = j[b] * weighted[0] + j[3 + b] * weighted[1] + j[6 + b] * weighted[2];
    }
    if (space.lab) {
      const Eigen::Matrix3d t = RowMajor(space.rgb_to_xyz);
      const Eigen::Vector3d xyz = t * Eigen::Vector3d(radiosity[i], radiosity[n + i], radiosity[2 * n + i]);
      // With a metric, Σ_k w_k ∇²(L_i Lab)_k = Σ_m (L_iᵀ w)_m ∇²Lab_m.
      Eigen::Vector3d by_lab(weighted[0], weighted[1], weighted[2]);
      if (space.factor != nullptr) {
        double l[9];
        LoadJacobian(space.factor, n, i, l);
        by_lab = RowMajor(l).transpose() * by_lab;
      }
      const Eigen::Vector3d curve = XyzToLabWeightedCurvature(
          xyz, Eigen::Vector3d(space.white[0], space.white[1], space.white[2]), by_lab);
      for (int c = 0; c < 3; ++c) curvature[c * n + i] = curve[c];
    }
  }
  if (GridReduce(value, 0u, reduction.partials, reduction.counter)) scalars->value = value[0];
}

// ‖x − P(x − g)‖∞, the variables Eq. 12 fixes, and how many stay free.
__device__ void GradientCheckPhase(long count, const double* x, const double* g, const double* lower,
                                    const double* upper, unsigned char* fixed, Scalars* scalars,
                                    Reduction reduction) {
  double value[2] = {0.0, 0.0};  // max projected, free
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    const double xk = x[k], gk = g[k], l = lower[k], u = upper[k];
    value[0] = fmax(value[0], fabs(Clamp(xk - gk, l, u) - xk));
    const bool at_lower = xk <= l && gk > 0.0;
    const bool at_upper = xk >= u && gk < 0.0;
    fixed[k] = (at_lower || at_upper) ? 1 : 0;
    value[1] += (at_lower || at_upper) ? 0.0 : 1.0;
  }
  if (GridReduce(value, 1u, reduction.partials, reduction.counter)) {
    scalars->projected_gradient = value[0];
    scalars->free_variables = value[1];
  }
}

// ---------------------------------------------------------------------------------------------
// Alg. 2 (solver_driver.h's SolveInnerQp) on q(d) = gᵀd + ½ dᵀHd, l − x ≤ d ≤ u − x.

// ∇q = g + Hd, the mask of the free variables, and q's projected gradient at d. `first`: d = 0
// and Hd = 0 (both written).
__device__ void InnerStartPhase(long count, bool first, double* d, double* hd, const double* g, const double* x,
                                 const double* lower, const double* upper, const unsigned char* fixed, double* qg,
                                 double* mask, Scalars* scalars, Reduction reduction) {
  const double eps = 1e-13;
  double value[1] = {0.0};
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    double dk = 0.0, hdk = 0.0;
    if (first) {
      d[k] = 0.0;
      hd[k] = 0.0;
    } else {
      dk = d[k];
      hdk = hd[k];
    }
    const double q = g[k] + hdk;
    const double lo = lower[k] - x[k], hi = upper[k] - x[k];
    const bool at_lo = dk <= lo + eps * (1.0 + fabs(lo));
    const bool at_hi = dk >= hi - eps * (1.0 + fabs(hi));
    const bool is_fixed = fixed[k] != 0;
    const bool bound = is_fixed || (at_lo && q > 0.0) || (at_hi && q < 0.0);
    mask[k] = bound ? 0.0 : 1.0;
    qg[k] = q;
    value[0] = fmax(value[0], fabs((Clamp(dk - q, lo, hi) - dk) * (is_fixed ? 0.0 : 1.0)));
  }
  if (GridReduce(value, 1u, reduction.partials, reduction.counter)) scalars->inner_projected = value[0];
}

// CG on H_FF s = −∇q_F: r = −∇q ∘ mask, x = 0, the preconditioner blocks for this mask, z = P r,
// p = z (and its copy in the products' precision).
// With `split` (the Neumann preconditioner), z = D⁻¹r goes to `y` instead, and NeumannPhase forms
// z, p and rᵀz from it.
template <typename P>
__device__ void CgStartPhase(int n, bool split, const double* qg, const double* mask, const double* jacobian,
                              const double* weight_diagonal, double* x, double* r, double* b0, double* p,
                              double* preconditioner, P* p_fast, double* y, Scalars* scalars, Reduction reduction) {
  double value[2] = {0.0, 0.0};  // rᵀr, rᵀz
  for (int i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
    double m[3], ri[3], j[9], block[9];
    for (int c = 0; c < 3; ++c) {
      const int k = c * n + i;
      m[c] = mask[k];
      ri[c] = -qg[k] * m[c];
      x[k] = 0.0;
      r[k] = ri[c];
      b0[k] = ri[c];
    }
    LoadJacobian(jacobian, n, i, j);
    FreeBlockInverse(j, weight_diagonal[i], m, block);
    for (int e = 0; e < 9; ++e) preconditioner[e * n + i] = block[e];
    for (int a = 0; a < 3; ++a) {
      const double z = block[3 * a] * ri[0] + block[3 * a + 1] * ri[1] + block[3 * a + 2] * ri[2];
      if (split) {
        y[a * n + i] = z;
      } else {
        p[a * n + i] = z;
        p_fast[a * n + i] = static_cast<P>(z);
      }
      value[0] += ri[a] * ri[a];
      value[1] += ri[a] * z;
    }
  }
  if (GridReduce(value, 0u, reduction.partials, reduction.counter)) {
    CgStart(scalars->cg, sqrt(value[0]), value[1]);
  }
}

// c_j = J_j u_j: patch j's part of J u.
template <typename P>
__device__ void ColourProduct(const double* jacobian, const P* u, int n, int j, double out[3]) {
  const double uj[3] = {static_cast<double>(u[j]), static_cast<double>(u[n + j]), static_cast<double>(u[2 * n + j])};
  for (int a = 0; a < 3; ++a) {
    out[a] = jacobian[(3 * a) * n + j] * uj[0] + jacobian[(3 * a + 1) * n + j] * uj[1] +
             jacobian[(3 * a + 2) * n + j] * uj[2];
  }
}

// The colour-space part of a Hessian product H v = K⁻ᵀ (Jᵀ 2W J + S) K⁻¹ v, after u = K⁻¹ v:
// back_i = J_iᵀ (2 W J u)_i + S_i u_i with S_i = Tᵀ diag(curvature_i) T; K⁻ᵀ back is H v. The
// neighbours' J_j u_j are formed where needed (one launch, no n×3 intermediate). `gate`: nothing
// once CG has stopped.
template <typename P>
__device__ void WeightedProductPhase(int n, ColourSpace space, Weights w, bool second_order, const double* jacobian,
                                      const double* curvature, const P* u, P* back, const CgState* gate) {
  if (gate != nullptr && gate->done) return;
  for (int i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
    double wc[3], c[3];
    ColourProduct(jacobian, u, n, i, c);
    const double diagonal = w.diagonal[i];
    for (int a = 0; a < 3; ++a) wc[a] = diagonal * c[a];
    for (int e = w.offsets[i]; e < w.offsets[i + 1]; ++e) {
      ColourProduct(jacobian, u, n, w.neighbours[e], c);
      const double value = w.values[e];
      for (int a = 0; a < 3; ++a) wc[a] += value * c[a];
    }
    double j[9];
    LoadJacobian(jacobian, n, i, j);
    double result[3];
    for (int b = 0; b < 3; ++b) result[b] = 2.0 * (j[b] * wc[0] + j[3 + b] * wc[1] + j[6 + b] * wc[2]);
    if (second_order) {
      const double* t = space.rgb_to_xyz;
      const double ui[3] = {static_cast<double>(u[i]), static_cast<double>(u[n + i]),
                            static_cast<double>(u[2 * n + i])};
      double scaled[3];
      for (int a = 0; a < 3; ++a) {
        scaled[a] = curvature[a * n + i] * (t[3 * a] * ui[0] + t[3 * a + 1] * ui[1] + t[3 * a + 2] * ui[2]);
      }
      for (int b = 0; b < 3; ++b) result[b] += t[b] * scaled[0] + t[3 + b] * scaled[1] + t[6 + b] * scaled[2];
    }
    for (int b = 0; b < 3; ++b) back[b * n + i] = static_cast<P>(result[b]);
  }
}

// hp = (H p) ∘ mask and pᵀhp; CG stops at non-positive curvature, else takes its step length.
template <typename P>
__device__ void CgCurvaturePhase(long count, const P* product, const double* mask, const double* p, double* hp,
                                  Scalars* scalars, Reduction reduction) {
  if (scalars->cg.done) return;
  double value[1] = {0.0};
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    const double h = static_cast<double>(product[k]) * mask[k];
    hp[k] = h;
    value[0] += p[k] * h;
  }
  if (GridReduce(value, 0u, reduction.partials, reduction.counter)) CgCurvature(scalars->cg, value[0]);
}

// x += step p, r −= step hp, z = P r; CG stops once ‖r‖ ≤ tolerance ‖r0‖ or at the iteration limit.
// With `split` (the Neumann preconditioner), `z` gets D⁻¹r, and NeumannPhase the rest.
__device__ void CgUpdatePhase(int n, bool split, const double* p, const double* hp, const double* preconditioner,
                               double* x, double* r, double* z, double tolerance, int max_iterations,
                               Scalars* scalars, Reduction reduction) {
  if (scalars->cg.done) return;
  const double step = scalars->cg.step;
  double value[2] = {0.0, 0.0};  // rᵀr, rᵀz
  for (int i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
    double ri[3];
    for (int c = 0; c < 3; ++c) {
      const int k = c * n + i;
      x[k] += step * p[k];
      ri[c] = r[k] - step * hp[k];
      r[k] = ri[c];
      value[0] += ri[c] * ri[c];
    }
    for (int a = 0; a < 3; ++a) {
      const double za = preconditioner[(3 * a) * n + i] * ri[0] + preconditioner[(3 * a + 1) * n + i] * ri[1] +
                        preconditioner[(3 * a + 2) * n + i] * ri[2];
      z[a * n + i] = za;
      value[1] += ri[a] * za;
    }
  }
  if (GridReduce(value, 0u, reduction.partials, reduction.counter)) {
    if (CgResidual(scalars->cg, sqrt(value[0]), tolerance) && !split)
      CgDirection(scalars->cg, value[1], max_iterations);
  }
}

// The Neumann preconditioner: block Jacobi with one term of the Neumann series of M_FF = D − N
// (D its 3×3 diagonal blocks, −N the coupling through W's neighbours): z = (D⁻¹ + D⁻¹ N D⁻¹) r =
// y − D⁻¹ M_off y with y = D⁻¹ r, M_off,ij = 2 W_ij J_iᵀ J_j on the free variables. It is SPD
// because D^-½ M_FF D^-½ has its eigenvalues in (0, 2): W = diag(α a) + (1 − α) L is strictly
// diagonally dominant, so M ≺ 2D, and restricting both sides to the free variables keeps it.
// Where block Jacobi maps that spectrum to itself, this maps λ to λ(2 − λ) ≤ 1, lifting the
// smooth modes (small λ) by up to 2×. Then rᵀz; at the start p = z, else β (as CgUpdatePhase
// without `split`).
template <typename P>
__device__ void NeumannPhase(int n, bool start, Weights w, const double* jacobian, const double* preconditioner,
                              const double* y, const double* r, double* z, double* p, P* p_fast, int max_iterations,
                              Scalars* scalars, Reduction reduction) {
  if (scalars->cg.done) return;
  double value[1] = {0.0};  // rᵀz
  for (int i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
    double coupled[3] = {0.0, 0.0, 0.0}, c[3];
    for (int e = w.offsets[i]; e < w.offsets[i + 1]; ++e) {
      ColourProduct(jacobian, y, n, w.neighbours[e], c);
      for (int a = 0; a < 3; ++a) coupled[a] += w.values[e] * c[a];
    }
    double j[9], t[3];
    LoadJacobian(jacobian, n, i, j);
    for (int b = 0; b < 3; ++b) t[b] = 2.0 * (j[b] * coupled[0] + j[3 + b] * coupled[1] + j[6 + b] * coupled[2]);
    for (int a = 0; a < 3; ++a) {
      const double za = y[a * n + i] - (preconditioner[(3 * a) * n + i] * t[0] +
                                        preconditioner[(3 * a + 1) * n + i] * t[1] +
                                        preconditioner[(3 * a + 2) * n + i] * t[2]);
      if (start) {
        p[a * n + i] = za;
        p_fast[a * n + i] = static_cast<P>(za);
      } else {
        z[a * n + i] = za;
      }
      value[0] += r[a * n + i] * za;
    }
  }
  if (GridReduce(value, 0u, reduction.partials, reduction.counter)) {
    if (start) {
      scalars->cg.rz = value[0];  // CgStartPhase's rᵀz was rᵀD⁻¹r
    } else {
      CgDirection(scalars->cg, value[0], max_iterations);
    }
  }
}

// p = z + β p.
template <typename P>
__device__ void CgDirectionPhase(long count, const double* z, double* p, P* p_fast, const Scalars* scalars) {
  if (scalars->cg.done) return;
  const double beta = scalars->cg.beta;
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    const double value = z[k] + beta * p[k];
    p[k] = value;
    p_fast[k] = static_cast<P>(value);
  }
}

// CG's solution s (p after negative curvature in the first iteration, else x), its curvature
// sᵀHs = xᵀ(b − r) (from CG's residual), max |s|, non-finite entries, ∇qᵀs, and Alg. 2's first
// step length: the minimiser along s.
__device__ void CgFinishPhase(long count, const double* x, const double* b0, const double* r, const double* p,
                               const double* qg, double* solution, Scalars* scalars, Reduction reduction) {
  const bool negative = scalars->cg.negative_first != 0;
  double value[4] = {0.0, 0.0, 0.0, 0.0};  // curvature, max, non-finite, slope
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    const double s = negative ? p[k] : x[k];
    solution[k] = s;
    value[0] += x[k] * (b0[k] - r[k]);
    value[1] = fmax(value[1], fabs(s));
    value[2] += isfinite(s) ? 0.0 : 1.0;
    value[3] += qg[k] * s;
  }
  if (GridReduce(value, 2u, reduction.partials, reduction.counter)) {
    const double curvature = negative ? scalars->cg.curvature : value[0];
    scalars->solution_curvature = curvature;
    scalars->solution_max = value[1];
    scalars->solution_nonfinite = value[2];
    scalars->solution_slope = value[3];
    scalars->alpha = InnerStepLength(value[3], curvature);
  }
}

// A step of Alg. 2: trial = P(d + α s) within [lo, hi], δ = trial − d, whether the projection cut
// (max |δ − α s| > 0) and ∇qᵀδ. α from `alpha_on_device` when given (CgFinishPhase's), else
// `alpha`.
__device__ void StepTrialPhase(long count, const double* d, const double* solution, const double* x,
                                const double* lower, const double* upper, const double* qg, double alpha,
                                const double* alpha_on_device, double* trial, double* delta, Scalars* scalars,
                                Reduction reduction) {
  const double a = alpha_on_device != nullptr ? *alpha_on_device : alpha;
  double value[2] = {0.0, 0.0};  // max cut, slope
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    const double lo = lower[k] - x[k], hi = upper[k] - x[k];
    const double t = Clamp(d[k] + a * solution[k], lo, hi);
    const double dk = t - d[k];
    trial[k] = t;
    delta[k] = dk;
    value[0] = fmax(value[0], fabs(dk - a * solution[k]));
    value[1] += qg[k] * dk;
  }
  if (GridReduce(value, 1u, reduction.partials, reduction.counter)) {
    scalars->cut = value[0];
    scalars->delta_slope = value[1];
  }
}

template <typename P>
__device__ void ToPrecisionPhase(long count, const double* v, P* out) {
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    out[k] = static_cast<P>(v[k]);
  }
}

// δᵀ(Hδ).
template <typename P>
__device__ void QuadraticPhase(long count, const double* delta, const P* product, Scalars* scalars,
                                Reduction reduction) {
  double value[1] = {0.0};
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    value[0] += delta[k] * static_cast<double>(product[k]);
  }
  if (GridReduce(value, 0u, reduction.partials, reduction.counter)) scalars->quadratic = value[0];
}

// d = trial; Hd += Hδ when `accumulate`.
template <typename P>
__device__ void AcceptStepPhase(long count, const double* trial, const P* product, bool accumulate, double* d,
                                 double* hd) {
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    d[k] = trial[k];
    if (accumulate) hd[k] += static_cast<double>(product[k]);
  }
}

// ---------------------------------------------------------------------------------------------
// Alg. 1's direction and Armijo search.

// ∇fᵀd and d's non-finite entries.
__device__ void DirectionSlopePhase(long count, const double* g, const double* d, Scalars* scalars,
                                     Reduction reduction) {
  double value[2] = {0.0, 0.0};
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    value[0] += g[k] * d[k];
    value[1] += isfinite(d[k]) ? 0.0 : 1.0;
  }
  if (GridReduce(value, 0u, reduction.partials, reduction.counter)) {
    scalars->direction_slope = value[0];
    scalars->direction_nonfinite = value[1];
  }
}

// The projected steepest-descent direction d = P(x − g) − x and ∇fᵀd.
__device__ void SteepestDirectionPhase(long count, const double* x, const double* g, const double* lower,
                                        const double* upper, double* d, Scalars* scalars, Reduction reduction) {
  double value[1] = {0.0};
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    const double dk = Clamp(x[k] - g[k], lower[k], upper[k]) - x[k];
    d[k] = dk;
    value[0] += g[k] * dk;
  }
  if (GridReduce(value, 0u, reduction.partials, reduction.counter)) {
    scalars->direction_slope = value[0];
    scalars->direction_nonfinite = 0.0;
  }
}

// out = P(x + step d).
__device__ void LineTrialPhase(long count, const double* x, const double* d, double step, const double* lower,
                                const double* upper, double* out) {
  for (long k = blockIdx.x * static_cast<long>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<long>(gridDim.x) * blockDim.x) {
    out[k] = Clamp(x[k] + step * d[k], lower[k], upper[k]);
  }
}

// A phase launched alone (the host-driven loop): one kernel, whose grid-stride loops and
// reduction the phase's own code does.
template <auto kPhase, typename... Args>
__global__ void __launch_bounds__(kThreads) Kernel(Args... args) {
  kPhase(args...);
}

// ---------------------------------------------------------------------------------------------
// Device memory, kept between calls (a pool of workspaces, one per solve in flight).

// One region carved into the loop's arrays; grown (never shrunk) when a larger problem comes.
// Carving runs twice: once measuring (Measure, then Take returns null), once for real (after
// Allocate).
class Workspace {
 public:
  void Measure() {
    measuring_ = true;
    used_ = 0;
  }
  void Allocate() {
    const size_t bytes = used_;
    if (bytes > capacity_) {
      if (base_ != nullptr) PROCAM_CUDA(cudaFree(base_));
      base_ = nullptr;
      capacity_ = 0;
      PROCAM_CUDA(cudaMalloc(&base_, bytes));
      capacity_ = bytes;
    }
    measuring_ = false;
    used_ = 0;
  }
  static size_t Aligned(size_t bytes) { return (bytes + 255) / 256 * 256; }

  template <typename T>
  T* Take(size_t count) {
    const size_t bytes = Aligned(std::max<size_t>(count, 1) * sizeof(T));
    used_ += bytes;
    if (measuring_) return nullptr;
    if (used_ > capacity_) throw std::logic_error("resident GPU solve: workspace carved past its size");
    return reinterpret_cast<T*>(static_cast<char*>(base_) + used_ - bytes);
  }

  // The loop's stream (where the radiosity solves name none), the device scalars and their
  // pinned host copy, made once.
  cudaStream_t stream() {
    if (stream_ == nullptr) PROCAM_CUDA(cudaStreamCreateWithFlags(&stream_, cudaStreamNonBlocking));
    return stream_;
  }
  Scalars* device_scalars() {
    if (device_scalars_ == nullptr) {
      PROCAM_CUDA(cudaMalloc(&device_scalars_, sizeof(Scalars)));
      PROCAM_CUDA(cudaMalloc(&partials_, kMaxReduced * kMaxBlocks * sizeof(double)));
      PROCAM_CUDA(cudaMalloc(&counter_, sizeof(unsigned)));
      PROCAM_CUDA(cudaMallocHost(&host_scalars_, sizeof(Scalars)));
    }
    return device_scalars_;
  }
  Scalars* host_scalars() { return host_scalars_; }

  // A copy between host and device memory: `bytes` from `from` to `to`.
  struct Copy {
    void* to;
    const void* from;
    size_t bytes;
  };

  // Host-to-device copies enqueued on `stream` from pinned staging (kept, grown as needed), so
  // that they neither block the host nor wait for a bounce buffer; the staging is reused once the
  // last upload's copies have finished.
  void UploadAll(std::initializer_list<Copy> copies, cudaStream_t stream) {
    char* staging = Staging(copies);
    for (const Copy& copy : copies) {
      if (copy.bytes == 0) continue;
      std::memcpy(staging, copy.from, copy.bytes);
      PROCAM_CUDA(cudaMemcpyAsync(copy.to, staging, copy.bytes, cudaMemcpyHostToDevice, stream));
      staging += Aligned(copy.bytes);
    }
    PROCAM_CUDA(cudaEventRecord(staged_, stream));
  }

  // Device-to-host copies through the same staging, waited for together.
  void DownloadAll(std::initializer_list<Copy> copies, cudaStream_t stream) {
    char* const staging = Staging(copies);
    char* next = staging;
    for (const Copy& copy : copies) {
      PROCAM_CUDA(cudaMemcpyAsync(next, copy.from, copy.bytes, cudaMemcpyDeviceToHost, stream));
      next += Aligned(copy.bytes);
    }
    PROCAM_CUDA(cudaEventRecord(staged_, stream));
    PROCAM_CUDA(cudaEventSynchronize(staged_));
    next = staging;
    for (const Copy& copy : copies) {
      std::memcpy(copy.to, next, copy.bytes);
      next += Aligned(copy.bytes);
    }
  }

  // The pinned staging, large enough for `copies`, once the copies of its last use have finished.
  char* Staging(std::initializer_list<Copy> copies) {
    size_t bytes = 0;
    for (const Copy& copy : copies) bytes += Aligned(copy.bytes);
    if (staged_ == nullptr) PROCAM_CUDA(cudaEventCreateWithFlags(&staged_, cudaEventDisableTiming));
    PROCAM_CUDA(cudaEventSynchronize(staged_));
    if (bytes > pinned_capacity_) {
      if (pinned_ != nullptr) PROCAM_CUDA(cudaFreeHost(pinned_));
      pinned_ = nullptr;
      pinned_capacity_ = 0;
      PROCAM_CUDA(cudaMallocHost(&pinned_, bytes));
      pinned_capacity_ = bytes;
    }
    return static_cast<char*>(pinned_);
  }
  Reduction reduction() const { return {partials_, counter_}; }

 private:
  void* base_ = nullptr;
  size_t capacity_ = 0, used_ = 0;
  bool measuring_ = false;
  void* pinned_ = nullptr;
  size_t pinned_capacity_ = 0;
  cudaEvent_t staged_ = nullptr;  // recorded after the staging's last copies
  cudaStream_t stream_ = nullptr;
  Scalars* device_scalars_ = nullptr;
  Scalars* host_scalars_ = nullptr;
  double* partials_ = nullptr;
  unsigned* counter_ = nullptr;
};

// The workspaces of the process: a solve takes one for its duration (a new one where every one is
// in use) and gives it back, so that solves from several threads run at once, each on its own
// device memory, stream and pinned staging, while a thread that solves again and again reuses one
// (no allocation per solve: cudaMallocHost alone costs about as much as a small solve's loop).
// Never destroyed (the runtime may be torn down before static destructors run), as the handles of
// cuda_dense.cu; the pool holds as many workspaces as solves ever ran at once.
class WorkspacePool {
 public:
  // A workspace for one solve, back in the pool when the lease ends (an exception included: each
  // solve resets the state it reads, so a failed one leaves nothing behind).
  class Lease {
   public:
    Lease(WorkspacePool* pool, Workspace* workspace) : pool_(pool), workspace_(workspace) {}
    ~Lease() { pool_->Give(workspace_); }
    Lease(const Lease&) = delete;
    Lease& operator=(const Lease&) = delete;
    Workspace* get() const { return workspace_; }

   private:
    WorkspacePool* pool_;
    Workspace* workspace_;
  };

  static WorkspacePool& Get() {
    static WorkspacePool* pool = new WorkspacePool;
    return *pool;
  }

  Lease Take() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (idle_.empty()) return Lease(this, new Workspace);
    Workspace* workspace = idle_.back();
    idle_.pop_back();
    return Lease(this, workspace);
  }

 private:
  void Give(Workspace* workspace) {
    std::lock_guard<std::mutex> lock(mutex_);
    idle_.push_back(workspace);
  }

  std::mutex mutex_;
  std::vector<Workspace*> idle_;
};

using Clock = std::chrono::steady_clock;
double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Everything the objective knows at one point (ObjectivePoint).
struct Point {
  double* emittance;
  double* radiosity;
  double* residual;
  double* jacobian;    // 9 planes of n
  double* gradient_b;  // J_iᵀ (2 W r)_i
  double* curvature;   // second-order term, diagonal in XYZ
};

// ---------------------------------------------------------------------------------------------
// The fused loop: the driver in one cooperative kernel, for small problems on the dense K⁻¹.
//
// Below a few thousand patches every kernel of the host-driven loop is launch-bound, and each of
// its ~45 host reads per solve leaves the device idle: the solve is paid in latency, not
// arithmetic. Here the same phases (the same device functions) run in the same order inside one
// kernel launched cooperatively, with a grid-wide barrier after each; MinimiseBoundedDriver runs
// in every thread on the scalars the reductions wrote, so every block takes the same branch. A
// reduction's last block writes its scalars only after every block has entered the phase, so
// every read of a scalar (right after a barrier) precedes the next write of it. The grid is one
// wave of resident blocks; the K⁻¹ products loop over their groups of outputs (cuda_product.cuh,
// as the standalone kernel forms them).

// The fused loop's summary, in device memory beside its trace.
struct FusedRecords {
  DriverRecords driver;
  int records;  // trace entries written
  int result;   // the point (0 or 1) that holds the result
};

// Everything the fused kernel reads: the options, the problem and the loop's arrays.
struct FusedArgs {
  int n;
  long count;
  ResidentSettings options;
  bool second_order, neumann;  // the loop's: the Lab model's second-order term, the preconditioner
  ColourSpace space;
  Weights weights;
  DenseProduct products[3];  // the K⁻¹ solves, `product_count` of them
  int product_count;
  Point points[2];
  double *lower, *upper, *desired_colour, *gradient, *d, *hd, *qg, *mask;
  double *x, *r, *b0, *p, *z, *y, *hp, *solution, *delta, *step_trial, *preconditioner;
  float *p_fast, *u_fast, *back_fast, *product_fast;
  unsigned char* fixed;
  Scalars* scalars;
  Reduction reduction;
  FusedRecords* records;
  IterationRecord* trace;  // max_iterations + 1 entries
};

__device__ unsigned long long GlobalNanoseconds() {
  unsigned long long t;
  asm volatile("mov.u64 %0, %%globaltimer;" : "=l"(t));
  return t;
}

// MinimiseBoundedDriver's executor in one cooperative kernel: every operation runs its phases
// over the grid with a barrier after each and returns the scalars the reductions wrote, read by
// every thread right after the barrier.
class FusedLoop {
 public:
  __device__ explicit FusedLoop(const FusedArgs& a) : a_(a), grid_(cooperative_groups::this_grid()) {}

  __device__ void Run() {
    start_ = GlobalNanoseconds();
    DriverRecords records;
    MinimiseBoundedDriver(a_.options, *this, &records);
    if (Leader()) *a_.records = {records, records_, current_};
  }

  // The executor's operations (solver_driver.h).
  __device__ int Variables() const { return static_cast<int>(a_.count); }

  __device__ double Evaluate() {
    EvaluateAt(Current());
    return scalars().value;
  }

  __device__ GradientCheck Gradient() {
    GradientAt(Current());
    return {scalars().projected_gradient, static_cast<int>(scalars().free_variables)};
  }

  __device__ double InnerStart(bool first) {
    InnerStartPhase(a_.count, first, a_.d, a_.hd, a_.gradient, Current().emittance, a_.lower, a_.upper, a_.fixed,
                    a_.qg, a_.mask, a_.scalars, a_.reduction);
    Barrier();
    return scalars().inner_projected;
  }

  __device__ NewtonStep SolveNewton() {
    const Point& point = Current();
    CgStartPhase<float>(a_.n, a_.neumann, a_.qg, a_.mask, point.jacobian, a_.weights.diagonal, a_.x, a_.r, a_.b0,
                        a_.p, a_.preconditioner, a_.p_fast, a_.y, a_.scalars, a_.reduction);
    Barrier();
    if (a_.neumann) Neumann(point, /*start=*/true);
    while (!scalars().cg.done) CgIteration(point);
    CgFinishPhase(a_.count, a_.x, a_.b0, a_.r, a_.p, a_.qg, a_.solution, a_.scalars, a_.reduction);
    Barrier();
    const Scalars& s = scalars();
    return {s.cg.iterations, s.cg.preconditioner_applications, !(s.solution_nonfinite > 0.0), s.solution_max,
            s.solution_slope, s.solution_curvature};
  }

  __device__ TrialStep StepTrial(double alpha) {
    StepTrialPhase(a_.count, a_.d, a_.solution, Current().emittance, a_.lower, a_.upper, a_.qg, alpha, nullptr,
                   a_.step_trial, a_.delta, a_.scalars, a_.reduction);
    Barrier();
    return {scalars().cut > 0.0, scalars().delta_slope};
  }

  __device__ double StepCurvature() {
    ToPrecisionPhase<float>(a_.count, a_.delta, a_.p_fast);
    Barrier();
    HessianProduct(Current(), a_.p_fast, a_.product_fast);
    QuadraticPhase<float>(a_.count, a_.delta, a_.product_fast, a_.scalars, a_.reduction);
    Barrier();
    return scalars().quadratic;
  }

  __device__ void AcceptStep(bool accumulate) {
    AcceptStepPhase<float>(a_.count, a_.step_trial, a_.product_fast, accumulate, a_.d, a_.hd);
    Barrier();
  }

  __device__ SearchDirection Direction() {
    DirectionSlopePhase(a_.count, a_.gradient, a_.d, a_.scalars, a_.reduction);
    Barrier();
    return {!(scalars().direction_nonfinite > 0.0), scalars().direction_slope};
  }

  __device__ double SteepestDirection() {
    SteepestDirectionPhase(a_.count, Current().emittance, a_.gradient, a_.lower, a_.upper, a_.d, a_.scalars,
                           a_.reduction);
    Barrier();
    return scalars().direction_slope;
  }

  __device__ double LineTrial(double step) {
    const Point& trial = a_.points[current_ ^ 1];
    LineTrialPhase(a_.count, Current().emittance, a_.d, step, a_.lower, a_.upper, trial.emittance);
    Barrier();
    EvaluateAt(trial);
    return scalars().value;
  }

  __device__ void AcceptTrial() { current_ ^= 1; }

  __device__ double FinalProjectedGradient() {
    GradientAt(Current());
    return scalars().projected_gradient;
  }

  // Trace entry records_ (the leader writes it).
  __device__ void Record(int iteration, double cost, double step, int free_variables, int cg_iterations) {
    if (Leader()) {
      IterationRecord& record = a_.trace[records_];
      record.iteration = iteration;
      record.cost = cost;
      record.seconds = 1e-9 * static_cast<double>(GlobalNanoseconds() - start_);
      record.step = step;
      record.free_variables = free_variables;
      record.cg_iterations = cg_iterations;
      record.projected_gradient = 0.0;
    }
    ++records_;
  }

  __device__ void SetProjectedGradient(double projected) {
    if (Leader()) a_.trace[records_ - 1].projected_gradient = projected;
  }

 private:
  __device__ bool Leader() const { return blockIdx.x == 0 && threadIdx.x == 0; }
  __device__ void Barrier() { grid_.sync(); }
  __device__ const Scalars& scalars() const { return *a_.scalars; }
  __device__ const Point& Current() const { return a_.points[current_]; }

  // What one K⁻¹ product reads: the stored K⁻¹ (S), the Cholesky path's s² and s⁻² and the
  // factor the stored copy is scaled by, in the vectors' precision T.
  template <typename S, typename T>
  struct Operand {
    const S* matrix;
    const T *square, *inverse_square;
    T post;
  };

  // x = K⁻¹y (K⁻ᵀy when `transposed`): every group of outputs of every product, spread over the
  // grid; `operand(view)` gives a product's Operand.
  template <typename Rows, typename T, typename OperandOf>
  __device__ void Product(const OperandOf& operand, const T* y, bool transposed, T* x) {
    const int per_product = product::ProductGroups<Rows>(a_.n);
    const int groups = per_product * a_.product_count;
    for (int group = blockIdx.x; group < groups; group += gridDim.x) {
      const DenseProduct& p = a_.products[group / per_product];
      const auto o = operand(p.inverse);
      const size_t offset = static_cast<size_t>(p.first_channel) * a_.n;
      product::TransposedProductGroup<Rows>(group % per_product, a_.n, p.columns, o.matrix,
                                            transposed ? nullptr : o.square, transposed ? nullptr : o.inverse_square,
                                            o.post, y + offset, x + offset);
      __syncthreads();  // the block's shared partials are reused by its next group
    }
    Barrier();
  }
  // float64 with the float64 K⁻¹.
  __device__ void Solve(const double* y, bool transposed, double* x) {
    Product<product::DenseRows<double>>(
        [](const DenseInverseView& k) {
          return Operand<double, double>{k.inverse, k.square, k.inverse_square, 1.0};
        },
        y, transposed, x);
  }
  // float32 vectors with the float16 quads of 2^k K⁻¹.
  __device__ void SolveFast(const float* y, bool transposed, float* x) {
    Product<product::HalfRows>(
        [](const DenseInverseView& k) {
          return Operand<product::HalfQuad, float>{static_cast<const product::HalfQuad*>(k.half_quads),
                                                   k.square_single, k.inverse_square_single, k.half_post};
        },
        y, transposed, x);
  }

  // H v (as Loop::Product forms it).
  __device__ void HessianProduct(const Point& point, const float* v, float* result) {
    SolveFast(v, false, a_.u_fast);
    WeightedProductPhase<float>(a_.n, a_.space, a_.weights, a_.second_order, point.jacobian, point.curvature,
                                a_.u_fast, a_.back_fast, nullptr);
    Barrier();
    SolveFast(a_.back_fast, true, result);
  }

  // f and everything the objective knows at point.emittance; f lands in the scalars.
  __device__ void EvaluateAt(const Point& point) {
    Solve(point.emittance, false, point.radiosity);
    ResidualPhase(a_.n, a_.space, point.radiosity, a_.desired_colour, point.residual, point.jacobian);
    Barrier();
    WeightedResidualPhase(a_.n, a_.space, a_.weights, point.radiosity, point.residual, point.jacobian,
                          point.gradient_b, point.curvature, a_.scalars, a_.reduction);
    Barrier();
  }

  // The gradient at `point` and its check.
  __device__ void GradientAt(const Point& point) {
    Solve(point.gradient_b, true, a_.gradient);
    GradientCheckPhase(a_.count, point.emittance, a_.gradient, a_.lower, a_.upper, a_.fixed, a_.scalars,
                       a_.reduction);
    Barrier();
  }

  __device__ void Neumann(const Point& point, bool start) {
    NeumannPhase<float>(a_.n, start, a_.weights, point.jacobian, a_.preconditioner, a_.y, a_.r, a_.z, a_.p,
                        a_.p_fast, a_.options.max_cg_iterations, a_.scalars, a_.reduction);
    Barrier();
  }

  // One CG iteration (as Loop::CgIteration enqueues it).
  __device__ void CgIteration(const Point& point) {
    HessianProduct(point, a_.p_fast, a_.product_fast);
    CgCurvaturePhase<float>(a_.count, a_.product_fast, a_.mask, a_.p, a_.hp, a_.scalars, a_.reduction);
    Barrier();
    CgUpdatePhase(a_.n, a_.neumann, a_.p, a_.hp, a_.preconditioner, a_.x, a_.r, a_.neumann ? a_.y : a_.z,
                  a_.options.cg_tolerance, a_.options.max_cg_iterations, a_.scalars, a_.reduction);
    Barrier();
    if (a_.neumann) Neumann(point, /*start=*/false);
    CgDirectionPhase<float>(a_.count, a_.z, a_.p, a_.p_fast, a_.scalars);
    Barrier();
  }

  const FusedArgs a_;
  cooperative_groups::grid_group grid_;
  unsigned long long start_ = 0;  // %globaltimer at the kernel's start
  int current_ = 0;               // the point (0 or 1) that holds the iterate
  int records_ = 0;               // trace entries written
};

__global__ void __launch_bounds__(kThreads) FusedLoopKernel(const FusedArgs args) {
  FusedLoop(args).Run();
}

// The loop's fixed sequences of device work, each replayed as one CUDA graph.
enum class Sequence {
  kHead,         // gradient, its check, Alg. 2's start and CG's start
  kCgIteration,  // one CG iteration
  kTail,         // CG's finish and Alg. 2's first trial step
  kFirstTrial,   // the direction's slope and the Armijo search's first trial
  kCount
};

// Problems below this many patches are launch-bound: CG's first read of its state comes after
// one iteration fewer than the last Newton system took (an iteration enqueued past CG's end costs
// its two products, ~3× a read on the H100, so the guess errs low), then after every iteration.
// Above, each iteration's products cost far more than a read: one iteration per read.
constexpr int kSmallPatches = 4096;

// The loop; P is the precision of the Hessian products' vectors (float: the dense float32 K⁻¹;
// double: the matrix-free CG).
template <typename P>
class Loop {
 public:
  Loop(const ResidentOptions& options, const ResidentProblem& problem, const DeviceRadiosity& radiosity,
       Workspace* workspace)
      : options_(options), radiosity_(radiosity), workspace_(workspace), n_(problem.patches),
        count_(3L * problem.patches) {
    stream_ = radiosity.stream() != nullptr ? radiosity.stream() : workspace->stream();
    scalars_ = workspace->device_scalars();
    host_ = workspace->host_scalars();
    reduction_ = workspace->reduction();
    const size_t n = static_cast<size_t>(n_), vector = 3 * n;
    const int entries = problem.neighbour_offsets[n_];
    metric_ = problem.lab && problem.metric_factor != nullptr;
    workspace->Measure();
    Carve(workspace, entries);
    workspace->Allocate();
    Carve(workspace, entries);

    // The problem's arrays through pinned staging: copies that neither block the host nor wait for
    // a bounce buffer (pageable copies cost ~10 µs each, most of a small solve's set-up).
    const size_t bytes = vector * sizeof(double);
    PROCAM_CUDA(cudaMemsetAsync(reduction_.counter, 0, sizeof(unsigned), stream_));
    workspace->UploadAll(
        {{lower_, problem.lower, bytes},
         {upper_, problem.upper, bytes},
         {current_.emittance, problem.initial, bytes},
         {trial_.emittance, problem.desired, bytes},  // the desired colours' staging
         {weight_diagonal_, problem.weight_diagonal, n * sizeof(double)},
         {offsets_, problem.neighbour_offsets, (n + 1) * sizeof(int)},
         {neighbours_, problem.neighbours, entries * sizeof(int)},
         {neighbour_weights_, problem.neighbour_weights, entries * sizeof(double)},
         {factor_, metric_ ? problem.metric_factor : nullptr, metric_ ? 9 * n * sizeof(double) : 0}},
        stream_);
    weights_ = {weight_diagonal_, offsets_, neighbours_, neighbour_weights_};
    for (int k = 0; k < 9; ++k) {
      space_.rgb_to_xyz[k] = problem.rgb_to_xyz[k];
      space_.linear[k] = problem.linear_colour[k];
    }
    for (int c = 0; c < 3; ++c) space_.white[c] = problem.white_xyz[c];
    space_.lab = problem.lab ? 1 : 0;
    space_.factor = metric_ ? factor_ : nullptr;
    second_order_ = problem.lab && options.second_order;
    // The desired colours, from their staging in the trial point's emittance.
    DesiredColourKernel<<<Blocks(n_), kThreads, 0, stream_>>>(n_, space_, trial_.emittance, desired_colour_);
    Launched("DesiredColourKernel");
    small_ = n_ < kSmallPatches;
    neumann_ = options.neumann;
    graphs_ = !radiosity.iterative() && options.graphs;
    ahead_ = !radiosity.iterative();
    if constexpr (std::is_same_v<P, float>) {
      product_count_ = small_ && options.fused ? radiosity.DenseProducts(products_) : 0;
      fused_blocks_ = product_count_ > 0 ? FusedBlocks(options.fused_blocks) : 0;
    }
  }

  ~Loop() {
    for (auto& by_parity : graphs_by_parity_) {
      for (cudaGraphExec_t graph : by_parity) {
        if (graph != nullptr) cudaGraphExecDestroy(graph);
      }
    }
  }
  Loop(const Loop&) = delete;
  Loop& operator=(const Loop&) = delete;

  // Every device array of the loop, from `workspace`.
  void Carve(Workspace* workspace, int entries) {
    const size_t n = static_cast<size_t>(n_), vector = 3 * n;
    for (Point* point : {&current_, &trial_}) {
      point->emittance = workspace->Take<double>(vector);
      point->radiosity = workspace->Take<double>(vector);
      point->residual = workspace->Take<double>(vector);
      point->jacobian = workspace->Take<double>(9 * n);
      point->gradient_b = workspace->Take<double>(vector);
      point->curvature = workspace->Take<double>(vector);
    }
    for (double** array : {&lower_, &upper_, &desired_colour_, &gradient_, &d_, &hd_, &qg_, &mask_, &x_, &r_, &b0_,
                           &p_, &z_, &y_, &hp_, &solution_, &delta_, &step_trial_}) {
      *array = workspace->Take<double>(vector);
    }
    preconditioner_ = workspace->Take<double>(9 * n);
    for (P** array : {&p_fast_, &u_fast_, &back_fast_, &product_fast_}) *array = workspace->Take<P>(vector);
    weight_diagonal_ = workspace->Take<double>(n);
    offsets_ = workspace->Take<int>(n + 1);
    neighbours_ = workspace->Take<int>(entries);
    neighbour_weights_ = workspace->Take<double>(entries);
    if (metric_) factor_ = workspace->Take<double>(9 * n);
    fixed_ = workspace->Take<unsigned char>(vector);
    records_ = workspace->Take<FusedRecords>(1);
    trace_ = workspace->Take<IterationRecord>(static_cast<size_t>(options_.max_iterations) + 1);
  }

  // Alg. 1 and 2 (MinimiseBoundedDriver): in one cooperative kernel (FusedLoop) where the loop
  // is fused and its grid fits, else with this loop as the executor, a kernel per step.
  void Run(double* emittance, double* radiosity, ResidentSummary* summary) {
    if (fused_blocks_ > 0 && RunFused(emittance, radiosity, summary)) return;
    start_ = Clock::now();
    summary_ = summary;
    MinimiseBoundedDriver(options_, *this, &summary->records);
    DownloadResult(current_, emittance, radiosity);  // its K⁻¹E, evaluated at acceptance
    if (options_.profile) PrintProfile(SecondsSince(start_));
  }

  // The executor's operations (solver_driver.h). Each enqueues its kernels and reads the scalars
  // back (Sync), except where the work was enqueued ahead and read with an earlier operation's
  // scalars: Alg. 2's first start and (where products are cheap, `ahead_`) CG with a guess of its
  // iterations, its finish and the first trial step go with the gradient; the line search's
  // first trial (step 1) goes with the direction's slope.
  int Variables() const { return static_cast<int>(count_); }

  double Evaluate() {
    EnqueueEvaluation(current_);
    Sync();
    return host_->value;
  }

  GradientCheck Gradient() {
    Enqueue(Sequence::kHead, [&] {
      EnqueueGradient(current_);
      EnqueueGradientCheck();
      EnqueueInnerStart(/*first=*/true);
      if (ahead_) CgStart();
    });
    if (ahead_) {
      CgIterations(FirstBatch(expected_cg_));
      CgFinish();
    }
    Sync();
    newton_enqueued_ = ahead_;
    return {host_->projected_gradient, static_cast<int>(host_->free_variables)};
  }

  double InnerStart(bool first) {
    first_step_trial_ready_ = false;
    if (!first) {  // the first start went with the gradient
      EnqueueInnerStart(/*first=*/false);
      if (ahead_) {
        CgStart();
        CgIterations(FirstBatch(expected_cg_));
        CgFinish();
      }
      Sync();
      newton_enqueued_ = ahead_;
    }
    return host_->inner_projected;
  }

  NewtonStep SolveNewton() {
    if (!newton_enqueued_) {
      CgStart();
      CgFinish();
      Sync();
    }
    newton_enqueued_ = false;
    while (!host_->cg.done) {
      CgIterations(1);
      CgFinish();
      Sync();
    }
    expected_cg_ = std::max(1, host_->cg.iterations);
    first_step_trial_ready_ = true;  // CgFinish's, with the step length the driver forms
    return {host_->cg.iterations, host_->cg.preconditioner_applications, !(host_->solution_nonfinite > 0.0),
            host_->solution_max, host_->solution_slope, host_->solution_curvature};
  }

  TrialStep StepTrial(double alpha) {
    if (!first_step_trial_ready_) {
      EnqueueStepTrial(alpha, nullptr);
      Sync();
    }
    first_step_trial_ready_ = false;
    return {host_->cut > 0.0, host_->delta_slope};
  }

  double StepCurvature() {
    // δ in the products' precision, through CG's p (CG is done with it).
    Kernel<ToPrecisionPhase<P>><<<Blocks(count_), kThreads, 0, stream_>>>(count_, delta_, p_fast_);
    Launched("ToPrecisionPhase");
    Product(p_fast_, product_fast_, nullptr);
    Kernel<QuadraticPhase<P>><<<Blocks(count_), kThreads, 0, stream_>>>(count_, delta_, product_fast_, scalars_,
                                                                  reduction_);
    Launched("QuadraticPhase");
    Sync();
    return host_->quadratic;
  }

  void AcceptStep(bool accumulate) {
    Kernel<AcceptStepPhase<P>><<<Blocks(count_), kThreads, 0, stream_>>>(count_, step_trial_, product_fast_,
                                                                   accumulate, d_, hd_);
    Launched("AcceptStepPhase");
  }

  SearchDirection Direction() {
    Enqueue(Sequence::kFirstTrial, [&] {
      Kernel<DirectionSlopePhase><<<Blocks(count_), kThreads, 0, stream_>>>(count_, gradient_, d_, scalars_,
                                                                        reduction_);
      Launched("DirectionSlopePhase");
      EnqueueLineTrial(1.0);
      EnqueueEvaluation(trial_);
    });
    Sync();
    first_line_trial_ready_ = true;
    return {!(host_->direction_nonfinite > 0.0), host_->direction_slope};
  }

  double SteepestDirection() {
    Kernel<SteepestDirectionPhase><<<Blocks(count_), kThreads, 0, stream_>>>(count_, current_.emittance, gradient_,
                                                                       lower_, upper_, d_, scalars_, reduction_);
    Launched("SteepestDirectionPhase");
    Sync();
    first_line_trial_ready_ = false;  // the trial went along the other direction
    return host_->direction_slope;
  }

  double LineTrial(double step) {
    if (!first_line_trial_ready_) {
      EnqueueLineTrial(step);
      EnqueueEvaluation(trial_);
      Sync();
    }
    first_line_trial_ready_ = false;
    return host_->value;
  }

  void AcceptTrial() {
    std::swap(current_, trial_);
    parity_ ^= 1;
  }

  double FinalProjectedGradient() {
    EnqueueGradient(current_);
    EnqueueGradientCheck();
    Sync();
    return host_->projected_gradient;
  }

  void Record(int iteration, double cost, double step, int free_variables, int cg_iterations) {
    summary_->trace.push_back({iteration, cost, SecondsSince(start_), step, free_variables, cg_iterations, 0.0});
    if (iteration > 0 && options_.progress) options_.progress(iteration, cost, SecondsSince(start_));
  }

  void SetProjectedGradient(double projected) { summary_->trace.back().projected_gradient = projected; }

 private:
  // Run in one cooperative kernel (FusedLoop), then the summary from its records: the trace's
  // times are the device's, from the kernel's start, plus the host's time until the launch; the
  // progress callback is called afterwards, once per iteration, with those records. False (and
  // nothing done) where the device cannot hold the grid at once.
  bool RunFused(double* emittance, double* radiosity, ResidentSummary* summary) {
    const auto start = Clock::now();
    FusedArgs args{};
    args.n = n_;
    args.count = count_;
    args.options = options_;  // the plain settings, without the progress callback
    args.second_order = second_order_;
    args.neumann = neumann_;
    args.space = space_;
    args.weights = weights_;
    for (int k = 0; k < product_count_; ++k) args.products[k] = products_[k];
    args.product_count = product_count_;
    args.points[0] = current_;
    args.points[1] = trial_;
    args.lower = lower_, args.upper = upper_, args.desired_colour = desired_colour_, args.gradient = gradient_;
    args.d = d_, args.hd = hd_, args.qg = qg_, args.mask = mask_, args.x = x_, args.r = r_, args.b0 = b0_;
    args.p = p_, args.z = z_, args.y = y_, args.hp = hp_, args.solution = solution_, args.delta = delta_;
    args.step_trial = step_trial_, args.preconditioner = preconditioner_;
    if constexpr (std::is_same_v<P, float>) {  // fused_blocks_ is 0 otherwise
      args.p_fast = p_fast_, args.u_fast = u_fast_, args.back_fast = back_fast_, args.product_fast = product_fast_;
    }
    args.fixed = fixed_;
    args.scalars = scalars_;
    args.reduction = reduction_;
    args.records = records_;
    args.trace = trace_;
    void* parameters[] = {&args};
    const double launched = SecondsSince(start);
    const cudaError_t launch = cudaLaunchCooperativeKernel(reinterpret_cast<const void*>(&FusedLoopKernel),
                                                           fused_blocks_, kThreads, parameters, 0, stream_);
    if (launch == cudaErrorCooperativeLaunchTooLarge) {
      // Fewer multiprocessors free than when the grid was sized (another context holds some, say):
      // nothing ran, so the loop with a kernel per step starts from the same state.
      cudaGetLastError();
      return false;
    }
    Check(launch, "cudaLaunchCooperativeKernel(FusedLoopKernel)");
    // The records, the whole trace buffer and both points (the result is one of them), in one wait.
    FusedRecords records{};
    std::vector<IterationRecord> trace(static_cast<size_t>(options_.max_iterations) + 1);
    const size_t bytes = count_ * sizeof(double);
    std::vector<double> points(4 * count_);  // emittance of points 0 and 1, then their radiosity
    workspace_->DownloadAll({{&records, records_, sizeof records},
                             {trace.data(), trace_, trace.size() * sizeof(IterationRecord)},
                             {points.data(), current_.emittance, bytes},
                             {points.data() + count_, trial_.emittance, bytes},
                             {points.data() + 2 * count_, current_.radiosity, bytes},
                             {points.data() + 3 * count_, trial_.radiosity, bytes}},
                            stream_);
    std::memcpy(emittance, points.data() + records.result * count_, bytes);
    if (radiosity != nullptr) std::memcpy(radiosity, points.data() + (2 + records.result) * count_, bytes);
    trace.resize(records.records);
    summary->records = records.driver;
    summary->fused = true;
    summary->fused_blocks = fused_blocks_;
    for (IterationRecord& record : trace) record.seconds += launched;
    summary->trace = std::move(trace);
    if (options_.progress) {
      for (const IterationRecord& record : summary->trace) {
        if (record.iteration > 0) options_.progress(record.iteration, record.cost, record.seconds);
      }
    }
    if (options_.profile) {
      std::fprintf(stderr, "resident profile: %d patches, fused loop on %d blocks: %.3f ms (launched after %.3f ms)\n",
                   n_, fused_blocks_, 1e3 * SecondsSince(start), 1e3 * launched);
    }
    return true;
  }

  // The fused loop's grid: one block per multiprocessor (at most kMaxBlocks, what the reductions
  // hold), or `wanted` blocks (ResidentSettings::fused_blocks), even past what the device holds at
  // once: that launch fails and the loop with a kernel per step runs instead (a device test checks
  // it). 0 where the device has no cooperative launch.
  static int FusedBlocks(int wanted) {
    struct Device {
      int multiprocessors = 0, resident = 0;
    };
    static const Device device = [] {
      int ordinal = 0, cooperative = 0, multiprocessors = 0, per_multiprocessor = 0;
      PROCAM_CUDA(cudaGetDevice(&ordinal));
      PROCAM_CUDA(cudaDeviceGetAttribute(&cooperative, cudaDevAttrCooperativeLaunch, ordinal));
      PROCAM_CUDA(cudaDeviceGetAttribute(&multiprocessors, cudaDevAttrMultiProcessorCount, ordinal));
      PROCAM_CUDA(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&per_multiprocessor, FusedLoopKernel, kThreads, 0));
      return cooperative == 0 ? Device{} : Device{multiprocessors, multiprocessors * per_multiprocessor};
    }();
    if (device.resident == 0) return 0;
    if (wanted > device.resident) return wanted;
    return std::min(kMaxBlocks, wanted > 0 ? wanted : std::min(device.multiprocessors, device.resident));
  }

  void Launched(const char* name) {
    Check(cudaGetLastError(), name);
    ++profile_.launches;
  }

  // The scalars to the host; waits for everything enqueued.
  void Sync() {
    PROCAM_CUDA(cudaMemcpyAsync(host_, scalars_, sizeof(Scalars), cudaMemcpyDeviceToHost, stream_));
    const auto start = Clock::now();
    PROCAM_CUDA(cudaStreamSynchronize(stream_));
    ++profile_.syncs;
    profile_.sync_seconds += SecondsSince(start);
  }

  // Enqueues `sequence` (whose device work depends on nothing but the sequence and which point
  // buffer is current): replayed from a CUDA graph on the dense path, captured at its second use
  // (the first runs directly, so that cuBLAS has set itself up outside the capture); enqueued
  // directly on the matrix-free path, whose solves read their residuals on the host, or where a
  // capture failed.
  template <typename Work>
  void Enqueue(Sequence sequence, const Work& work) {
    if (!graphs_) {
      work();
      return;
    }
    const int s = static_cast<int>(sequence);
    cudaGraphExec_t& graph = graphs_by_parity_[s][parity_];
    if (graph == nullptr) {
      if (uses_[s][parity_]++ == 0 || !Capture(work, &graph)) {
        work();
        return;
      }
    }
    PROCAM_CUDA(cudaGraphLaunch(graph, stream_));
    ++profile_.graph_launches;
  }

  // Records `work` into `graph`; false (graphs off from then on) where the capture or the
  // instantiation failed.
  template <typename Work>
  bool Capture(const Work& work, cudaGraphExec_t* graph) {
    const auto start = Clock::now();
    ++profile_.captures;
    struct Timed {
      Profile& profile;
      Clock::time_point start;
      ~Timed() { profile.capture_seconds += SecondsSince(start); }
    } timed{profile_, start};
    if (cudaStreamBeginCapture(stream_, cudaStreamCaptureModeThreadLocal) != cudaSuccess) {
      cudaGetLastError();
      graphs_ = false;
      return false;
    }
    bool recorded = true;
    try {
      work();
    } catch (const std::exception&) {
      recorded = false;
    }
    cudaGraph_t captured = nullptr;
    const bool ended = cudaStreamEndCapture(stream_, &captured) == cudaSuccess && captured != nullptr;
    const bool ok = recorded && ended && cudaGraphInstantiate(graph, captured, 0) == cudaSuccess;
    if (captured != nullptr) cudaGraphDestroy(captured);
    if (!ok) {
      *graph = nullptr;
      cudaGetLastError();
      graphs_ = false;
    }
    return ok;
  }

  // ResidentSettings::profile: the solve's counts, then unit costs in µs (time to enqueue one,
  // and per operation until the device has finished a run of them).
  void PrintProfile(double loop_seconds) {
    const Profile counted = profile_;
    const int repeats = radiosity_.iterative() ? 5 : 100;
    const auto unit = [&](int count, const auto& enqueue, double* enqueue_us, double* complete_us) {
      PROCAM_CUDA(cudaStreamSynchronize(stream_));
      const auto start = Clock::now();
      for (int k = 0; k < count; ++k) enqueue();
      *enqueue_us = 1e6 * SecondsSince(start) / count;
      PROCAM_CUDA(cudaStreamSynchronize(stream_));
      *complete_us = 1e6 * SecondsSince(start) / count;
    };
    double kernel[2], fast[2], solve[2], sync[2];
    unit(100, [&] { Kernel<ToPrecisionPhase<P>><<<Blocks(count_), kThreads, 0, stream_>>>(count_, delta_, p_fast_); },
         &kernel[0], &kernel[1]);
    unit(repeats, [&] { SolveFast(p_fast_, false, u_fast_); }, &fast[0], &fast[1]);
    unit(repeats, [&] { radiosity_.Solve(current_.emittance, false, trial_.radiosity, stream_); }, &solve[0],
         &solve[1]);
    unit(100, [&] { Sync(); }, &sync[0], &sync[1]);
    std::fprintf(stderr,
                 "resident profile: %d patches, loop %.3f ms: %d syncs waiting %.3f ms, %d kernels, %d solves, "
                 "%d fast solves enqueued directly, %d graph launches (graphs %s, %d captured in %.3f ms); unit "
                 "costs, µs to enqueue / to complete: kernel %.1f / %.1f, fast solve %.1f / %.1f, solve %.1f / "
                 "%.1f, sync %.1f\n",
                 n_, 1e3 * loop_seconds, counted.syncs, 1e3 * counted.sync_seconds, counted.launches, counted.solves,
                 counted.fast_solves, counted.graph_launches, graphs_ ? "on" : "off", counted.captures,
                 1e3 * counted.capture_seconds, kernel[0], kernel[1], fast[0], fast[1], solve[0], solve[1], sync[1]);
  }

  // The point's emittance and (if `radiosity` is not null) radiosity, in one wait.
  void DownloadResult(const Point& point, double* emittance, double* radiosity) {
    const size_t bytes = count_ * sizeof(double);
    if (radiosity == nullptr) {
      workspace_->DownloadAll({{emittance, point.emittance, bytes}}, stream_);
    } else {
      workspace_->DownloadAll({{emittance, point.emittance, bytes}, {radiosity, point.radiosity, bytes}}, stream_);
    }
  }

  void SolveFast(const P* y, bool transposed, P* x) {
    radiosity_.SolveFast(y, transposed, x, stream_);
    ++profile_.fast_solves;
  }

  // result = H v (GaussNewtonProduct with fast solves); `gate`: skipped once CG has stopped
  // (the solves themselves still run).
  void Product(const P* v, P* result, const CgState* gate) {
    SolveFast(v, false, u_fast_);
    Kernel<WeightedProductPhase<P>><<<Blocks(n_), kThreads, 0, stream_>>>(n_, space_, weights_, second_order_,
                                                                    current_.jacobian, current_.curvature, u_fast_,
                                                                    back_fast_, gate);
    Launched("WeightedProductPhase");
    SolveFast(back_fast_, true, result);
  }

  // Fills `point` at point.emittance; f lands in the scalars.
  void EnqueueEvaluation(const Point& point) {
    radiosity_.Solve(point.emittance, false, point.radiosity, stream_);
    ++profile_.solves;
    Kernel<ResidualPhase><<<Blocks(n_), kThreads, 0, stream_>>>(n_, space_, point.radiosity, desired_colour_, point.residual,
                                                          point.jacobian);
    Launched("ResidualPhase");
    Kernel<WeightedResidualPhase><<<Blocks(n_), kThreads, 0, stream_>>>(n_, space_, weights_, point.radiosity,
                                                                  point.residual, point.jacobian, point.gradient_b,
                                                                  point.curvature, scalars_, reduction_);
    Launched("WeightedResidualPhase");
  }

  void EnqueueGradient(const Point& point) {
    radiosity_.Solve(point.gradient_b, true, gradient_, stream_);
    ++profile_.solves;
  }

  void EnqueueGradientCheck() {
    Kernel<GradientCheckPhase><<<Blocks(count_), kThreads, 0, stream_>>>(count_, current_.emittance, gradient_, lower_,
                                                                   upper_, fixed_, scalars_, reduction_);
    Launched("GradientCheckPhase");
  }

  void EnqueueLineTrial(double step) {
    Kernel<LineTrialPhase><<<Blocks(count_), kThreads, 0, stream_>>>(count_, current_.emittance, d_, step, lower_, upper_,
                                                               trial_.emittance);
    Launched("LineTrialPhase");
  }

  // ∇q, the mask and q's projected gradient (first: at d = 0).
  void EnqueueInnerStart(bool first) {
    Kernel<InnerStartPhase><<<Blocks(count_), kThreads, 0, stream_>>>(count_, first, d_, hd_, gradient_,
                                                                current_.emittance, lower_, upper_, fixed_, qg_,
                                                                mask_, scalars_, reduction_);
    Launched("InnerStartPhase");
  }

  // CG iterations enqueued before the first read of CG's state, given the last system's count.
  int FirstBatch(int expected) const { return small_ ? std::max(1, expected - 1) : 1; }

  void CgStart() {
    Kernel<CgStartPhase<P>><<<Blocks(n_), kThreads, 0, stream_>>>(n_, neumann_, qg_, mask_, current_.jacobian,
                                                            weight_diagonal_, x_, r_, b0_, p_, preconditioner_,
                                                            p_fast_, y_, scalars_, reduction_);
    Launched("CgStartPhase");
    if (neumann_) Neumann(/*start=*/true);
  }

  void Neumann(bool start) {
    Kernel<NeumannPhase<P>><<<Blocks(n_), kThreads, 0, stream_>>>(n_, start, weights_, current_.jacobian, preconditioner_,
                                                            y_, r_, z_, p_, p_fast_, options_.max_cg_iterations,
                                                            scalars_, reduction_);
    Launched("NeumannPhase");
  }

  // NewtonSystem::SolveMasked's loop body, `iterations` times (no-ops once CG has stopped).
  void CgIterations(int iterations) {
    for (int i = 0; i < iterations; ++i) Enqueue(Sequence::kCgIteration, [&] { CgIteration(); });
  }

  void CgIteration() {
    Product(p_fast_, product_fast_, &scalars_->cg);
    Kernel<CgCurvaturePhase<P>><<<Blocks(count_), kThreads, 0, stream_>>>(count_, product_fast_, mask_, p_, hp_, scalars_,
                                                                    reduction_);
    Launched("CgCurvaturePhase");
    Kernel<CgUpdatePhase><<<Blocks(n_), kThreads, 0, stream_>>>(n_, neumann_, p_, hp_, preconditioner_, x_, r_,
                                                          neumann_ ? y_ : z_, options_.cg_tolerance,
                                                          options_.max_cg_iterations, scalars_, reduction_);
    Launched("CgUpdatePhase");
    if (neumann_) Neumann(/*start=*/false);
    Kernel<CgDirectionPhase<P>><<<Blocks(count_), kThreads, 0, stream_>>>(count_, z_, p_, p_fast_, scalars_);
    Launched("CgDirectionPhase");
  }

  // CG's solution and Alg. 2's first trial step along it (with CgFinishPhase's step length).
  void CgFinish() {
    Enqueue(Sequence::kTail, [&] { CgFinishDirect(); });
  }

  void CgFinishDirect() {
    Kernel<CgFinishPhase><<<Blocks(count_), kThreads, 0, stream_>>>(count_, x_, b0_, r_, p_, qg_, solution_, scalars_,
                                                              reduction_);
    Launched("CgFinishPhase");
    EnqueueStepTrial(0.0, &scalars_->alpha);
  }

  void EnqueueStepTrial(double alpha, const double* alpha_on_device) {
    Kernel<StepTrialPhase><<<Blocks(count_), kThreads, 0, stream_>>>(count_, d_, solution_, current_.emittance, lower_,
                                                               upper_, qg_, alpha, alpha_on_device, step_trial_,
                                                               delta_, scalars_, reduction_);
    Launched("StepTrialPhase");
  }

  struct Profile {
    int syncs = 0, launches = 0, solves = 0, fast_solves = 0, graph_launches = 0, captures = 0;
    double sync_seconds = 0.0;     // the host waiting in cudaStreamSynchronize
    double capture_seconds = 0.0;  // recording and instantiating the CUDA graphs
  };

  const ResidentOptions& options_;
  const DeviceRadiosity& radiosity_;
  Workspace* workspace_;
  Profile profile_;
  // The driver's run: its start, where the trace goes, and the work enqueued ahead of it.
  Clock::time_point start_;
  ResidentSummary* summary_ = nullptr;
  bool ahead_ = false;                   // CG enqueued ahead of reads (products are cheap: not matrix-free)
  int expected_cg_ = 1;                  // CG iterations of the last Newton system
  bool newton_enqueued_ = false;         // CG started (and run ahead) with the last InnerStart
  bool first_step_trial_ready_ = false;  // Alg. 2's first trial step, read with CG's finish
  bool first_line_trial_ready_ = false;  // the line search's trial at step 1, read with the slope
  // CUDA graphs of the sequences, per parity (which point buffer is current_).
  bool graphs_ = false;
  int parity_ = 0;
  cudaGraphExec_t graphs_by_parity_[static_cast<int>(Sequence::kCount)][2] = {};
  int uses_[static_cast<int>(Sequence::kCount)][2] = {};
  const int n_;
  const long count_;  // variables, 3n
  bool small_ = true;
  bool second_order_ = false;
  bool neumann_ = false;  // CG's preconditioner: block Jacobi with a Neumann term (NeumannPhase)
  cudaStream_t stream_ = nullptr;
  Scalars* scalars_ = nullptr;  // device
  Scalars* host_ = nullptr;     // pinned host copy, as of the last Sync
  Reduction reduction_{};
  ColourSpace space_{};
  Weights weights_{};
  Point current_{}, trial_{};
  double *lower_, *upper_, *desired_colour_, *gradient_, *d_, *hd_, *qg_, *mask_;
  bool metric_ = false;       // the problem has a colour metric's factors ...
  double* factor_ = nullptr;  // ... here (ColourSpace::factor)
  double *x_, *r_, *b0_, *p_, *z_, *y_, *hp_, *solution_, *delta_, *step_trial_, *preconditioner_;
  P *p_fast_, *u_fast_, *back_fast_, *product_fast_;
  double *weight_diagonal_, *neighbour_weights_;
  int *offsets_, *neighbours_;
  unsigned char* fixed_;
  // The fused loop (FusedLoop): its grid (0: not used), the dense K⁻¹ it reads, and its records.
  int fused_blocks_ = 0;
  DenseProduct products_[3] = {};
  int product_count_ = 0;
  FusedRecords* records_ = nullptr;
  IterationRecord* trace_ = nullptr;
};

}  // namespace

void MinimiseResident(const ResidentOptions& options, const ResidentProblem& problem, const DeviceRadiosity& radiosity,
                      double* emittance, double* radiosity_out, ResidentSummary* summary) {
  if (problem.patches <= 0) throw std::invalid_argument("resident GPU solve: no patches");
  const WorkspacePool::Lease workspace = WorkspacePool::Get().Take();
  if (radiosity.single()) {
    Loop<float>(options, problem, radiosity, workspace.get()).Run(emittance, radiosity_out, summary);
  } else {
    Loop<double>(options, problem, radiosity, workspace.get()).Run(emittance, radiosity_out, summary);
  }
}

}  // namespace procam::cuda
