// `didim` with loop: open on a floating base: the humanoid's joints driven by the recorded
// torque on the recorded base motion and contact wrench, in windows each from its recorded
// start, fitted to the recorded positions (no reference, no controller gains). The recording
// comes from `simulate` (its floating-base inverse dynamics: exid::floatingInverseDynamics,
// recursive Newton-Euler, and the contact wrench that balances the base rows), the loop from
// the `floating_base` model's joint rows: two independent paths through the same physics.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>

#include "closed_loop_test_util.hpp"
#include "exid/error.hpp"
#include "exid/estimators/closed_loop.hpp"
#include "exid/json.hpp"
#include "model_test_util.hpp"

namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

// The humanoid's joints on their reference (sums of sines, scaled to about 15 deg), sampled at
// 1 kHz for `duration` s; one contact at the left shank (its wrench enters the joint rows
// through J^T).
exid::Dataset humanoidRecording(double duration) {
  auto robot = mtest::robot("humanoid");
  exid::Samples ref = cltest::reference(robot->dof(), duration);
  ref.q *= 0.25;
  ref.qd *= 0.25;
  ref.qdd *= 0.25;
  return mtest::simulate(robot,
                         "{sample_period_s: 0.001, contact_link: l_shank, contact_pose: [0.03, 0, "
                         "-0.36, 0, 0, 0]}",
                         7, &ref);
}

std::shared_ptr<exid::ObservationModel> jointRowsModel() {
  return mtest::model("floating_base",
                      "{rows: joints, contact_links: [l_shank], contact_poses: [0.03, 0, -0.36, "
                      "0, 0, 0]}",
                      mtest::robot("humanoid"));
}

double scaledErr(const VectorXd& th, const VectorXd& tr) {
  return (th - tr).cwiseAbs().maxCoeff() / tr.cwiseAbs().maxCoeff();
}

// The torque-driven loop at the truth against the recording: the largest joint error [rad].
double replay(const exid::ObservationModel& model, const exid::Dataset& d) {
  exid::estimators::ClosedLoop loop(model, d, "test");
  EXPECT_TRUE(loop.floatingBase());
  EXPECT_TRUE(loop.torqueDriven());
  const int n = loop.dof();
  exid::estimators::ClosedLoop::Tolerances tol;
  tol.rtol = 1e-12;
  tol.atol = 1e-14;
  // from the fourth sample (where the recorded torque's spline starts) to the fifth-to-last
  const int first = 3, last = d.size() - 5;
  VectorXd times = d.t.segment(first, last - first + 1);
  const VectorXd x0 =
      (VectorXd(2 * n) << d.q.row(first).transpose(), d.qd.row(first).transpose()).finished();
  double eq = 0.0;
  exid::estimators::ClosedLoop::Path path;
  loop.simulateFrom(
      model.baseNominal(), times[0], x0, times, tol, false,
      [&](int k, const VectorXd& x, const MatrixXd*) {
        eq = std::max(eq, (x.head(n) - d.q.row(first + k).transpose()).cwiseAbs().maxCoeff());
      },
      &path);
  return eq;
}

}  // namespace

// The loop at the truth follows the recording (to the interpolation of the recorded torque,
// base motion and wrench between samples); with the contact wrench read as zero it does not.
TEST(FloatingOpenLoop, TheTorqueDrivenLoopFollowsTheRecording) {
  // (the first 0.1 s of a 1 s recording: the joints without their controller are unstable, an
  // error grows about 1e6-fold in 0.5 s; and simulate's base harmonics are of the recording's
  // length: over 0.1 s alone they reach 190 rad/s, where the interpolation between 1 ms samples
  // is no longer exact to 1e-7)
  const exid::Dataset d = exid::sliceDataset(humanoidRecording(1.0), 0, 101);
  auto model = jointRowsModel();
  const double eq = replay(*model, d);
  exid::Dataset no_contact = d;
  no_contact.contact.setZero();
  const double bq = replay(*model, no_contact);
  std::printf(
      "[floating open loop] at the truth %.2e rad off the recording; contact read as "
      "zero: %.2e rad\n",
      eq, bq);
  EXPECT_LT(eq, 1e-7);
  EXPECT_GT(bq, 1e-4);
}

// From the recorded torque alone (no reference or gains), didim's torque-driven output error
// identifies the humanoid's joint-row base parameters from a biased start (least squares on
// noisy accelerations).
TEST(FloatingOpenLoop, DidimIdentifiesTheHumanoidFromTheRecordedTorque) {
  exid::Dataset d = humanoidRecording(0.6);
  auto model = jointRowsModel();
  const VectorXd truth = model->baseNominal();
  std::mt19937_64 rng(3);
  std::normal_distribution<double> nd(0.0, 1.0);
  for (int k = 0; k < d.size(); ++k)
    for (int j = 0; j < d.dof(); ++j) d.qdd(k, j) += 0.002 * nd(rng);
  const exid::Estimate e =
      exid_test::create<exid::Estimator>(
          "didim", "{loop: open, window_s: 0.1, output: position, rtol: 1e-10, atol: 1e-12}")
          ->estimate(*model, d, nullptr, mtest::context());
  const exid::Estimate el = exid_test::create<exid::Estimator>("batch_ls", "{}")
                                ->estimate(*model, d, nullptr, mtest::context());
  const double err = scaledErr(e.value, truth), err_ls = scaledErr(el.value, truth);
  std::printf(
      "[didim open, floating] largest error / largest parameter %.2e (least squares on noisy "
      "accelerations %.2e); %s iterations, %s simulations\n",
      err, err_ls, e.details.find("iterations")->dump().c_str(),
      e.details.find("simulations")->dump().c_str());
  RecordProperty("didim_open_floating", fmt::format("{:.3e}", err));
  EXPECT_LT(err, 1e-5);
  EXPECT_GT(err_ls, 1e-3);
  EXPECT_EQ(e.details.find("loop")->asString(), "open");
  EXPECT_NE(e.details.find("controller")->asString().find("recorded base motion"),
            std::string::npos);
}

// didim's Jacobian of the floating torque-driven loop (exact in theta, central differences of
// the joint rows in q and qd, integrated along CVODES's steps) against central differences of
// its simulation, in random directions at the start.
TEST(FloatingOpenLoop, DidimJacobianMatchesCentralDifferences) {
  const exid::Dataset d = humanoidRecording(0.2);
  const exid::Estimate e =
      exid_test::create<exid::Estimator>("didim",
                                         "{loop: open, window_s: 0.1, output: position, "
                                         "gradient_check: 2, rtol: 1e-11, atol: 1e-13, "
                                         "max_iterations: 1}")
          ->estimate(*jointRowsModel(), d, nullptr, mtest::context());
  const double grad = e.details.find("gradient_check")->find("max_relative_difference")->asDouble();
  std::printf("[didim open, floating] Jacobian against central differences %.2e\n", grad);
  EXPECT_LT(grad, 1e-3);
}
