// exid::fmath (sin, cos, sincos, exp, log): against the x87 long-double libm (64-bit significands,
// an independent computation 11 bits finer than the result) over millions of arguments: within
// one unit in the last place of the double result everywhere, and within one of glibc's double
// functions; the special values as C99 Annex F says.
#include "exid/fmath.hpp"

#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "exid/fmath_kernels.hpp"  // the vector lanes (internal)

namespace {

// the spacing of doubles at |ref| (a subnormal's spacing below DBL_MIN)
double ulpAt(long double ref) {
  const double r = std::fabs(static_cast<double>(ref));
  if (r < DBL_MIN) return std::ldexp(1.0, -1074);
  int e;
  std::frexp(r, &e);
  return std::ldexp(1.0, e - 53);
}

// the error of `got` in units of the last place of the exact value (approximated by `ref`)
double ulps(double got, long double ref) {
  return static_cast<double>(std::fabs(static_cast<long double>(got) - ref) / ulpAt(ref));
}

struct Worst {
  double ulps = 0, arg = 0;
  void take(double u, double x) {
    if (u > ulps) {
      ulps = u;
      arg = x;
    }
  }
};

std::vector<double> uniform(double lo, double hi, int n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(lo, hi);
  std::vector<double> v(static_cast<size_t>(n));
  for (double& x : v) x = U(rng);
  return v;
}

// arguments a few ulps around n pi/2: where the reduction cancels most
std::vector<double> nearMultiplesOfHalfPi(int count) {
  std::vector<double> v;
  const long double pio2 = 1.570796326794896619231321691639751442L;
  for (int n = -count; n <= count; ++n) {
    double x = static_cast<double>(n * pio2);
    for (int k = 0; k < 4; ++k) x = std::nextafter(x, -HUGE_VAL);
    for (int k = 0; k < 9; ++k, x = std::nextafter(x, HUGE_VAL)) v.push_back(x);
  }
  for (double scale : {1e3, 1e4, 1e5, 1e6}) {  // large multiples
    for (int n = 1; n < 2000; ++n) {
      double x = static_cast<double>(std::nearbyint(scale / pio2 + n) * pio2);
      v.push_back(x);
      v.push_back(std::nextafter(x, HUGE_VAL));
      v.push_back(-std::nextafter(x, -HUGE_VAL));
    }
  }
  return v;
}

void checkSinCos(const std::vector<double>& xs, const char* what) {
  Worst ws, wc, wls, wlc;
  for (double x : xs) {
    const long double rs = std::sin(static_cast<long double>(x));
    const long double rc = std::cos(static_cast<long double>(x));
    const double s = exid::fmath::sin(x), c = exid::fmath::cos(x);
    double s2, c2;
    exid::fmath::sincos(x, &s2, &c2);
    ASSERT_EQ(std::memcmp(&s, &s2, sizeof s), 0) << "sincos's sine differs from sin at " << x;
    ASSERT_EQ(std::memcmp(&c, &c2, sizeof c), 0) << "sincos's cosine differs from cos at " << x;
    ws.take(ulps(s, rs), x);
    wc.take(ulps(c, rc), x);
    wls.take(std::fabs(s - std::sin(x)) / ulpAt(rs), x);
    wlc.take(std::fabs(c - std::cos(x)) / ulpAt(rc), x);
  }
  EXPECT_LT(ws.ulps, 1.0) << what << ": sin, worst at " << ws.arg;
  EXPECT_LT(wc.ulps, 1.0) << what << ": cos, worst at " << wc.arg;
  EXPECT_LE(wls.ulps, 1.0) << what << ": sin against glibc, worst at " << wls.arg;
  EXPECT_LE(wlc.ulps, 1.0) << what << ": cos against glibc, worst at " << wlc.arg;
}

TEST(Fmath, SinCosWithinOneUlp) {
  checkSinCos(uniform(-M_PI / 4, M_PI / 4, 400000, 1), "|x| <= pi/4");
  checkSinCos(uniform(-20.0, 20.0, 800000, 2), "|x| <= 20");
  checkSinCos(uniform(-2000.0, 2000.0, 400000, 3), "|x| <= 2000");
  checkSinCos(uniform(-1.6e6, 1.6e6, 400000, 4), "|x| <= 1.6e6");
  checkSinCos(uniform(-1e-6, 1e-6, 100000, 5), "|x| <= 1e-6");
  checkSinCos(nearMultiplesOfHalfPi(5000), "near n pi/2");
  // beyond the exact reduction: libm's own value
  for (double x : uniform(1.7e6, 1e300, 1000, 6)) {
    EXPECT_EQ(exid::fmath::sin(x), std::sin(x)) << x;
    EXPECT_EQ(exid::fmath::cos(x), std::cos(x)) << x;
  }
}

TEST(Fmath, SinCosSpecialValues) {
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(std::signbit(exid::fmath::sin(-0.0)), true);
  EXPECT_EQ(exid::fmath::sin(0.0), 0.0);
  EXPECT_EQ(exid::fmath::cos(-0.0), 1.0);
  EXPECT_EQ(exid::fmath::sin(1e-300), 1e-300);
  EXPECT_EQ(exid::fmath::sin(4.9e-324), 4.9e-324);
  for (double x : {inf, -inf, std::numeric_limits<double>::quiet_NaN()}) {
    EXPECT_TRUE(std::isnan(exid::fmath::sin(x))) << x;
    EXPECT_TRUE(std::isnan(exid::fmath::cos(x))) << x;
    double s, c;
    exid::fmath::sincos(x, &s, &c);
    EXPECT_TRUE(std::isnan(s) && std::isnan(c)) << x;
  }
}

// the vector lanes' sine and cosine (exid/fmath_kernels.hpp, which the torque regressors of
// several samples use) give each lane the bits of the scalar sincos, in every case sincos
// distinguishes: tiny, |x| <= pi/4 and either side of it, reductions with one, two and three
// rounds, and the bound beyond which the caller must use the scalar function (which
// anyBeyondMedium reports, and only then)
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wpsabi"  // 4-double vectors passed within this file
#endif
typedef double Lane2 __attribute__((vector_size(16)));
typedef long long LaneInt2 __attribute__((vector_size(16)));
typedef double Lane4 __attribute__((vector_size(32)));
typedef long long LaneInt4 __attribute__((vector_size(32)));

template <class T, class I, int W>
void checkLanes(const std::vector<double>& xs, const char* what, std::size_t* compared,
                std::size_t* refused) {
  namespace K = exid::fmath::kernels;
  for (std::size_t i = 0; i + W <= xs.size(); i += W) {
    T x;
    bool beyond = false;
    for (int l = 0; l < W; ++l) {
      x[l] = xs[i + static_cast<std::size_t>(l)];
      beyond |= !(std::fabs(x[l]) < 0x1.921fbp+20);  // sincos's own bound: high word 0x413921fb
    }
    ASSERT_EQ((K::anyBeyondMedium<T, I, W>(x)), beyond) << what << " at " << x[0];
    if (beyond) {
      ++*refused;
      continue;
    }
    T s, c;
    K::sincosVector<T, I, W>(x, s, c);
    for (int l = 0; l < W; ++l) {
      double s1, c1;
      exid::fmath::sincos(x[l], &s1, &c1);
      const double sl = s[l], cl = c[l];
      ASSERT_EQ(std::memcmp(&sl, &s1, sizeof s1), 0)
          << what << ": sine of lane " << l << " at " << x[l] << ": " << sl << " vs " << s1;
      ASSERT_EQ(std::memcmp(&cl, &c1, sizeof c1), 0)
          << what << ": cosine of lane " << l << " at " << x[l] << ": " << cl << " vs " << c1;
      ++*compared;
    }
  }
}

// the reduction x = n pi/2 + y0 + y1 of each lane is remPio2's, bit for bit, on both sides of
// the exponent tests that choose its second and third rounds (|y0| near 2^-16 and 2^-49 of |x|)
template <class T, class I, int W>
void checkReduction(const std::vector<double>& xs, int* rounds) {
  namespace K = exid::fmath::kernels;
  for (std::size_t i = 0; i + W <= xs.size(); i += W) {
    T x, fn, y0, y1;
    for (int l = 0; l < W; ++l) x[l] = xs[i + static_cast<std::size_t>(l)];
    K::remPio2Vector<T, I, W>(x, fn, y0, y1);
    for (int l = 0; l < W; ++l) {
      double y[2];
      const int n = K::remPio2(x[l], y);
      const double a0 = y0[l], a1 = y1[l];
      ASSERT_EQ(static_cast<double>(n), fn[l]) << x[l];
      ASSERT_EQ(std::memcmp(&a0, &y[0], sizeof a0), 0) << "y0 at " << x[l];
      ASSERT_EQ(std::memcmp(&a1, &y[1], sizeof a1), 0) << "y1 at " << x[l];
      const int ex = std::ilogb(x[l]), ey = y[0] == 0 ? -1100 : std::ilogb(y[0]);
      ++rounds[ex - ey > 49 ? 2 : ex - ey > 16 ? 1 : 0];
    }
  }
}

TEST(Fmath, VectorReductionIsTheScalarOne) {
  const long double pio2 = 1.570796326794896619231321691639751442L;
  std::vector<double> xs;
  for (int n = 1; n < 3000; n += 7)
    for (double e :
         {15.5, 16.0, 16.25, 16.5, 16.75, 17.0, 17.5, 48.5, 49.0, 49.25, 49.5, 49.75, 50.0, 50.5})
      for (double sign : {1.0, -1.0}) {
        const double x = static_cast<double>(n * pio2 * (1.0L + sign * std::exp2(-e)));
        xs.push_back(x);
        xs.push_back(-std::nextafter(x, HUGE_VAL));
      }
  for (double x : nearMultiplesOfHalfPi(500)) xs.push_back(x);
  for (double x : uniform(-1.6e6, 1.6e6, 20000, 36)) xs.push_back(x);
  std::vector<double> medium;  // remPio2's domain: pi/4 < |x| < 2^20 pi/2
  for (double x : xs)
    if (std::fabs(x) > M_PI / 4 && std::fabs(x) < 0x1.921fbp+20) medium.push_back(x);
  int rounds[3] = {0, 0, 0};
  checkReduction<Lane2, LaneInt2, 2>(medium, rounds);
  checkReduction<Lane4, LaneInt4, 4>(medium, rounds);
  // each number of rounds was taken, and beside the others in one vector
  EXPECT_GT(rounds[0], 1000);
  EXPECT_GT(rounds[1], 1000);
  EXPECT_GT(rounds[2], 1000);
}

TEST(Fmath, VectorLanesGiveTheScalarBits) {
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> edges = {0.0,
                               -0.0,
                               1e-300,
                               -4.9e-324,
                               0x1.6a09ep-27,
                               -0x1.6a09ep-27,
                               std::nextafter(0x1.6a09ep-27, 0.0),
                               1e-9,
                               0x1.921fcp-1,
                               -0x1.921fcp-1,
                               std::nextafter(0x1.921fcp-1, 0.0),
                               M_PI / 4,
                               -M_PI / 4,
                               1.0,
                               -2.5,
                               M_PI,
                               0x1.921fbp+20,
                               std::nextafter(0x1.921fbp+20, 0.0),
                               -0x1.921fbp+20,
                               1e7,
                               inf,
                               -inf,
                               std::numeric_limits<double>::quiet_NaN()};
  std::vector<std::vector<double>> sets = {edges,
                                           uniform(-M_PI / 4, M_PI / 4, 40000, 31),
                                           uniform(-4.0, 4.0, 100000, 32),
                                           uniform(-2000.0, 2000.0, 40000, 33),
                                           uniform(-1.6e6, 1.6e6, 40000, 34),
                                           uniform(-1e-6, 1e-6, 20000, 35),
                                           nearMultiplesOfHalfPi(3000)};
  // every case beside every other in one vector: each edge value in each lane with each other
  std::vector<double> mixed;
  for (double a : edges)
    for (double b : edges)
      for (double e : {a, b, 1.0, b, a, -3.0, a, b}) mixed.push_back(e);
  sets.push_back(mixed);
  std::size_t compared = 0, refused = 0;
  for (const auto& xs : sets) {
    checkLanes<Lane2, LaneInt2, 2>(xs, "2 lanes", &compared, &refused);
    checkLanes<Lane4, LaneInt4, 4>(xs, "4 lanes", &compared, &refused);
  }
  EXPECT_GT(compared, 500000u);
  EXPECT_GT(refused, 100u);  // the vectors holding 2^20 pi/2, 1e7, inf or NaN
}

// A number that counts the +, - and * made on it (the flop count of the kernels' templates)
struct Counted {
  double v = 0;
  static int& ops() {
    static int n = 0;
    return n;
  }
};
Counted operator+(Counted a, Counted b) { return ++Counted::ops(), Counted{a.v + b.v}; }
Counted operator-(Counted a, Counted b) { return ++Counted::ops(), Counted{a.v - b.v}; }
Counted operator*(Counted a, Counted b) { return ++Counted::ops(), Counted{a.v * b.v}; }
Counted operator+(double a, Counted b) { return Counted{a} + b; }
Counted operator-(double a, Counted b) { return Counted{a} - b; }
Counted operator*(double a, Counted b) { return Counted{a} * b; }
Counted operator*(Counted a, double b) { return a * Counted{b}; }

// kSincosSmallFlops, which the benchmarks' bound adds per joint angle, is the operations of the
// small case's two kernels (and their values are the scalar sin and cos's there)
TEST(Fmath, SmallCaseOperationCountIsTheKernelsOwn) {
  namespace k = exid::fmath::kernels;
  const double x = 0.7;
  Counted::ops() = 0;
  const Counted s = k::kernelSin(Counted{x});
  const int sin_ops = Counted::ops();
  const Counted c = k::kernelCos(Counted{x}, Counted{});
  EXPECT_EQ(sin_ops, 16);
  EXPECT_EQ(Counted::ops(), k::kSincosSmallFlops);
  double s1, c1;
  exid::fmath::sincos(x, &s1, &c1);
  EXPECT_EQ(s.v, s1);
  EXPECT_EQ(c.v, c1);
}

TEST(Fmath, ExpWithinOneUlp) {
  Worst w, wl;
  auto check = [&](const std::vector<double>& xs) {
    for (double x : xs) {
      const long double r = std::exp(static_cast<long double>(x));
      const double e = exid::fmath::exp(x);
      w.take(ulps(e, r), x);
      wl.take(std::fabs(e - std::exp(x)) / ulpAt(r), x);
    }
  };
  check(uniform(-1.0, 1.0, 400000, 11));
  check(uniform(-0.4, 0.4, 200000, 12));
  check(uniform(-50.0, 50.0, 400000, 13));
  check(uniform(-708.0, 709.78, 400000, 14));
  check(uniform(-1e-9, 1e-9, 100000, 15));
  EXPECT_LT(w.ulps, 1.0) << "worst at " << w.arg;
  EXPECT_LE(wl.ulps, 1.0) << "against glibc, worst at " << wl.arg;
  // subnormal results: one rounding, within one subnormal spacing
  Worst ws;
  for (double x : uniform(-745.0, -708.5, 100000, 16))
    ws.take(ulps(exid::fmath::exp(x), std::exp(static_cast<long double>(x))), x);
  EXPECT_LE(ws.ulps, 1.0) << "subnormal results, worst at " << ws.arg;
}

TEST(Fmath, ExpSpecialValues) {
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(exid::fmath::exp(0.0), 1.0);
  EXPECT_EQ(exid::fmath::exp(-0.0), 1.0);
  EXPECT_EQ(exid::fmath::exp(inf), inf);
  EXPECT_EQ(exid::fmath::exp(-inf), 0.0);
  EXPECT_EQ(exid::fmath::exp(710.0), inf);
  EXPECT_EQ(exid::fmath::exp(-746.0), 0.0);
  EXPECT_TRUE(std::isfinite(exid::fmath::exp(709.78)));
  EXPECT_TRUE(std::isnan(exid::fmath::exp(std::numeric_limits<double>::quiet_NaN())));
}

TEST(Fmath, LogWithinOneUlp) {
  Worst w, wl;
  auto check = [&](double x) {
    const long double r = std::log(static_cast<long double>(x));
    const double l = exid::fmath::log(x);
    w.take(ulps(l, r), x);
    wl.take(std::fabs(l - std::log(x)) / ulpAt(r), x);
  };
  for (double x : uniform(0.5, 2.0, 400000, 21)) check(x);
  for (double x : uniform(1.0 - 1e-6, 1.0 + 1e-6, 100000, 22)) check(x);
  for (double x : uniform(0.0, 1e6, 200000, 23)) check(x);
  // every exponent: random bit patterns of positive finite doubles, subnormals included
  std::mt19937_64 rng(24);
  for (int i = 0; i < 400000; ++i) {
    const std::uint64_t u = rng() & 0x7fefffffffffffffULL;
    double x;
    std::memcpy(&x, &u, sizeof x);
    if (x > 0) check(x);
  }
  EXPECT_LT(w.ulps, 1.0) << "worst at " << w.arg;
  EXPECT_LE(wl.ulps, 1.0) << "against glibc, worst at " << wl.arg;
}

TEST(Fmath, LogSpecialValues) {
  const double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(exid::fmath::log(1.0), 0.0);
  EXPECT_EQ(exid::fmath::log(0.0), -inf);
  EXPECT_EQ(exid::fmath::log(-0.0), -inf);
  EXPECT_EQ(exid::fmath::log(inf), inf);
  EXPECT_TRUE(std::isnan(exid::fmath::log(-1.0)));
  EXPECT_TRUE(std::isnan(exid::fmath::log(-inf)));
  EXPECT_TRUE(std::isnan(exid::fmath::log(std::numeric_limits<double>::quiet_NaN())));
  EXPECT_EQ(exid::fmath::log(2.0), 0.6931471805599453);
}

}  // namespace
