#include "compensation/dense_kernels.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>
#include <limits>

#include <cpuid.h>
#include <immintrin.h>

#include <Eigen/Core>

namespace procam {
namespace {

// For rows i in [begin, end): the dot products of a[i·stride + j], j < length, with the columns
// of x (leading dimension ldx), stored to (or, with `subtract`, subtracted from) the columns of
// out (leading dimension ldo) at row i. Two rows at a time, so every load of x serves two rows.
template <typename T, int C>
inline __attribute__((always_inline)) void RowsDot(const T* a, long stride, long length, const T* x, long ldx,
                                                  T* out, long ldo, long begin, long end, bool subtract) {
  static_assert(C == 1 || C == 3, "one or three columns");
  const T* x0 = x;
  const T* x1 = x + (C == 3 ? ldx : 0);
  const T* x2 = x + (C == 3 ? 2 * ldx : 0);
  const T sign = subtract ? T(-1) : T(1);
  auto store = [&](long i, long c, T value) {
    T& target = out[c * ldo + i];
    target = subtract ? target + sign * value : value;
  };
  long i = begin;
  for (; i + 1 < end; i += 2) {
    const T* r0 = a + i * stride;
    const T* r1 = r0 + stride;
    T s00 = 0, s01 = 0, s02 = 0, s10 = 0, s11 = 0, s12 = 0;
    if constexpr (C == 3) {
#pragma omp simd reduction(+ : s00, s01, s02, s10, s11, s12)
      for (long j = 0; j < length; ++j) {
        s00 += r0[j] * x0[j];
        s01 += r0[j] * x1[j];
        s02 += r0[j] * x2[j];
        s10 += r1[j] * x0[j];
        s11 += r1[j] * x1[j];
        s12 += r1[j] * x2[j];
      }
      store(i, 1, s01);
      store(i, 2, s02);
      store(i + 1, 1, s11);
      store(i + 1, 2, s12);
    } else {
#pragma omp simd reduction(+ : s00, s10)
      for (long j = 0; j < length; ++j) {
        s00 += r0[j] * x0[j];
        s10 += r1[j] * x0[j];
      }
    }
    store(i, 0, s00);
    store(i + 1, 0, s10);
  }
  for (; i < end; ++i) {
    const T* r0 = a + i * stride;
    T s0 = 0, s1 = 0, s2 = 0;
#pragma omp simd reduction(+ : s0, s1, s2)
    for (long j = 0; j < length; ++j) {
      s0 += r0[j] * x0[j];
      s1 += r0[j] * x1[j];
      s2 += r0[j] * x2[j];
    }
    store(i, 0, s0);
    if constexpr (C == 3) {
      store(i, 1, s1);
      store(i, 2, s2);
    }
  }
}

// Rows [begin, end) of A contribute A(i,:)ᵀ x(i,:) to y = Aᵀ x (y must start at zero).
template <typename T, int C>
inline __attribute__((always_inline)) void RowsTransposedTimes(const T* a, long n, const T* x, T* y, long begin,
                                                              long end) {
  static_assert(C == 1 || C == 3, "one or three columns");
  T* y0 = y;
  T* y1 = y + (C == 3 ? n : 0);
  T* y2 = y + (C == 3 ? 2 * n : 0);
  for (long i = begin; i < end; ++i) {
    const T* r = a + i * n;
    const T c0 = x[i];
    if constexpr (C == 3) {
      const T c1 = x[n + i], c2 = x[2 * n + i];
#pragma omp simd
      for (long j = 0; j < n; ++j) {
        y0[j] += r[j] * c0;
        y1[j] += r[j] * c1;
        y2[j] += r[j] * c2;
      }
    } else {
#pragma omp simd
      for (long j = 0; j < n; ++j) y0[j] += r[j] * c0;
    }
  }
}

// The compiled variants: AVX2 + FMA where the CPU has them, the baseline otherwise.
#define PROCAM_CLONES __attribute__((target_clones("arch=haswell", "default")))
template <typename T>
using RowsDotKernel = void (*)(const T*, long, long, const T*, long, T*, long, long, long, bool);
PROCAM_CLONES void RowsDotF1(const float* a, long stride, long length, const float* x, long ldx, float* out,
                             long ldo, long begin, long end, bool subtract) {
  RowsDot<float, 1>(a, stride, length, x, ldx, out, ldo, begin, end, subtract);
}
PROCAM_CLONES void RowsDotF3(const float* a, long stride, long length, const float* x, long ldx, float* out,
                             long ldo, long begin, long end, bool subtract) {
  RowsDot<float, 3>(a, stride, length, x, ldx, out, ldo, begin, end, subtract);
}
PROCAM_CLONES void RowsDotD1(const double* a, long stride, long length, const double* x, long ldx, double* out,
                             long ldo, long begin, long end, bool subtract) {
  RowsDot<double, 1>(a, stride, length, x, ldx, out, ldo, begin, end, subtract);
}
PROCAM_CLONES void RowsDotD3(const double* a, long stride, long length, const double* x, long ldx, double* out,
                             long ldo, long begin, long end, bool subtract) {
  RowsDot<double, 3>(a, stride, length, x, ldx, out, ldo, begin, end, subtract);
}
PROCAM_CLONES void RowsTransposedTimesF1(const float* a, long n, const float* x, float* y, long b, long e) {
  RowsTransposedTimes<float, 1>(a, n, x, y, b, e);
}
PROCAM_CLONES void RowsTransposedTimesF3(const float* a, long n, const float* x, float* y, long b, long e) {
  RowsTransposedTimes<float, 3>(a, n, x, y, b, e);
}
#undef PROCAM_CLONES

// Half-precision rows: binary16 → float32 with F16C, eight at a time, where the CPU has it.
__attribute__((target("avx2,fma,f16c"))) inline float HorizontalSum(__m256 v) {
  const __m128 sum = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
  const __m128 pairs = _mm_add_ps(sum, _mm_movehl_ps(sum, sum));
  return _mm_cvtss_f32(_mm_add_ss(pairs, _mm_shuffle_ps(pairs, pairs, 1)));
}

template <int C>
__attribute__((target("avx2,fma,f16c"))) void RowsDotHalfF16c(const std::uint16_t* a, long stride, long length,
                                                               const float* x, long ldx, float* out, long ldo,
                                                               long begin, long end) {
  const long vector_end = length / 8 * 8;
  long i = begin;
  for (; i + 1 < end; i += 2) {  // two rows: every load of x serves both
    const std::uint16_t* r0 = a + i * stride;
    const std::uint16_t* r1 = r0 + stride;
    __m256 s[2][C];
    for (int c = 0; c < C; ++c) s[0][c] = s[1][c] = _mm256_setzero_ps();
    for (long j = 0; j < vector_end; j += 8) {
      const __m256 a0 = _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(r0 + j)));
      const __m256 a1 = _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(r1 + j)));
      for (int c = 0; c < C; ++c) {
        const __m256 xc = _mm256_loadu_ps(x + c * ldx + j);
        s[0][c] = _mm256_fmadd_ps(a0, xc, s[0][c]);
        s[1][c] = _mm256_fmadd_ps(a1, xc, s[1][c]);
      }
    }
    for (int c = 0; c < C; ++c) {
      float t0 = HorizontalSum(s[0][c]), t1 = HorizontalSum(s[1][c]);
      for (long j = vector_end; j < length; ++j) {
        t0 += _cvtsh_ss(r0[j]) * x[c * ldx + j];
        t1 += _cvtsh_ss(r1[j]) * x[c * ldx + j];
      }
      out[c * ldo + i] -= t0;
      out[c * ldo + i + 1] -= t1;
    }
  }
  for (; i < end; ++i) {
    const std::uint16_t* r0 = a + i * stride;
    __m256 s[C];
    for (int c = 0; c < C; ++c) s[c] = _mm256_setzero_ps();
    for (long j = 0; j < vector_end; j += 8) {
      const __m256 a0 = _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(r0 + j)));
      for (int c = 0; c < C; ++c) s[c] = _mm256_fmadd_ps(a0, _mm256_loadu_ps(x + c * ldx + j), s[c]);
    }
    for (int c = 0; c < C; ++c) {
      float t = HorizontalSum(s[c]);
      for (long j = vector_end; j < length; ++j) t += _cvtsh_ss(r0[j]) * x[c * ldx + j];
      out[c * ldo + i] -= t;
    }
  }
}

// float32 → binary16, rounding to nearest even (Eigen's conversion).
std::uint16_t FloatToHalf(float value) { return Eigen::numext::bit_cast<std::uint16_t>(Eigen::half(value)); }

// The portable fallback: binary16 → float32 by Eigen's conversion.
float HalfToFloat(std::uint16_t h) { return static_cast<float>(Eigen::numext::bit_cast<Eigen::half>(h)); }

void RowsDotHalfPortable(const std::uint16_t* a, long stride, long length, const float* x, long ldx, float* out,
                         long ldo, long begin, long end, int columns) {
  for (long i = begin; i < end; ++i) {
    for (int c = 0; c < columns; ++c) {
      float t = 0;
      for (long j = 0; j < length; ++j) t += HalfToFloat(a[i * stride + j]) * x[c * ldx + j];
      out[c * ldo + i] -= t;
    }
  }
}

bool HaveF16c() {
  static const bool have = [] {
    __builtin_cpu_init();
    // F16C through cpuid: clang before 15 knows no "f16c" for __builtin_cpu_supports.
    unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
    const bool f16c = __get_cpuid(1, &eax, &ebx, &ecx, &edx) && (ecx & bit_F16C);
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") && f16c;
  }();
  return have;
}

// Subtracts the dot products (as RowsDot with `subtract`), for the half-precision factor.
void RowsDotHalf(const std::uint16_t* a, long stride, long length, const float* x, long ldx, float* out, long ldo,
                 long begin, long end, int columns) {
  if (!HaveF16c()) return RowsDotHalfPortable(a, stride, length, x, ldx, out, ldo, begin, end, columns);
  if (columns == 3) return RowsDotHalfF16c<3>(a, stride, length, x, ldx, out, ldo, begin, end);
  RowsDotHalfF16c<1>(a, stride, length, x, ldx, out, ldo, begin, end);
}

template <typename T>
void Product(const T* a, int n, const T* x, T* y, RowsDotKernel<T> kernel) {
  kernel(a, n, n, x, n, y, n, 0, n, false);
}

// Rows per block of the substitutions (32–128 measured within noise of each other; 256 slower).
constexpr int kSubstitutionBlock = 64;

// `subtract_dots(a, stride, length, x, out, begin, end)`: out_i −= Σ_{j<length} a[i·stride + j]
// x_j for rows i in [begin, end), every column; `diagonal(i)` = S_ii.
template <typename Factor, typename T, typename SubtractDots, typename Diagonal>
void Substitute(const Factor* s, int n, int columns, T* x, SubtractDots subtract_dots, Diagonal diagonal) {
  const long size = n;
  const auto diagonal_row = [&](long i, long from, long to) {
    // x_i = (x_i − Σ_{from≤j<to} S_ij x_j) / S_ii.
    subtract_dots(s + from, size, to - from, x + from, x, i, i + 1);
    for (int c = 0; c < columns; ++c) x[c * size + i] /= diagonal(i);
  };
  // Forward, L y = b: the rows of a block first subtract their part left of the block (two rows
  // at a time), then the block's triangle is solved row by row.
  for (long k0 = 0; k0 < size; k0 += kSubstitutionBlock) {
    const long k1 = std::min(size, k0 + kSubstitutionBlock);
    subtract_dots(s, size, k0, x, x, k0, k1);
    for (long i = k0; i < k1; ++i) diagonal_row(i, k0, i);
  }
  // Backward, Lᵀ x = y, from the last block: row i of Lᵀ is the part of row i of S right of the
  // diagonal.
  const long last = (size - 1) / kSubstitutionBlock * kSubstitutionBlock;
  for (long k0 = last; k0 >= 0; k0 -= kSubstitutionBlock) {
    const long k1 = std::min(size, k0 + kSubstitutionBlock);
    subtract_dots(s + k1, size, size - k1, x + k1, x, k0, k1);
    for (long i = k1 - 1; i >= k0; --i) diagonal_row(i, i + 1, k1);
  }
}

template <typename T, typename Kernel>
void TransposedProduct(const T* a, int n, const T* x, int columns, T* y, Kernel kernel) {
  std::fill(y, y + static_cast<long>(n) * columns, T(0));
  kernel(a, n, x, y, 0, n);
}

}  // namespace

void DenseProduct(const float* a, int n, const float* x, int columns, float* y) {
  assert(columns == 1 || columns == 3);
  Product<float>(a, n, x, y, columns == 3 ? RowsDotF3 : RowsDotF1);
}

void DenseProduct(const double* a, int n, const double* x, int columns, double* y) {
  assert(columns == 1 || columns == 3);
  Product<double>(a, n, x, y, columns == 3 ? RowsDotD3 : RowsDotD1);
}

void DenseTransposedProduct(const float* a, int n, const float* x, int columns, float* y) {
  assert(columns == 1 || columns == 3);
  TransposedProduct(a, n, x, columns, y, columns == 3 ? RowsTransposedTimesF3 : RowsTransposedTimesF1);
}

template <typename T>
void CholeskySolveWith(const T* factor, int n, int columns, T* x, RowsDotKernel<T> kernel) {
  const long ld = n;
  Substitute(
      factor, n, columns, x,
      [&](const T* a, long stride, long length, const T* xs, T* out, long begin, long end) {
        kernel(a, stride, length, xs, ld, out, ld, begin, end, true);
      },
      [&](long i) { return factor[i * ld + i]; });
}

void CholeskySolve(const float* factor, int n, int columns, float* x) {
  assert(columns == 1 || columns == 3);
  CholeskySolveWith<float>(factor, n, columns, x, columns == 3 ? RowsDotF3 : RowsDotF1);
}

void CholeskySolve(const double* factor, int n, int columns, double* x) {
  assert(columns == 1 || columns == 3);
  CholeskySolveWith<double>(factor, n, columns, x, columns == 3 ? RowsDotD3 : RowsDotD1);
}

void CholeskySolve(const std::uint16_t* factor, int n, int columns, float* x) {
  assert(columns == 1 || columns == 3);
  const long ld = n;
  Substitute(
      factor, n, columns, x,
      [&](const std::uint16_t* a, long stride, long length, const float* xs, float* out, long begin, long end) {
        RowsDotHalf(a, stride, length, xs, ld, out, ld, begin, end, columns);
      },
      [&](long i) { return HalfToFloat(factor[i * ld + i]); });
}

void ToHalf(const float* values, long count, std::uint16_t* half) {
  for (long k = 0; k < count; ++k) half[k] = FloatToHalf(values[k]);
}

}  // namespace procam
