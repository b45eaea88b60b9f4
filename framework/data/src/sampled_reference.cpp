// exid — the quintic Hermite interpolant of sampled q, qd, qdd (exid/sampled_reference.hpp).
#include "exid/sampled_reference.hpp"

#include <algorithm>

namespace exid {

namespace {

// The interval [t_i, t_i+1] holding t (the first or last outside the samples), its length h
// and t's place x in it.
int interval(const Samples& s, double t, double* h, double* x) {
  const int K = s.size();
  const double* b = s.t.data();
  int i = static_cast<int>(std::upper_bound(b, b + K, t) - b) - 1;
  i = std::max(0, std::min(i, K - 2));
  *h = s.t[i + 1] - s.t[i];
  *x = (t - s.t[i]) / *h;
  return i;
}

// Joint j's polynomial on interval i in x = (t - t_i) / h: c[0] + c[1] x + ... + c[5] x^5.
void coefficients(const Samples& s, int i, int j, double h, double c[6]) {
  const double p0 = s.q(i, j), v0 = s.qd(i, j), a0 = s.qdd(i, j);
  const double p1 = s.q(i + 1, j), v1 = s.qd(i + 1, j), a1 = s.qdd(i + 1, j);
  const double P = p1 - p0 - v0 * h - 0.5 * a0 * h * h, V = (v1 - v0 - a0 * h) * h,
               A = (a1 - a0) * h * h;
  c[0] = p0;
  c[1] = v0 * h;
  c[2] = 0.5 * a0 * h * h;
  c[3] = 10 * P - 4 * V + 0.5 * A;
  c[4] = -15 * P + 7 * V - A;
  c[5] = 6 * P - 3 * V + 0.5 * A;
}

}  // namespace

void quinticHermite(const Samples& s, double t, Eigen::VectorXd* q, Eigen::VectorXd* qd,
                    Eigen::VectorXd* qdd) {
  const int K = s.size(), n = s.dof();
  if (K == 1) {
    *q = s.q.row(0).transpose();
    *qd = s.qd.row(0).transpose();
    *qdd = s.qdd.row(0).transpose();
    return;
  }
  double h = 0, x = 0;
  const int i = interval(s, t, &h, &x);
  q->resize(n);
  qd->resize(n);
  qdd->resize(n);
  for (int j = 0; j < n; ++j) {
    double c[6];
    coefficients(s, i, j, h, c);
    (*q)[j] = c[0] + x * (c[1] + x * (c[2] + x * (c[3] + x * (c[4] + x * c[5]))));
    (*qd)[j] = (c[1] + x * (2 * c[2] + x * (3 * c[3] + x * (4 * c[4] + x * 5 * c[5])))) / h;
    (*qdd)[j] = (2 * c[2] + x * (6 * c[3] + x * (12 * c[4] + x * 20 * c[5]))) / (h * h);
  }
}

Eigen::VectorXd quinticHermiteJerk(const Samples& s, double t) {
  const int K = s.size(), n = s.dof();
  Eigen::VectorXd j3 = Eigen::VectorXd::Zero(n);
  if (K == 1) return j3;
  double h = 0, x = 0;
  const int i = interval(s, t, &h, &x);
  for (int j = 0; j < n; ++j) {
    double c[6];
    coefficients(s, i, j, h, c);
    j3[j] = (6 * c[3] + x * (24 * c[4] + x * 60 * c[5])) / (h * h * h);
  }
  return j3;
}

}  // namespace exid
