// Trajectory plugins: exact VJP and Jacobian (against central finite differences), the pointwise
// recursion, Fourier periodicity, splines at rest at both ends, limits of the starts.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>

#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid_test.hpp"

namespace {

using exid::Samples;

struct Case {
  std::string robot, traj, params;
};

std::shared_ptr<exid::Trajectory> bound(const Case& c) {
  auto t = exid_test::create<exid::Trajectory>(c.traj, c.params);
  exid::RunContext ctx;
  ctx.seed = 7;
  t->bind(exid_test::robot(c.robot), ctx);
  return t;
}

Eigen::VectorXd stackSignals(const Samples& s) {
  const Eigen::Index Kn = s.q.size();
  Eigen::VectorXd v(3 * Kn);
  v << Eigen::Map<const Eigen::VectorXd>(s.q.data(), Kn),
      Eigen::Map<const Eigen::VectorXd>(s.qd.data(), Kn),
      Eigen::Map<const Eigen::VectorXd>(s.qdd.data(), Kn);
  return v;
}

class TrajectoryTest : public ::testing::TestWithParam<Case> {};

TEST_P(TrajectoryTest, JacobianAndVjpMatchFiniteDifferences) {
  auto t = bound(GetParam());
  const int nz = t->numVariables();
  ASSERT_GT(nz, 0);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> N(0.0, 1.0);
  Eigen::VectorXd z = t->initial();
  for (int i = 0; i < nz; ++i) z(i) += 0.05 * N(rng);
  const Eigen::MatrixXd J = t->jacobian(z);
  const Samples s0 = t->evaluate(z);
  ASSERT_EQ(J.rows(), 3 * s0.q.size());
  ASSERT_EQ(J.cols(), nz);
  // Jacobian columns by central differences (the map is linear: differences are exact up to
  // rounding)
  double err = 0, scale = 1e-12;
  for (int i = 0; i < nz; ++i) {
    const double h = 1e-4;
    Eigen::VectorXd zp = z, zm = z;
    zp(i) += h;
    zm(i) -= h;
    Eigen::VectorXd col = (stackSignals(t->evaluate(zp)) - stackSignals(t->evaluate(zm))) / (2 * h);
    err = std::max(err, (col - J.col(i)).cwiseAbs().maxCoeff());
    scale = std::max(scale, col.cwiseAbs().maxCoeff());
  }
  EXPECT_LT(err, 1e-7 * scale) << "Jacobian vs finite differences";
  // VJP against the Jacobian and against the directional derivative
  Samples adj = s0;
  for (auto* m : {&adj.q, &adj.qd, &adj.qdd})
    for (Eigen::Index i = 0; i < m->size(); ++i) m->data()[i] = N(rng);
  const Eigen::VectorXd g = t->vjp(z, adj);
  const Eigen::VectorXd gJ = J.transpose() * stackSignals(adj);
  EXPECT_LT((g - gJ).cwiseAbs().maxCoeff(), 1e-9 * std::max(1.0, gJ.cwiseAbs().maxCoeff()));
  Eigen::VectorXd dir(nz);
  for (int i = 0; i < nz; ++i) dir(i) = N(rng);
  const double h = 1e-4;
  const double fd =
      (stackSignals(t->evaluate(z + h * dir)) - stackSignals(t->evaluate(z - h * dir)))
          .dot(stackSignals(adj)) /
      (2 * h);
  EXPECT_NEAR(g.dot(dir), fd, 1e-7 * std::max(1.0, std::abs(fd)));
}

// A trajectory that declares itself continuous gives at its sample times what evaluate() gives,
// and vjpAt() is the VJP of evaluateAt(); one that does not refuses evaluateAt().
TEST_P(TrajectoryTest, SpecsAndEvaluationAtArbitraryTimes) {
  const Case& c = GetParam();
  auto t = bound(c);
  const exid::TrajectorySpecs sp = t->specs();
  const Samples s = t->evaluate(t->initial());
  EXPECT_TRUE(sp.linear);
  ASSERT_FALSE(sp.moving_joints.empty());
  for (int j = 0; j < s.dof(); ++j) {  // the held joints do not move
    if (std::find(sp.moving_joints.begin(), sp.moving_joints.end(), j) != sp.moving_joints.end())
      continue;
    EXPECT_EQ(s.q.col(j).maxCoeff(), s.q.col(j).minCoeff()) << "joint " << j + 1;
    EXPECT_EQ(s.qd.col(j).cwiseAbs().maxCoeff(), 0.0) << "joint " << j + 1;
  }
  EXPECT_GT(sp.duration_s, 0.0);
  if (!sp.continuous) {
    EXPECT_EQ(c.traj, "pointwise");
    EXPECT_THROW(t->evaluateAt(t->initial(), s.t), exid::Error);
    return;
  }
  EXPECT_EQ(sp.periodic, c.traj == "fourier" || c.params.find("periodic") != std::string::npos);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> N(0.0, 1.0);
  Eigen::VectorXd z = t->initial();
  for (Eigen::Index i = 0; i < z.size(); ++i) z(i) += 0.05 * N(rng);
  const Samples g = t->evaluate(z), a = t->evaluateAt(z, g.t);
  const double scale = 1.0 + g.qdd.cwiseAbs().maxCoeff();
  EXPECT_LT((g.q - a.q).cwiseAbs().maxCoeff(), 1e-12 * scale);
  EXPECT_LT((g.qd - a.qd).cwiseAbs().maxCoeff(), 1e-12 * scale);
  EXPECT_LT((g.qdd - a.qdd).cwiseAbs().maxCoeff(), 1e-12 * scale);
  // between the samples, up to the end; the VJP against central differences
  Eigen::VectorXd tt(4);
  tt << 0.37 * sp.duration_s, 0.5 * sp.duration_s + 1e-3, 0.91 * sp.duration_s, sp.duration_s;
  const Samples at = t->evaluateAt(z, tt);
  ASSERT_EQ(at.size(), 4);
  Samples adj = at;
  for (auto* m : {&adj.q, &adj.qd, &adj.qdd})
    for (Eigen::Index i = 0; i < m->size(); ++i) m->data()[i] = N(rng);
  const Eigen::VectorXd gz = t->vjpAt(z, tt, adj);
  Eigen::VectorXd dir(z.size());
  for (Eigen::Index i = 0; i < z.size(); ++i) dir(i) = N(rng);
  const double h = 1e-4;
  const Samples p = t->evaluateAt(z + h * dir, tt), m = t->evaluateAt(z - h * dir, tt);
  const double fd = ((stackSignals(p) - stackSignals(m)).dot(stackSignals(adj))) / (2 * h);
  EXPECT_NEAR(gz.dot(dir), fd, 1e-7 * std::max(1.0, std::abs(fd)));
  // on the sample grid vjpAt is vjp
  Samples adjg = g;
  for (auto* mm : {&adjg.q, &adjg.qd, &adjg.qdd})
    for (Eigen::Index i = 0; i < mm->size(); ++i) mm->data()[i] = N(rng);
  const Eigen::VectorXd v1 = t->vjp(z, adjg), v2 = t->vjpAt(z, g.t, adjg);
  EXPECT_LT((v1 - v2).cwiseAbs().maxCoeff(), 1e-10 * std::max(1.0, v1.cwiseAbs().maxCoeff()));
}

TEST_P(TrajectoryTest, InitialPointRespectsTheLimits) {
  const Case& c = GetParam();
  auto t = bound(c);
  auto robot = exid_test::robot(c.robot);
  const Samples s = t->evaluate(t->initial());
  const double margin = t->positionMargin();
  // the limits the excitation problem imposes: the robot's, adjusted by the trajectory (caps)
  std::vector<exid::JointLimits> limits = robot->limits;
  t->adjustLimits(&limits);
  for (int j = 0; j < s.dof(); ++j) {
    const auto& L = limits[static_cast<std::size_t>(j)];
    EXPECT_LE(s.q.col(j).maxCoeff(), L.q_max - margin + 1e-12) << "joint " << j + 1;
    EXPECT_GE(s.q.col(j).minCoeff(), L.q_min + margin - 1e-12) << "joint " << j + 1;
    if (t->velocityLimits() && L.qd_max < 1e299) {
      EXPECT_LE(s.qd.col(j).cwiseAbs().maxCoeff(), L.qd_max + 1e-12);
    }
    if (t->accelerationLimits() && L.qdd_max < 1e299) {
      EXPECT_LE(s.qdd.col(j).cwiseAbs().maxCoeff(), L.qdd_max + 1e-12);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(
    All, TrajectoryTest,
    ::testing::Values(
        Case{"planar2r", "pointwise", "{duration_s: 2, sample_period_s: 0.05}"},
        Case{"puma560", "pointwise", "{duration_s: 1, sample_period_s: 0.05, joints: [1, 3]}"},
        Case{"planar2r", "fourier", "{period_s: 4, harmonics: 3, sample_period_s: 0.1}"},
        Case{"panda", "fourier",
             "{period_s: 10, harmonics: 5, position_margin_rad: 0.1, acceleration_limits: false}"},
        Case{"puma560", "fourier",
             "{period_s: 5, harmonics: 2, joints: [2], velocity_limit_rad_s: 3}"},
        Case{"planar2r", "spline", "{duration_s: 4, knots: 6, degree: 3}"},
        Case{"planar2r", "spline", "{duration_s: 4, knots: 6, degree: 5}"},
        Case{"puma560", "spline", "{duration_s: 4, knots: 7, degree: 5, boundary: periodic}"},
        Case{"planar2r", "spline", "{duration_s: 4, knots: 5, degree: 3, boundary: periodic}"},
        Case{"panda", "fourier",
             "{period_s: 10, harmonics: 5, position_margin_rad: 0.1, rest_to_rest: true}"},
        Case{"puma560", "fourier",
             "{period_s: 5, harmonics: 3, joints: [2, 3], rest_to_rest: true, "
             "start_position_rad: [0, 0.5, -0.5, 0, 0, 0]}"},
        Case{"planar2r", "spline",
             "{duration_s: 4, knots: 6, degree: 5, rest_to_rest: true, "
             "start_position_rad: [0.3, -0.2]}"}),
    [](const auto& param_info) {
      return param_info.param.robot + "_" + param_info.param.traj + "_" +
             std::to_string(param_info.index);
    });

TEST(Pointwise, IntegratesExactlyByTheRecursion) {
  auto t = bound(
      {"planar2r", "pointwise", "{duration_s: 3, sample_period_s: 0.01, q0_rad: [0.2, -0.3]}"});
  Eigen::VectorXd z = t->initial();
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> U(-5, 5);
  for (Eigen::Index i = 0; i < z.size(); ++i) z(i) = U(rng);
  const Samples s = t->evaluate(z);
  const double dt = 0.01;
  ASSERT_EQ(s.size(), 300);
  EXPECT_DOUBLE_EQ(s.q(0, 0), 0.2);
  EXPECT_DOUBLE_EQ(s.q(0, 1), -0.3);
  EXPECT_EQ(s.qd(0, 0), 0.0);
  for (int j = 0; j < 2; ++j)
    for (int k = 0; k + 1 < s.size(); ++k) {
      // exact for piecewise-constant acceleration
      EXPECT_NEAR(s.q(k + 1, j), s.q(k, j) + dt * s.qd(k, j) + 0.5 * dt * dt * s.qdd(k, j), 1e-12);
      EXPECT_NEAR(s.qd(k + 1, j), s.qd(k, j) + dt * s.qdd(k, j), 1e-12);
      EXPECT_EQ(s.qdd(k, j), z(j * 300 + k));
    }
  // closed form: q_k = q0 + dt^2 sum_{i<k} (k - i - 1/2) u_i
  const int k = 250;
  double q = 0.2;
  for (int i = 0; i < k; ++i) q += dt * dt * (k - i - 0.5) * z(i);
  EXPECT_NEAR(s.q(k, 0), q, 1e-11);
}

TEST(Pointwise, CostateRecursionIsTheAdjointOfTheRecursion) {
  // <adj, signals(z)> is linear in z plus a constant: the VJP is its exact gradient.
  auto t = bound({"planar2r", "pointwise", "{duration_s: 1, sample_period_s: 0.02}"});
  Samples adj = t->evaluate(t->initial());
  std::mt19937_64 rng(5);
  std::normal_distribution<double> N(0.0, 1.0);
  for (auto* m : {&adj.q, &adj.qd, &adj.qdd})
    for (Eigen::Index i = 0; i < m->size(); ++i) m->data()[i] = N(rng);
  auto inner = [&](const Eigen::VectorXd& z) {
    Samples s = t->evaluate(z);
    return (s.q.cwiseProduct(adj.q).sum() + s.qd.cwiseProduct(adj.qd).sum() +
            s.qdd.cwiseProduct(adj.qdd).sum());
  };
  const Eigen::VectorXd z = Eigen::VectorXd::Zero(t->numVariables());
  const Eigen::VectorXd g = t->vjp(z, adj);
  for (int i = 0; i < t->numVariables(); ++i) {
    Eigen::VectorXd e = Eigen::VectorXd::Zero(t->numVariables());
    e(i) = 1.0;
    EXPECT_NEAR(g(i), inner(e) - inner(z), 1e-10);
  }
}

TEST(Pointwise, StartsFromCsvAccelerationsOrPositions) {
  // positions of a periodic signal: the accelerations follow by exact differentiation
  const auto dir = std::filesystem::temp_directory_path() / "exid_pointwise_csv";
  std::filesystem::create_directories(dir);
  const double T = 2.0, dt = 0.02;
  const int N = 100;
  {
    std::ofstream f(dir / "q.csv");
    f.precision(17);
    f << "t,q1,q2\n";
    for (int k = 0; k < N; ++k) {
      const double tt = k * dt, w = 2 * M_PI / T;
      f << tt << "," << 0.3 + 0.4 * std::cos(w * tt) << "," << -0.2 + 0.5 * std::sin(2 * w * tt)
        << "\n";
    }
  }
  auto t = bound({"planar2r", "pointwise",
                  "{duration_s: 2, sample_period_s: 0.02, init: csv, init_csv: " +
                      (dir / "q.csv").string() + "}"});
  const Samples s = t->evaluate(t->initial());
  const double w = 2 * M_PI / T;
  EXPECT_NEAR(s.q(0, 0), 0.7, 1e-9);
  EXPECT_NEAR(s.qd(0, 1), 0.5 * 2 * w, 1e-9);
  for (int k = 0; k < N; ++k) {
    // qd exact at the samples (u_k = (qd(t_k+1) - qd(t_k)) / dt), q to O(dt^2)
    EXPECT_NEAR(s.qd(k, 0), -0.4 * w * std::sin(w * k * dt), 1e-9);
    EXPECT_NEAR(s.q(k, 1), -0.2 + 0.5 * std::sin(2 * w * k * dt), 2e-3);
  }
}

TEST(Fourier, IsPeriodicAndBandLimited) {
  auto t = bound({"puma560", "fourier", "{period_s: 8, harmonics: 4, sample_period_s: 0.05}"});
  const Samples s = t->evaluate(t->initial());
  ASSERT_EQ(s.size(), 160);
  EXPECT_NEAR(s.t(s.size() - 1), 8.0 - 0.05, 1e-12);
  const double w = 2 * M_PI / 8.0;
  for (int j = 0; j < s.dof(); ++j) {
    // the integral of qd and qdd over a period vanishes (sum exact for a band-limited signal)
    EXPECT_NEAR(s.qd.col(j).sum(), 0.0, 1e-9);
    EXPECT_NEAR(s.qdd.col(j).sum(), 0.0, 1e-9);
    // no harmonic above 4 in q
    for (int l = 5; l < 20; ++l) {
      double c = 0, si = 0;
      for (int k = 0; k < s.size(); ++k) {
        c += s.q(k, j) * std::cos(w * l * s.t(k));
        si += s.q(k, j) * std::sin(w * l * s.t(k));
      }
      EXPECT_NEAR(c, 0.0, 1e-9);
      EXPECT_NEAR(si, 0.0, 1e-9);
    }
  }
  // continuity across the period: q(T) from the formula equals q(0)
  const Eigen::VectorXd z = t->initial();
  const int L = 4, m = 1 + 2 * L;
  for (int j = 0; j < s.dof(); ++j) {
    double qT = z(j * m), q0 = s.q(0, j);
    for (int l = 1; l <= L; ++l)
      qT += z(j * m + l) / (w * l) * std::sin(w * l * 8.0) -
            z(j * m + L + l) / (w * l) * std::cos(w * l * 8.0);
    EXPECT_NEAR(qT, q0, 1e-12);
  }
}

TEST(Fourier, HeldJointsStayAtRest) {
  auto t = bound({"puma560", "fourier",
                  "{period_s: 4, harmonics: 2, joints: [2, 3], rest_position_rad: [0.1, 0.2, 0.3, "
                  "0.4, 0.5, 0.6]}"});
  EXPECT_EQ(t->numVariables(), 2 * 5);
  const Samples s = t->evaluate(t->initial());
  for (int j : {0, 3, 4, 5}) {
    EXPECT_DOUBLE_EQ(s.q.col(j).minCoeff(), 0.1 * (j + 1));
    EXPECT_DOUBLE_EQ(s.q.col(j).maxCoeff(), 0.1 * (j + 1));
    EXPECT_EQ(s.qd.col(j).cwiseAbs().maxCoeff(), 0.0);
  }
  EXPECT_GT(s.qd.col(1).cwiseAbs().maxCoeff(), 0.0);
}

TEST(Spline, StartsAndEndsAtRest) {
  for (int degree : {3, 5}) {
    auto t = bound({"planar2r", "spline",
                    "{duration_s: 5, knots: 8, sample_period_s: 0.01, degree: " +
                        std::to_string(degree) + "}"});
    Eigen::VectorXd z = t->initial();
    const Samples s = t->evaluate(z);
    ASSERT_NEAR(s.t(s.size() - 1), 5.0, 1e-12);
    for (int j = 0; j < 2; ++j) {
      EXPECT_NEAR(s.qd(0, j), 0.0, 1e-10);
      EXPECT_NEAR(s.qd(s.size() - 1, j), 0.0, 1e-10);
      if (degree == 5) {
        EXPECT_NEAR(s.qdd(0, j), 0.0, 1e-9);
        EXPECT_NEAR(s.qdd(s.size() - 1, j), 0.0, 1e-9);
      }
      // interpolates the knots (every 5/7 s: samples at multiples of 0.01 hit t = 0 and 5)
      EXPECT_NEAR(s.q(0, j), z(j * 8), 1e-10);
      EXPECT_NEAR(s.q(s.size() - 1, j), z(j * 8 + 7), 1e-10);
      // continuity of qdd (C2): no jumps larger than the local slope allows
      for (int k = 1; k < s.size(); ++k) EXPECT_LT(std::abs(s.qdd(k, j) - s.qdd(k - 1, j)), 1.0);
    }
  }
}

TEST(Spline, PeriodicWrapsSmoothly) {
  auto t =
      bound({"planar2r", "spline",
             "{duration_s: 4, knots: 5, degree: 5, boundary: periodic, sample_period_s: 0.001}"});
  const Samples s = t->evaluate(t->initial());
  ASSERT_EQ(s.size(), 4000);
  const int K = s.size();
  const double dt = 0.001;
  for (int j = 0; j < 2; ++j) {
    // the sample after the last is the first one: extrapolate with the Taylor step
    EXPECT_NEAR(s.q(K - 1, j) + dt * s.qd(K - 1, j) + 0.5 * dt * dt * s.qdd(K - 1, j), s.q(0, j),
                1e-7);
    EXPECT_NEAR(s.qd(K - 1, j) + dt * s.qdd(K - 1, j), s.qd(0, j), 1e-5);
  }
}

}  // namespace
