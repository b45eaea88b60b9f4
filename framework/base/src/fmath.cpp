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

constexpr double S1 = -1.66666666666666324348e-01, S2 = 8.33333333332248946124e-03,
                 S3 = -1.98412698298579493134e-04, S4 = 2.75573137070700676789e-06,
                 S5 = -2.50507602534068634195e-08, S6 = 1.58969099521155010221e-10;
constexpr double C1 = 4.16666666666666019037e-02, C2 = -1.38888888888741095749e-03,
                 C3 = 2.48015872894767294178e-05, C4 = -2.75573143513906633035e-07,
                 C5 = 2.08757232129817482790e-09, C6 = -1.13596475577881948265e-11;

// sin(x + y) for |x + y| <= pi/4, y the tail of the reduced argument (0 if iy == 0)
inline double kernelSin(double x, double y, bool iy) {
  const double z = x * x, w = z * z;
  const double r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6);
  const double v = z * x;
  if (!iy) return x + v * (S1 + z * r);
  return x - ((z * (0.5 * y - v * r) - y) - v * S1);
}

// cos(x + y) for |x + y| <= pi/4
inline double kernelCos(double x, double y) {
  const double z = x * x, w = z * z;
  const double r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6));
  const double hz = 0.5 * z, one_hz = 1.0 - hz;
  return one_hz + (((1.0 - one_hz) - hz) + (z * r - x * y));
}

// pi/2 in pieces: pio2_1 has 33 significant bits, so n * pio2_1 is exact for |n| < 2^20; each
// tail pio2_kt is pi/2 - (pio2_1 + ... + pio2_k) rounded.
constexpr double kInvPio2 = 6.36619772367581382433e-01;  // 2/pi
constexpr double kPio2_1 = 1.57079632673412561417e+00, kPio2_1t = 6.07710050650619224932e-11,
                 kPio2_2 = 6.07710050630396597660e-11, kPio2_2t = 2.02226624879595063154e-21,
                 kPio2_3 = 2.02226624871116645580e-21, kPio2_3t = 8.47842766036889956997e-32;
constexpr double kToInt = 1.5 / 2.220446049250313080847e-16;  // 1.5 * 2^52: rounds to an integer

// x = n pi/2 + y[0] + y[1] for pi/4 < |x| < 2^20 pi/2 (fdlibm's medium case: one, two or three
// pieces of pi/2 as the cancellation requires); returns n.
int remPio2(double x, double y[2]) {
  const double fn = (x * kInvPio2 + kToInt) - kToInt;
  const int n = static_cast<int>(fn);
  double r = x - fn * kPio2_1;
  double w = fn * kPio2_1t;  // first round: good to 85 bits
  y[0] = r - w;
  const int ex = static_cast<int>((highWord(x) >> 20) & 0x7ff);
  int ey = static_cast<int>((highWord(y[0]) >> 20) & 0x7ff);
  if (ex - ey > 16) {  // second round: good to 118 bits
    double t = r;
    w = fn * kPio2_2;
    r = t - w;
    w = fn * kPio2_2t - ((t - r) - w);
    y[0] = r - w;
    ey = static_cast<int>((highWord(y[0]) >> 20) & 0x7ff);
    if (ex - ey > 49) {  // third round: 151 bits, enough for every double below 2^20 pi/2
      t = r;
      w = fn * kPio2_3;
      r = t - w;
      w = fn * kPio2_3t - ((t - r) - w);
      y[0] = r - w;
    }
  }
  y[1] = (r - y[0]) - w;
  return n;
}

constexpr std::uint32_t kPio4High = 0x3fe921fb;    // |x| <= pi/4 (high word)
constexpr std::uint32_t kTinyHigh = 0x3e46a09e;    // |x| < 2^-27 * sqrt(2): sin x = x, cos x = 1
constexpr std::uint32_t kMediumHigh = 0x413921fb;  // |x| < 2^20 pi/2

}  // namespace

void sincos(double x, double* s, double* c) {
  const std::uint32_t ix = highWord(x) & 0x7fffffffu;
  if (ix <= kPio4High) {
    if (ix < kTinyHigh) {
      *s = x;
      *c = 1.0;
      return;
    }
    *s = kernelSin(x, 0.0, false);
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
  const double ks = kernelSin(y[0], y[1], true), kc = kernelCos(y[0], y[1]);
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
  if (ix <= kPio4High) return ix < kTinyHigh ? x : kernelSin(x, 0.0, false);
  if (ix >= 0x7ff00000u) return x - x;
  if (ix >= kMediumHigh) return std::sin(x);
  double y[2];
  const int n = remPio2(x, y);
  switch (n & 3) {
    case 0:
      return kernelSin(y[0], y[1], true);
    case 1:
      return kernelCos(y[0], y[1]);
    case 2:
      return -kernelSin(y[0], y[1], true);
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
      return -kernelSin(y[0], y[1], true);
    case 2:
      return -kernelCos(y[0], y[1]);
    default:
      return kernelSin(y[0], y[1], true);
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
