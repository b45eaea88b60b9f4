// Shared numerical code of the estimators: Butterworth design, zero-phase filtering, central
// differences, parallel decimation, streaming QR accumulation.
#include <gtest/gtest.h>

#include <Eigen/QR>
#include <cmath>
#include <cstdio>
#include <random>

#include "exid/error.hpp"
#include "exid/estimators/common.hpp"

namespace estimators = exid::estimators;

TEST(Butterworth, MatchesPublishedCoefficients) {
  // scipy.signal.butter(2, 0.2): b = [0.06745527, 0.13491055, 0.06745527],
  // a = [1, -1.1429805, 0.4128016] (Wn = 0.2 of Nyquist: fc = 0.1 fs).
  estimators::Sos s = estimators::butterworthLowpass(2, 10.0, 100.0);
  ASSERT_EQ(s.sections.size(), 1u);
  const auto& c = s.sections[0];
  EXPECT_NEAR(c[0], 0.0674552738890719, 1e-12);
  EXPECT_NEAR(c[1], 0.1349105477781438, 1e-12);
  EXPECT_NEAR(c[2], 0.0674552738890719, 1e-12);
  EXPECT_NEAR(c[4], -1.142980502539901, 1e-12);
  EXPECT_NEAR(c[5], 0.412801598096189, 1e-12);
}

TEST(Butterworth, MagnitudeIsTheBilinearButterworth) {
  for (int N : {1, 2, 3, 4, 5, 8}) {
    const double fs = 1000, fc = 37;
    estimators::Sos s = estimators::butterworthLowpass(N, fc, fs);
    EXPECT_EQ(static_cast<int>(s.sections.size()), (N + 1) / 2);
    for (double f : {0.0, 5.0, 37.0, 80.0, 300.0, 499.0}) {
      const double w = std::tan(M_PI * f / fs) / std::tan(M_PI * fc / fs);
      const double expect = 1.0 / std::sqrt(1.0 + std::pow(w, 2 * N));
      EXPECT_NEAR(std::abs(estimators::sosResponse(s, f, fs)), expect, 1e-10)
          << "N=" << N << " f=" << f;
    }
  }
  EXPECT_THROW(estimators::butterworthLowpass(4, 600, 1000), exid::Error);
}

TEST(Filtfilt, ZeroPhaseAndNoEdgeTransient) {
  const double fs = 1000;
  const int n = 4000;
  estimators::Sos s = estimators::butterworthLowpass(4, 20, fs);
  Eigen::VectorXd x(n), y(n);
  for (int k = 0; k < n; ++k) {
    const double t = k / fs;
    x(k) = 3.0 + std::sin(2 * M_PI * 2 * t + 0.3);  // in band: passes unchanged, no phase lag
  }
  y = estimators::filtfilt(s, x);
  // |H(2 Hz)|^2 = 1 / (1 + (tan(2pi/1000)/tan(20pi/1000))^8) ~ 1 - 1e-8
  EXPECT_LE((y - x).segment(200, n - 400).cwiseAbs().maxCoeff(), 1e-7);
  // Edges: a long odd extension + steady-state initial conditions keep the error small (a pad
  // of scipy's 15 samples would leave 0.08 here).
  EXPECT_LE((y - x).cwiseAbs().maxCoeff(), 2e-3);
  // A constant passes exactly.
  Eigen::VectorXd c = Eigen::VectorXd::Constant(100, 2.5);
  EXPECT_LE((estimators::filtfilt(s, c).array() - 2.5).abs().maxCoeff(), 1e-12);
  // Out of band: 200 Hz attenuated by |H|^2 ~ (20/200... )^8
  for (int k = 0; k < n; ++k) x(k) = std::sin(2 * M_PI * 200 * k / fs);
  y = estimators::filtfilt(s, x);
  // (odd reflection about a non-zero end value puts a step in the pad: it decays within ~20 tau)
  EXPECT_LE(y.segment(500, n - 1000).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(CentralDifferences, ExactOnQuadraticsIncludingNonUniform) {
  const int n = 50;
  Eigen::VectorXd t(n);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.5, 1.5);
  t(0) = 0.1;
  for (int k = 1; k < n; ++k) t(k) = t(k - 1) + 0.01 * u(rng);
  Eigen::MatrixXd X(n, 2), dX(n, 2);
  for (int k = 0; k < n; ++k) {
    X(k, 0) = 1 + 2 * t(k) - 3 * t(k) * t(k);
    dX(k, 0) = 2 - 6 * t(k);
    X(k, 1) = 5 * t(k);
    dX(k, 1) = 5;
  }
  EXPECT_LE((estimators::centralFirstDerivative(t, X) - dX).cwiseAbs().maxCoeff(), 1e-9);
  Eigen::MatrixXd d2 = estimators::centralSecondDerivative(t, X);
  EXPECT_LE((d2.col(0).array() + 6).abs().maxCoeff(), 1e-6);
  EXPECT_LE(d2.col(1).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(Decimation, PerEquationAndExactForConsistentRows) {
  // Two equations interleaved; y = W theta exactly; decimation keeps it exact and keeps labels.
  const int K = 1000, p = 3;
  exid::Rows r;
  r.W.resize(2 * K, p);
  r.y.resize(2 * K);
  r.numEquations = 2;
  Eigen::Vector3d theta(1, -2, 0.5);
  for (int k = 0; k < K; ++k)
    for (int j = 0; j < 2; ++j) {
      const int i = 2 * k + j;
      const double t = k * 0.001;
      r.W.row(i) << std::sin(3 * t + j), std::cos(5 * t), 1.0 + j;
      r.y(i) = r.W.row(i).dot(theta);
      r.equation.push_back(j);
    }
  exid::Rows d = estimators::decimateRows(
      r, 10, estimators::butterworthLowpass(8, 0.8 * 0.5 * 1000 / 10, 1000));
  ASSERT_EQ(d.y.size(), 2 * 100);
  EXPECT_EQ(d.equation[0], 0);
  EXPECT_EQ(d.equation[1], 1);
  EXPECT_EQ(d.equation[3], 1);
  EXPECT_LE((d.W * theta - d.y).cwiseAbs().maxCoeff(), 1e-12);
  // smooth columns pass the decimation filter unchanged (away from nothing: zero phase)
  EXPECT_NEAR(d.W(2 * 50, 1), std::cos(5 * 0.5), 1e-6);
}

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
  qr.addEquations(W, y, eq);  // Qr: add()
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

TEST(RowAccumulator, ExplainsNullSpace) {
  Eigen::MatrixXd N(3, 1);
  N << 0.7071, -0.7071, 0.001;
  Eigen::VectorXd r(1);
  r << 1e-17;
  const std::string s = estimators::explainNullSpace(N, r, {"Fc1", "OFF1", "MX1"}, 4);
  EXPECT_NE(s.find("0.707 Fc1 - 0.707 OFF1"), std::string::npos) << s;
  EXPECT_EQ(s.find("MX1"), std::string::npos) << s;
}

TEST(Filtfilt, RowMajorBlockEqualsPerColumnBitForBit) {
  const exid::estimators::Sos sos = exid::estimators::butterworthLowpass(8, 12.0, 1000.0);
  Eigen::MatrixXd X(700, 5);
  for (Eigen::Index i = 0; i < X.rows(); ++i)
    for (Eigen::Index j = 0; j < X.cols(); ++j)
      X(i, j) = std::sin(0.01 * static_cast<double>(i * (j + 1))) + 0.1 * std::cos(0.9 * i + j);
  exid::estimators::RowMajorMatrix R = X;
  exid::estimators::filtfiltRowsInPlace(sos, &R);
  for (Eigen::Index j = 0; j < X.cols(); ++j) {
    const Eigen::VectorXd ref = exid::estimators::filtfilt(sos, X.col(j));
    for (Eigen::Index i = 0; i < X.rows(); ++i) ASSERT_EQ(R(i, j), ref(i)) << i << "," << j;
  }
  // the settling margin: the slowest pole decays below the tolerance within it
  const long M = exid::estimators::settlingSamples(sos, 1e-13);
  EXPECT_GT(M, 100);
  EXPECT_LT(M, 5000);
}
