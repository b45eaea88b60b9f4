// The estimators that simulate the closed loop (didim, iv) on a floating base: the shipped
// humanoid's joints tracking a commanded trajectory under PD and feed-forward while its base
// moves as recorded (a manipulator on a moving platform), with two contacts: an F/T sensor
// between the base link and its mount (torso) and one at the left shank (whose wrench enters
// the joint rows through J^T). The recording is made here by an independent path: the joints'
// equations of motion from exid::floatingInverseDynamics (recursive Newton-Euler, not the
// regressor the model's rows use) with the base motion and the shank wrench as analytic
// functions of time, integrated by fixed-step RK4; the base sensor's wrench is then the one
// that balances the base rows for the motion obtained. The estimators' loop
// (exid::estimators::ClosedLoop) integrates it by CVODES from the model's joint rows and the
// recorded samples of the base motion and the wrenches.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>
#include <string>

#include "closed_loop_test_util.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/estimators/closed_loop.hpp"
#include "exid/floating_base.hpp"
#include "exid/json.hpp"
#include "exid_cli.hpp"
#include "model_test_util.hpp"

namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

constexpr double kScale = 0.5;  // of cltest::reference's sums of sines (about 30 deg per joint)
constexpr double kKp = 200.0, kKd = 20.0;
const char* kModel =
    "contact_links: [torso, l_shank], contact_poses: [0, 0, 0, 0, 0, 0, 0.03, 0, -0.36, 0, 0, 0]";

// cltest::reference's sums of sines at any time, scaled by kScale.
void referenceAt(double t, int n, VectorXd* q, VectorXd* qd, VectorXd* qdd) {
  q->setZero(n);
  qd->setZero(n);
  qdd->setZero(n);
  for (int j = 0; j < n; ++j)
    for (int l = 1; l <= 4; ++l) {
      const double a = kScale * 0.5 / l, w = 0.9 * l + 0.23 * j, ph = 0.7 * j + l;
      (*q)[j] += a * std::sin(w * t + ph);
      (*qd)[j] += a * w * std::cos(w * t + ph);
      (*qdd)[j] += -a * w * w * std::sin(w * t + ph);
    }
}

// The base motion: omega two harmonics per component, alpha its exact derivative, f = a - g
// about (0, 0, 9.81) with two harmonics per component.
exid::BaseMotion baseAt(double t) {
  exid::BaseMotion b;
  for (int c = 0; c < 3; ++c) {
    b[c] = b[3 + c] = 0.0;
    b[6 + c] = c == 2 ? 9.81 : 0.0;
    for (int l = 1; l <= 2; ++l) {
      const double A = 0.4 / l, w = 1.1 * l + 0.3 * c, ph = 0.5 * c + 1.3 * l;
      b[c] += A * std::sin(w * t + ph);
      b[3 + c] += A * w * std::cos(w * t + ph);
      b[6 + c] += 2.0 / l * std::sin(0.8 * l * t + 0.4 * c + l);
    }
  }
  return b;
}

// The shank sensor's wrench (exerted on the robot, sensor frame): forces of 20 N, moments of
// 2 N m.
Eigen::Matrix<double, 6, 1> shankWrenchAt(double t) {
  Eigen::Matrix<double, 6, 1> w;
  for (int e = 0; e < 6; ++e) w[e] = (e < 3 ? 20.0 : 2.0) * std::sin((0.7 + 0.2 * e) * t + e);
  return w;
}

// The plant: M_jj qdd = tau_c + J_s^T w_s(t) - h_j, from the joint rows of
// floatingInverseDynamics (unit accelerations for M_jj); `zero_alpha`: the base's angular
// acceleration left out (a broken plant, for the test that must tell it).
struct Plant {
  std::shared_ptr<const exid::RobotModel> robot;
  int shank = 0;
  exid::Pose shank_pose;
  int n = 0;

  VectorXd command(double t, const VectorXd& q, const VectorXd& qd) const {
    VectorXd qr, qdr, qddr;
    referenceAt(t, n, &qr, &qdr, &qddr);
    return kKp * (qr - q) + kKd * (qdr - qd) +
           exid::floatingInverseDynamics(*robot, qr, qdr, qddr, baseAt(t)).tail(n);
  }
  VectorXd acceleration(double t, const VectorXd& q, const VectorXd& qd) const {
    const exid::BaseMotion b = baseAt(t);
    const VectorXd h = exid::floatingInverseDynamics(*robot, q, qd, VectorXd::Zero(n), b).tail(n);
    MatrixXd M(n, n);
    for (int i = 0; i < n; ++i)
      M.col(i) = exid::floatingInverseDynamics(*robot, q, qd, VectorXd::Unit(n, i), b).tail(n) - h;
    const MatrixXd Jt = exid::contactMap(*robot, q, shank, shank_pose).bottomRows(n);
    return M.ldlt().solve(command(t, q, qd) + Jt * shankWrenchAt(t) - h);
  }
};

struct Case {
  cltest::Loop loop;
  Plant plant;
  std::filesystem::path reference;
};

// The humanoid tracking the reference for `duration` s, sampled every 5 ms, RK4 with steps of
// `step` s from the reference's start.
Case humanoidTracking(double duration, double step) {
  Case c;
  c.loop.robot = mtest::robot("humanoid");
  const exid::RobotModel& R = *c.loop.robot;
  const int n = R.dof();
  c.plant = {c.loop.robot, exid::floatingBodyIndex(R, "l_shank", "test"), {}, n};
  const double shank[6] = {0.03, 0, -0.36, 0, 0, 0};
  c.plant.shank_pose = exid::poseFromXyzRpy(shank);
  const double dt = 0.005;
  const int K = static_cast<int>(std::round(duration / dt)) + 1,
            sub = static_cast<int>(std::round(dt / step));
  exid::Dataset& d = c.loop.data;
  d.t.resize(K);
  d.q.resize(K, n);
  d.qd.resize(K, n);
  d.qdd.resize(K, n);
  d.tau.resize(K, n);
  d.base.resize(K, 9);
  d.contact.resize(K, 12);
  VectorXd q, qd, qdd;
  referenceAt(0.0, n, &q, &qd, &qdd);  // the loop starts on the reference
  const exid::Pose none{};
  for (int k = 0; k < K; ++k) {
    const double t = k * dt;
    if (k > 0) {
      const double h = dt / sub;
      for (int s = 0; s < sub; ++s) {
        const double ts = (k - 1) * dt + s * h;
        auto f = [&](double tt, const VectorXd& x, const VectorXd& v) {
          return c.plant.acceleration(tt, x, v);
        };
        const VectorXd a1 = f(ts, q, qd), v1 = qd;
        const VectorXd v2 = qd + 0.5 * h * a1, x2 = q + 0.5 * h * v1;
        const VectorXd a2 = f(ts + 0.5 * h, x2, v2);
        const VectorXd v3 = qd + 0.5 * h * a2, x3 = q + 0.5 * h * v2;
        const VectorXd a3 = f(ts + 0.5 * h, x3, v3);
        const VectorXd v4 = qd + h * a3, x4 = q + h * v3;
        const VectorXd a4 = f(ts + h, x4, v4);
        q += h / 6.0 * (v1 + 2.0 * v2 + 2.0 * v3 + v4);
        qd += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
      }
    }
    qdd = c.plant.acceleration(t, q, qd);
    const exid::BaseMotion b = baseAt(t);
    const Eigen::Matrix<double, 6, 1> ws = shankWrenchAt(t);
    // the base sensor's wrench balances the base rows: X*_torso w_t + X*_shank w_s = Y_base pi
    const VectorXd id = exid::floatingInverseDynamics(R, q, qd, qdd, b);
    const MatrixXd Ct = exid::contactMap(R, q, -1, none),
                   Cs = exid::contactMap(R, q, c.plant.shank, c.plant.shank_pose);
    const Eigen::Matrix<double, 6, 1> wt =
        Ct.topRows(6).partialPivLu().solve(id.head(6) - Cs.topRows(6) * ws);
    d.t[k] = t;
    d.q.row(k) = q.transpose();
    d.qd.row(k) = qd.transpose();
    d.qdd.row(k) = qdd.transpose();
    d.tau.row(k) = c.plant.command(t, q, qd).transpose();
    d.base.row(k) = b.transpose();
    d.contact.block(k, 0, 1, 6) = wt.transpose();
    d.contact.block(k, 6, 1, 6) = ws.transpose();
  }
  d.source = "floating_loop_test (RK4)";
  // the reference as the export writes it (1 kHz)
  exid::Samples ref = cltest::reference(n, duration);
  ref.q *= kScale;
  ref.qd *= kScale;
  ref.qdd *= kScale;
  const std::filesystem::path dir = exid_cli::freshTempDir("exid_floating_loop_", "ref");
  c.reference = dir / "reference.csv";
  cltest::writeReference(ref, c.reference);
  c.loop.params = fmt::format("reference_file: {}, kp_Nm_per_rad: [{}], kd_Nm_s_per_rad: [{}]",
                              c.reference.string(), kKp, kKd);
  c.loop.model = mtest::model("floating_base", std::string("{") + kModel + "}", c.loop.robot);
  c.loop.truth = c.loop.model->baseNominal();
  return c;
}

exid::ParamSet loopParams(const Case& c) {
  exid::ParamSet p;
  p.set("reference_file", c.reference.string());
  p.set("kp_Nm_per_rad", std::vector<double>{kKp});
  p.set("kd_Nm_s_per_rad", std::vector<double>{kKd});
  p.set("feedforward", std::string("nominal"));
  return p;
}

// The loop at theta simulated at the recording's times: the largest joint error [rad] and
// torque error [N m] against the recording.
std::pair<double, double> replay(const Case& c, const exid::Dataset& d, const VectorXd& theta) {
  exid::estimators::ClosedLoop loop(*c.loop.model, loopParams(c), d, mtest::context(), "test");
  EXPECT_TRUE(loop.floatingBase());
  const int n = loop.dof();
  double eq = 0.0, et = 0.0;
  exid::estimators::ClosedLoop::Tolerances tol;
  tol.rtol = 1e-12;
  tol.atol = 1e-14;
  loop.simulate(theta, d.t, tol, false, [&](int k, const VectorXd& x, const MatrixXd*) {
    eq = std::max(eq, (x.head(n) - c.loop.data.q.row(k).transpose()).cwiseAbs().maxCoeff());
    et = std::max(et,
                  (loop.control(d.t[k], x.head(n), x.tail(n)) - c.loop.data.tau.row(k).transpose())
                      .cwiseAbs()
                      .maxCoeff());
  });
  return {eq, et};
}

double scaledErr(const VectorXd& th, const VectorXd& tr) {
  return (th - tr).cwiseAbs().maxCoeff() / tr.cwiseAbs().maxCoeff();
}

}  // namespace

// The estimators' loop at the true parameters reproduces the RK4 recording (to the two
// integrations' and the base interpolation's error); the same loop on a recording whose base
// angular acceleration reads zero does not.
TEST(FloatingLoop, TheLoopReproducesAnIndependentRecording) {
  // (RK4's own error in the torque, through Kd qd: 2.3e-6 N m at steps of 0.25 ms, 1.2e-7 at
  // 0.125 ms)
  const Case c = humanoidTracking(2.0, 1.25e-4);
  // the plant's own consistency: the recorded motion fed to the inverse dynamics gives back the
  // torque it applied plus the shank wrench's J^T w (exact: both from the same samples)
  const exid::RobotModel& R = *c.loop.robot;
  const int n = R.dof();
  double worst_id = 0.0;
  for (int k = 0; k < c.loop.data.size(); k += 40) {
    const VectorXd q = c.loop.data.q.row(k).transpose();
    const VectorXd id = exid::floatingInverseDynamics(R, q, c.loop.data.qd.row(k).transpose(),
                                                      c.loop.data.qdd.row(k).transpose(),
                                                      c.loop.data.base.row(k).transpose());
    const MatrixXd Jt = exid::contactMap(R, q, c.plant.shank, c.plant.shank_pose).bottomRows(n);
    worst_id = std::max(worst_id, (id.tail(n) - c.loop.data.tau.row(k).transpose() -
                                   Jt * c.loop.data.contact.block(k, 6, 1, 6).transpose())
                                      .cwiseAbs()
                                      .maxCoeff());
  }
  EXPECT_LT(worst_id, 1e-9);
  // and the model's rows hold on the recording, base rows (balanced by the base sensor) and
  // joint rows alike
  const exid::Rows rows = c.loop.model->fullRows(c.loop.data, mtest::context());
  const double res = (rows.W * c.loop.model->fullNominal() - rows.y).cwiseAbs().maxCoeff();
  EXPECT_LT(res, 1e-10 * rows.y.cwiseAbs().maxCoeff()) << res;
  // the RK4 recording against one at half the step: its own error
  const Case half = humanoidTracking(2.0, 6.25e-5);
  const double rk4 = (half.loop.data.q - c.loop.data.q).cwiseAbs().maxCoeff();
  const auto [eq, et] = replay(c, c.loop.data, c.loop.truth);

  std::printf(
      "humanoid loop at the truth: joints %.2e rad, torque %.2e N m off the recording "
      "(RK4 step halved: %.2e rad); tracking error %.3f rad\n",
      eq, et, rk4,
      (c.loop.data.q -
       [&] {
         MatrixXd r(c.loop.data.size(), n);
         for (int k = 0; k < c.loop.data.size(); ++k) {
           VectorXd q, qd, qdd;
           referenceAt(c.loop.data.t[k], n, &q, &qd, &qdd);
           r.row(k) = q.transpose();
         }
         return r;
       }())
          .cwiseAbs()
          .maxCoeff());
  EXPECT_LT(eq, 1e-10);
  EXPECT_LT(et, 1e-6);
  // the base's angular acceleration read as zero: the loop leaves the recording
  exid::Dataset broken = c.loop.data;
  broken.base.middleCols(3, 3).setZero();
  const auto [bq, bt] = replay(c, broken, c.loop.truth);
  std::printf("  with alpha = 0: joints %.2e rad, torque %.2e N m off\n", bq, bt);
  EXPECT_GT(bq, 1e-5);
  EXPECT_GT(bt, 1e-2);
}

// From noise-free recorded torques, didim and iv identify the humanoid's base parameters (all
// rows: the base's six and the joints') to 1e-9 of the largest; didim's sensitivities match
// central differences of its simulation.
TEST(FloatingLoop, DidimAndIvIdentifyTheHumanoid) {
  // (didim fits the loop's output to the recording's: the plant's RK4 error is its floor,
  // 1.7e-7 at steps of 0.125 ms; iv regresses the recorded torques on their own rows and has
  // no such floor)
  const Case c = humanoidTracking(2.0, 3.125e-5);
  for (const std::string est : {"didim", "iv"}) {
    const std::string extra =
        est == "didim" ? ", rtol: 1e-12, atol: 1e-14, step_tolerance: 1e-12, gradient_check: 2"
                       : ", rtol: 1e-10, atol: 1e-12";
    auto e = exid_test::create<exid::Estimator>(est, "{" + c.loop.params + extra + "}");
    const exid::Estimate r = e->estimate(*c.loop.model, c.loop.data, nullptr, mtest::context());
    const double err = scaledErr(r.value, c.loop.truth);
    std::printf(
        "[%s] humanoid, noise-free torques: largest error / largest parameter %.2e, "
        "%s iterations\n",
        est.c_str(), err, r.details.find("iterations")->dump().c_str());
    RecordProperty(est, fmt::format("{:.3e}", err));
    EXPECT_LT(err, 1e-9) << est;
    EXPECT_NE(r.details.find("controller")->asString().find("recorded base motion"),
              std::string::npos)
        << est;
    if (est == "didim") {
      const double grad =
          r.details.find("gradient_check")->find("max_relative_difference")->asDouble();
      std::printf("[didim] sensitivities against central differences %.2e\n", grad);
      EXPECT_LT(grad, 1e-4);
    }
  }
}

// What the floating loop does not do is refused by name: the measurement delay (didim), the
// positions fitted beside the base rows, a recording that starts after the reference (no base
// motion to start from); the same estimators run with rows: joints (no base rows fitted).
TEST(FloatingLoop, RefusalsNameWhy) {
  const Case c = humanoidTracking(0.4, 2.5e-4);
  auto msg = [&](const std::string& est, const std::string& extra, const exid::Dataset& d,
                 const exid::ObservationModel* model = nullptr) {
    try {
      exid_test::create<exid::Estimator>(est, "{" + c.loop.params + extra + "}")
          ->estimate(model ? *model : *c.loop.model, d, nullptr, mtest::context());
    } catch (const exid::Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  std::string m =
      msg("didim", ", measurement_delay: true, measurement_delay_max_s: 0.01, max_iterations: 1",
          c.loop.data);
  EXPECT_NE(m.find("measurement_delay is not available on a floating base"), std::string::npos)
      << m;
  m = msg("didim", ", output: position, max_iterations: 1", c.loop.data);
  EXPECT_NE(m.find("would fit positions and wrenches together"), std::string::npos) << m;
  const exid::Dataset late = exid::sliceDataset(c.loop.data, 2, c.loop.data.size());
  for (const char* est : {"didim", "iv"}) {
    m = msg(est, ", max_iterations: 1", late);
    EXPECT_NE(m.find("more than a sample after the reference's start"), std::string::npos)
        << est << ": " << m;
  }
  // the model's nonlinear parameters beside the base rows: refused before anything is simulated
  {
    auto fm =
        mtest::model("floating_base",
                     std::string("{coulomb: true, coulomb_smoothing_rad_s: [0.1], ") + kModel + "}",
                     c.loop.robot);
    try {
      exid_test::create<exid::Estimator>("didim", "{" + c.loop.params + ", max_iterations: 1}")
          ->estimate(*fm, c.loop.data, nullptr, mtest::context());
      ADD_FAILURE() << "no error";
    } catch (const exid::Error& e) {
      EXPECT_NE(std::string(e.what()).find("beside a floating base's base rows"), std::string::npos)
          << e.what();
    }
    // not refused: the same model with its nonlinear parameters kept, and with the joint rows
    // alone (where they are fitted)
    auto fj = mtest::model("floating_base",
                           std::string("{rows: joints, coulomb: true, coulomb_smoothing_rad_s: "
                                       "[0.1], ") +
                               kModel + "}",
                           c.loop.robot);
    EXPECT_EQ(msg("didim", ", fit_nonlinear: false, max_iterations: 1", c.loop.data, fm.get()),
              "no error");
    EXPECT_EQ(msg("didim", ", max_iterations: 1", c.loop.data, fj.get()), "no error");
  }
  // one sample late is read by the Lagrange polynomial of the first six: accepted
  m = msg("iv", ", max_iterations: 1", exid::sliceDataset(c.loop.data, 1, c.loop.data.size()));
  EXPECT_EQ(m, "no error");
  // the joint rows alone: no base rows in didim's output
  auto mj =
      mtest::model("floating_base", std::string("{rows: joints, ") + kModel + "}", c.loop.robot);
  const exid::Estimate e =
      exid_test::create<exid::Estimator>("didim", "{" + c.loop.params + ", max_iterations: 1}")
          ->estimate(*mj, c.loop.data, nullptr, mtest::context());
  EXPECT_EQ(e.value.size(), mj->numBase());
}

// Noisy torques and contact wrenches (0.01 N m; 0.05 N and 0.005 N m: at 0.2 N m the
// least-squares start's joint mass matrix is not positive definite and iv refuses to simulate
// it): iv's estimate within 4 of its own standard deviations for every parameter, and noise did
// enter. (Its sandwich is summed over each sample's 16 rows; this test does not tell that
// grouping from another.)
TEST(FloatingLoop, IvNoisyWithinItsStd) {
  Case c = humanoidTracking(2.0, 1.25e-4);
  std::mt19937_64 rng(11);
  std::normal_distribution<double> nd(0.0, 1.0);
  exid::Dataset& d = c.loop.data;
  for (int k = 0; k < d.size(); ++k) {
    for (int j = 0; j < d.tau.cols(); ++j) d.tau(k, j) += 0.01 * nd(rng);
    for (int e = 0; e < 12; ++e) d.contact(k, e) += (e % 6 < 3 ? 0.05 : 0.005) * nd(rng);
  }
  const exid::Estimate e = exid_test::create<exid::Estimator>("iv", "{" + c.loop.params + "}")
                               ->estimate(*c.loop.model, d, nullptr, mtest::context());
  int outside = 0;
  double worst_z = 0.0;
  for (Eigen::Index i = 0; i < c.loop.truth.size(); ++i) {
    const double z = std::abs(e.value[i] - c.loop.truth[i]) / e.std[i];
    worst_z = std::max(worst_z, z);
    outside += z > 4.0;
  }
  std::printf(
      "[iv] humanoid, noisy torques and wrenches: worst |error|/std %.2f, %d of %d beyond "
      "4 std, %s iterations\n",
      worst_z, outside, static_cast<int>(c.loop.truth.size()),
      e.details.find("iterations")->dump().c_str());
  EXPECT_EQ(outside, 0);
  EXPECT_GT(worst_z, 0.05);
}
