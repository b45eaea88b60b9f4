// exid/gradient_check.hpp, the derivative checks published for plugin authors: every in-tree
// criterion, the continuous and the sampled trajectories and the differential model (with a
// nonlinear friction parameter) pass; a criterion, a trajectory and a model whose derivative is
// deliberately wrong fail, naming the wrong component; the discrete excitation problem's gradient
// with scaled columns passes too.
#include "exid/gradient_check.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/excitation.hpp"
#include "exid_test.hpp"

namespace {

// The PUMA 560's first three joints along a Fourier trajectory: an information matrix of a real
// design (base columns, scaled or not) and the plugins that give it.
struct Rig {
  std::shared_ptr<const exid::RobotModel> robot;
  std::shared_ptr<exid::Trajectory> traj;
  std::shared_ptr<exid::ObservationModel> model;
};

Rig setup(const std::string& model_params = "{joints: [1, 2, 3], friction: subtract}") {
  Rig s;
  exid::RunContext ctx;
  s.robot = exid_test::robot("puma560");
  s.traj = exid_test::create<exid::Trajectory>(
      "fourier",
      "{period_s: 4, harmonics: 2, joints: [1, 2, 3], sample_period_s: 0.05, init_scale: 0.4}");
  s.traj->bind(s.robot, ctx);
  s.model = exid_test::create<exid::ObservationModel>("differential", model_params);
  s.model->restrictMotion({0, 1, 2}, s.traj->evaluate(s.traj->initial()).q.row(0).transpose());
  s.model->bind(s.robot, ctx);
  return s;
}

Eigen::MatrixXd information(const Rig& s, bool scaled) {
  Eigen::MatrixXd W = s.model->design(s.traj->evaluate(s.traj->initial()));
  if (scaled) {  // as framework/excitation/src/excitation.cpp
    const Eigen::VectorXd nom = s.model->baseNominal().cwiseAbs();
    const double floor = std::max(1e-6, 1e-3 * nom.maxCoeff());
    W = W * nom.cwiseMax(floor).asDiagonal();
  }
  return W.transpose() * W;
}

// log_det whose dJ/dM is 25 % too large in one entry pair (2, 3): a plugin author's slip.
class WrongLogDet final : public exid::Criterion {
 public:
  double evaluate(const Eigen::MatrixXd& M, Eigen::MatrixXd* dM) const override {
    Eigen::LLT<Eigen::MatrixXd> llt(M);
    const Eigen::MatrixXd Minv = llt.solve(Eigen::MatrixXd::Identity(M.rows(), M.cols()));
    if (dM) {
      *dM = -Minv;
      (*dM)(2, 3) *= 1.25;
      (*dM)(3, 2) *= 1.25;
    }
    return -2.0 * Eigen::MatrixXd(llt.matrixL()).diagonal().array().log().sum();
  }
};

TEST(GradientCheck, EveryInTreeCriterionPassesScaledAndUnscaled) {
  const Rig s = setup();
  for (bool scaled : {false, true}) {
    const Eigen::MatrixXd M = information(s, scaled);
    for (const char* name : {"cond", "min_sv", "log_det", "frobenius_cond"}) {
      auto crit = exid_test::create<exid::Criterion>(name);
      const exid::DerivativeCheck c = exid::checkCriterion(*crit, M);
      std::cout << "  " << (scaled ? "scaled   " : "unscaled ") << c.message() << "\n";
      EXPECT_TRUE(c.ok) << c.message();
      EXPECT_GT(c.step, 0.0);
      EXPECT_EQ(c.evaluations, 1 + M.rows() * (M.rows() + 1));
    }
  }
}

TEST(GradientCheck, CriterionWithAWrongDerivativeFailsAtThatEntry) {
  const Rig s = setup();
  WrongLogDet wrong;
  wrong.setPluginName("wrong_log_det");
  const exid::DerivativeCheck c = exid::checkCriterion(wrong, information(s, true));
  std::cout << "  " << c.message() << "\n";
  EXPECT_FALSE(c.ok);
  EXPECT_EQ(c.worst, "M(2, 3)");
  EXPECT_NEAR(c.worst_analytic / c.worst_numeric, 1.25, 1e-4);
  // A small entry 25 % off, relative to the largest derivative (the file's header): far above
  // the correct criteria's errors (below 3e-7 in the test above), above the tolerance.
  EXPECT_GT(c.max_rel_error, 1e-5);
  EXPECT_NE(c.message().find("FAILED"), std::string::npos);
  EXPECT_NE(c.message().find("wrong_log_det"), std::string::npos);
  const exid::Json j = c.toJson();
  EXPECT_FALSE(j.find("ok")->asBool());
  EXPECT_EQ(j.find("worst")->asString(), "M(2, 3)");
}

// A trajectory whose vjp (and so its default jacobian) is 25 % off in one variable.
class WrongVjp final : public exid::Trajectory {
 public:
  explicit WrongVjp(std::shared_ptr<exid::Trajectory> t) : t_(std::move(t)) {}
  void bind(std::shared_ptr<const exid::RobotModel>, const exid::RunContext&) override {}
  int numVariables() const override { return t_->numVariables(); }
  Eigen::VectorXd initial() const override { return t_->initial(); }
  exid::Samples evaluate(const Eigen::VectorXd& z) const override { return t_->evaluate(z); }
  Eigen::VectorXd vjp(const Eigen::VectorXd& z, const exid::Samples& adj) const override {
    Eigen::VectorXd g = t_->vjp(z, adj);
    g(1) *= 1.25;
    return g;
  }

 private:
  std::shared_ptr<exid::Trajectory> t_;
};

TEST(GradientCheck, TrajectoriesPassAndAWrongVjpFails) {
  const Rig s = setup();
  const exid::DerivativeCheck f = exid::checkTrajectory(*s.traj, s.traj->initial());
  std::cout << "  " << f.message() << "\n";
  EXPECT_TRUE(f.ok) << f.message();
  ASSERT_EQ(f.parts.size(), 3u);  // jacobian, vjp, vjpAt (continuous)
  exid::RunContext ctx;
  auto spline = exid_test::create<exid::Trajectory>(
      "spline", "{duration_s: 2, knots: 5, joints: [1, 2], sample_period_s: 0.1}");
  spline->bind(s.robot, ctx);
  const exid::DerivativeCheck sp = exid::checkTrajectory(*spline, spline->initial());
  std::cout << "  " << sp.message() << "\n";
  EXPECT_TRUE(sp.ok) << sp.message();
  auto pw =
      exid_test::create<exid::Trajectory>("pointwise", "{duration_s: 0.5, sample_period_s: 0.1}");
  pw->bind(s.robot, ctx);
  const exid::DerivativeCheck p = exid::checkTrajectory(*pw, pw->initial());
  std::cout << "  " << p.message() << "\n";
  EXPECT_TRUE(p.ok) << p.message();
  EXPECT_EQ(p.parts.size(), 2u);  // sampled only: no vjpAt

  WrongVjp wrong(s.traj);
  wrong.setPluginName("wrong_vjp");
  const exid::DerivativeCheck w = exid::checkTrajectory(wrong, wrong.initial());
  std::cout << "  " << w.message() << "\n";
  EXPECT_FALSE(w.ok);
  EXPECT_GT(w.max_rel_error, 0.01);
  EXPECT_NE(w.worst.find("/ z_1"), std::string::npos) << w.worst;
  EXPECT_FALSE(w.parts.at(0).ok);  // jacobian (from vjp)
  EXPECT_FALSE(w.parts.at(1).ok);  // vjp
}

// A model whose fullDesignVjp loses part of the derivative with respect to qd.
class WrongModel final : public exid::ObservationModel {
 public:
  explicit WrongModel(std::shared_ptr<exid::ObservationModel> m) : m_(std::move(m)) {}
  std::vector<std::string> fullNames() const override { return m_->fullNames(); }
  Eigen::VectorXd fullNominal() const override { return m_->fullNominal(); }
  exid::Rows fullRows(const exid::Dataset& d, const exid::RunContext& c) const override {
    return m_->fullRows(d, c);
  }
  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override { return m_->fullDesign(s); }
  void fullDesignVjp(const exid::Samples& s, const Eigen::MatrixXd& dW,
                     exid::Samples* g) const override {
    m_->fullDesignVjp(s, dW, g);
    g->qd *= 0.75;
  }

 private:
  std::shared_ptr<exid::ObservationModel> m_;
};

TEST(GradientCheck, ModelPassesWithItsNonlinearParameterAndAWrongVjpFails) {
  // Stribeck friction: a nonlinear parameter per joint (fullDesignAt's dW, fullDesignVjpAt).
  const Rig s = setup("{joints: [1, 2, 3], stribeck: true, stribeck_velocity_rad_s: [0.5]}");
  ASSERT_FALSE(s.model->nonlinearParameters().empty());
  const exid::Samples few = s.model->randomSamples(3, 5);
  const exid::DerivativeCheck c = exid::checkModel(*s.model, few);
  std::cout << "  " << c.message() << "\n";
  EXPECT_TRUE(c.ok) << c.message();
  EXPECT_EQ(c.parts.size(), 3u);  // fullDesignVjp, fullDesignVjpAt, fullDesignAt dW/deta

  WrongModel wrong(s.model);
  wrong.setPluginName("wrong_model");
  const exid::DerivativeCheck w = exid::checkModel(wrong, few);
  std::cout << "  " << w.message() << "\n";
  EXPECT_FALSE(w.ok);
  EXPECT_GT(w.max_rel_error, 0.01);
  EXPECT_EQ(w.worst.rfind("model 'wrong_model': fullDesignVjp: adjoint", 0), 0u) << w.worst;
  EXPECT_NE(w.worst.find("qd(sample"), std::string::npos) << w.worst;
}

TEST(GradientCheck, GradientOfAFunctionAndOfTheScaledExcitationProblem) {
  const auto f = [](const Eigen::VectorXd& x) { return std::sin(x(0)) * x(1) * x(1); };
  Eigen::VectorXd x(2);
  x << 0.3, -2.0;
  Eigen::VectorXd g(2);
  g << std::cos(0.3) * 4.0, 2.0 * std::sin(0.3) * -2.0;
  EXPECT_TRUE(exid::checkGradient(f, x, g).ok);
  const double slip = 1e-3 * std::abs(g(1));
  g(1) *= 1.001;
  const exid::DerivativeCheck bad = exid::checkGradient(f, x, g, {}, "f", {"a", "b"});
  EXPECT_FALSE(bad.ok);
  EXPECT_EQ(bad.worst, "b");
  EXPECT_NEAR(bad.max_rel_error, slip / std::abs(g(0)), 1e-8);  // relative to the largest

  // The discrete problem J(z) = F(S W^T W S) and its gradient, every spectral criterion scaled.
  const Rig s = setup();
  for (const char* name : {"cond", "min_sv", "log_det"}) {
    auto crit = exid_test::create<exid::Criterion>(name, "{scale_columns: true}");
    exid::ExcitationOptions xo;
    xo.scale_columns = true;
    auto p = exid::makeExcitationProblem(s.traj, s.model, crit, xo);
    const Eigen::VectorXd z = p->initial();
    Eigen::VectorXd grad;
    p->value(z, &grad);
    exid::DerivativeCheckOptions o;
    o.tolerance = 1e-5;
    const exid::DerivativeCheck c =
        exid::checkGradient([&](const Eigen::VectorXd& v) { return p->value(v, nullptr); }, z, grad,
                            o, std::string("excitation problem, ") + name + " scaled");
    std::cout << "  " << c.message() << "\n";
    EXPECT_TRUE(c.ok) << c.message();
  }
}

TEST(GradientCheck, RefusesWhatItCannotCheck) {
  const Rig s = setup();
  auto crit = exid_test::create<exid::Criterion>("log_det");
  EXPECT_THROW(exid::checkCriterion(*crit, Eigen::MatrixXd::Zero(3, 3)), exid::Error);
  exid::DerivativeCheckOptions o;
  o.relative_step = -1.0;
  EXPECT_THROW(exid::checkCriterion(*crit, information(s, false), o), exid::Error);
  EXPECT_THROW(exid::checkTrajectory(*s.traj, Eigen::VectorXd::Zero(2)), exid::Error);
}

}  // namespace
