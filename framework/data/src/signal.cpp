// Butterworth design (bilinear transform), zero-phase filtering, central differences,
// parallel decimation.
#include "exid/signal.hpp"

#include <fmt/format.h>
#include <sys/mman.h>

#include <algorithm>
#include <cmath>
#include <map>

#include "exid/error.hpp"

namespace exid {

Sos butterworthLowpass(int order, double cutoff_hz, double fs_hz) {
  check(order >= 1 && order <= 20,
        fmt::format("Butterworth order must be in [1, 20], got {}", order));
  check(fs_hz > 0 && std::isfinite(fs_hz),
        fmt::format("sampling rate must be positive, got {} Hz", fs_hz));
  check(cutoff_hz > 0 && cutoff_hz < 0.5 * fs_hz,
        fmt::format("Butterworth cutoff must be in (0, fs/2) = (0, {:g}) Hz, got {:g} Hz",
                    0.5 * fs_hz, cutoff_hz));
  // Analog prototype poles p_k = exp(i pi (2k + N + 1) / (2N)) (left half plane, |p| = 1),
  // pre-warped cutoff 2 fs tan(pi fc / fs); the bilinear transform s = 2 fs (z - 1) / (z + 1)
  // maps them to z = (1 + K p) / (1 - K p), K = tan(pi fc / fs); the N zeros go to z = -1.
  const double K = std::tan(M_PI * cutoff_hz / fs_hz);
  Sos sos;
  sos.order = order;
  for (int k = 0; k < order / 2; ++k) {
    const std::complex<double> p = std::polar(1.0, M_PI * (2.0 * k + order + 1.0) / (2.0 * order));
    const std::complex<double> z = (1.0 + K * p) / (1.0 - K * p);
    const double a1 = -2.0 * z.real(), a2 = std::norm(z);
    const double g = (1.0 + a1 + a2) / 4.0;  // unit gain at DC (z = 1)
    sos.sections.push_back({g, 2.0 * g, g, 1.0, a1, a2});
  }
  if (order % 2 == 1) {
    const double z = (1.0 - K) / (1.0 + K);  // p = -1
    const double a1 = -z;
    const double g = (1.0 + a1) / 2.0;
    sos.sections.push_back({g, g, 0.0, 1.0, a1, 0.0});
  }
  return sos;
}

std::complex<double> sosResponse(const Sos& sos, double f_hz, double fs_hz) {
  const std::complex<double> zi = std::polar(1.0, -2.0 * M_PI * f_hz / fs_hz);  // z^-1
  std::complex<double> h = 1.0;
  for (const auto& s : sos.sections)
    h *= (s[0] + s[1] * zi + s[2] * zi * zi) / (s[3] + s[4] * zi + s[5] * zi * zi);
  return h;
}

std::vector<double> sosStepState(const Sos& sos) {
  std::vector<double> zi;
  double u = 1.0;  // input level of this section
  for (const auto& s : sos.sections) {
    const double g = (s[0] + s[1] + s[2]) / (1.0 + s[4] + s[5]);
    const double z1 = (s[2] - s[5] * g) * u;
    const double z0 = (s[1] - s[4] * g) * u + z1;
    zi.push_back(z0);
    zi.push_back(z1);
    u *= g;
  }
  return zi;
}

void sosFilter(const Sos& sos, Eigen::Ref<Eigen::VectorXd> x, std::vector<double>* zi) {
  check(zi->size() == 2 * sos.sections.size(), "sosFilter: state size");
  for (std::size_t k = 0; k < sos.sections.size(); ++k) {
    const auto& s = sos.sections[k];
    double z0 = (*zi)[2 * k], z1 = (*zi)[2 * k + 1];
    const double b0 = s[0], b1 = s[1], b2 = s[2], a1 = s[4], a2 = s[5];
    for (Eigen::Index i = 0; i < x.size(); ++i) {
      const double xi = x(i);
      const double yi = b0 * xi + z0;
      z0 = b1 * xi - a1 * yi + z1;
      z1 = b2 * xi - a2 * yi;
      x(i) = yi;
    }
    (*zi)[2 * k] = z0;
    (*zi)[2 * k + 1] = z1;
  }
}

Eigen::VectorXd filtfilt(const Sos& sos, const Eigen::Ref<const Eigen::VectorXd>& x) {
  const Eigen::Index n = x.size();
  check(n >= 2, fmt::format("filtfilt: needs at least 2 samples, got {}", n));
  // Pad long enough for the initial-condition transient to die out before the data start:
  // 10 time constants of the slowest pole (at least scipy's 3 (2 sections + 1)).
  double rmax = 0.0;
  for (const auto& s : sos.sections) {
    const double a1 = s[4], a2 = s[5], disc = a1 * a1 - 4.0 * a2;
    const double r = disc < 0 ? std::sqrt(a2) : 0.5 * (std::abs(a1) + std::sqrt(disc));
    rmax = std::max(rmax, r);
  }
  const double tau = rmax > 0 && rmax < 1 ? -1.0 / std::log(rmax) : 0.0;
  // In double: a tiny cut-off gives a time constant beyond any integer (the cast wrapped).
  const Eigen::Index padlen = static_cast<Eigen::Index>(std::min<double>(
      std::max<double>(3.0 * (2.0 * static_cast<double>(sos.sections.size()) + 1.0),
                       std::ceil(10.0 * tau)),
      static_cast<double>(n - 1)));
  Eigen::VectorXd ext(n + 2 * padlen);
  for (Eigen::Index i = 0; i < padlen; ++i) ext(i) = 2.0 * x(0) - x(padlen - i);
  ext.segment(padlen, n) = x;
  for (Eigen::Index i = 0; i < padlen; ++i) ext(padlen + n + i) = 2.0 * x(n - 1) - x(n - 2 - i);
  const std::vector<double> z = sosStepState(sos);
  std::vector<double> zi(z.size());
  for (std::size_t i = 0; i < z.size(); ++i) zi[i] = z[i] * ext(0);
  sosFilter(sos, ext, &zi);
  ext.reverseInPlace();
  for (std::size_t i = 0; i < z.size(); ++i) zi[i] = z[i] * ext(0);
  sosFilter(sos, ext, &zi);
  ext.reverseInPlace();
  return ext.segment(padlen, n);
}

namespace {

double slowestPoleRadius(const Sos& sos) {
  double rmax = 0.0;
  for (const auto& s : sos.sections) {
    const double a1 = s[4], a2 = s[5], disc = a1 * a1 - 4.0 * a2;
    const double r = disc < 0 ? std::sqrt(a2) : 0.5 * (std::abs(a1) + std::sqrt(disc));
    rmax = std::max(rmax, r);
  }
  return rmax;
}

// The state of the sections of one pass over rows of c columns (row-major), carried from one
// block of rows to the next, so that a signal held in several blocks (the pads and the data of
// filtfilt) is filtered as one sequence without being copied into one.
class SosRows {
 public:
  SosRows(const Sos& sos, Eigen::Index c) : sos_(sos), c_(c), z_(2 * sos.sections.size() * c) {}
  /// The steady state of a constant input equal to `row`.
  void start(const std::vector<double>& zstep, const double* row) {
    const auto c = static_cast<std::size_t>(c_);
    for (std::size_t k = 0; k < sos_.sections.size(); ++k)
      for (std::size_t j = 0; j < c; ++j) {
        z_[2 * k * c + j] = zstep[2 * k] * row[j];
        z_[(2 * k + 1) * c + j] = zstep[2 * k + 1] * row[j];
      }
  }
  /// Filters n rows in place: row i at first + i * step (step = +c forward, -c backward). Every
  /// section on one row before the next row (the state stays in the cache); per column exactly
  /// sosFilter's arithmetic.
  void run(double* first, Eigen::Index n, Eigen::Index step) {
    const auto c = static_cast<std::size_t>(c_);
    for (Eigen::Index i = 0; i < n; ++i) {
      double* x = first + i * step;
      for (std::size_t k = 0; k < sos_.sections.size(); ++k) {
        const auto& s = sos_.sections[k];
        const double b0 = s[0], b1 = s[1], b2 = s[2], a1 = s[4], a2 = s[5];
        double* z0 = z_.data() + 2 * k * c;
        double* z1 = z0 + c;
        for (std::size_t j = 0; j < c; ++j) {
          const double xi = x[j];
          const double yi = b0 * xi + z0[j];
          z0[j] = b1 * xi - a1 * yi + z1[j];
          z1[j] = b2 * xi - a2 * yi;
          x[j] = yi;
        }
      }
    }
  }

 private:
  const Sos& sos_;
  Eigen::Index c_;
  std::vector<double> z_;
};

}  // namespace

long settlingSamples(const Sos& sos, double tol) {
  const double r = slowestPoleRadius(sos);
  if (!(r > 0 && r < 1)) return 0;
  return static_cast<long>(std::ceil(std::log(tol) / std::log(r)));
}

LargeRows::LargeRows(Eigen::Index rows, Eigen::Index cols) : rows_(rows), cols_(cols) {
  constexpr std::size_t kHuge = 2u << 20;
  const std::size_t need = sizeof(double) * static_cast<std::size_t>(rows * cols);
  bytes_ = std::max<std::size_t>(kHuge, (need + kHuge - 1) / kHuge * kHuge);
  void* p = mmap(nullptr, bytes_, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED)
    throw Error(fmt::format("out of memory: {} x {} doubles ({:.0f} MB) could not be mapped", rows,
                            cols, static_cast<double>(need) / 1e6));
  madvise(p, bytes_, MADV_HUGEPAGE);  // advice only: without huge pages the block still works
  data_ = static_cast<double*>(p);
}

LargeRows::~LargeRows() {
  if (data_) munmap(data_, bytes_);
}

LargeRows::LargeRows(LargeRows&& o) noexcept
    : data_(o.data_), bytes_(o.bytes_), rows_(o.rows_), cols_(o.cols_) {
  o.data_ = nullptr;
  o.bytes_ = 0;
}

LargeRows& LargeRows::operator=(LargeRows&& o) noexcept {
  if (this != &o) {
    if (data_) munmap(data_, bytes_);
    data_ = o.data_;
    bytes_ = o.bytes_;
    rows_ = o.rows_;
    cols_ = o.cols_;
    o.data_ = nullptr;
    o.bytes_ = 0;
  }
  return *this;
}

void filtfiltRowsInPlace(const Sos& sos, RowMajorMatrix* X) {
  filtfiltRowsInPlace(sos, Eigen::Map<RowMajorMatrix>(X->data(), X->rows(), X->cols()));
}

void filtfiltRowsInPlace(const Sos& sos, Eigen::Map<RowMajorMatrix> X) {
  const Eigen::Index n = X.rows(), c = X.cols();
  check(n >= 2, fmt::format("filtfilt: needs at least 2 samples, got {}", n));
  const double rmax = slowestPoleRadius(sos);
  const double tau = rmax > 0 && rmax < 1 ? -1.0 / std::log(rmax) : 0.0;
  const Eigen::Index padlen = static_cast<Eigen::Index>(std::min<double>(
      std::max<double>(3.0 * (2.0 * static_cast<double>(sos.sections.size()) + 1.0),
                       std::ceil(10.0 * tau)),
      static_cast<double>(n - 1)));
  // The odd extensions at both ends, held apart: the signal is [pre, X, post], filtered forward
  // then backward in place (the same numbers as filtering one extended copy).
  RowMajorMatrix pre(padlen, c), post(padlen, c);
  for (Eigen::Index i = 0; i < padlen; ++i) pre.row(i) = 2.0 * X.row(0) - X.row(padlen - i);
  for (Eigen::Index i = 0; i < padlen; ++i) post.row(i) = 2.0 * X.row(n - 1) - X.row(n - 2 - i);
  const std::vector<double> z = sosStepState(sos);
  SosRows f(sos, c);
  f.start(z, padlen > 0 ? pre.data() : X.data());
  f.run(pre.data(), padlen, c);
  f.run(X.data(), n, c);
  f.run(post.data(), padlen, c);
  const Eigen::VectorXd last =  // the backward pass starts from the forward pass's last output
      padlen > 0 ? Eigen::VectorXd(post.row(padlen - 1).transpose())
                 : Eigen::VectorXd(X.row(n - 1).transpose());
  f.start(z, last.data());
  if (padlen > 0) f.run(post.data() + (padlen - 1) * c, padlen, -c);
  f.run(X.data() + (n - 1) * c, n, -c);  // (the pre pad's backward output is not needed)
}

Eigen::MatrixXd filtfiltColumns(const Sos& sos, const Eigen::MatrixXd& X) {
  RowMajorMatrix R = X;
  filtfiltRowsInPlace(sos, &R);
  return R;
}

double samplingRate(const Eigen::VectorXd& t, double* jitter) {
  const Eigen::Index n = t.size();
  check(n >= 3, fmt::format("a sampled signal needs at least 3 samples, got {}", n));
  std::vector<double> dt(static_cast<std::size_t>(n - 1));
  for (Eigen::Index i = 0; i + 1 < n; ++i) {
    dt[static_cast<std::size_t>(i)] = t(i + 1) - t(i);
    check(dt[static_cast<std::size_t>(i)] > 0,
          fmt::format("time must increase strictly: t[{}] = {} then t[{}] = {}", i, t(i), i + 1,
                      t(i + 1)));
  }
  std::vector<double> sorted = dt;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<long>(sorted.size() / 2),
                   sorted.end());
  const double med = sorted[sorted.size() / 2];
  double jit = 0.0;
  for (double d : dt) jit = std::max(jit, std::abs(d - med) / med);
  if (jitter) *jitter = jit;
  return 1.0 / med;
}

double samplingRate(const Dataset& d, double* jitter) {
  if (!d.streamed()) return samplingRate(d.t, jitter);
  double fs = 0.0, jit = 0.0;
  if (d.stream->samplingRate(&fs, &jit)) {
    if (jitter) *jitter = jit;
    return fs;
  }
  Eigen::VectorXd t(d.size());
  Dataset chunk;
  d.stream->rewind();
  Eigen::Index k = 0;
  while (const int got = d.stream->read(65536, &chunk)) {
    check(k + got <= t.size(),
          fmt::format("'{}': the stream gave more than its {} samples", d.source, t.size()));
    t.segment(k, got) = chunk.t.head(got);
    k += got;
  }
  check(k == t.size(),
        fmt::format("'{}': the stream gave {} of its {} samples", d.source, k, t.size()));
  return samplingRate(t, jitter);
}

Eigen::MatrixXd centralFirstDerivative(const Eigen::VectorXd& t, const Eigen::MatrixXd& X) {
  const Eigen::Index n = X.rows();
  check(n >= 3 && t.size() == n,
        "central differences need at least 3 samples and one time per sample");
  Eigen::MatrixXd D(n, X.cols());
  for (Eigen::Index k = 1; k + 1 < n; ++k) {
    const double h1 = t(k) - t(k - 1), h2 = t(k + 1) - t(k);
    D.row(k) = (-h2 / (h1 * (h1 + h2))) * X.row(k - 1) + ((h2 - h1) / (h1 * h2)) * X.row(k) +
               (h1 / (h2 * (h1 + h2))) * X.row(k + 1);
  }
  {  // one-sided, second order, at the start: nodes 0, 1, 2
    const double h1 = t(1) - t(0), h2 = t(2) - t(1);
    D.row(0) = (-(2 * h1 + h2) / (h1 * (h1 + h2))) * X.row(0) + ((h1 + h2) / (h1 * h2)) * X.row(1) +
               (-h1 / (h2 * (h1 + h2))) * X.row(2);
  }
  {  // at the end: nodes n-3, n-2, n-1
    const double h1 = t(n - 2) - t(n - 3), h2 = t(n - 1) - t(n - 2);
    D.row(n - 1) = (h2 / (h1 * (h1 + h2))) * X.row(n - 3) +
                   (-(h1 + h2) / (h1 * h2)) * X.row(n - 2) +
                   ((h1 + 2 * h2) / (h2 * (h1 + h2))) * X.row(n - 1);
  }
  return D;
}

Eigen::MatrixXd centralSecondDerivative(const Eigen::VectorXd& t, const Eigen::MatrixXd& X) {
  const Eigen::Index n = X.rows();
  check(n >= 4 && t.size() == n,
        "second differences need at least 4 samples and one time per sample");
  Eigen::MatrixXd D(n, X.cols());
  for (Eigen::Index k = 1; k + 1 < n; ++k) {
    const double h1 = t(k) - t(k - 1), h2 = t(k + 1) - t(k);
    D.row(k) = 2.0 * (X.row(k - 1) / (h1 * (h1 + h2)) - X.row(k) / (h1 * h2) +
                      X.row(k + 1) / (h2 * (h1 + h2)));
  }
  // Linear extrapolation of the second derivative to the ends.
  const double a0 = (t(0) - t(1)) / (t(2) - t(1));
  D.row(0) = D.row(1) + a0 * (D.row(2) - D.row(1));
  const double a1 = (t(n - 1) - t(n - 2)) / (t(n - 2) - t(n - 3));
  D.row(n - 1) = D.row(n - 2) + a1 * (D.row(n - 2) - D.row(n - 3));
  return D;
}

Rows decimateRows(const Rows& rows, int factor, const Sos& sos) {
  check(factor >= 1, fmt::format("decimation factor must be >= 1, got {}", factor));
  if (factor == 1) return rows;
  const auto R = static_cast<int>(rows.y.size());
  std::map<int, std::vector<int>> groups;
  for (int i = 0; i < R; ++i)
    groups[rows.equation.size() == static_cast<std::size_t>(R)
               ? rows.equation[static_cast<std::size_t>(i)]
               : 0]
        .push_back(i);
  const Eigen::Index p = rows.W.cols();
  std::vector<Eigen::MatrixXd> dec;  // per equation: kept rows of [W y]
  std::vector<int> labels;
  std::size_t total = 0, longest = 0;
  for (const auto& [label, idx] : groups) {
    const auto L = static_cast<Eigen::Index>(idx.size());
    RowMajorMatrix A(L, p + 1);
    for (Eigen::Index i = 0; i < L; ++i) {
      A.row(i).head(p) = rows.W.row(idx[static_cast<std::size_t>(i)]);
      A(i, p) = rows.y(idx[static_cast<std::size_t>(i)]);
    }
    if (L >= 2) filtfiltRowsInPlace(sos, &A);
    const Eigen::Index kept = (L + factor - 1) / factor;
    Eigen::MatrixXd K(kept, p + 1);
    for (Eigen::Index i = 0; i < kept; ++i) K.row(i) = A.row(i * factor);
    total += static_cast<std::size_t>(kept);
    longest = std::max(longest, static_cast<std::size_t>(kept));
    dec.push_back(std::move(K));
    labels.push_back(label);
  }
  Rows out;
  out.W.resize(static_cast<Eigen::Index>(total), p);
  out.y.resize(static_cast<Eigen::Index>(total));
  out.equation.reserve(total);
  out.numEquations = rows.numEquations;
  Eigen::Index r = 0;
  for (std::size_t j = 0; j < longest; ++j)
    for (std::size_t g = 0; g < dec.size(); ++g)
      if (j < static_cast<std::size_t>(dec[g].rows())) {
        out.W.row(r) = dec[g].row(static_cast<Eigen::Index>(j)).head(p);
        out.y(r) = dec[g](static_cast<Eigen::Index>(j), p);
        out.equation.push_back(labels[g]);
        if (rows.t.size() == static_cast<std::size_t>(R))
          out.t.push_back(rows.t[static_cast<std::size_t>(
              groups.at(labels[g])[j * static_cast<std::size_t>(factor)])]);
        ++r;
      }
  out.equation_names = rows.equation_names;
  return out;
}

double decimationVarianceFactor(const Sos& sos, int factor) {
  check(factor >= 1, "decimationVarianceFactor: factor must be >= 1");
  // Impulse response of the zero-phase filter, long enough to have decayed.
  double rmax = 0.0;
  for (const auto& s : sos.sections) {
    const double a1 = s[4], a2 = s[5], disc = a1 * a1 - 4.0 * a2;
    rmax = std::max(rmax, disc < 0 ? std::sqrt(a2) : 0.5 * (std::abs(a1) + std::sqrt(disc)));
  }
  const double tau = rmax > 0 && rmax < 1 ? -1.0 / std::log(rmax) : 1.0;
  const Eigen::Index half = static_cast<Eigen::Index>(std::ceil(60.0 * tau)) + 10 * factor;
  Eigen::VectorXd x = Eigen::VectorXd::Zero(2 * half + 1);
  x(half) = 1.0;
  const Eigen::VectorXd h = filtfilt(sos, x);
  auto g = [&](Eigen::Index lag) {
    const Eigen::Index n = h.size() - lag;
    return n > 0 ? h.head(n).dot(h.tail(n)) : 0.0;
  };
  const double g0 = g(0);
  double sum = g0;
  for (Eigen::Index j = 1; j * factor < h.size(); ++j) sum += 2.0 * g(j * factor);
  return sum / g0;
}

void savitzkyGolay(const Eigen::MatrixXd& X, double dt, int m, Eigen::MatrixXd* value,
                   Eigen::MatrixXd* d1, Eigen::MatrixXd* d2) {
  using Eigen::Index;
  using Eigen::MatrixXd;
  const Index K = X.rows();
  if (value) value->resize(K, X.cols());
  if (d1) d1->resize(K, X.cols());
  if (d2) d2->resize(K, X.cols());
  // The fit over +-h samples is three fixed weightings of the window (value, slope, curvature):
  // the weights are computed once per half-width h (h = m inside, smaller near the ends).
  struct Weights {
    std::vector<double> w0, w1, w2;
  };
  std::vector<Weights> by_h(static_cast<std::size_t>(std::max(0, m)) + 1);
  auto weights = [&](Index h) -> const Weights& {
    Weights& w = by_h[static_cast<std::size_t>(h)];
    if (!w.w0.empty()) return w;
    double S2 = 0, S4 = 0;
    for (Index i = -h; i <= h; ++i) {
      S2 += static_cast<double>(i * i);
      S4 += static_cast<double>(i * i * i * i);
    }
    const double N = static_cast<double>(2 * h + 1);
    const double den0 = N * S4 - S2 * S2;
    double cc = 0;  // sum of (i^2 - S2/N)^2
    for (Index i = -h; i <= h; ++i) {
      const double c = static_cast<double>(i * i) - S2 / N;
      cc += c * c;
    }
    for (Index i = -h; i <= h; ++i) {
      const double ii = static_cast<double>(i * i);
      w.w0.push_back((S4 - S2 * ii) / den0);
      w.w1.push_back(static_cast<double>(i) / S2 / dt);
      w.w2.push_back(2.0 * (ii - S2 / N) / cc / (dt * dt));
    }
    return w;
  };
  // Near the ends the window does not shrink (a fit to three samples differentiates their noise
  // twice): the fit to the first (last) 2h + 1 samples, evaluated off its centre, u samples away.
  const Index hw = std::min<Index>(static_cast<Index>(m), (K - 1) / 2);
  if (hw < 1) {
    for (MatrixXd* M : {d1, d2})
      if (M) M->setZero();
    if (value) *value = X;
    return;
  }
  const Weights& w = weights(hw);
  for (Index j = 0; j < X.cols(); ++j) {
    const double* x = X.col(j).data();
    for (Index k = 0; k < K; ++k) {
      const Index c = std::clamp<Index>(k, hw, K - 1 - hw);  // the window's centre
      const double u = static_cast<double>(k - c);
      const double* xk = x + (c - hw);
      double s0 = 0, s1 = 0, s2 = 0;
      for (Index i = 0; i <= 2 * hw; ++i) {
        s0 += w.w0[static_cast<std::size_t>(i)] * xk[i];
        s1 += w.w1[static_cast<std::size_t>(i)] * xk[i];
        s2 += w.w2[static_cast<std::size_t>(i)] * xk[i];
      }
      // s0, s1, s2: value, slope and curvature at the centre (a0, a1 / dt, 2 a2 / dt^2)
      if (value) (*value)(k, j) = s0 + s1 * dt * u + 0.5 * s2 * dt * dt * u * u;
      if (d1) (*d1)(k, j) = s1 + s2 * dt * u;
      if (d2) (*d2)(k, j) = s2;
    }
  }
}

}  // namespace exid
