// exid — estimator `gains_ls`: drive gains identified with the base parameters, the recorded
// torque in the measurement only (docs/estimators.md, "gains_ls").
//
// With the `differential` model's drive_gains, the rows of joint j are
//   tau_j - p_j = w theta - dK_j tau_j,
// tau_j the recorded torque, p_j the known payload's torque (the payload part only). The
// recorded torque is in a column: least squares on these rows has errors in variables, and
// since the gains' common scale is set by the payload alone (a small part of the torque), the
// bias is large (30 % on a PUMA at 1 % torque noise). gains_ls fits the same model written
// with the noise in the measurement only:
//   tau_j = g_j (w theta + p_j),   g_j = 1 / (1 + dK_j)   (the recorded / true gain),
// bilinear in (theta, g). Everything the fit needs is in per-joint sums taken in one pass:
// with u = [w, p, tau] per row of joint j, S_j = sum u u^T. The residual sum of squares, its
// gradient and the Gauss-Newton matrix of (theta, g) follow exactly from the S_j, so
// Levenberg-Marquardt runs on them without another pass. Covariance sigma^2 H^-1 at the
// optimum, sigma^2 = rss / (m - p), carried to dK_j = 1 / g_j - 1 by the delta method.
//
// A prior on the gains (gain_prior_std, gain_prior_dK: a datasheet's torque constants and their
// tolerance) adds the pseudo-observations sigma (dK_j - mu_j) / s_j, sigma the data's noise std
// (from the fit, to a fixed point), so the objective is the negative log posterior times
// sigma^2 and sigma^2 H^-1 the posterior covariance. With drive_gains_scale: prior (no payload
// part) the data fix the gains' ratios and the prior alone their common scale.
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <chrono>
#include <cmath>
#include <map>

#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"

namespace {

using exid::estimators::RowAccumulator;

class GainsLs : public exid::Estimator {
 public:
  static constexpr const char* kName = "gains_ls";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "drive gains with the base parameters (differential's drive_gains), the recorded torque "
      "in the measurement only: tau = g (w theta + p), Levenberg-Marquardt on per-joint sums of "
      "one pass; no errors-in-variables bias";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_int("max_iterations", 100, "Levenberg-Marquardt steps at most", 1, 10000),
        exid::param_double("step_tolerance", 1e-12, "",
                           "stop when the largest relative step is below this", 0.0, 1.0, true),
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

  explicit GainsLs(const exid::ParamSet& p)
      : max_iter_(static_cast<int>(p.getInt("max_iterations"))),
        xtol_(p.getDouble("step_tolerance")),
        chunk_(static_cast<int>(p.getInt("chunk_samples"))),
        rank_tol_(p.getDouble("rank_tolerance")),
        prior_std_(p.getDoubles("gain_prior_std")),
        prior_mean_(p.getDoubles("gain_prior_dK")) {
    for (double v : prior_std_)
      exid::check(v > 0 && std::isfinite(v),
                  fmt::format("gains_ls: gain_prior_std: {} is not a positive std", v));
    for (double v : prior_mean_)
      exid::check(std::isfinite(v) && v > -1.0,
                  fmt::format("gains_ls: gain_prior_dK: {} is not a gain correction above -1", v));
    exid::check(prior_mean_.empty() || !prior_std_.empty(),
                "gains_ls: gain_prior_dK is given without gain_prior_std");
  }

  exid::EstimatorSpecs specs() const override {
    exid::EstimatorSpecs s;
    s.streams = true;  // one pass, per-joint sums
    return s;
  }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
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

 private:
  // The base columns: the gains' (dK<j>) and the others'.
  void split(const exid::ObservationModel& model) {
    gain_cols_.clear();
    other_cols_.clear();
    const std::vector<std::string>& names = model.base().names;
    for (int c = 0; c < static_cast<int>(names.size()); ++c) {
      const std::string& n = names[static_cast<std::size_t>(c)];
      const bool gain = n.size() > 2 && n.compare(0, 2, "dK") == 0 &&
                        n.find_first_not_of("0123456789", 2) == std::string::npos;
      (gain ? gain_cols_ : other_cols_).push_back(c);
    }
    exid::check(!gain_cols_.empty(),
                fmt::format("gains_ls: model '{}' has no drive gain among its base parameters "
                            "(differential with drive_gains: true); batch_ls gives its fit",
                            model.pluginName()));
  }

  // The gain prior per gain column (mu_, sd_; empty: none).
  void setPrior(const exid::ObservationModel& model) {
    const auto ng = gain_cols_.size();
    mu_.resize(0);
    sd_.resize(0);
    if (prior_std_.empty()) return;
    auto expand = [&](const std::vector<double>& v, const char* key, double def) {
      exid::check(v.empty() || v.size() == 1 || v.size() == ng,
                  fmt::format("gains_ls: {} has {} values; expected 1 or one per drive gain ({}: "
                              "{})",
                              key, v.size(), ng, model.pluginName()));
      Eigen::VectorXd out(static_cast<Eigen::Index>(ng));
      for (std::size_t k = 0; k < ng; ++k)
        out[static_cast<Eigen::Index>(k)] = v.empty() ? def : (v.size() == 1 ? v[0] : v[k]);
      return out;
    };
    sd_ = expand(prior_std_, "gain_prior_std", 0.0);
    mu_ = expand(prior_mean_, "gain_prior_dK", 0.0);
  }
  bool hasPrior() const { return sd_.size() > 0; }

  // Per equation (joint): its gain's base column and the sums of u u^T, u = [w, p, tau].
  struct Sums {
    std::map<int, RowAccumulator> acc;  // [w, p] with tau as the "y" column
    std::map<int, int> gain_of;         // equation -> its gain's index in gain_cols_
    long m = 0;
  };

  Sums accumulate(const exid::ObservationModel& model, const exid::Dataset& data,
                  const exid::RunContext& ctx) const {
    Sums S;
    const int p0 = static_cast<int>(other_cols_.size());
    Eigen::MatrixXd U;
    Eigen::VectorXd tau;
    exid::estimators::forEachChunk(
        model, data, chunk_, ctx, kName, 0.0, 0.9, [&](const exid::Rows& r, int b, int) {
          const Eigen::Index R = r.y.size();
          exid::check(r.equation.size() == static_cast<std::size_t>(R),
                      "gains_ls: the model's rows carry no equation labels");
          std::map<int, std::vector<Eigen::Index>> rows_of;
          for (Eigen::Index i = 0; i < R; ++i) {
            const int eq = r.equation[static_cast<std::size_t>(i)];
            int gain = -1;
            for (std::size_t g = 0; g < gain_cols_.size(); ++g)
              if (r.W(i, gain_cols_[g]) != 0.0) {
                exid::check(gain < 0, fmt::format("gains_ls: a row (sample {} on) has two drive "
                                                  "gains' columns: one gain per equation",
                                                  b));
                gain = static_cast<int>(g);
              }
            if (gain >= 0) {
              auto [it, fresh] = S.gain_of.emplace(eq, gain);
              exid::check(fresh || it->second == gain,
                          fmt::format("gains_ls: equation {} has rows with two drive gains' "
                                      "columns",
                                      eq));
            }
            rows_of[eq].push_back(i);
          }
          for (const auto& [eq, idx] : rows_of) {
            const auto n = static_cast<Eigen::Index>(idx.size());
            U.resize(n, p0 + 1);
            tau.resize(n);
            const auto it = S.gain_of.find(eq);
            for (Eigen::Index k = 0; k < n; ++k) {
              const Eigen::Index i = idx[static_cast<std::size_t>(k)];
              for (int c = 0; c < p0; ++c)
                U(k, c) = r.W(i, other_cols_[static_cast<std::size_t>(c)]);
              // tau from the gain's column (-tau), 0 where it is 0 (a row before the equation's
              // gain column was seen has tau 0 there); p = tau - y
              const double t = it == S.gain_of.end()
                                   ? 0.0
                                   : -r.W(i, gain_cols_[static_cast<std::size_t>(it->second)]);
              tau[k] = t;
              U(k, p0) = t - r.y[i];
            }
            auto a = S.acc.find(eq);
            if (a == S.acc.end()) a = S.acc.emplace(eq, RowAccumulator(p0 + 1)).first;
            a->second.add(U, tau);
            S.m += n;
          }
        });
    for (const auto& [eq, a] : S.acc)
      exid::check(S.gain_of.count(eq) > 0,
                  fmt::format("gains_ls: equation {} has no drive gain column (its recorded "
                              "torque is zero throughout, or its gain is not identifiable)",
                              eq));
    std::vector<int> seen(gain_cols_.size(), 0);
    for (const auto& [eq, g] : S.gain_of) ++seen[static_cast<std::size_t>(g)];
    for (std::size_t g = 0; g < seen.size(); ++g)
      exid::check(
          seen[g] == 1,
          fmt::format("gains_ls: drive gain '{}' appears in {} equations (one expected)",
                      model.base().names[static_cast<std::size_t>(gain_cols_[g])], seen[g]));
    return S;
  }

  struct Fit {
    Eigen::VectorXd theta, g;  // other base parameters, per-gain g = recorded / true
    double rss = 0.0;          // the data's residual sum of squares
    double objective = 0.0;    // rss + the prior's weighted pseudo-residuals
    double noise = 0.0;        // the noise std the prior was weighed with (0: no prior)
    int noise_rounds = 0;      // fits to the noise std's fixed point
    double noise_floor = 0.0;  // its floor; floored: the floor was used
    bool floored = false;
    Eigen::MatrixXd H;         // Gauss-Newton matrix of (theta, g), the prior's part included
    int iterations = 0;
    std::string stop;
    bool converged = false;
  };

  // The objective (rss, plus the gain prior's squared pseudo-residuals weighted by noise^2), its
  // gradient and Gauss-Newton matrix at (theta, g) from the sums; *data_rss: the rss alone.
  double evaluate(const Sums& S, const std::vector<Eigen::MatrixXd>& G, const Eigen::VectorXd& th,
                  const Eigen::VectorXd& g, double noise, Eigen::VectorXd* grad,
                  Eigen::MatrixXd* H, double* data_rss = nullptr) const {
    const int p0 = static_cast<int>(th.size()), ng = static_cast<int>(g.size());
    if (grad) grad->setZero(p0 + ng);
    if (H) H->setZero(p0 + ng, p0 + ng);
    double rss = 0.0;
    std::size_t e = 0;
    for (const auto& [eq, a] : S.acc) {
      const Eigen::MatrixXd& M = G[e++];  // [w p tau]^T [w p tau]
      const int k = S.gain_of.at(eq);
      const double gk = g[k];
      const auto A = M.topLeftCorner(p0, p0);
      const Eigen::VectorXd c = M.col(p0).head(p0), at = M.col(p0 + 1).head(p0);
      const double pp = M(p0, p0), tp = M(p0, p0 + 1), tt = M(p0 + 1, p0 + 1);
      const Eigen::VectorXd Ath = A * th;
      const double q = th.dot(Ath) + 2 * th.dot(c) + pp;  // ||w theta + p||^2
      const double s = th.dot(at) + tp;                   // tau . (w theta + p)
      rss += tt - 2 * gk * s + gk * gk * q;
      if (grad) {  // d rss / d(theta, g) / 2 = -J^T r
        grad->head(p0) += -gk * at + gk * gk * (Ath + c);
        (*grad)[p0 + k] += -s + gk * q;
      }
      if (H) {  // J^T J: J = -[g w, w theta + p]
        H->topLeftCorner(p0, p0) += gk * gk * A;
        const Eigen::VectorXd x = gk * (Ath + c);
        H->col(p0 + k).head(p0) += x;
        H->row(p0 + k).head(p0) += x.transpose();
        (*H)(p0 + k, p0 + k) += q;
      }
    }
    if (data_rss) *data_rss = rss;
    for (Eigen::Index k = 0; k < sd_.size(); ++k) {
      // rho = noise (dK - mu) / s, dK = 1 / g - 1
      const double rho = noise * (1.0 / g[k] - 1.0 - mu_[k]) / sd_[k];
      const double drho = -noise / (sd_[k] * g[k] * g[k]);
      rss += rho * rho;
      if (grad) (*grad)[p0 + k] += rho * drho;
      if (H) (*H)(p0 + k, p0 + k) += drho * drho;
    }
    return rss;
  }

  Fit solve(const Sums& S) const {
    const int p0 = static_cast<int>(other_cols_.size()), ng = static_cast<int>(gain_cols_.size());
    std::vector<Eigen::MatrixXd> G;
    for (const auto& [eq, a] : S.acc) G.push_back(a.factor().transpose() * a.factor());
    Fit f;
    // start: the prior's gains (or the recorded torque is the true one), theta by least squares
    f.g = Eigen::VectorXd::Ones(ng);
    for (Eigen::Index k = 0; k < mu_.size(); ++k) f.g[k] = 1.0 / (1.0 + mu_[k]);
    {
      Eigen::MatrixXd A = Eigen::MatrixXd::Zero(p0, p0);
      Eigen::VectorXd b = Eigen::VectorXd::Zero(p0);
      std::size_t e = 0;
      for (const auto& [eq, a] : S.acc) {
        const Eigen::MatrixXd& M = G[e++];
        const double gk = f.g[S.gain_of.at(eq)];
        A += gk * gk * M.topLeftCorner(p0, p0);
        b += gk * M.col(p0 + 1).head(p0) - gk * gk * M.col(p0).head(p0);
      }
      f.theta = A.ldlt().solve(b);
    }
    if (!hasPrior()) {
      iterate(S, G, 0.0, &f);
      return f;
    }
    // The prior is weighed by the data's noise std: from the start's rss, then the fit's, to a
    // fixed point (the gains' common scale, which the prior sets, does not change the rss).
    const double dof = static_cast<double>(std::max<long>(1, S.m - p0 - ng));
    double rss0 = 0.0, tt = 0.0;
    (void)evaluate(S, G, f.theta, f.g, 0.0, nullptr, nullptr, &rss0);
    for (const Eigen::MatrixXd& M : G) tt += M(p0 + 1, p0 + 1);
    // Near noise-free data the prior's weight (noise^2 / s^2) would vanish against the data's
    // and the scale it sets would drown in rounding: the noise std is floored at 1e-3 of the
    // recorded torque's rms (said in the details; it only widens the posterior).
    f.noise_floor = 1e-3 * std::sqrt(tt / static_cast<double>(std::max<long>(1, S.m)));
    double noise = std::sqrt(std::max(rss0, 0.0) / dof);
    for (f.noise_rounds = 1; f.noise_rounds <= 20; ++f.noise_rounds) {
      f.noise = std::max(noise, f.noise_floor);
      iterate(S, G, f.noise, &f);
      const double next = std::max(std::sqrt(std::max(f.rss, 0.0) / dof), f.noise_floor);
      if (std::abs(next - f.noise) <= 1e-6 * f.noise) break;
      noise = next;
    }
    f.floored = f.noise <= f.noise_floor;
    return f;
  }

  // Levenberg-Marquardt from f's (theta, g) with the prior weighed by `noise`.
  void iterate(const Sums& S, const std::vector<Eigen::MatrixXd>& G, double noise, Fit* fp) const {
    Fit& f = *fp;
    const int p0 = static_cast<int>(other_cols_.size()), ng = static_cast<int>(gain_cols_.size());
    Eigen::VectorXd grad;
    double mu = 1e-3;
    f.converged = false;
    f.objective = evaluate(S, G, f.theta, f.g, noise, &grad, &f.H, &f.rss);
    for (f.iterations = 0; f.iterations < max_iter_; ++f.iterations) {
      bool accepted = false;
      Eigen::VectorXd step;
      for (int tries = 0; tries < 40 && !accepted; ++tries) {
        Eigen::MatrixXd A = f.H;
        A.diagonal() += mu * f.H.diagonal().cwiseMax(1e-300);
        step = A.ldlt().solve(-grad);
        if (!step.allFinite()) {
          mu *= 10;
          continue;
        }
        const Eigen::VectorXd th = f.theta + step.head(p0), g = f.g + step.tail(ng);
        const double obj = evaluate(S, G, th, g, noise, nullptr, nullptr);
        if (std::isfinite(obj) && obj <= f.objective && (g.array() > 0).all()) {
          f.theta = th;
          f.g = g;
          f.objective = evaluate(S, G, f.theta, f.g, noise, &grad, &f.H, &f.rss);
          mu = std::max(mu / 3, 1e-15);
          accepted = true;
        } else {
          mu *= 4;
        }
      }
      Eigen::VectorXd scale(p0 + ng);
      scale << f.theta.cwiseAbs(), f.g.cwiseAbs();
      const double rel = (step.array().abs() / (scale.array() + 1e-300)).maxCoeff();
      if (!accepted) {
        f.stop = "no step lowers the residual (a minimum to working precision)";
        f.converged = true;
        break;
      }
      if (rel < xtol_) {
        f.stop = fmt::format("relative step below step_tolerance = {:g}", xtol_);
        f.converged = true;
        break;
      }
    }
    if (!f.converged)
      f.stop = fmt::format("max_iterations = {} reached (not converged)", max_iter_);
    f.rss = std::max(f.rss, 0.0);
  }

  exid::Estimate finish(const exid::ObservationModel& model, const Sums& S, const Fit& f,
                        std::chrono::steady_clock::time_point t0) const {
    const int p = model.numBase(), p0 = static_cast<int>(other_cols_.size()),
              ng = static_cast<int>(gain_cols_.size());
    exid::check(S.m > p, fmt::format("gains_ls: {} rows for {} parameters", S.m, p));
    // the Gauss-Newton matrix must be regular (column-scaled)
    Eigen::VectorXd sc = f.H.diagonal().cwiseMax(0.0).cwiseSqrt();
    for (Eigen::Index i = 0; i < sc.size(); ++i) sc[i] = sc[i] > 0 ? 1.0 / sc[i] : 0.0;
    const Eigen::MatrixXd Hs = sc.asDiagonal() * f.H * sc.asDiagonal();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Hs);
    const Eigen::VectorXd ev = eig.eigenvalues();  // ascending
    // with a prior: positive definite is enough (its weight is small against near noise-free data)
    const double tol = hasPrior() ? 0.0 : rank_tol_ * rank_tol_;
    exid::check(ev[0] > tol * ev[ev.size() - 1],
                "gains_ls: the gains and the base parameters are not identifiable together (the "
                "Gauss-Newton matrix is singular: does the payload part move every joint whose "
                "gain is fitted? Without a payload part the gains' common scale needs a prior: "
                "gain_prior_std)");
    exid::estimators::LsSolution s;
    s.p = p;
    s.m = S.m;
    s.rss = f.rss;
    // with a prior: the noise it was weighed with (the fixed point of rss / (m - p))
    s.sigma2 = hasPrior() ? f.noise * f.noise : f.rss / static_cast<double>(S.m - p);
    const Eigen::MatrixXd Hinv =
        sc.asDiagonal() *
        (eig.eigenvectors() * ev.cwiseInverse().asDiagonal() * eig.eigenvectors().transpose()) *
        sc.asDiagonal();
    // (theta, g) -> base order, dK = 1 / g - 1: d dK / d g = -1 / g^2
    Eigen::MatrixXd T = Eigen::MatrixXd::Zero(p, p0 + ng);
    s.theta.resize(p);
    for (int c = 0; c < p0; ++c) {
      s.theta[other_cols_[static_cast<std::size_t>(c)]] = f.theta[c];
      T(other_cols_[static_cast<std::size_t>(c)], c) = 1.0;
    }
    for (int k = 0; k < ng; ++k) {
      s.theta[gain_cols_[static_cast<std::size_t>(k)]] = 1.0 / f.g[k] - 1.0;
      T(gain_cols_[static_cast<std::size_t>(k)], p0 + k) = -1.0 / (f.g[k] * f.g[k]);
    }
    s.covariance = s.sigma2 * T * Hinv * T.transpose();
    s.std = s.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
    s.rel_std_percent = exid::estimators::relativeStdPercent(s.theta, s.std);
    // singular values of the Jacobian [g w, w theta + p]: square roots of H's eigenvalues
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> he(f.H, Eigen::EigenvaluesOnly);
    s.singular_values = he.eigenvalues().reverse().cwiseMax(0.0).cwiseSqrt();
    s.singular_values_scaled = ev.reverse().cwiseMax(0.0).cwiseSqrt();
    s.cond_W = s.singular_values[0] / s.singular_values[s.singular_values.size() - 1];
    s.cond_W_scaled =
        s.singular_values_scaled[0] / s.singular_values_scaled[s.singular_values_scaled.size() - 1];
    exid::Estimate e;
    exid::estimators::fillEstimate(&e, model, s, f.rss, S.m);
    exid::Json& d = e.details;
    d["estimator"] = kName;
    d["method"] =
        "tau_j = g_j (w theta + p_j), bilinear least squares with the recorded torque in the "
        "measurement only (no errors in variables), Levenberg-Marquardt on per-joint sums of one "
        "pass; dK_j = 1 / g_j - 1";
    d["covariance_definition"] =
        hasPrior() ? "the posterior sigma^2 H^-1 of (theta, g), H = J^T J + sigma^2 (d dK / d g)^2 "
                     "/ s^2 (the gain prior), sigma^2 = rss / (m - p) at its fixed point, carried "
                     "to dK by the delta method"
                   : "sigma^2 H^-1 of (theta, g), H = J^T J, sigma^2 = rss / (m - p), carried to "
                     "dK by the delta method";
    exid::Json gains = exid::Json::array();
    for (int k = 0; k < ng; ++k) {
      exid::Json o = exid::Json::object();
      const auto c = static_cast<std::size_t>(gain_cols_[static_cast<std::size_t>(k)]);
      o["name"] = model.base().names[c];
      o["dK"] = s.theta[static_cast<Eigen::Index>(c)];
      o["dK_std"] = s.std[static_cast<Eigen::Index>(c)];
      o["recorded_over_true"] = f.g[k];
      o["recorded_over_true_std"] = std::sqrt(std::max(0.0, s.sigma2 * Hinv(p0 + k, p0 + k)));
      if (hasPrior()) {
        o["prior_dK"] = mu_[k];
        o["prior_std"] = sd_[k];
        // posterior variance / prior variance: 1 = the prior alone, 0 = the data decide
        o["prior_share"] = std::pow(s.std[static_cast<Eigen::Index>(c)] / sd_[k], 2);
      }
      gains.push_back(o);
    }
    d["gains"] = gains;
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
    d["iterations"] = f.iterations;
    d["stop"] = f.stop;
    d["converged"] = f.converged;
    d["memory"] = "per joint a (p + 2)^2 factor, whatever the number of samples";
    d["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!f.converged) {
      exid::Json w = exid::Json::array();
      w.push_back(exid::Json(fmt::format("gains_ls: {}", f.stop)));
      d["warnings"] = w;
    }
    return e;
  }

  int max_iter_;
  double xtol_;
  int chunk_;
  double rank_tol_;
  std::vector<double> prior_std_, prior_mean_;  // as given
  Eigen::VectorXd mu_, sd_;                      // the gain prior per gain column (empty: none)
  std::vector<int> gain_cols_, other_cols_;      // base columns
};

}  // namespace

EXID_REGISTER_PLUGIN(GainsLs)
