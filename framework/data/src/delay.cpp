// exid — a measurement channel delayed against the positions (exid/delay.hpp).
#include "exid/delay.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "exid/error.hpp"

namespace exid {

namespace {

// The five-point Lagrange derivative at x[2] of nodes x[0..4]: weights a[0..4].
void slopeWeights(const double* x, double* a) {
  a[2] = 0.0;
  for (int m = 0; m < 5; ++m)
    if (m != 2) a[2] += 1.0 / (x[2] - x[m]);
  for (int j = 0; j < 5; ++j) {
    if (j == 2) continue;
    double num = 1.0, den = 1.0;
    for (int m = 0; m < 5; ++m) {
      if (m != j) den *= x[j] - x[m];
      if (m != j && m != 2) num *= x[2] - x[m];
    }
    a[j] = num / den;
  }
}

// Weights over samples i - 2 .. i + 3 giving the interpolant (w) and its derivative in time
// (dw) at tau in [t_i, t_{i+1}].
void hermiteWeights(const Eigen::VectorXd& t, int i, double tau, double* w, double* dw) {
  double a[5], b[5];
  slopeWeights(t.data() + i - 2, a);  // slope at t_i
  slopeWeights(t.data() + i - 1, b);  // slope at t_{i+1}
  const double h = t[i + 1] - t[i], s = (tau - t[i]) / h;
  const double s2 = s * s, s3 = s2 * s;
  const double h00 = 2 * s3 - 3 * s2 + 1, h10 = s3 - 2 * s2 + s, h01 = -2 * s3 + 3 * s2,
               h11 = s3 - s2;
  const double g00 = (6 * s2 - 6 * s) / h, g10 = 3 * s2 - 4 * s + 1, g01 = (6 * s - 6 * s2) / h,
               g11 = 3 * s2 - 2 * s;
  for (int m = 0; m < 6; ++m) w[m] = dw[m] = 0.0;
  w[2] += h00;
  w[3] += h01;
  dw[2] += g00;
  dw[3] += g01;
  for (int m = 0; m < 5; ++m) {
    w[m] += h * h10 * a[m];
    w[m + 1] += h * h11 * b[m];
    dw[m] += g10 * a[m];
    dw[m + 1] += g11 * b[m];
  }
}

}  // namespace

void shiftedRange(const Eigen::VectorXd& t, double shift_s, int* first, int* last) {
  const int K = static_cast<int>(t.size());
  *first = *last = 0;
  if (K < 6 || !std::isfinite(shift_s)) return;
  const double lo = t[2], hi = t[K - 3];
  int a = 0;
  while (a < K && t[a] + shift_s < lo) ++a;
  int b = K;
  while (b > a && t[b - 1] + shift_s > hi) --b;
  *first = a;
  *last = std::max(a, b);
}

void shiftedRows(const Eigen::VectorXd& t, const Eigen::MatrixXd& X, int per_sample, double shift_s,
                 int first, int last, Eigen::MatrixXd* out, Eigen::MatrixXd* d_out) {
  const int K = static_cast<int>(t.size());
  const Eigen::Index P = per_sample, n = X.cols();
  // (messages formatted only on failure: a simulation reads its input here at every step)
  if (!(per_sample >= 1 && X.rows() == K * P && K >= 6))
    throw Error(
        fmt::format("shiftedRows: {} samples of {} rows each and {} rows (at least 6 samples)", K,
                    per_sample, X.rows()));
  if (!(0 <= first && first <= last && last <= K))
    throw Error(fmt::format("shiftedRows: samples [{}, {}) outside {}", first, last, K));
  out->setZero((last - first) * P, n);
  if (d_out) d_out->setZero((last - first) * P, n);
  int i = 2;  // interval [t_i, t_{i+1}], 2 <= i <= K - 4
  double w[6], dw[6];
  for (int k = first; k < last; ++k) {
    const double at = t[k] + shift_s;
    if (!(at >= t[2] && at <= t[K - 3]))
      throw Error(
          fmt::format("shiftedRows: t = {} s shifted by {} s lies outside the "
                      "interpolable samples [{}, {}] s",
                      t[k], shift_s, t[2], t[K - 3]));
    // the interval holding `at` (the targets increase with k: move forward, rarely back)
    while (i > 2 && at < t[i]) --i;
    while (i < K - 4 && at > t[i + 1]) ++i;
    hermiteWeights(t, i, at, w, dw);
    for (int m = 0; m < 6; ++m) {
      const Eigen::Index src = static_cast<Eigen::Index>(i - 2 + m) * P,
                         dst = static_cast<Eigen::Index>(k - first) * P;
      out->middleRows(dst, P) += w[m] * X.middleRows(src, P);
      if (d_out) d_out->middleRows(dst, P) += dw[m] * X.middleRows(src, P);
    }
  }
}

Dataset compensateDelay(const Dataset& d, double delay_s, const std::string& who,
                        int* dropped_front, int* dropped_back) {
  check(!d.streamed(), who + ": compensating a measurement delay needs the samples in memory");
  check(std::isfinite(delay_s),
        fmt::format("{}: the measurement delay {} s is not finite", who, delay_s));
  const int K = d.size();
  int a = 0, b = 0;
  shiftedRange(d.t, -delay_s, &a, &b);
  check(b - a >= 4,
        fmt::format("{}: a measurement delay of {} s leaves {} of {} samples (the positions "
                    "must be known at t - delay, between the third and the third-to-last "
                    "sample)",
                    who, delay_s, b - a, K));
  Dataset out = sliceDataset(d, a, b);
  for (auto [src, dst] : {std::pair{&d.q, &out.q}, {&d.qd, &out.qd}, {&d.qdd, &out.qdd}})
    if (src->cols() > 0 && src->rows() == K)
      shiftedRows(d.t, *src, 1, -delay_s, a, b, dst, nullptr);
  *dropped_front = a;
  *dropped_back = K - b;
  return out;
}

Rows delayedRows(const Rows& rows, const Eigen::VectorXd& t, double delay_s, const std::string& who,
                 int* dropped_front, int* dropped_back) {
  const auto K = static_cast<int>(t.size());
  const Eigen::Index R = rows.y.size();
  check(K > 0 && R % K == 0 && rows.W.rows() == R,
        fmt::format("{}: {} rows for {} samples: compensating a delay needs the same number of "
                    "rows per sample (a per-sample model)",
                    who, R, K));
  const int P = static_cast<int>(R / K);
  int a = 0, b = 0;
  shiftedRange(t, -delay_s, &a, &b);
  check(b - a >= 1,
        fmt::format("{}: a measurement delay of {} s leaves no sample of {}", who, delay_s, K));
  Rows out;
  shiftedRows(t, rows.W, P, -delay_s, a, b, &out.W, nullptr);
  out.y = rows.y.segment(static_cast<Eigen::Index>(a) * P, static_cast<Eigen::Index>(b - a) * P);
  auto part = [&](const auto& v) {
    using V = std::decay_t<decltype(v)>;
    if (v.size() != static_cast<std::size_t>(R)) return V(v);
    return V(v.begin() + static_cast<std::ptrdiff_t>(a) * P,
             v.begin() + static_cast<std::ptrdiff_t>(b) * P);
  };
  out.equation = part(rows.equation);
  out.t = part(rows.t);
  out.numEquations = rows.numEquations;
  out.equation_names = rows.equation_names;
  *dropped_front = a;
  *dropped_back = K - b;
  return out;
}

}  // namespace exid
