// exid — sin, cos, exp, log with the same bits on every CPU (exid/fmath.hpp).
//
// The algorithms and their minimax coefficients are those of fdlibm (k_sin.c, k_cos.c,
// e_rem_pio2.c, e_exp.c, e_log.c):
//   Copyright (C) 1993 by Sun Microsystems, Inc. All rights reserved.
//   Developed at SunPro, a Sun Microsystems, Inc. business.
//   Permission to use, copy, modify, and distribute this software is freely granted, provided
//   that this notice is preserved.
// Written here in plain double arithmetic; this file is compiled with -ffp-contract=off
// (framework/CMakeLists.txt): a fused multiply-add would round differently on a CPU that has one.
#include "exid/fmath.hpp"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "exid/fmath_kernels.hpp"

namespace exid::fmath {
namespace {

inline std::uint64_t bits(double x) {
  std::uint64_t u;
  std::memcpy(&u, &x, sizeof u);
  return u;
}
inline double fromBits(std::uint64_t u) {
  double x;
  std::memcpy(&x, &u, sizeof x);
  return x;
}
inline std::uint32_t highWord(double x) { return static_cast<std::uint32_t>(bits(x) >> 32); }
// 2^k for -1022 <= k <= 1023
inline double pow2(int k) { return fromBits(static_cast<std::uint64_t>(k + 1023) << 52); }

// ---- sin, cos ----------------------------------------------------------------------------------
// the kernels, the reduction and the constants are in exid/fmath_kernels.hpp, shared with the
// vector lanes

using namespace kernels;

}  // namespace

void sincos(double x, double* s, double* c) {
  const std::uint32_t ix = highWord(x) & 0x7fffffffu;
  if (ix <= kPio4High) {
    if (ix < kTinyHigh) {
      *s = x;
      *c = 1.0;
      return;
    }
    *s = kernelSin(x);
    *c = kernelCos(x, 0.0);
    return;
  }
  if (ix >= 0x7ff00000u) {  // inf or NaN
    *s = *c = x - x;
    return;
  }
  if (ix >= kMediumHigh) {  // beyond the exact reduction: libm's (see the header)
    *s = std::sin(x);
    *c = std::cos(x);
    return;
  }
  double y[2];
  const int n = remPio2(x, y);
  const double ks = kernelSin(y[0], y[1]), kc = kernelCos(y[0], y[1]);
  switch (n & 3) {
    case 0:
      *s = ks;
      *c = kc;
      break;
    case 1:
      *s = kc;
      *c = -ks;
      break;
    case 2:
      *s = -ks;
      *c = -kc;
      break;
    default:
      *s = -kc;
      *c = ks;
      break;
  }
}

double sin(double x) {
  const std::uint32_t ix = highWord(x) & 0x7fffffffu;
  if (ix <= kPio4High) return ix < kTinyHigh ? x : kernelSin(x);
  if (ix >= 0x7ff00000u) return x - x;
  if (ix >= kMediumHigh) return std::sin(x);
  double y[2];
  const int n = remPio2(x, y);
  switch (n & 3) {
    case 0:
      return kernelSin(y[0], y[1]);
    case 1:
      return kernelCos(y[0], y[1]);
    case 2:
      return -kernelSin(y[0], y[1]);
    default:
      return -kernelCos(y[0], y[1]);
  }
}

double cos(double x) {
  const std::uint32_t ix = highWord(x) & 0x7fffffffu;
  if (ix <= kPio4High) return ix < kTinyHigh ? 1.0 : kernelCos(x, 0.0);
  if (ix >= 0x7ff00000u) return x - x;
  if (ix >= kMediumHigh) return std::cos(x);
  double y[2];
  const int n = remPio2(x, y);
  switch (n & 3) {
    case 0:
      return kernelCos(y[0], y[1]);
    case 1:
      return -kernelSin(y[0], y[1]);
    case 2:
      return -kernelCos(y[0], y[1]);
    default:
      return kernelSin(y[0], y[1]);
  }
}

// ---- exp, log ----------------------------------------------------------------------------------

namespace {
// ln 2 in two pieces: kLn2Hi has 32 significant bits (k * kLn2Hi exact for |k| < 2^21)
constexpr double kLn2Hi = 6.93147180369123816490e-01, kLn2Lo = 1.90821492927058770002e-10;
constexpr double kInvLn2 = 1.44269504088896338700e+00;
constexpr double P1 = 1.66666666666666019037e-01, P2 = -2.77777777770155933842e-03,
                 P3 = 6.61375632143793436117e-05, P4 = -1.65339022054652515390e-06,
                 P5 = 4.13813679705723846039e-08;
constexpr double kExpOverflow = 7.09782712893383973096e+02;    // above: +inf
constexpr double kExpUnderflow = -7.45133219101941108420e+02;  // below: 0
constexpr double Lg1 = 6.666666666666735130e-01, Lg2 = 3.999999999940941908e-01,
                 Lg3 = 2.857142874366239149e-01, Lg4 = 2.222219843214978396e-01,
                 Lg5 = 1.818357216161805012e-01, Lg6 = 1.531383769920937332e-01,
                 Lg7 = 1.479819860511658591e-01;
}  // namespace

double exp(double x) {
  if (std::isnan(x)) return x + x;
  if (x > kExpOverflow) return HUGE_VAL;
  if (x < kExpUnderflow) return 0.0;
  const std::uint32_t ix = highWord(x) & 0x7fffffffu;
  if (ix < 0x3e300000u) return 1.0 + x;  // |x| < 2^-28
  double hi = 0.0, lo = 0.0;
  int k = 0;
  if (ix > 0x3fd62e42u) {  // |x| > ln2 / 2: x = k ln2 + r, |r| <= ln2 / 2
    const double fk = (x * kInvLn2 + kToInt) - kToInt;
    k = static_cast<int>(fk);
    hi = x - fk * kLn2Hi;  // exact
    lo = fk * kLn2Lo;
    x = hi - lo;
  }
  // exp(r) = 1 + r + r c(r) / (2 - c(r)), c(r) = r - r^2 P(r^2): the Remez fit of fdlibm
  const double t = x * x;
  const double c = x - t * (P1 + t * (P2 + t * (P3 + t * (P4 + t * P5))));
  if (k == 0) return 1.0 - ((x * c) / (c - 2.0) - x);
  const double y = 1.0 - ((lo - (x * c) / (2.0 - c)) - hi);
  if (k > 1023) return y * 2.0 * pow2(1023);  // y < 1 here: finite up to kExpOverflow
  if (k >= -1021) return y * pow2(k);         // exact
  return y * pow2(k + 1000) * pow2(-1000);    // a subnormal result: one rounding, the last
}

double log(double x) {
  std::uint64_t u = bits(x);
  std::uint32_t hx = static_cast<std::uint32_t>(u >> 32);
  int k = 0;
  if (hx < 0x00100000u || (hx >> 31)) {
    if ((u << 1) == 0) return -HUGE_VAL;                            // +-0
    if (hx >> 31) return std::numeric_limits<double>::quiet_NaN();  // below 0 (or -NaN)
    k -= 54;                                                        // subnormal: scale up
    x *= 18014398509481984.0;                                       // 2^54
    u = bits(x);
    hx = static_cast<std::uint32_t>(u >> 32);
  } else if (hx >= 0x7ff00000u) {
    return x + x;  // +inf, NaN
  } else if (hx == 0x3ff00000u && (u << 32) == 0) {
    return 0.0;
  }
  // x = 2^k m, m in [sqrt(2)/2, sqrt(2)); f = m - 1
  hx += 0x3ff00000u - 0x3fe6a09eu;
  k += static_cast<int>(hx >> 20) - 0x3ff;
  hx = (hx & 0x000fffffu) + 0x3fe6a09eu;
  u = (static_cast<std::uint64_t>(hx) << 32) | (u & 0xffffffffu);
  const double f = fromBits(u) - 1.0;
  // log(1 + f) = f - f^2/2 + s (f^2/2 + R(s^2)), s = f / (2 + f)
  const double hfsq = 0.5 * f * f, s = f / (2.0 + f), z = s * s, w = z * z;
  const double t1 = w * (Lg2 + w * (Lg4 + w * Lg6));
  const double t2 = z * (Lg1 + w * (Lg3 + w * (Lg5 + w * Lg7)));
  const double R = t2 + t1, dk = k;
  return s * (hfsq + R) + dk * kLn2Lo - hfsq + f + dk * kLn2Hi;
}

}  // namespace exid::fmath
