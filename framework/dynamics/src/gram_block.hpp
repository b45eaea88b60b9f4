// exid — the Gram block update acc[i][j] += sum_r B[r][i] B[r][j], j <= i < m, r < k (B row-major
// with leading dimension ldb, acc row-major with leading dimension ld), written once for the
// portable copy (kernels_portable.cpp) and the AVX one without FMA (kernels_lanes_avx.cpp): the
// compiler vectorises the loop over j, each j's sum the same sequence of operations, so both
// give the same bits. Each including source defines EXID_GRAM_NS first. Not a public header.
#pragma once

#if !defined(EXID_GRAM_NS)
#error "define EXID_GRAM_NS before including gram_block.hpp"
#endif

namespace exid::detail::EXID_GRAM_NS {
namespace {

inline void gramBlock(double* acc, int ld, const double* B, int ldb, int k, int m) {
  for (int i = 0; i < m; ++i) {
    double* A = acc + static_cast<long>(i) * ld;
    const int len = i + 1;
    int r = 0;
    for (; r + 4 <= k; r += 4) {
      const double* B0 = B + static_cast<long>(r) * ldb;
      const double* B1 = B0 + ldb;
      const double* B2 = B1 + ldb;
      const double* B3 = B2 + ldb;
      const double b0 = B0[i], b1 = B1[i], b2 = B2[i], b3 = B3[i];
      for (int j = 0; j < len; ++j) A[j] += b0 * B0[j] + b1 * B1[j] + b2 * B2[j] + b3 * B3[j];
    }
    for (; r < k; ++r) {
      const double* B0 = B + static_cast<long>(r) * ldb;
      const double b0 = B0[i];
      for (int j = 0; j < len; ++j) A[j] += b0 * B0[j];
    }
  }
}

}  // namespace
}  // namespace exid::detail::EXID_GRAM_NS
