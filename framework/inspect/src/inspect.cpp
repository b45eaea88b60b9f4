// exid — checks on a recording before it is trusted (inspect.hpp).
#include "exid/inspect.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <future>
#include <limits>
#include <random>
#include <stdexcept>

#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "inspect_torque.hpp"

namespace exid {

namespace {

using namespace inspect;
using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::VectorXd;

constexpr double kUnknownLimit = 1e299;  // JointLimits are +-1e300 where unknown

double percentileOf(std::vector<double> v, double p) {
  if (v.empty()) return NAN;
  const auto k = static_cast<std::size_t>(std::floor(p * static_cast<double>(v.size() - 1)));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

Json pair(double a, double b) { return Json(std::vector<double>{a, b}); }

Json numberOrNull(double x) { return std::isfinite(x) ? Json(x) : Json(); }

/// Warnings from the file-level statistics of an experiment (meta.recording of the csv one).
void recordingWarnings(const Json& rec, std::vector<std::string>* W) {
  const std::string file =
      rec.find("file") ? rec.find("file")->asString() + ": " : std::string("the recording: ");
  if (const Json* t = rec.find("timing")) {
    const Json* j = t->find("jitter");
    const Json* sd = j ? j->find("std_rel") : nullptr;
    if (sd && sd->isNumber() && sd->asDouble() > kJitterStdWarn)
      W->push_back(fmt::format(
          "{}the time steps vary by {:.1f} % (std, relative to the median step {} s; max {:.1f} "
          "%): uneven stamps from a non-real-time logger? Derivatives and filters assume a "
          "uniform rate",
          file, 100.0 * sd->asDouble(), t->find("period_s") ? t->find("period_s")->asDouble() : NAN,
          j->find("max_rel") ? 100.0 * j->find("max_rel")->asDouble() : NAN));
    const Json* g = t->find("gaps");
    if (g && g->find("count") && g->find("count")->asInt() > 0) {
      const Json* at = g->find("at_s");
      W->push_back(fmt::format(
          "{}{} gap(s) in the time stamps (largest {:.6g} s; the first after t = {:.6g} s): "
          "samples were lost; cut the segment around them",
          file, g->find("count")->asInt(), g->find("largest_s")->asDouble(),
          at && at->size() > 0 ? at->at(0).at(0).asDouble() : NAN));
    }
  }
  if (const Json* dup = rec.find("duplicate_rows"); dup && dup->find("count")) {
    const auto c = dup->find("count")->asInt();
    if (c > 0)
      W->push_back(fmt::format(
          "{}{} row(s) repeat the previous row in every used column but the time stamp while "
          "the robot moves: duplicated rows (a logger writing the same sample twice); the "
          "derivatives are wrong there",
          file, c));
  }
  if (const Json* fr = rec.find("frozen_rows"); fr && fr->find("rows")) {
    const auto c = fr->find("rows")->asInt();
    if (c > 0)
      W->push_back(fmt::format(
          "{}{} row(s) in {} run(s) hold every joint position while the robot moves (the next "
          "step jumps): sample-and-hold positions; velocities and accelerations are wrong there",
          file, c, fr->find("runs") ? fr->find("runs")->asInt() : 0));
  }
  if (const Json* sat = rec.find("saturation"); sat && sat->isArray()) {
    for (std::size_t i = 0; i < sat->size(); ++i) {
      const Json& s = sat->at(i);
      const Json* f = s.find("fraction");
      if (!f || !f->isNumber() || f->asDouble() < kSaturationWarnFraction) continue;
      W->push_back(fmt::format(
          "{}torque column '{}' sits at its minimum or maximum ({:.6g} / {:.6g}) for {:.2f} % of "
          "the samples in runs of 3 or more: saturated (current limit, sensor range)? Those "
          "samples do not measure the dynamics",
          file, s.find("column") ? s.find("column")->asString() : "?",
          s.find("min") ? s.find("min")->asDouble() : NAN,
          s.find("max") ? s.find("max")->asDouble() : NAN, 100.0 * f->asDouble()));
    }
  }
}

}  // namespace

namespace {

/// The velocities, accelerations and torque the checks read: the data's own, or (when the data
/// has no qd or qdd) derived from q by a Savitzky-Golay fit that also smooths the torque.
struct Signals {
  MatrixXd qd, qdd, tau;
  bool has_tau = false;
  int sg_half_width = 0;  // > 0: qd (and qdd) derived from q by Savitzky-Golay over +-this
  // derived: alternativePositions and their derivatives, as the error estimate's second version
  MatrixXd alt_q, alt_qd, alt_qdd;
  bool derived_qd = false, derived_qdd = false;
};

/// A second version of the positions with an error of the same kind as theirs: where a joint's
/// positions are quantised (their resolution / sqrt(12) above their noise), the smoothed
/// positions quantised again on a grid shifted by half a step (a staircase error with the same
/// spectrum); otherwise the positions plus white noise of their own level. Derivatives of both
/// differ by about the error the positions' own derivatives carry. Fixed seed.
MatrixXd alternativePositions(const MatrixXd& q, const MatrixXd& smooth) {
  const Index K = q.rows();
  std::mt19937_64 rng(0x5eedu);
  std::normal_distribution<double> nz(0.0, 1.0);
  MatrixXd alt = q;
  for (Index j = 0; j < q.cols(); ++j) {
    double quantum = HUGE_VAL;
    for (Index k = 1; k < K; ++k) {
      const double d = std::abs(q(k, j) - q(k - 1, j));
      if (d > 0) quantum = std::min(quantum, d);
    }
    const double white = inspect_torque::noiseLevel(q.col(j));
    if (std::isfinite(quantum) && quantum / std::sqrt(12.0) > white) {
      for (Index k = 0; k < K; ++k)
        alt(k, j) = (std::floor(smooth(k, j) / quantum) + 0.5) * quantum;
    } else {
      for (Index k = 0; k < K; ++k) alt(k, j) += white * nz(rng);
    }
  }
  return alt;
}

/// Missing qd/qdd from q by a quadratic Savitzky-Golay fit, at kDifferentiateCutoffHz, or at half
/// that (down to kMinDifferentiateCutoffHz) while the accelerations' own error (estimated from
/// alternativePositions) is above kMaxDerivedAccelError of their RMS for some joint: coarse or
/// noisy positions get a narrower band, where their derivatives still mean something.
/// savitzkyGolay over each part of the data on its own (DatasetFacts::parts: no fit spans two
/// recordings), the results stacked.
void savitzkyGolayParts(const MatrixXd& X, const std::vector<PartRange>& parts, double dt, int m,
                        MatrixXd* value, MatrixXd* d1, MatrixXd* d2) {
  if (parts.size() < 2) return savitzkyGolay(X, dt, m, value, d1, d2);
  for (MatrixXd* M : {value, d1, d2})
    if (M) M->resize(X.rows(), X.cols());
  MatrixXd v, a, b;
  for (const PartRange& pr : parts) {
    const Index len = pr.end - pr.begin;
    savitzkyGolay(X.middleRows(pr.begin, len), dt, m, value ? &v : nullptr, d1 ? &a : nullptr,
                  d2 ? &b : nullptr);
    if (value) value->middleRows(pr.begin, len) = v;
    if (d1) d1->middleRows(pr.begin, len) = a;
    if (d2) d2->middleRows(pr.begin, len) = b;
  }
}

Signals deriveSignals(const Dataset& data, int n, double rate, double dt, Json& J) {
  Signals s;
  s.qd = data.qd;
  s.qdd = data.qdd;
  s.tau = data.tau;
  s.has_tau = data.hasTorque() && data.tau.cols() == n;
  if (!data.hasVelocity() || !data.hasAcceleration()) {
    double cutoff = kDifferentiateCutoffHz;
    const std::vector<PartRange> parts = partRanges(data.t, data.facts);
    Index K = data.size();  // (the shortest part's samples bound the fit's width)
    for (const PartRange& pr : parts) K = std::min<Index>(K, pr.end - pr.begin);
    int m = 0;
    MatrixXd v, a;
    double worst = 0;
    for (;;) {
      m = std::max(2, static_cast<int>(std::lround((1.5 * rate / cutoff + 4.6) / 3.2)));
      MatrixXd smooth;
      savitzkyGolayParts(data.q, parts, dt, m, &smooth, &v, &a);
      s.alt_q = alternativePositions(data.q, smooth);
      savitzkyGolayParts(s.alt_q, parts, dt, m, nullptr, &s.alt_qd, &s.alt_qdd);
      const MatrixXd& aa = s.alt_qdd;
      worst = 0;
      for (int j = 0; j < n; ++j) {
        const double ref = a.col(j).norm();
        if (ref > 0) worst = std::max(worst, (aa.col(j) - a.col(j)).norm() / ref);
      }
      if (!(worst > kMaxDerivedAccelError) || cutoff / 2 < kMinDifferentiateCutoffHz ||
          2 * m + 1 > K / 4)
        break;
      cutoff /= 2;
    }
    if (!data.hasVelocity()) s.qd = v;
    if (!data.hasAcceleration()) s.qdd = a;
    s.sg_half_width = m;
    s.derived_qd = !data.hasVelocity();
    s.derived_qdd = !data.hasAcceleration();
    if (s.has_tau) savitzkyGolayParts(data.tau, parts, dt, m, &s.tau, nullptr, nullptr);
    J["derivatives"] = fmt::format(
        "the data has no {}: derived from q by a quadratic Savitzky-Golay fit over +-{} samples "
        "(about {:g} Hz{}); the torque is smoothed by the same fit (zero phase){}",
        data.hasVelocity() ? "qdd" : "qd and qdd", m, cutoff,
        cutoff < kDifferentiateCutoffHz
            ? fmt::format(", lowered from {:g} Hz: the positions' resolution or noise left the "
                          "accelerations {:.0f} % error there",
                          kDifferentiateCutoffHz, 100 * kMaxDerivedAccelError)
            : std::string(),
        parts.size() > 1 ? "; each recording on its own" : "");
    J["derivatives_accel_error"] = worst;
  } else {
    J["derivatives"] = "qd and qdd from the data";
  }
  return s;
}

/// A stretch of samples that all move or all stand still.
struct MotionRun {
  bool moving;
  Index begin, end;  // [begin, end)
};

/// Per joint: the speed above which a sample counts as moving.
std::vector<double> velocityThresholds(const MatrixXd& qd, int n) {
  const Index K = qd.rows();
  std::vector<double> thr(static_cast<std::size_t>(n));
  for (int j = 0; j < n; ++j) {
    std::vector<double> a(static_cast<std::size_t>(K));
    for (Index k = 0; k < K; ++k) a[static_cast<std::size_t>(k)] = std::abs(qd(k, j));
    thr[static_cast<std::size_t>(j)] =
        std::max(kStandstillVelocityFraction * percentileOf(a, 0.99), kStandstillVelocityFloor);
  }
  return thr;
}

/// The stretches of moving and standing samples, those shorter than kMinSegmentS merged into
/// their neighbours.
std::vector<MotionRun> motionRuns(const std::vector<char>& moving, double dt) {
  const auto K = static_cast<Index>(moving.size());
  std::vector<MotionRun> runs;
  for (Index k = 0; k < K; ++k) {
    const bool mv = moving[static_cast<std::size_t>(k)] != 0;
    if (runs.empty() || runs.back().moving != mv)
      runs.push_back({mv, k, k + 1});
    else
      runs.back().end = k + 1;
  }
  auto lengthS = [&](const MotionRun& r) { return static_cast<double>(r.end - r.begin) * dt; };
  std::vector<MotionRun> merged;
  for (const MotionRun& r : runs) {
    if (!merged.empty() && (lengthS(r) < kMinSegmentS || r.moving == merged.back().moving))
      merged.back().end = r.end;
    else
      merged.push_back(r);
  }
  if (merged.size() > 1 && lengthS(merged[0]) < kMinSegmentS) {
    merged[1].begin = 0;
    merged.erase(merged.begin());
  }
  return merged;
}

/// J["motion"]: standstill and moving stretches. Returns per sample whether it moves (after the
/// merging) and counts the moving samples.
std::vector<char> motionCheck(const Dataset& data, const MatrixXd& qd, int n, double dt, Json& J,
                              Index* moving_samples) {
  const Index K = data.size();
  const std::vector<double> thr = velocityThresholds(qd, n);
  std::vector<char> moving(static_cast<std::size_t>(K), 0);
  for (Index k = 0; k < K; ++k)
    for (int j = 0; j < n; ++j)
      if (std::abs(qd(k, j)) > thr[static_cast<std::size_t>(j)])
        moving[static_cast<std::size_t>(k)] = 1;
  const std::vector<MotionRun> merged = motionRuns(moving, dt);
  Json standstill = Json::array(), movingS = Json::array();
  *moving_samples = 0;
  for (const MotionRun& r : merged) {
    (r.moving ? movingS : standstill).push_back(pair(data.t(r.begin), data.t(r.end - 1)));
    for (Index k = r.begin; k < r.end; ++k) moving[static_cast<std::size_t>(k)] = r.moving;
    if (r.moving) *moving_samples += r.end - r.begin;
  }
  Json& M = J["motion"];
  M["velocity_threshold"] = Json(thr);
  M["velocity_threshold_rule"] = fmt::format(
      "a sample moves when some joint's |qd| exceeds {:g} of its 99th percentile (and {:g} rad/s "
      "or m/s); stretches shorter than {:g} s are merged into their neighbours",
      kStandstillVelocityFraction, kStandstillVelocityFloor, kMinSegmentS);
  M["moving_fraction"] = static_cast<double>(*moving_samples) / static_cast<double>(K);
  M["moving_s"] = movingS;
  M["standstill_s"] = standstill;
  return moving;
}

/// One joint's position coverage and limits (entries of e), warning about samples outside the
/// limits. Returns whether the limits are known.
bool positionCoverage(const RobotModel& robot, const MatrixXd& qj, int j, Json& e,
                      std::vector<std::string>* W) {
  const Index K = qj.rows();
  const JointLimits& L = robot.limits[static_cast<std::size_t>(j)];
  const double lo = qj.col(j).minCoeff(), hi = qj.col(j).maxCoeff();
  e["position_range"] = pair(lo, hi);
  const bool qknown = L.q_max < kUnknownLimit && L.q_min > -kUnknownLimit && L.q_max > L.q_min;
  if (qknown) {
    e["position_limits"] = pair(L.q_min, L.q_max);
    e["position_coverage"] = (hi - lo) / (L.q_max - L.q_min);
    const double tol = 1e-9 * (L.q_max - L.q_min);
    Index outside = 0;
    for (Index k = 0; k < K; ++k) outside += qj(k, j) < L.q_min - tol || qj(k, j) > L.q_max + tol;
    const double frac = static_cast<double>(outside) / static_cast<double>(K);
    e["outside_limits_fraction"] = frac;
    if (frac > kOutsideLimitsWarnFraction)
      W->push_back(fmt::format(
          "joint {} ({}): {:.1f} % of the samples lie outside its position limits [{:.4g}, "
          "{:.4g}] (the data spans [{:.4g}, {:.4g}]): a wrong offset (offset_rad), sign or unit "
          "(q_scale) of q, or motor angles read without the robot's transmission?",
          j + 1, robot.bodies[static_cast<std::size_t>(robot.actuatedJoint(j))].joint_name,
          100.0 * frac, L.q_min, L.q_max, lo, hi));
  } else {
    e["position_limits"] = Json();
    e["position_coverage"] = Json();
  }
  return qknown;
}

/// Per joint: the covered share of its position and velocity limits (joint coordinates), with
/// warnings about motion outside them.
std::vector<Json> coverageRows(const RobotModel& robot, const Dataset& data, const MatrixXd& qd,
                               std::vector<std::string>* W) {
  const int n = robot.dof();
  // joint coordinates, as measuredToJoint maps each sample: q = T qm + offset, qd = T qdm
  check(data.q.cols() == n && qd.cols() == n,
        fmt::format("inspection: q and qd have {} and {} columns, expected {}", data.q.cols(),
                    qd.cols(), n));
  MatrixXd qj = robot.hasTransmission() ? MatrixXd(data.q * robot.transmission.transpose())
                                        : MatrixXd(data.q);
  const MatrixXd qdj =
      robot.hasTransmission() ? MatrixXd(qd * robot.transmission.transpose()) : MatrixXd(qd);
  if (robot.transmission_offset.size() == n) qj.rowwise() += robot.transmission_offset.transpose();
  std::vector<Json> jrows;
  for (int j = 0; j < n; ++j) {
    const JointLimits& L = robot.limits[static_cast<std::size_t>(j)];
    Json e = Json::object();
    e["joint"] = j + 1;
    e["name"] = robot.bodies[static_cast<std::size_t>(robot.actuatedJoint(j))].joint_name;
    const bool qknown = positionCoverage(robot, qj, j, e, W);
    const double vmax = qdj.col(j).cwiseAbs().maxCoeff();
    e["velocity_max"] = vmax;
    const bool vknown = L.qd_max < kUnknownLimit && L.qd_max > 0;
    e["velocity_limit"] = vknown ? Json(L.qd_max) : Json();
    e["velocity_coverage"] = vknown ? Json(vmax / L.qd_max) : Json();
    e["limits"] = qknown && vknown ? "known"
                  : qknown         ? "velocity limit unknown"
                  : vknown         ? "position limits unknown"
                                   : "unknown";
    if (vknown && vmax > 1.5 * L.qd_max)
      W->push_back(fmt::format(
          "joint {} ({}): moves at up to {:.2f} times its velocity limit {:.4g}: a wrong unit of "
          "q (q_scale), motor angles read without the robot's transmission, or a wrong sample "
          "period?",
          j + 1, robot.bodies[static_cast<std::size_t>(robot.actuatedJoint(j))].joint_name,
          vmax / L.qd_max, L.qd_max));
    jrows.push_back(e);
  }
  return jrows;
}

/// The nominal model's torque without friction at every sample (pred: rigid bodies and rotor
/// inertia) and, at the standing samples, its torque at rest (pred_rest; zero where moving). The
/// checks put friction columns of their own beside it (inspect_torque.cpp): the description's
/// Coulomb term, sign(qd), flips at random where a derived velocity hovers around zero (coarse
/// positions, a standstill), which no check should read as the torque's fault. The samples in
/// two halves on two threads (each sample's torque is the same on either).
void predictTorque(const RobotModel& robot, const Dataset& data, const Signals& sig,
                   const std::vector<char>& moving, MatrixXd* pred, MatrixXd* pred_rest) {
  const int n = robot.dof();
  const Index K = data.size();
  DriveColumns cols;
  cols.rotor_inertia = true;
  pred->resize(K, n);
  *pred_rest = MatrixXd::Zero(K, n);
  auto part = [&](Index k0, Index k1) {
    auto dd = makeDynamicsData(robot);
    const VectorXd zero = VectorXd::Zero(n);
    VectorXd qk(n), qdk(n), qddk(n);
    for (Index k = k0; k < k1; ++k) {
      qk = data.q.row(k).transpose();
      qdk = sig.qd.row(k).transpose();
      qddk = sig.qdd.row(k).transpose();
      pred->row(k) = actuatorTorque(robot, *dd, cols, qk, qdk, qddk).transpose();
      if (!moving[static_cast<std::size_t>(k)])
        pred_rest->row(k) = actuatorTorque(robot, *dd, cols, qk, zero, zero).transpose();
    }
  };
  std::future<void> first = std::async(std::launch::async, part, Index{0}, K / 2);
  part(K / 2, K);
  first.get();
}

/// Per joint, the std of the nominal model's torque that comes from the position error through
/// derived velocities and accelerations (zero when the data has them): the prediction from
/// alternativePositions, differentiated the same way, against the prediction; the change's RMS
/// over the moving samples (for quantised positions an upper bound, by up to sqrt(2)).
VectorXd predictionNoise(const RobotModel& robot, const Dataset& data, const Signals& sig,
                         const std::vector<char>& moving, const MatrixXd& pred) {
  const int n = robot.dof();
  VectorXd out = VectorXd::Zero(n);
  if (!sig.derived_qd && !sig.derived_qdd) return out;
  const Index K = data.size();
  // (the second version deriveSignals made when it chose the band)
  Dataset alt;
  alt.t = data.t;
  alt.q = sig.alt_q;
  Signals as = sig;
  if (sig.derived_qd) as.qd = sig.alt_qd;
  if (sig.derived_qdd) as.qdd = sig.alt_qdd;
  MatrixXd p2, p2_rest;
  predictTorque(robot, alt, as, moving, &p2, &p2_rest);
  for (int j = 0; j < n; ++j) {
    double ss = 0;
    Index m = 0;
    for (Index k = 0; k < K; ++k)
      if (moving[static_cast<std::size_t>(k)]) {
        ss += (p2(k, j) - pred(k, j)) * (p2(k, j) - pred(k, j));
        ++m;
      }
    out(j) = m > 0 ? std::sqrt(ss / static_cast<double>(m)) : 0.0;
  }
  return out;
}

/// sqrt of the extreme eigenvalues' ratio of a symmetric matrix (inf when singular).
double conditionOfGram(const MatrixXd& A) {
  Eigen::SelfAdjointEigenSolver<MatrixXd> es(A, Eigen::EigenvaluesOnly);
  const VectorXd& ev = es.eigenvalues();
  if (ev.size() == 0) return static_cast<double>(NAN);
  const double lmax = ev(ev.size() - 1), lmin = ev(0);
  return lmin > 0 && lmax > 0 ? std::sqrt(lmax / lmin) : HUGE_VAL;
}

/// W^T W of the model's base regressor over the recording, built block by block.
MatrixXd regressorGram(const ObservationModel& model, const Dataset& data, const Signals& sig,
                       const RunContext& ctx, Index stride, long long* rows) {
  const int p = model.numBase();
  MatrixXd G = MatrixXd::Zero(p, p);
  *rows = 0;
  // (each part of the data on its own: no block spans two recordings)
  for (const PartRange& pr : partRanges(data.t, data.facts)) {
    const Index K = (pr.end - pr.begin + stride - 1) / stride;  // samples used: 0, stride, ...
    for (Index k0 = 0; k0 < K; k0 += kRegressorBlockSamples) {
      if (ctx.shouldStop()) throw std::runtime_error("stopped");
      const Index m = std::min<Index>(kRegressorBlockSamples, K - k0);
      // the block's samples: pr.begin + (k0, k0 + 1, ..., k0 + m - 1) * stride
      const auto used = Eigen::seqN(pr.begin + k0 * stride, m, stride);
      Samples s;
      s.t = data.t(used);
      s.q = data.q(used, Eigen::all);
      s.qd = sig.qd(used, Eigen::all);
      s.qdd = sig.qdd(used, Eigen::all);
      if (data.base.size() > 0) s.base = data.base(used, Eigen::all);  // a floating base
      const MatrixXd Wb = model.design(s);
      G.selfadjointView<Eigen::Lower>().rankUpdate(Wb.transpose());
      *rows += Wb.rows();
    }
  }
  G = G.selfadjointView<Eigen::Lower>();
  return G;
}

/// R = J["regressor"]: the condition number of the model's base regressor on the recording.
void regressorCheck(const ObservationModel& model, const Dataset& data, const Signals& sig,
                    const RunContext& ctx, long max_samples, Json& R, std::vector<std::string>* W) {
  R["model"] = model.pluginName();
  R["base_columns"] = model.numBase();
  try {
    const int p = model.numBase();
    const Index K = data.size();
    const Index stride =
        max_samples > 0 ? std::max<Index>(1, (K + max_samples - 1) / max_samples) : 1;
    if (stride > 1) {
      R["stride"] = static_cast<long long>(stride);
      R["samples_used"] = static_cast<long long>((K + stride - 1) / stride);
    }
    long long rows = 0;
    const MatrixXd G = regressorGram(model, data, sig, ctx, stride, &rows);
    const double c_raw = conditionOfGram(G);
    VectorXd sc(p);
    bool zero_col = false;
    for (int i = 0; i < p; ++i) {
      zero_col = zero_col || !(G(i, i) > 0);
      sc(i) = G(i, i) > 0 ? 1.0 / std::sqrt(G(i, i)) : 0.0;
    }
    const double c_scaled =
        zero_col ? HUGE_VAL : conditionOfGram(sc.asDiagonal() * G * sc.asDiagonal());
    R["rows"] = rows;
    R["cond"] = numberOrNull(c_raw);
    R["cond_scaled"] = numberOrNull(c_scaled);
    R["rank_deficient"] = !std::isfinite(c_scaled);
    R["method"] = fmt::format(
        "sqrt of the extreme eigenvalues of W^T W (base columns; scaled: each column to unit "
        "norm){}; reliable up to about 1e7",
        stride > 1 ? fmt::format(", W from one sample in {}", stride) : std::string());
    if (!std::isfinite(c_scaled))
      W->push_back(fmt::format(
          "the recording does not excite every base parameter of model '{}' (the regressor's "
          "{} base columns are rank deficient): more or other motion is needed",
          model.pluginName(), p));
    else if (c_scaled > kCondWarn)
      W->push_back(fmt::format(
          "the regressor of model '{}' on this recording has condition number {:.3g} (columns "
          "scaled to unit norm; above {:g}): some base parameters are poorly excited",
          model.pluginName(), c_scaled, kCondWarn));
  } catch (const std::exception& e) {
    R["cond"] = Json();
    R["cond_scaled"] = Json();
    R["note"] = fmt::format("not computed: {}", e.what());
  }
}

}  // namespace

Json inspectDataset(const RobotModel& robot, const ObservationModel* model, const Dataset& data,
                    const RunContext& ctx, long regressor_max_samples) {
  Json J = Json::object();
  std::vector<std::string> W;
  const int n = robot.dof();
  const Index K = data.size();
  J["source"] = data.source;
  J["samples"] = static_cast<long long>(K);
  J["duration_s"] = K > 0 ? data.t(K - 1) - data.t(0) : 0.0;
  J["simulated"] = data.facts.simulated.has_value();
  if (const Json* rec = data.meta.find("recording")) {
    J["recording"] = *rec;
    recordingWarnings(*rec, &W);
  }
  if (data.facts.parts.size() > 1) {  // several recordings: each one's timing, and where it is
    Json parts = Json::array();
    const Json* pm = data.meta.find("parts");
    for (const PartRange& pr : partRanges(data.t, data.facts)) {
      const DatasetPart& dp = data.facts.parts[static_cast<std::size_t>(pr.part)];
      Json e = Json::object();
      e["part"] = pr.part + 1;
      e["source"] = dp.source;
      e["samples_inspected"] = pr.end - pr.begin;
      e["t_s"] = pair(data.t(pr.begin), data.t(pr.end - 1));
      const Json* m = pm && pm->isArray() && static_cast<std::size_t>(pr.part) < pm->size()
                          ? pm->at(static_cast<std::size_t>(pr.part)).find("meta")
                          : nullptr;
      if (const Json* rec = m ? m->find("recording") : nullptr) {
        e["recording"] = *rec;
        recordingWarnings(*rec, &W);
      }
      parts.push_back(std::move(e));
    }
    J["parts"] = std::move(parts);
  }
  auto finish = [&]() {
    J["warnings"] = Json(W);
    return J;
  };
  if (K < 5 || data.q.cols() != n || data.q.rows() != K) {
    J["note"] = fmt::format("{} samples of {} joints: too few to inspect", K, data.q.cols());
    return finish();
  }
  {
    std::vector<double> t(data.t.data(), data.t.data() + K);
    std::vector<int> rows(static_cast<std::size_t>(K));
    for (Index k = 0; k < K; ++k) rows[static_cast<std::size_t>(k)] = static_cast<int>(k);
    J["timing"] = samplingStats(t, 1.0, rows, 1.5);
  }
  const double rate = J["timing"].find("rate_hz")->asDouble();
  const double dt = 1.0 / rate;
  J["rate_hz"] = rate;

  const Signals sig = deriveSignals(data, n, rate, dt, J);
  // The regressor's Gram matrix (the costliest check) on its own thread, beside the others; its
  // result and warnings are put in their place afterwards (the same output in the same order).
  Json regressor = Json::object();
  std::vector<std::string> regressor_warnings;
  std::future<void> regressor_done;
  if (model)
    regressor_done = std::async(std::launch::async, [&] {
      regressorCheck(*model, data, sig, ctx, regressor_max_samples, regressor, &regressor_warnings);
    });
  Index moving_samples = 0;
  const std::vector<char> moving = motionCheck(data, sig.qd, n, dt, J, &moving_samples);
  std::vector<Json> jrows = coverageRows(robot, data, sig.qd, &W);

  (void)moving_samples;
  if (!sig.has_tau || robot.floating_base) {
    // (a floating base: the torque checks predict fixed-base torques; not done)
    const char* why = robot.floating_base
                          ? "a floating-base robot (the torque checks predict fixed-base torques)"
                          : "the data has no torque";
    J["sign_check"] = Json();
    J["sign_check_note"] = why;
    J["delay"]["delay_samples"] = Json();
    J["delay"]["delay_s"] = Json();
    J["delay"]["note"] = why;
    J["delay"]["verdict"] = std::string("not checkable here: ") + why;
  } else {
    MatrixXd pred, pred_rest;
    predictTorque(robot, data, sig, moving, &pred, &pred_rest);
    const VectorXd pred_noise = predictionNoise(robot, data, sig, moving, pred);
    inspect_torque::Input in;
    in.pred_noise = &pred_noise;
    in.tau = &sig.tau;
    in.tau_raw = &data.tau;
    in.pred = &pred;
    in.pred_rest = &pred_rest;
    in.qd = &sig.qd;
    in.moving = &moving;
    in.dt = dt;
    const std::vector<char> usable = inspect_torque::signCheck(in, &jrows, &W);
    // The delay from the samples whose derived q-dot and q-ddot come from a centred fit: with
    // Savitzky-Golay derivatives, not within its half-width of an end of the recording (an
    // off-centre fit there) nor of a start or stop of the motion (a window across it smooths the
    // onset on both sides, which a lag can mimic).
    std::vector<char> moving_delay = moving;
    if (sig.sg_half_width > 0) {
      const Index M = static_cast<Index>(moving.size()), h = sig.sg_half_width;
      auto clear = [&](Index a, Index b) {
        for (Index k = std::max<Index>(0, a); k < std::min(M, b); ++k)
          moving_delay[static_cast<std::size_t>(k)] = 0;
      };
      clear(0, h);
      clear(M - h, M);
      for (const PartRange& pr : partRanges(data.t, data.facts))
        if (pr.begin > 0) clear(pr.begin - h, pr.begin + h);  // the ends of each recording
      for (Index k = 1; k < M; ++k)
        if (moving[static_cast<std::size_t>(k)] != moving[static_cast<std::size_t>(k - 1)])
          clear(k - h, k + h);
    }
    inspect_torque::Input in_delay = in;
    in_delay.moving = &moving_delay;
    inspect_torque::delayCheck(in_delay, usable, J["delay"], &W);
  }
  {
    Json joints = Json::array();
    for (const Json& e : jrows) joints.push_back(e);
    J["joints"] = joints;
  }
  if (model) {
    regressor_done.get();  // (regressorCheck catches its own errors)
    J["regressor"] = std::move(regressor);
    W.insert(W.end(), regressor_warnings.begin(), regressor_warnings.end());
  }
  return finish();
}

std::vector<std::string> experimentWarnings(const Dataset& data, const std::string& what) {
  std::vector<std::string> out;
  if (const Json* w = data.meta.find("warnings"); w && w->isArray())
    for (std::size_t i = 0; i < w->size(); ++i) out.push_back(what + ": " + w->at(i).asString());
  return out;
}

Json inspectExperimentData(const RobotModel& robot, const ObservationModel* model,
                           const Dataset& data, const RunContext& ctx, const std::string& what) {
  Json J = inspectDataset(robot, model, data, ctx);
  if (const Json* a = data.meta.find("accounting")) J["accounting"] = *a;
  if (const Json* t = data.meta.find("topics")) J["topics"] = *t;  // a bag's topics
  if (const Json* n = data.meta.find("notes")) J["notes"] = *n;
  // several recordings: each one's accounting and topics with its part
  const Json* pm = data.meta.find("parts");
  if (const Json* parts = J.find("parts"); parts && pm && pm->isArray()) {
    Json with = Json::array();
    for (std::size_t i = 0; i < parts->size(); ++i) {
      Json e = parts->at(i);
      const auto k = static_cast<std::size_t>(e.find("part")->asInt() - 1);
      const Json* m = k < pm->size() ? pm->at(k).find("meta") : nullptr;
      for (const char* key : {"accounting", "topics"})  // (notes: the data's, with their part)
        if (const Json* x = m ? m->find(key) : nullptr) e[key] = *x;
      with.push_back(std::move(e));
    }
    J["parts"] = std::move(with);
  }
  std::vector<std::string> W = experimentWarnings(data, what);
  if (const Json* w = J.find("warnings"))
    for (std::size_t i = 0; i < w->size(); ++i) W.push_back(w->at(i).asString());
  J["warnings"] = Json(W);
  return J;
}

namespace {

// A number of the inspection's JSON as text ("-" when absent), and a fraction as a percentage.
std::string num(const Json* j, const char* f = "{:.4g}") {
  return j && j->isNumber() ? fmt::format(fmt::runtime(f), j->asDouble()) : std::string("-");
}
std::string pct(const Json* j) {
  return j && j->isNumber() ? fmt::format("{:.0f} %", 100.0 * j->asDouble()) : std::string("-");
}

// The recording's lines: rate, jitter and gaps; duplicate, frozen and held rows; saturation.
std::string recordingText(const Json& rec) {
  std::string out;
  const Json* t = rec.find("timing");
  if (t && t->find("source") && t->find("source")->asString() == "sample_period_s") {
    out += fmt::format(
        "recording: {} Hz (sample_period_s: no time stamps, so no jitter or gaps to measure)\n",
        num(t->find("rate_hz"), "{:.10g}"));
  } else if (t) {
    const Json* jit = t->find("jitter");
    const Json* g = t->find("gaps");
    out += fmt::format("recording: {} Hz ({}), jitter {} std / {} max (relative), gaps {}\n",
                       num(t->find("rate_hz"), "{:.10g}"),
                       t->find("source") ? t->find("source")->asString() : "time stamps",
                       jit ? num(jit->find("std_rel"), "{:.2e}") : "-",
                       jit ? num(jit->find("max_rel"), "{:.2e}") : "-",
                       g ? num(g->find("count"), "{:.0f}") : "-");
  }
  const Json* dup = rec.find("duplicate_rows");
  const Json* fr = rec.find("frozen_rows");
  const Json* rest = rec.find("held_at_rest");
  out += fmt::format(
      "rows while moving: {} duplicate, {} frozen (sample-and-hold); held at rest: {}\n",
      dup ? num(dup->find("count"), "{:.0f}") : "-", fr ? num(fr->find("rows"), "{:.0f}") : "-",
      rest ? num(rest->find("rows"), "{:.0f}") : "-");
  if (const Json* sat = rec.find("saturation"); sat && sat->isArray()) {
    std::string s;
    for (std::size_t i = 0; i < sat->size(); ++i) {
      const Json& c = sat->at(i);
      const Json* f = c.find("fraction");
      if (!f || !f->isNumber() || f->asDouble() <= 0) continue;
      s +=
          fmt::format("{}{} {:.2f} %", s.empty() ? "" : ", ",
                      c.find("column") ? c.find("column")->asString() : "?", 100.0 * f->asDouble());
    }
    out += "saturated torque samples: " + (s.empty() ? std::string("none") : s) + "\n";
  }
  return out;
}

// The motion's line: the moving fraction, the moving and standstill segments (the first six).
std::string motionText(const Json& m) {
  std::string out;
  auto segs = [&](const Json* s) {
    std::string r;
    if (!s) return r;
    for (std::size_t i = 0; i < s->size(); ++i) {
      if (i == 6) {
        r += fmt::format(" ... ({} in all)", s->size());
        break;
      }
      r += fmt::format("{}[{:.3f}, {:.3f}]", i ? " " : "", s->at(i).at(0).asDouble(),
                       s->at(i).at(1).asDouble());
    }
    return r.empty() ? std::string("none") : r;
  };
  out += fmt::format("motion: moving {} of the time\n  moving s: {}\n  standstill s: {}\n",
                     pct(m.find("moving_fraction")), segs(m.find("moving_s")),
                     segs(m.find("standstill_s")));
  return out;
}

// What the experiment said of one recording (the data's, or a part's of several): its timing,
// where its samples went, notes, and a bag's topics.
std::string recordingFileText(const Json& F) {
  std::string out;
  if (const Json* rec = F.find("recording")) out += recordingText(*rec);
  if (const Json* a = F.find("accounting"); a && a->isObject()) {
    std::string s;
    for (const auto& [k, v] : a->items())
      if (v.isNumber()) s += fmt::format("{}{} {}", s.empty() ? "" : ", ", k, v.dump(0));
    out += "samples: " + s + "\n";
  }
  if (const Json* n = F.find("notes"); n && n->isArray())
    for (std::size_t i = 0; i < n->size(); ++i) out += "note: " + n->at(i).asString() + "\n";
  if (const Json* ts = F.find("topics"); ts && ts->isArray()) {
    out += "topics of the bag:\n";
    for (std::size_t i = 0; i < ts->size(); ++i) {
      const Json& t = ts->at(i);
      out += fmt::format("  {}  {}  {} messages  {} Hz  {} publisher(s)  {}\n",
                         t.find("topic")->asString(), t.find("type")->asString(),
                         num(t.find("messages"), "{:.0f}"), num(t.find("rate_hz"), "{:.4g}"),
                         num(t.find("publishers"), "{:.0f}"), t.find("used_as")->asString());
    }
  }
  return out;
}

}  // namespace

std::string inspectionText(const Json& J) {
  std::string out;
  out += fmt::format("data: {} ({} samples, {} s)\n",
                     J.find("source") ? J.find("source")->asString() : "?",
                     num(J.find("samples"), "{:.0f}"), num(J.find("duration_s")));
  if (const Json* parts = J.find("parts"); parts && parts->isArray())
    for (std::size_t i = 0; i < parts->size(); ++i) {
      const Json& e = parts->at(i);
      out += fmt::format("part {}: {} ({} samples, t {} .. {} s)\n", num(e.find("part"), "{:.0f}"),
                         e.find("source") ? e.find("source")->asString() : "?",
                         num(e.find("samples_inspected"), "{:.0f}"),
                         e.find("t_s") ? num(&e.find("t_s")->at(0)) : "-",
                         e.find("t_s") ? num(&e.find("t_s")->at(1)) : "-");
      out += recordingFileText(e);
    }
  out += recordingFileText(J);
  if (const Json* t = J.find("timing"))
    out += fmt::format("data as used: {} Hz\n", num(t->find("rate_hz"), "{:.10g}"));
  if (const Json* d = J.find("derivatives")) out += "derivatives: " + d->asString() + "\n";
  if (const Json* m = J.find("motion")) out += motionText(*m);
  if (const Json* js = J.find("joints")) {
    out += "joint  range covered  |qd| covered  gain +- std      noise  model signal  verdict\n";
    for (std::size_t i = 0; i < js->size(); ++i) {
      const Json& e = js->at(i);
      const Json* s = e.find("sign_check");
      out += fmt::format("{:>5}  {:>13}  {:>12}  {:>15}  {:>5}  {:>12}  {}\n",
                         e.find("joint")->asInt(), pct(e.find("position_coverage")),
                         pct(e.find("velocity_coverage")),
                         s ? fmt::format("{} +- {}", num(s->find("gain"), "{:.2f}"),
                                         num(s->find("gain_std"), "{:.2f}"))
                           : "-",
                         s ? num(s->find("noise"), "{:.2g}") : "-",
                         s ? num(s->find("model_signal"), "{:.3g}") : "-",
                         s && s->find("verdict") ? s->find("verdict")->asString() : "-");
    }
  }
  if (const Json* d = J.find("delay")) {
    if (d->find("delay_samples") && d->find("delay_samples")->isNumber())
      out += fmt::format(
          "delay: {:.2f} +- {} samples = {:.4g} s (positive: measured torque lags the model; "
          "joints spread {} s; {}){}\n",
          d->find("delay_samples")->asDouble(), num(d->find("std_samples"), "{:.2f}"),
          d->find("delay_s")->asDouble(), num(d->find("per_joint_spread_s"), "{:.2g}"),
          d->find("reported") && d->find("reported")->asBool() ? std::string("reported")
          : d->find("verdict") && d->find("verdict")->asString() != "none found"
              ? d->find("verdict")->asString()
              : std::string("not reported: not significant, not consistent, or no better fit"),
          d->find("at_window_edge") && d->find("at_window_edge")->asBool()
              ? " [at the edge of the window]"
              : "");
    else
      out += fmt::format("delay: - ({})\n",
                         d->find("note") ? d->find("note")->asString() : "not estimated");
  }
  if (const Json* r = J.find("regressor")) {
    out += fmt::format("regressor ({}, {} base columns): cond {}, with unit-norm columns {}{}\n",
                       r->find("model") ? r->find("model")->asString() : "?",
                       num(r->find("base_columns"), "{:.0f}"), num(r->find("cond"), "{:.4g}"),
                       num(r->find("cond_scaled"), "{:.4g}"),
                       r->find("note") ? " (" + r->find("note")->asString() + ")" : "");
  }
  const Json* w = J.find("warnings");
  if (w && w->size() > 0) {
    out += "warnings:\n";
    for (std::size_t i = 0; i < w->size(); ++i) out += "  - " + w->at(i).asString() + "\n";
  } else {
    out += "warnings: none\n";
  }
  return out;
}

}  // namespace exid
