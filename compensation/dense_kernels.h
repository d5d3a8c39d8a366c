#pragma once
// Dense matrix times a few columns (1 or 3: one colour channel, or all three), the products
// every radiosity and Hessian application of the solver reduces to. Eigen's general product
// does these with SSE2 at default compiler flags; these kernels are compiled for AVX2/FMA as
// well (chosen at run time when the CPU has it). They are single-threaded: splitting rows over
// two OpenMP threads gained ≤ 20% on an idle 2-core machine and lost 10–100× whenever another
// process held a core (every block of a substitution ends in a barrier), see docs/solver.md.
// The CUDA port replaces them with cuBLAS gemm/trsm.
//
// Storage: `a` is n×n with row i contiguous (a[i·n + j] = A_ij; an Eigen column-major matrix
// passes its transpose this way). `x` and `y` are n×columns, column-major (leading dimension n),
// and must not overlap.

#include <cstdint>

namespace procam {

// y = A x.
void DenseProduct(const float* a, int n, const float* x, int columns, float* y);
void DenseProduct(const double* a, int n, const double* x, int columns, double* y);
// y = Aᵀ x.
void DenseTransposedProduct(const float* a, int n, const float* x, int columns, float* y);

// Solves L Lᵀ x = b in place (x holds b on entry): a forward and a backward substitution.
// `factor` is n×n holding the Cholesky factor L in its lower triangle and Lᵀ in its strict
// upper one; that matrix is symmetric, so its storage order does not matter, and row i holds
// both row i of L (forward pass) and row i of Lᵀ (backward pass) contiguously. Blocks of rows
// are first updated two rows at a time (a dot-product sweep), then the small diagonal triangle.
void CholeskySolve(const float* factor, int n, int columns, float* x);
void CholeskySolve(const double* factor, int n, int columns, double* x);
// The same with the factor in IEEE half precision (binary16 bit patterns, from ToHalf): half
// the bytes of float32 again, so the solves that CG repeats are twice as fast once they are
// memory-bound (and a 1000-patch factor fits a 4 MB L2 cache). Arithmetic is float32. Entry
// rounding is ≤ 2⁻¹¹ relative (absolute ≤ 3·10⁻⁸ below 6·10⁻⁵), so a solve is accurate to about
// cond(L Lᵀ)·5·10⁻⁴ relative: for CG directions and preconditioners, never for values.
void CholeskySolve(const std::uint16_t* factor, int n, int columns, float* x);
// Round-to-nearest binary16 of each value (overflow to ±inf; the factors are bounded by 1).
void ToHalf(const float* values, long count, std::uint16_t* half);

}  // namespace procam
