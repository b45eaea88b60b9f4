// exid — estimator `rls`: recursive least squares, the paper's eqns 6-7, row by row in time
// order, with initial covariance P0 = p0 I (or a prior) and a forgetting factor lambda:
//   g = P phi,  s = phi^T g,  k = g / (lambda + s)            (k = P_{k+1} phi of eqn 6)
//   theta <- theta + k (y - phi^T theta)                       (eqn 6)
//   P <- [(I - k phi^T) P (I - k phi^T)^T + lambda k k^T] / lambda
//      = [P - k g^T - g k^T + (lambda + s) k k^T] / lambda      (Joseph form; = eqn 7 for lambda =
//      1)
// P is stored as its lower triangle and updated by symmetric rank-one/two updates, so it is
// exactly symmetric; the Joseph form is first-order insensitive to rounding errors in k.
// P is the normalised covariance ((W^T W + P0^-1)^-1 for lambda = 1); the reported covariance is
// sigma^2 P with sigma^2 = ||y - W theta||^2 / (m - p) (see docs/estimators.md).
//
// With random_walk_std (the parameters drift as a random walk), the recursion is the Kalman
// filter of that state model: theta_k = theta_{k-1} + w_k, w_k ~ N(0, diag(q^2) dt_k), and each
// row y = phi^T theta_k + v, v ~ N(0, noise_std^2). Before the rows of a sample (after the
// first), the prediction P <- P + diag(q^2) dt_k / noise_std^2 (dt_k: the time since the
// previous sample); the rows then update as above with lambda = 1. The covariance of the final
// estimate is noise_std^2 P_K (the state model's, not a refit of sigma).
#include <fmt/format.h>

#include <chrono>
#include <cmath>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"

namespace {

class Rls : public exid::Estimator {
 public:
  static constexpr const char* kName = "rls";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "recursive least squares (paper eqns 6-7), P0 = p0 I or a prior, forgetting factor, "
      "Joseph-form symmetric update, history of the estimate and diag(P)";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_double("p0", 1e6, "",
                           "initial covariance P0 = p0 I (normalised by the noise variance)", 0.0,
                           std::nullopt, true),
        exid::param_double("forgetting_factor", 1.0, "",
                           "lambda in (0, 1]: weight lambda^(K-k) on row k; 1 = no forgetting", 0.0,
                           1.0, true, false),
        exid::param_int("history_stride", 1,
                        "record the estimate and diag(P) every N samples (the last one always)",
                        1.0, 1e9),
        exid::param_string(
            "update", std::string("joseph"),
            "joseph: symmetric Joseph form (robust to rounding); standard: eqn 7 as written "
            "(P - g g^T / (lambda + s)), also kept symmetric",
            {"joseph", "standard"}),
        exid::param_double(
            "noise_std", 0.0, "units of y",
            "standard deviation of one measurement, converts a prior covariance into "
            "P0 = Sigma0 / noise_std^2; 0: P0 = Sigma0",
            0.0),
        exid::param_bool(
            "residual_pass", false,
            "recompute the final residuals in a second pass over the data (always done "
            "when forgetting_factor < 1)"),
        exid::param_int("chunk_samples", 4096, "samples per chunk passed to the model", 1.0, 1e9),
        exid::param_doubles(
            "random_walk_std", std::vector<double>{}, "base parameter units per sqrt(s)",
            "Kalman filter of parameters that drift as a random walk: the std of each base "
            "parameter's drift over one second (one value for every base parameter, or one per "
            "base parameter; needs noise_std); empty: no drift (least squares)"),
    };
  }

  explicit Rls(const exid::ParamSet& p)
      : p0_(p.getDouble("p0")),
        lambda_(p.getDouble("forgetting_factor")),
        stride_(p.getInt("history_stride")),
        joseph_(p.getString("update") == "joseph"),
        noise_std_(p.getDouble("noise_std")),
        residual_pass_(p.getBool("residual_pass")),
        chunk_(static_cast<int>(p.getInt("chunk_samples"))),
        walk_(p.getDoubles("random_walk_std")) {
    for (double v : walk_)
      exid::check(v >= 0 && std::isfinite(v),
                  fmt::format("rls: random_walk_std: {} is not a std (finite, >= 0)", v));
    exid::check(walk_.empty() || noise_std_ > 0,
                "rls: random_walk_std needs noise_std (the std of one measurement, in units of "
                "y): the drift is weighed against it, and exid does not guess it");
    exid::check(walk_.empty() || lambda_ == 1.0,
                "rls: random_walk_std and forgetting_factor < 1 are two models of drifting "
                "parameters; give one");
  }

  exid::EstimatorSpecs specs() const override {
    exid::EstimatorSpecs s = exid::estimators::streamingSpecs();
    s.recursive = true;
    return s;
  }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override {
    const auto t0 = std::chrono::steady_clock::now();
    const int p = model.numBase();
    const int K = data.size();
    exid::check(K > 0, fmt::format("rls: the dataset '{}' is empty", data.source));

    // ---- initial state
    State st;
    Eigen::VectorXd theta0;
    Eigen::MatrixXd P0inv;  // for the residual identity
    initialState(prior, p, &theta0, &st.P, &P0inv);
    st.theta = theta0;

    // ---- history
    const long n_hist = (K - 1) / stride_ + 1 + ((K - 1) % stride_ != 0 ? 1 : 0);
    exid::Estimate e;
    e.history_t.resize(n_hist);
    e.history_value.resize(n_hist, p);
    e.history_pdiag.resize(n_hist, p);

    // ---- recursion
    recursion(model, data, ctx, n_hist, &st, &e);
    e.history_t.conservativeResize(st.h);
    e.history_value.conservativeResize(st.h, p);
    e.history_pdiag.conservativeResize(st.h, p);
    exid::check(st.theta.allFinite() && st.P.allFinite(),
                "rls: the recursion diverged (non-finite estimate); "
                "lower p0 or check the data scaling");

    // ---- residuals
    std::string rss_method;
    const double rss = residuals(model, data, ctx, st, theta0, P0inv, &rss_method);
    exid::check(st.m > p,
                fmt::format("rls: {} observation rows for {} base parameters; the estimate is the "
                            "prior's pull, not the data's (need more rows than parameters)",
                            st.m, p));

    // ---- result
    fillResult(model, prior != nullptr, st, rss, rss_method, &e);
    e.details["wall_s"] =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ctx.report(1.0, "rls: done");
    return e;
  }

 private:
  using Json = exid::Json;

  /// The recursion's state.
  struct State {
    Eigen::VectorXd theta;
    Eigen::MatrixXd P;   // lower triangle used
    double V = 0.0;      // weighted a-priori cost: V <- lambda V + e^2 / (lambda + s)
    long m = 0;          // rows
    double m_eff = 0.0;  // sum of the weights lambda^(K-k)
    long h = 0;          // history records
  };

  /// theta0 and P0 (the prior's, its covariance scaled by 1 / noise_std^2; or 0 and p0 I), and
  /// P0^-1.
  void initialState(const exid::Prior* prior, int p, Eigen::VectorXd* theta0, Eigen::MatrixXd* P,
                    Eigen::MatrixXd* P0inv) const {
    *theta0 = Eigen::VectorXd::Zero(p);
    *P = Eigen::MatrixXd::Zero(p, p);
    if (prior) {
      exid::check(
          prior->value.size() == p && prior->covariance.rows() == p &&
              prior->covariance.cols() == p,
          fmt::format("rls: the prior has {} values and a {}x{} covariance; the model has {} base "
                      "parameters",
                      prior->value.size(), prior->covariance.rows(), prior->covariance.cols(), p));
      const double scale = noise_std_ > 0 ? 1.0 / (noise_std_ * noise_std_) : 1.0;
      Eigen::MatrixXd S = 0.5 * (prior->covariance + prior->covariance.transpose()) * scale;
      Eigen::LLT<Eigen::MatrixXd> llt(S);
      exid::check(llt.info() == Eigen::Success && S.allFinite(),
                  "rls: the prior covariance is not symmetric positive definite");
      *theta0 = prior->value;
      *P = S;
      *P0inv = llt.solve(Eigen::MatrixXd::Identity(p, p));
    } else {
      P->diagonal().setConstant(p0_);
      *P0inv = Eigen::MatrixXd::Identity(p, p) / p0_;
    }
  }

  /// The recursion over every row in time order; the history (at most n_hist records) into e.
  void recursion(const exid::ObservationModel& model, const exid::Dataset& data,
                 const exid::RunContext& ctx, long n_hist, State* st, exid::Estimate* e) const {
    const int p = model.numBase();
    const int K = data.size();
    Eigen::VectorXd& theta = st->theta;
    Eigen::MatrixXd& P = st->P;
    Eigen::VectorXd g(p), k(p);
    std::vector<int> sample_of_row, order;
    const Eigen::VectorXd q2 = driftVariance(model);  // per second, normalised; empty: none
    double t_prev = NAN;
    exid::estimators::forEachChunk(
        model, data, chunk_, ctx, kName, 0.0, residualPass() ? 0.5 : 0.95,
        [&](const exid::Rows& r, int begin, int end) {
          const Eigen::MatrixXd Wt = r.W.transpose();
          exid::estimators::rowTimeOrder(r, end - begin, &sample_of_row, &order);
          const auto R = static_cast<int>(order.size());
          for (int idx = 0; idx < R; ++idx) {
            const int i = order[static_cast<std::size_t>(idx)];
            if (q2.size() > 0 && (idx == 0 || sample_of_row[static_cast<std::size_t>(i)] !=
                                                  sample_of_row[static_cast<std::size_t>(
                                                      order[static_cast<std::size_t>(idx - 1)])])) {
              // the Kalman prediction to this sample's time
              const double t =
                  rowTime(model, data, r, i, begin + sample_of_row[static_cast<std::size_t>(i)]);
              if (!std::isnan(t_prev)) {
                if (t < t_prev)  // (per sample: the message only on failure)
                  throw exid::Error(
                      fmt::format("rls: random_walk_std: the rows' times go back from {} s to {} s",
                                  t_prev, t));
                P.diagonal() += q2 * (t - t_prev);
              }
              t_prev = t;
            }
            const auto phi = Wt.col(i);
            g.noalias() = P.selfadjointView<Eigen::Lower>() * phi;
            const double s = phi.dot(g);
            const double den = lambda_ + s;
            k = g / den;
            const double err = r.y(i) - phi.dot(theta);
            theta.noalias() += err * k;
            st->V = lambda_ * st->V + err * err / den;
            st->m_eff = lambda_ * st->m_eff + 1.0;
            if (joseph_) {
              P.selfadjointView<Eigen::Lower>().rankUpdate(k, g, -1.0);
              P.selfadjointView<Eigen::Lower>().rankUpdate(k, den);
            } else {
              P.selfadjointView<Eigen::Lower>().rankUpdate(g, -1.0 / den);
            }
            if (lambda_ != 1.0) P.triangularView<Eigen::Lower>() *= 1.0 / lambda_;
            // history after the last row of a sample
            const int smp = sample_of_row[static_cast<std::size_t>(i)];
            const bool last_of_sample =
                idx + 1 == R ||
                sample_of_row[static_cast<std::size_t>(order[static_cast<std::size_t>(idx + 1)])] !=
                    smp;
            const long global = begin + smp;
            if (last_of_sample && (global % stride_ == 0 || global == K - 1) && st->h < n_hist)
              recordHistory(model, data, r, i, global, *st, e);
          }
          st->m += R;
        });
  }

  /// One history record: the estimate and diag(P) after row i of chunk r (sample `global`).
  void recordHistory(const exid::ObservationModel& model, const exid::Dataset& data,
                     const exid::Rows& r, int i, long global, State& st, exid::Estimate* e) const {
    const long h = st.h;
    e->history_t(h) = rowTime(model, data, r, i, global);
    e->history_value.row(h) = st.theta.transpose();
    e->history_pdiag.row(h) = st.P.diagonal().transpose();
    ++st.h;
  }

  /// The time of row i of chunk r (sample `global`): the row's own (a streamed dataset holds
  /// no samples itself), else the dataset's.
  static double rowTime(const exid::ObservationModel& model, const exid::Dataset& data,
                        const exid::Rows& r, int i, long global) {
    if (r.t.size() == static_cast<std::size_t>(r.y.size())) return r.t[static_cast<std::size_t>(i)];
    if (!data.streamed()) return data.t(global);
    throw exid::Error(
        fmt::format("rls: the model '{}' gives no time per row, needed for the history or the "
                    "drift of a streamed dataset",
                    model.pluginName()));
  }

  /// random_walk_std^2 / noise_std^2 per base parameter (empty without drift).
  Eigen::VectorXd driftVariance(const exid::ObservationModel& model) const {
    if (walk_.empty()) return {};
    const int p = model.numBase();
    exid::check(walk_.size() == 1 || walk_.size() == static_cast<std::size_t>(p),
                fmt::format("rls: random_walk_std has {} values; expected 1 or one per base "
                            "parameter ({})",
                            walk_.size(), p));
    Eigen::VectorXd q2(p);
    for (int j = 0; j < p; ++j) {
      const double v = walk_.size() == 1 ? walk_[0] : walk_[static_cast<std::size_t>(j)];
      q2[j] = v * v / (noise_std_ * noise_std_);
    }
    return q2;
  }

  /// ||y - W theta_K||^2: a second pass, or (lambda = 1) the exact identity; method: which.
  double residuals(const exid::ObservationModel& model, const exid::Dataset& data,
                   const exid::RunContext& ctx, const State& st, const Eigen::VectorXd& theta0,
                   const Eigen::MatrixXd& P0inv, std::string* method) const {
    double rss = 0.0;
    if (residualPass()) {
      const Eigen::VectorXd& theta = st.theta;
      exid::estimators::forEachChunk(
          model, data, chunk_, ctx, kName, 0.5, 0.95,
          [&](const exid::Rows& r, int, int) { rss += (r.y - r.W * theta).squaredNorm(); });
      *method = "second pass over the data with the final estimate";
    } else {
      // lambda = 1: RLS minimises ||y - W theta||^2 + (theta - theta0)^T P0^-1 (theta - theta0),
      // whose minimum is V; so ||y - W theta_K||^2 = V - (theta_K - theta0)^T P0^-1 (theta_K -
      // theta0).
      const Eigen::VectorXd dth = st.theta - theta0;
      rss = std::max(0.0, st.V - dth.dot(P0inv * dth));
      *method = "exact identity V_K - (theta_K - theta0)^T P0^-1 (theta_K - theta0) (lambda = 1)";
    }
    return rss;
  }

  /// The estimate, its covariance sigma^2 P_K and the details (without wall_s).
  void fillResult(const exid::ObservationModel& model, bool has_prior, const State& st, double rss,
                  const std::string& rss_method, exid::Estimate* ep) const {
    exid::Estimate& e = *ep;
    const int p = model.numBase();
    const long m = st.m;
    const Eigen::MatrixXd Pfull = st.P.selfadjointView<Eigen::Lower>();
    // (the Kalman filter: the state model's noise; least squares: refitted from the residuals)
    const double sigma2 = kalman() ? noise_std_ * noise_std_ : rss / static_cast<double>(m - p);
    const exid::BaseParameters& b = model.base();
    for (int i = 0; i < p; ++i) {
      const auto u = static_cast<std::size_t>(i);
      e.names.push_back(u < b.names.size() ? b.names[u] : fmt::format("theta{}", i + 1));
      e.expressions.push_back(u < b.expressions.size() ? b.expressions[u] : e.names.back());
    }
    e.value = st.theta;
    e.covariance = sigma2 * Pfull;
    e.std = e.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
    e.sigma = std::sqrt(sigma2);
    e.residual_rms = std::sqrt(rss / static_cast<double>(m));
    e.rows = m;
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Pfull, Eigen::EigenvaluesOnly);
    const double lmin = es.eigenvalues()(0), lmax = es.eigenvalues()(p - 1);
    e.cond_W = lmin > 0 ? std::sqrt(lmax / lmin) : INFINITY;
    exid::Json& d = e.details;
    d["estimator"] = kName;
    d["parameters"] = exid::estimators::parameterTable(e);
    d["rows"] = Json(static_cast<long long>(m));
    d["dof"] = Json(static_cast<long long>(m - p));
    d["effective_rows"] = st.m_eff;
    d["p0"] = has_prior ? Json(nullptr) : Json(p0_);
    d["prior"] = has_prior;
    d["forgetting_factor"] = lambda_;
    d["update"] = joseph_ ? "joseph" : "standard";
    d["sigma2"] = sigma2;
    d["rss"] = rss;
    d["rss_method"] = rss_method;
    d["std_definition"] =
        kalman() ? "covariance = noise_std^2 P_K: the Kalman filter's covariance of the final "
                   "parameters under its random-walk model (noise_std, random_walk_std given)"
                 : "covariance = sigma^2 P_K, sigma^2 = ||y - W theta_K||^2 / (m - p); with "
                   "forgetting (lambda < 1) this over-states the covariance of theta_K "
                   "(conservative)";
    d["filter"] = kalman() ? "kalman (random-walk parameters)" : "least squares";
    if (kalman()) d["random_walk_std"] = Json(walk_);
    d["cond_W_definition"] =
        "sqrt(cond(P_K)); P_K^-1 = W^T W + P0^-1 for lambda = 1, so ~ cond(W) when P0 is large";
    d["min_eig_P"] = lmin;
    d["history_stride"] = Json(static_cast<long long>(stride_));
    d["history_records"] = Json(static_cast<long long>(st.h));
  }
  bool residualPass() const { return residual_pass_ || lambda_ != 1.0 || kalman(); }
  bool kalman() const { return !walk_.empty(); }
  double p0_, lambda_;
  long stride_;
  bool joseph_;
  double noise_std_;
  bool residual_pass_;
  int chunk_;
  std::vector<double> walk_;
};

}  // namespace

EXID_REGISTER_PLUGIN(Rls)
