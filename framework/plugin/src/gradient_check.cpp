#include "exid/gradient_check.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

namespace exid {

namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();
// The rounding noise of a central difference (f(x + h) - f(x - h)) / 2h, relative to |f| / h.
constexpr double kNoise = 16.0 * kEps;

using Namer = std::function<std::string(Eigen::Index row, Eigen::Index col)>;

double stepOr(const DerivativeCheckOptions& o, double fallback) {
  check(std::isfinite(o.relative_step) && o.relative_step >= 0.0,
        fmt::format("derivative check: relative_step must be finite and >= 0 (0: the default), "
                    "found {}",
                    o.relative_step));
  return o.relative_step > 0.0 ? o.relative_step : fallback;
}

DerivativeCheck start(const std::string& what, const DerivativeCheckOptions& o, double step) {
  DerivativeCheck c;
  c.what = what;
  c.tolerance = o.tolerance;
  c.step = step;
  return c;
}

/// Fills c's errors from the analytic and numeric derivatives (outputs x inputs) and the
/// differences' rounding noise (same shape).
void compare(const Eigen::MatrixXd& A, const Eigen::MatrixXd& N, const Eigen::MatrixXd& noise,
             const Namer& name, DerivativeCheck* c) {
  check(A.rows() == N.rows() && A.cols() == N.cols(),
        fmt::format("{}: the analytic derivative is {} x {}, the differences {} x {}", c->what,
                    A.rows(), A.cols(), N.rows(), N.cols()));
  c->analytic = A;
  c->numeric = N;
  c->max_rel_error = 0.0;
  c->max_abs_error = 0.0;
  c->worst.clear();
  bool finite = true;
  for (Eigen::Index i = 0; i < A.rows(); ++i) {
    double scale = 0.0;
    for (Eigen::Index j = 0; j < A.cols(); ++j)
      scale = std::max({scale, std::abs(A(i, j)), std::abs(N(i, j)), noise(i, j)});
    for (Eigen::Index j = 0; j < A.cols(); ++j) {
      const double err = std::abs(A(i, j) - N(i, j));
      const double rel = err == 0.0 ? 0.0 : err / scale;
      if (!std::isfinite(rel)) {
        if (finite) {
          c->worst = name(i, j);
          c->worst_analytic = A(i, j);
          c->worst_numeric = N(i, j);
        }
        finite = false;
        continue;
      }
      c->max_abs_error = std::max(c->max_abs_error, err);
      if (finite && (rel > c->max_rel_error || c->worst.empty())) {
        c->max_rel_error = rel;
        c->worst = name(i, j);
        c->worst_analytic = A(i, j);
        c->worst_numeric = N(i, j);
      }
    }
  }
  if (!finite) c->max_rel_error = std::numeric_limits<double>::infinity();
  c->ok = finite && c->max_rel_error <= c->tolerance;
}

/// The parts' aggregate: ok when every part is, the worst part's error, component and matrices.
DerivativeCheck aggregate(const std::string& what, const DerivativeCheckOptions& o, double step,
                          std::vector<DerivativeCheck> parts) {
  DerivativeCheck c = start(what, o, step);
  c.ok = true;
  const DerivativeCheck* worst = nullptr;
  for (const DerivativeCheck& p : parts) {
    c.ok = c.ok && p.ok;
    c.evaluations += p.evaluations;
    c.max_abs_error = std::max(c.max_abs_error, p.max_abs_error);
    if (!worst || !(p.max_rel_error <= worst->max_rel_error)) worst = &p;
  }
  if (worst) {
    c.max_rel_error = worst->max_rel_error;
    c.worst = worst->what + ": " + worst->worst;
    c.worst_analytic = worst->worst_analytic;
    c.worst_numeric = worst->worst_numeric;
    c.analytic = worst->analytic;
    c.numeric = worst->numeric;
  }
  c.parts = std::move(parts);
  return c;
}

std::string indexName(const std::vector<std::string>& names, Eigen::Index i, const char* stem) {
  if (i >= 0 && static_cast<std::size_t>(i) < names.size())
    return names[static_cast<std::size_t>(i)];
  return fmt::format("{}_{}", stem, i);
}

/// Central differences of a vector function: the Jacobian (outputs x inputs) and its rounding
/// noise; steps h_i = step * max(1, |x_i|).
void differences(const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& f,
                 const Eigen::VectorXd& x, double step, Eigen::Index outputs, Eigen::MatrixXd* N,
                 Eigen::MatrixXd* noise, long* evaluations) {
  N->resize(outputs, x.size());
  noise->resize(outputs, x.size());
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    const double h = step * std::max(1.0, std::abs(x(i)));
    Eigen::VectorXd xp = x, xm = x;
    xp(i) += h;
    xm(i) -= h;
    const Eigen::VectorXd fp = f(xp), fm = f(xm);
    *evaluations += 2;
    check(fp.size() == outputs && fm.size() == outputs,
          fmt::format("derivative check: the function gives {} values at x, {} at x + h e_{}",
                      outputs, fp.size(), i));
    N->col(i) = (fp - fm) / (2.0 * h);
    noise->col(i) = kNoise * fp.cwiseAbs().cwiseMax(fm.cwiseAbs()) / h;
  }
}

Eigen::MatrixXd randomLike(Eigen::Index rows, Eigen::Index cols, std::mt19937_64* rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index j = 0; j < cols; ++j)
    for (Eigen::Index i = 0; i < rows; ++i) m(i, j) = u(*rng);
  return m;
}

// ---- samples <-> one vector: [vec(q); vec(qd); vec(qdd)], column-major (Trajectory::jacobian)
Eigen::VectorXd flatten(const Samples& s) {
  const Eigen::Index m = s.q.size();
  Eigen::VectorXd v(3 * m);
  v.segment(0, m) = Eigen::Map<const Eigen::VectorXd>(s.q.data(), m);
  v.segment(m, m) = Eigen::Map<const Eigen::VectorXd>(s.qd.data(), m);
  v.segment(2 * m, m) = Eigen::Map<const Eigen::VectorXd>(s.qdd.data(), m);
  return v;
}

Samples unflatten(const Eigen::VectorXd& v, const Samples& like) {
  Samples s = like;
  const Eigen::Index m = like.q.size();
  s.q = Eigen::Map<const Eigen::MatrixXd>(v.data(), like.q.rows(), like.q.cols());
  s.qd = Eigen::Map<const Eigen::MatrixXd>(v.data() + m, like.q.rows(), like.q.cols());
  s.qdd = Eigen::Map<const Eigen::MatrixXd>(v.data() + 2 * m, like.q.rows(), like.q.cols());
  return s;
}

void checkShape(const Samples& s, Eigen::Index K, Eigen::Index n, const std::string& what) {
  check(s.q.rows() == K && s.q.cols() == n && s.qd.rows() == K && s.qd.cols() == n &&
            s.qdd.rows() == K && s.qdd.cols() == n,
        fmt::format("{}: q, qd, qdd must be {} x {} (samples x coordinates), found {} x {}, {} x "
                    "{}, {} x {}",
                    what, K, n, s.q.rows(), s.q.cols(), s.qd.rows(), s.qd.cols(), s.qdd.rows(),
                    s.qdd.cols()));
}

/// "qd(sample 4, coordinate 2)" for index r of [vec q; vec qd; vec qdd] (K samples).
std::string signalName(Eigen::Index r, Eigen::Index K, Eigen::Index n) {
  static const char* const kSignal[] = {"q", "qd", "qdd"};
  const Eigen::Index m = K * n, block = r / m, idx = r % m;
  return fmt::format("{}(sample {}, coordinate {})", kSignal[block], idx % K, idx / K);
}

/// A VJP against the differences: for random adjoints u, analytic vjp(u) (a row over the
/// inputs) against u^T N.
DerivativeCheck checkVjp(const std::string& what, const DerivativeCheckOptions& o, double step,
                         const Eigen::MatrixXd& N, const Eigen::MatrixXd& noise,
                         const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& vjp,
                         const Namer& input_name, std::mt19937_64* rng) {
  DerivativeCheck c = start(what, o, step);
  const int dirs = std::max(1, o.directions);
  Eigen::MatrixXd A(dirs, N.cols()), D(dirs, N.cols()), Z(dirs, N.cols());
  for (int d = 0; d < dirs; ++d) {
    const Eigen::VectorXd u = randomLike(N.rows(), 1, rng);
    const Eigen::VectorXd a = vjp(u);
    check(a.size() == N.cols(),
          fmt::format("{}: gives {} components, expected {}", what, a.size(), N.cols()));
    A.row(d) = a.transpose();
    D.row(d) = u.transpose() * N;
    Z.row(d) = u.cwiseAbs().transpose() * noise;
  }
  compare(
      A, D, Z,
      [&](Eigen::Index i, Eigen::Index j) {
        return fmt::format("adjoint {}, {}", i, input_name(0, j));
      },
      &c);
  return c;
}

}  // namespace

std::string DerivativeCheck::message() const {
  std::string m = fmt::format("{}: {} (max relative error {:.3g}, tolerance {:.3g}", what,
                              ok ? "ok" : "FAILED", max_rel_error, tolerance);
  if (!worst.empty())
    m += fmt::format(", at {}: analytic {:.10g}, differences {:.10g}", worst, worst_analytic,
                     worst_numeric);
  m += fmt::format("; relative step {:.3g}, {} evaluations)", step, evaluations);
  return m;
}

Json DerivativeCheck::toJson() const {
  Json j = Json::object();
  j["what"] = what;
  j["ok"] = ok;
  j["max_rel_error"] = max_rel_error;
  j["max_abs_error"] = max_abs_error;
  j["tolerance"] = tolerance;
  j["worst"] = worst;
  j["worst_analytic"] = worst_analytic;
  j["worst_numeric"] = worst_numeric;
  j["relative_step"] = step;
  j["evaluations"] = Json(static_cast<long long>(evaluations));
  if (analytic.rows() == 1) {
    j["analytic"] = Json(std::vector<double>(analytic.data(), analytic.data() + analytic.size()));
    j["numeric"] = Json(std::vector<double>(numeric.data(), numeric.data() + numeric.size()));
  }
  if (!parts.empty()) {
    Json ps = Json::array();
    for (const DerivativeCheck& p : parts) ps.push_back(p.toJson());
    j["parts"] = ps;
  }
  return j;
}

DerivativeCheck checkGradient(const std::function<double(const Eigen::VectorXd&)>& f,
                              const Eigen::VectorXd& x, const Eigen::VectorXd& gradient,
                              const DerivativeCheckOptions& options, const std::string& what,
                              const std::vector<std::string>& names) {
  const double step = stepOr(options, 1e-6);
  DerivativeCheck c = start(what, options, step);
  check(gradient.size() == x.size(),
        fmt::format("{}: the gradient has {} components, x {}", what, gradient.size(), x.size()));
  Eigen::MatrixXd N, noise;
  differences([&](const Eigen::VectorXd& v) { return Eigen::VectorXd::Constant(1, f(v)); }, x, step,
              1, &N, &noise, &c.evaluations);
  compare(
      gradient.transpose(), N, noise,
      [&](Eigen::Index, Eigen::Index j) { return indexName(names, j, "x"); }, &c);
  return c;
}

DerivativeCheck checkJacobian(const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& f,
                              const Eigen::VectorXd& x, const Eigen::MatrixXd& jacobian,
                              const DerivativeCheckOptions& options, const std::string& what,
                              const std::vector<std::string>& output_names,
                              const std::vector<std::string>& input_names) {
  const double step = stepOr(options, 1e-6);
  DerivativeCheck c = start(what, options, step);
  check(jacobian.cols() == x.size(), fmt::format("{}: the Jacobian has {} columns, x {} components",
                                                 what, jacobian.cols(), x.size()));
  Eigen::MatrixXd N, noise;
  differences(f, x, step, jacobian.rows(), &N, &noise, &c.evaluations);
  compare(
      jacobian, N, noise,
      [&](Eigen::Index i, Eigen::Index j) {
        return indexName(output_names, i, "f") + " / " + indexName(input_names, j, "x");
      },
      &c);
  return c;
}

DerivativeCheck checkCriterion(const Criterion& criterion, const Eigen::MatrixXd& M,
                               const DerivativeCheckOptions& options) {
  const double step = stepOr(options, 1e-4);
  const std::string what = fmt::format("criterion '{}': dJ/dM", criterion.pluginName());
  DerivativeCheck c = start(what, options, step);
  const Eigen::Index p = M.rows();
  check(
      p > 0 && M.cols() == p && M.allFinite(),
      fmt::format("{}: M must be a finite square matrix, found {} x {}", what, M.rows(), M.cols()));
  const Eigen::MatrixXd Ms = 0.5 * (M + M.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Ms, Eigen::EigenvaluesOnly);
  check(es.info() == Eigen::Success, what + ": the eigenvalues of M could not be computed");
  const double lmin = es.eigenvalues()(0);
  check(lmin > 0.0,
        fmt::format("{}: M must be positive definite (smallest eigenvalue {:g})", what, lmin));
  const double h = step * lmin;
  Eigen::MatrixXd G;
  const double J0 = criterion.evaluate(Ms, &G);
  ++c.evaluations;
  check(G.rows() == p && G.cols() == p,
        fmt::format("{}: dJ/dM is {} x {}, M {} x {}", what, G.rows(), G.cols(), p, p));
  const Eigen::Index m = p * (p + 1) / 2;
  Eigen::MatrixXd A(1, m), N(1, m), noise(1, m);
  std::vector<std::pair<Eigen::Index, Eigen::Index>> at;
  for (Eigen::Index j = 0; j < p; ++j)
    for (Eigen::Index i = 0; i <= j; ++i) {
      const Eigen::Index k = static_cast<Eigen::Index>(at.size());
      at.emplace_back(i, j);
      Eigen::MatrixXd Mp = Ms, Mm = Ms;
      Mp(i, j) += h;
      Mm(i, j) -= h;
      if (i != j) {
        Mp(j, i) += h;
        Mm(j, i) -= h;
      }
      const double Jp = criterion.evaluate(Mp, nullptr), Jm = criterion.evaluate(Mm, nullptr);
      c.evaluations += 2;
      A(0, k) = i == j ? G(i, i) : G(i, j) + G(j, i);
      N(0, k) = (Jp - Jm) / (2.0 * h);
      noise(0, k) = kNoise * std::max({std::abs(Jp), std::abs(Jm), std::abs(J0)}) / h;
    }
  compare(
      A, N, noise,
      [&](Eigen::Index, Eigen::Index k) {
        const auto [i, j] = at[static_cast<std::size_t>(k)];
        return fmt::format("M({}, {})", i, j);
      },
      &c);
  c.step = step;
  return c;
}

DerivativeCheck checkTrajectory(const Trajectory& trajectory, const Eigen::VectorXd& z,
                                const DerivativeCheckOptions& options) {
  const double step = stepOr(options, 1e-6);
  const std::string who = fmt::format("trajectory '{}'", trajectory.pluginName());
  check(z.size() == trajectory.numVariables(),
        fmt::format("{}: z has {} components, the trajectory {} variables", who, z.size(),
                    trajectory.numVariables()));
  const Samples s0 = trajectory.evaluate(z);
  const Eigen::Index K = s0.q.rows(), n = s0.q.cols(), nz = z.size();
  checkShape(s0, K, n, who + ": evaluate(z)");
  std::mt19937_64 rng(options.seed);
  const Namer zname = [](Eigen::Index, Eigen::Index j) { return fmt::format("z_{}", j); };
  std::vector<DerivativeCheck> parts;

  // Central differences of evaluate(): the Jacobian of [vec q; vec qd; vec qdd].
  Eigen::MatrixXd N, noise;
  long evals = 0;
  differences(
      [&](const Eigen::VectorXd& v) {
        const Samples s = trajectory.evaluate(v);
        checkShape(s, K, n, who + ": evaluate");
        return flatten(s);
      },
      z, step, 3 * K * n, &N, &noise, &evals);
  {
    DerivativeCheck c = start(who + ": jacobian", options, step);
    c.evaluations = evals;
    const Eigen::MatrixXd J = trajectory.jacobian(z);
    check(J.rows() == N.rows() && J.cols() == nz,
          fmt::format("{}: jacobian(z) is {} x {}, expected {} x {}", who, J.rows(), J.cols(),
                      N.rows(), nz));
    compare(
        J, N, noise,
        [&](Eigen::Index i, Eigen::Index j) { return signalName(i, K, n) + " / " + zname(0, j); },
        &c);
    parts.push_back(std::move(c));
  }
  parts.push_back(checkVjp(
      who + ": vjp", options, step, N, noise,
      [&](const Eigen::VectorXd& u) { return trajectory.vjp(z, unflatten(u, s0)); }, zname, &rng));

  if (trajectory.specs().continuous) {
    const Eigen::VectorXd t = s0.t;
    Eigen::MatrixXd Nt, noise_t;
    long evals_t = 0;
    differences(
        [&](const Eigen::VectorXd& v) {
          const Samples s = trajectory.evaluateAt(v, t);
          checkShape(s, K, n, who + ": evaluateAt");
          return flatten(s);
        },
        z, step, 3 * K * n, &Nt, &noise_t, &evals_t);
    DerivativeCheck c = checkVjp(
        who + ": vjpAt (the sample times)", options, step, Nt, noise_t,
        [&](const Eigen::VectorXd& u) { return trajectory.vjpAt(z, t, unflatten(u, s0)); }, zname,
        &rng);
    c.evaluations += evals_t;
    parts.push_back(std::move(c));
  }
  return aggregate(who + ": derivatives", options, step, std::move(parts));
}

DerivativeCheck checkModel(const ObservationModel& model, const Samples& s,
                           const DerivativeCheckOptions& options) {
  const double step = stepOr(options, 1e-6);
  const std::string who = fmt::format("model '{}'", model.pluginName());
  const Eigen::Index K = s.q.rows(), n = s.q.cols();
  checkShape(s, K, n, who + ": the samples");
  check(s.t.size() == K,
        fmt::format("{}: the samples have {} times for {} rows", who, s.t.size(), K));
  std::mt19937_64 rng(options.seed);
  const Eigen::VectorXd x = flatten(s);
  const Namer sname = [&](Eigen::Index, Eigen::Index j) { return signalName(j, K, n); };
  std::vector<DerivativeCheck> parts;

  // The design and its VJP: f(s) = vec(design(s)); the VJP of dW is dW : df/ds.
  auto vjpPart = [&](const std::string& what,
                     const std::function<Eigen::MatrixXd(const Samples&)>& design,
                     const std::function<Samples(const Eigen::MatrixXd&)>& vjp) {
    const Eigen::MatrixXd W0 = design(s);
    Eigen::MatrixXd N, noise;
    long evals = 1;
    differences(
        [&](const Eigen::VectorXd& v) {
          const Eigen::MatrixXd W = design(unflatten(v, s));
          check(W.rows() == W0.rows() && W.cols() == W0.cols(),
                fmt::format("{}: the design changes shape ({} x {} to {} x {})", what, W0.rows(),
                            W0.cols(), W.rows(), W.cols()));
          return Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(W.data(), W.size()));
        },
        x, step, W0.size(), &N, &noise, &evals);
    DerivativeCheck c = checkVjp(
        what, options, step, N, noise,
        [&](const Eigen::VectorXd& u) {
          const Samples g = vjp(Eigen::Map<const Eigen::MatrixXd>(u.data(), W0.rows(), W0.cols()));
          checkShape(g, K, n, what);
          return flatten(g);
        },
        sname, &rng);
    c.evaluations += evals;
    parts.push_back(std::move(c));
  };
  vjpPart(
      who + ": fullDesignVjp", [&](const Samples& v) { return model.fullDesign(v); },
      [&](const Eigen::MatrixXd& dW) {
        Samples g;
        model.fullDesignVjp(s, dW, &g);
        return g;
      });

  const std::vector<NonlinearParameter> nl = model.nonlinearParameters();
  if (!nl.empty()) {
    Eigen::VectorXd eta(static_cast<Eigen::Index>(nl.size()));
    for (std::size_t k = 0; k < nl.size(); ++k) eta(static_cast<Eigen::Index>(k)) = nl[k].value;
    vjpPart(
        who + ": fullDesignVjpAt",
        [&](const Samples& v) { return model.fullDesignAt(v, eta, nullptr); },
        [&](const Eigen::MatrixXd& dW) {
          Samples g;
          model.fullDesignVjpAt(s, eta, dW, &g);
          return g;
        });
    // The columns moved by eta: fullDesignAt's dW (rows x L) against differences over eta.
    DerivativeCheck c = start(who + ": fullDesignAt dW/deta", options, step);
    Eigen::MatrixXd dW;
    const Eigen::MatrixXd W0 = model.fullDesignAt(s, eta, &dW);
    ++c.evaluations;
    std::vector<std::pair<std::size_t, int>> cols;  // (k, full column) per column of dW
    for (std::size_t k = 0; k < nl.size(); ++k)
      for (int col : nl[k].columns) cols.emplace_back(k, col);
    check(dW.rows() == W0.rows() && dW.cols() == static_cast<Eigen::Index>(cols.size()),
          fmt::format("{}: dW is {} x {}, expected {} x {}", c.what, dW.rows(), dW.cols(),
                      W0.rows(), cols.size()));
    Eigen::MatrixXd A = dW.transpose(), N(A.rows(), A.cols()), noise(A.rows(), A.cols());
    for (Eigen::Index l = 0; l < A.rows(); ++l) {
      const auto [k, col] = cols[static_cast<std::size_t>(l)];
      const Eigen::Index ki = static_cast<Eigen::Index>(k);
      const double h = step * (eta(ki) != 0.0 ? std::abs(eta(ki)) : 1.0);
      Eigen::VectorXd ep = eta, em = eta;
      ep(ki) += h;
      em(ki) -= h;
      const Eigen::MatrixXd Wp = model.fullDesignAt(s, ep, nullptr);
      const Eigen::MatrixXd Wm = model.fullDesignAt(s, em, nullptr);
      c.evaluations += 2;
      N.row(l) = ((Wp.col(col) - Wm.col(col)) / (2.0 * h)).transpose();
      noise.row(l) =
          (kNoise * Wp.col(col).cwiseAbs().cwiseMax(Wm.col(col).cwiseAbs()) / h).transpose();
    }
    const std::vector<std::string> names = model.fullNames();
    compare(
        A, N, noise,
        [&](Eigen::Index l, Eigen::Index r) {
          const auto [k, col] = cols[static_cast<std::size_t>(l)];
          return fmt::format("W(row {}, column {}) / {}", r, indexName(names, col, "column"),
                             nl[k].name);
        },
        &c);
    parts.push_back(std::move(c));
  }
  return aggregate(who + ": derivatives", options, step, std::move(parts));
}

}  // namespace exid
