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
