// exid — the pieces of exid's sine and cosine (exid/fmath.hpp), written once for a scalar double
// and for a GCC vector of doubles, so that several arguments computed in one vector register get
// the bits that exid::fmath::sincos gives each alone (kernels_lanes.hpp uses it; fmath.cpp is the
// scalar function).
//
// The algorithms and their minimax coefficients are those of fdlibm (k_sin.c, k_cos.c,
// e_rem_pio2.c):
//   Copyright (C) 1993 by Sun Microsystems, Inc. All rights reserved.
//   Developed at SunPro, a Sun Microsystems, Inc. business.
//   Permission to use, copy, modify, and distribute this software is freely granted, provided
//   that this notice is preserved.
//
// Every source that computes with these kernels compiles with -ffp-contract=off (no fused
// multiply-add may round a step differently). Not installed: internal to the build.
#pragma once

#include <cstdint>
#include <cstring>

// (vectors passed by value between inline functions: no ABI crosses here)
#if defined(__clang__)
#pragma clang diagnostic push
#pragma clang diagnostic ignored "-Wpsabi"
#elif defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"
#endif

namespace exid::fmath::kernels {

constexpr double S1 = -1.66666666666666324348e-01, S2 = 8.33333333332248946124e-03,
                 S3 = -1.98412698298579493134e-04, S4 = 2.75573137070700676789e-06,
                 S5 = -2.50507602534068634195e-08, S6 = 1.58969099521155010221e-10;
constexpr double C1 = 4.16666666666666019037e-02, C2 = -1.38888888888741095749e-03,
                 C3 = 2.48015872894767294178e-05, C4 = -2.75573143513906633035e-07,
                 C5 = 2.08757232129817482790e-09, C6 = -1.13596475577881948265e-11;

// sin x for |x| <= pi/4 (no tail)
template <class T>
inline T kernelSin(T x) {
  const T z = x * x, w = z * z;
  const T r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6);
  const T v = z * x;
  return x + v * (S1 + z * r);
}

// sin(x + y) for |x + y| <= pi/4, y the tail of the reduced argument
template <class T>
inline T kernelSin(T x, T y) {
  const T z = x * x, w = z * z;
  const T r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6);
  const T v = z * x;
  return x - ((z * (0.5 * y - v * r) - y) - v * S1);
}

// cos(x + y) for |x + y| <= pi/4
template <class T>
inline T kernelCos(T x, T y) {
  const T z = x * x, w = z * z;
  const T r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6));
  const T hz = 0.5 * z, one_hz = 1.0 - hz;
  return one_hz + (((1.0 - one_hz) - hz) + (z * r - x * y));
}

// The +, - and * of kernelSin(x) and kernelCos(x, 0) together (16 + 23): a sine and cosine of
// |x| <= pi/4, the fewest operations sincos takes for any argument but the tiny ones (beyond
// pi/4 the reduction and both kernels with a tail take more). The benchmarks' flop count adds it
// per joint angle (exid::kernelFlops); tests/unit/base/fmath_test.cpp counts it on the kernels.
constexpr int kSincosSmallFlops = 39;

// pi/2 in pieces: pio2_1 has 33 significant bits, so n * pio2_1 is exact for |n| < 2^20; each
// tail pio2_kt is pi/2 - (pio2_1 + ... + pio2_k) rounded.
constexpr double kInvPio2 = 6.36619772367581382433e-01;  // 2/pi
constexpr double kPio2_1 = 1.57079632673412561417e+00, kPio2_1t = 6.07710050650619224932e-11,
                 kPio2_2 = 6.07710050630396597660e-11, kPio2_2t = 2.02226624879595063154e-21,
                 kPio2_3 = 2.02226624871116645580e-21, kPio2_3t = 8.47842766036889956997e-32;
constexpr double kToInt = 1.5 / 2.220446049250313080847e-16;  // 1.5 * 2^52: rounds to an integer

// x = n pi/2 + y[0] + y[1] for pi/4 < |x| < 2^20 pi/2 (fdlibm's medium case: one, two or three
// pieces of pi/2 as the cancellation requires); returns n.
inline int remPio2(double x, double y[2]) {
  const double fn = (x * kInvPio2 + kToInt) - kToInt;
  const int n = static_cast<int>(fn);
  double r = x - fn * kPio2_1;
  double w = fn * kPio2_1t;  // first round: good to 85 bits
  y[0] = r - w;
  std::uint64_t bx, by;
  std::memcpy(&bx, &x, sizeof bx);
  std::memcpy(&by, &y[0], sizeof by);
  const int ex = static_cast<int>((bx >> 52) & 0x7ff);
  int ey = static_cast<int>((by >> 52) & 0x7ff);
  if (ex - ey > 16) {  // second round: good to 118 bits
    double t = r;
    w = fn * kPio2_2;
    r = t - w;
    w = fn * kPio2_2t - ((t - r) - w);
    y[0] = r - w;
    std::memcpy(&by, &y[0], sizeof by);
    ey = static_cast<int>((by >> 52) & 0x7ff);
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

// high words (bits 63..32 without the sign) that bound the cases
constexpr std::uint32_t kPio4High = 0x3fe921fb;    // |x| <= pi/4
constexpr std::uint32_t kTinyHigh = 0x3e46a09e;    // |x| < 2^-27 * sqrt(2): sin x = x, cos x = 1
constexpr std::uint32_t kMediumHigh = 0x413921fb;  // |x| < 2^20 pi/2

// the bits of a vector as another vector type of the same size
template <class To, class From>
inline To bitCast(const From& x) {
  static_assert(sizeof(To) == sizeof(From), "same size");
  To y;
  std::memcpy(&y, &x, sizeof y);
  return y;
}

// |x| below these is the case's bound on the high word (sincos compares the high word; the same
// sets, as comparisons of |x| that a vector unit makes in its floating-point registers)
constexpr double kPio4Bound = 0x1.921fcp-1;     // bits 0x3fe921fc00000000
constexpr double kTinyBound = 0x1.6a09ep-27;    // bits 0x3e46a09e00000000
constexpr double kMediumBound = 0x1.921fbp+20;  // bits 0x413921fb00000000

// |x| of each lane (the sign bit cleared; T a GCC vector of doubles)
template <class T, class I>
inline T absLanes(const T& x) {
  return bitCast<T>(bitCast<I>(x) & static_cast<long long>(0x7fffffffffffffffLL));
}

// whether any lane of a comparison's mask is set
template <class I, int W>
inline bool anyLane(const I& m) {
  bool any = false;
  for (int l = 0; l < W; ++l) any |= m[l] != 0;
  return any;
}

// remPio2 of every lane: n (as the double fn), y0 and y1 with remPio2's bits, for lanes with
// pi/4 < |x| < 2^20 pi/2. A round is computed for the vector when one of its lanes needs it.
// remPio2's exponent test ex - ey > 16 (ex, ey the biased exponents of x and y0) is made as
// |y0| < 2^(ex - 1023 - 16): the power of two of |x| (its exponent bits) scaled exactly.
template <class T, class I, int W>
inline void remPio2Vector(const T& x, T& fn, T& y0, T& y1) {
  fn = (x * kInvPio2 + kToInt) - kToInt;
  T r = x - fn * kPio2_1;
  T w = fn * kPio2_1t;
  y0 = r - w;
  const T px = bitCast<T>(bitCast<I>(x) & static_cast<long long>(0x7ff0000000000000LL));
  const I round2 = absLanes<T, I>(y0) < px * 0x1p-16;
  if (anyLane<I, W>(round2)) {
    T t = r;
    T w2 = fn * kPio2_2;
    const T r2 = t - w2;
    w2 = fn * kPio2_2t - ((t - r2) - w2);
    const T y02 = r2 - w2;
    const I round3 = round2 & (absLanes<T, I>(y02) < px * 0x1p-49);
    r = round2 ? r2 : r;
    w = round2 ? w2 : w;
    y0 = round2 ? y02 : y0;
    if (anyLane<I, W>(round3)) {
      t = r2;
      T w3 = fn * kPio2_3;
      const T r3 = t - w3;
      w3 = fn * kPio2_3t - ((t - r3) - w3);
      const T y03 = r3 - w3;
      r = round3 ? r3 : r;
      w = round3 ? w3 : w;
      y0 = round3 ? y03 : y0;
    }
  }
  y1 = (r - y0) - w;
}

// sin and cos of every lane of x (T a GCC vector of W doubles, I the vector of as many signed
// 64-bit integers, the type of T's comparisons) for lanes with |x| < 2^20 pi/2 (the caller sends
// the others, inf and NaN among them, to the scalar function: anyBeyondMedium). Each lane takes
// the sequence of operations that fmath.cpp's sincos takes for its value (the small case, or the
// reduction with one, two or three rounds), on the same operands, so it gets the same bits; a
// sequence is computed for the whole vector when one of its lanes needs it, and each lane keeps
// its own. The case tests are comparisons of |x| and of exponents made in floating point (the
// same sets as sincos's high-word tests): no 64-bit integer comparison, which the baseline's SSE2
// and AVX without AVX2 lack.
template <class T, class I, int W>
inline void sincosVector(const T& x, T& s, T& c) {
  const T ax = absLanes<T, I>(x);
  const I small = ax < kPio4Bound;
  const bool any_small = anyLane<I, W>(small);
  T s_small{}, c_small{};
  if (any_small) {  // |x| <= pi/4: no reduction
    const I tiny = ax < kTinyBound;
    s_small = kernelSin(x);
    c_small = kernelCos(x, T{});  // y = 0, as sincos passes
    s_small = tiny ? x : s_small;
    c_small = tiny ? T{} + 1.0 : c_small;
    if (!anyLane<I, W>(~small)) {
      s = s_small;
      c = c_small;
      return;
    }
  }
  // pi/4 < |x| < 2^20 pi/2: x = n pi/2 + y0 + y1
  T fn, y0, y1;
  remPio2Vector<T, I, W>(x, fn, y0, y1);
  const T ks = kernelSin(y0, y1), kc = kernelCos(y0, y1);
  // n mod 4 from d = n - 4 round(n / 4), in {-2, -1, 0, 1, 2} (every step exact):
  // 0 (sin, cos), 1 (cos, -sin), 2 (-sin, -cos), 3 = -1 (-cos, sin)
  const T d = fn - 4.0 * ((fn * 0.25 + kToInt) - kToInt);
  const I odd = (d == 1.0) | (d == -1.0), two = (d == 2.0) | (d == -2.0);
  const I neg_s = two | (d == -1.0), neg_c = two | (d == 1.0);
  T s_med = odd ? kc : ks, c_med = odd ? ks : kc;
  s_med = neg_s ? -s_med : s_med;
  c_med = neg_c ? -c_med : c_med;
  s = any_small ? (small ? s_small : s_med) : s_med;
  c = any_small ? (small ? c_small : c_med) : c_med;
}

// whether any lane of x needs the scalar function (|x| >= 2^20 pi/2, inf, NaN)
template <class T, class I, int W>
inline bool anyBeyondMedium(const T& x) {
  const T ax = absLanes<T, I>(x);
  return anyLane<I, W>(~(ax < kMediumBound));  // NaN compares false
}

}  // namespace exid::fmath::kernels

#if defined(__clang__)
#pragma clang diagnostic pop
#elif defined(__GNUC__)
#pragma GCC diagnostic pop
#endif
