// exid — the AVX2 + FMA copy of the hot kernels (kernels.hpp). framework/CMakeLists.txt compiles
// this source alone with -mavx2 -mfma -ffp-contract=fast on x86-64 (GCC, Clang); isa.cpp runs it
// only where the CPU has both. Every entry point is flattened (all it calls, Eigen included, is
// inlined into it) and has internal linkage: the only symbol this object defines is
// exid::detail::avx2Kernels(), so no inline function compiled for AVX2 can replace the baseline
// copy of another source at link time (ctest dynamics.isa_symbols checks it with nm). Built where
// EXID_KERNELS_AVX2 (CMakeLists.txt): optimised builds without sanitizers, on x86-64.
#if defined(__AVX2__) && defined(__FMA__)

#include <immintrin.h>

#include <cmath>

#include "exid/fmath.hpp"

namespace exid::detail::avx2 {
namespace {
// sin and cos of every joint angle: exid's (exid/fmath.hpp, compiled without contraction), the
// same bits as the portable copy's; the rest of this copy contracts into FMAs and may differ in
// the last bits (docs/dynamics.md §6)
inline void sinCos(int n, const double* q, double* s, double* c) {
  for (int j = 0; j < n; ++j) {
    const double x = q[j];  // one load: s may alias q
    double sj, cj;
    exid::fmath::sincos(x, &sj, &cj);
    s[j] = sj;
    c[j] = cj;
  }
}
}  // namespace
}  // namespace exid::detail::avx2

#define EXID_KERNEL_NS avx2
#define EXID_KERNEL __attribute__((flatten))
#include "kernels.hpp"

namespace exid::detail {

namespace avx2 {
namespace {

// GramAccumulator's block update with full vectors: the rows of acc have room for ldb entries
// past the diagonal block's start and B's rows are zero-padded to ldb, so the extra entries land
// in the unused upper triangle.
inline int roundUp4(int x) { return (x + 3) & ~3; }

void gram(double* acc, int ld, const double* B, int ldb, int k, int m) {
  for (int i = 0; i < m; ++i) {
    double* A = acc + static_cast<long>(i) * ld;
    const int len4 = roundUp4(i + 1);
    int r = 0;
    for (; r + 4 <= k; r += 4) {
      const double* B0 = B + static_cast<long>(r) * ldb;
      const double* B1 = B0 + ldb;
      const double* B2 = B1 + ldb;
      const double* B3 = B2 + ldb;
      const __m256d b0 = _mm256_set1_pd(B0[i]), b1 = _mm256_set1_pd(B1[i]);
      const __m256d b2 = _mm256_set1_pd(B2[i]), b3 = _mm256_set1_pd(B3[i]);
      for (int j = 0; j < len4; j += 4) {
        __m256d a = _mm256_loadu_pd(A + j);
        a = _mm256_fmadd_pd(b0, _mm256_loadu_pd(B0 + j), a);
        a = _mm256_fmadd_pd(b1, _mm256_loadu_pd(B1 + j), a);
        a = _mm256_fmadd_pd(b2, _mm256_loadu_pd(B2 + j), a);
        a = _mm256_fmadd_pd(b3, _mm256_loadu_pd(B3 + j), a);
        _mm256_storeu_pd(A + j, a);
      }
    }
    for (; r < k; ++r) {
      const double* B0 = B + static_cast<long>(r) * ldb;
      const __m256d b0 = _mm256_set1_pd(B0[i]);
      for (int j = 0; j < len4; j += 4)
        _mm256_storeu_pd(A + j,
                         _mm256_fmadd_pd(b0, _mm256_loadu_pd(B0 + j), _mm256_loadu_pd(A + j)));
    }
  }
}

const Kernels kTable = {Isa::Avx2,
                        &torqueRegressor,
                        &inverseDynamics,
                        &energyRegressor,
                        &torqueRegressorVjp,
                        &energyRegressorVjp,
                        &gram};

}  // namespace
}  // namespace avx2

const Kernels* avx2Kernels() { return &avx2::kTable; }

}  // namespace exid::detail

#else

#include "kernel_table.hpp"

namespace exid::detail {
const Kernels* avx2Kernels() { return nullptr; }
}  // namespace exid::detail

#endif
