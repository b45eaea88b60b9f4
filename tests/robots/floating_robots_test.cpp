// The shipped floating-base robots (robots/humanoid, robots/quadruped) and the floating-base
// descriptions of the loaders: structure, physics against the virtual-chain reference, and the
// base-parameter counts of the floating regressor (all rows, base rows alone, joint rows alone)
// against the fixed-base chain with six massless virtual joints.
#include <gtest/gtest.h>

#include <cstdio>
#include <random>

#include "dyn_reference.hpp"
#include "exid/base_parameters.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/floating_base.hpp"
#include "exid/robot_loaders.hpp"
#include "floating_reference.hpp"

using namespace exid;
using namespace exid::testing;

namespace {

RobotModel shipped(const std::string& name) {
  LoadOptions o;
  o.strict = true;  // made-up data: no defect to excuse
  return loadUrdf(std::string(EXID_SOURCE_DIR) + "/robots/" + name + "/" + name + ".urdf", o);
}

double uniform(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

struct Counts {
  int all = 0, base_rows = 0, joint_rows = 0;
};

// Stacked floating regressors at random states (joints within their limits, random base motion)
// and the virtual chain's at the same states.
void counts(const RobotModel& m, int samples, Counts* floating, Counts* chain_counts) {
  std::mt19937 rng(5);
  const int n = m.dof();
  const RobotModel chain = virtualChain(m, Eigen::Vector3d(0, 0, -9.81));
  auto d = makeDynamicsData(chain);
  const int p = 10 * (n + 1);
  Eigen::MatrixXd Wa(samples * (6 + n), p), Wb(samples * 6, p), Wj(samples * n, p);
  Eigen::MatrixXd Va(samples * (6 + n), p), Vb(samples * 6, p), Vj(samples * n, p);
  Eigen::MatrixXd Yf, Yv(n + 7, 10 * (n + 7));
  for (int k = 0; k < samples; ++k) {
    Eigen::VectorXd q(n), qd(n), qdd(n);
    for (int i = 0; i < n; ++i) {
      const JointLimits& L = m.limits[static_cast<size_t>(i)];
      q[i] = uniform(rng, L.q_min, L.q_max);
      qd[i] = uniform(rng, -2, 2);
      qdd[i] = uniform(rng, -8, 8);
    }
    const Eigen::Matrix<double, 6, 1> v = randomVec(rng, 6, 1.2), vd = randomVec(rng, 6, 1.5),
                                      vdd = randomVec(rng, 6, 4.0);
    const Eigen::VectorXd qv = virtualCoordinates(v, q), qdv = virtualCoordinates(vd, qd),
                          qddv = virtualCoordinates(vdd, qdd);
    const BaseMotion base = virtualBaseMotion(chain, qv, qdv, qddv);
    floatingRegressor(m, q, qd, qdd, base, Yf);
    Wa.middleRows(k * (6 + n), 6 + n) = Yf;
    Wb.middleRows(k * 6, 6) = Yf.topRows(6);
    Wj.middleRows(k * n, n) = Yf.bottomRows(n);
    torqueRegressor(chain, *d, qv, qdv, qddv, Yv);
    const Eigen::MatrixXd cols = Yv.rightCols(p);  // without the massless virtual bodies
    Va.middleRows(k * (6 + n), 6) = cols.topRows(6);
    Va.middleRows(k * (6 + n) + 6, n) = cols.bottomRows(n);  // (row 7, the held joint, left out)
    Vb.middleRows(k * 6, 6) = cols.topRows(6);
    Vj.middleRows(k * n, n) = cols.bottomRows(n);
  }
  const auto names = floatingParameterNames(m);
  floating->all = computeBaseParameters(Wa, names).rank();
  floating->base_rows = computeBaseParameters(Wb, names).rank();
  floating->joint_rows = computeBaseParameters(Wj, names).rank();
  chain_counts->all = computeBaseParameters(Va, names).rank();
  chain_counts->base_rows = computeBaseParameters(Vb, names).rank();
  chain_counts->joint_rows = computeBaseParameters(Vj, names).rank();
}

}  // namespace

TEST(FloatingRobots, ShippedRobotsLoadAsFloatingBases) {
  const RobotModel h = shipped("humanoid");
  EXPECT_TRUE(h.floating_base);
  EXPECT_EQ(h.base.link, "torso");
  EXPECT_EQ(h.base.joint_name, "floating_base");
  EXPECT_EQ(h.dof(), 10);
  int roots = 0;
  for (const Body& b : h.bodies) roots += b.parent < 0;
  EXPECT_EQ(roots, 4);  // two legs, two arms on the torso
  // the feet are merged into the shanks: 0.0465 + 0.0145 of 33 kg
  for (const Body& b : h.bodies) {
    if (b.name == "l_shank") {
      EXPECT_NEAR(b.inertia(9), 0.061 * 33.0, 1e-9);
    }
  }
  EXPECT_NEAR(h.base.inertia(9), 0.578 * 33.0, 1e-9);
  double total = h.base.inertia(9);
  for (const Body& b : h.bodies) total += b.inertia(9);
  EXPECT_NEAR(total, 33.0 * (0.578 + 2 * (0.100 + 0.0465 + 0.0145 + 0.028 + 0.022)) + 1.2, 1e-9);
  const RobotModel q = shipped("quadruped");
  EXPECT_TRUE(q.floating_base);
  EXPECT_EQ(q.base.link, "trunk");
  EXPECT_EQ(q.dof(), 12);
  EXPECT_NEAR(q.base.inertia(9), 6.0, 1e-12);
  // fixed-base algorithms refuse them, naming why
  try {
    makeDynamicsData(h);
    ADD_FAILURE() << "no refusal";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("floating base (link 'torso')"), std::string::npos)
        << e.what();
  }
}

// The shipped robots' floating rows against the virtual chain (merged feet, the loader's frames).
TEST(FloatingRobots, ShippedRobotsMatchTheVirtualChain) {
  std::mt19937 rng(3);
  for (const char* name : {"humanoid", "quadruped"}) {
    const RobotModel m = shipped(name);
    const int n = m.dof();
    const RobotModel chain = virtualChain(m, Eigen::Vector3d(0, 0, -9.81));
    Eigen::VectorXd piv = Eigen::VectorXd::Zero(10 * (n + 7));
    piv.tail(10 * (n + 1)) = floatingParameters(m);
    for (int s = 0; s < 5; ++s) {
      const Eigen::Matrix<double, 6, 1> v = randomVec(rng, 6, 1.0);
      const Eigen::VectorXd q = randomVec(rng, n, 1.5), qd = randomVec(rng, n, 2.0),
                            qdd = randomVec(rng, n, 5.0);
      const Eigen::VectorXd qv = virtualCoordinates(v, q),
                            qdv = virtualCoordinates(randomVec(rng, 6, 1.0), qd),
                            qddv = virtualCoordinates(randomVec(rng, 6, 3.0), qdd);
      const BaseMotion base = virtualBaseMotion(chain, qv, qdv, qddv);
      const Eigen::VectorXd id = floatingInverseDynamics(m, q, qd, qdd, base);
      const Eigen::VectorXd ref = refTorques(chain, qv, qdv, qddv, piv);
      const double scale = 1.0 + ref.cwiseAbs().maxCoeff();
      EXPECT_LT((virtualRowMap(v) * id.head<6>() - ref.head<6>()).cwiseAbs().maxCoeff(),
                1e-10 * scale)
          << name;
      EXPECT_LT((id.tail(n) - ref.tail(n)).cwiseAbs().maxCoeff(), 1e-10 * scale) << name;
    }
  }
}

// Base-parameter counts: the floating regressor's and the virtual chain's (without the 60
// virtual-body columns) agree for all rows, the base rows alone and the joint rows alone; the
// base rows alone identify as many parameters as base and joint rows together (Ayusawa, Venture
// and Nakamura 2014: the base-link dynamics identify every identifiable parameter of a
// floating-base robot), and the joint rows alone fewer.
TEST(FloatingRobots, BaseParameterCountsAgreeWithTheVirtualChain) {
  for (const char* name : {"humanoid", "quadruped"}) {
    const RobotModel m = shipped(name);
    Counts f, v;
    counts(m, 120, &f, &v);
    std::printf(
        "%s: %d standard parameters; base parameters: all rows %d, base rows %d, joint "
        "rows %d (virtual chain: %d, %d, %d)\n",
        name, 10 * (m.dof() + 1), f.all, f.base_rows, f.joint_rows, v.all, v.base_rows,
        v.joint_rows);
    EXPECT_EQ(f.all, v.all) << name;
    EXPECT_EQ(f.base_rows, v.base_rows) << name;
    EXPECT_EQ(f.joint_rows, v.joint_rows) << name;
    EXPECT_EQ(f.base_rows, f.all) << name;
    EXPECT_LT(f.joint_rows, f.all) << name;
  }
}

TEST(FloatingRobots, DhDescriptionFloatingBaseKey) {
  const std::string yaml = R"(name: hopper
convention: modified
floating_base: {link: body, mass: 4.0, com: [0, 0, 0.05], inertia_com: {xx: 0.02, yy: 0.03, zz: 0.04}}
links:
  - {name: thigh, a: 0, alpha: 0, d: 0, theta: 0, mass: 1.0, com: [0.1, 0, 0], inertia_com: {xx: 0.001, yy: 0.01, zz: 0.01}}
  - {name: shank, a: 0.3, alpha: 0, d: 0, theta: 0, mass: 0.5, com: [0.1, 0, 0], inertia_com: {xx: 0.001, yy: 0.005, zz: 0.005}}
)";
  const RobotModel m = loadDhYamlString(yaml, "hopper.yaml", {});
  EXPECT_TRUE(m.floating_base);
  EXPECT_EQ(m.base.link, "body");
  EXPECT_NEAR(m.base.inertia(9), 4.0, 1e-15);
  EXPECT_NEAR(m.base.inertia(8), 0.2, 1e-15);  // MZ = 4 * 0.05
  EXPECT_NEAR(m.base.inertia(0), 0.02 + 4.0 * 0.05 * 0.05, 1e-15);
  // without the key: a fixed base
  std::string fixed = yaml;
  fixed.erase(fixed.find("floating_base"), fixed.find("links:") - fixed.find("floating_base"));
  EXPECT_FALSE(loadDhYamlString(fixed, "hopper.yaml", {}).floating_base);
  // an unknown key inside it is refused with its place
  std::string bad = yaml;
  bad.replace(bad.find("link: body"), 10, "lnk: body");
  try {
    loadDhYamlString(bad, "hopper.yaml", {});
    ADD_FAILURE() << "no refusal";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("hopper.yaml:3"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("unknown key 'lnk'"), std::string::npos) << e.what();
  }
}
