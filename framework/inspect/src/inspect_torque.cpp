// exid — the torque checks of inspectDataset (inspect_torque.hpp).
//
// Sign check, per joint j, on the moving samples (at rest when the robot never moves): the
// measured torque y regressed on the nominal model's torque p beside friction columns the
// description may lack (a smooth sign of qd_j, qd_j, a constant):
//     y = g p + c1 tanh(qd_j / v_j) + c2 qd_j + c3 + e.
// g is the torque's gain against the model; its standard deviation comes from the residual, with
// the residual's lag-1 autocorrelation rho inflating the variance by (1 + rho) / (1 - rho) (a
// smooth model error is not m independent samples). The joint is checkable when the part of p
// the friction columns cannot explain varies by more than kSignalOverNoise times the recording's
// noise on tau_j (noiseLevel) and g is known to within kMaxGainHalfWidth; then: flipped when
// g + kZ se < 0, does not follow when |g| + kZ se < kNoFollowGain and g is not significantly
// positive, scale when g is significantly outside [1 / kGainFactor, kGainFactor], else ok.
// Every sample of the set enters the same sums: one sample more changes g by about 1/m.
//
// Delay: for every lag l in [-L, L] the same regression with p shifted by l over the same
// samples, friction columns shifted too; the residual sum of squares RSS_j(l) has its minimum at
// joint j's delay (a coarse scan, then every lag near its minimum, a parabola through the three
// lowest points), whose standard deviation follows from the information the samples hold on the
// lag: RSS(d + x) ~ RSS(d) + g^2 ||dp_perp||^2 x^2 against s^2 f. The overall delay
// minimises sum_j RSS_j(l) / (s_j^2 f_j). It is reported as a warning only when it is at least
// kDelayMinSamples, more than kZ standard deviations from zero (the std from the spread of the
// estimates of kDelayParts parts of the recording that give it), the joints agree with it, two
// thirds of the informative parts give it, and shifting by it lowers the joints' residuals by
// kDelayMinImprovement on average.
#include "inspect_torque.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <numeric>

#include "exid/eigen_instances.hpp"
#include "exid/inspect.hpp"

namespace exid::inspect_torque {

namespace {

using namespace inspect;
using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::VectorXd;

Json numOrNull(double x) { return std::isfinite(x) ? Json(x) : Json(); }

std::string joints(const std::vector<int>& js) {
  std::string s;
  for (std::size_t i = 0; i < js.size(); ++i) s += fmt::format("{}tau{}", i ? ", " : "", js[i] + 1);
  return s;
}

double medianAbs(std::vector<double> v) {
  if (v.empty()) return NAN;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

/// The samples a joint is judged on, as indices into the recording, and the friction columns'
/// orthonormal basis over them.
struct SampleSet {
  std::vector<Index> k;  // ascending
  MatrixXd Q;            // orthonormal basis of the friction columns on those samples
};

SampleSet sampleSet(const Input& in, int j, bool at_rest, Index from, Index to) {
  SampleSet s;
  const std::vector<char>& moving = *in.moving;
  for (Index k = from; k < to; ++k)
    if ((moving[static_cast<std::size_t>(k)] != 0) != at_rest) s.k.push_back(k);
  const auto m = static_cast<Index>(s.k.size());
  if (m == 0) return s;
  MatrixXd F(m, at_rest ? 1 : 3);
  double vmax = 0;
  for (Index i = 0; i < m; ++i) vmax = std::max(vmax, std::abs((*in.qd)(s.k[i], j)));
  const double v0 = std::max(0.02 * vmax, 1e-9);
  for (Index i = 0; i < m; ++i) {
    F(i, 0) = 1.0;
    if (!at_rest) {
      const double v = (*in.qd)(s.k[i], j);
      F(i, 1) = std::tanh(v / v0);
      F(i, 2) = v;
    }
  }
  // Columns that vanish (a joint that does not move) or repeat another are dropped by the rank
  // of a column-pivoting QR.
  Eigen::ColPivHouseholderQR<MatrixXd> qr(F);
  qr.setThreshold(1e-10);
  const Index r = qr.rank();
  s.Q = (qr.householderQ() * MatrixXd::Identity(m, r)).eval();
  return s;
}

/// x minus its projection on the friction columns.
VectorXd orthogonal(const SampleSet& s, const VectorXd& x) {
  return x - s.Q * (s.Q.transpose() * x);
}

/// Lag-1 autocorrelation of a residual over consecutive samples of the set, in [0, 0.999].
double lagOneCorrelation(const SampleSet& s, const VectorXd& e) {
  double num = 0, den = e.squaredNorm();
  for (std::size_t i = 1; i < s.k.size(); ++i)
    if (s.k[i] == s.k[i - 1] + 1) num += e(static_cast<Index>(i)) * e(static_cast<Index>(i - 1));
  if (!(den > 0)) return 0.0;
  return std::clamp(num / den, 0.0, 0.999);
}

struct GainFit {
  Index m = 0;
  double gain = NAN, gain_std = NAN, signal = NAN, sigma = NAN, rho = 0, inflation = 1;
  double correlation = NAN;
};

/// y regressed on p beside the friction columns (Frisch-Waugh: both made orthogonal to them).
GainFit fitGain(const SampleSet& s, const VectorXd& y, const VectorXd& p) {
  GainFit f;
  f.m = static_cast<Index>(s.k.size());
  const Index dof = f.m - s.Q.cols() - 1;
  if (dof < 2) return f;
  const VectorXd yo = orthogonal(s, y), po = orthogonal(s, p);
  const double pp = po.squaredNorm();
  f.signal = std::sqrt(pp / static_cast<double>(f.m));
  if (!(pp > 0)) return f;
  f.gain = po.dot(yo) / pp;
  const VectorXd e = yo - f.gain * po;
  f.sigma = std::sqrt(e.squaredNorm() / static_cast<double>(dof));
  f.rho = lagOneCorrelation(s, e);
  f.inflation = (1 + f.rho) / (1 - f.rho);
  f.gain_std = f.sigma * std::sqrt(f.inflation / pp);
  const double yy = yo.squaredNorm();
  f.correlation = yy > 0 ? po.dot(yo) / std::sqrt(pp * yy) : NAN;
  return f;
}

VectorXd gather(const Eigen::MatrixXd& M, int j, const std::vector<Index>& k, Index shift = 0) {
  VectorXd v(static_cast<Index>(k.size()));
  for (std::size_t i = 0; i < k.size(); ++i) v(static_cast<Index>(i)) = M(k[i] - shift, j);
  return v;
}

struct JointVerdict {
  std::string verdict;  // ok, flipped, does not follow, scale, not checkable
  std::string why;      // for "not checkable"
};

/// noise: the measured torque's; pred_noise: the prediction's own (from derived derivatives),
/// which is not signal: the signal is what the prediction varies by beyond it.
JointVerdict judge(const GainFit& f, double noise, double pred_noise) {
  if (f.m < kMinCorrelationSamples)
    return {"not checkable",
            fmt::format("{} samples (fewer than {})", f.m, kMinCorrelationSamples)};
  const double signal =
      std::isfinite(f.signal)
          ? std::sqrt(std::max(0.0, f.signal * f.signal - pred_noise * pred_noise))
          : 0.0;
  if (!(signal > kSignalOverNoise * noise) || !std::isfinite(f.gain))
    return {"not checkable",
            fmt::format("the model's torque beyond friction varies by {:.3g} (std), within {:g} "
                        "times the recording's noise {:.3g}",
                        signal, kSignalOverNoise, noise)};
  if (!(signal > kSignalOverNoise * pred_noise))
    return {"not checkable",
            fmt::format("the model's torque beyond friction varies by {:.3g} (std), within {:g} "
                        "times its own error {:.3g} from velocities and accelerations derived "
                        "from noisy or quantised positions",
                        signal, kSignalOverNoise, pred_noise)};
  if (!(kZ * f.gain_std < kMaxGainHalfWidth))
    return {"not checkable",
            fmt::format("the gain is known only to +-{:.2g} ({:g} std): the model's errors are as "
                        "large as its signal here",
                        kZ * f.gain_std, kZ)};
  const double lo = f.gain - kZ * f.gain_std, hi = f.gain + kZ * f.gain_std;
  if (hi < 0) return {"flipped", ""};
  if (std::abs(f.gain) + kZ * f.gain_std < kNoFollowGain && !(lo > 0))
    return {"does not follow", ""};
  if (lo > kGainFactor || (hi < 1.0 / kGainFactor && lo > 0)) return {"scale", ""};
  return {"ok", ""};
}

}  // namespace

double noiseLevel(const Eigen::Ref<const VectorXd>& x) {
  const Index K = x.size();
  if (K < 8) return NAN;
  std::vector<double> d2(static_cast<std::size_t>(K - 2));
  for (Index k = 1; k + 1 < K; ++k)
    d2[static_cast<std::size_t>(k - 1)] = std::abs(x(k + 1) - 2 * x(k) + x(k - 1));
  // 1.4826 MAD: the std of a normal variable from its median absolute value
  return 1.4826 * medianAbs(std::move(d2)) / std::sqrt(6.0);
}

std::vector<char> signCheck(const Input& in, std::vector<Json>* jrows,
                            std::vector<std::string>* W) {
  const auto n = static_cast<int>(in.tau->cols());
  const Index K = in.tau->rows();
  Index moving = 0;
  for (char c : *in.moving) moving += c != 0;
  const bool at_rest = moving < kMinCorrelationSamples;
  std::vector<char> usable(static_cast<std::size_t>(n), 0);
  std::vector<int> flipped, nofollow, scale, ok, unknown;
  std::vector<double> g_flipped, g_nofollow, g_scale;
  for (int j = 0; j < n; ++j) {
    const SampleSet s = sampleSet(in, j, at_rest, 0, K);
    const VectorXd y = gather(*in.tau, j, s.k);
    const VectorXd p = gather(at_rest ? *in.pred_rest : *in.pred, j, s.k);
    const GainFit f = fitGain(s, y, p);
    const double noise = noiseLevel(in.tau_raw->col(j));
    const double pnoise = in.pred_noise ? (*in.pred_noise)(j) : 0.0;
    const JointVerdict v = judge(f, noise, pnoise);
    Json c = Json::object();
    c["judged_on"] = s.k.empty() ? "nothing" : at_rest ? "rest" : "motion";
    c["samples"] = static_cast<long long>(f.m);
    c["gain"] = numOrNull(f.gain);
    c["gain_std"] = numOrNull(f.gain_std);
    c["correlation"] = numOrNull(f.correlation);
    c["noise"] = numOrNull(noise);
    c["model_signal"] = numOrNull(f.signal);
    c["model_noise"] = pnoise;
    c["residual_lag1_correlation"] = f.rho;
    c["verdict"] = v.verdict;
    if (!v.why.empty()) c["why"] = v.why;
    c["statistic"] = fmt::format(
        "gain g of the measured torque on the nominal model's, beside friction columns (smooth "
        "sign of qd, qd, offset), its std from the residual inflated by (1 + rho) / (1 - rho); "
        "checkable when the model's torque beyond friction varies by more than {:g} times the "
        "torque's noise and its own error (derived derivatives), and {:g} std of g is below "
        "{:g}; flipped: g + {:g} std < 0",
        kSignalOverNoise, kZ, kMaxGainHalfWidth, kZ);
    (*jrows)[static_cast<std::size_t>(j)]["sign_check"] = c;
    if (v.verdict == "flipped") {
      flipped.push_back(j);
      g_flipped.push_back(f.gain);
    } else if (v.verdict == "does not follow") {
      nofollow.push_back(j);
      g_nofollow.push_back(f.gain);
    } else if (v.verdict == "scale") {
      scale.push_back(j);
      g_scale.push_back(f.gain);
    } else if (v.verdict == "ok") {
      ok.push_back(j);
    } else {
      unknown.push_back(j);
    }
    usable[static_cast<std::size_t>(j)] =
        !at_rest && (v.verdict == "ok" || v.verdict == "flipped" || v.verdict == "scale");
  }
  auto gains = [](const std::vector<double>& g) {
    std::string s;
    for (std::size_t i = 0; i < g.size(); ++i) s += fmt::format("{}{:.3g}", i ? ", " : "", g[i]);
    return s;
  };
  const char* where = at_rest ? "at rest" : "in motion";
  const std::size_t checkable = flipped.size() + nofollow.size() + scale.size() + ok.size();
  if (flipped.size() >= 2 && 2 * flipped.size() > checkable) {
    // one whole-robot verdict: the data's sign convention differs from the model's
    W->push_back(fmt::format(
        "the torque of {} of the {} joints that can be checked here ({}) is the negative of the "
        "nominal model's {} (gains {}){}: the recording's torque sign convention is the opposite "
        "of the model's: tau_scale -1 for every joint?",
        flipped.size(), checkable, joints(flipped), where, gains(g_flipped),
        unknown.empty() ? std::string()
                        : fmt::format("; {} cannot be checked here", joints(unknown))));
  } else if (!flipped.empty()) {
    W->push_back(fmt::format(
        "{} {} the negative of the nominal model's torque {} (gain{} {}, more than {:g} std below "
        "zero): torque sign flipped (tau_scale -1 for {}, or check the column's sign)",
        joints(flipped), flipped.size() > 1 ? "are" : "is", where, flipped.size() > 1 ? "s" : "",
        gains(g_flipped), kZ, flipped.size() > 1 ? "those joints" : "that joint"));
  }
  if (!nofollow.empty())
    W->push_back(fmt::format(
        "{} {} not follow the nominal model's torque {} (gain{} {}, within {:g} std of zero, "
        "where the model's torque varies by more than {:g} times the noise): a wrong column, "
        "scale or unit?",
        joints(nofollow), nofollow.size() > 1 ? "do" : "does", where,
        nofollow.size() > 1 ? "s" : "", gains(g_nofollow), kZ, kSignalOverNoise));
  if (!scale.empty())
    W->push_back(fmt::format(
        "{} follow{} the nominal model's torque but with a gain of {} (outside [1/{:g}, {:g}] by "
        "more than {:g} std): scale, torque constant or units (tau_scale, "
        "torque_constants_Nm_per_A)?",
        joints(scale), scale.size() > 1 ? "" : "s", gains(g_scale), kGainFactor, kGainFactor, kZ));
  return usable;
}

namespace {

/// The regressors at sample k - l: the model's torque and the friction columns (a smooth sign
/// of qd_j, qd_j, a constant): the whole prediction shifted, friction included.
MatrixXd shiftedRegressors(const Input& in, int j, const std::vector<Index>& k, Index l,
                           double v0) {
  MatrixXd X(static_cast<Index>(k.size()), 4);
  for (std::size_t i = 0; i < k.size(); ++i) {
    const Index r = k[i] - l;
    const double v = (*in.qd)(r, j);
    X(static_cast<Index>(i), 0) = (*in.pred)(r, j);
    X(static_cast<Index>(i), 1) = std::tanh(v / v0);
    X(static_cast<Index>(i), 2) = v;
    X(static_cast<Index>(i), 3) = 1.0;
  }
  return X;
}

/// Residual of y on X (columns scaled; dependent ones dropped by the QR's rank).
VectorXd residualOf(const MatrixXd& X, const VectorXd& y) {
  VectorXd scale = X.colwise().norm().transpose();
  for (Index c = 0; c < scale.size(); ++c) scale(c) = scale(c) > 0 ? 1.0 / scale(c) : 0.0;
  const MatrixXd Xs = X * scale.asDiagonal();
  Eigen::ColPivHouseholderQR<MatrixXd> qr(Xs);
  qr.setThreshold(1e-10);
  return y - Xs * qr.solve(y);
}

/// Joint j's residual sum of squares over a set of samples with the prediction shifted by l
/// (every sample of the set lies in [L, K - L)), computed once per lag.
class LagRss {
 public:
  LagRss(const Input& in, int j, std::vector<Index> k, double v0)
      : in_(in), j_(j), k_(std::move(k)), v0_(v0), y_(gather(*in.tau, j, k_)) {}
  Index samples() const { return static_cast<Index>(k_.size()); }
  double at(int l) {
    auto it = cache_.find(l);
    if (it != cache_.end()) return it->second;
    const double r = residualOf(shiftedRegressors(in_, j_, k_, l, v0_), y_).squaredNorm();
    cache_[l] = r;
    return r;
  }
  /// At lag l: unit = s^2 f (the residual variance, inflated by its autocorrelation) and the
  /// information the samples hold on the lag, c = g^2 ||dp_perp||^2 (dp: the change of the
  /// shifted prediction per sample of lag, its central difference, made orthogonal to the
  /// regressors; g: the prediction's coefficient): RSS(l + x) ~ RSS(l) + c x^2 near the minimum,
  /// so the lag's std is sqrt(unit / c). (The curvature of the computed RSS over a few lags is
  /// no measure of it: on a flat profile, noise gives it any value.)
  struct Info {
    double unit = NAN, c = NAN, sigma2 = NAN;
  };
  Info infoAt(int l) const {
    Info r;
    const Index dof = samples() - 5;
    if (dof < 2) return r;
    const MatrixXd X = shiftedRegressors(in_, j_, k_, l, v0_);
    VectorXd scale = X.colwise().norm().transpose();
    for (Index c = 0; c < scale.size(); ++c) scale(c) = scale(c) > 0 ? 1.0 / scale(c) : 0.0;
    const MatrixXd Xs = X * scale.asDiagonal();
    Eigen::ColPivHouseholderQR<MatrixXd> qr(Xs);
    qr.setThreshold(1e-10);
    const VectorXd beta = qr.solve(y_);
    const VectorXd e = y_ - Xs * beta;
    const double g = beta(0) * scale(0);
    const Index K = in_.pred->rows();
    VectorXd dp(samples());
    for (Index i = 0; i < samples(); ++i) {
      const Index r0 = k_[static_cast<std::size_t>(i)] - l;
      const Index a = std::max<Index>(0, r0 - 1), b = std::min<Index>(K - 1, r0 + 1);
      dp(i) = b > a ? ((*in_.pred)(b, j_) - (*in_.pred)(a, j_)) / static_cast<double>(b - a) : 0.0;
    }
    const VectorXd dpo = dp - Xs * qr.solve(dp);
    double num = 0;
    for (std::size_t i = 1; i < k_.size(); ++i)
      if (k_[i] == k_[i - 1] + 1) num += e(static_cast<Index>(i)) * e(static_cast<Index>(i - 1));
    const double den = e.squaredNorm();
    const double rho = den > 0 ? std::clamp(num / den, 0.0, 0.999) : 0.0;
    r.sigma2 = den / static_cast<double>(dof);
    r.unit = r.sigma2 * (1 + rho) / (1 - rho);
    r.c = g * g * dpo.squaredNorm();
    return r;
  }

 private:
  const Input& in_;
  int j_;
  std::vector<Index> k_;
  double v0_;
  VectorXd y_;
  std::map<int, double> cache_;
};

struct LagMinimum {
  double d = NAN, std = NAN;
  double std_white = NAN;  // the std were the residuals white (no inflation): a lower bound
  bool edge = false;
};

/// The minimum of f over whole lags in [-L, L]: a coarse scan every `step` lags, then every lag
/// within a step of the coarse minimum; a parabola through the lowest point and its neighbours;
/// std from the curvature against a 1-sigma change `unit`.
template <class F>
LagMinimum lagMinimum(F f, int L, int step, double unit) {
  LagMinimum r;
  int best = 0;
  double fb = f(0);
  for (int l = -L; l <= L; l += step)
    if (const double v = f(l); v < fb) {
      fb = v;
      best = l;
    }
  if (f(L) < fb) {
    fb = f(L);
    best = L;
  }
  const int c = best;
  for (int l = std::max(-L, c - step); l <= std::min(L, c + step); ++l)
    if (const double v = f(l); v < fb) {
      fb = v;
      best = l;
    }
  r.edge = best == -L || best == L;
  if (r.edge) {
    r.d = best;
    return r;
  }
  const double ym = f(best - 1), y0 = fb, yp = f(best + 1);
  const double curv = 0.5 * (ym - 2 * y0 + yp);
  r.d = best + (curv > 0 ? 0.25 * (ym - yp) / curv : 0.0);
  r.std = curv > 0 && unit > 0 ? std::sqrt(unit / curv) : HUGE_VAL;
  return r;
}

struct Combined {
  LagMinimum all;
  std::vector<LagMinimum> per_joint;
  double improvement = 0;  // mean relative RSS decrease at the combined delay's whole lag
};

/// The joints' profiles over the moving samples in [from, to) and their combination.
Combined combine(const Input& in, const std::vector<int>& js, int L, Index from, Index to) {
  Combined C;
  const int step = std::max(1, L / 8);
  std::vector<std::unique_ptr<LagRss>> rss;
  std::vector<double> unit;
  for (int j : js) {
    const SampleSet s = sampleSet(in, j, false, from, to);
    double vmax = 0;
    for (Index r = 0; r < in.qd->rows(); ++r) vmax = std::max(vmax, std::abs((*in.qd)(r, j)));
    auto R = std::make_unique<LagRss>(in, j, s.k, std::max(0.02 * vmax, 1e-9));
    if (R->samples() < kMinCorrelationSamples) {
      C.per_joint.push_back({});
      rss.push_back(nullptr);
      unit.push_back(NAN);
      continue;
    }
    // the joint's own minimum, its std from the information on the lag there
    LagMinimum m = lagMinimum([&](int l) { return R->at(l); }, L, step, 1.0);
    const LagRss::Info info = R->infoAt(static_cast<int>(std::lround(m.d)));
    m.std = m.edge || !(info.c > 0) ? NAN : std::sqrt(info.unit / info.c);
    C.per_joint.push_back(m);
    unit.push_back(info.unit);
    rss.push_back(std::move(R));
  }
  auto total = [&](int l) {
    double t = 0;
    for (std::size_t i = 0; i < rss.size(); ++i)
      if (rss[i] && unit[i] > 0) t += rss[i]->at(l) / unit[i];
    return t;
  };
  C.all = lagMinimum(total, L, step, 1.0);
  if (std::isfinite(C.all.d)) {
    const int at = static_cast<int>(std::lround(C.all.d));
    // the sum's information on the lag: each joint's, in its own units
    double info = 0, info_white = 0;
    for (std::size_t i = 0; i < rss.size(); ++i)
      if (rss[i] && unit[i] > 0) {
        const LagRss::Info f = rss[i]->infoAt(at);
        if (f.unit > 0 && f.c > 0) info += f.c / f.unit;
        if (f.sigma2 > 0 && f.c > 0) info_white += f.c / f.sigma2;
      }
    C.all.std = C.all.edge || !(info > 0) ? NAN : 1.0 / std::sqrt(info);
    C.all.std_white = C.all.edge || !(info_white > 0) ? NAN : 1.0 / std::sqrt(info_white);
    double sum = 0;
    int cnt = 0;
    for (auto& R : rss)
      if (R && R->at(0) > 0) {
        sum += (R->at(0) - R->at(at)) / R->at(0);
        ++cnt;
      }
    C.improvement = cnt > 0 ? sum / cnt : 0.0;
  }
  return C;
}

/// The delay of each of kDelayParts parts of the recording, each holding an equal share of its
/// moving rows (halves where fewer than two of them are informative: a short recording): the
/// informative parts' estimates; every part listed in *parts_out with its white std and whether
/// it is informative (its std, were the residuals white, below the agreement tolerance tol_d).
std::vector<double> partEstimates(const Input& in, const std::vector<int>& js, int L, double tol_d,
                                  Json* parts_out) {
  const Index K = in.tau->rows();
  std::vector<double> parts;
  Json& parts_json = *parts_out;
  // The parts hold equal shares of the moving rows (a standstill would otherwise leave a part
  // with nothing to say and its neighbour with the motion's slow start alone).
  std::vector<Index> moving_rows;
  for (Index k = L; k < K - L; ++k)
    if ((*in.moving)[static_cast<std::size_t>(k)] != 0) moving_rows.push_back(k);
  const auto M = static_cast<Index>(moving_rows.size());
  for (const int count : {kDelayParts, 2}) {
    parts.clear();
    parts_json = Json::array();
    for (int b = 0; b < count && M >= count; ++b) {
      const Index from = b == 0 ? L : moving_rows[static_cast<std::size_t>(M * b / count)];
      const Index to =
          b + 1 == count ? K - L : moving_rows[static_cast<std::size_t>(M * (b + 1) / count)];
      const Combined P = combine(in, js, L, from, to);
      Json e = Json::object();
      e["delay_samples"] = numOrNull(P.all.edge ? NAN : P.all.d);
      e["white_std_samples"] = numOrNull(P.all.std_white);
      // (halves, the short recording's fallback: their own data hold half as much, so a half
      // votes while its white std is within twice the agreement tolerance)
      const double informative_below = count == 2 ? 2 * tol_d : tol_d;
      const bool informative = std::isfinite(P.all.d) && !P.all.edge &&
                               std::isfinite(P.all.std_white) &&
                               P.all.std_white < informative_below;
      e["informative"] = informative;
      parts_json.push_back(e);
      if (informative) parts.push_back(P.all.d);
    }
    if (parts.size() >= 2) break;
  }
  return parts;
}

/// Each judged joint's own delay and std into D["per_joint"] (and their spread in seconds);
/// *judged: the joints with a finite delay and std, *agreeing: those within kZ std (or the
/// agreement tolerance tol_d) of the overall delay d.
void perJointDelays(const Input& in, const std::vector<int>& js, const Combined& C, double d,
                    double tol_d, Json& D, int* agreeing_out, int* judged_out) {
  Json per = Json::array();
  std::vector<double> djs;
  int& agreeing = *agreeing_out;
  int& judged = *judged_out;
  agreeing = judged = 0;
  for (std::size_t i = 0; i < js.size(); ++i) {
    const LagMinimum& m = C.per_joint[i];
    Json e = Json::object();
    e["joint"] = js[i] + 1;
    e["delay_samples"] = numOrNull(m.d);
    e["delay_s"] = numOrNull(m.d * in.dt);
    e["std_samples"] = numOrNull(m.std);
    e["at_window_edge"] = m.edge;
    per.push_back(e);
    if (std::isfinite(m.d)) djs.push_back(m.d * in.dt);
    if (!std::isfinite(m.d) || !std::isfinite(m.std)) continue;
    ++judged;
    if (std::abs(m.d - d) <= std::max(kZ * m.std, tol_d)) ++agreeing;
  }
  D["per_joint"] = per;
  {
    double mean = 0;
    for (double x : djs) mean += x;
    mean /= std::max<std::size_t>(1, djs.size());
    double v = 0;
    for (double x : djs) v += (x - mean) * (x - mean);
    D["per_joint_spread_s"] = djs.size() > 1 ? Json(std::sqrt(v / (djs.size() - 1))) : Json();
  }
}

/// What the recording can say of the delay: a delay it confirms (warned), none where it could
/// have confirmed one, or not checkable here (too few joints or parts hold information on the
/// lag: the estimate is listed, but the recording can neither confirm nor rule out a delay).
std::string delayVerdict(bool edge_warned, bool reported, int judged, std::size_t parts) {
  std::string verdict;
  if (edge_warned) {
    verdict = "delay at the edge of the searched window";
  } else if (reported) {
    verdict = "delay";
  } else if (judged < 2 || parts < 2) {
    std::vector<std::string> why;
    if (judged < 2)
      why.push_back(fmt::format("{} joint{} judged on the lag, two are needed", judged,
                                judged == 1 ? "" : "s"));
    if (parts < 2)
      why.push_back(fmt::format("{} part{} of the recording informative, two are needed", parts,
                                parts == 1 ? "" : "s"));
    verdict = fmt::format("not checkable here: {}", fmt::join(why, "; "));
  } else {
    verdict = "none found";
  }
  return verdict;
}

}  // namespace

void delayCheck(const Input& in, const std::vector<char>& usable, Json& D,
                std::vector<std::string>* W) {
  D["convention"] =
      "positive: the measured torque lags the prediction, tau_measured(t) ~ "
      "tau_predicted(t - delay_s)";
  const Index K = in.tau->rows();
  const double rate = 1.0 / in.dt;
  const int L =
      std::min(std::max(static_cast<int>(std::lround(kDelayMaxLagS * rate)), kDelayMinLagSamples),
               static_cast<int>(K / 8));
  D["max_lag_samples"] = L;
  std::vector<int> js;
  for (std::size_t j = 0; j < usable.size(); ++j)
    if (usable[j]) js.push_back(static_cast<int>(j));
  if (js.empty() || L < 2) {
    D["delay_samples"] = Json();
    D["delay_s"] = Json();
    D["note"] = js.empty() ? "no joint's torque can be checked against the model in motion: "
                             "nothing to align"
                           : "too few samples";
    D["verdict"] = "not checkable here: " + D["note"].asString();
    return;
  }
  const Combined C = combine(in, js, L, L, K - L);
  // The recording in kDelayParts parts, each with its own estimate: their spread gives
  // the delay's std (batch means: it holds whatever the residuals' correlation), and they must
  // agree for the delay to be reported.
  // A part whose own data hold little on the lag (its std, were the residuals white, above
  // kDelayAgreeSamples or kDelayAgreeFraction of the delay: a standstill, slow motion) is listed
  // but neither votes nor enters the spread.
  const double d = C.all.d;
  const double tol_d =
      std::max(kDelayAgreeSamples, kDelayAgreeFraction * (std::isfinite(d) ? std::abs(d) : 0.0));
  Json parts_json;
  const std::vector<double> parts = partEstimates(in, js, L, tol_d, &parts_json);
  // The std from the spread of the parts that give the delay (within the agreement tolerance):
  // a part the vote outweighs (a spurious minimum of its own) does not also inflate it.
  std::vector<double> voting;
  for (double x : parts)
    if (std::isfinite(d) && std::abs(x - d) <= tol_d && x * d > 0) voting.push_back(x);
  double sd = NAN;
  if (voting.size() >= 2) {
    double mean = 0;
    for (double x : voting) mean += x;
    mean /= static_cast<double>(voting.size());
    double v = 0;
    for (double x : voting) v += (x - mean) * (x - mean);
    sd = std::sqrt(v / static_cast<double>(voting.size() - 1) / static_cast<double>(voting.size()));
  }
  D["delay_samples"] = numOrNull(d);
  D["delay_s"] = numOrNull(d * in.dt);
  D["std_samples"] = numOrNull(sd);
  D["std_s"] = numOrNull(sd * in.dt);
  D["std_method"] = fmt::format(
      "the spread of the estimates of the informative ones of {} parts of the recording that "
      "give the delay (within the agreement tolerance) over the square root of their count; "
      "each part holds an equal share of the moving rows (halves where fewer than two of {} "
      "are informative)",
      kDelayParts, kDelayParts);
  D["model_std_samples"] = numOrNull(C.all.std);
  D["at_window_edge"] = C.all.edge;
  D["fit_improvement"] = C.improvement;
  int agreeing = 0, judged = 0;
  perJointDelays(in, js, C, d, tol_d, D, &agreeing, &judged);
  const bool joints_agree = judged >= 2 && 3 * agreeing >= 2 * judged;
  D["joints_agree"] = joints_agree;
  D["parts_delay_samples"] = parts_json;
  std::size_t parts_agreeing = 0;
  for (double x : parts) parts_agreeing += std::abs(x - d) <= tol_d && x * d > 0;
  const bool parts_agree =
      parts.size() >= 2 && std::isfinite(d) && 3 * parts_agreeing >= 2 * parts.size();
  D["parts_agree"] = parts_agree;
  const bool significant = std::isfinite(d) && std::isfinite(sd) && std::abs(d) > kZ * sd &&
                           std::abs(d) >= kDelayMinSamples;
  D["significant"] = significant;
  const bool reported =
      significant && joints_agree && parts_agree && C.improvement >= kDelayMinImprovement;
  D["reported"] = reported;
  const bool edge_warned = C.all.edge && C.improvement >= kDelayMinImprovement && judged >= 2;
  D["verdict"] = delayVerdict(edge_warned, reported, judged, parts.size());
  D["rule"] = fmt::format(
      "warned when |delay| >= {:g} samples and > {:g} std, at least two joints are judged and "
      "two thirds of them agree with it, at least two parts of the recording are informative and "
      "two thirds of those give it within {:g} samples or {:g} % of it, and shifting by it "
      "lowers the joints' residuals by {:g} % on average",
      kDelayMinSamples, kZ, kDelayAgreeSamples, 100 * kDelayAgreeFraction,
      100 * kDelayMinImprovement);
  auto partsText = [&] {
    std::string t;
    for (std::size_t i = 0; i < parts.size(); ++i)
      t += fmt::format("{}{:.2f}", i ? ", " : "", parts[i]);
    return t;
  };
  if (edge_warned)
    W->push_back(fmt::format(
        "the torque's delay against the model lies at the edge of the searched window (+-{} "
        "samples, {:.3g} s) and shifting lowers the residuals by {:.1f} %: a large delay between "
        "torque and position",
        L, L * in.dt, 100 * C.improvement));
  else if (reported)
    W->push_back(fmt::format(
        "the measured torque {} the nominal model's prediction by {:.2f} +- {:.2f} samples "
        "({:.4g} s; the recording's parts: {}; {} of {} joints agree), and shifting by it lowers "
        "the residuals by {:.1f} %: a delay in the torque (or position) signal; shift one of "
        "them before identifying (measurement_delay_s)",
        d > 0 ? "lags" : "leads", std::abs(d), sd, std::abs(d * in.dt), partsText(), agreeing,
        judged, 100 * C.improvement));
}

}  // namespace exid::inspect_torque
