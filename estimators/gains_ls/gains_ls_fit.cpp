// exid — estimator `gains_ls`: the rows grouped by (equation, torque column, a) into the sums
// of one pass, and Levenberg-Marquardt on (theta, phi) from them, from each start (see
// gains_ls.cpp).
#include <fmt/format.h>

#include <cmath>
#include <map>
#include <tuple>

#include "exid/drive.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "gains_ls.hpp"

namespace exid::gains_ls {

// The base columns: the torque columns' (dK<j>, FcL<j>) and the others'.
void GainsLs::split(const exid::ObservationModel& model) {
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
void GainsLs::setPrior(const exid::ObservationModel& model) {
  std::size_t ng = 0;  // the dK columns (a prior is on the gains only)
  for (bool g : is_gain_) ng += g;
  mu_.resize(0);
  sd_.resize(0);
  if (prior_std_.empty()) return;
  exid::check(ng > 0, "gains_ls: gain_prior_std is given but the model has no drive gain");
  const std::string who = "gains_ls (model " + model.pluginName() + ")";
  const Eigen::VectorXd sd = exid::estimators::perGain(prior_std_, ng, "gain_prior_std", 0.0, who);
  const Eigen::VectorXd mu = exid::estimators::perGain(prior_mean_, ng, "gain_prior_dK", 0.0, who);
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

GainsLs::Sums GainsLs::accumulate(const exid::ObservationModel& model, const exid::Dataset& data,
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
          // the recorded torque: minus a gain column; else the model's (Rows::torque: a
          // floating base's joint rows, y = tau + J^T w), or the measurement (no payload part
          // without gains)
          const bool given = !r.torque.empty();
          double t = given ? r.torque[static_cast<std::size_t>(i)] : r.y[i], a = 0.0;
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
          } else if (given) {
            t = r.y[i];  // (a row without a torque column: p = 0, as before)
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
            for (int c = 0; c < p0; ++c) U(q, c) = r.W(i, other_cols_[static_cast<std::size_t>(c)]);
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

// theta by least squares at the given phi.
Eigen::VectorXd GainsLs::thetaAt(const Sums& S, const std::vector<Eigen::MatrixXd>& G,
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
void GainsLs::multiStart(const Sums& S, const std::vector<Eigen::MatrixXd>& G, double noise,
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
        st.degenerate =
            st.degenerate || (!is_gain_[k] && std::abs(t.phi[static_cast<Eigen::Index>(k)]) >= 0.9);
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

// The objective (rss, plus the gain prior's squared pseudo-residuals weighted by noise^2), its
// gradient and Gauss-Newton matrix at (theta, phi) from the sums; *data_rss: the rss alone.
// Per group r = tau - g (w theta + p), g = 1 / (1 + a phi): dr/dtheta = -g w, dr/dphi =
// -(w theta + p) g', g' = -a g^2.
double GainsLs::evaluate(const Sums& S, const std::vector<Eigen::MatrixXd>& G,
                         const Eigen::VectorXd& th, const Eigen::VectorXd& phi, double noise,
                         Eigen::VectorXd* grad, Eigen::MatrixXd* H, double* data_rss,
                         int only_eq) const {
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

GainsLs::Fit GainsLs::solve(const Sums& S) const {
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
void GainsLs::linearStart(const Sums& S, const std::vector<Eigen::MatrixXd>& G, Fit* f) const {
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
void GainsLs::iterate(const Sums& S, const std::vector<Eigen::MatrixXd>& G, double noise,
                      Fit* fp) const {
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

}  // namespace exid::gains_ls
