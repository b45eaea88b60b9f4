// exid — estimator `gains_ls`: the parameters of the recorded torque's own columns (drive gains
// dK_j, load-dependent Coulomb FcL_j) identified with the base parameters, the recorded torque
// in the measurement only (docs/estimators.md, "gains_ls").
//
// The `differential` model's torque columns hold the recorded torque itself: with drive_gains
// the rows of joint j are tau_j - p_j = w theta - dK_j tau_j (p_j the known payload's torque,
// the payload part only); with coulomb_load, tau_j = w theta + FcL_j |tau_j| sign(qdm_j). Least
// squares on such rows has errors in variables: the column's noise is the measurement's. Both
// are one form, a_i = -W(i, c) / tau_i per row (dK: a = 1; FcL: a = -sign(tau qdm)):
//   tau_i (1 + a_i phi_c) = w_i theta + p_i,   i.e.   tau_i = g_i (w_i theta + p_i),
//   g_i = 1 / (1 + a_i phi_c)   (phi_c = dK_j or FcL_j),
// bilinear in (theta, phi) once the rows are grouped by (equation, a). Everything the fit needs
// is in per-group sums taken in one pass: with u = [w, p, tau] per row, S = sum u u^T. The
// residual sum of squares, its gradient and the Gauss-Newton matrix of (theta, phi) follow
// exactly from the S, so Levenberg-Marquardt runs on them without another pass. Covariance
// sigma^2 H^-1 at the optimum, sigma^2 = rss / (m - p).
//
// Starts (`starts`, default 3): LM runs from the first start (least squares on the rows, or the
// gain prior's mean) and from starts on both sides of it, every torque column's parameter
// shifted by -+ start_spread, -+ start_spread / 2, -+ 2 start_spread (theta by least squares at
// each); the lowest objective is kept, and "converged" needs its first-order test. The shift is
// common to the columns: the gains' common scale is the direction the data fix least (without a
// payload part, not at all). The sums make a start cost no pass over the data.
//
// A prior on the gains (gain_prior_std, gain_prior_dK: a datasheet's torque constants and their
// tolerance) adds the pseudo-observations sigma (dK_j - mu_j) / s_j, sigma the data's noise std
// (from the fit, to a fixed point), so the objective is the negative log posterior times
// sigma^2 and sigma^2 H^-1 the posterior covariance. With drive_gains_scale: prior (no payload
// part) the data fix the gains' ratios and the prior alone their common scale.
#include "gains_ls.hpp"

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <map>
#include <tuple>

#include "exid/drive.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"

namespace exid::gains_ls {

std::vector<exid::ParamDecl> GainsLs::params() {
  return {
      exid::param_int("max_iterations", 100, "Levenberg-Marquardt steps at most", 1, 10000),
      exid::param_double("step_tolerance", 1e-12, "",
                         "stop when the largest relative step is below this", 0.0, 1.0, true),
      exid::param_double("gradient_tolerance", 1e-6, "",
                         "first-order test of convergence: a Gauss-Newton step from the result "
                         "would lower the objective by at most this fraction of it (or the "
                         "fit is exact to the sums' precision, rss <= 1e-12 sum tau^2)",
                         0.0, 1.0, true),
      exid::param_int("starts", 3,
                      "Levenberg-Marquardt starts, the best kept: the first (least squares on "
                      "the rows, or the gain prior's mean), then every torque column's "
                      "parameter shifted by -start_spread, +start_spread, -start_spread/2, "
                      "+start_spread/2, -2 start_spread, +2 start_spread",
                      1, 7),
      exid::param_double("start_spread", 0.25, "",
                         "the starts' shift of dK (a relative gain error) and FcL (a fraction "
                         "of the recorded torque)",
                         0.0, 0.45, true),
      exid::param_int("chunk_samples", 4096, "samples per chunk passed to the model", 1, 1e9),
      exid::estimators::rankToleranceParam(),
      exid::param_doubles("gain_prior_std", std::vector<double>{}, "",
                          "prior std of each drive's dK (one value: every drive; empty: no "
                          "prior), e.g. a datasheet torque constant's relative tolerance"),
      exid::param_doubles("gain_prior_dK", std::vector<double>{}, "",
                          "prior mean of each drive's dK (one value: every drive; empty: 0, "
                          "the recorded torque is the true one)"),
  };
}

GainsLs::GainsLs(const exid::ParamSet& p)
    : max_iter_(static_cast<int>(p.getInt("max_iterations"))),
      xtol_(p.getDouble("step_tolerance")),
      gtol_(p.getDouble("gradient_tolerance")),
      starts_(static_cast<int>(p.getInt("starts"))),
      spread_(p.getDouble("start_spread")),
      chunk_(static_cast<int>(p.getInt("chunk_samples"))),
      rank_tol_(p.getDouble("rank_tolerance")),
      prior_std_(p.getDoubles("gain_prior_std")),
      prior_mean_(p.getDoubles("gain_prior_dK")) {
  exid::estimators::checkGainPrior(prior_std_, prior_mean_, "gains_ls");
}

exid::Estimate GainsLs::estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                                 const exid::Prior* prior, const exid::RunContext& ctx) {
  const auto t0 = std::chrono::steady_clock::now();
  exid::check(prior == nullptr,
              "gains_ls: the study's prior is not supported (a prior on the gains: "
              "gain_prior_std, gain_prior_dK)");
  split(model);
  setPrior(model);
  const Sums S = accumulate(model, data, ctx);
  Fit f = solve(S);
  return finish(model, S, f, t0);
}

exid::Estimate GainsLs::finish(const exid::ObservationModel& model, const Sums& S, const Fit& f,
                               std::chrono::steady_clock::time_point t0) const {
  exid::Json per_eq = exid::Json::array();
  const exid::estimators::LsSolution s = solution(model, S, f, &per_eq);
  exid::Estimate e;
  exid::estimators::fillEstimate(&e, model, s, f.rss, S.m);
  exid::Json& d = e.details;
  d["estimator"] = kName;
  d["method"] =
      "tau_i = (w_i theta + p_i) / (1 + a_i phi) per row (phi = dK_j: a = 1; phi = FcL_j: a = "
      "-sign(tau qdm)), bilinear least squares with the recorded torque in the measurement only "
      "(no errors in variables), Levenberg-Marquardt on per-group sums of one pass";
  d["covariance_definition"] =
      hasPrior() ? "H^-1 (sum_e sigma_e^2 J_e^T J_e + sigma^2 (sigma^2 / s^2) on the gains) "
                   "H^-1 of (theta, phi), H = J^T J + sigma^2 / s^2 on the gains (their "
                   "prior), sigma^2 = rss / (m - p) at its fixed point, per equation e (a "
                   "joint) sigma_e^2 = rss_e / m_e * m / (m - p) (details.noise_per_equation); "
                   "with equal sigma_e the posterior sigma^2 H^-1"
                 : "H^-1 (sum_e sigma_e^2 J_e^T J_e) H^-1 of (theta, phi), H = J^T J, per "
                   "equation e (a joint) sigma_e^2 = rss_e / m_e * m / (m - p) "
                   "(details.noise_per_equation); with equal sigma_e it is sigma^2 H^-1";
  if (per_eq.size() > 0) d["noise_per_equation"] = per_eq;
  describeTorqueColumns(model, s, f, &d);
  describeStarts(model, f, &d);
  d["iterations"] = f.iterations;
  d["stop"] = f.stop;
  d["converged"] = f.converged;
  d["gradient_norm"] = f.gradient_norm;
  d["gauss_newton_fraction"] = f.gn_fraction;
  d["convergence_test"] = fmt::format(
      "converged: at the start of lowest objective (details.starts), a stop test held and a "
      "Gauss-Newton step would lower the objective by at most gradient_tolerance = {:g} of it "
      "(or rss <= 1e-12 sum tau^2); gradient_norm = ||d objective / d(theta, phi)||",
      gtol_);
  d["memory"] =
      "per group of rows (equation, sign) a (p + 2)^2 factor, whatever the number of samples";
  d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!f.converged) {
    exid::Json w = exid::Json::array();
    w.push_back(exid::Json(fmt::format(
        "gains_ls: not converged: from start {} of {} ({}), the lowest objective of the "
        "starts, stopped after {} iterations at {} with rss {:.6g}, gradient norm {:.3g} (a "
        "Gauss-Newton step would remove {:.2g} of the objective; gradient_tolerance = {:g}): "
        "{}",
        f.best + 1, f.starts.size(), startName(f, f.best), f.iterations,
        exid::estimators::describePoint(e.names, e.value), f.rss, f.gradient_norm, f.gn_fraction,
        gtol_, f.stop)));
    d["warnings"] = w;
  }
  return e;
}

// The solution at the fit f: the checks (no load term on its degenerate branch, a regular
// Gauss-Newton matrix), theta and phi in base order, their covariance and the Jacobian's
// singular values; per_eq: the noise std per equation.
exid::estimators::LsSolution GainsLs::solution(const exid::ObservationModel& model, const Sums& S,
                                               const Fit& f, exid::Json* per_eq) const {
  const int p = model.numBase(), p0 = static_cast<int>(other_cols_.size()),
            ng = static_cast<int>(gain_cols_.size());
  exid::check(S.m > p, fmt::format("gains_ls: {} rows for {} parameters", S.m, p));
  // A load term at |FcL| -> 1 is the fit's degenerate branch, not friction: the groups follow
  // the recorded torque's sign, and where noise flips it often (a drive whose torque is near
  // its noise) one group's 1 + a FcL goes to 0.
  for (int k = 0; k < ng; ++k)
    exid::check(
        is_gain_[static_cast<std::size_t>(k)] || std::abs(f.phi[k]) < 0.9,
        fmt::format(
            "gains_ls: '{}' went to {:.6g}, the degenerate branch 1 +- FcL -> "
            "0: the recorded torque of this drive is near its noise, so its "
            "sign (which the load term follows) is not known; leave the drive "
            "out (the model's joints) or fit it with batch_ls",
            model.base().names[static_cast<std::size_t>(gain_cols_[static_cast<std::size_t>(k)])],
            f.phi[k]));
  // the Gauss-Newton matrix must be regular (column-scaled)
  Eigen::VectorXd sc = f.H.diagonal().cwiseMax(0.0).cwiseSqrt();
  for (Eigen::Index i = 0; i < sc.size(); ++i) sc[i] = sc[i] > 0 ? 1.0 / sc[i] : 0.0;
  const Eigen::MatrixXd Hs = sc.asDiagonal() * f.H * sc.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Hs);
  const Eigen::VectorXd ev = eig.eigenvalues();  // ascending
  // with a prior: positive definite is enough (its weight is small against near noise-free data)
  const double tol = hasPrior() ? 0.0 : rank_tol_ * rank_tol_;
  exid::check(ev[0] > tol * ev[ev.size() - 1],
              "gains_ls: the torque columns' parameters and the base parameters are not "
              "identifiable together (the Gauss-Newton matrix is singular: does the payload "
              "part move every joint whose gain is fitted? Without a payload part the gains' "
              "common scale needs a prior: gain_prior_std)");
  exid::estimators::LsSolution s;
  s.p = p;
  s.m = S.m;
  s.rss = f.rss;
  s.sigma2 = f.rss / static_cast<double>(S.m - p);  // (pooled; the covariance is below)
  const Eigen::MatrixXd Hinv =
      sc.asDiagonal() *
      (eig.eigenvectors() * ev.cwiseInverse().asDiagonal() * eig.eigenvectors().transpose()) *
      sc.asDiagonal();
  // (theta, phi) -> base order
  Eigen::MatrixXd T = Eigen::MatrixXd::Zero(p, p0 + ng);
  s.theta.resize(p);
  for (int c = 0; c < p0; ++c) {
    s.theta[other_cols_[static_cast<std::size_t>(c)]] = f.theta[c];
    T(other_cols_[static_cast<std::size_t>(c)], c) = 1.0;
  }
  for (int k = 0; k < ng; ++k) {
    s.theta[gain_cols_[static_cast<std::size_t>(k)]] = f.phi[k];
    T(gain_cols_[static_cast<std::size_t>(k)], p0 + k) = 1.0;
  }
  // The noise std per equation (a joint's), sigma_e^2 = rss_e / m_e times m / (m - p), in the
  // sandwich H^-1 (sum_e sigma_e^2 H_e + the prior's part) H^-1, H_e = J_e^T J_e its rows'
  // part; with equal sigma_e it is sigma^2 H^-1 (with a prior, the posterior). One pooled
  // sigma^2 H^-1 gave a wrist drive's parameters (a small torque, its small noise) a std up to
  // 7 times their spread and a large joint's half of it (tests/models/sigma_montecarlo_test.cpp).
  // The prior stays weighed by the pooled noise std, heavier than a quiet joint's own: there
  // it narrows a gain less than a posterior weighed per joint would.
  s.covariance = covariance(S, f, p, Hinv, T, per_eq);
  s.std = s.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  s.rel_std_percent = exid::estimators::relativeStdPercent(s.theta, s.std);
  // singular values of the Jacobian: square roots of H's eigenvalues
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> he(f.H, Eigen::EigenvaluesOnly);
  s.singular_values = he.eigenvalues().reverse().cwiseMax(0.0).cwiseSqrt();
  s.singular_values_scaled = ev.reverse().cwiseMax(0.0).cwiseSqrt();
  s.cond_W = s.singular_values[0] / s.singular_values[s.singular_values.size() - 1];
  s.cond_W_scaled =
      s.singular_values_scaled[0] / s.singular_values_scaled[s.singular_values_scaled.size() - 1];
  return s;
}

// The sandwich covariance of theta in base order (see solution): Hinv = H^-1, T: (theta,
// phi) -> base order, p base parameters; per_eq: the noise std per equation.
Eigen::MatrixXd GainsLs::covariance(const Sums& S, const Fit& f, int p, const Eigen::MatrixXd& Hinv,
                                    const Eigen::MatrixXd& T, exid::Json* per_eq) const {
  const int p0 = static_cast<int>(other_cols_.size()), ng = static_cast<int>(gain_cols_.size());
  std::vector<Eigen::MatrixXd> G;
  for (const RowAccumulator& a : S.acc) G.push_back(a.factor().transpose() * a.factor());
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(p0 + ng, p0 + ng), He;
  const double small = static_cast<double>(S.m) / static_cast<double>(S.m - p);
  for (const auto& [eq, rows] : S.rows_of_eq) {
    double rss_e = 0.0;
    (void)evaluate(S, G, f.theta, f.phi, 0.0, nullptr, &He, &rss_e, eq);
    const double s2 = std::max(rss_e, 0.0) / static_cast<double>(rows) * small;
    B += s2 * He;
    exid::Json o = exid::Json::object();
    o["equation"] = eq;
    o["rows"] = rows;
    o["noise_std"] = std::sqrt(s2);
    per_eq->push_back(o);
  }
  // the prior's pseudo-observations noise (dK - mu) / s, the prior mean's own error of
  // std s: their noise std is `noise`
  for (Eigen::Index k = 0; k < sd_.size(); ++k)
    if (sd_[k] > 0.0) B(p0 + k, p0 + k) += std::pow(f.noise * f.noise / sd_[k], 2);
  return T * (Hinv * B * Hinv) * T.transpose();
}

// details.gains (dK, its std, recorded over true torque, the prior's share),
// details.load_coulomb (FcL) and details.gain_prior.
void GainsLs::describeTorqueColumns(const exid::ObservationModel& model,
                                    const exid::estimators::LsSolution& s, const Fit& f,
                                    exid::Json* dp) const {
  exid::Json& d = *dp;
  const int ng = static_cast<int>(gain_cols_.size());
  exid::Json gains = exid::Json::array(), loads = exid::Json::array();
  for (int k = 0; k < ng; ++k) {
    exid::Json o = exid::Json::object();
    const auto c = static_cast<std::size_t>(gain_cols_[static_cast<std::size_t>(k)]);
    const auto ci = static_cast<Eigen::Index>(c);
    o["name"] = model.base().names[c];
    if (!is_gain_[static_cast<std::size_t>(k)]) {
      o["FcL"] = s.theta[ci];
      o["FcL_std"] = s.std[ci];
      loads.push_back(o);
      continue;
    }
    o["dK"] = s.theta[ci];
    o["dK_std"] = s.std[ci];
    // g = 1 / (1 + dK): d g / d dK = -g^2
    const double g = 1.0 / (1.0 + f.phi[k]);
    o["recorded_over_true"] = g;
    o["recorded_over_true_std"] = g * g * s.std[ci];
    if (hasPrior()) {
      o["prior_dK"] = mu_[k];
      o["prior_std"] = sd_[k];
      // posterior variance / prior variance: 1 = the prior alone, 0 = the data decide
      o["prior_share"] = std::pow(s.std[static_cast<Eigen::Index>(c)] / sd_[k], 2);
    }
    gains.push_back(o);
  }
  if (gains.size() > 0) d["gains"] = gains;
  if (loads.size() > 0) d["load_coulomb"] = loads;
  if (hasPrior()) {
    exid::Json pr = exid::Json::object();
    pr["definition"] =
        "pseudo-observations noise_std (dK_j - prior_dK_j) / prior_std_j added to the rows; "
        "noise_std = sqrt(rss / (m - p)) at its fixed point";
    pr["noise_std"] = f.noise;
    pr["noise_rounds"] = f.noise_rounds;
    pr["noise_std_floor"] = f.noise_floor;
    pr["noise_std_floored"] = f.floored;
    if (f.floored)
      pr["noise_std_floor_note"] =
          "the data's noise std is below 1e-3 of the recorded torque's rms: the floor was used, "
          "so the prior weighs more and the posterior is wider than the data alone would give";
    d["gain_prior"] = pr;
  }
}

// Start i of the fit f: the first, or the first shifted in every torque column.
std::string GainsLs::startName(const Fit& f, int i) const {
  const std::string first_start =
      hasPrior() ? "the gain prior's mean" : "least squares on the rows";
  const double sh = f.starts[static_cast<std::size_t>(i)].shift;
  return i == 0 ? first_start : fmt::format("{} {:+g} in every torque column", first_start, sh);
}

// details.starts: where each start began and ended; details.best_start.
void GainsLs::describeStarts(const exid::ObservationModel& model, const Fit& f,
                             exid::Json* dp) const {
  exid::Json& d = *dp;
  std::vector<std::string> tnames;
  for (int c : gain_cols_) tnames.push_back(model.base().names[static_cast<std::size_t>(c)]);
  exid::Json starts = exid::Json::array();
  for (std::size_t i = 0; i < f.starts.size(); ++i) {
    const Fit::Start& st = f.starts[i];
    exid::Json o = exid::Json::object();
    o["start"] = startName(f, static_cast<int>(i));
    o["from"] = exid::estimators::describePoint(tnames, st.phi0);
    o["admissible"] = st.admissible;
    if (st.admissible) {
      o["to"] = exid::estimators::describePoint(tnames, st.phi);
      o["objective"] = st.objective;
      o["rss"] = st.rss;
      o["iterations"] = st.iterations;
      o["gauss_newton_fraction"] = st.gn_fraction;
      o["first_order"] = st.first_order;
      if (st.degenerate)
        o["degenerate"] = "a load term at |FcL| >= 0.9: kept only when every start ends so";
    }
    starts.push_back(o);
  }
  d["starts"] = starts;
  d["best_start"] = f.best + 1;
  d["starts_definition"] = fmt::format(
      "Levenberg-Marquardt from each start (theta by least squares at its phi; with a gain "
      "prior, at the first weight of the noise std), the lowest objective kept; start_spread "
      "= {:g}",
      spread_);
}

}  // namespace exid::gains_ls

EXID_REGISTER_PLUGIN(exid::gains_ls::GainsLs)
