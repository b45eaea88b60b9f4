// exid — base (identifiable) parameters, found numerically (Gautier 1990).
//
// Given a regressor W (rows stacked over random samples within the limits, columns = the full
// parameter vector), QR with column pivoting splits the columns into independent ones W1 and
// dependent ones W2 = W1 * beta. Then W * pi = W1 * pi_b with pi_b = pi_1 + beta * pi_2:
// each base parameter is its own standard parameter plus the regrouped dependent ones.
// Rank tolerance: a column is independent when |R_kk| > tolerance * |R_00| (after optional
// scaling of every column to unit norm); the default tolerance is 1e-8 (documented in
// docs/base_parameters.md). Columns that are identically zero are dropped (not identifiable).
#pragma once

#include <Eigen/Core>
#include <functional>
#include <string>
#include <vector>

#include "exid/export.hpp"

namespace exid {

struct EXID_API BaseParameters {
  std::vector<std::string> full_names;   // columns of the full regressor
  std::vector<int> independent;          // base columns, indices into full_names, ascending
  std::vector<int> dependent;            // the others (regrouped or unidentifiable)
  Eigen::MatrixXd beta;                  // |independent| x |dependent|: W_dep = W_ind * beta
  Eigen::MatrixXd K;                     // base x full: pi_b = K * pi
  std::vector<std::string> names;        // base names: "ZZ1R" when regrouped, else the full name
  std::vector<std::string> expressions;  // "ZZ1 + YY2 + 0.186 M3" with the numbers filled in
  double tolerance = 1e-8;
  int rank() const { return static_cast<int>(independent.size()); }
  int numFull() const { return static_cast<int>(full_names.size()); }

  Eigen::VectorXd reduce(const Eigen::VectorXd& full) const { return K * full; }
  /// The base columns of a full regressor.
  Eigen::MatrixXd columns(const Eigen::MatrixXd& W_full) const;
};

struct EXID_API BaseParameterOptions {
  double tolerance = 1e-8;
  bool normalize_columns = true;  // scale each column to unit norm before the QR
  /// Full parameters to keep as base columns: visited first, in this order, before the others
  /// in their natural order. Each must exist and be independent of those named before it, or
  /// computeBaseParameters throws naming it. Empty: the natural order (Khalil/Gautier's
  /// lexicographically lowest set). The identifiable space is the same for any choice; the
  /// base columns, their regrouping and the unscaled cond(W) are not.
  std::vector<std::string> preferred;
  /// How the independent columns are chosen when `preferred` is empty.
  ///  - Natural: visited in their natural order (the lexicographically lowest set, above).
  ///  - Pivoted: QR with column pivoting on the unit-norm columns (Businger-Golub): at each step
  ///    the column with the largest residual on the columns already kept, the rule of
  ///    scipy.linalg.qr(pivoting=True) baselines. Residuals within a relative 1e-9 of the
  ///    largest are equal (structurally equal columns, whose order rounding would otherwise
  ///    decide) and the lowest natural index is kept. The kept columns depend on the stack's
  ///    samples wherever two residuals are close (docs/base_parameters.md). With `preferred`
  ///    named, computeBaseParameters throws (the named columns are a choice of their own).
  enum class Rule { Natural, Pivoted };
  Rule rule = Rule::Natural;
};

/// The columns `Rule::Pivoted` keeps, in their pivot order (indices into the columns of W).
EXID_API std::vector<int> pivotedBaseColumns(const Eigen::MatrixXd& W, double tolerance = 1e-8);

/// From a stacked full regressor and its column names.
EXID_API BaseParameters computeBaseParameters(const Eigen::MatrixXd& W,
                                              const std::vector<std::string>& names,
                                              const BaseParameterOptions& opt = {});

/// Stack `samples` calls of `rows(k, W_k)` (each returning rows of the full regressor) and
/// compute the base parameters.
EXID_API BaseParameters
computeBaseParameters(int samples, int rows_per_sample,
                      const std::function<void(int, Eigen::Ref<Eigen::MatrixXd>)>& rows,
                      const std::vector<std::string>& names, const BaseParameterOptions& opt = {});

}  // namespace exid
