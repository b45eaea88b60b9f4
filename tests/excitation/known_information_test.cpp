// Excitation that knows what is already known (excitation.information): the criterion sees
// W^T W + the known information, with its exact gradient; a design that adds it excites what the
// earlier data missed better than one that does not; the study writes covariance.csv and reads
// it back; what exid cannot know (the new noise and rate) is asked for.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "exid/config.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/excitation.hpp"
#include "exid/interfaces.hpp"
#include "exid/runner.hpp"
#include "exid_test.hpp"

namespace fs = std::filesystem;

namespace {

const char* kFourier =
    "{period_s: 4, harmonics: 3, sample_period_s: 0.1, position_margin_rad: 0.1, "
    "acceleration_limits: false, init: random, init_scale: 0.4}";

struct DesignSetup {
  std::shared_ptr<exid::Trajectory> traj;
  std::shared_ptr<exid::ObservationModel> model;
  std::shared_ptr<exid::Criterion> crit;
};

DesignSetup make() {
  DesignSetup s;
  exid::RunContext ctx;
  ctx.seed = 3;
  auto robot = exid_test::robot("planar2r");
  s.model = exid_test::create<exid::ObservationModel>("differential", "{}");
  s.model->bind(robot, ctx);
  s.traj = exid_test::create<exid::Trajectory>("fourier", kFourier);
  s.traj->bind(robot, ctx);
  s.crit = exid_test::create<exid::Criterion>("cond", "{}");
  return s;
}

/// Information known very well about some parameters and not at all about the others (an
/// earlier experiment that moved one joint): large on the first half of the base parameters.
Eigen::MatrixXd lopsided(int p, double scale) {
  std::mt19937 rng(11);
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::MatrixXd A(p, p);
  for (int i = 0; i < p; ++i)
    for (int j = 0; j < p; ++j) A(i, j) = n(rng);
  Eigen::VectorXd d(p);
  for (int i = 0; i < p; ++i) d(i) = i < p / 2 ? scale : 1e-6 * scale;
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(A);
  const Eigen::MatrixXd Q = qr.householderQ();
  return Q * d.asDiagonal() * Q.transpose();
}

double condOf(const Eigen::MatrixXd& M) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (M + M.transpose()));
  return std::sqrt(es.eigenvalues().maxCoeff() / es.eigenvalues().minCoeff());
}

}  // namespace

// value() is the criterion of W^T W + M0 and its gradient the exact one (M0 is constant).
TEST(KnownInformation, TheCriterionSeesTheSumAndItsGradientIsExact) {
  DesignSetup s = make();
  const int p = s.model->numBase();
  const Eigen::MatrixXd W0 = s.model->design(s.traj->evaluate(s.traj->initial()));
  const Eigen::MatrixXd M0 = lopsided(p, (W0.transpose() * W0).trace() / p);
  exid::ExcitationOptions xo;
  xo.position_margin = s.traj->positionMargin();
  xo.velocity_limits = s.traj->velocityLimits();
  xo.acceleration_limits = s.traj->accelerationLimits();
  xo.prior_information = M0;
  auto prob = exid::makeExcitationProblem(s.traj, s.model, s.crit, xo);
  const Eigen::VectorXd z = prob->initial();
  Eigen::VectorXd g;
  const double J = prob->value(z, &g);
  EXPECT_NEAR(J, s.crit->evaluate(W0.transpose() * W0 + M0, nullptr), 1e-12 * J);
  EXPECT_LT((prob->information(z) - (W0.transpose() * W0 + M0)).norm(), 1e-12 * M0.norm());
  EXPECT_LT((prob->priorInformation() - M0).norm(), 1e-12 * M0.norm());
  const double h = 1e-6;
  for (Eigen::Index i = 0; i < z.size(); i += 3) {
    Eigen::VectorXd zp = z, zm = z;
    zp(i) += h;
    zm(i) -= h;
    const double fd = (prob->value(zp, nullptr) - prob->value(zm, nullptr)) / (2 * h);
    EXPECT_NEAR(g(i), fd, 1e-5 * (1 + std::abs(fd))) << "variable " << i;
  }
  // Without it, another value: the known information changes the criterion.
  exid::ExcitationOptions none = xo;
  none.prior_information.resize(0, 0);
  auto plain = exid::makeExcitationProblem(s.traj, s.model, s.crit, none);
  EXPECT_GT(std::abs(plain->value(z, nullptr) - J), 1e-3 * J);
}

// With an evaluation budget and a seed (the same answer on any machine): the design that adds
// what is known ends with a better total information than the design that ignores it.
TEST(KnownInformation, ADesignThatKnowsExcitesWhatTheEarlierDataMissed) {
  DesignSetup s = make();
  const int p = s.model->numBase();
  const Eigen::MatrixXd W0 = s.model->design(s.traj->evaluate(s.traj->initial()));
  const Eigen::MatrixXd M0 = lopsided(p, 30.0 * (W0.transpose() * W0).trace() / p);
  auto totalCond = [&](const Eigen::VectorXd& z) {
    const Eigen::MatrixXd W = s.model->design(s.traj->evaluate(z));
    return condOf(W.transpose() * W + M0);
  };
  exid::RunContext ctx;
  ctx.seed = 9;
  exid::ExcitationOptions xo;
  xo.position_margin = s.traj->positionMargin();
  xo.velocity_limits = s.traj->velocityLimits();
  xo.acceleration_limits = s.traj->accelerationLimits();
  auto optimise = [&](const Eigen::MatrixXd& known) {
    exid::ExcitationOptions o = xo;
    o.prior_information = known;
    auto prob = exid::makeExcitationProblem(s.traj, s.model, s.crit, o);
    auto opt = exid_test::create<exid::Optimizer>(
        "nlopt", "{algorithm: LD_SLSQP, objective: log, max_evaluations: 400}");
    return opt->minimize(*prob, ctx).z;
  };
  const double knowing = totalCond(optimise(M0));
  const double ignoring = totalCond(optimise(Eigen::MatrixXd()));
  EXPECT_LT(knowing, 0.8 * ignoring) << "knowing " << knowing << ", ignoring " << ignoring;
  std::cout << "total cond: knowing " << knowing << ", ignoring " << ignoring << "\n";
}

// End to end: an identification writes covariance.csv; the next design reads it (weighed by the
// new noise and rate), says what it added, and the sum's condition number is reported.
TEST(KnownInformation, AStudyAddsAnEarlierStudysCovarianceAndSaysSo) {
  const fs::path dir = fs::temp_directory_path() / ("exid_known_" + std::to_string(getpid()));
  fs::remove_all(dir);
  const std::string first =
      "robot: {type: planar2r}\n"
      "model: {type: differential}\n"
      "experiment: {type: simulate, params: {duration_s: 4, period_s: 4, harmonics: 2, "
      "noise_tau_Nm: 0.05, sample_period_s: 0.01}}\n"
      "estimator: {type: batch_ls}\n";
  exid::RunOptions o1;
  o1.out_dir = dir / "first";
  auto c1 = exid::parseStudy(first, "first.yaml", exid_test::sourceDir(), exid_test::registry());
  const exid::StudyResult r1 = exid::runStudy(c1, exid_test::registry(), o1);
  ASSERT_TRUE(r1.ok) << r1.message;
  ASSERT_TRUE(fs::exists(dir / "first" / "covariance.csv"));
  {
    std::ifstream f(dir / "first" / "covariance.csv");
    std::string head;
    std::getline(f, head);
    EXPECT_EQ(head.rfind("name,", 0), 0u) << head;
  }
  const std::string second =
      "robot: {type: planar2r}\n"
      "model: {type: differential}\n"
      "excitation:\n"
      "  trajectory: {type: fourier, params: " +
      std::string(kFourier) +
      "}\n"
      "  criterion: {type: cond}\n"
      "  optimizer: {type: nlopt, params: {max_evaluations: 150}}\n"
      "  information: {earlier_study: " +
      (dir / "first").string() + ", noise_std: 0.05, recording_rate_hz: 100}\n";
  auto c2 = exid::parseStudy(second, "second.yaml", exid_test::sourceDir(), exid_test::registry());
  const exid::StudyResult r2 = exid::runStudy(c2, exid_test::registry(), exid::RunOptions{});
  ASSERT_TRUE(r2.ok) << r2.message;
  const exid::Json* K = r2.summary.find("excitation")->find("known_information");
  ASSERT_TRUE(K);
  EXPECT_NE(K->find("sources")->at(0).asString().find("first"), std::string::npos);
  EXPECT_NEAR(K->find("rows_per_design_sample")->asDouble(), 10.0, 1e-9);  // 100 Hz x 0.1 s
  EXPECT_LE(K->find("cond_total_final")->asDouble(), K->find("cond_total_initial")->asDouble());
  // Without the new noise and rate exid cannot weigh the rows: the study says so.
  const std::string missing =
      "robot: {type: planar2r}\n"
      "model: {type: differential}\n"
      "excitation:\n"
      "  trajectory: {type: fourier}\n"
      "  criterion: {type: cond}\n"
      "  optimizer: {type: nlopt}\n"
      "  information: {prior_relative_std: 0.3}\n";
  try {
    exid::parseStudy(missing, "missing.yaml", exid_test::sourceDir(), exid_test::registry());
    ADD_FAILURE() << "no error";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("noise_std and recording_rate_hz are required"),
              std::string::npos)
        << e.what();
  }
  // Another model's study cannot be added: the base parameters differ.
  const std::string other =
      "robot: {type: planar2r}\n"
      "model: {type: differential, params: {coulomb: false, viscous: false}}\n"
      "excitation:\n"
      "  trajectory: {type: fourier, params: " +
      std::string(kFourier) +
      "}\n"
      "  criterion: {type: cond}\n"
      "  optimizer: {type: nlopt, params: {max_evaluations: 20}}\n"
      "  information: {earlier_study: " +
      (dir / "first").string() + ", noise_std: 0.05, recording_rate_hz: 100}\n";
  auto c3 = exid::parseStudy(other, "other.yaml", exid_test::sourceDir(), exid_test::registry());
  const exid::StudyResult r3 = exid::runStudy(c3, exid_test::registry(), exid::RunOptions{});
  ASSERT_FALSE(r3.ok);
  EXPECT_NE(r3.message.find("the studies must share the robot, the observation model"),
            std::string::npos)
      << r3.message;
  fs::remove_all(dir);
}

// A payload-only design for a tool change: the model is the wrist sensor's, so the criterion is
// the information of the payload's 10 parameters alone; a short period keeps the motion brief.
TEST(KnownInformation, APayloadOnlyDesignOptimisesTheTenLoadParameters) {
  const std::string study =
      "robot: {type: panda}\n"
      "model: {type: load_wrench, params: {payload_mass_kg: 1.0, payload_com_m: [0, 0, 0.05]}}\n"
      "excitation:\n"
      "  trajectory: {type: fourier, params: {period_s: 3, harmonics: 3, sample_period_s: 0.05, "
      "position_margin_rad: 0.1, init: random, init_scale: 0.3}}\n"
      "  criterion: {type: cond}\n"
      "  optimizer: {type: nlopt, params: {max_evaluations: 200}}\n";
  auto cfg = exid::parseStudy(study, "payload.yaml", exid_test::sourceDir(), exid_test::registry());
  const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), exid::RunOptions{});
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_EQ(*r.headline.robot->n_base_parameters, 10);
  const auto& x = *r.headline.excitation;
  EXPECT_LE(x.evaluations, 200);
  EXPECT_LT(x.cond_W_final, 0.5 * x.cond_W_initial) << x.cond_W_initial << " -> " << x.cond_W_final;
}
