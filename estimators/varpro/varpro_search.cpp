// exid — estimator `varpro`: the globalisation (a grid over each group's multiples, the
// linear part exact at each point; the checks around the best end) and Levenberg-Marquardt on
// lambda = log(eta) from each start (see varpro.cpp).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "varpro.hpp"

namespace exid::varpro {

// "vs1 = 0.05 rad/s, eps1 = ..." (the delay in s)
std::string VarPro::where(const Eigen::VectorXd& eta) const {
  std::string out;
  for (std::size_t k = 0; k < nl_.size(); ++k)
    out += fmt::format("{}{} = {:.6g} {}", k ? ", " : "", nl_[k].name,
                       eta[static_cast<Eigen::Index>(k)], nl_[k].unit);
  return out;
}

// The model's nonlinear parameters in groups that move common columns (union-find; for
// `differential`: one joint's eps and vs); the delay is in none (it is not a scale).
std::vector<std::vector<int>> VarPro::groups() const {
  std::vector<int> parent(static_cast<std::size_t>(q_model_));
  for (int k = 0; k < q_model_; ++k) parent[static_cast<std::size_t>(k)] = k;
  auto find = [&](int k) {
    while (parent[static_cast<std::size_t>(k)] != k) k = parent[static_cast<std::size_t>(k)];
    return k;
  };
  for (int a = 0; a < q_model_; ++a)
    for (int b = a + 1; b < q_model_; ++b) {
      const auto& ca = nl_[static_cast<std::size_t>(a)].columns;
      const auto& cb = nl_[static_cast<std::size_t>(b)].columns;
      const bool shared = std::any_of(ca.begin(), ca.end(), [&](int c) {
        return std::find(cb.begin(), cb.end(), c) != cb.end();
      });
      if (shared) parent[static_cast<std::size_t>(find(b))] = find(a);
    }
  std::vector<std::vector<int>> out;
  std::vector<int> slot(static_cast<std::size_t>(q_model_), -1);
  for (int k = 0; k < q_model_; ++k) {
    const int r = find(k);
    if (slot[static_cast<std::size_t>(r)] < 0) {
      slot[static_cast<std::size_t>(r)] = static_cast<int>(out.size());
      out.emplace_back();
    }
    out[static_cast<std::size_t>(slot[static_cast<std::size_t>(r)])].push_back(k);
  }
  return out;
}

// Block-coordinate search over the grid: for each group in turn, every combination of the
// multipliers on its parameters (one common multiplier when the combinations would exceed
// 125), the other groups at the best point so far; the linear part solved exactly at each.
VarPro::Grid VarPro::searchGrid(const exid::ObservationModel& model, const exid::Dataset& data,
                                const Eigen::VectorXd& lambda0, const Eval& at_study,
                                const exid::RunContext& ctx) {
  Grid g;
  g.best = lambda0;
  g.best_eval = at_study;
  g.groups = groups();
  for (int i = 0; i < starts_; ++i)
    g.multipliers.push_back(i == 0 ? 1.0 : std::pow(2.0, (i % 2 ? -1.0 : 1.0) * ((i + 1) / 2)));
  const int S = static_cast<int>(g.multipliers.size());
  if (S < 2) return g;
  // sweeps over the groups until one improves nothing (at most 3): a group scanned while the
  // others were far off can prefer a wrong point, which the next sweep corrects
  for (g.sweeps = 1; g.sweeps <= 3; ++g.sweeps) {
    const double before = g.best_eval.rss;
    sweep(model, data, lambda0, &g, ctx);
    if (!(g.best_eval.rss < before)) break;
  }
  g.sweeps = std::min(g.sweeps, 3);
  return g;
}

// The residual at points that move only the base columns of some nonlinear parameters (one
// group of the grid, one parameter of a scan), the others held at `lambda`. The held columns'
// rows A and y are kept with the triangular factor [R z; 0 rho] of [A y] (each joint's rows over
// its own columns first: from the kept factors of the fixed columns, or
// RowAccumulator::addEquations); at each point only the moved columns B are computed, and with
// u = R^-T A^T B (A^T B over B's non-zero rows: a friction column lives on one joint's rows)
//   rss = rho^2 - b^T G^-1 b,  G = B^T B - u^T u,  b = B^T y - u^T z,
// the residual of y on [A B] (the Gram matrix of B's part orthogonal to A, and its projection
// of y). A semi-normal form: its rounding is eps ||B||^2 / ||B_perp||^2 of G, far below what
// separates the grid's points, and a point it takes is then evaluated in full (tryPoint); it
// costs the model's B and 2 f nnz(B) flops instead of the QR of all p + L + 1 columns and the
// SVD of the solve. With the kept factors, A is kept by equation (Part: the kept F and the
// other groups' columns), and A^T B is a product per equation where B is non-zero; otherwise
// row by row (At). A delay is held too (the grid does not move it; the rows are read at t_k - d
// as evaluate reads them). Unused (every point a whole evaluation) when the held rows would
// exceed kHeldBytes, or when the held columns are not of full rank.
struct VarPro::Held {
  bool ok = false;
  std::vector<int> moved;  // base columns recomputed at each point (ascending)
  Eigen::MatrixXd At;      // f x m: the held columns' rows, one column each (without parts)
  Eigen::VectorXd y;       // m (without parts)
  Eigen::MatrixXd R;       // f x f upper triangular: R^T R = A^T A
  Eigen::VectorXd z;       // R^-T A^T y
  double rho2 = 0.0;       // ||y||^2 - ||z||^2: the residual on A alone
  Eigen::Index m = 0;
  // From the kept factors (fromKept), the held rows by equation instead of At: F's kept rows
  // (shared with evaluate's FixedFactors) at the held positions fpos, and the other groups'
  // moved columns non-zero in them (O, at opos); At is then empty.
  struct Part {
    std::shared_ptr<const FixedFactors::Equation> e;
    Eigen::Index offset = 0;  // the chunk's first row among the m
    std::vector<int> fpos, opos;
    Eigen::MatrixXd O;  // k x o
    Eigen::VectorXd y;  // k
  };
  std::vector<Part> parts;

  Held(const VarPro& vp, const exid::ObservationModel& model, const exid::Dataset& data,
       const Eigen::VectorXd& lambda, const std::vector<int>& params, const exid::RunContext& ctx) {
    if (!vp.project_) return;
    const int p = model.numBase();
    for (std::size_t l = 0; l < vp.keep_.size(); ++l)
      if (std::find(params.begin(), params.end(), vp.owner_[l]) != params.end())
        moved.push_back(vp.base_col_[l]);
    std::sort(moved.begin(), moved.end());
    moved.erase(std::unique(moved.begin(), moved.end()), moved.end());
    const int c = static_cast<int>(moved.size()), f = p - c;
    if (c == 0 || f == 0) return;
    std::vector<int> held;
    for (int j = 0, k = 0; j < p; ++j) {
      if (k < c && moved[static_cast<std::size_t>(k)] == j)
        ++k;
      else
        held.push_back(j);
    }
    const Eigen::VectorXd eta = vp.heldEta(lambda);
    RowAccumulator acc(f, RowAccumulator::Method::Qr);
    Eigen::MatrixXd Ah;
    if (fromKept(vp, model, data, eta, held, ctx, &acc)) {
      finish(acc, p, f);
      return;
    }
    bool fits = true;
    m = rows(vp, model, data, eta, ctx, [&](const exid::Rows& r, Eigen::Index at) {
      if (!fits) return;
      const Eigen::Index need = at + r.W.rows();
      if (static_cast<double>(need) * (f + 1) * sizeof(double) > kHeldBytes) {
        fits = false;
        return;
      }
      if (need > At.cols()) {  // (grown geometrically: the row count is known at the end)
        const Eigen::Index cap = std::max<Eigen::Index>(need, 2 * At.cols());
        At.conservativeResize(f, cap);
        y.conservativeResize(cap);
      }
      Ah.resize(r.W.rows(), f);
      for (int j = 0; j < f; ++j) Ah.col(j) = r.W.col(held[static_cast<std::size_t>(j)]);
      At.middleCols(at, r.W.rows()) = Ah.transpose();
      y.segment(at, r.W.rows()) = r.y;
      acc.addEquations(Ah, r.y, r.equation);
    });
    if (!fits) return;
    At.conservativeResize(f, m);
    y.conservativeResize(m);
    finish(acc, p, f);
  }

  // The held rows from the fixed columns evaluate() keeps (VarPro::FixedFactors: the same values
  // at every eta) and the other groups' moved columns from the model (fullColumnsAt), instead of
  // the model's whole rows; each equation's factor from F's kept Householder factor, reflecting
  // only the other groups' moved columns and y (emitEquation). False (nothing done) when
  // nothing is kept for every chunk.
  bool fromKept(const VarPro& vp, const exid::ObservationModel& model, const exid::Dataset& data,
                const Eigen::VectorXd& eta, const std::vector<int>& held,
                const exid::RunContext& ctx, RowAccumulator* acc) {
    if (vp.delay_ || !vp.fixed_) return false;
    const std::vector<FixedFactors::Chunk>& chunks = vp.fixed_->chunks;
    const int first = vp.margin_, last = data.size() - vp.margin_;
    const auto count = static_cast<std::size_t>((last - first + vp.chunk_ - 1) / vp.chunk_);
    if (chunks.size() != count) return false;
    Eigen::Index total = 0;
    for (const FixedFactors::Chunk& ch : chunks) {
      if (!ch.whole) return false;
      total += ch.y.size();
    }
    const auto f = static_cast<Eigen::Index>(held.size());
    if (static_cast<double>(total) * (f + 1) * sizeof(double) > kHeldBytes) return false;
    const int p = model.numBase();
    std::vector<int> pos(static_cast<std::size_t>(p), -1), others, full;
    std::vector<bool> moves(static_cast<std::size_t>(p), false);
    for (const int c : vp.base_col_) moves[static_cast<std::size_t>(c)] = true;
    for (Eigen::Index j = 0; j < f; ++j) {
      const int c = held[static_cast<std::size_t>(j)];
      pos[static_cast<std::size_t>(c)] = static_cast<int>(j);
      if (moves[static_cast<std::size_t>(c)]) {
        others.push_back(c);
        full.push_back(model.base().independent[static_cast<std::size_t>(c)]);
      }
    }
    parts.clear();
    exid::SampleWindow window(data);
    Eigen::Index at = 0;
    Eigen::MatrixXd Wc, X, E;
    std::vector<int> xpos, opos_of;  // (opos_of: each of Wc's columns' held position)
    for (const int o : others) opos_of.push_back(pos[static_cast<std::size_t>(o)]);
    for (std::size_t c = 0; c < chunks.size(); ++c) {
      const FixedFactors::Chunk& ch = chunks[c];
      const int b = first + static_cast<int>(c) * vp.chunk_, end = std::min(last, b + vp.chunk_);
      const Eigen::Index r = ch.y.size();
      if (!others.empty()) {
        Wc = model.fullColumnsAt(window.span(b, end), eta, full, ctx);
        exid::check(Wc.rows() == r && Wc.cols() == static_cast<Eigen::Index>(others.size()),
                    "varpro: the model's row count changed with eta");
        if (!Wc.allFinite())
          throw exid::Error(fmt::format("varpro: a row from samples {}..{} is not finite", b, end));
      } else {
        Wc.resize(r, 0);
      }
      // each equation's factor from F's kept one: Q_F^T applied to the other groups' moved
      // columns (those non-zero in its rows) and y alone (emitEquation, as evaluate does)
      for (const auto& ep : ch.eqs) {
        Part pt;
        pt.e = ep;
        pt.offset = at;
        const std::vector<Eigen::Index>& idx = ep->rows;
        for (std::size_t a = 0; a < ep->cols.size(); ++a) {
          const int j = pos[static_cast<std::size_t>(ep->cols[a])];
          exid::check(j >= 0, "varpro: a fixed column is not held");
          pt.fpos.push_back(j);
        }
        gatherEquation(Wc, opos_of, ch.y, idx, f, &X, &xpos);
        pt.opos.assign(xpos.begin(), xpos.end() - 1);
        pt.O = X.leftCols(X.cols() - 1);
        pt.y = X.col(X.cols() - 1);
        emitEquation(acc, ep->qr, pt.fpos, &X, xpos, f, &E);
        parts.push_back(std::move(pt));
      }
      at += r;
    }
    acc->setRowCount(total);
    m = total;
    return true;
  }

  void finish(const RowAccumulator& acc, int p, Eigen::Index f) {
    if (m <= p) return;
    const Eigen::MatrixXd& F = acc.factor();
    R = F.topLeftCorner(f, f).triangularView<Eigen::Upper>();
    const Eigen::VectorXd d = R.diagonal().cwiseAbs();
    if (!(d.minCoeff() > 1e-12 * d.maxCoeff())) return;  // held columns of deficient rank
    z = F.col(f).head(f);
    rho2 = F(f, f) * F(f, f);
    ok = true;
  }

  // The model's rows at eta, chunk by chunk as VarPro::evaluate reads them; their count.
  template <class F>
  static Eigen::Index rows(const VarPro& vp, const exid::ObservationModel& model,
                           const exid::Dataset& data, const Eigen::VectorXd& eta,
                           const exid::RunContext& ctx, F&& take) {
    exid::SampleWindow window(data);
    Eigen::Index m = 0;
    Eigen::MatrixXd D;
    const int first = vp.margin_, last = data.size() - vp.margin_;
    for (int b = first; b < last; b += vp.chunk_) {
      const int end = std::min(last, b + vp.chunk_);
      // (with a delay the rows are read at t_k - d, as evaluate reads them)
      const exid::Rows r = vp.delay_ ? vp.chunkRows(model, window, b, end, eta, &D, ctx)
                                     : model.rowsAt(window.span(b, end), eta, nullptr, ctx);
      exid::estimators::checkRows(r, model.numBase(), kName, b);
      if (!r.W.allFinite() || !r.y.allFinite())
        throw exid::Error(fmt::format("varpro: a row from samples {}..{} is not finite", b, end));
      take(r, m);
      m += r.W.rows();
    }
    return m;
  }

  double rss(const VarPro& vp, const exid::ObservationModel& model, const exid::Dataset& data,
             const Eigen::VectorXd& lambda, const exid::RunContext& ctx) const {
    const int c = static_cast<int>(moved.size());
    const Eigen::Index f = R.cols();
    Eigen::MatrixXd B(m, c);
    const Eigen::VectorXd eta = vp.heldEta(lambda);
    Eigen::Index got = 0;
    if (!vp.delay_) {
      // the moved columns alone (ObservationModel::fullColumnsAt: a base column is the full
      // column base().independent names), chunk by chunk as rows() reads them
      std::vector<int> full(static_cast<std::size_t>(c));
      for (int j = 0; j < c; ++j)
        full[static_cast<std::size_t>(j)] =
            model.base().independent[static_cast<std::size_t>(moved[static_cast<std::size_t>(j)])];
      exid::SampleWindow window(data);
      const int first = vp.margin_, last = data.size() - vp.margin_;
      for (int b = first; b < last; b += vp.chunk_) {
        const int end = std::min(last, b + vp.chunk_);
        const Eigen::MatrixXd Wc = model.fullColumnsAt(window.span(b, end), eta, full, ctx);
        exid::check(Wc.cols() == c && got + Wc.rows() <= m,
                    "varpro: the model's row count changed with eta");
        if (!Wc.allFinite())
          throw exid::Error(fmt::format("varpro: a row from samples {}..{} is not finite", b, end));
        B.block(got, 0, Wc.rows(), c) = Wc;
        got += Wc.rows();
      }
    } else {
      got = rows(vp, model, data, eta, ctx, [&](const exid::Rows& r, Eigen::Index at) {
        exid::check(at + r.W.rows() <= m, "varpro: the model's row count changed with eta");
        for (int j = 0; j < c; ++j)
          B.col(j).segment(at, r.W.rows()) = r.W.col(moved[static_cast<std::size_t>(j)]);
      });
    }
    exid::check(got == m, "varpro: the model's row count changed with eta");
    Eigen::MatrixXd AtB = Eigen::MatrixXd::Zero(f, c), G = Eigen::MatrixXd::Zero(c, c);
    Eigen::VectorXd b = Eigen::VectorXd::Zero(c);
    if (!parts.empty()) {
      // by equation: A's rows there are F's kept rows and the other groups' columns O, so
      // A^T B = sum over the equations where B is non-zero of [F O]^T B_e (two small products)
      Eigen::MatrixXd Be, P;
      for (const Part& pt : parts) {
        const std::vector<Eigen::Index>& idx = pt.e->rows;
        const auto k = static_cast<Eigen::Index>(idx.size());
        Be.resize(k, c);
        for (int j = 0; j < c; ++j)
          for (Eigen::Index i = 0; i < k; ++i)
            Be(i, j) = B(pt.offset + idx[static_cast<std::size_t>(i)], j);
        if (Be.isZero(0.0)) continue;
        P.noalias() = pt.e->F.transpose() * Be;
        for (std::size_t a = 0; a < pt.fpos.size(); ++a)
          AtB.row(pt.fpos[a]) += P.row(static_cast<Eigen::Index>(a));
        if (pt.O.cols() > 0) {
          P.noalias() = pt.O.transpose() * Be;
          for (std::size_t a = 0; a < pt.opos.size(); ++a)
            AtB.row(pt.opos[a]) += P.row(static_cast<Eigen::Index>(a));
        }
        b.noalias() += Be.transpose() * pt.y;
        G.noalias() += Be.transpose() * Be;
      }
      return residual(AtB, G, b);
    }
    // A^T B, B^T B and B^T y over B's non-zero rows: each held row (a column of At) read once
    // for every moved column non-zero there (each sum still over its rows in ascending order)
    std::vector<Eigen::Index> any;
    for (Eigen::Index i = 0; i < m; ++i)
      for (int j = 0; j < c; ++j)
        if (B(i, j) != 0.0) {
          any.push_back(i);
          break;
        }
    for (const Eigen::Index i : any)
      for (int j = 0; j < c; ++j) {
        const double bij = B(i, j);
        if (bij == 0.0) continue;
        AtB.col(j).noalias() += bij * At.col(i);
        b[j] += bij * y[i];
      }
    for (int j = 0; j < c; ++j)
      for (int l = 0; l <= j; ++l) {
        double s = 0.0;
        for (const Eigen::Index i : any)
          if (B(i, j) != 0.0) s += B(i, j) * B(i, l);
        G(j, l) = s;
        G(l, j) = s;
      }
    return residual(AtB, G, b);
  }

  // rho^2 - b^T G^-1 b after the projection on A (u = R^-T A^T B)
  double residual(const Eigen::MatrixXd& AtB, Eigen::MatrixXd G, Eigen::VectorXd b) const {
    const auto c = static_cast<int>(G.rows());
    const Eigen::MatrixXd u = R.transpose().triangularView<Eigen::Lower>().solve(AtB);
    G.noalias() -= u.transpose() * u;
    b.noalias() -= u.transpose() * z;
    // G^-1 b by the eigen-decomposition (B's part orthogonal to A may be deficient: its
    // directions below the rank tolerance do not lower the residual)
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(G);
    const Eigen::VectorXd ev = es.eigenvalues();
    const Eigen::VectorXd v = es.eigenvectors().transpose() * b;
    const double top = std::max(ev.cwiseAbs().maxCoeff(), 0.0);
    double fitted = 0.0;
    for (int j = 0; j < c; ++j)
      if (ev[j] > 1e-12 * top) fitted += v[j] * v[j] / ev[j];
    return std::max(0.0, rho2 - fitted);
  }
};

void VarPro::tryPoint(const exid::ObservationModel& model, const exid::Dataset& data,
                      const Held& held, const Eigen::VectorXd& lambda, Grid* gp,
                      const exid::RunContext& ctx) const {
  Grid& g = *gp;
  ++g.evaluations;
  try {
    double r = NAN;
    if (held.ok) {
      r = held.rss(*this, model, data, lambda, ctx);
      if (!(std::isfinite(r) && r < g.best_eval.rss)) return;  // (not taken: no check needed)
    }
    Eval e = evaluate(model, data, lambda, ctx);
    if (held.ok && std::isfinite(e.rss)) {
      ++g.projected_checked;
      g.projected_difference =
          std::max(g.projected_difference, std::abs(r - e.rss) / std::max(e.yy, 1e-300));
    }
    if (std::isfinite(e.rss) && e.rss < g.best_eval.rss) {
      g.best = lambda;
      g.best_eval = std::move(e);
    }
  } catch (const exid::Error&) {
    ++g.singular;
  }
}

void VarPro::checkHeld(const exid::ObservationModel& model, const exid::Dataset& data,
                       const Held& held, const Eigen::VectorXd& lambda, Grid* gp,
                       const exid::RunContext& ctx) const {
  Grid& g = *gp;
  if (!held.ok || !std::isfinite(g.best_eval.rss)) return;
  // (its columns are those of the best point's whole evaluation: an error here is the
  // held rows' own, as in the constructor)
  const double r = held.rss(*this, model, data, lambda, ctx);
  ++g.held_checked;
  g.projected_difference = std::max(
      g.projected_difference, std::abs(r - g.best_eval.rss) / std::max(g.best_eval.yy, 1e-300));
}

void VarPro::sweep(const exid::ObservationModel& model, const exid::Dataset& data,
                   const Eigen::VectorXd& lambda0, Grid* gp, const exid::RunContext& ctx) {
  Grid& g = *gp;
  const int S = static_cast<int>(g.multipliers.size());
  for (const auto& grp : g.groups) {
    const int n = static_cast<int>(grp.size());
    const bool common = std::pow(S, n) > 125;
    const long combos = common ? S : static_cast<long>(std::lround(std::pow(S, n)));
    const Eigen::VectorXd base = g.best;
    const Held held(*this, model, data, base, grp, ctx);
    checkHeld(model, data, held, base, &g, ctx);
    for (long c = 0; c < combos; ++c) {
      if (ctx.shouldStop()) throw exid::Error("varpro: stopped");
      Eigen::VectorXd lambda = base;
      long rest = c;
      for (int i = 0; i < n; ++i) {
        const int digit = common ? static_cast<int>(c) : static_cast<int>(rest % S);
        rest /= S;
        lambda[grp[static_cast<std::size_t>(i)]] =
            lambda0[grp[static_cast<std::size_t>(i)]] +
            std::log(g.multipliers[static_cast<std::size_t>(digit)]);
      }
      if (lambda == base) continue;  // (the point itself: known)
      tryPoint(model, data, held, lambda, &g, ctx);
    }
  }
}

// Each model parameter alone at kAxisMultipliers of the centre's value, the others at the best
// point so far.
void VarPro::axisScan(const exid::ObservationModel& model, const exid::Dataset& data,
                      const Eigen::VectorXd& centre, Grid* gp, const exid::RunContext& ctx) {
  Grid& g = *gp;
  for (int k = 0; k < q_model_; ++k) {
    // (the other parameters stay at g.best's values while k is scanned: a point taken moves
    // only k)
    const Held held(*this, model, data, g.best, {k}, ctx);
    checkHeld(model, data, held, g.best, &g, ctx);
    for (double mult : kAxisMultipliers) {
      if (ctx.shouldStop()) throw exid::Error("varpro: stopped");
      Eigen::VectorXd lambda = g.best;
      lambda[k] = centre[k] + std::log(mult);
      if (lambda == g.best) continue;
      tryPoint(model, data, held, lambda, &g, ctx);
    }
  }
}

// Every stride-th sample of d (read in chunks: a stream is never held whole).
exid::Dataset VarPro::strided(const exid::Dataset& d, long stride) {
  const int K = d.size();
  const int n = static_cast<int>((K + stride - 1) / stride);
  exid::Dataset out;
  out.source = d.source;
  out.meta = d.meta;
  out.facts = d.facts;
  exid::SampleWindow window(d);
  int row = 0;
  constexpr int kChunk = 8192;
  for (int b = 0; b < K; b += kChunk) {
    const exid::Dataset c = window.span(b, std::min(K, b + kChunk));
    auto take = [&](const Eigen::MatrixXd& src, Eigen::MatrixXd& dst) {
      if (src.cols() == 0) return;
      if (dst.rows() != n) dst.resize(n, src.cols());
      int r = row;
      for (int k = static_cast<int>((b + stride - 1) / stride * stride); k < b + c.size();
           k += static_cast<int>(stride))
        dst.row(r++) = src.row(k - b);
    };
    if (out.t.size() != n) out.t.resize(n);
    int r = row;
    for (int k = static_cast<int>((b + stride - 1) / stride * stride); k < b + c.size();
         k += static_cast<int>(stride))
      out.t(r++) = c.t(k - b);
    take(c.q, out.q);
    take(c.qd, out.qd);
    take(c.qdd, out.qdd);
    take(c.tau, out.tau);
    take(c.wrench, out.wrench);
    row = r;
  }
  return out;
}

// Levenberg-Marquardt on lambda = log(eta) from `lambda` (its fit `cur`).
VarPro::Run VarPro::levenbergMarquardt(const exid::ObservationModel& model,
                                       const exid::Dataset& data, Eigen::VectorXd lambda, Eval cur,
                                       const std::string& origin, const exid::RunContext& ctx) {
  const int q = static_cast<int>(nl_.size());
  Run run;
  run.origin = origin;
  run.eta0 = cur.eta;
  int evals = 1, iterations = 0;
  double mu = 1e-3;
  std::string stop;
  auto record = [&](const Eval& e) {
    exid::Json t = exid::Json::object();
    t["rss"] = e.rss;
    // (eta: the nonlinear parameters in their units, the delay in s)
    t["eta"] = exid::Json(std::vector<double>(e.eta.data(), e.eta.data() + e.eta.size()));
    run.trace.push_back(t);
  };
  record(cur);
  bool cur_regular = regular(jointMatrix(model, cur));
  while (evals < max_evals_) {
    if (ctx.shouldStop()) throw exid::Error("varpro: stopped");
    const Eigen::MatrixXd H = cur.JtJ;
    if (cur.Jtr.norm() == 0.0) {
      stop = "zero gradient";
      break;
    }
    bool accepted = false;
    double decrease = 0.0;
    Eigen::VectorXd delta;
    while (evals < max_evals_) {
      Eigen::MatrixXd A = H;
      A.diagonal() += mu * H.diagonal().cwiseMax(1e-300);
      delta = A.ldlt().solve(-cur.Jtr);
      if (!delta.allFinite() && mu < 1e30) {
        mu *= 10;
        continue;
      }
      if (!delta.allFinite()) break;
      // A trial where the fit is singular (a width so large that s is constant, say) or not
      // finite is a rejected step, as one that raises the residual.
      Eval trial;
      bool ok = true;
      int trial_regular = -1;  // the trial's joint problem regular (1) or not (0); -1: not tested
      if (delay_ && std::abs(ts_ * (lambda[q - 1] + delta[q - 1])) > delay_max_) {
        ok = false;  // outside the delays the kept rows allow
        ++rejected_bound_;
      } else {
        try {
          // (from a regular point the trial's regularity is tested below: no SVD in its solve)
          trial = evaluate(model, data, lambda + delta, ctx, cur_regular);
          // a step from a regular point into one where the joint problem is singular (a
          // Stribeck velocity drifting so high that its term is a Coulomb term, or so low that
          // it vanishes) is rejected: there the nonlinear parameter is not determined, and
          // the run would wander where no start can bring it back
          if (cur_regular) trial_regular = regular(jointMatrix(model, trial)) ? 1 : 0;
          if (trial_regular == 0) {
            ok = false;
            ++rejected_singular_;
          }
        } catch (const exid::Error&) {
          ok = false;
          ++rejected_singular_;
        }
      }
      ++evals;
      if (ok && std::isfinite(trial.rss) && trial.rss <= cur.rss) {
        lambda += delta;
        // (tested above when the point it left was regular: one SVD per trial)
        cur_regular = trial_regular >= 0 ? trial_regular == 1 : regular(jointMatrix(model, trial));
        decrease = (cur.rss - trial.rss) / std::max(cur.rss, 1e-300);
        cur = std::move(trial);
        record(cur);
        mu = std::max(mu / 3.0, 1e-12);
        accepted = true;
        break;
      }
      mu *= 4.0;
      if (delta.cwiseAbs().maxCoeff() < xtol_) break;
    }
    ++iterations;
    if (!accepted && evals >= max_evals_) break;  // (not converged)
    if (!accepted) {
      stop = "no step decreases the residual";
      break;
    }
    if (delta.cwiseAbs().maxCoeff() < xtol_) {
      stop = fmt::format("step in log(eta) below step_tolerance = {:g}", xtol_);
      break;
    }
    if (decrease < ftol_) {
      stop = fmt::format("the residual fell by {:.2g} of itself, below rss_tolerance = {:g}",
                         decrease, ftol_);
      break;
    }
  }
  if (stop.empty()) stop = fmt::format("max_evaluations = {} reached", max_evals_);
  run.lambda = lambda;
  run.cur = std::move(cur);
  run.evals = evals;
  run.iterations = iterations;
  run.stop = stop;
  return run;
}

// The first-order test at a run's end, and whether the joint problem is regular there.
void VarPro::firstOrder(const exid::ObservationModel& model, Run* r) const {
  const Eval& e = r->cur;
  r->gradient_norm = 2.0 * e.Jtr.norm();  // ||d rss / d lambda|| = 2 ||J^T r||
  // g^T (J^T J)^+ g: the decrease of rss the Gauss-Newton step predicts
  Eigen::JacobiSVD<Eigen::MatrixXd> s(e.JtJ, Eigen::ComputeThinU | Eigen::ComputeThinV);
  s.setThreshold(1e-14);
  const double pred = e.Jtr.dot(s.solve(e.Jtr));
  r->gn_fraction = e.rss > 0 ? pred / e.rss : 0.0;
  // exact to rounding: the residual below 1e-12 of the measurement, relatively
  r->exact = e.rss <= 1e-24 * e.yy;
  r->stationary = r->exact || (std::isfinite(r->gn_fraction) && r->gn_fraction <= gtol_);
  r->M = jointMatrix(model, e);
  r->singular = !regular(r->M);
}

}  // namespace exid::varpro
