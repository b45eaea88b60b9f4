// The estimators' streaming least squares (exid/estimators/common.hpp): normal equations and QR
// accumulated by equation, the solution and the explained null space; the rank test at a
// relative tolerance (exid/estimators/rank.hpp).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>

#include "exid/dynamics.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/common.hpp"
#include "exid/estimators/rank.hpp"

namespace estimators = exid::estimators;

TEST(RowAccumulator, NormalEquationsByEquationEqualTheDenseGramMatrix) {
  // Rows of three equations (labels 4, 0, 7, interleaved as a model gives them), each zero in
  // its own set of columns, some rows of an equation zero where the others are not; a row of
  // zeros; then a plain block without labels.
  std::mt19937_64 rng(11);
  std::normal_distribution<double> N(0, 1);
  const int m = 900, p = 9;
  Eigen::MatrixXd W(m, p);
  Eigen::VectorXd y(m);
  std::vector<int> eq(m);
  const int labels[3] = {4, 0, 7};
  for (int i = 0; i < m; ++i) {
    const int g = i % 3;
    eq[static_cast<std::size_t>(i)] = labels[g];
    for (int j = 0; j < p; ++j) {
      const bool zero = (g == 0 && j < 3) || (g == 1 && (j == 5 || j == 8)) ||
                        (g == 2 && j % 2 == 0) || (i % 17 == 0 && j == 4);
      W(i, j) = zero ? 0.0 : N(rng);
    }
    y(i) = N(rng);
  }
  W.row(30).setZero();
  Eigen::MatrixXd A(m, p + 1);
  A << W, y;
  const Eigen::MatrixXd G = A.transpose() * A;
  using M = estimators::RowAccumulator::Method;
  estimators::RowAccumulator by_eq(p, M::Normal), dense(p, M::Normal), qr(p, M::Qr);
  by_eq.addEquations(W.topRows(600), y.head(600), std::vector<int>(eq.begin(), eq.begin() + 600));
  by_eq.addEquations(W.bottomRows(300), y.tail(300), {});  // no labels: add()
  dense.add(W, y);
  qr.addEquations(W, y, eq);  // Qr: each equation's own factor first (below)
  EXPECT_EQ(by_eq.rows(), m);
  for (const estimators::RowAccumulator* a : {&by_eq, &dense, &qr}) {
    const Eigen::MatrixXd& F = a->factor();
    EXPECT_LE((F.transpose() * F - G).cwiseAbs().maxCoeff(), 1e-12 * G.cwiseAbs().maxCoeff());
  }
  estimators::SolveOptions opt;
  const estimators::LsSolution a = estimators::solveLeastSquares(by_eq, {}, opt, "test");
  const estimators::LsSolution b = estimators::solveLeastSquares(dense, {}, opt, "test");
  EXPECT_LE((a.theta - b.theta).cwiseAbs().maxCoeff(), 1e-12 * b.theta.cwiseAbs().maxCoeff());
  EXPECT_NEAR(a.rss, b.rss, 1e-12 * b.rss);
  // the wrong number of labels is refused rather than misread: add() of every row
  estimators::RowAccumulator short_labels(p, M::Normal);
  short_labels.addEquations(W, y, std::vector<int>(eq.begin(), eq.begin() + 10));
  EXPECT_LE((short_labels.factor().transpose() * short_labels.factor() - G).cwiseAbs().maxCoeff(),
            1e-12 * G.cwiseAbs().maxCoeff());
  // more than 64 labels (here 70, in descending order): add() of every row, the same Gram matrix
  estimators::RowAccumulator many_labels(p, M::Normal);
  std::vector<int> many(m);
  for (int i = 0; i < m; ++i) many[static_cast<std::size_t>(i)] = 69 - i % 70;
  many_labels.addEquations(W, y, many);
  EXPECT_LE((many_labels.factor().transpose() * many_labels.factor() - G).cwiseAbs().maxCoeff(),
            1e-12 * G.cwiseAbs().maxCoeff());
}

TEST(RowAccumulator, QrFactorMatchesDenseAndKeepsConditioning) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> N(0, 1);
  const int m = 5000, p = 8;
  Eigen::MatrixXd W(m, p);
  Eigen::VectorXd y(m);
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < p; ++j) W(i, j) = N(rng);
    y(i) = N(rng);
  }
  // Badly scaled, nearly collinear columns: cond(W) ~ 1e7, cond(W^T W) ~ 1e14.
  W.col(1) = W.col(0) + 1e-7 * W.col(1);
  W.col(3) *= 1e4;
  estimators::RowAccumulator acc(p);
  for (int b = 0; b < m; b += 333) {
    const int e = std::min(m, b + 333);
    acc.add(W.middleRows(b, e - b), y.segment(b, e - b));
  }
  EXPECT_EQ(acc.rows(), m);
  Eigen::MatrixXd A(m, p + 1);
  A << W, y;
  const Eigen::MatrixXd& F = acc.factor();
  EXPECT_LE((F.transpose() * F - A.transpose() * A).cwiseAbs().maxCoeff(),
            1e-10 * (A.transpose() * A).cwiseAbs().maxCoeff());
  estimators::SolveOptions opt;
  opt.rank_tolerance = 1e-12;
  estimators::LsSolution s = estimators::solveLeastSquares(acc, {}, opt, "test");
  // Reference in long double: the accumulated QR keeps cond(W) ~ 1e7 (scaled), the normal
  // equations square it and lose about 7 more digits.
  using MatL = Eigen::Matrix<long double, Eigen::Dynamic, Eigen::Dynamic>;
  using VecL = Eigen::Matrix<long double, Eigen::Dynamic, 1>;
  const VecL refl =
      MatL(W.cast<long double>()).colPivHouseholderQr().solve(VecL(y.cast<long double>()));
  const Eigen::VectorXd ref = refl.cast<double>();
  const double err_qr = (s.theta - ref).cwiseAbs().maxCoeff() / ref.cwiseAbs().maxCoeff();
  EXPECT_LE(err_qr, 1e-7);
  EXPECT_NEAR(s.rss, (y - W * ref).squaredNorm(), 1e-9 * s.rss);
  EXPECT_GT(s.cond_W_scaled, 1e6);
  estimators::RowAccumulator nacc(p, estimators::RowAccumulator::Method::Normal);
  nacc.add(W, y);
  // The scaled condition number: exact from the QR factor; from the Gram matrix it is only
  // known to be far beyond what the normal equations tolerate (cond^2 ~ 1/eps).
  EXPECT_NEAR(acc.scaledCondition(), s.cond_W_scaled, 1e-6 * s.cond_W_scaled);
  EXPECT_GT(nacc.scaledCondition(), 1e5);
  estimators::LsSolution sn = estimators::solveLeastSquares(nacc, {}, opt, "test");
  const double err_normal = (sn.theta - ref).cwiseAbs().maxCoeff() / ref.cwiseAbs().maxCoeff();
  EXPECT_GT(err_normal, 100 * err_qr);
  std::printf(
      "relative error vs long double: QR accumulation %.2e, normal equations %.2e (cond_W %.2e, "
      "scaled %.2e)\n",
      err_qr, err_normal, s.cond_W, s.cond_W_scaled);
  // merge and scale
  estimators::RowAccumulator a2(p), b2(p);
  a2.add(W.topRows(100), y.head(100));
  b2.merge(a2, 2.0);
  Eigen::MatrixXd A2(100, p + 1);
  A2 << 2 * W.topRows(100), 2 * y.head(100);
  const Eigen::MatrixXd& F2 = b2.factor();
  EXPECT_LE((F2.transpose() * F2 - A2.transpose() * A2).cwiseAbs().maxCoeff(),
            1e-9 * (A2.transpose() * A2).cwiseAbs().maxCoeff());
  EXPECT_EQ(b2.rows(), 100);
}

// Qr by equation: each equation's rows over its own non-zero columns reduced to their triangular
// factor first. The factor has the Gram matrix of the rows and the solve their least-squares
// solution, also for badly scaled, nearly collinear columns (where the normal equations would
// lose digits); an equation with fewer rows than its columns in a block, a block of fewer than
// 64 rows (add()) and a row of zeros are taken alike.
TEST(RowAccumulator, QrByEquationKeepsTheRowsGramMatrixAndConditioning) {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> N(0, 1);
  const int m = 1500, p = 10;
  Eigen::MatrixXd W(m, p);
  Eigen::VectorXd y(m);
  std::vector<int> eq(m);
  for (int i = 0; i < m; ++i) {
    // joint-like equations: label g's rows are zero in the columns before 3 g (a joint's torque
    // does not depend on the links before it), and its own drive column is 7 + g
    const int g = i % 3;
    eq[static_cast<std::size_t>(i)] = g;
    for (int j = 0; j < p; ++j) W(i, j) = (j < 7 && j >= 3 * g) || j == 7 + g ? N(rng) : 0.0;
    y(i) = N(rng);
  }
  W.col(6) = W.col(5) + 1e-7 * W.col(6);  // nearly collinear where both are non-zero
  W.col(4) *= 1e4;
  W.row(31).setZero();
  Eigen::MatrixXd A(m, p + 1);
  A << W, y;
  const Eigen::MatrixXd G = A.transpose() * A;
  using M = estimators::RowAccumulator::Method;
  estimators::RowAccumulator by_eq(p, M::Qr), dense(p, M::Qr);
  int b = 0;
  for (const int len : {600, 40, 300, 70, 490}) {  // (40: add(); 70 rows: 3 rows of label 2...)
    std::vector<int> labels(eq.begin() + b, eq.begin() + b + len);
    if (len == 70)  // ...except 3 rows of label 5: fewer rows than its columns
      for (int i = 0; i < 3; ++i) labels[static_cast<std::size_t>(3 * i)] = 5;
    by_eq.addEquations(W.middleRows(b, len), y.segment(b, len), labels);
    b += len;
  }
  ASSERT_EQ(b, m);
  dense.add(W, y);
  EXPECT_EQ(by_eq.rows(), m);
  const Eigen::MatrixXd& F = by_eq.factor();
  EXPECT_TRUE(F.triangularView<Eigen::StrictlyLower>().toDenseMatrix().isZero(0.0));
  EXPECT_LE((F.transpose() * F - G).cwiseAbs().maxCoeff(), 1e-12 * G.cwiseAbs().maxCoeff());
  estimators::SolveOptions opt;
  opt.rank_tolerance = 1e-12;
  const estimators::LsSolution a = estimators::solveLeastSquares(by_eq, {}, opt, "test");
  const estimators::LsSolution d = estimators::solveLeastSquares(dense, {}, opt, "test");
  using MatL = Eigen::Matrix<long double, Eigen::Dynamic, Eigen::Dynamic>;
  using VecL = Eigen::Matrix<long double, Eigen::Dynamic, 1>;
  const Eigen::VectorXd ref = MatL(W.cast<long double>())
                                  .colPivHouseholderQr()
                                  .solve(VecL(y.cast<long double>()))
                                  .cast<double>();
  const double err = (a.theta - ref).cwiseAbs().maxCoeff() / ref.cwiseAbs().maxCoeff();
  const double err_dense = (d.theta - ref).cwiseAbs().maxCoeff() / ref.cwiseAbs().maxCoeff();
  std::printf("Qr by equation: relative error vs long double %.2e (the rows' own QR %.2e)\n", err,
              err_dense);
  EXPECT_LE(err, 1e-7);
  EXPECT_NEAR(a.rss, (y - W * ref).squaredNorm(), 1e-9 * a.rss);
  EXPECT_NEAR(by_eq.minimumResidualSquared(), a.rss, 1e-9 * a.rss);
}

// The solve without statistics (varpro's trial points): the same theta and rss as the full solve
// (another SVD of the same scaled factor), no covariance; a rank-deficient problem is refused
// alike, naming the direction.
TEST(RowAccumulator, SolveWithoutStatisticsGivesTheSameFitAndRefusesTheSame) {
  std::mt19937_64 rng(9);
  std::normal_distribution<double> N(0, 1);
  const int m = 400, p = 7;
  Eigen::MatrixXd W(m, p);
  Eigen::VectorXd y(m);
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < p; ++j) W(i, j) = N(rng) * (j == 2 ? 1e3 : 1.0);
    y(i) = N(rng);
  }
  W.col(5) = W.col(4) + 1e-5 * W.col(5);
  estimators::RowAccumulator acc(p);
  acc.add(W, y);
  estimators::SolveOptions full, lean;
  lean.statistics = false;
  const estimators::LsSolution a = estimators::solveLeastSquares(acc, {}, full, "test");
  const estimators::LsSolution b = estimators::solveLeastSquares(acc, {}, lean, "test");
  EXPECT_LE((a.theta - b.theta).cwiseAbs().maxCoeff(), 1e-9 * a.theta.cwiseAbs().maxCoeff());
  EXPECT_NEAR(a.rss, b.rss, 1e-12 * a.rss);
  EXPECT_NEAR(a.cond_W_scaled, b.cond_W_scaled, 1e-9 * a.cond_W_scaled);
  EXPECT_EQ(a.std.size(), p);
  EXPECT_EQ(b.std.size(), 0);
  EXPECT_EQ(b.covariance.size(), 0);
  W.col(6) = 2.0 * W.col(3);  // rank deficient
  estimators::RowAccumulator bad(p);
  bad.add(W, y);
  for (const estimators::SolveOptions& o : {full, lean}) {
    try {
      estimators::solveLeastSquares(bad, {"a", "b", "c", "d", "e", "f", "g"}, o, "test");
      ADD_FAILURE() << "a rank-deficient problem was solved";
    } catch (const exid::Error& e) {
      EXPECT_NE(std::string(e.what()).find("numerical rank 6 of 7"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("d"), std::string::npos) << e.what();
    }
  }
}

TEST(RowAccumulator, ExplainsNullSpace) {
  Eigen::MatrixXd N(3, 1);
  N << 0.7071, -0.7071, 0.001;
  Eigen::VectorXd r(1);
  r << 1e-17;
  const std::string s = estimators::explainNullSpace(N, r, {"Fc1", "OFF1", "MX1"}, 4);
  EXPECT_NE(s.find("0.707 Fc1 - 0.707 OFF1"), std::string::npos) << s;
  EXPECT_EQ(s.find("MX1"), std::string::npos) << s;
}

// addEquations gives the bits of one gramUpdate per equation (its rows in order, over its own
// non-zero columns and y, ascending labels), written out here: pinned, so that a faster
// gathering of the rows (in blocks, say) must keep the operations and their order. Equations
// whose row counts are not multiples of four, not in turn, rows zero in whole columns.
TEST(RowAccumulator, GivesTheBitsOfOneGramUpdatePerEquation) {
  std::mt19937_64 rng(12);
  std::normal_distribution<double> N(0, 1);
  const int p = 11;
  for (const int m : {64, 1023, 1025, 2500, 5003}) {
    Eigen::MatrixXd W(m, p);
    Eigen::VectorXd y(m);
    std::vector<int> eq(static_cast<std::size_t>(m));
    for (int i = 0; i < m; ++i) {
      // five equations, not in turn: a run of one, then the others
      const int g = (i % 7 == 3) ? 9 : (i * 7 / 5) % 4;
      eq[static_cast<std::size_t>(i)] = g;
      for (int j = 0; j < p; ++j) W(i, j) = (j < g || (g == 9 && j % 3 == 0)) ? 0.0 : N(rng);
      y(i) = N(rng);
    }
    estimators::RowAccumulator acc(p, estimators::RowAccumulator::Method::Normal);
    acc.addEquations(W, y, eq);
    // the reference: per equation (ascending labels) its rows in order, its non-zero columns
    // ascending and y, padded to a multiple of 4, one gramUpdate into a zero Gram matrix, added
    // into the whole's lower triangle
    Eigen::MatrixXd ref = Eigen::MatrixXd::Zero(p + 1, p + 1);
    for (const int g : {0, 1, 2, 3, 9}) {
      std::vector<int> rows, cols;
      for (int i = 0; i < m; ++i)
        if (eq[static_cast<std::size_t>(i)] == g) rows.push_back(i);
      if (rows.empty()) continue;
      for (int c = 0; c < p; ++c)
        for (int i : rows)
          if (W(i, c) != 0.0) {
            cols.push_back(c);
            break;
          }
      cols.push_back(p);
      const int q = static_cast<int>(cols.size()), ld = (q + 3) & ~3;
      std::vector<double> B(rows.size() * static_cast<std::size_t>(ld), 0.0),
          G(static_cast<std::size_t>(q * ld), 0.0);
      for (std::size_t k = 0; k < rows.size(); ++k)
        for (int c = 0; c < q; ++c)
          B[k * static_cast<std::size_t>(ld) + static_cast<std::size_t>(c)] =
              cols[static_cast<std::size_t>(c)] == p
                  ? y(rows[k])
                  : W(rows[k], cols[static_cast<std::size_t>(c)]);
      exid::gramUpdate(G.data(), ld, B.data(), ld, static_cast<int>(rows.size()), q);
      for (int a = 0; a < q; ++a)
        for (int b = 0; b <= a; ++b)
          ref(cols[static_cast<std::size_t>(a)], cols[static_cast<std::size_t>(b)]) +=
              G[static_cast<std::size_t>(a * ld + b)];
    }
    const Eigen::MatrixXd& got = acc.normalLower();
    for (int a = 0; a <= p; ++a)
      for (int b = 0; b <= a; ++b)
        EXPECT_EQ(0, std::memcmp(&got(a, b), &ref(a, b), sizeof(double)))
            << m << " rows: entry (" << a << ", " << b << "): " << got(a, b) << " vs " << ref(a, b);
    // and it is [W y]^T [W y]
    Eigen::MatrixXd A(m, p + 1);
    A << W, y;
    const Eigen::MatrixXd dense = A.transpose() * A;
    EXPECT_LE((Eigen::MatrixXd(got.triangularView<Eigen::Lower>()) -
               Eigen::MatrixXd(dense.triangularView<Eigen::Lower>()))
                  .cwiseAbs()
                  .maxCoeff(),
              1e-12 * dense.cwiseAbs().maxCoeff());
  }
  estimators::RowAccumulator qr(3, estimators::RowAccumulator::Method::Qr);
  EXPECT_THROW(qr.normalLower(), exid::Error);
}

TEST(RankTolerance, DecidesAsTheSvdDoesAndNeedsItOnlyNearTheTolerance) {
  // Matrices with prescribed singular values 1 .. rho (graded), rho from 1e-12 to 0.5 around
  // tol = 1e-8, and columns scaled by up to 1e6: the test's answer against sigma_min / sigma_max
  // > tol from Jacobi's SVD, and whether it took the SVD.
  std::mt19937_64 rng(9);
  std::normal_distribution<double> N(0, 1);
  auto gaussian = [&](Eigen::Index r, Eigen::Index c) {
    Eigen::MatrixXd A(r, c);
    for (Eigen::Index j = 0; j < c; ++j)
      for (Eigen::Index i = 0; i < r; ++i) A(i, j) = N(rng);
    return A;
  };
  const double tol = 1e-8;
  int by_bounds = 0, by_svd_near = 0;
  for (const Eigen::Index n : {5, 30, 76})
    for (const double rho : {1e-12, 1e-10, 3e-9, 6e-9, 9e-9, 1.1e-8, 2e-8, 1e-7, 1e-6, 1e-3, 0.5}) {
      const Eigen::Index m = n + 12;
      const Eigen::JacobiSVD<Eigen::MatrixXd> q(gaussian(m, n),
                                                Eigen::ComputeThinU | Eigen::ComputeThinV);
      Eigen::VectorXd s(n);
      for (Eigen::Index i = 0; i < n; ++i)
        s[i] = std::pow(rho, static_cast<double>(i) / static_cast<double>(n - 1));
      const Eigen::MatrixXd A = q.matrixU() * s.asDiagonal() * q.matrixV().transpose();
      const Eigen::VectorXd ref = Eigen::JacobiSVD<Eigen::MatrixXd>(A).singularValues();
      const bool expected = ref[n - 1] > tol * ref[0];
      bool by_svd = false;
      SCOPED_TRACE(testing::Message() << "n " << n << " rho " << rho);
      EXPECT_EQ(estimators::aboveRankTolerance(A, tol, &by_svd), expected);
      // far from the tolerance (beyond the bounds' factor n and the margin 2) no SVD is taken
      const double ratio = ref[n - 1] / ref[0];
      if (ratio > 2.0 * n * tol || ratio < 0.5 * tol / n) {
        EXPECT_FALSE(by_svd);
        ++by_bounds;
      }
      if (ratio > 0.5 * tol && ratio < 2.0 * tol) {
        EXPECT_TRUE(by_svd);  // within the margin: the bounds cannot settle it
        ++by_svd_near;
      }
    }
  EXPECT_GE(by_bounds, 12);
  EXPECT_GE(by_svd_near, 6);
  // an exactly deficient matrix (a zero column: R singular) and a wide one go to the SVD
  Eigen::MatrixXd Z = gaussian(20, 6);
  Z.col(2).setZero();
  bool by_svd = false;
  EXPECT_FALSE(estimators::aboveRankTolerance(Z, tol, &by_svd));
  EXPECT_TRUE(by_svd);
  const Eigen::MatrixXd wide = gaussian(4, 9);
  EXPECT_TRUE(estimators::aboveRankTolerance(wide, tol, &by_svd));
  EXPECT_TRUE(by_svd);
  // columns of very different sizes, unscaled: cond about 1e12, below the tolerance
  const Eigen::MatrixXd scaled =
      gaussian(40, 8) * Eigen::VectorXd::LinSpaced(8, 0, 12)
                            .unaryExpr([](double e) { return std::pow(10.0, e); })
                            .asDiagonal();
  EXPECT_FALSE(estimators::aboveRankTolerance(scaled, tol, &by_svd));
  EXPECT_FALSE(by_svd);
}
