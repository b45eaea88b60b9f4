// Shipped closed chains: the palletiser's actuated torques against the tree's torques projected
// by a hand-written G of its parallelogram; base-parameter counts (an analytic count for the
// four-bar, the numerical rank for both); the DH YAML `closed_chain` keys and their errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>

#include "exid/base_parameters.hpp"
#include "exid/closed_chain.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"

namespace {

using exid::RobotModel;

std::string robotFile(const std::string& rel) {
  return std::string(EXID_SOURCE_DIR) + "/robots/" + rel;
}

RobotModel load(const std::string& rel) {
  exid::LoadOptions o;
  std::vector<std::string> sink;
  o.warnings = &sink;
  return exid::loadRobotFile(robotFile(rel), o);
}

std::string readFile(const std::string& rel) {
  std::ifstream f(robotFile(rel));
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

std::string loadError(const std::string& text) {
  try {
    exid::loadDhYamlString(text, "closed.yaml (test)");
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "";
}

// A random measured state inside the limits (positions), with velocities and accelerations.
void randomState(const RobotModel& m, std::mt19937& rng, Eigen::VectorXd* qa, Eigen::VectorXd* qda,
                 Eigen::VectorXd* qdda) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const int n = m.dof();
  qa->resize(n), qda->resize(n), qdda->resize(n);
  for (int k = 0; k < n; ++k) {
    const exid::JointLimits& L = m.limits[static_cast<size_t>(k)];
    const double lo = std::max(L.q_min, -M_PI), hi = std::min(L.q_max, M_PI);
    (*qa)[k] = lo + (hi - lo) * U(rng);
    (*qda)[k] = (2 * U(rng) - 1) * std::min(L.qd_max, 3.0);
    (*qdda)[k] = (2 * U(rng) - 1) * std::min(L.qdd_max, 10.0);
  }
}

Eigen::MatrixXd stackedRegressor(const RobotModel& m, int K, unsigned seed) {
  auto data = exid::makeDynamicsData(m);
  const exid::DriveColumns none;
  std::mt19937 rng(seed);
  Eigen::MatrixXd W(static_cast<Eigen::Index>(K) * m.dof(), exid::numParameters(m, none));
  Eigen::VectorXd qa, qda, qdda;
  for (int k = 0; k < K; ++k) {
    randomState(m, rng, &qa, &qda, &qdda);
    exid::actuatorRegressor(m, *data, none, qa, qda, qdda, W.middleRows(k * m.dof(), m.dof()));
  }
  return W;
}

int svdRank(const Eigen::MatrixXd& W) {
  // columns scaled to unit norm (as the base-parameter QR does), singular values above 1e-8
  // of the largest
  // (a column of rounding size, 1e-9 of the largest, is a parameter that does not enter: the
  // passive rows of G carry rounding errors of 1e-12 into columns that are zero in exact
  // arithmetic)
  Eigen::MatrixXd S = W;
  const double big = W.colwise().norm().maxCoeff();
  for (Eigen::Index j = 0; j < S.cols(); ++j) {
    const double c = S.col(j).norm();
    if (c > 1e-9 * big)
      S.col(j) /= c;
    else
      S.col(j).setZero();
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(S);
  const Eigen::VectorXd s = svd.singularValues();
  int r = 0;
  for (Eigen::Index i = 0; i < s.size(); ++i) r += s[i] > 1e-8 * s[0];
  return r;
}

}  // namespace

TEST(ClosedChainRobots, ShippedLoad) {
  const RobotModel f = load("fourbar/fourbar.yaml");
  EXPECT_TRUE(f.hasLoops());
  EXPECT_EQ(f.dof(), 1);
  EXPECT_EQ(f.numJoints(), 3);
  EXPECT_EQ(f.limits.size(), 1u);
  EXPECT_EQ(f.drives.size(), 1u);
  EXPECT_EQ(f.numInertialParameters(), 30);
  const RobotModel p = load("palletizer/palletizer.yaml");
  EXPECT_EQ(p.dof(), 4);
  EXPECT_EQ(p.numJoints(), 6);
  EXPECT_EQ(p.closed.actuated, (std::vector<int>{0, 1, 4, 3}));
  EXPECT_DOUBLE_EQ(p.drives[2].rotor_inertia, 2.5);  // joint5's drive is measured coordinate 3
  EXPECT_DOUBLE_EQ(p.limits[2].q_min, 75 * M_PI / 180);
  ASSERT_EQ(p.closed.tree_limits.size(), 6u);
  // (exported and read back: tests/robots/export_formats_test.cpp, ClosedChains...)
}

// The palletiser's parallelogram: crank (joint5), rod (joint6), forearm lever and upper arm
// keep the forearm's absolute angle at the crank's minus 90 degrees, so, by hand,
//   q3 = q5 - q2 - pi/2,  q6 = q2 - q5,
// and with measured coordinates (q1, q2, q5, q4):
//   G = d(q1..q6)/d(q1, q2, q5, q4) = [1 0 0 0; 0 1 0 0; 0 -1 1 0; 0 0 0 1; 0 0 1 0; 0 1 -1 0],
// constant (Gdot = 0). tau_a = G^T tau_tree(q, G qd_a, G qdd_a).
TEST(ClosedChainRobots, ParallelogramAgainstHandProjection) {
  const RobotModel m = load("palletizer/palletizer.yaml");
  Eigen::MatrixXd G(6, 4);
  G << 1, 0, 0, 0, 0, 1, 0, 0, 0, -1, 1, 0, 0, 0, 0, 1, 0, 0, 1, 0, 0, 1, -1, 0;
  auto data = exid::makeDynamicsData(m);
  std::mt19937 rng(601);
  const exid::DriveColumns none, all{true, true, true, true};
  double worst = 0.0;
  for (int t = 0; t < 100; ++t) {
    Eigen::VectorXd qa, qda, qdda;
    randomState(m, rng, &qa, &qda, &qdda);
    Eigen::VectorXd q(6);
    q << qa[0], qa[1], qa[2] - qa[1] - M_PI / 2, qa[3], qa[2], qa[1] - qa[2];
    const Eigen::VectorXd qd = G * qda, qdd = G * qdda;
    const Eigen::VectorXd tau_tree = exid::inverseDynamics(m, *data, q, qd, qdd);
    const Eigen::VectorXd hand = G.transpose() * tau_tree;
    const Eigen::VectorXd tau = exid::actuatorTorque(m, *data, none, qa, qda, qdda);
    const double scale = std::max(1.0, hand.cwiseAbs().maxCoeff());
    EXPECT_LT((tau - hand).cwiseAbs().maxCoeff(), 1e-10 * scale);
    worst = std::max(worst, (tau - hand).cwiseAbs().maxCoeff() / scale);
    // the solved tree coordinates are the hand's
    Eigen::VectorXd qs, qds, qdds;
    exid::measuredToJoint(m, qa, qda, qdda, &qs, &qds, &qdds);
    EXPECT_LT((qs - q).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((qds - qd).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((qdds - qdd).cwiseAbs().maxCoeff(), 1e-11);
    // with the drives: the regressor times the full parameters
    Eigen::MatrixXd Y(4, exid::numParameters(m, all));
    exid::actuatorRegressor(m, *data, all, qa, qda, qdda, Y);
    const Eigen::VectorXd full = exid::actuatorTorque(m, *data, all, qa, qda, qdda);
    EXPECT_LT((Y * exid::parameterValues(m, all) - full).cwiseAbs().maxCoeff(), 1e-10 * scale);
    // the joint-to-measured map picks the actuated joints
    Eigen::VectorXd back;
    exid::jointToMeasured(m, q, qd, qdd, &back, nullptr, nullptr);
    EXPECT_LT((back - qa).cwiseAbs().maxCoeff(), 1e-15);
  }
  {
    std::ostringstream os;
    os << std::scientific << worst;
    RecordProperty("worst_relative", os.str());
  }
}

// Base parameters of the four-bar (one actuated coordinate, motion in a vertical plane). Only
// ZZ, MX, MY and M of each link enter a planar motion about z. Counted by hand: crank and rocker
// turn about fixed pivots (ZZ, MX, MY each; their masses do not enter: 6); the coupler moves with
// B on the crank: its mass regroups into the crank (ZZ1 += a^2 M2, MX1 += a M2), leaving ZZ2, MX2,
// MY2 (3): 9 for the open tree. The loop adds one regrouping: a point mass at C on the coupler
// (MX2 = m b, ZZ2 = m b^2, M2 = m) is the same point mass at the rocker's end (MX3 = m c,
// ZZ3 = m c^2), so MX2 regroups into ZZ2, ZZ3, MX3: 8 base parameters.
TEST(ClosedChainRobots, BaseParameterCounts) {
  const RobotModel f = load("fourbar/fourbar.yaml");
  const Eigen::MatrixXd Wf = stackedRegressor(f, 300, 602);
  const exid::BaseParameters bf =
      exid::computeBaseParameters(Wf, exid::parameterNames(f, exid::DriveColumns{}));
  EXPECT_EQ(bf.rank(), 8);
  EXPECT_EQ(svdRank(Wf), 8);
  const RobotModel p = load("palletizer/palletizer.yaml");
  const Eigen::MatrixXd Wp = stackedRegressor(p, 300, 603);
  const exid::BaseParameters bp =
      exid::computeBaseParameters(Wp, exid::parameterNames(p, exid::DriveColumns{}));
  EXPECT_EQ(bp.rank(), svdRank(Wp));
  RecordProperty("palletizer_base_parameters", std::to_string(bp.rank()));
  // the base parameters reproduce the torques of fresh states
  const Eigen::MatrixXd W2 = stackedRegressor(p, 50, 604);
  const Eigen::VectorXd pi = exid::parameterValues(p, exid::DriveColumns{});
  EXPECT_LT((bp.columns(W2) * bp.reduce(pi) - W2 * pi).cwiseAbs().maxCoeff(),
            1e-8 * (W2 * pi).cwiseAbs().maxCoeff());
}

TEST(ClosedChainRobots, LoaderErrors) {
  const std::string four = readFile("fourbar/fourbar.yaml");
  ASSERT_FALSE(four.empty());
  auto replaced = [&](const std::string& a, const std::string& b) {
    std::string s = four;
    const std::size_t i = s.find(a);
    EXPECT_NE(i, std::string::npos) << a;
    return s.replace(i, a.size(), b);
  };
  EXPECT_EQ(loadError(four), "");
  std::string e = loadError(replaced("link_b: rocker", "link_b: rockr"));
  EXPECT_NE(e.find("unknown link 'rockr'"), std::string::npos) << e;
  EXPECT_NE(e.find("closed_chain.loops[0].link_b"), std::string::npos) << e;
  e = loadError(replaced("actuated: [joint1]", "actuated: [joint9]"));
  EXPECT_NE(e.find("unknown joint 'joint9'"), std::string::npos) << e;
  e = loadError(replaced("actuated: [joint1]", "actuated: []"));
  EXPECT_NE(e.find("actuated"), std::string::npos) << e;
  // a passive joint as the only actuated one still determines the rest; two are too many
  e = loadError(replaced("actuated: [joint1]", "actuated: [joint1, joint3]"));
  EXPECT_NE(e.find("not independent"), std::string::npos) << e;
  // a drive on a passive joint
  e = loadError(replaced("    com: [0.175, 0.0, 0.0]\n",
                         "    com: [0.175, 0.0, 0.0]\n    drive: {viscous: 0.1}\n"));
  EXPECT_NE(e.find("passive"), std::string::npos) << e;
  // a coupler too short to close anywhere near the reference
  // (|b - c| = 0.6 m exceeds every distance |BD| <= 0.5 m: it never closes)
  e = loadError(replaced("pose_a: {xyz: [0.35, 0.0, 0.0]}", "pose_a: {xyz: [0.9, 0.0, 0.0]}"));
  EXPECT_NE(e.find("does not assemble"), std::string::npos) << e;
  EXPECT_NE(e.find("'C'"), std::string::npos) << e;
  // the palletiser with its elbow crank passive: fewer actuated joints than its mobility
  std::string pal = readFile("palletizer/palletizer.yaml");
  const std::string a = "actuated: [joint1, joint2, joint5, joint4]";
  pal.replace(pal.find(a), a.size(), "actuated: [joint1, joint2, joint4]");
  const std::string d = "    drive: {rotor_inertia: 2.5, coulomb: 50.0, viscous: 70.0}\n";
  ASSERT_NE(pal.find(d), std::string::npos);
  pal.replace(pal.find(d), d.size(), "");
  e = loadError(pal);
  EXPECT_NE(e.find("do not determine the passive ones"), std::string::npos) << e;
  EXPECT_NE(e.find("mobility is 4"), std::string::npos) << e;
}

// The same four-bar as a URDF with the <exid> loop elements: the same torques as the DH file.
TEST(ClosedChainRobots, UrdfFourbarEqualsDh) {
  const char* link =
      "  <link name=\"%s\"><inertial><origin xyz=\"%s 0 0\"/><mass value=\"%s\"/>"
      "<inertia ixx=\"%s\" iyy=\"%s\" izz=\"%s\" ixy=\"0\" ixz=\"0\" iyz=\"0\"/>"
      "</inertial></link>\n";
  auto L = [&](const char* n, const char* c, const char* m, const char* xx, const char* yy,
               const char* zz) {
    char buf[512];
    std::snprintf(buf, sizeof buf, link, n, c, m, xx, yy, zz);
    return std::string(buf);
  };
  const std::string urdf =
      "<robot name=\"fourbar\">\n  <link name=\"base\"/>\n" +
      L("crank", "0.05", "0.157", "6.5417e-6", "1.32142e-4", "1.36067e-4") +
      L("coupler", "0.175", "0.5495", "2.2896e-5", "5.6141e-3", "5.6278e-3") +
      L("rocker", "0.15", "0.471", "1.9625e-5", "3.5364e-3", "3.5482e-3") +
      "  <joint name=\"joint1\" type=\"continuous\"><parent link=\"base\"/><child "
      "link=\"crank\"/><axis xyz=\"0 0 1\"/></joint>\n"
      "  <joint name=\"joint2\" type=\"continuous\"><parent link=\"crank\"/><child "
      "link=\"coupler\"/><origin xyz=\"0.1 0 0\"/><axis xyz=\"0 0 1\"/></joint>\n"
      "  <joint name=\"joint3\" type=\"continuous\"><parent link=\"base\"/><child "
      "link=\"rocker\"/><origin xyz=\"0.4 0 0\"/><axis xyz=\"0 0 1\"/></joint>\n"
      "  <exid>\n    <gravity xyz=\"0 -9.81 0\"/>\n"
      "    <loop name=\"C\" link_a=\"coupler\" link_b=\"rocker\" xyz_a=\"0.35 0 0\" "
      "xyz_b=\"0.3 0 0\" axis=\"0 0 1\"/>\n"
      "    <actuated joints=\"joint1\"/>\n"
      "    <reference joint=\"joint2\" value=\"0.9486\"/>\n"
      "    <reference joint=\"joint3\" value=\"1.8963\"/>\n"
      "    <drive joint=\"joint1\" viscous=\"0.002\" coulomb=\"0.01\"/>\n"
      "  </exid>\n</robot>\n";
  exid::LoadOptions o;
  std::vector<std::string> sink;
  o.warnings = &sink;
  const RobotModel u = exid::loadUrdfString(urdf, "fourbar.urdf (test)", o);
  const RobotModel d = load("fourbar/fourbar.yaml");
  ASSERT_EQ(u.dof(), 1);
  ASSERT_EQ(u.numJoints(), 3);
  auto du = exid::makeDynamicsData(u);
  auto dd = exid::makeDynamicsData(d);
  const exid::DriveColumns all{true, true, true, true};
  std::mt19937 rng(605);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (int t = 0; t < 30; ++t) {
    const Eigen::VectorXd qa = Eigen::VectorXd::Constant(1, M_PI * U(rng)),
                          qda = Eigen::VectorXd::Constant(1, 3 * U(rng)),
                          qdda = Eigen::VectorXd::Constant(1, 10 * U(rng));
    const Eigen::VectorXd a = exid::actuatorTorque(u, *du, all, qa, qda, qdda),
                          b = exid::actuatorTorque(d, *dd, all, qa, qda, qdda);
    EXPECT_NEAR(a[0], b[0], 1e-12 * std::max(1.0, std::abs(b[0])));
  }
  // errors: an unknown link, a drive on a passive joint, actuated joints without a loop
  auto err = [&](const std::string& from, const std::string& to) {
    std::string x = urdf;
    x.replace(x.find(from), from.size(), to);
    try {
      exid::loadUrdfString(x, "bad.urdf (test)", o);
    } catch (const exid::Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  std::string e = err("link_b=\"rocker\"", "link_b=\"rockr\"");
  EXPECT_NE(e.find("link_b 'rockr': no such link"), std::string::npos) << e;
  EXPECT_NE(e.find("bad.urdf (test):"), std::string::npos) << e;
  e = err("<drive joint=\"joint1\"", "<drive joint=\"joint2\"");
  EXPECT_NE(e.find("passive"), std::string::npos) << e;
  e = err("<actuated joints=\"joint1\"/>", "");
  EXPECT_NE(e.find("must name its actuated joints"), std::string::npos) << e;
}

// The energy model's rows on a closed chain: the tree's kinetic energy at q = phi(qa),
// qd = G qd_a equals 1/2 qd_a^T (G^T M G) qd_a, the mechanism's (with G^T M G from
// actuatorTorqueDerivatives); the regressor's rows times the parameters give it.
TEST(ClosedChainRobots, EnergyOfTheMechanism) {
  for (const char* file : {"palletizer/palletizer.yaml", "fourbar/fourbar.yaml"}) {
    const RobotModel m = load(file);
    auto data = exid::makeDynamicsData(m);
    std::mt19937 rng(606);
    const exid::DriveColumns none;
    const Eigen::VectorXd pi = m.inertialParameters();
    for (int t = 0; t < 20; ++t) {
      Eigen::VectorXd qa, qda, qdda, q, qd;
      randomState(m, rng, &qa, &qda, &qdda);
      exid::measuredToJoint(m, qa, qda, qdda, &q, &qd, nullptr);
      Eigen::RowVectorXd kin(m.numInertialParameters()), pot(m.numInertialParameters());
      exid::energyRegressor(m, *data, q, qd, kin, pot);
      Eigen::VectorXd tau;
      Eigen::MatrixXd Ma;
      exid::actuatorTorqueDerivatives(m, *data, none, qa, qda, qdda, &tau, nullptr, nullptr, &Ma);
      const double T = 0.5 * qda.dot(Ma * qda);
      EXPECT_NEAR(kin.dot(pi), T, 1e-12 * std::max(1.0, std::abs(T))) << file;
    }
  }
}
