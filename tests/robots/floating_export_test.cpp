// Floating-base robots written as URDF, MJCF and SDF and read back: exid's loaders give the same
// floating regressor and floating inverse dynamics (6 + n values) at random states; MuJoCo 2.2
// (mj_inverse with the free joint, after converting its conventions) gives exid's
// floatingInverseDynamics with the drive terms MJCF carries; libsdformat 12 loads the SDF (a
// model with no joint to the world: free) with every link where exid has it. The shipped
// floating robots: humanoid and quadruped.
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/floating_base.hpp"
#include "exid/mjcf_writer.hpp"
#include "exid/robot_loaders.hpp"
#include "exid/sdf_writer.hpp"
#include "exid/urdf_writer.hpp"
#include "exid_cli.hpp"

#ifdef EXID_HAVE_MUJOCO
#include "mujoco_test_util.hpp"
#endif
#ifdef EXID_HAVE_SDFORMAT
#include <sdf/Link.hh>
#include <sdf/Model.hh>
#include <sdf/Root.hh>
#endif

namespace {

namespace fs = std::filesystem;
using exid::BaseMotion;
using exid::Pose;
using exid::RobotModel;

RobotModel shipped(const std::string& name) {
  exid::LoadOptions o;
  o.strict = true;
  return exid::loadUrdf(std::string(EXID_SOURCE_DIR) + "/robots/" + name + "/" + name + ".urdf", o);
}

const std::vector<std::string> kRobots = {"humanoid", "quadruped"};

double uniform(std::mt19937& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}
Eigen::Vector3d random3(std::mt19937& rng, double s) {
  return Eigen::Vector3d(uniform(rng, -s, s), uniform(rng, -s, s), uniform(rng, -s, s));
}

struct State {
  Eigen::VectorXd q, qd, qdd;
  BaseMotion base;
};

State randomState(const RobotModel& m, std::mt19937& rng) {
  const int n = m.dof();
  State s{Eigen::VectorXd(n), Eigen::VectorXd(n), Eigen::VectorXd(n), BaseMotion()};
  for (int j = 0; j < n; ++j) {
    const auto& L = m.limits[static_cast<std::size_t>(j)];
    s.q(j) = uniform(rng, L.q_min, L.q_max);
    s.qd(j) = uniform(rng, -2, 2);
    s.qdd(j) = uniform(rng, -8, 8);
  }
  s.base << random3(rng, 1.5), random3(rng, 4.0), random3(rng, 12.0);
  return s;
}

/// The text of `model` in `format`, read back by exid's loader of that format.
RobotModel roundTrip(const RobotModel& model, const std::string& format, std::string* text) {
  std::vector<std::string> sink;
  exid::LoadOptions o;
  o.warnings = &sink;
  if (format == "URDF") {
    *text = exid::writeUrdf(model);
    return exid::loadUrdfString(*text, "floating.urdf", o);
  }
  if (format == "MJCF") {
    *text = exid::writeMjcf(model);
    return exid::loadMjcfString(*text, "floating.xml", o);
  }
  *text = exid::writeSdf(model);
  return exid::loadSdfString(*text, "floating.sdf", o);
}

bool mentions(const std::vector<std::string>& notes, const std::string& what) {
  for (const auto& n : notes)
    if (n.find(what) != std::string::npos) return true;
  return false;
}

}  // namespace

// The three formats read back by exid's loaders: the same floating base, bodies, parameters
// (and names), floating regressor rows and floating inverse dynamics.
TEST(FloatingExport, EveryFormatReadBackGivesTheSameFloatingDynamics) {
  for (const std::string& name : kRobots) {
    const RobotModel m = shipped(name);
    ASSERT_TRUE(m.floating_base);
    const int n = m.dof();
    for (const std::string format : {"URDF", "MJCF", "SDF"}) {
      SCOPED_TRACE(name + " as " + format);
      std::string text;
      const RobotModel r = roundTrip(m, format, &text);
      ASSERT_TRUE(r.floating_base) << text;
      EXPECT_EQ(r.base.link, m.base.link);
      // (SDF has no floating joint: a model without a joint to the world is free)
      EXPECT_EQ(r.base.joint_name, format == "SDF" ? "" : m.base.joint_name);
      EXPECT_EQ(mentions(r.notes, "read as a floating base"), format == "SDF");
      ASSERT_EQ(r.dof(), n);
      // the same bodies, perhaps in another order (MJCF nests them depth first): perm[j] is the
      // read-back index of body j
      std::vector<int> perm(static_cast<std::size_t>(n), -1);
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
          if (r.bodies[static_cast<std::size_t>(i)].name ==
              m.bodies[static_cast<std::size_t>(j)].name)
            perm[static_cast<std::size_t>(j)] = i;
      auto P = [&](int j) { return j < 0 ? -1 : perm[static_cast<std::size_t>(j)]; };
      for (int j = 0; j < n; ++j) {
        ASSERT_GE(P(j), 0) << m.bodies[static_cast<std::size_t>(j)].name;
        const auto& a = m.bodies[static_cast<std::size_t>(j)];
        const auto& b = r.bodies[static_cast<std::size_t>(P(j))];
        EXPECT_EQ(b.joint_name, a.joint_name);
        EXPECT_EQ(b.parent, P(a.parent));
        EXPECT_EQ(b.type, a.type);
        // limits as for a fixed base (velocity limits: not in MJCF)
        const auto& la = m.limits[static_cast<std::size_t>(j)];
        const auto& lb = r.limits[static_cast<std::size_t>(P(j))];
        EXPECT_EQ(lb.q_min, la.q_min);
        EXPECT_EQ(lb.q_max, la.q_max);
        EXPECT_EQ(lb.tau_max, la.tau_max);
        if (format != "MJCF") {
          EXPECT_EQ(lb.qd_max, la.qd_max);
        }
      }
      // the sensor frame as for a fixed base
      EXPECT_EQ(r.bodies[static_cast<std::size_t>(r.sensorBody())].name,
                m.bodies[static_cast<std::size_t>(m.sensorBody())].name);
      EXPECT_LE((r.sensor_pose.p - m.sensor_pose.p).cwiseAbs().maxCoeff(), 1e-15);
      EXPECT_LE((r.sensor_pose.R - m.sensor_pose.R).cwiseAbs().maxCoeff(), 1e-15);
      // the parameters and their names body by body: block 0 the base, block 1 + j body j
      const std::vector<std::string> nm = exid::floatingParameterNames(m),
                                     nr = exid::floatingParameterNames(r);
      const Eigen::VectorXd pm = exid::floatingParameters(m), pr = exid::floatingParameters(r);
      ASSERT_EQ(pr.size(), pm.size());
      ASSERT_EQ(nr.size(), nm.size());
      auto column = [&](int c) { return 10 * (P(c / 10 - 1) + 1) + c % 10; };
      Eigen::VectorXd pr_m(pm.size());
      for (int c = 0; c < pm.size(); ++c) {
        pr_m(c) = pr(column(c));
        // XX0 ... M0, then XX<k> ... M<k> of the k-th body in each model's own order
        EXPECT_EQ(nr[static_cast<std::size_t>(column(c))],
                  nm[static_cast<std::size_t>(c)].substr(
                      0, nm[static_cast<std::size_t>(c)].find_first_of("0123456789")) +
                      std::to_string(column(c) / 10));
      }
      EXPECT_LE((pr_m - pm).cwiseAbs().maxCoeff(), 1e-12 * pm.cwiseAbs().maxCoeff());
      bool same_order = true;
      for (int j = 0; j < n; ++j) same_order &= P(j) == j;
      if (same_order) {
        EXPECT_EQ(nr, nm);
      }
      std::mt19937 rng(11);
      double worst_y = 0.0, worst_id = 0.0;
      Eigen::MatrixXd Ym, Yr;
      for (int k = 0; k < 30; ++k) {
        const State s = randomState(m, rng);
        State t = s;  // the same state in the read-back order
        for (int j = 0; j < n; ++j) {
          t.q(P(j)) = s.q(j);
          t.qd(P(j)) = s.qd(j);
          t.qdd(P(j)) = s.qdd(j);
        }
        exid::floatingRegressor(m, s.q, s.qd, s.qdd, s.base, Ym);
        exid::floatingRegressor(r, t.q, t.qd, t.qdd, t.base, Yr);
        ASSERT_EQ(Yr.rows(), 6 + n);
        ASSERT_EQ(Yr.cols(), Ym.cols());
        for (int row = 0; row < 6 + n; ++row) {
          const int rr = row < 6 ? row : 6 + P(row - 6);
          const double scale = std::max(1e-300, Ym.row(row).cwiseAbs().maxCoeff());
          for (int c = 0; c < Ym.cols(); ++c)
            worst_y = std::max(worst_y, std::abs(Yr(rr, column(c)) - Ym(row, c)) / scale);
        }
        const Eigen::VectorXd wm = exid::floatingInverseDynamics(m, s.q, s.qd, s.qdd, s.base);
        const Eigen::VectorXd wr = exid::floatingInverseDynamics(r, t.q, t.qd, t.qdd, t.base);
        ASSERT_EQ(wr.size(), 6 + n);
        Eigen::VectorXd wr_m(6 + n);
        wr_m.head<6>() = wr.head<6>();
        for (int j = 0; j < n; ++j) wr_m(6 + j) = wr(6 + P(j));
        worst_id = std::max(
            worst_id, (wr_m - wm).cwiseAbs().maxCoeff() / std::max(1.0, wm.cwiseAbs().maxCoeff()));
      }
      std::printf(
          "%s as %s read back: floating regressor rows differ by %.3g (relative, row by row), "
          "floating inverse dynamics by %.3g of the largest value\n",
          name.c_str(), format.c_str(), worst_y, worst_id);
      EXPECT_LE(worst_y, 1e-12);
      EXPECT_LE(worst_id, 1e-12);
    }
  }
}

// What each writer puts at the root: URDF a massless world link and a `floating` joint to the
// base link; MJCF a <freejoint/> in the root body and no motor on it; SDF no joint to the world
// and no <static>. A fixed-base robot keeps its weld.
TEST(FloatingExport, TheRootOfEachFormat) {
  const RobotModel h = shipped("humanoid");
  const std::string urdf = exid::writeUrdf(h);
  EXPECT_NE(urdf.find("<joint name=\"floating_base\" type=\"floating\">\n    <parent "
                      "link=\"world\"/>\n    <child link=\"torso\"/>"),
            std::string::npos)
      << urdf;
  const std::string mjcf = exid::writeMjcf(h);
  EXPECT_NE(mjcf.find("<body name=\"torso\" pos=\"0 0 0\" quat=\"1 0 0 0\">"), std::string::npos)
      << mjcf;
  EXPECT_NE(mjcf.find("<freejoint name=\"floating_base\"/>"), std::string::npos) << mjcf;
  EXPECT_EQ(mjcf.find("joint=\"floating_base\""), std::string::npos) << mjcf;  // no motor
  const std::string sdf = exid::writeSdf(h);
  EXPECT_EQ(sdf.find("<parent>world</parent>"), std::string::npos) << sdf;
  EXPECT_EQ(sdf.find("<static>"), std::string::npos) << sdf;
  EXPECT_NE(sdf.find("<link name=\"torso\">\n      <inertial>"), std::string::npos) << sdf;
  // a fixed-base robot: the weld to the world, no free joint
  RobotModel fixed = h;
  fixed.floating_base = false;
  EXPECT_EQ(exid::writeUrdf(fixed).find("floating"), std::string::npos);
  EXPECT_EQ(exid::writeMjcf(fixed).find("freejoint"), std::string::npos);
  EXPECT_NE(exid::writeSdf(fixed).find("<parent>world</parent>"), std::string::npos);
  // a base link named as a body is refused by the model itself
  RobotModel clash = h;
  clash.base.link = clash.bodies[0].name;
  EXPECT_THROW(exid::writeMjcf(clash), exid::Error);
  // an inconsistent base is refused by the formats that need physical inertia
  RobotModel heavy = h;
  heavy.base.inertia(9) = -1.0;
  for (auto write : {+[](const RobotModel& x) { exid::writeMjcf(x); },
                     +[](const RobotModel& x) { exid::writeSdf(x); }}) {
    try {
      write(heavy);
      ADD_FAILURE() << "no error";
    } catch (const exid::Error& e) {
      EXPECT_NE(std::string(e.what()).find("floating base link 'torso': negative mass"),
                std::string::npos)
          << e.what();
    }
  }
}

#ifdef EXID_HAVE_MUJOCO
using mjtest::MjDataPtr;
using mjtest::MjModelPtr;
#endif

// MuJoCo's inverse dynamics of the exported MJCF, free joint included, equals exid's floating
// inverse dynamics plus the drive terms MJCF carries (armature, damping). MuJoCo's free joint:
// qpos = world position of the base origin, quaternion (w x y z) of the base frame; qvel = the
// origin's linear velocity in the WORLD frame, the angular velocity in the BODY frame; qacc their
// derivatives (the derivative of the body-frame angular velocity is the body-frame angular
// acceleration); qfrc_inverse = force in the world frame, moment about the origin in the body
// frame. exid: omega, alpha in the base frame, f = R^T (a - g).
TEST(FloatingExport, MujocoInverseDynamicsEqualsFloatingInverseDynamics) {
#ifndef EXID_HAVE_MUJOCO
  FAIL() << "built without MuJoCo (libmujoco-dev; scripts/install-deps.sh installs it)";
#else
  for (const std::string& name : kRobots) {
    SCOPED_TRACE(name);
    RobotModel m = shipped(name);
    const int n = m.dof();
    // drive terms on every joint (the shipped robots have none): MJCF carries rotor inertia as
    // armature and viscous friction as damping
    for (int j = 0; j < n; ++j) {
      m.drives[static_cast<std::size_t>(j)].rotor_inertia = 0.01 * (j + 1);
      m.drives[static_cast<std::size_t>(j)].viscous = 0.2 + 0.05 * j;
    }
    std::string err;
    const MjModelPtr mm = mjtest::loadMjcf(name, exid::writeMjcf(m), &err);
    ASSERT_NE(mm.m, nullptr) << err;
    EXPECT_EQ(err, "");
    ASSERT_EQ(mm.m->nq, 7 + n);
    ASSERT_EQ(mm.m->nv, 6 + n);
    ASSERT_EQ(mm.m->nu, n);  // one motor per joint, none on the free joint
    mm.m->opt.disableflags |= mjDSBL_FRICTIONLOSS | mjDSBL_LIMIT | mjDSBL_CONTACT;
    const int free = mj_name2id(mm.m, mjOBJ_JOINT, m.base.joint_name.c_str());
    ASSERT_GE(free, 0);
    ASSERT_EQ(mm.m->jnt_type[free], mjJNT_FREE);
    const int fq = mm.m->jnt_qposadr[free], fv = mm.m->jnt_dofadr[free];
    std::vector<int> qadr(static_cast<std::size_t>(n)), vadr(static_cast<std::size_t>(n));
    for (int j = 0; j < n; ++j) {
      const int id =
          mj_name2id(mm.m, mjOBJ_JOINT, m.bodies[static_cast<std::size_t>(j)].joint_name.c_str());
      ASSERT_GE(id, 0);
      qadr[static_cast<std::size_t>(j)] = mm.m->jnt_qposadr[id];
      vadr[static_cast<std::size_t>(j)] = mm.m->jnt_dofadr[id];
    }
    const Eigen::Vector3d g_w(mm.m->opt.gravity[0], mm.m->opt.gravity[1], mm.m->opt.gravity[2]);
    EXPECT_EQ(g_w, m.gravity);
    MjDataPtr md;
    md.d = mj_makeData(mm.m);
    std::mt19937 rng(23);
    double worst = 0.0, drive_share = 0.0, base_share = 0.0;
    for (int k = 0; k < 40; ++k) {
      State s = randomState(m, rng);
      const Eigen::Vector3d p = random3(rng, 2.0), v_w = random3(rng, 1.5),
                            omega_b = random3(rng, 1.5), a_w = random3(rng, 6.0),
                            alpha_b = random3(rng, 4.0);
      Eigen::Quaterniond quat(uniform(rng, -1, 1), uniform(rng, -1, 1), uniform(rng, -1, 1),
                              uniform(rng, -1, 1));
      quat.normalize();
      const Eigen::Matrix3d R = quat.toRotationMatrix();  // base axes in the world frame
      for (int i = 0; i < 3; ++i) {
        md.d->qpos[fq + i] = p(i);
        md.d->qvel[fv + i] = v_w(i);
        md.d->qvel[fv + 3 + i] = omega_b(i);
        md.d->qacc[fv + i] = a_w(i);
        md.d->qacc[fv + 3 + i] = alpha_b(i);
      }
      md.d->qpos[fq + 3] = quat.w();
      md.d->qpos[fq + 4] = quat.x();
      md.d->qpos[fq + 5] = quat.y();
      md.d->qpos[fq + 6] = quat.z();
      for (int j = 0; j < n; ++j) {
        md.d->qpos[qadr[static_cast<std::size_t>(j)]] = s.q(j);
        md.d->qvel[vadr[static_cast<std::size_t>(j)]] = s.qd(j);
        md.d->qacc[vadr[static_cast<std::size_t>(j)]] = s.qdd(j);
      }
      mj_inverse(mm.m, md.d);
      Eigen::VectorXd w_mj(6 + n);
      const Eigen::Vector3d F_w(md.d->qfrc_inverse[fv], md.d->qfrc_inverse[fv + 1],
                                md.d->qfrc_inverse[fv + 2]);
      w_mj.head<3>() = R.transpose() * F_w;
      for (int i = 0; i < 3; ++i) w_mj(3 + i) = md.d->qfrc_inverse[fv + 3 + i];
      for (int j = 0; j < n; ++j)
        w_mj(6 + j) = md.d->qfrc_inverse[vadr[static_cast<std::size_t>(j)]];
      s.base << omega_b, alpha_b, R.transpose() * (a_w - g_w);
      const Eigen::VectorXd rigid = exid::floatingInverseDynamics(m, s.q, s.qd, s.qdd, s.base);
      Eigen::VectorXd w = rigid;
      for (int j = 0; j < n; ++j) {
        const auto& d = m.drives[static_cast<std::size_t>(j)];
        w(6 + j) += d.rotor_inertia * s.qdd(j) + d.viscous * s.qd(j);
      }
      const double scale = std::max(1.0, w.cwiseAbs().maxCoeff());
      worst = std::max(worst, (w_mj - w).cwiseAbs().maxCoeff() / scale);
      drive_share = std::max(drive_share, (w - rigid).cwiseAbs().maxCoeff() / scale);
      base_share = std::max(base_share, w.head<6>().cwiseAbs().maxCoeff() / scale);
    }
    std::printf(
        "%s: MuJoCo mj_inverse (free joint) vs exid floatingInverseDynamics + drive terms, "
        "largest error %.3g of the largest value (the drive terms are up to %.3g of it)\n",
        name.c_str(), worst, drive_share);
    EXPECT_LE(worst, 1e-9);
    EXPECT_GT(drive_share, 1e-4);
    EXPECT_GT(base_share, 0.1);  // the six base rows are compared, not only the joints
  }
#endif
}

// At MuJoCo's reference configuration (qpos0: the free joint at the root body's pos/quat, the
// identity, the joints at 0) every body is where exid's floatingBodyPose puts it with the base
// frame at the world frame: the root pose and the bodies hanging from it are written right.
TEST(FloatingExport, MujocoPlacesTheBodiesAtTheReferencePose) {
#ifndef EXID_HAVE_MUJOCO
  FAIL() << "built without MuJoCo (libmujoco-dev; scripts/install-deps.sh installs it)";
#else
  for (const std::string& name : kRobots) {
    SCOPED_TRACE(name);
    const RobotModel m = shipped(name);
    const int n = m.dof();
    std::string err;
    const MjModelPtr mm = mjtest::loadMjcf(name, exid::writeMjcf(m), &err);
    ASSERT_NE(mm.m, nullptr) << err;
    MjDataPtr md;
    md.d = mj_makeData(mm.m);  // qpos = qpos0
    mj_kinematics(mm.m, md.d);
    const Eigen::VectorXd q0 = Eigen::VectorXd::Zero(n);
    double worst = 0.0;
    for (int j = -1; j < n; ++j) {
      const std::string body = j < 0 ? m.base.link : m.bodies[static_cast<std::size_t>(j)].name;
      const int id = mj_name2id(mm.m, mjOBJ_BODY, body.c_str());
      ASSERT_GE(id, 0) << body;
      const Pose X = exid::floatingBodyPose(m, q0, j);
      for (int r = 0; r < 3; ++r) {
        worst = std::max(worst, std::abs(md.d->xpos[3 * id + r] - X.p(r)));
        for (int c = 0; c < 3; ++c)
          worst = std::max(worst, std::abs(md.d->xmat[9 * id + 3 * r + c] - X.R(r, c)));
      }
    }
    EXPECT_LE(worst, 1e-12);
  }
#endif
}

// libsdformat loads the SDF without errors: a model with no joint to the world (free in
// SDFormat), not static, the base link its canonical link, every link at exid's body pose.
TEST(FloatingExport, SdformatLoadsAFreeModel) {
#ifndef EXID_HAVE_SDFORMAT
  FAIL() << "built without libsdformat (libsdformat-dev; scripts/install-deps.sh installs it)";
#else
  for (const std::string& name : kRobots) {
    SCOPED_TRACE(name);
    const RobotModel m = shipped(name);
    const int n = m.dof();
    sdf::Root root;
    const sdf::Errors errors = root.LoadSdfString(exid::writeSdf(m));
    for (const auto& e : errors) ADD_FAILURE() << e.Message();
    ASSERT_TRUE(errors.empty());
    const sdf::Model* model = root.Model();
    ASSERT_NE(model, nullptr);
    EXPECT_FALSE(model->Static());
    EXPECT_EQ(model->LinkCount(), static_cast<uint64_t>(n + 1));
    EXPECT_EQ(model->JointCount(), static_cast<uint64_t>(n));  // none to the world
    ASSERT_NE(model->CanonicalLink(), nullptr);
    EXPECT_EQ(model->CanonicalLink()->Name(), m.base.link);
    const Eigen::VectorXd q0 = Eigen::VectorXd::Zero(n);
    double worst = 0.0;
    for (int j = -1; j < n; ++j) {
      const std::string link = j < 0 ? m.base.link : m.bodies[static_cast<std::size_t>(j)].name;
      const sdf::Link* l = model->LinkByName(link);
      ASSERT_NE(l, nullptr) << link;
      ignition::math::Pose3d P;
      const sdf::Errors pe = l->SemanticPose().Resolve(P, "__model__");
      ASSERT_TRUE(pe.empty()) << pe[0].Message();
      const Pose X = exid::floatingBodyPose(m, q0, j);
      const ignition::math::Matrix3d Rs(P.Rot());
      for (int r = 0; r < 3; ++r) {
        worst = std::max(worst, std::abs(P.Pos()[static_cast<std::size_t>(r)] - X.p(r)));
        for (int c = 0; c < 3; ++c)
          worst = std::max(
              worst,
              std::abs(Rs(static_cast<std::size_t>(r), static_cast<std::size_t>(c)) - X.R(r, c)));
      }
      if (j < 0) {
        EXPECT_NEAR(l->Inertial().MassMatrix().Mass(), m.base.inertia(9),
                    1e-12 * m.base.inertia(9));
      }
    }
    EXPECT_LE(worst, 1e-12);
  }
#endif
}

// `exid export` of a floating-base robot: the identified XX0 ... M0 go to the base link, XX1 ...
// to the bodies, Ia/Fv/Fc to the drives; every format is written and read back floating.
TEST(FloatingExport, ExidExportWritesAFloatingRobot) {
  const fs::path dir = exid_cli::freshTempDir("exid_floating_export_", "cli");
  RobotModel want = shipped("humanoid");
  const int n = want.dof();
  std::string names, values;
  auto add = [&](const std::string& name, double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.17g", v);
    names += (names.empty() ? "\"" : ", \"") + name + "\"";
    values += (values.empty() ? "" : ", ") + std::string(buf);
  };
  want.base.inertia *= 1.07;  // (a scaled body stays consistent)
  for (int j = 0; j < n; ++j) want.bodies[static_cast<std::size_t>(j)].inertia *= 1.0 + 0.03 * j;
  const std::vector<std::string> pn = exid::floatingParameterNames(want);
  const Eigen::VectorXd pv = exid::floatingParameters(want);
  for (std::size_t i = 0; i < pn.size(); ++i) add(pn[i], pv(static_cast<Eigen::Index>(i)));
  for (int j = 0; j < n; ++j) {
    auto& d = want.drives[static_cast<std::size_t>(j)];
    d.rotor_inertia = 0.01 * (j + 1);
    d.viscous = 0.1 * (j + 1);
    add("Ia" + std::to_string(j + 1), d.rotor_inertia);
    add("Fv" + std::to_string(j + 1), d.viscous);
  }
  fs::create_directories(dir / "run");
  std::ofstream(dir / "run" / "summary.json")
      << "{\"identification\": {\"details\": {\"standard_parameters\": {\"names\": [" << names
      << "], \"values\": [" << values << "]}}}}\n";
  exid::LoadOptions o;
  std::vector<std::string> sink;
  o.warnings = &sink;
  for (const std::string format : {"urdf", "mjcf", "sdf"}) {
    SCOPED_TRACE(format);
    const fs::path out = dir / ("identified." + format);
    const exid_cli::CmdResult r = exid_cli::runExid(
        "export humanoid --study " + (dir / "run").string() + " --out " + out.string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(exid_cli::contains(
        r.out, std::to_string(10 * (n + 1) + 2 * n) + " identified parameters written"))
        << r.out;
    const RobotModel got = format == "urdf"   ? exid::loadUrdf(out, o)
                           : format == "mjcf" ? exid::loadMjcf(out, o)
                                              : exid::loadSdf(out, o);
    ASSERT_TRUE(got.floating_base);
    EXPECT_EQ(got.base.link, want.base.link);
    EXPECT_LE((got.base.inertia - want.base.inertia).cwiseAbs().maxCoeff(),
              1e-12 * want.base.inertia.cwiseAbs().maxCoeff());
    ASSERT_EQ(got.dof(), n);
    for (int j = 0; j < n; ++j) {
      const auto& b = want.bodies[static_cast<std::size_t>(j)];
      for (const auto& g : got.bodies)
        if (g.name == b.name) {
          EXPECT_LE((g.inertia - b.inertia).cwiseAbs().maxCoeff(),
                    1e-12 * b.inertia.cwiseAbs().maxCoeff())
              << b.name;
        }
    }
    if (format == "urdf") {  // the drives travel in <exid>
      for (int j = 0; j < n; ++j) {
        EXPECT_EQ(got.drives[static_cast<std::size_t>(j)].rotor_inertia,
                  want.drives[static_cast<std::size_t>(j)].rotor_inertia);
        EXPECT_EQ(got.drives[static_cast<std::size_t>(j)].viscous,
                  want.drives[static_cast<std::size_t>(j)].viscous);
      }
    }
  }
  // an inconsistent identified base is refused, naming it
  std::ofstream(dir / "run" / "summary.json")
      << "{\"identification\": {\"details\": {\"standard_parameters\": {\"names\": [\"M0\"], "
         "\"values\": [-1]}}}}\n";
  const exid_cli::CmdResult bad = exid_cli::runExid(
      "export humanoid --study " + (dir / "run").string() + " --out " + (dir / "x.urdf").string());
  EXPECT_NE(bad.code, 0);
  EXPECT_TRUE(exid_cli::contains(bad.out, "floating base link 'torso': negative mass")) << bad.out;
  fs::remove_all(dir);
}
