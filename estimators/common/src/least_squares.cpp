// Streaming QR / normal-equation accumulation and the rank-revealing least-squares solve.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "exid/dynamics.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/common.hpp"

namespace exid::estimators {

namespace {
std::vector<double> toStd(const Eigen::VectorXd& v) { return {v.data(), v.data() + v.size()}; }

}  // namespace

void nonzeroColumns(const Eigen::Ref<const Eigen::MatrixXd>& W,
                    const std::vector<Eigen::Index>& idx, std::vector<Eigen::Index>* cols) {
  cols->clear();
  // (eight rows at a time without a branch: a column that is zero in these rows, the common
  // case, is read through once)
  const std::size_t k = idx.size(), k8 = k - k % 8;
  for (Eigen::Index c = 0; c < W.cols(); ++c) {
    const double* w = W.col(c).data();
    bool nz = false;
    for (std::size_t i = 0; i < k8 && !nz; i += 8) {
      unsigned any = 0;
      for (std::size_t t = 0; t < 8; ++t) any |= static_cast<unsigned>(w[idx[i + t]] != 0.0);
      nz = any != 0;
    }
    for (std::size_t i = k8; i < k && !nz; ++i) nz = w[idx[i]] != 0.0;
    if (nz) cols->push_back(c);
  }
}

bool rowsByEquation(const std::vector<int>& equation, std::vector<int>* labels,
                    std::vector<std::vector<Eigen::Index>>* rows) {
  // (labels are few: joints, wrench components; found by a search among those seen, not by
  // sorting every row's label)
  labels->clear();
  for (const int l : equation) {
    const auto at = std::lower_bound(labels->begin(), labels->end(), l);
    if (at != labels->end() && *at == l) continue;
    if (labels->size() == 64) return false;
    labels->insert(at, l);
  }
  rows->assign(labels->size(), {});
  for (std::size_t i = 0; i < equation.size(); ++i)
    (*rows)[static_cast<std::size_t>(std::lower_bound(labels->begin(), labels->end(), equation[i]) -
                                     labels->begin())]
        .push_back(static_cast<Eigen::Index>(i));
  return true;
}

// ---------------------------------------------------------------- RowAccumulator
RowAccumulator::RowAccumulator(int p, Method method, int block_rows)
    : p_(p), method_(method), block_rows_(std::max(block_rows, 8)) {
  check(p > 0, "RowAccumulator: no parameter column");
  const int a = p + 1;
  if (method_ == Method::Qr) {
    buf_ = Eigen::MatrixXd::Zero(a + block_rows_, a);
    fill_ = a;  // the top a rows hold R (zero at first)
  } else {
    buf_ = Eigen::MatrixXd::Zero(block_rows_, a);
    gram_ = Eigen::MatrixXd::Zero(a, a);
    fill_ = 0;
  }
}

void RowAccumulator::compress() const {
  const int a = p_ + 1;
  if (method_ == Method::Qr) {
    if (fill_ == a) return;
    Eigen::Ref<Eigen::MatrixXd> block = buf_.topRows(fill_);
    Eigen::HouseholderQR<Eigen::Ref<Eigen::MatrixXd>> qr(block);  // in place
    buf_.topRows(a).triangularView<Eigen::StrictlyLower>().setZero();
    buf_.middleRows(a, fill_ - a).setZero();
    fill_ = a;
  } else {
    if (fill_ == 0) return;
    gram_.selfadjointView<Eigen::Lower>().rankUpdate(buf_.topRows(fill_).transpose());
    fill_ = 0;
  }
  dirty_ = true;
}

void RowAccumulator::add(const Eigen::Ref<const Eigen::MatrixXd>& W,
                         const Eigen::Ref<const Eigen::VectorXd>& y, double scale) {
  if (W.cols() != p_ || W.rows() != y.size())  // (the message only when it fails: hot path)
    throw Error(
        fmt::format("RowAccumulator: rows of {} x {} and y of {}, expected {} columns "
                    "and one y per row",
                    W.rows(), W.cols(), y.size(), p_));
  const Eigen::Index r = W.rows();
  if (method_ == Method::Normal && fill_ == 0 && r >= 64) {
    // A large block goes straight into the Gram matrix (no copy into the buffer):
    // [W y]^T [W y] = [W^T W, W^T y; y^T W, y^T y] (lower triangle kept).
    const int pp = p_;
    const double s2 = scale * scale;
    gram_.topLeftCorner(pp, pp).selfadjointView<Eigen::Lower>().rankUpdate(W.transpose(), s2);
    gram_.row(pp).head(pp).noalias() += s2 * (y.transpose() * W);
    gram_(pp, pp) += s2 * y.squaredNorm();
    m_ += r;
    dirty_ = true;
    return;
  }
  const Eigen::Index cap = buf_.rows();
  Eigen::Index i = 0;
  while (i < r) {
    if (fill_ == cap) compress();
    const Eigen::Index take = std::min<Eigen::Index>(r - i, cap - fill_);
    if (scale == 1.0) {
      buf_.block(fill_, 0, take, p_) = W.middleRows(i, take);
      buf_.block(fill_, p_, take, 1) = y.segment(i, take);
    } else {
      buf_.block(fill_, 0, take, p_) = scale * W.middleRows(i, take);
      buf_.block(fill_, p_, take, 1) = scale * y.segment(i, take);
    }
    fill_ += static_cast<int>(take);
    i += take;
  }
  m_ += r;
  dirty_ = true;
}

void RowAccumulator::addEquations(const Eigen::Ref<const Eigen::MatrixXd>& W,
                                  const Eigen::Ref<const Eigen::VectorXd>& y,
                                  const std::vector<int>& equation) {
  const Eigen::Index r = W.rows();
  if (static_cast<Eigen::Index>(equation.size()) != r || r < 64) {
    add(W, y);
    return;
  }
  if (W.cols() != p_ || y.size() != r)
    throw Error(
        fmt::format("RowAccumulator: rows of {} x {} and y of {}, expected {} columns "
                    "and one y per row",
                    r, W.cols(), y.size(), p_));
  // the rows of each equation, in order
  std::vector<int> labels;
  std::vector<std::vector<Eigen::Index>> rows;
  if (!rowsByEquation(equation, &labels, &rows)) {
    add(W, y);
    return;
  }
  std::vector<Eigen::Index> cols;
  if (method_ == Method::Qr) {
    addEquationsQr(W, y, rows);
    return;
  }
  std::vector<double> B, G;
  for (const auto& idx : rows) {
    // the columns not zero in these rows (y always), ascending: the lower triangle of their
    // Gram matrix lands in the lower triangle of the whole one
    nonzeroColumns(W, idx, &cols);
    const auto q = static_cast<Eigen::Index>(cols.size());
    // the rows, row-major with the padding zero, and their Gram matrix by gramUpdate (the same
    // bits on every CPU, in AVX registers where there are some)
    const int m = static_cast<int>(q + 1), ld = (m + 3) & ~3;
    const auto k = static_cast<Eigen::Index>(idx.size());
    B.assign(static_cast<std::size_t>(k * ld), 0.0);
    for (Eigen::Index c = 0; c < q; ++c) {
      const double* w = W.col(cols[static_cast<std::size_t>(c)]).data();
      for (Eigen::Index i = 0; i < k; ++i)
        B[static_cast<std::size_t>(i * ld + c)] = w[idx[static_cast<std::size_t>(i)]];
    }
    for (Eigen::Index i = 0; i < k; ++i)
      B[static_cast<std::size_t>(i * ld + q)] = y(idx[static_cast<std::size_t>(i)]);
    cols.push_back(p_);
    G.assign(static_cast<std::size_t>(m * ld), 0.0);
    exid::gramUpdate(G.data(), ld, B.data(), ld, static_cast<int>(k), m);
    for (Eigen::Index a = 0; a <= q; ++a)
      for (Eigen::Index b = 0; b <= a; ++b)
        gram_(cols[static_cast<std::size_t>(a)], cols[static_cast<std::size_t>(b)]) +=
            G[static_cast<std::size_t>(a * ld + b)];
  }
  m_ += r;
  dirty_ = true;
}

// Qr: each equation's rows over its own non-zero columns (and y) reduced to their triangular
// factor first (Householder, in place), whose rows, put back in their columns, are added: the
// same R^T R as of the rows themselves, with the flops of the equations' narrow blocks (a 6-joint
// arm's joint rows span on average about a third of the columns: about a ninth of the flops).
void RowAccumulator::addEquationsQr(const Eigen::Ref<const Eigen::MatrixXd>& W,
                                    const Eigen::Ref<const Eigen::VectorXd>& y,
                                    const std::vector<std::vector<Eigen::Index>>& rows) {
  const long m = m_ + W.rows();
  std::vector<Eigen::Index> cols;
  Eigen::MatrixXd C, E;
  for (const auto& idx : rows) {
    nonzeroColumns(W, idx, &cols);
    const auto q = static_cast<Eigen::Index>(cols.size());
    const auto k = static_cast<Eigen::Index>(idx.size());
    C.resize(k, q + 1);
    for (Eigen::Index c = 0; c < q; ++c) {
      const double* w = W.col(cols[static_cast<std::size_t>(c)]).data();
      for (Eigen::Index i = 0; i < k; ++i) C(i, c) = w[idx[static_cast<std::size_t>(i)]];
    }
    for (Eigen::Index i = 0; i < k; ++i) C(i, q) = y(idx[static_cast<std::size_t>(i)]);
    // (fewer rows than columns: the rows themselves)
    const Eigen::Index rr = std::min(k, q + 1);
    if (k > q + 1) {
      Eigen::HouseholderQR<Eigen::Ref<Eigen::MatrixXd>> qr(C);  // in place
      C.topRows(rr).triangularView<Eigen::StrictlyLower>().setZero();
    }
    E.setZero(rr, p_ + 1);
    for (Eigen::Index c = 0; c < q; ++c)
      E.col(cols[static_cast<std::size_t>(c)]) = C.col(c).head(rr);
    E.col(p_) = C.col(q).head(rr);
    add(E.leftCols(p_), E.col(p_));
  }
  m_ = m;
}

void RowAccumulator::addRow(const Eigen::Ref<const Eigen::RowVectorXd>& w, double y, double scale) {
  if (w.size() != p_)  // (the message only when it fails: once per row)
    throw Error(fmt::format("RowAccumulator: row has {} columns, expected {}", w.size(), p_));
  if (fill_ == buf_.rows()) compress();
  buf_.block(fill_, 0, 1, p_) = scale * w;
  buf_(fill_, p_) = scale * y;
  ++fill_;
  ++m_;
  dirty_ = true;
}

void RowAccumulator::merge(const RowAccumulator& other, double scale) {
  check(other.p_ == p_, "RowAccumulator::merge: different numbers of columns");
  const Eigen::MatrixXd& F = other.factor();
  const long m = m_ + other.m_;
  add(F.leftCols(p_), F.col(p_), scale);
  m_ = m;
}

const Eigen::MatrixXd& RowAccumulator::normalLower() const {
  if (method_ != Method::Normal)
    throw Error("RowAccumulator: normalLower() of a QR accumulator (it holds R, not W^T W)");
  compress();
  return gram_;
}

const Eigen::MatrixXd& RowAccumulator::factor() const {
  compress();
  if (!dirty_) return F_;
  const int a = p_ + 1;
  if (method_ == Method::Qr) {
    F_ = buf_.topRows(a);
  } else {
    Eigen::MatrixXd G = gram_.selfadjointView<Eigen::Lower>();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(G);
    Eigen::VectorXd l = es.eigenvalues().cwiseMax(0.0).cwiseSqrt();
    F_ = l.asDiagonal() * es.eigenvectors().transpose();
  }
  dirty_ = false;
  return F_;
}

double RowAccumulator::residualSquared(const Eigen::VectorXd& theta) const {
  const Eigen::MatrixXd& F = factor();
  return (F.leftCols(p_) * theta - F.col(p_)).squaredNorm();
}

Eigen::VectorXd RowAccumulator::columnNorms() const {
  return factor().leftCols(p_).colwise().norm().transpose();
}

double RowAccumulator::ySquaredNorm() const {
  if (method_ == Method::Normal) {
    compress();
    return gram_(p_, p_);
  }
  return factor().col(p_).squaredNorm();
}

double RowAccumulator::minimumResidualSquared() const {
  if (method_ == Method::Qr) {
    const double r = factor()(p_, p_);
    return r * r;
  }
  compress();
  const Eigen::MatrixXd G = gram_.topLeftCorner(p_, p_).selfadjointView<Eigen::Lower>();
  const Eigen::VectorXd b = gram_.row(p_).head(p_).transpose();
  Eigen::VectorXd d = G.diagonal().cwiseMax(0.0).cwiseSqrt();
  for (Eigen::Index j = 0; j < p_; ++j)
    if (!(d(j) > 0.0)) return HUGE_VAL;
  const Eigen::VectorXd di = d.cwiseInverse();
  Eigen::LDLT<Eigen::MatrixXd> ldlt(di.asDiagonal() * G * di.asDiagonal());
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0.0)) return HUGE_VAL;
  const Eigen::VectorXd bs = di.asDiagonal() * b;
  return std::max(0.0, gram_(p_, p_) - bs.dot(ldlt.solve(bs)));
}

double RowAccumulator::scaledCondition() const {
  if (method_ == Method::Normal) {
    compress();
    const Eigen::MatrixXd G = gram_.topLeftCorner(p_, p_).selfadjointView<Eigen::Lower>();
    Eigen::VectorXd d = G.diagonal().cwiseMax(0.0).cwiseSqrt();
    for (Eigen::Index j = 0; j < p_; ++j)
      if (!(d(j) > 0.0)) return std::numeric_limits<double>::infinity();
    const Eigen::VectorXd di = d.cwiseInverse();
    const Eigen::MatrixXd Gs = di.asDiagonal() * G * di.asDiagonal();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Gs, Eigen::EigenvaluesOnly);
    const double lmin = es.eigenvalues()(0), lmax = es.eigenvalues()(p_ - 1);
    if (!(lmin > 0.0) || !std::isfinite(lmax)) return std::numeric_limits<double>::infinity();
    return std::sqrt(lmax / lmin);
  }
  const Eigen::MatrixXd Fw = factor().leftCols(p_);
  Eigen::VectorXd d = Fw.colwise().norm().transpose();
  for (Eigen::Index j = 0; j < p_; ++j)
    if (!(d(j) > 0.0)) return std::numeric_limits<double>::infinity();
  const Eigen::VectorXd s =
      Eigen::JacobiSVD<Eigen::MatrixXd>(Fw * d.cwiseInverse().asDiagonal()).singularValues();
  return s(p_ - 1) > 0.0 ? s(0) / s(p_ - 1) : std::numeric_limits<double>::infinity();
}

// ---------------------------------------------------------------- solve
Eigen::VectorXd relativeStdPercent(const Eigen::VectorXd& value, const Eigen::VectorXd& std) {
  Eigen::VectorXd r(value.size());
  for (Eigen::Index i = 0; i < value.size(); ++i)
    r(i) = value(i) != 0.0 ? 100.0 * std(i) / std::abs(value(i))
                           : std::numeric_limits<double>::infinity();
  return r;
}

std::string explainNullSpace(const Eigen::MatrixXd& null_vectors, const Eigen::VectorXd& ratios,
                             const std::vector<std::string>& names, int terms) {
  std::string out;
  for (Eigen::Index d = 0; d < null_vectors.cols(); ++d) {
    Eigen::VectorXd v = null_vectors.col(d);
    v /= v.norm();
    std::vector<int> idx(static_cast<std::size_t>(v.size()));
    std::iota(idx.begin(), idx.end(), 0);
    std::stable_sort(idx.begin(), idx.end(),
                     [&](int a, int b) { return std::abs(v(a)) > std::abs(v(b)); });
    // sign convention: largest component positive
    if (v(idx[0]) < 0) v = -v;
    std::string expr;
    int shown = 0;
    for (int i : idx) {
      if (shown >= terms || (shown > 0 && std::abs(v(i)) < 0.05)) break;
      const std::string nm = i < static_cast<int>(names.size()) ? names[static_cast<std::size_t>(i)]
                                                                : fmt::format("theta{}", i + 1);
      const double c = v(i);
      if (shown == 0)
        expr += fmt::format("{:.3g} {}", c, nm);
      else
        expr += fmt::format(" {} {:.3g} {}", c < 0 ? "-" : "+", std::abs(c), nm);
      ++shown;
    }
    int rest = 0;
    for (Eigen::Index i = 0; i < v.size(); ++i) rest += std::abs(v(i)) >= 0.05 ? 1 : 0;
    if (rest > shown) expr += fmt::format(" + ... ({} more)", rest - shown);
    out += fmt::format("{}[{}] {} (sigma/sigma_max = {:.2g})", d ? "; " : "", d + 1, expr,
                       ratios.size() > d ? ratios(d) : 0.0);
  }
  return out;
}

namespace {

// The solve from the SVD of the column-scaled factor Fs = Fw D^-1 (Jacobi's, or with
// opt.statistics false divide and conquer's).
template <class Svd>
LsSolution solveFromSvd(const Svd& svd, const Eigen::MatrixXd& Fw, const Eigen::VectorXd& fy,
                        const Eigen::VectorXd& d, long m, const std::vector<std::string>& names,
                        const SolveOptions& opt, const std::string& who) {
  const auto p = static_cast<int>(Fw.cols());
  const Eigen::VectorXd s = svd.singularValues();
  check(s(0) > 0.0,
        fmt::format("{}: the regressor is identically zero (no excitation at all)", who));
  const double smax = s(0);
  std::vector<int> null_idx;
  for (int i = 0; i < p; ++i)
    if (!(s(i) > opt.rank_tolerance * smax)) null_idx.push_back(i);
  if (!null_idx.empty()) {
    Eigen::MatrixXd N(p, static_cast<Eigen::Index>(null_idx.size()));
    Eigen::VectorXd ratios(static_cast<Eigen::Index>(null_idx.size()));
    for (std::size_t k = 0; k < null_idx.size(); ++k) {
      N.col(static_cast<Eigen::Index>(k)) = svd.matrixV().col(null_idx[k]);
      ratios(static_cast<Eigen::Index>(k)) = s(null_idx[k]) / smax;
    }
    throw Error(fmt::format(
        "{}: the data do not identify all {} base parameters (numerical rank {} of {} at "
        "tolerance {:g} on the column-scaled regressor, {} rows). Unidentifiable directions "
        "(unit-norm combinations of the column-scaled base parameters that leave W theta "
        "unchanged): {}. The experiment does not excite these combinations: move every joint in "
        "both directions with varied velocities and accelerations, or remove the parameters "
        "involved from the model.",
        who, p, p - static_cast<int>(null_idx.size()), p, opt.rank_tolerance, m,
        explainNullSpace(N, ratios, names, opt.explain_terms)));
  }

  LsSolution out;
  out.m = m;
  out.p = p;
  const Eigen::MatrixXd& V = svd.matrixV();
  const Eigen::VectorXd sinv = s.cwiseInverse();
  const Eigen::VectorXd theta_s = V * (sinv.asDiagonal() * (svd.matrixU().transpose() * fy));
  out.theta = theta_s.cwiseQuotient(d);
  out.rss = (Fw * out.theta - fy).squaredNorm();
  out.sigma2 = out.rss / static_cast<double>(m - p);
  out.singular_values_scaled = s;
  out.cond_W_scaled = smax / s(p - 1);
  if (!opt.statistics) return out;
  const Eigen::MatrixXd Vs =
      d.cwiseInverse().asDiagonal() * V * sinv.asDiagonal();  // (W^T W)^-1 = Vs Vs^T
  out.covariance = (opt.unit_variance ? 1.0 : out.sigma2) * (Vs * Vs.transpose());
  out.std = out.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  out.rel_std_percent = relativeStdPercent(out.theta, out.std);
  out.singular_values = Eigen::JacobiSVD<Eigen::MatrixXd>(Fw).singularValues();
  out.cond_W = out.singular_values(0) / out.singular_values(p - 1);
  return out;
}

}  // namespace

LsSolution solveLeastSquares(const RowAccumulator& acc, const std::vector<std::string>& names,
                             const SolveOptions& opt, const std::string& who) {
  const int p = acc.cols();
  const long m = acc.rows();
  check(m > p, fmt::format("{}: {} observation rows for {} base parameters; least squares needs "
                           "more rows than parameters (a longer experiment)",
                           who, m, p));
  const Eigen::MatrixXd& F = acc.factor();
  const Eigen::MatrixXd Fw = F.leftCols(p);
  const Eigen::VectorXd fy = F.col(p);

  // Column scaling: the rank decision and the null-space directions do not depend on units.
  Eigen::VectorXd d = Fw.colwise().norm().transpose();
  for (Eigen::Index j = 0; j < p; ++j)
    if (!(d(j) > 0.0)) d(j) = 1.0;  // zero column: stays zero, found as a null direction
  const Eigen::MatrixXd Fs = Fw * d.cwiseInverse().asDiagonal();
  if (!opt.statistics)  // (about half the time of Jacobi's at p = 64; the same values to 1e-14)
    return solveFromSvd(
        Eigen::BDCSVD<Eigen::MatrixXd>(Fs, Eigen::ComputeThinU | Eigen::ComputeThinV), Fw, fy, d, m,
        names, opt, who);
  return solveFromSvd(
      Eigen::JacobiSVD<Eigen::MatrixXd>(Fs, Eigen::ComputeThinU | Eigen::ComputeThinV), Fw, fy, d,
      m, names, opt, who);
}

// ---------------------------------------------------------------- Estimate
Json parameterTable(const Estimate& e) {
  Json t = Json::array();
  for (Eigen::Index i = 0; i < e.value.size(); ++i) {
    Json p = Json::object();
    const auto k = static_cast<std::size_t>(i);
    p["name"] = k < e.names.size() ? e.names[k] : fmt::format("theta{}", i + 1);
    p["expression"] = k < e.expressions.size() ? e.expressions[k] : std::string();
    p["value"] = e.value(i);
    const double sd = e.std.size() > i ? e.std(i) : NAN;
    p["std"] = sd;
    p["rel_std_percent"] = e.value(i) != 0.0 ? 100.0 * sd / std::abs(e.value(i)) : INFINITY;
    t.push_back(p);
  }
  return t;
}

std::string describePoint(const std::vector<std::string>& names, const Eigen::VectorXd& values,
                          int max_terms) {
  std::string out;
  const int n = static_cast<int>(values.size());
  for (int i = 0; i < n && i < max_terms; ++i) {
    const auto k = static_cast<std::size_t>(i);
    out += fmt::format("{}{} = {:.6g}", i ? ", " : "",
                       k < names.size() ? names[k] : fmt::format("theta{}", i + 1), values[i]);
  }
  if (n > max_terms) out += fmt::format(" ({} more: details.parameters)", n - max_terms);
  return out;
}

void fillEstimate(Estimate* e, const ObservationModel& model, const LsSolution& s,
                  double rss_unweighted, long m_unweighted) {
  const BaseParameters& b = model.base();
  e->names.clear();
  e->expressions.clear();
  for (int i = 0; i < s.p; ++i) {
    const auto k = static_cast<std::size_t>(i);
    e->names.push_back(k < b.names.size() ? b.names[k] : fmt::format("theta{}", i + 1));
    e->expressions.push_back(k < b.expressions.size() ? b.expressions[k] : e->names.back());
  }
  e->value = s.theta;
  e->std = s.std;
  e->covariance = s.covariance;
  e->sigma = std::sqrt(s.sigma2);
  e->cond_W = s.cond_W;
  e->residual_rms =
      m_unweighted > 0 ? std::sqrt(rss_unweighted / static_cast<double>(m_unweighted)) : 0.0;
  e->rows = s.m;
  Json& d = e->details;
  if (!d.isObject()) d = Json::object();
  d["parameters"] = parameterTable(*e);
  d["rows"] = Json(static_cast<long long>(s.m));
  d["dof"] = Json(static_cast<long long>(s.m - s.p));
  d["sigma2"] = s.sigma2;
  d["rss"] = s.rss;
  d["cond_W"] = s.cond_W;
  d["cond_W_scaled"] = s.cond_W_scaled;
  d["cond_W_definition"] =
      "sigma_max / sigma_min of the (weighted) base regressor W; cond_W_scaled: same with every "
      "column scaled to unit norm; cond(W^T W) = cond_W^2";
  d["singular_values"] = Json(toStd(s.singular_values));
  d["covariance_definition"] = "sigma^2 (W^T W)^-1, sigma^2 = ||y - W theta||^2 / (m - p)";
}

bool secantSecondOrderUpdate(Eigen::MatrixXd* S, const Eigen::VectorXd& s, const Eigen::VectorXd& y,
                             const Eigen::VectorXd& ysharp) {
  check(S->rows() == s.size() && S->cols() == s.size() && y.size() == s.size() &&
            ysharp.size() == s.size(),
        "secantSecondOrderUpdate: sizes differ");
  const double ys = y.dot(s);
  if (!(ys > 1e-12 * y.norm() * s.norm())) return false;
  const double sSs = s.dot(*S * s);
  if (sSs != 0.0) *S *= std::min(1.0, std::abs(s.dot(ysharp)) / std::abs(sSs));  // sizing
  const Eigen::VectorXd v = ysharp - *S * s;
  *S += (v * y.transpose() + y * v.transpose()) / ys - (v.dot(s) / (ys * ys)) * (y * y.transpose());
  return true;
}

}  // namespace exid::estimators
