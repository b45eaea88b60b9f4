// exid — numerical base parameters (Gautier 1990). See base_parameters.hpp and
// docs/base_parameters.md.
//
// Choice of the independent set: columns are visited in their natural order (body 1 first, XX
// before YY, inertial before drive columns) and a column is kept when its residual after
// projection on the columns already kept (sequential Householder QR) exceeds the tolerance.
// This gives the lexicographically lowest independent set, which is the classical
// Khalil/Gautier convention (YYj regrouped into XXjR, Mj+1 into ZZjR, MXj ...). A
// column-pivoted QR (Eigen ColPivHouseholderQR) computes the rank independently; if both
// disagree (ill-conditioned stack) the pivoted set is used instead.
#include "exid/base_parameters.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

namespace exid {

Eigen::MatrixXd BaseParameters::columns(const Eigen::MatrixXd& W_full) const {
  if (W_full.cols() != numFull())  // (a hot path: the message only when it fails)
    throw Error("BaseParameters::columns: the regressor has " + std::to_string(W_full.cols()) +
                " columns (expected " + std::to_string(numFull()) + ")");
  Eigen::MatrixXd W(W_full.rows(), rank());
  for (int k = 0; k < rank(); ++k) W.col(k) = W_full.col(independent[static_cast<size_t>(k)]);
  return W;
}

namespace {

std::string formatCoef(double c) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", c);
  return buf;
}

}  // namespace

namespace {

BaseParameters naturalOrder(const Eigen::MatrixXd& W_stacked, const std::vector<std::string>& names,
                            const BaseParameterOptions& opt);

/// The preferred columns first: the algorithm on the permuted columns, mapped back to the
/// natural order (independent and dependent ascending, beta, K, names and expressions with them).
BaseParameters preferredFirst(const Eigen::MatrixXd& W, const std::vector<std::string>& names,
                              const BaseParameterOptions& opt) {
  const int p = static_cast<int>(names.size());
  std::vector<int> perm;
  std::vector<char> taken(static_cast<size_t>(p), 0);
  for (const auto& want : opt.preferred) {
    const auto it = std::find(names.begin(), names.end(), want);
    if (it == names.end()) {
      std::string all;
      for (const auto& n : names) all += (all.empty() ? "" : ", ") + n;
      throw Error("base columns: '" + want +
                  "' is not a parameter of the model (parameters: " + all + ")");
    }
    const int j = static_cast<int>(it - names.begin());
    check(!taken[static_cast<size_t>(j)], "base columns: '" + want + "' is named twice");
    taken[static_cast<size_t>(j)] = 1;
    perm.push_back(j);
  }
  for (int j = 0; j < p; ++j)
    if (!taken[static_cast<size_t>(j)]) perm.push_back(j);
  Eigen::MatrixXd Wp(W.rows(), p);
  std::vector<std::string> np(static_cast<size_t>(p));
  for (int k = 0; k < p; ++k) {
    Wp.col(k) = W.col(perm[static_cast<size_t>(k)]);
    np[static_cast<size_t>(k)] = names[static_cast<size_t>(perm[static_cast<size_t>(k)])];
  }
  BaseParameterOptions o = opt;
  o.preferred.clear();
  const BaseParameters bp = naturalOrder(Wp, np, o);
  // Every preferred column must have been kept.
  for (std::size_t k = 0; k < opt.preferred.size(); ++k) {
    if (std::find(bp.independent.begin(), bp.independent.end(), static_cast<int>(k)) ==
        bp.independent.end()) {
      std::string before;
      for (std::size_t i = 0; i < k; ++i) before += (i ? ", " : "") + opt.preferred[i];
      throw Error("base columns: '" + opt.preferred[k] + "' is " +
                  (bp.K.rows() > 0 && bp.K.col(static_cast<Eigen::Index>(k)).isZero()
                       ? std::string("not identifiable (its column is zero)")
                       : "a combination of the columns named before it (" +
                             (before.empty() ? std::string("none") : before) + ")") +
                  ": name independent columns only");
    }
  }
  // Back to the natural order.
  BaseParameters out;
  out.full_names = names;
  out.tolerance = bp.tolerance;
  std::vector<int> ind_rows(bp.independent.size()), dep_cols(bp.dependent.size());
  for (std::size_t i = 0; i < ind_rows.size(); ++i) ind_rows[i] = static_cast<int>(i);
  for (std::size_t i = 0; i < dep_cols.size(); ++i) dep_cols[i] = static_cast<int>(i);
  auto orig = [&](int k) { return perm[static_cast<size_t>(k)]; };
  std::sort(ind_rows.begin(), ind_rows.end(), [&](int a, int b) {
    return orig(bp.independent[static_cast<size_t>(a)]) <
           orig(bp.independent[static_cast<size_t>(b)]);
  });
  std::sort(dep_cols.begin(), dep_cols.end(), [&](int a, int b) {
    return orig(bp.dependent[static_cast<size_t>(a)]) < orig(bp.dependent[static_cast<size_t>(b)]);
  });
  const auto r = static_cast<Eigen::Index>(ind_rows.size());
  const auto nd = static_cast<Eigen::Index>(dep_cols.size());
  out.beta.resize(r, nd);
  out.K = Eigen::MatrixXd::Zero(r, p);
  for (Eigen::Index a = 0; a < r; ++a) {
    const int ra = ind_rows[static_cast<size_t>(a)];
    out.independent.push_back(orig(bp.independent[static_cast<size_t>(ra)]));
    out.names.push_back(bp.names[static_cast<size_t>(ra)]);
    out.expressions.push_back(bp.expressions[static_cast<size_t>(ra)]);
    for (int k = 0; k < p; ++k) out.K(a, orig(k)) = bp.K(ra, k);
    for (Eigen::Index c = 0; c < nd; ++c)
      out.beta(a, c) = bp.beta(ra, dep_cols[static_cast<size_t>(c)]);
  }
  for (Eigen::Index c = 0; c < nd; ++c)
    out.dependent.push_back(
        orig(bp.dependent[static_cast<size_t>(dep_cols[static_cast<size_t>(c)])]));
  return out;
}

}  // namespace

BaseParameters computeBaseParameters(const Eigen::MatrixXd& W_stacked,
                                     const std::vector<std::string>& names,
                                     const BaseParameterOptions& opt) {
  check(static_cast<Eigen::Index>(names.size()) == W_stacked.cols(),
        "computeBaseParameters: " + std::to_string(names.size()) + " names for " +
            std::to_string(W_stacked.cols()) + " columns");
  if (opt.rule == BaseParameterOptions::Rule::Pivoted) {
    check(opt.preferred.empty(),
          "base columns: named columns and the pivoted rule were both given (choose one)");
    BaseParameterOptions o = opt;
    o.rule = BaseParameterOptions::Rule::Natural;
    for (const int k : pivotedBaseColumns(W_stacked, opt.tolerance))
      o.preferred.push_back(names[static_cast<size_t>(k)]);
    return preferredFirst(W_stacked, names, o);
  }
  if (!opt.preferred.empty()) return preferredFirst(W_stacked, names, opt);
  return naturalOrder(W_stacked, names, opt);
}

namespace {

// Cost for large chains (p = 14 n columns for n joints with drives): every step of naturalOrder
// uses only the relations between the columns, which W shares with R of W = Q R. So (1) at most
// max(4 p, kMinRows) stacked rows are used (random samples: 4 p rows reveal the rank with a
// wide margin; kMinRows keeps every row of the shipped robots, up to 200 samples x 7 joints),
// and (2) they are compressed to R (p x p) by a blocked Householder QR, O(N p^2) at level-3
// speed; the column-ordered QR, the pivoted rank check and the solve for beta then cost
// O(p^3) instead of the unblocked O(N p^2) passes they made over W (a 50-link chain, N = 10000
// rows, p = 700: 6.2 s). In all O(n^3) for n joints. triangular: W was compressed to R.
Eigen::MatrixXd compressedRows(const Eigen::MatrixXd& W_stacked, bool* triangular) {
  const Eigen::Index p = W_stacked.cols();
  constexpr Eigen::Index kMinRows = 2000;
  const Eigen::Index rows_used =
      std::min(W_stacked.rows(), std::max<Eigen::Index>(4 * p, kMinRows));
  Eigen::MatrixXd W;
  if (rows_used > p) {
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(W_stacked.topRows(rows_used));
    W = qr.matrixQR().topRows(p).triangularView<Eigen::Upper>();
  } else {
    W = W_stacked.topRows(rows_used);
  }
  *triangular = rows_used > p;
  return W;
}

// The column-ordered QR of A: the kept columns, the factor B (R of the kept columns and, in each
// dropped column, its coordinates on the kept columns left of it), and how clear the rank is.
struct SequentialQr {
  std::vector<int> ind;
  Eigen::MatrixXd B;
  std::vector<int> kept_before;  // kept columns left of each column
  double r00 = -1.0;
  double gap = HUGE_VAL;  // how far (factor) the closest residual is from the threshold
};

// Sequential Householder QR, keeping a column when |R_kk| > tol * |R_00|. On the compressed
// (upper triangular) W, column k has no entry below row k, and a reflector of rows r..k keeps
// that true for every later column: the reflectors are as long as the number of columns
// dropped so far plus one, O(p^2 (p - rank)) in all instead of O(p^3).
SequentialQr sequentialQr(const Eigen::MatrixXd& A, const std::vector<bool>& zero, bool triangular,
                          double tolerance) {
  const Eigen::Index N = A.rows(), p = A.cols();
  SequentialQr s;
  s.B = A;
  s.kept_before.assign(static_cast<size_t>(p), 0);
  Eigen::MatrixXd& B = s.B;
  Eigen::Index r = 0;
  for (Eigen::Index k = 0; k < p && r < N; ++k) {
    s.kept_before[static_cast<size_t>(k)] = static_cast<int>(r);
    if (zero[static_cast<size_t>(k)]) continue;
    const Eigen::Index len = triangular ? std::min<Eigen::Index>(k + 1, N) - r : N - r;
    const double res = B.col(k).segment(r, len).norm();
    if (s.r00 < 0.0) {
      if (res == 0.0) continue;
      s.r00 = res;
    }
    const double ratio = res / (tolerance * s.r00);
    s.gap = std::min(s.gap, ratio > 1.0 ? ratio : (ratio > 0.0 ? 1.0 / ratio : HUGE_VAL));
    if (!(res > tolerance * s.r00)) continue;
    double tau = 0.0, beta = 0.0;
    Eigen::VectorXd essential(len - 1);
    B.col(k).segment(r, len).makeHouseholder(essential, tau, beta);
    B(r, k) = beta;
    B.col(k).segment(r + 1, len - 1).setZero();
    if (k + 1 < p) {
      Eigen::VectorXd work(p);
      B.block(r, k + 1, len, p - k - 1).applyHouseholderOnTheLeft(essential, tau, work.data());
    }
    s.ind.push_back(static_cast<int>(k));
    ++r;
  }
  return s;
}

// An estimate of the smallest singular value of the upper triangular T (inverse iteration,
// O(r^2) per step).
double smallestSingularValue(const Eigen::MatrixXd& T) {
  const auto r = static_cast<int>(T.rows());
  if (r == 0) return 0.0;
  Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(r, 1.0, 2.0);
  x.normalize();
  double growth = 1.0;
  for (int it = 0; it < 30; ++it) {
    Eigen::VectorXd y = T.triangularView<Eigen::Upper>().solve(x);
    y = T.transpose().triangularView<Eigen::Lower>().solve(y);
    growth = y.norm();
    if (!(growth > 0.0) || !std::isfinite(growth)) break;
    x = y / growth;
  }
  return std::isfinite(growth) && growth > 0.0 ? 1.0 / std::sqrt(growth) : 0.0;
}

// The rank by column-pivoted QR of A (O(p^3), unblocked); when it differs from r_seq, ind
// becomes the pivoted set (ascending) and the result is true.
bool pivotedRankCheck(const Eigen::MatrixXd& A, double tolerance, int r_seq,
                      std::vector<int>* ind) {
  const Eigen::Index N = A.rows(), p = A.cols();
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> cpqr(A);
  int rank_cp = 0;
  const Eigen::MatrixXd& R = cpqr.matrixQR();
  const Eigen::Index m = std::min(N, p);
  const double R00 = m > 0 ? std::abs(R(0, 0)) : 0.0;
  for (Eigen::Index k = 0; k < m; ++k)
    if (std::abs(R(k, k)) > tolerance * R00 && R00 > 0.0) ++rank_cp;
  if (rank_cp == r_seq) return false;
  ind->clear();
  for (int k = 0; k < rank_cp; ++k)
    ind->push_back(static_cast<int>(cpqr.colsPermutation().indices()[k]));
  std::sort(ind->begin(), ind->end());
  return true;
}

// beta from R11 beta = R12. With the column-ordered set, R12 is in B: a dependent column j
// depends on the kept columns left of it, its first kept_before[j] entries are its
// coordinates (triangular solve, then back to the original column scaling). With the pivoted
// set: least squares in the original scaling, exact when W2 = W1 beta.
// (No solve with an empty right-hand side: Eigen binds a reference to its null data pointer.)
Eigen::MatrixXd solveBeta(const BaseParameters& bp, const Eigen::MatrixXd& W,
                          const std::vector<bool>& zero, const SequentialQr& s,
                          const Eigen::MatrixXd& T, const Eigen::VectorXd& scale, bool pivoted,
                          const Eigen::VectorXd& norms, double tolerance) {
  const Eigen::Index N = W.rows();
  const std::vector<int>& ind = bp.independent;
  const int r = bp.rank(), nd = static_cast<int>(bp.dependent.size());
  Eigen::MatrixXd W1(N, r), W2(N, nd);
  for (int k = 0; k < r; ++k) W1.col(k) = W.col(ind[static_cast<size_t>(k)]);
  for (int k = 0; k < nd; ++k) {
    const int c = bp.dependent[static_cast<size_t>(k)];
    W2.col(k) = zero[static_cast<size_t>(c)] ? Eigen::VectorXd::Zero(N) : Eigen::VectorXd(W.col(c));
  }
  Eigen::MatrixXd beta;
  if (r > 0 && nd > 0 && !pivoted) {
    Eigen::MatrixXd R12 = Eigen::MatrixXd::Zero(r, nd);
    for (int c = 0; c < nd; ++c) {
      const int j = bp.dependent[static_cast<size_t>(c)];
      const int rows = s.kept_before[static_cast<size_t>(j)];
      if (!zero[static_cast<size_t>(j)]) R12.col(c).head(rows) = s.B.col(j).head(rows);
    }
    beta = T.triangularView<Eigen::Upper>().solve(R12);
    for (int c = 0; c < nd; ++c)
      for (int k = 0; k < r; ++k)
        beta(k, c) *=
            scale[ind[static_cast<size_t>(k)]] / scale[bp.dependent[static_cast<size_t>(c)]];
  } else {
    beta = (r > 0 && nd > 0) ? Eigen::MatrixXd(W1.colPivHouseholderQr().solve(W2))
                             : Eigen::MatrixXd(Eigen::MatrixXd::Zero(r, nd));
  }
  // A coefficient whose share of the dependent column is below a hundredth of the rank tolerance
  // is rounding, not structure (W_dep = sum_k beta_k W_k: beta_k ||W_k|| / ||W_dep|| is its
  // share, on the scale the rank was decided on; the solve's rounding is about eps cond(R11),
  // 1e-14..1e-11): zero, so that it neither renames a parameter nor enters its expression.
  for (int c = 0; c < nd; ++c) {
    const double nd_norm = norms[bp.dependent[static_cast<size_t>(c)]];
    for (int k = 0; k < r; ++k) {
      const double share =
          nd_norm > 0 ? std::abs(beta(k, c)) * norms[ind[static_cast<size_t>(k)]] / nd_norm : 0.0;
      if (!(share > 1e-2 * tolerance)) beta(k, c) = 0.0;
    }
  }
  return beta;
}

// K, the base parameters' names (an R for a regrouped one) and their expressions from beta.
void regroupedNames(const std::vector<std::string>& names, BaseParameters* bp) {
  const std::vector<int>& ind = bp->independent;
  const Eigen::Index p = static_cast<Eigen::Index>(names.size());
  const int r = bp->rank(), nd = static_cast<int>(bp->dependent.size());
  bp->K = Eigen::MatrixXd::Zero(r, p);
  for (int k = 0; k < r; ++k) bp->K(k, ind[static_cast<size_t>(k)]) = 1.0;
  for (int k = 0; k < nd; ++k) bp->K.col(bp->dependent[static_cast<size_t>(k)]) = bp->beta.col(k);

  for (int k = 0; k < r; ++k) {
    const std::string& base = names[static_cast<size_t>(ind[static_cast<size_t>(k)])];
    std::string expr = base;
    bool regrouped = false;
    for (int c = 0; c < nd; ++c) {
      const double b = bp->beta(k, c);
      if (b == 0.0) continue;  // (rounding was zeroed by solveBeta)
      regrouped = true;
      const std::string& nm = names[static_cast<size_t>(bp->dependent[static_cast<size_t>(c)])];
      const double a = std::abs(b);
      expr += b < 0 ? " - " : " + ";
      const std::string num = formatCoef(a);
      expr += num == "1" ? nm : num + "*" + nm;
    }
    bp->names.push_back(regrouped ? base + "R" : base);
    bp->expressions.push_back(expr);
  }
}

BaseParameters naturalOrder(const Eigen::MatrixXd& W_stacked, const std::vector<std::string>& names,
                            const BaseParameterOptions& opt) {
  const Eigen::Index p = W_stacked.cols();
  check(static_cast<Eigen::Index>(names.size()) == p,
        "computeBaseParameters: " + std::to_string(names.size()) + " names for " +
            std::to_string(p) + " columns");
  check(W_stacked.allFinite(),
        "computeBaseParameters: the stacked regressor contains non-finite numbers");
  check(opt.tolerance > 0.0 && opt.tolerance < 1.0,
        "computeBaseParameters: tolerance must be in (0, 1)");
  bool triangular = false;
  const Eigen::MatrixXd W = compressedRows(W_stacked, &triangular);
  const Eigen::Index N = W.rows();
  BaseParameters bp;
  bp.full_names = names;
  bp.tolerance = opt.tolerance;

  Eigen::VectorXd norms = W.colwise().norm().transpose();
  const double max_norm = p > 0 ? norms.maxCoeff() : 0.0;
  std::vector<bool> zero(static_cast<size_t>(p), false);
  for (Eigen::Index k = 0; k < p; ++k)
    zero[static_cast<size_t>(k)] = !(norms[k] > opt.tolerance * max_norm) || max_norm == 0.0;

  Eigen::MatrixXd A(N, p);
  Eigen::VectorXd scale(p);  // A = W diag(scale)
  for (Eigen::Index k = 0; k < p; ++k) {
    scale[k] = (opt.normalize_columns && !zero[static_cast<size_t>(k)]) ? 1.0 / norms[k] : 1.0;
    A.col(k) = zero[static_cast<size_t>(k)] ? Eigen::VectorXd::Zero(N)
                                            : Eigen::VectorXd(W.col(k) * scale[k]);
  }

  SequentialQr s = sequentialQr(A, zero, triangular, opt.tolerance);
  std::vector<int> ind = s.ind;
  const int r_seq = static_cast<int>(ind.size());
  // R11 of the kept columns (upper triangular) and an estimate of its smallest singular value.
  Eigen::MatrixXd T(r_seq, r_seq);
  for (int k = 0; k < r_seq; ++k) T.col(k) = s.B.col(ind[static_cast<size_t>(k)]).head(r_seq);
  const double sigma_min = smallestSingularValue(T);
  // Independent check of the rank by column-pivoted QR, when the rank is not clear: a residual
  // within a factor 1e3 of the threshold, or R11 within that factor of singular. Otherwise both
  // would find the same rank.
  const bool clear = s.r00 > 0.0 && s.gap > 1e3 && sigma_min > 1e3 * opt.tolerance * s.r00;
  const bool pivoted = !clear && pivotedRankCheck(A, opt.tolerance, r_seq, &ind);
  bp.independent = ind;
  std::vector<bool> is_ind(static_cast<size_t>(p), false);
  for (int k : ind) is_ind[static_cast<size_t>(k)] = true;
  for (Eigen::Index k = 0; k < p; ++k)
    if (!is_ind[static_cast<size_t>(k)]) bp.dependent.push_back(static_cast<int>(k));

  bp.beta = solveBeta(bp, W, zero, s, T, scale, pivoted, norms, opt.tolerance);
  regroupedNames(names, &bp);
  return bp;
}

}  // namespace

BaseParameters computeBaseParameters(
    int samples, int rows_per_sample,
    const std::function<void(int, Eigen::Ref<Eigen::MatrixXd>)>& rows,
    const std::vector<std::string>& names, const BaseParameterOptions& opt) {
  check(samples > 0 && rows_per_sample > 0,
        "computeBaseParameters: samples and rows_per_sample must be positive");
  Eigen::MatrixXd W(static_cast<Eigen::Index>(samples) * rows_per_sample,
                    static_cast<Eigen::Index>(names.size()));
  for (int k = 0; k < samples; ++k)
    rows(k, W.middleRows(static_cast<Eigen::Index>(k) * rows_per_sample, rows_per_sample));
  return computeBaseParameters(W, names, opt);
}

std::vector<int> pivotedBaseColumns(const Eigen::MatrixXd& W_stacked, double tolerance) {
  check(W_stacked.allFinite(),
        "computeBaseParameters: the stacked regressor contains non-finite numbers");
  check(tolerance > 0.0 && tolerance < 1.0, "computeBaseParameters: tolerance must be in (0, 1)");
  bool triangular = false;
  Eigen::MatrixXd A = compressedRows(W_stacked, &triangular);  // the same column norms as W
  const Eigen::Index N = A.rows(), p = A.cols();
  const Eigen::VectorXd norms = A.colwise().norm().transpose();
  const double max_norm = p > 0 ? norms.maxCoeff() : 0.0;
  std::vector<char> out(static_cast<size_t>(p), 0);  // zero, or kept already
  for (Eigen::Index k = 0; k < p; ++k) {
    out[static_cast<size_t>(k)] = !(norms[k] > tolerance * max_norm) || max_norm == 0.0;
    if (!out[static_cast<size_t>(k)]) A.col(k) /= norms[k];
  }
  // Residual norms recomputed at every step (no downdating, whose rounding would decide the
  // ties): O(N p) a step, O(p^3) on the compressed rows.
  constexpr double kTie = 1e-9;
  std::vector<int> order;
  Eigen::VectorXd res(p), essential;
  Eigen::VectorXd work(p);
  double r00 = -1.0;
  for (Eigen::Index r = 0; r < std::min(N, p); ++r) {
    double best = 0.0;
    for (Eigen::Index k = 0; k < p; ++k) {
      res[k] = out[static_cast<size_t>(k)] ? -1.0 : A.col(k).tail(N - r).norm();
      best = std::max(best, res[k]);
    }
    if (r00 < 0.0) r00 = best;
    if (!(best > tolerance * r00)) break;
    Eigen::Index pick = 0;
    while (!(res[pick] >= best * (1.0 - kTie))) ++pick;
    double tau = 0.0, beta = 0.0;
    essential.resize(N - r - 1);
    A.col(pick).tail(N - r).makeHouseholder(essential, tau, beta);
    out[static_cast<size_t>(pick)] = 1;
    order.push_back(static_cast<int>(pick));
    A.bottomRows(N - r).applyHouseholderOnTheLeft(essential, tau, work.data());
  }
  return order;
}

}  // namespace exid
