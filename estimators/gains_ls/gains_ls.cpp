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
#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <chrono>
#include <cmath>
#include <map>
#include <tuple>

#include "exid/drive.hpp"
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
      "the recorded torque's own columns (differential's drive_gains dK, coulomb_load FcL) with "
      "the base parameters, the recorded torque in the measurement only: tau = (w theta + p) / "
      "(1 + a phi), Levenberg-Marquardt on per-group sums of one pass; no errors-in-variables "
      "bias";

  static std::vector<exid::ParamDecl> params() {
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

  explicit GainsLs(const exid::ParamSet& p)
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
  // The base columns: the torque columns' (dK<j>, FcL<j>) and the others'.
  void split(const exid::ObservationModel& model) {
    gain_cols_.clear();
    other_cols_.clear();
    is_gain_.clear();
    const std::vector<std::string>& names = model.base().names;
    for (int c = 0; c < static_cast<int>(names.size()); ++c) {
      const int kind = exid::torqueColumnKind(names[static_cast<std::size_t>(c)]);
      if (kind != 0) is_gain_.push_back(kind == 1);
      (kind != 0 ? gain_cols_ : other_cols_).push_back(c);
    }
    exid::check(!gain_cols_.empty(),
                fmt::format("gains_ls: model '{}' has no column of the recorded torque among its "
                            "base parameters (differential with drive_gains or coulomb_load); "
                            "batch_ls gives its fit",
                            model.pluginName()));
  }

  // The gain prior per gain column (mu_, sd_; empty: none).
  void setPrior(const exid::ObservationModel& model) {
    std::size_t ng = 0;  // the dK columns (a prior is on the gains only)
    for (bool g : is_gain_) ng += g;
    mu_.resize(0);
    sd_.resize(0);
    if (prior_std_.empty()) return;
    exid::check(ng > 0, "gains_ls: gain_prior_std is given but the model has no drive gain");
    const std::string who = "gains_ls (model " + model.pluginName() + ")";
    const Eigen::VectorXd sd =
        exid::estimators::perGain(prior_std_, ng, "gain_prior_std", 0.0, who);
    const Eigen::VectorXd mu =
        exid::estimators::perGain(prior_mean_, ng, "gain_prior_dK", 0.0, who);
    // per torque column (sd 0: no prior on it)
    sd_ = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(gain_cols_.size()));
    mu_ = Eigen::VectorXd::Zero(sd_.size());
    Eigen::Index g = 0;
    for (std::size_t k = 0; k < gain_cols_.size(); ++k)
      if (is_gain_[k]) {
        sd_[static_cast<Eigen::Index>(k)] = sd[g];
        mu_[static_cast<Eigen::Index>(k)] = mu[g++];
      }
  }
  bool hasPrior() const { return sd_.size() > 0; }

  // Per group of rows (equation, torque column, a): the sums of u u^T, u = [w, p, tau].
  struct Group {
    int eq = 0;
    int k = -1;    // its torque column (index in gain_cols_); -1: none (g = 1)
    double a = 0;  // g = 1 / (1 + a phi_k)
  };
  struct Sums {
    std::vector<Group> groups;
    std::vector<RowAccumulator> acc;
    std::map<std::tuple<int, int, int>, std::size_t> index;  // (eq, k, a) -> group
    std::map<int, std::size_t> rows_of_col;                  // torque column -> its rows
    std::map<int, int> eq_of_col;                            // torque column -> its equation
    std::map<int, long> rows_of_eq;                          // equation -> its rows
    long m = 0;
  };

  Sums accumulate(const exid::ObservationModel& model, const exid::Dataset& data,
                  const exid::RunContext& ctx) const {
    Sums S;
    const int p0 = static_cast<int>(other_cols_.size());
    bool has_gain = false;
    for (bool g : is_gain_) has_gain = has_gain || g;
    Eigen::MatrixXd U;
    Eigen::VectorXd tau;
    std::map<std::size_t, std::vector<Eigen::Index>> rows_of;  // group -> rows of the chunk
    exid::estimators::forEachChunk(
        model, data, chunk_, ctx, kName, 0.0, 0.9, [&](const exid::Rows& r, int b, int) {
          const Eigen::Index R = r.y.size();
          exid::check(r.equation.size() == static_cast<std::size_t>(R),
                      "gains_ls: the model's rows carry no equation labels");
          rows_of.clear();
          std::vector<double> tau_of(static_cast<std::size_t>(R), 0.0);
          for (Eigen::Index i = 0; i < R; ++i) {
            const int eq = r.equation[static_cast<std::size_t>(i)];
            int k = -1;
            for (std::size_t c = 0; c < gain_cols_.size(); ++c)
              if (r.W(i, gain_cols_[c]) != 0.0) {
                if (k >= 0)
                  throw exid::Error(
                      fmt::format("gains_ls: a row (sample {} on) has two columns "
                                  "of the recorded torque: one per equation",
                                  b));
                k = static_cast<int>(c);
              }
            // the recorded torque: minus a gain column; else the measurement (no payload part
            // without gains)
            double t = r.y[i], a = 0.0;
            if (k >= 0) {
              const double w = r.W(i, gain_cols_[static_cast<std::size_t>(k)]);
              if (is_gain_[static_cast<std::size_t>(k)]) {
                t = -w;
                a = 1.0;
              } else {
                a = t != 0.0 ? (-w / t > 0 ? 1.0 : -1.0) : 0.0;  // -sign(tau qdm)
                if (a == 0.0) k = -1;
              }
              auto [it, fresh] = S.eq_of_col.emplace(k, eq);
              if (!fresh && it->second != eq)
                throw exid::Error(fmt::format(
                    "gains_ls: '{}' appears in two equations (one expected)",
                    model.base()
                        .names[static_cast<std::size_t>(gain_cols_[static_cast<std::size_t>(k)])]));
            } else if (has_gain) {
              t = 0.0;  // (a gain's equation with a zero recorded torque: p = -y)
            }
            tau_of[static_cast<std::size_t>(i)] = t;
            const auto key = std::make_tuple(eq, k, static_cast<int>(a));
            auto g = S.index.find(key);
            if (g == S.index.end()) {
              g = S.index.emplace(key, S.groups.size()).first;
              S.groups.push_back({eq, k, a});
              S.acc.emplace_back(p0 + 1);
            }
            rows_of[g->second].push_back(i);
          }
          for (const auto& [gi, idx] : rows_of) {
            const auto n = static_cast<Eigen::Index>(idx.size());
            U.resize(n, p0 + 1);
            tau.resize(n);
            for (Eigen::Index q = 0; q < n; ++q) {
              const Eigen::Index i = idx[static_cast<std::size_t>(q)];
              for (int c = 0; c < p0; ++c)
                U(q, c) = r.W(i, other_cols_[static_cast<std::size_t>(c)]);
              tau[q] = tau_of[static_cast<std::size_t>(i)];
              U(q, p0) = tau[q] - r.y[i];  // p = tau - y
            }
            S.acc[gi].add(U, tau);
            S.m += n;
            S.rows_of_eq[S.groups[gi].eq] += n;
            const int k = S.groups[gi].k;
            if (k >= 0) S.rows_of_col[k] += static_cast<std::size_t>(n);
          }
        });
    for (std::size_t k = 0; k < gain_cols_.size(); ++k)
      exid::check(S.rows_of_col.count(static_cast<int>(k)) > 0,
                  fmt::format("gains_ls: '{}' has no row with a nonzero recorded torque (not "
                              "identifiable)",
                              model.base().names[static_cast<std::size_t>(gain_cols_[k])]));
    return S;
  }

  struct Fit {
    Eigen::VectorXd theta, phi;  // other base parameters; torque columns' (dK, FcL)
    double rss = 0.0;            // the data's residual sum of squares
    double objective = 0.0;      // rss + the prior's weighted pseudo-residuals
    double noise = 0.0;          // the noise std the prior was weighed with (0: no prior)
    int noise_rounds = 0;        // fits to the noise std's fixed point
    double noise_floor = 0.0;    // its floor; floored: the floor was used
    bool floored = false;
    Eigen::MatrixXd H;  // Gauss-Newton matrix of (theta, phi), the prior's included
    int iterations = 0;
    std::string stop;
    bool converged = false;
    double gradient_norm = 0.0;  // ||d objective / d(theta, phi)|| at the end
    double gn_fraction = 0.0;    // the part of the objective a Gauss-Newton step would remove
    bool first_order = false;    // the first-order test holds there
    // the starts (first: the one LM ran from in every later round of the prior's noise)
    struct Start {
      double shift = 0;           // of every torque column's parameter from the first start
      Eigen::VectorXd phi0, phi;  // where it started and ended
      double objective = 0, rss = 0, gn_fraction = 0;
      int iterations = 0;
      bool first_order = false, admissible = true;
      bool degenerate = false;  // a load term at |FcL| >= 0.9 (refused unless every start is)
    };
    std::vector<Start> starts;
    int best = 0;  // the kept start
  };

  // The shift of start i from the first: 0, -s, +s, -s/2, +s/2, -2s, +2s.
  double shiftOf(int i) const {
    static const double kMul[] = {0.0, -1.0, 1.0, -0.5, 0.5, -2.0, 2.0};
    return kMul[i] * spread_;
  }

  // theta by least squares at the given phi.
  Eigen::VectorXd thetaAt(const Sums& S, const std::vector<Eigen::MatrixXd>& G,
                          const Eigen::VectorXd& phi) const {
    const int p0 = static_cast<int>(other_cols_.size());
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(p0, p0);
    Eigen::VectorXd b = Eigen::VectorXd::Zero(p0);
    for (std::size_t e = 0; e < S.groups.size(); ++e) {
      const Eigen::MatrixXd& M = G[e];
      const Group& gr = S.groups[e];
      const double gk = gr.k >= 0 ? 1.0 / (1.0 + gr.a * phi[gr.k]) : 1.0;
      A += gk * gk * M.topLeftCorner(p0, p0);
      b += gk * M.col(p0 + 1).head(p0) - gk * gk * M.col(p0).head(p0);
    }
    return A.ldlt().solve(b);
  }

  // LM from every start (f holds the first), the lowest objective kept in f.
  void multiStart(const Sums& S, const std::vector<Eigen::MatrixXd>& G, double noise,
                  Fit* fp) const {
    Fit& f = *fp;
    const Fit first = f;
    std::vector<Fit::Start> starts;
    Fit best;
    int bi = -1;
    // a later start beats the kept one only by more than the objective's rounding (the sums'
    // cancellation in tt - 2 g s + g^2 q), else the earlier is kept
    const int p0 = static_cast<int>(other_cols_.size());
    double tt = 0.0;
    for (const Eigen::MatrixXd& M : G) tt += M(p0 + 1, p0 + 1);
    for (int i = 0; i < starts_; ++i) {
      Fit::Start st;
      st.shift = shiftOf(i);
      st.phi0 = first.phi.array() + st.shift;
      Fit t = first;
      t.phi = st.phi0;
      if (i > 0) t.theta = thetaAt(S, G, t.phi);
      st.admissible = admissible(S, t.phi) && t.theta.allFinite();
      if (st.admissible) {
        iterate(S, G, noise, &t);
        st.phi = t.phi;
        st.objective = t.objective;
        st.rss = t.rss;
        st.gn_fraction = t.gn_fraction;
        st.iterations = t.iterations;
        st.first_order = t.first_order;
        for (std::size_t k = 0; k < is_gain_.size(); ++k)
          st.degenerate = st.degenerate ||
                          (!is_gain_[k] && std::abs(t.phi[static_cast<Eigen::Index>(k)]) >= 0.9);
        // the lowest objective, a degenerate end only when every start is one
        const bool best_degenerate = bi >= 0 && starts[static_cast<std::size_t>(bi)].degenerate;
        const bool better =
            bi < 0 || (st.degenerate == best_degenerate
                           ? t.objective < best.objective - 1e-10 * best.objective - 1e-14 * tt
                           : best_degenerate);
        if (std::isfinite(t.objective) && better) {
          best = t;
          bi = i;
        }
      }
      starts.push_back(st);
    }
    exid::check(bi >= 0,
                "gains_ls: no start could be fitted (every start leaves some 1 + a phi "
                "<= 0: lower start_spread)");
    f = best;
    f.starts = starts;
    f.best = bi;
  }

  // Whether every group's 1 + a phi_k is positive (the recorded torque keeps its sign).
  static bool admissible(const Sums& S, const Eigen::VectorXd& phi) {
    for (const Group& g : S.groups)
      if (g.k >= 0 && !(1.0 + g.a * phi[g.k] > 0.0)) return false;
    return true;
  }

  // The objective (rss, plus the gain prior's squared pseudo-residuals weighted by noise^2), its
  // gradient and Gauss-Newton matrix at (theta, phi) from the sums; *data_rss: the rss alone.
  // Per group r = tau - g (w theta + p), g = 1 / (1 + a phi): dr/dtheta = -g w, dr/dphi =
  // -(w theta + p) g', g' = -a g^2.
  double evaluate(const Sums& S, const std::vector<Eigen::MatrixXd>& G, const Eigen::VectorXd& th,
                  const Eigen::VectorXd& phi, double noise, Eigen::VectorXd* grad,
                  Eigen::MatrixXd* H, double* data_rss = nullptr, int only_eq = -1) const {
    const int p0 = static_cast<int>(th.size()), ng = static_cast<int>(phi.size());
    if (grad) grad->setZero(p0 + ng);
    if (H) H->setZero(p0 + ng, p0 + ng);
    double rss = 0.0;
    for (std::size_t e = 0; e < S.groups.size(); ++e) {
      const Group& gr = S.groups[e];
      if (only_eq >= 0 && gr.eq != only_eq) continue;  // (one equation's rows: no prior)
      const Eigen::MatrixXd& M = G[e];                 // [w p tau]^T [w p tau]
      const double gk = gr.k >= 0 ? 1.0 / (1.0 + gr.a * phi[gr.k]) : 1.0;
      const double dg = -gr.a * gk * gk;
      const auto A = M.topLeftCorner(p0, p0);
      const Eigen::VectorXd c = M.col(p0).head(p0), at = M.col(p0 + 1).head(p0);
      const double pp = M(p0, p0), tp = M(p0, p0 + 1), tt = M(p0 + 1, p0 + 1);
      const Eigen::VectorXd Ath = A * th;
      const double q = th.dot(Ath) + 2 * th.dot(c) + pp;  // ||w theta + p||^2
      const double s = th.dot(at) + tp;                   // tau . (w theta + p)
      rss += tt - 2 * gk * s + gk * gk * q;
      if (grad) {  // d rss / d(theta, phi) / 2 = J^T r
        grad->head(p0) += -gk * at + gk * gk * (Ath + c);
        if (gr.k >= 0) (*grad)[p0 + gr.k] += (-s + gk * q) * dg;
      }
      if (H) {  // J^T J
        H->topLeftCorner(p0, p0) += gk * gk * A;
        if (gr.k >= 0) {
          const Eigen::VectorXd x = gk * dg * (Ath + c);
          H->col(p0 + gr.k).head(p0) += x;
          H->row(p0 + gr.k).head(p0) += x.transpose();
          (*H)(p0 + gr.k, p0 + gr.k) += dg * dg * q;
        }
      }
    }
    if (data_rss) *data_rss = rss;
    if (only_eq >= 0) return rss;
    for (Eigen::Index k = 0; k < sd_.size(); ++k) {
      if (sd_[k] == 0.0) continue;  // (no prior on a load term)
      const double rho = noise * (phi[k] - mu_[k]) / sd_[k], drho = noise / sd_[k];
      rss += rho * rho;
      if (grad) (*grad)[p0 + k] += rho * drho;
      if (H) (*H)(p0 + k, p0 + k) += drho * drho;
    }
    return rss;
  }

  Fit solve(const Sums& S) const {
    const int p0 = static_cast<int>(other_cols_.size()), ng = static_cast<int>(gain_cols_.size());
    std::vector<Eigen::MatrixXd> G;
    for (const RowAccumulator& a : S.acc) G.push_back(a.factor().transpose() * a.factor());
    Fit f;
    // start: the prior's gains (else 0: the recorded torque is the true one), theta by least
    // squares at them
    f.phi = mu_.size() > 0 ? mu_ : Eigen::VectorXd::Zero(ng);
    f.theta = thetaAt(S, G, f.phi);
    if (!hasPrior()) {
      // Start from least squares on the rows themselves (tau - p = w theta - a phi tau: errors
      // in variables, but near): from phi = 0 LM can walk to a spurious fit with some
      // 1 + a phi -> 0 (a drive of small torques, its sign flipped by noise).
      linearStart(S, G, &f);
      multiStart(S, G, 0.0, &f);
      return f;
    }
    // The prior is weighed by the data's noise std (pooled over the equations, as the data's rows
    // are): from the start's rss, then the fit's, to a fixed point (the gains' common scale,
    // which the prior sets, does not change the rss).
    const double dof = static_cast<double>(std::max<long>(1, S.m - p0 - ng));
    double rss0 = 0.0, tt = 0.0;
    (void)evaluate(S, G, f.theta, f.phi, 0.0, nullptr, nullptr, &rss0);
    for (const Eigen::MatrixXd& M : G) tt += M(p0 + 1, p0 + 1);
    // Near noise-free data the prior's weight (noise^2 / s^2) would vanish against the data's
    // and the scale it sets would drown in rounding: the noise std is floored at 1e-3 of the
    // recorded torque's rms (said in the details; it only widens the posterior).
    f.noise_floor = 1e-3 * std::sqrt(tt / static_cast<double>(std::max<long>(1, S.m)));
    double noise = std::sqrt(std::max(rss0, 0.0) / dof);
    for (f.noise_rounds = 1; f.noise_rounds <= 20; ++f.noise_rounds) {
      f.noise = std::max(noise, f.noise_floor);
      if (f.noise_rounds == 1)
        multiStart(S, G, f.noise, &f);  // the starts at the first weight, LM on from the best
      else
        iterate(S, G, f.noise, &f);
      const double next = std::max(std::sqrt(std::max(f.rss, 0.0) / dof), f.noise_floor);
      if (std::abs(next - f.noise) <= 1e-6 * f.noise) break;
      noise = next;
    }
    f.floored = f.noise <= f.noise_floor;
    return f;
  }

  // (theta, phi) of least squares on the rows tau - p = w theta - a phi tau, from the sums: per
  // group the regressor [w, -a tau] and the target tau - p are linear in u = [w, p, tau].
  void linearStart(const Sums& S, const std::vector<Eigen::MatrixXd>& G, Fit* f) const {
    const int p0 = static_cast<int>(other_cols_.size()), ng = static_cast<int>(gain_cols_.size());
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(p0 + ng, p0 + ng);
    Eigen::VectorXd b = Eigen::VectorXd::Zero(p0 + ng);
    for (std::size_t e = 0; e < S.groups.size(); ++e) {
      const Group& gr = S.groups[e];
      // L u = [w; -a tau at k] (regressor), t u = tau - p (target)
      Eigen::MatrixXd L = Eigen::MatrixXd::Zero(p0 + ng, p0 + 2);
      L.topLeftCorner(p0, p0).setIdentity();
      if (gr.k >= 0) L(p0 + gr.k, p0 + 1) = -gr.a;
      Eigen::VectorXd t = Eigen::VectorXd::Zero(p0 + 2);
      t[p0] = -1.0;
      t[p0 + 1] = 1.0;
      A += L * G[e] * L.transpose();
      b += L * (G[e] * t);
    }
    Eigen::LDLT<Eigen::MatrixXd> ldlt(A);
    const Eigen::VectorXd x = ldlt.solve(b);
    if (ldlt.info() != Eigen::Success || !x.allFinite() || !admissible(S, x.tail(ng))) return;
    f->theta = x.head(p0);
    f->phi = x.tail(ng);
  }

  // Levenberg-Marquardt from f's (theta, phi) with the prior weighed by `noise`.
  void iterate(const Sums& S, const std::vector<Eigen::MatrixXd>& G, double noise, Fit* fp) const {
    Fit& f = *fp;
    const int p0 = static_cast<int>(other_cols_.size()), ng = static_cast<int>(gain_cols_.size());
    Eigen::VectorXd grad;
    double mu = 1e-3;
    f.converged = false;
    f.objective = evaluate(S, G, f.theta, f.phi, noise, &grad, &f.H, &f.rss);
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
        const Eigen::VectorXd th = f.theta + step.head(p0), phi = f.phi + step.tail(ng);
        const double obj =
            admissible(S, phi) ? evaluate(S, G, th, phi, noise, nullptr, nullptr) : HUGE_VAL;
        if (std::isfinite(obj) && obj <= f.objective) {
          f.theta = th;
          f.phi = phi;
          f.objective = evaluate(S, G, f.theta, f.phi, noise, &grad, &f.H, &f.rss);
          mu = std::max(mu / 3, 1e-15);
          accepted = true;
        } else {
          mu *= 4;
        }
      }
      // relative step: phi against 1 (the gain and load terms are relative corrections)
      Eigen::VectorXd scale(p0 + ng);
      scale << f.theta.cwiseAbs(), Eigen::VectorXd::Ones(ng);
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
    // "converged" only where the first-order test holds: g^T H^+ g, the decrease a
    // Gauss-Newton step predicts, at most gradient_tolerance of the objective, or the fit exact
    // to the precision of the sums (whatever the stop test said)
    {
      Eigen::JacobiSVD<Eigen::MatrixXd> sv(f.H, Eigen::ComputeThinU | Eigen::ComputeThinV);
      sv.setThreshold(1e-14);
      const double pred = grad.dot(sv.solve(grad));
      double tt = 0.0;
      for (const Eigen::MatrixXd& M : G) tt += M(p0 + 1, p0 + 1);
      f.gradient_norm = 2.0 * grad.norm();
      f.gn_fraction = f.objective > 0 ? pred / f.objective : 0.0;
      const bool exact = f.objective <= 1e-12 * tt;
      f.first_order = exact || (std::isfinite(f.gn_fraction) && f.gn_fraction <= gtol_);
    }
    if (!f.converged) f.stop = fmt::format("max_iterations = {} reached", max_iter_);
    f.converged = f.converged && f.first_order;
    f.rss = std::max(f.rss, 0.0);
  }

  exid::Estimate finish(const exid::ObservationModel& model, const Sums& S, const Fit& f,
                        std::chrono::steady_clock::time_point t0) const {
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
    exid::Json per_eq = exid::Json::array();
    {
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
        per_eq.push_back(o);
      }
      // the prior's pseudo-observations noise (dK - mu) / s, the prior mean's own error of
      // std s: their noise std is `noise`
      for (Eigen::Index k = 0; k < sd_.size(); ++k)
        if (sd_[k] > 0.0) B(p0 + k, p0 + k) += std::pow(f.noise * f.noise / sd_[k], 2);
      s.covariance = T * (Hinv * B * Hinv) * T.transpose();
    }
    s.std = s.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
    s.rel_std_percent = exid::estimators::relativeStdPercent(s.theta, s.std);
    // singular values of the Jacobian: square roots of H's eigenvalues
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
    // the starts: where each began and ended
    std::vector<std::string> tnames;
    for (int c : gain_cols_) tnames.push_back(model.base().names[static_cast<std::size_t>(c)]);
    const std::string first_start =
        hasPrior() ? "the gain prior's mean" : "least squares on the rows";
    auto startName = [&](int i) {
      const double sh = f.starts[static_cast<std::size_t>(i)].shift;
      return i == 0 ? first_start : fmt::format("{} {:+g} in every torque column", first_start, sh);
    };
    exid::Json starts = exid::Json::array();
    for (std::size_t i = 0; i < f.starts.size(); ++i) {
      const Fit::Start& st = f.starts[i];
      exid::Json o = exid::Json::object();
      o["start"] = startName(static_cast<int>(i));
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
          f.best + 1, f.starts.size(), startName(f.best), f.iterations,
          exid::estimators::describePoint(e.names, e.value), f.rss, f.gradient_norm, f.gn_fraction,
          gtol_, f.stop)));
      d["warnings"] = w;
    }
    return e;
  }

  int max_iter_;
  double xtol_, gtol_;
  int starts_;
  double spread_;
  int chunk_;
  double rank_tol_;
  std::vector<double> prior_std_, prior_mean_;  // as given
  Eigen::VectorXd mu_, sd_;                     // the gain prior per gain column (empty: none)
  std::vector<int> gain_cols_, other_cols_;     // base columns: torque columns', others'
  std::vector<bool> is_gain_;                   // per torque column: dK (else FcL)
};

}  // namespace

EXID_REGISTER_PLUGIN(GainsLs)
