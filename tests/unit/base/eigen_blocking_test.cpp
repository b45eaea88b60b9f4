// Eigen's matrix products block their sums by cache sizes it reads with CPUID unless
// EIGEN_NO_CPUID is defined, which the build defines for every target (CMakeLists.txt) and for
// plugins built against exid (exid::dynamics' interface). Then Eigen blocks by its fixed
// defaults on every machine, and a design's bits do not follow the CPU's L1 size: with 48 KiB
// (this machine's reading) a 77 x 700 by 700 x 77 product summed its 700 terms in one pass,
// with 32 KiB in two (docs/excitation.md §6).
#include <gtest/gtest.h>

#include <Eigen/Core>

TEST(EigenBlocking, ProductsAreBlockedByFixedCacheSizesNotTheCpus) {
#ifndef EIGEN_NO_CPUID
  FAIL() << "EIGEN_NO_CPUID is not defined for this target";
#endif
  EXPECT_EQ(Eigen::l1CacheSize(), 32 * 1024);
  EXPECT_EQ(Eigen::l2CacheSize(), 256 * 1024);
  EXPECT_EQ(Eigen::l3CacheSize(), 2 * 1024 * 1024);
  // the information matrix of a 100-sample Panda design (700 rows, 77 columns): two depth blocks
  Eigen::Index k = 700, m = 77, n = 77;
  Eigen::internal::computeProductBlockingSizes<double, double>(k, m, n, Eigen::Index(1));
  EXPECT_EQ(k, 352);
}
