// The data layer's signal processing (exid/signal.hpp, shared by the estimators and the
// experiments): Butterworth design, zero-phase filtering, central differences, parallel
// decimation.
#include "exid/signal.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "exid/error.hpp"

TEST(Butterworth, MatchesPublishedCoefficients) {
  // scipy.signal.butter(2, 0.2): b = [0.06745527, 0.13491055, 0.06745527],
  // a = [1, -1.1429805, 0.4128016] (Wn = 0.2 of Nyquist: fc = 0.1 fs).
  exid::Sos s = exid::butterworthLowpass(2, 10.0, 100.0);
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
    exid::Sos s = exid::butterworthLowpass(N, fc, fs);
    EXPECT_EQ(static_cast<int>(s.sections.size()), (N + 1) / 2);
    for (double f : {0.0, 5.0, 37.0, 80.0, 300.0, 499.0}) {
      const double w = std::tan(M_PI * f / fs) / std::tan(M_PI * fc / fs);
      const double expect = 1.0 / std::sqrt(1.0 + std::pow(w, 2 * N));
      EXPECT_NEAR(std::abs(exid::sosResponse(s, f, fs)), expect, 1e-10) << "N=" << N << " f=" << f;
    }
  }
  EXPECT_THROW(exid::butterworthLowpass(4, 600, 1000), exid::Error);
}

TEST(Filtfilt, ZeroPhaseAndNoEdgeTransient) {
  const double fs = 1000;
  const int n = 4000;
  exid::Sos s = exid::butterworthLowpass(4, 20, fs);
  Eigen::VectorXd x(n), y(n);
  for (int k = 0; k < n; ++k) {
    const double t = k / fs;
    x(k) = 3.0 + std::sin(2 * M_PI * 2 * t + 0.3);  // in band: passes unchanged, no phase lag
  }
  y = exid::filtfilt(s, x);
  // |H(2 Hz)|^2 = 1 / (1 + (tan(2pi/1000)/tan(20pi/1000))^8) ~ 1 - 1e-8
  EXPECT_LE((y - x).segment(200, n - 400).cwiseAbs().maxCoeff(), 1e-7);
  // Edges: a long odd extension + steady-state initial conditions keep the error small (a pad
  // of scipy's 15 samples would leave 0.08 here).
  EXPECT_LE((y - x).cwiseAbs().maxCoeff(), 2e-3);
  // A constant passes exactly.
  Eigen::VectorXd c = Eigen::VectorXd::Constant(100, 2.5);
  EXPECT_LE((exid::filtfilt(s, c).array() - 2.5).abs().maxCoeff(), 1e-12);
  // Out of band: 200 Hz attenuated by |H|^2 ~ (20/200... )^8
  for (int k = 0; k < n; ++k) x(k) = std::sin(2 * M_PI * 200 * k / fs);
  y = exid::filtfilt(s, x);
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
  EXPECT_LE((exid::centralFirstDerivative(t, X) - dX).cwiseAbs().maxCoeff(), 1e-9);
  Eigen::MatrixXd d2 = exid::centralSecondDerivative(t, X);
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
  exid::Rows d =
      exid::decimateRows(r, 10, exid::butterworthLowpass(8, 0.8 * 0.5 * 1000 / 10, 1000));
  ASSERT_EQ(d.y.size(), 2 * 100);
  EXPECT_EQ(d.equation[0], 0);
  EXPECT_EQ(d.equation[1], 1);
  EXPECT_EQ(d.equation[3], 1);
  EXPECT_LE((d.W * theta - d.y).cwiseAbs().maxCoeff(), 1e-12);
  // smooth columns pass the decimation filter unchanged (away from nothing: zero phase)
  EXPECT_NEAR(d.W(2 * 50, 1), std::cos(5 * 0.5), 1e-6);
}

TEST(Filtfilt, RowMajorBlockEqualsPerColumnBitForBit) {
  const exid::Sos sos = exid::butterworthLowpass(8, 12.0, 1000.0);
  Eigen::MatrixXd X(700, 5);
  for (Eigen::Index i = 0; i < X.rows(); ++i)
    for (Eigen::Index j = 0; j < X.cols(); ++j)
      X(i, j) = std::sin(0.01 * static_cast<double>(i * (j + 1))) + 0.1 * std::cos(0.9 * i + j);
  exid::RowMajorMatrix R = X;
  exid::filtfiltRowsInPlace(sos, &R);
  for (Eigen::Index j = 0; j < X.cols(); ++j) {
    const Eigen::VectorXd ref = exid::filtfilt(sos, X.col(j));
    for (Eigen::Index i = 0; i < X.rows(); ++i) ASSERT_EQ(R(i, j), ref(i)) << i << "," << j;
  }
  // the settling margin: the slowest pole decays below the tolerance within it
  const long M = exid::settlingSamples(sos, 1e-13);
  EXPECT_GT(M, 100);
  EXPECT_LT(M, 5000);
}
