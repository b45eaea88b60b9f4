// exid — estimator `varpro`: one fit at given nonlinear parameters, streamed in chunks (the
// rows [W D y] folded into the triangular factor R; theta, rss, J^T J and J^T r from R), and
// the joint problem [W V] of the covariance (see varpro.cpp).
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "exid/delay.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/rank.hpp"
#include "varpro.hpp"

namespace exid::varpro {

// The whole problem's Gauss-Newton matrix [W V]^T [W V] = M^T M,
// M = [R11, R12 Theta; 0, R22 Theta] (the rows of [W D] in the QR basis).
Eigen::MatrixXd VarPro::jointMatrix(const exid::ObservationModel& model, const Eval& cur) const {
  const int p = model.numBase(), L = static_cast<int>(keep_.size()),
            q = static_cast<int>(nl_.size());
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(p + L, p + q);
  M.topLeftCorner(p, p) = cur.R.topLeftCorner(p, p);
  M.topRightCorner(p, q) = cur.R.block(0, p, p, L) * cur.Theta;
  M.bottomRightCorner(L, q) = cur.R.block(p, p, L, L) * cur.Theta;
  return M;
}

Eigen::VectorXd VarPro::columnScale(const Eigen::MatrixXd& M) {
  Eigen::VectorXd sc = M.colwise().norm().transpose();
  for (Eigen::Index i = 0; i < sc.size(); ++i) sc[i] = sc[i] > 0 ? 1.0 / sc[i] : 0.0;
  return sc;
}

bool VarPro::regular(const Eigen::MatrixXd& M) const {
  // (the decision of the column-scaled SVD; bounds from the triangular factor settle it without
  // one away from the tolerance)
  return exid::estimators::aboveRankTolerance(M * columnScale(M).asDiagonal(), opt_.rank_tolerance);
}

void VarPro::setUp(const exid::ObservationModel& model, const exid::Dataset& data) {
  fixed_.reset();
  nl_ = model.nonlinearParameters();
  q_model_ = static_cast<int>(nl_.size());
  exid::check(!nl_.empty() || delay_,
              fmt::format("varpro: model '{}' has no nonlinear parameter (e.g. differential "
                          "with stribeck or coulomb_smoothing_rad_s) and measurement_delay is "
                          "false; batch_ls gives its fit",
                          model.pluginName()));
  // the moved columns that are base columns (the others do not enter the rows)
  const std::vector<int> in_base = model.nonlinearColumnsInBase();
  keep_.clear();
  owner_.clear();
  base_col_.clear();
  std::size_t l = 0;
  for (std::size_t k = 0; k < nl_.size(); ++k) {
    bool any = false;
    for (std::size_t i = 0; i < nl_[k].columns.size(); ++i, ++l)
      if (in_base[l] >= 0) {
        keep_.push_back(static_cast<int>(l));
        owner_.push_back(static_cast<int>(k));
        base_col_.push_back(in_base[l]);
        any = true;
      }
    exid::check(any, fmt::format("varpro: nonlinear parameter '{}' moves no base column of "
                                 "model '{}' (its columns are not identifiable from this "
                                 "motion): it cannot be fitted",
                                 nl_[k].name, model.pluginName()));
  }
  margin_ = 0;
  ts_ = 1.0;
  if (!delay_) return;
  // The delay: one more parameter; its columns in D are dW/dd (every base column).
  exid::check(model.specs().per_sample,
              fmt::format("varpro: measurement_delay needs a model whose rows are per sample "
                          "(model '{}' builds rows from several samples)",
                          model.pluginName()));
  double jitter = 0.0;
  const double fs = exid::samplingRate(data, &jitter);
  exid::check(std::isfinite(fs) && fs > 0 && jitter < 0.5,
              fmt::format("varpro: measurement_delay needs time stamps of a steady rate "
                          "(found {:g} Hz with steps {:.0f} % off the median)",
                          fs, 100 * jitter));
  ts_ = 1.0 / fs;
  // samples within measurement_delay_max_s of an end (the shortest step: median (1 -
  // jitter)), plus the three the interpolation's stencil needs
  // (a hair below: a bound of exactly n samples is n, not n + 1 by a rounding)
  // (counted in double first: a bound of 1e300 s is no int; refused before it is converted)
  const double margin = std::ceil(delay_max_ * fs / (1.0 - jitter) * (1 - 1e-12)) + 3;
  exid::check(
      margin <= 0.5 * (data.size() - 8),
      fmt::format("varpro: measurement_delay_max_s = {:g} s leaves {} of {} samples at "
                  "{:g} Hz ({:g} without rows at each end; at least 8 are needed)",
                  delay_max_,
                  static_cast<long>(std::max(0.0, data.size() - 2 * std::min(margin, 1e15))),
                  data.size(), fs, margin));
  margin_ = static_cast<int>(margin);
  exid::NonlinearParameter d;
  d.name = "measurement_delay_s";
  d.unit = "s";
  d.value = delay0_;
  nl_.push_back(d);
  for (int c = 0; c < model.numBase(); ++c) {
    keep_.push_back(-1);
    owner_.push_back(static_cast<int>(nl_.size()) - 1);
    base_col_.push_back(c);
  }
}

// eta from lambda: exp for the model's parameters, d = ts lambda for the delay.
Eigen::VectorXd VarPro::etaOf(const Eigen::VectorXd& lambda) const {
  Eigen::VectorXd eta = lambda;
  for (int k = 0; k < q_model_; ++k) eta[k] = std::exp(lambda[k]);
  if (delay_) eta[eta.size() - 1] = ts_ * lambda[lambda.size() - 1];
  return eta;
}

// The rows of samples [b, end) at eta (model parameters and the delay): W, y and the
// derivative columns [dW_kept, dW/dd] into *D.
exid::Rows VarPro::chunkRows(const exid::ObservationModel& model, exid::SampleWindow& window, int b,
                             int end, const Eigen::VectorXd& eta, Eigen::MatrixXd* D,
                             const exid::RunContext& ctx) const {
  const int L = static_cast<int>(keep_.size()), Lm = L - (delay_ ? model.numBase() : 0);
  const Eigen::VectorXd eta_m = eta.head(q_model_);
  Eigen::MatrixXd dW;
  if (!delay_) {
    exid::Rows r = model.rowsAt(window.span(b, end), eta_m, &dW, ctx);
    D->resize(r.W.rows(), L);
    for (int l = 0; l < L; ++l) D->col(l) = dW.col(keep_[static_cast<std::size_t>(l)]);
    return r;
  }
  // the rows of the chunk and its margins, W (and dW) read at t_k - d
  const double d = eta[eta.size() - 1];
  const exid::Dataset span = window.span(b - margin_, end + margin_);
  const int S = span.size(), first = margin_, last = margin_ + end - b;
  const exid::Rows rs = model.rowsAt(span, eta_m, q_model_ > 0 ? &dW : nullptr, ctx);
  const auto R = static_cast<int>(rs.y.size());
  exid::check(R % S == 0 && rs.W.rows() == R,
              fmt::format("varpro: measurement_delay: model '{}' gave {} rows for {} samples "
                          "(not the same number per sample)",
                          model.pluginName(), R, S));
  const int P = R / S;
  exid::Rows r;
  Eigen::MatrixXd dWd;
  exid::shiftedRows(span.t, rs.W, P, -d, first, last, &r.W, &dWd);  // dWd: d/d(-d)
  r.y = rs.y.segment(static_cast<Eigen::Index>(first) * P,
                     static_cast<Eigen::Index>(last - first) * P);
  if (rs.equation.size() == static_cast<std::size_t>(R))
    r.equation.assign(rs.equation.begin() + first * P, rs.equation.begin() + last * P);
  r.numEquations = rs.numEquations;
  D->resize(r.W.rows(), L);
  if (Lm > 0) {
    Eigen::MatrixXd kept(R, Lm), kept_d;
    for (int l = 0; l < Lm; ++l) kept.col(l) = dW.col(keep_[static_cast<std::size_t>(l)]);
    exid::shiftedRows(span.t, kept, P, -d, first, last, &kept_d, nullptr);
    D->leftCols(Lm) = kept_d;
  }
  D->rightCols(L - Lm) = -dWd;
  return r;
}

// Each chunk's rows [W D y] by equation (a joint's torque rows), over the equation's non-zero
// columns: the fixed ones F (base columns no nonlinear parameter moves: the same at every
// evaluation) and the others X (the moved base columns, D, y). F's Householder factor
// F = Q_F [R_F; 0] is computed at the first evaluation and kept; each evaluation applies Q_F^T
// to X alone and factors what lies below R_F, so that the equation's factor is
// [R_F, (Q_F^T X)_top; 0, R_X]: the same R^T R as of its rows, with 4 k f x flops for the
// reflections instead of 2 k (f + x)^2 for a QR of all its columns (a 6-joint arm's first
// joint: about 4x fewer), applied as two matrix products (KeptFactor: the compact WY form).
// The kept F is compared with each evaluation's (a model whose "fixed" columns moved gets a new
// factor, which replaces the kept one: the grid's held rows may share the old). With a delay
// every column moves, with accumulate: normal or more than kHeldBytes of F there is nothing
// kept: RowAccumulator::addEquations.
void KeptFactor::compute(const Eigen::MatrixXd& F) {
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(F);
  const Eigen::Index k = F.rows(), f = F.cols();
  R = qr.matrixQR().topRows(f).triangularView<Eigen::Upper>();
  V = qr.matrixQR().triangularView<Eigen::StrictlyLower>();
  V.diagonal().setOnes();
  const Eigen::VectorXd& tau = qr.hCoeffs();
  T.setZero(f, f);
  for (Eigen::Index i = 0; i < f; ++i) {
    // T(0:i, i) = -tau_i T(0:i, 0:i) V(:, 0:i)^T v_i (v_i is zero above row i)
    if (i > 0) {
      const Eigen::VectorXd w = V.bottomLeftCorner(k - i, i).transpose() * V.col(i).tail(k - i);
      const Eigen::VectorXd tw = T.topLeftCorner(i, i).triangularView<Eigen::Upper>() * w;
      T.col(i).head(i) = -tau[i] * tw;
    }
    T(i, i) = tau[i];
  }
}

void KeptFactor::applyTransposeTo(Eigen::MatrixXd* X, Eigen::MatrixXd* work) const {
  // Q^T X = X - V T^T (V^T X)
  Eigen::MatrixXd& W = *work;
  W.noalias() = V.transpose() * *X;
  W = T.transpose().triangularView<Eigen::Lower>() * W;
  X->noalias() -= V * W;
}

void emitEquation(RowAccumulator* acc, const KeptFactor& qf, const std::vector<int>& fcols,
                  Eigen::MatrixXd* Xp, const std::vector<int>& xcols, Eigen::Index nc,
                  Eigen::MatrixXd* Ep) {
  Eigen::MatrixXd& X = *Xp;
  Eigen::MatrixXd& E = *Ep;
  const Eigen::Index k = X.rows(), x = X.cols(), f = static_cast<Eigen::Index>(fcols.size());
  qf.applyTransposeTo(&X, &E);
  Eigen::Ref<Eigen::MatrixXd> below = X.bottomRows(k - f);
  Eigen::HouseholderQR<Eigen::Ref<Eigen::MatrixXd>> qx(below);  // in place
  const Eigen::Index rx = std::min(k - f, x);
  E.setZero(f + rx, nc + 1);
  for (Eigen::Index c = 0; c < f; ++c)
    E.col(fcols[static_cast<std::size_t>(c)]).head(c + 1) = qf.R.col(c).head(c + 1);
  for (Eigen::Index c = 0; c < x; ++c) {
    const Eigen::Index to = xcols[static_cast<std::size_t>(c)];
    E.col(to).head(f) = X.col(c).head(f);
    // (R_X's upper triangle: its strictly lower part holds the reflections)
    E.col(to).segment(f, std::min(c + 1, rx)) = X.col(c).segment(f, std::min(c + 1, rx));
  }
  acc->add(E.leftCols(nc), E.col(nc));
}

void gatherEquation(const Eigen::MatrixXd& Xall, const std::vector<int>& colmap,
                    const Eigen::VectorXd& y, const std::vector<Eigen::Index>& rows,
                    Eigen::Index nc, Eigen::MatrixXd* Xp, std::vector<int>* xcols) {
  std::vector<Eigen::Index> src;
  exid::estimators::nonzeroColumns(Xall, rows, &src);
  const auto k = static_cast<Eigen::Index>(rows.size()),
             x = static_cast<Eigen::Index>(src.size()) + 1;
  Eigen::MatrixXd& X = *Xp;
  X.resize(k, x);
  xcols->clear();
  for (Eigen::Index c = 0; c + 1 < x; ++c) {
    const Eigen::Index a = src[static_cast<std::size_t>(c)];
    xcols->push_back(colmap[static_cast<std::size_t>(a)]);
    for (Eigen::Index i = 0; i < k; ++i) X(i, c) = Xall(rows[static_cast<std::size_t>(i)], a);
  }
  for (Eigen::Index i = 0; i < k; ++i) X(i, x - 1) = y[rows[static_cast<std::size_t>(i)]];
  xcols->push_back(static_cast<int>(nc));  // (y)
}

void VarPro::addChunk(RowAccumulator* acc, std::size_t chunk, const Eigen::MatrixXd& A,
                      const Eigen::VectorXd& y, const std::vector<int>& equation, int p) const {
  const Eigen::Index r = A.rows(), nc = A.cols();
  if (delay_ || method_ != RowAccumulator::Method::Qr ||
      static_cast<Eigen::Index>(equation.size()) != r || r < 64) {
    acc->addEquations(A, y, equation);
    return;
  }
  std::vector<bool> fixed(static_cast<std::size_t>(nc), false);
  for (int c = 0; c < p; ++c) fixed[static_cast<std::size_t>(c)] = true;
  for (const int c : base_col_) fixed[static_cast<std::size_t>(c)] = false;
  std::vector<int> labels;
  std::vector<std::vector<Eigen::Index>> rows;
  if (!exid::estimators::rowsByEquation(equation, &labels, &rows)) {
    acc->addEquations(A, y, equation);
    return;
  }
  if (!fixed_) fixed_ = std::make_shared<FixedFactors>();
  FixedFactors& ff = *fixed_;
  if (ff.chunks.size() <= chunk) ff.chunks.resize(chunk + 1);
  FixedFactors::Chunk& ch = ff.chunks[chunk];
  std::vector<std::shared_ptr<const FixedFactors::Equation>>& eqs = ch.eqs;
  if (eqs.size() != rows.size()) eqs.assign(rows.size(), nullptr);
  // (confirmed: every equation's F and y are the kept ones, the second time they are seen)
  ch.confirmed = ch.y.size() == y.size() && ch.equation == equation &&
                 std::memcmp(ch.y.data(), y.data(), sizeof(double) * y.size()) == 0;
  ch.y = y;
  ch.equation = equation;
  ch.whole = true;
  const long m = acc->rows() + r;
  std::vector<int> fcols, xcols;
  std::vector<Eigen::Index> nz;
  Eigen::MatrixXd F, X, E;
  for (std::size_t u = 0; u < rows.size(); ++u) {
    const std::vector<Eigen::Index>& idx = rows[u];
    const auto k = static_cast<Eigen::Index>(idx.size());
    fcols.clear();
    xcols.clear();
    exid::estimators::nonzeroColumns(A, idx, &nz);
    for (const Eigen::Index c : nz)
      (fixed[static_cast<std::size_t>(c)] ? fcols : xcols).push_back(static_cast<int>(c));
    const auto f = static_cast<Eigen::Index>(fcols.size()),
               x = static_cast<Eigen::Index>(xcols.size()) + 1;
    F.resize(k, f);
    for (Eigen::Index c = 0; c < f; ++c)
      for (Eigen::Index i = 0; i < k; ++i)
        F(i, c) = A(idx[static_cast<std::size_t>(i)], fcols[static_cast<std::size_t>(c)]);
    const FixedFactors::Equation* e = eqs[u].get();
    const bool kept = e && e->rows == idx && e->cols == fcols && e->F.rows() == k &&
                      e->F.cols() == f &&
                      (f == 0 || std::memcmp(e->F.data(), F.data(), sizeof(double) * k * f) == 0);
    if (!kept) {
      ch.confirmed = false;
      if (ff.bytes + 2.0 * sizeof(double) * k * f > kHeldBytes || k <= f + x || f == 0) {
        // (nothing kept: this equation's rows as addEquations takes them)
        Eigen::MatrixXd Ae(k, nc);
        Eigen::VectorXd ye(k);
        for (Eigen::Index i = 0; i < k; ++i) {
          Ae.row(i) = A.row(idx[static_cast<std::size_t>(i)]);
          ye[i] = y[idx[static_cast<std::size_t>(i)]];
        }
        acc->addEquations(Ae, ye, std::vector<int>(static_cast<std::size_t>(k), labels[u]));
        ch.whole = false;
        eqs[u].reset();
        continue;
      }
      ff.bytes += 2.0 * sizeof(double) * k * f;
      auto made = std::make_shared<FixedFactors::Equation>();
      made->rows = idx;
      made->cols = fcols;
      made->F = F;
      made->qr.compute(F);
      e = made.get();
      eqs[u] = std::move(made);
    }
    X.resize(k, x);
    for (Eigen::Index c = 0; c + 1 < x; ++c)
      for (Eigen::Index i = 0; i < k; ++i)
        X(i, c) = A(idx[static_cast<std::size_t>(i)], xcols[static_cast<std::size_t>(c)]);
    for (Eigen::Index i = 0; i < k; ++i) X(i, x - 1) = y[idx[static_cast<std::size_t>(i)]];
    xcols.push_back(static_cast<int>(nc));  // (y)
    emitEquation(acc, e->qr, e->cols, &X, xcols, nc, &E);
  }
  acc->setRowCount(m);
}

// The chunk's rows through the kept factors alone, the chunk's other columns given (Xall: the
// moved base columns and D, their columns among nc in cols): the rows' F and y are the kept
// ones (fixedConfirmed()).
void VarPro::addChunkKept(RowAccumulator* acc, std::size_t chunk, const Eigen::MatrixXd& Xall,
                          const std::vector<int>& cols, Eigen::Index nc) const {
  const FixedFactors::Chunk& ch = fixed_->chunks[chunk];
  const long m = acc->rows() + ch.y.size();
  std::vector<int> xcols;
  Eigen::MatrixXd X, E;
  for (const auto& ep : ch.eqs) {
    gatherEquation(Xall, cols, ch.y, ep->rows, nc, &X, &xcols);
    emitEquation(acc, ep->qr, ep->cols, &X, xcols, nc, &E);
  }
  acc->setRowCount(m);
}

bool VarPro::fixedConfirmed(std::size_t chunks) const {
  if (!fixed_ || fixed_->chunks.size() != chunks) return false;
  for (const FixedFactors::Chunk& ch : fixed_->chunks)
    if (!ch.whole || !ch.confirmed) return false;
  return true;
}

VarPro::Eval VarPro::evaluate(const exid::ObservationModel& model, const exid::Dataset& data,
                              const Eigen::VectorXd& lambda, const exid::RunContext& ctx,
                              bool rank_checked) const {
  const int p = model.numBase(), L = static_cast<int>(keep_.size()),
            q = static_cast<int>(nl_.size());
  Eval e;
  e.eta = etaOf(lambda);
  RowAccumulator acc(p + L, method_);
  const int first = margin_, last = data.size() - margin_;
  exid::SampleWindow window(data);
  Eigen::MatrixXd D, A;
  // Once the fixed columns' factors and y are kept and confirmed (fixedConfirmed), only the
  // moved base columns and their derivatives are asked of the model (fullColumnsAt), not its
  // whole rows.
  const auto chunks = static_cast<std::size_t>((last - first + chunk_ - 1) / chunk_);
  const bool columns_only = !delay_ && fixedConfirmed(chunks);
  if (columns_only) {
    std::vector<int> moved(base_col_.begin(), base_col_.end()), full, cols;
    std::sort(moved.begin(), moved.end());
    moved.erase(std::unique(moved.begin(), moved.end()), moved.end());
    for (const int c : moved) {
      full.push_back(model.base().independent[static_cast<std::size_t>(c)]);
      cols.push_back(c);
    }
    for (int l = 0; l < L; ++l) cols.push_back(p + l);
    const auto cm = static_cast<Eigen::Index>(moved.size());
    Eigen::MatrixXd dW, Xall;
    for (int b = first; b < last; b += chunk_) {
      const int end = std::min(last, b + chunk_);
      const std::size_t c = static_cast<std::size_t>((b - first) / chunk_);
      const Eigen::MatrixXd Wc = model.fullColumnsAt(window.span(b, end), e.eta, full, ctx, &dW);
      exid::check(Wc.rows() == fixed_->chunks[c].y.size() && dW.rows() == Wc.rows(),
                  "varpro: the model's row count changed with eta");
      Xall.resize(Wc.rows(), cm + L);
      Xall.leftCols(cm) = Wc;
      for (int l = 0; l < L; ++l) Xall.col(cm + l) = dW.col(keep_[static_cast<std::size_t>(l)]);
      if (!Xall.allFinite())
        throw exid::Error(
            fmt::format("varpro: a row from samples {}..{} is not finite at eta = [{}]", b, end,
                        fmt::join(e.eta.data(), e.eta.data() + q, ", ")));
      addChunkKept(&acc, c, Xall, cols, p + L);
    }
  }
  for (int b = first; b < last && !columns_only; b += chunk_) {
    const int end = std::min(last, b + chunk_);
    const exid::Rows r = chunkRows(model, window, b, end, e.eta, &D, ctx);
    exid::estimators::checkRows(r, p, kName, b);
    A.resize(r.W.rows(), p + L);
    A.leftCols(p) = r.W;
    A.rightCols(L) = D;
    if (!A.allFinite() || !r.y.allFinite())
      throw exid::Error(
          fmt::format("varpro: a row from samples {}..{} is not finite at eta = "
                      "[{}]",
                      b, end, fmt::join(e.eta.data(), e.eta.data() + q, ", ")));
    addChunk(&acc, static_cast<std::size_t>((b - first) / chunk_), A, r.y, r.equation, p);
  }
  e.m = acc.rows();
  // R of [W D y] (any factor F with F^T F = [W D y]^T [W D y] gives the same R)
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(acc.factor());
  e.R = qr.matrixQR().triangularView<Eigen::Upper>();
  // theta: the rank-revealing solve of [W y] (without its statistics: the estimate's come
  // from solve(.., true) at the end)
  if (rank_checked) {
    e.theta = e.R.topLeftCorner(p, p).triangularView<Eigen::Upper>().solve(e.R.col(p + L).head(p));
    if (!e.theta.allFinite())
      throw exid::Error(fmt::format("varpro: the fit at eta = [{}] is singular",
                                    fmt::join(e.eta.data(), e.eta.data() + q, ", ")));
  } else {
    e.ls = solve(model, e, false);
    e.theta = e.ls.theta;
  }
  e.rss = e.R.col(p + L).tail(L + 1).squaredNorm();
  e.yy = e.R.col(p + L).head(p + L + 1).squaredNorm();
  // V = D Theta in lambda: dW/dlambda_k = eta_k dW/deta_k; the delay: d = ts lambda
  e.Theta = Eigen::MatrixXd::Zero(L, q);
  for (int l = 0; l < L; ++l) {
    const int k = owner_[static_cast<std::size_t>(l)];
    e.Theta(l, k) =
        e.theta[base_col_[static_cast<std::size_t>(l)]] * (k < q_model_ ? e.eta[k] : ts_);
  }
  const Eigen::MatrixXd R22T = e.R.block(p, p, L, L).triangularView<Eigen::Upper>() * e.Theta;
  e.JtJ = R22T.transpose() * R22T;
  e.Jtr = -R22T.transpose() * e.R.col(p + L).segment(p, L);
  return e;
}

// The rank-revealing solve of [W y] at e (its Gram matrix from R's columns); with statistics,
// also theta's covariance, std and the unscaled singular values.
exid::estimators::LsSolution VarPro::solve(const exid::ObservationModel& model, const Eval& e,
                                           bool statistics) const {
  const int p = model.numBase(), L = static_cast<int>(keep_.size());
  RowAccumulator aw(p);
  Eigen::MatrixXd Rw(e.R.rows(), p);
  Rw = e.R.leftCols(p);
  aw.add(Rw, e.R.col(p + L));
  aw.setRowCount(e.m);
  exid::estimators::SolveOptions o = opt_;
  o.statistics = statistics;
  return exid::estimators::solveLeastSquares(aw, model.base().names, o, kName);
}

std::vector<std::string> VarPro::names() const {
  std::vector<std::string> out;
  for (const auto& p : nl_) out.push_back(p.name);
  return out;
}

}  // namespace exid::varpro
