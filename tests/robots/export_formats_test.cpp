// The robot description writers read back by their consumers: MJCF by MuJoCo 2.2 (mj_loadXML,
// then mj_inverse at random states equals exid's inverse dynamics with the drive terms that MJCF
// carries), SDF by libsdformat 12 (sdf::Root::Load without errors; every link's mass, inertia
// and pose, every joint's pose, axis, limits and dynamics equal to exid's), and URDF by exid's
// own loader — for every shipped robot with drive terms, the inertials of all three formats
// compared with exid's. MuJoCo (libmujoco-dev) and libsdformat (libsdformat-dev) are test-only
// dependencies (scripts/install-deps.sh); without one its tests skip, naming the package.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>
#include <string>
#include <vector>

#include "exid/closed_chain.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/mjcf_writer.hpp"
#include "exid/robot_loaders.hpp"
#include "exid/sdf_writer.hpp"
#include "exid/urdf_writer.hpp"
#include "exid_cli.hpp"

#ifdef EXID_HAVE_MUJOCO
#include "mujoco_test_util.hpp"
#endif
#ifdef EXID_HAVE_SDFORMAT
#include <sdf/Frame.hh>
#include <sdf/Joint.hh>
#include <sdf/JointAxis.hh>
#include <sdf/Link.hh>
#include <sdf/Model.hh>
#include <sdf/Root.hh>
#endif

namespace {

namespace fs = std::filesystem;
using exid::Pose;
using exid::RobotModel;
using Vec10 = Eigen::Matrix<double, 10, 1>;

struct Shipped {
  std::string name;
  RobotModel model;
  std::vector<int> coupled;  // measured coordinates (1-based) whose drives move several joints
};

/// Principal moments raised to satisfy the triangle inequality and positivity, keeping the mass,
/// the centre of mass and the principal axes: for published data that violate them (the PUMA
/// 560's links 1 and 3, the Stanford arm's link 5), which no exported model carries.
Vec10 madeConsistent(const Vec10& pi) {
  if (exid::checkPhysical(pi).ok) return pi;
  double mass = pi(9);
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  Eigen::Matrix3d Ic;
  if (mass > 0) {
    exid::comFromInertial(pi, &mass, &c, &Ic);
  } else {
    mass = 0;
    Ic << pi(0), pi(1), pi(2), pi(1), pi(3), pi(4), pi(2), pi(4), pi(5);
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(Ic);
  Eigen::Vector3d l = es.eigenvalues().cwiseMax(0.0);  // ascending
  if (l(0) + l(1) < l(2)) {
    const double half = 0.5 * (l(2) - l(0) - l(1)) * (1 + 1e-9);
    l(0) += half;
    l(1) += half;
  }
  Ic = es.eigenvectors() * l.asDiagonal() * es.eigenvectors().transpose();
  if (mass > 0) return exid::inertialFromCom(mass, c, Ic);
  Vec10 out = Vec10::Zero();
  out << Ic(0, 0), Ic(0, 1), Ic(0, 2), Ic(1, 1), Ic(1, 2), Ic(2, 2), 0, 0, 0, 0;
  return out;
}

std::vector<Shipped> shippedRobots() {
  const std::string dir = std::string(EXID_SOURCE_DIR);
  exid::LoadOptions o;
  std::vector<std::string> sink;
  o.warnings = &sink;
  std::vector<Shipped> out;
  for (const auto& [name, file] : std::vector<std::pair<std::string, std::string>>{
           {"panda", "robots/panda/panda.yaml"},
           {"puma560", "robots/puma560/puma560.yaml"},
           {"stanford", "robots/stanford/stanford.yaml"},
           {"irp6", "robots/irp6/irp6.yaml"},
           {"planar2r", "robots/planar2r/planar2r.yaml"}})
    out.push_back({name, exid::loadRobotFile(dir + "/" + file, o), {}});
  o.urdf_extension = dir + "/robots/tx40/tx40_exid.xml";
  out.push_back(
      {"tx40", exid::loadUrdf(dir + "/data/staubli_tx40/urdf/tx40_mdh_modified.urdf", o), {6}});
  out[3].coupled = {3, 4};  // irp6: absolute angles of joints 3 and 4 move joints 2-4 / 3-4
  for (auto& s : out)
    for (auto& b : s.model.bodies) b.inertia = madeConsistent(b.inertia);
  return out;
}

/// Body frames at q = 0 in the base frame.
std::vector<Pose> restPoses(const RobotModel& m) {
  std::vector<Pose> X(static_cast<std::size_t>(m.dof()));
  for (int i = 0; i < m.dof(); ++i) {
    const auto& b = m.bodies[static_cast<std::size_t>(i)];
    X[static_cast<std::size_t>(i)] =
        (b.parent < 0 ? Pose{} : X[static_cast<std::size_t>(b.parent)]) * b.pre * b.post;
  }
  return X;
}

/// Mass, centre of mass (body frame) and inertia about it (body axes) of exid's parameters.
void comOf(const Vec10& pi, double* mass, Eigen::Vector3d* c, Eigen::Matrix3d* Ic) {
  if (pi(9) > 0) {
    exid::comFromInertial(pi, mass, c, Ic);
  } else {
    *mass = 0;
    c->setZero();
    *Ic << pi(0), pi(1), pi(2), pi(1), pi(3), pi(4), pi(2), pi(4), pi(5);
  }
}

fs::path tempFile(const std::string& name) {
  return fs::temp_directory_path() /
         ("exid_export_formats_" + std::to_string(::getpid()) + "_" + name);
}

void writeText(const fs::path& p, const std::string& text) { std::ofstream(p) << text; }

bool mentions(const std::vector<std::string>& notes, const std::string& what) {
  for (const auto& n : notes)
    if (n.find(what) != std::string::npos) return true;
  return false;
}

/// Joint-side torque that the MJCF carries: exid's actuator torque with rotor inertia and viscous
/// friction of the coordinates that move one joint (the others' drive terms zeroed), mapped to
/// the joint coordinates (tau = T^-T tau_m).
Eigen::VectorXd expectedJointTorque(const Shipped& s, exid::DynamicsData& data,
                                    const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                    const Eigen::VectorXd& qdd) {
  RobotModel e = s.model;
  for (int j : s.coupled) {
    e.drives[static_cast<std::size_t>(j - 1)].rotor_inertia = 0;
    e.drives[static_cast<std::size_t>(j - 1)].viscous = 0;
  }
  Eigen::VectorXd qm, qdm, qddm;
  exid::jointToMeasured(e, q, qd, qdd, &qm, &qdm, &qddm);
  const exid::DriveColumns cols{true, false, true, false};
  const Eigen::VectorXd tau_m = exid::actuatorTorque(e, data, cols, qm, qdm, qddm);
  if (!e.hasTransmission()) return tau_m;
  return e.transmission.transpose().fullPivLu().solve(tau_m);
}

TEST(ExportFormats, NotesNameWhatEachFormatLeavesOut) {
  for (const Shipped& s : shippedRobots()) {
    SCOPED_TRACE(s.name);
    std::vector<std::string> mj, sd;
    exid::writeMjcf(s.model, {}, &mj);
    exid::writeSdf(s.model, {}, &sd);
    for (const auto& n : mj) std::printf("%s MJCF: %s\n", s.name.c_str(), n.c_str());
    for (const auto& n : sd) std::printf("%s SDF: %s\n", s.name.c_str(), n.c_str());
    bool offset = false, rotor = false;
    for (const auto& d : s.model.drives) {
      offset = offset || d.offset != 0;
      rotor = rotor || d.rotor_inertia != 0;
    }
    EXPECT_EQ(mentions(mj, "drive torque offsets"), offset);
    EXPECT_EQ(mentions(sd, "drive torque offsets"), offset);
    EXPECT_EQ(mentions(sd, "rotor inertias"), rotor);
    EXPECT_FALSE(mentions(mj, "rotor inertias"));
    EXPECT_EQ(mentions(mj, "the transmission"), s.model.hasTransmission());
    if (!s.coupled.empty()) {
      std::string list;
      for (std::size_t k = 0; k < s.coupled.size(); ++k)
        list += (k ? ", " : "") + std::to_string(s.coupled[k]);
      EXPECT_TRUE(mentions(mj, "drives of coordinates " + list + ", which move several joints"));
      EXPECT_TRUE(mentions(sd, "drives of coordinates " + list + ", which move several joints"));
    }
  }
  // The Panda's published viscous friction of joint 6 is negative: MJCF's damping carries it,
  // its frictionloss would not carry a negative Coulomb friction.
  RobotModel p = shippedRobots()[0].model;
  p.drives[2].coulomb = -0.5;
  std::vector<std::string> mj;
  const std::string text = exid::writeMjcf(p, {}, &mj);
  EXPECT_TRUE(mentions(mj, "negative Coulomb friction (joints 3)"));
  EXPECT_NE(text.find("Not carried by MJCF"), std::string::npos);
  EXPECT_NE(text.find("negative Coulomb friction (joints 3)"), std::string::npos);
}

TEST(ExportFormats, PhysicallyInconsistentBodiesAreRefused) {
  RobotModel m = shippedRobots()[0].model;
  auto message = [&](auto write) {
    try {
      write();
    } catch (const exid::Error& e) {
      return std::string(e.what());
    }
    return std::string("(nothing thrown)");
  };
  m.bodies[1].inertia(9) = -1.0;
  EXPECT_NE(message([&] {
              exid::writeMjcf(m);
            }).find("body 2 ('" + m.bodies[1].name + "'): negative mass"),
            std::string::npos);
  EXPECT_NE(message([&] { exid::writeSdf(m); }).find("cannot be written as SDF"),
            std::string::npos);
  m = shippedRobots()[0].model;
  m.bodies[3].inertia(5) += 100.0;  // ZZ about the origin: I1 + I2 < I3 about the centre of mass
  const std::string mj = message([&] { exid::writeMjcf(m); });
  EXPECT_NE(mj.find("body 4 ('" + m.bodies[3].name + "'): triangle inequality violated"),
            std::string::npos)
      << mj;
  EXPECT_NE(mj.find("cannot be written as MJCF"), std::string::npos) << mj;
  EXPECT_NE(message([&] { exid::writeSdf(m); }).find("triangle inequality violated"),
            std::string::npos);
}

#ifdef EXID_HAVE_MUJOCO
using mjtest::loadMjcf;
using mjtest::MjDataPtr;
using mjtest::MjModelPtr;
#endif

TEST(ExportFormats, MujocoInverseDynamicsEqualsExidWithDriveTerms) {
#ifndef EXID_HAVE_MUJOCO
  FAIL() << "built without MuJoCo (libmujoco-dev; scripts/install-deps.sh installs it)";
#else
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (const Shipped& s : shippedRobots()) {
    SCOPED_TRACE(s.name);
    const RobotModel& m = s.model;
    const int n = m.dof();
    std::string err;
    const MjModelPtr mm = loadMjcf(s.name, exid::writeMjcf(m), &err);
    ASSERT_NE(mm.m, nullptr) << err;
    EXPECT_EQ(err, "");
    ASSERT_EQ(mm.m->nv, n);
    // The smooth forces only: frictionloss is a constraint force of MuJoCo's solver (see below),
    // limits and contacts are constraints too.
    mm.m->opt.disableflags |= mjDSBL_FRICTIONLOSS | mjDSBL_LIMIT | mjDSBL_CONTACT;
    MjDataPtr md;
    md.d = mj_makeData(mm.m);
    std::vector<int> adr(static_cast<std::size_t>(n));
    for (int j = 0; j < n; ++j) {
      const int id =
          mj_name2id(mm.m, mjOBJ_JOINT, m.bodies[static_cast<std::size_t>(j)].joint_name.c_str());
      ASSERT_GE(id, 0);
      adr[static_cast<std::size_t>(j)] = mm.m->jnt_dofadr[id];
      ASSERT_EQ(mm.m->jnt_qposadr[id], mm.m->jnt_dofadr[id]);  // hinge and slide joints
    }
    auto data = exid::makeDynamicsData(m);
    double worst = 0.0, worst_drive_share = 0.0;
    for (int k = 0; k < 50; ++k) {
      Eigen::VectorXd q(n), qd(n), qdd(n);
      for (int j = 0; j < n; ++j) {
        const auto& L = m.limits[static_cast<std::size_t>(j)];
        const bool bounded = L.q_min > -1e100 && L.q_max < 1e100;
        q(j) =
            bounded ? 0.5 * (L.q_min + L.q_max) + 0.5 * (L.q_max - L.q_min) * u(rng) : 3.0 * u(rng);
        qd(j) = 2.0 * u(rng);
        qdd(j) = 4.0 * u(rng);
      }
      for (int j = 0; j < n; ++j) {
        const auto a = static_cast<std::size_t>(adr[static_cast<std::size_t>(j)]);
        md.d->qpos[a] = q(j);
        md.d->qvel[a] = qd(j);
        md.d->qacc[a] = qdd(j);
      }
      mj_inverse(mm.m, md.d);
      Eigen::VectorXd tau_mj(n);
      for (int j = 0; j < n; ++j) tau_mj(j) = md.d->qfrc_inverse[adr[static_cast<std::size_t>(j)]];
      const Eigen::VectorXd tau = expectedJointTorque(s, *data, q, qd, qdd);
      const Eigen::VectorXd rigid = exid::inverseDynamics(m, *data, q, qd, qdd);
      const double scale = std::max(1.0, tau.cwiseAbs().maxCoeff());
      worst = std::max(worst, (tau_mj - tau).cwiseAbs().maxCoeff() / scale);
      worst_drive_share = std::max(worst_drive_share, (tau - rigid).cwiseAbs().maxCoeff() / scale);
    }
    std::printf(
        "%s: MuJoCo mj_inverse vs exid (rigid body + rotor inertia + viscous friction), largest "
        "error %.3g of the largest torque; the drive terms are up to %.3g of it\n",
        s.name.c_str(), worst, worst_drive_share);
    EXPECT_LE(worst, 1e-9);
    // (planar2r has no drive terms; every other shipped robot's drives are in the comparison)
    if (s.name != "planar2r") {
      EXPECT_GT(worst_drive_share, 1e-4);
    }
  }
#endif
}

TEST(ExportFormats, MujocoReadsTheDriveTermsLimitsAndFrictionloss) {
#ifndef EXID_HAVE_MUJOCO
  FAIL() << "built without MuJoCo (libmujoco-dev; scripts/install-deps.sh installs it)";
#else
  for (const Shipped& s : shippedRobots()) {
    SCOPED_TRACE(s.name);
    const RobotModel& m = s.model;
    std::string err;
    const MjModelPtr mm = loadMjcf(s.name, exid::writeMjcf(m), &err);
    ASSERT_NE(mm.m, nullptr) << err;
    EXPECT_EQ(mm.m->opt.gravity[0], m.gravity.x());
    EXPECT_EQ(mm.m->opt.gravity[1], m.gravity.y());
    EXPECT_EQ(mm.m->opt.gravity[2], m.gravity.z());
    Eigen::MatrixXd Tinv = Eigen::MatrixXd::Identity(m.dof(), m.dof());
    if (m.hasTransmission()) Tinv = m.transmission.inverse();
    for (int j = 0; j < m.dof(); ++j) {
      const auto& b = m.bodies[static_cast<std::size_t>(j)];
      const int id = mj_name2id(mm.m, mjOBJ_JOINT, b.joint_name.c_str());
      ASSERT_GE(id, 0);
      const int dof = mm.m->jnt_dofadr[id];
      // the drive of coordinate j acts on joint j alone (diagonal T^-1) unless it is coupled
      const bool coupled = std::find(s.coupled.begin(), s.coupled.end(), j + 1) != s.coupled.end();
      const double r = Tinv(j, j);
      const auto& d = m.drives[static_cast<std::size_t>(j)];
      const double tol = 1e-12 * std::max(1.0, std::abs(d.rotor_inertia * r * r));
      if (!coupled) {
        EXPECT_NEAR(mm.m->dof_armature[dof], d.rotor_inertia * r * r, tol) << j;
        EXPECT_NEAR(mm.m->dof_damping[dof], d.viscous * r * r, 1e-12 * std::abs(d.viscous * r * r))
            << j;
        EXPECT_NEAR(mm.m->dof_frictionloss[dof], std::max(0.0, d.coulomb * std::abs(r)),
                    1e-12 * std::abs(d.coulomb * r))
            << j;
      }
      const auto& L = m.limits[static_cast<std::size_t>(j)];
      const bool bounded = L.q_min > -1e100 && L.q_max < 1e100;
      EXPECT_EQ(mm.m->jnt_limited[id] != 0, bounded);
      if (bounded) {
        EXPECT_EQ(mm.m->jnt_range[2 * id], L.q_min);
        EXPECT_EQ(mm.m->jnt_range[2 * id + 1], L.q_max);
      }
      EXPECT_EQ(mm.m->jnt_type[id],
                b.type == exid::JointType::Prismatic ? mjJNT_SLIDE : mjJNT_HINGE);
    }
    // Coulomb friction as MuJoCo has it: frictionloss is a dry-friction CONSTRAINT, its force
    // found by the (soft) constraint solver: bounded by frictionloss, opposing the motion, and a
    // smooth ramp through zero velocity where exid has Fc sign(qd). So mj_inverse with it adds
    // at most frictionloss per joint; away from rest (|qd| >= 0.1 here, MuJoCo's default
    // solref/solimp) exactly frictionloss in the direction of the velocity, as exid's.
    mm.m->opt.disableflags |= mjDSBL_LIMIT | mjDSBL_CONTACT;
    MjDataPtr md;
    md.d = mj_makeData(mm.m);
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    double moving = 0, slow = 1;
    bool any = false;
    for (int k = 0; k < 40; ++k) {
      for (int i = 0; i < mm.m->nv; ++i) {
        md.d->qpos[i] = 0.3 * u(rng);
        md.d->qvel[i] = k < 20 ? u(rng) : 1e-3 * u(rng);
        md.d->qacc[i] = u(rng);
      }
      mm.m->opt.disableflags &= ~mjDSBL_FRICTIONLOSS;
      mj_inverse(mm.m, md.d);
      const std::vector<double> with(md.d->qfrc_inverse, md.d->qfrc_inverse + mm.m->nv);
      mm.m->opt.disableflags |= mjDSBL_FRICTIONLOSS;
      mj_inverse(mm.m, md.d);
      for (int i = 0; i < mm.m->nv; ++i) {
        const double f = with[static_cast<std::size_t>(i)] - md.d->qfrc_inverse[i];
        const double fl = mm.m->dof_frictionloss[i];
        const double v = md.d->qvel[i];
        EXPECT_LE(std::abs(f), fl * (1 + 1e-12) + 1e-12) << i;
        if (fl <= 0) continue;
        any = true;
        if (std::abs(v) >= 0.1)  // the inverse force overcomes the friction, all of it
          moving = std::max(moving, std::abs(f - fl * (v > 0 ? 1 : -1)) / fl);
        if (std::abs(v) < 1e-3) slow = std::min(slow, std::abs(f) / fl);
      }
    }
    if (any) {
      EXPECT_LE(moving, 1e-12);
      EXPECT_LT(slow, 0.5);  // (near rest the force is a ramp, not Fc sign(qd))
      std::printf(
          "%s: MuJoCo frictionloss in mj_inverse: |qd| >= 0.1 differs from Fc sign(qd) by %.3g "
          "of Fc; |qd| < 1e-3 gives as little as %.3g of Fc\n",
          s.name.c_str(), moving, slow);
    }
  }
#endif
}

TEST(ExportFormats, SdformatReadsLinksJointsAndLimits) {
#ifndef EXID_HAVE_SDFORMAT
  FAIL() << "built without libsdformat (libsdformat-dev; scripts/install-deps.sh "
            "installs it)";
#else
  for (const Shipped& s : shippedRobots()) {
    SCOPED_TRACE(s.name);
    const RobotModel& m = s.model;
    const fs::path f = tempFile(s.name + ".sdf");
    writeText(f, exid::writeSdf(m));
    sdf::Root root;
    const sdf::Errors errors = root.Load(f.string());
    fs::remove(f);
    for (const auto& e : errors) ADD_FAILURE() << e.Message();
    ASSERT_TRUE(errors.empty());
    const sdf::Model* model = root.Model();
    ASSERT_NE(model, nullptr);
    EXPECT_EQ(model->LinkCount(), static_cast<uint64_t>(m.dof() + 1));
    EXPECT_EQ(model->JointCount(), static_cast<uint64_t>(m.dof() + 1));
    const std::vector<Pose> X = restPoses(m);
    auto near = [](double a, double b) {
      return std::abs(a - b) <= 1e-12 * std::max(1.0, std::abs(b));
    };
    for (int j = 0; j < m.dof(); ++j) {
      const auto& b = m.bodies[static_cast<std::size_t>(j)];
      SCOPED_TRACE(b.name);
      const sdf::Link* link = model->LinkByName(b.name);
      ASSERT_NE(link, nullptr);
      double mass = 0;
      Eigen::Vector3d c;
      Eigen::Matrix3d Ic;
      comOf(b.inertia, &mass, &c, &Ic);
      const auto& in = link->Inertial();
      EXPECT_TRUE(near(in.MassMatrix().Mass(), mass)) << in.MassMatrix().Mass() << " " << mass;
      const auto moi = in.MassMatrix().Moi();
      const double iscale = std::max(1e-300, Ic.cwiseAbs().maxCoeff());
      for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k)
          EXPECT_LE(std::abs(moi(r, k) - Ic(r, k)), 1e-12 * iscale) << r << k;
      for (int r = 0; r < 3; ++r) EXPECT_TRUE(near(in.Pose().Pos()[r], c(r))) << r;
      EXPECT_EQ(in.Pose().Rot(), ignition::math::Quaterniond::Identity);
      ignition::math::Pose3d P;
      const sdf::Errors pe = link->SemanticPose().Resolve(P, "__model__");
      ASSERT_TRUE(pe.empty()) << pe[0].Message();
      const Pose& Xj = X[static_cast<std::size_t>(j)];
      const Eigen::Quaterniond qe(Xj.R);
      const ignition::math::Quaterniond qs = P.Rot();
      EXPECT_LE(std::min((Eigen::Vector4d(qs.W(), qs.X(), qs.Y(), qs.Z()) -
                          Eigen::Vector4d(qe.w(), qe.x(), qe.y(), qe.z()))
                             .cwiseAbs()
                             .maxCoeff(),
                         (Eigen::Vector4d(qs.W(), qs.X(), qs.Y(), qs.Z()) +
                          Eigen::Vector4d(qe.w(), qe.x(), qe.y(), qe.z()))
                             .cwiseAbs()
                             .maxCoeff()),
                1e-12);
      for (int r = 0; r < 3; ++r) EXPECT_TRUE(near(P.Pos()[r], Xj.p(r))) << r;

      const sdf::Joint* joint = model->JointByName(b.joint_name);
      ASSERT_NE(joint, nullptr);
      EXPECT_EQ(joint->ChildLinkName(), b.name);
      EXPECT_EQ(joint->ParentLinkName(),
                b.parent < 0 ? "base_link" : m.bodies[static_cast<std::size_t>(b.parent)].name);
      const auto& L = m.limits[static_cast<std::size_t>(j)];
      const bool bounded = L.q_min > -1e100 && L.q_max < 1e100;
      EXPECT_EQ(joint->Type(), b.type == exid::JointType::Prismatic ? sdf::JointType::PRISMATIC
                               : bounded                            ? sdf::JointType::REVOLUTE
                                                                    : sdf::JointType::CONTINUOUS);
      const sdf::JointAxis* axis = joint->Axis(0);
      ASSERT_NE(axis, nullptr);
      // the axis in the model frame, and the joint frame's origin there (at q = 0)
      ignition::math::Vector3d a;
      const sdf::Errors ae = axis->ResolveXyz(a, "__model__");
      ASSERT_TRUE(ae.empty()) << ae[0].Message();
      const Pose Jf = (b.parent < 0 ? Pose{} : X[static_cast<std::size_t>(b.parent)]) * b.pre;
      const Eigen::Vector3d ae_model = Jf.R * b.axis;
      for (int r = 0; r < 3; ++r) EXPECT_TRUE(near(a[r], ae_model(r))) << r;
      ignition::math::Pose3d PJ;
      ASSERT_TRUE(joint->SemanticPose().Resolve(PJ, "__model__").empty());
      for (int r = 0; r < 3; ++r) EXPECT_TRUE(near(PJ.Pos()[r], Jf.p(r))) << r;
      if (bounded) {
        EXPECT_EQ(axis->Lower(), L.q_min);
        EXPECT_EQ(axis->Upper(), L.q_max);
      }
      if (L.tau_max < 1e100) {
        EXPECT_EQ(axis->Effort(), L.tau_max);
      }
      if (L.qd_max < 1e100) {
        EXPECT_EQ(axis->MaxVelocity(), L.qd_max);
      }
      const bool coupled = std::find(s.coupled.begin(), s.coupled.end(), j + 1) != s.coupled.end();
      const double r = m.hasTransmission() ? m.transmission.inverse()(j, j) : 1.0;
      const auto& d = m.drives[static_cast<std::size_t>(j)];
      if (!coupled) {
        EXPECT_TRUE(near(axis->Damping(), d.viscous * r * r)) << axis->Damping();
        EXPECT_TRUE(near(axis->Friction(), d.coulomb * std::abs(r))) << axis->Friction();
      }
    }
    const sdf::Frame* sensor = model->FrameByName("exid_sensor");
    ASSERT_NE(sensor, nullptr);
    EXPECT_EQ(sensor->AttachedTo(), m.bodies[static_cast<std::size_t>(m.sensorBody())].name);
  }
#endif
}

// URDF (read by exid's loader), MJCF (by MuJoCo) and SDF (by libsdformat) written from the
// same model carry the same inertials: mass, centre of mass and inertia about it, in the body
// frame, to 1e-12 — MuJoCo's through its principal axes, URDF's in the moved joint frame.
TEST(ExportFormats, EveryFormatCarriesTheSameInertials) {
  for (const Shipped& s : shippedRobots()) {
    SCOPED_TRACE(s.name);
    const RobotModel& m = s.model;
    std::vector<std::string> sink;
    exid::LoadOptions o;
    o.warnings = &sink;
    o.strict = true;
    RobotModel u;
    bool urdf_ok = true;
    try {
      u = exid::loadUrdfString(exid::writeUrdf(m), s.name + ".urdf", o);
    } catch (const exid::Error& e) {
      // (a massless body with rotational inertia: URDF has no way to say it, and refuses)
      urdf_ok = false;
      std::printf("%s: URDF refused: %s\n", s.name.c_str(), e.what());
    }
#ifdef EXID_HAVE_MUJOCO
    std::string err;
    const MjModelPtr mm = loadMjcf(s.name, exid::writeMjcf(m), &err);
    ASSERT_NE(mm.m, nullptr) << err;
    MjDataPtr md;
    md.d = mj_makeData(mm.m);
    mj_kinematics(mm.m, md.d);
    const std::vector<Pose> X = restPoses(m);
#endif
#ifdef EXID_HAVE_SDFORMAT
    sdf::Root sroot;
    ASSERT_TRUE(sroot.LoadSdfString(exid::writeSdf(m)).empty());
    ASSERT_NE(sroot.Model(), nullptr);
#endif
    double worst = 0;
    for (int j = 0; j < m.dof(); ++j) {
      const auto& b = m.bodies[static_cast<std::size_t>(j)];
      SCOPED_TRACE(b.name);
      double mass = 0;
      Eigen::Vector3d c;
      Eigen::Matrix3d Ic;
      comOf(b.inertia, &mass, &c, &Ic);
      const double iscale = Ic.cwiseAbs().maxCoeff();
      if (urdf_ok) {
        // URDF's link frame is the moved joint frame: exid's parameters moved by `post`.
        const Vec10 want = exid::transformInertial(b.inertia, b.post);
        const Vec10 got = u.bodies[static_cast<std::size_t>(j)].inertia;
        const double e =
            (got - want).cwiseAbs().maxCoeff() / std::max(1.0, want.cwiseAbs().maxCoeff());
        EXPECT_LE(e, 1e-12);
        worst = std::max(worst, e);
      }
#ifdef EXID_HAVE_MUJOCO
      const int id = mj_name2id(mm.m, mjOBJ_BODY, b.name.c_str());
      ASSERT_GE(id, 0);
      // (MuJoCo's minimum mass 1e-15 for a massless body)
      EXPECT_NEAR(mm.m->body_mass[id], mass, 1e-12 * std::max(1.0, mass));
      for (int r = 0; r < 3; ++r)
        EXPECT_NEAR(mm.m->body_ipos[3 * id + r], c(r), 1e-12 * std::max(1.0, c.norm())) << r;
      const mjtNum* iq = mm.m->body_iquat + 4 * id;
      const Eigen::Matrix3d R = Eigen::Quaterniond(iq[0], iq[1], iq[2], iq[3]).toRotationMatrix();
      const Eigen::Vector3d l(mm.m->body_inertia[3 * id], mm.m->body_inertia[3 * id + 1],
                              mm.m->body_inertia[3 * id + 2]);
      const Eigen::Matrix3d Imj = R * l.asDiagonal() * R.transpose();
      // (MuJoCo's minimum principal moment 1e-15 where exid has none)
      const double diff = (Imj - Ic).cwiseAbs().maxCoeff();
      EXPECT_LE(diff, 1e-12 * iscale + 2e-15) << Imj << "\n" << Ic;
      if (iscale > 0) worst = std::max(worst, diff / iscale);
      // MuJoCo's body frame at q = 0 is exid's body frame
      const Pose& Xj = X[static_cast<std::size_t>(j)];
      for (int r = 0; r < 3; ++r) {
        EXPECT_NEAR(md.d->xpos[3 * id + r], Xj.p(r), 1e-12 * std::max(1.0, Xj.p.norm()));
        for (int k = 0; k < 3; ++k) EXPECT_NEAR(md.d->xmat[9 * id + 3 * r + k], Xj.R(r, k), 1e-12);
      }
#endif
#ifdef EXID_HAVE_SDFORMAT
      const sdf::Link* link = sroot.Model()->LinkByName(b.name);
      ASSERT_NE(link, nullptr);
      const auto& in = link->Inertial();
      EXPECT_NEAR(in.MassMatrix().Mass(), mass, 1e-12 * std::max(1.0, mass));
      for (int r = 0; r < 3; ++r) {
        EXPECT_NEAR(in.Pose().Pos()[r], c(r), 1e-12 * std::max(1.0, c.norm())) << r;
        for (int k = 0; k < 3; ++k) {
          const double d = std::abs(in.MassMatrix().Moi()(r, k) - Ic(r, k));
          EXPECT_LE(d, 1e-12 * iscale) << r << k;
          if (iscale > 0) worst = std::max(worst, d / iscale);
        }
      }
#endif
    }
    std::printf("%s: inertials of the exported formats, largest relative difference %.3g\n",
                s.name.c_str(), worst);
  }
}

// A joint without position limits: SDF `continuous` (revolute) or a prismatic joint without
// lower/upper, MJCF `limited="false"`; both files still load.
TEST(ExportFormats, UnboundedJointsLoad) {
  RobotModel m = shippedRobots()[2].model;  // the Stanford arm: joint 3 prismatic
  ASSERT_EQ(m.bodies[2].type, exid::JointType::Prismatic);
  for (int j : {0, 2}) {
    m.limits[static_cast<std::size_t>(j)].q_min = -1e300;
    m.limits[static_cast<std::size_t>(j)].q_max = 1e300;
    m.limits[static_cast<std::size_t>(j)].tau_max = 1e300;
    m.limits[static_cast<std::size_t>(j)].qd_max = 1e300;
  }
#ifdef EXID_HAVE_SDFORMAT
  {
    sdf::Root root;
    const sdf::Errors errors = root.LoadSdfString(exid::writeSdf(m));
    for (const auto& e : errors) ADD_FAILURE() << e.Message();
    ASSERT_NE(root.Model(), nullptr);
    const sdf::Joint* j1 = root.Model()->JointByName(m.bodies[0].joint_name);
    const sdf::Joint* j3 = root.Model()->JointByName(m.bodies[2].joint_name);
    ASSERT_TRUE(j1 && j3);
    EXPECT_EQ(j1->Type(), sdf::JointType::CONTINUOUS);
    EXPECT_EQ(j3->Type(), sdf::JointType::PRISMATIC);
    EXPECT_LE(j3->Axis(0)->Lower(), -1e16);  // (SDFormat's "no limit")
    EXPECT_GE(j3->Axis(0)->Upper(), 1e16);
    EXPECT_TRUE(std::isinf(j3->Axis(0)->Effort()));  // (libsdformat 12's "no limit")
    EXPECT_TRUE(std::isinf(j3->Axis(0)->MaxVelocity()));
  }
#endif
#ifdef EXID_HAVE_MUJOCO
  {
    std::string err;
    const MjModelPtr mm = loadMjcf("unbounded", exid::writeMjcf(m), &err);
    ASSERT_NE(mm.m, nullptr) << err;
    for (int j = 0; j < m.dof(); ++j) {
      const int id =
          mj_name2id(mm.m, mjOBJ_JOINT, m.bodies[static_cast<std::size_t>(j)].joint_name.c_str());
      EXPECT_EQ(mm.m->jnt_limited[id] != 0, j != 0 && j != 2) << j;
    }
    const int a = mj_name2id(mm.m, mjOBJ_ACTUATOR, m.bodies[0].joint_name.c_str());
    ASSERT_GE(a, 0);
    EXPECT_EQ(mm.m->actuator_ctrllimited[a], 0);
  }
#endif
}

// exid export end to end: a study's identified parameters (summary.json) written by the exid
// program in the three formats and read by MuJoCo, libsdformat and exid's URDF loader.
TEST(ExportFormats, ExidExportWritesWhatTheConsumersRead) {
  const fs::path dir = exid_cli::freshTempDir("exid_export_formats_", "cli");
  RobotModel want = shippedRobots()[0].model;  // the panda, as the `panda` plugin has it
  std::string names, values;
  auto add = [&](const std::string& n, double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.17g", v);
    names += (names.empty() ? "\"" : ", \"") + n + "\"";
    values += (values.empty() ? "" : ", ") + std::string(buf);
  };
  for (int j = 0; j < want.dof(); ++j) {
    auto& b = want.bodies[static_cast<std::size_t>(j)];
    b.inertia *= 1.0 + 0.05 * (j + 1);  // (a scaled body stays consistent)
    for (int k = 0; k < 10; ++k) add(exid::kInertialNames[k] + std::to_string(j + 1), b.inertia(k));
    auto& d = want.drives[static_cast<std::size_t>(j)];
    d.rotor_inertia = 0.01 * (j + 1);
    d.viscous = 0.1 * (j + 1);
    d.coulomb = 0.2;
    add("Ia" + std::to_string(j + 1), d.rotor_inertia);
    add("Fv" + std::to_string(j + 1), d.viscous);
    add("Fc" + std::to_string(j + 1), d.coulomb);
  }
  fs::create_directories(dir / "run");
  std::ofstream(dir / "run" / "summary.json")
      << "{\"identification\": {\"details\": {\"standard_parameters\": {\"names\": [" << names
      << "], \"values\": [" << values << "]}}}}\n";
  for (const std::string format : {"urdf", "mjcf", "sdf"}) {
    const exid_cli::CmdResult r =
        exid_cli::runExid("export panda --study " + (dir / "run").string() + " --out " +
                          (dir / ("identified." + format)).string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_TRUE(exid_cli::contains(r.out, "91 identified parameters written")) << r.out;
  }
  // URDF: exid's loader gives back the identified model (the Panda is modified DH: post = 1)
  exid::LoadOptions o;
  std::vector<std::string> sink;
  o.warnings = &sink;
  o.strict = true;
  const RobotModel u = exid::loadUrdf(dir / "identified.urdf", o);
  ASSERT_EQ(u.dof(), want.dof());
  for (int j = 0; j < want.dof(); ++j) {
    const auto k = static_cast<std::size_t>(j);
    const Vec10 w = exid::transformInertial(want.bodies[k].inertia, want.bodies[k].post);
    EXPECT_LE((u.bodies[k].inertia - w).cwiseAbs().maxCoeff(), 1e-12 * w.cwiseAbs().maxCoeff());
    EXPECT_EQ(u.drives[k].rotor_inertia, want.drives[k].rotor_inertia);
    EXPECT_EQ(u.drives[k].viscous, want.drives[k].viscous);
    EXPECT_EQ(u.drives[k].coulomb, want.drives[k].coulomb);
  }
#ifdef EXID_HAVE_SDFORMAT
  {
    sdf::Root root;
    const sdf::Errors errors = root.Load((dir / "identified.sdf").string());
    ASSERT_TRUE(errors.empty()) << errors[0].Message();
    for (const auto& b : want.bodies) {
      double mass = 0;
      Eigen::Vector3d c;
      Eigen::Matrix3d Ic;
      comOf(b.inertia, &mass, &c, &Ic);
      const sdf::Link* link = root.Model()->LinkByName(b.name);
      ASSERT_NE(link, nullptr);
      EXPECT_NEAR(link->Inertial().MassMatrix().Mass(), mass, 1e-12 * mass);
      for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k)
          EXPECT_NEAR(link->Inertial().MassMatrix().Moi()(r, k), Ic(r, k),
                      1e-12 * Ic.cwiseAbs().maxCoeff());
      EXPECT_EQ(root.Model()->JointByName(b.joint_name)->Axis(0)->Damping(),
                want.drives[static_cast<std::size_t>(&b - &want.bodies[0])].viscous);
    }
  }
#endif
#ifdef EXID_HAVE_MUJOCO
  {
    char err[1000] = "";
    MjModelPtr mm;
    mju_user_warning = mjtest::sayMujocoWarning;
    mm.m = mj_loadXML((dir / "identified.mjcf").string().c_str(), nullptr, err, sizeof err);
    ASSERT_NE(mm.m, nullptr) << err;
    mm.m->opt.disableflags |= mjDSBL_FRICTIONLOSS | mjDSBL_LIMIT | mjDSBL_CONTACT;
    MjDataPtr md;
    md.d = mj_makeData(mm.m);
    const Shipped s{"panda", want, {}};
    auto data = exid::makeDynamicsData(want);
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> uni(-1.0, 1.0);
    const int n = want.dof();
    double worst = 0;
    for (int k = 0; k < 20; ++k) {
      Eigen::VectorXd q(n), qd(n), qdd(n);
      for (int j = 0; j < n; ++j) {
        q(j) = uni(rng);
        qd(j) = 2 * uni(rng);
        qdd(j) = 4 * uni(rng);
        md.d->qpos[j] = q(j);  // (a chain: MuJoCo's order is exid's)
        md.d->qvel[j] = qd(j);
        md.d->qacc[j] = qdd(j);
      }
      mj_inverse(mm.m, md.d);
      const Eigen::VectorXd tau = expectedJointTorque(s, *data, q, qd, qdd);
      const Eigen::VectorXd tau_mj = Eigen::Map<const Eigen::VectorXd>(md.d->qfrc_inverse, n);
      worst = std::max(
          worst, (tau_mj - tau).cwiseAbs().maxCoeff() / std::max(1.0, tau.cwiseAbs().maxCoeff()));
    }
    EXPECT_LE(worst, 1e-9);
    for (int j = 0; j < n; ++j) EXPECT_EQ(mm.m->dof_frictionloss[j], 0.2);
    std::printf("exid export panda --out identified.mjcf: mj_inverse vs exid, largest error %.3g\n",
                worst);
  }
#endif
  fs::remove_all(dir);
}

// ---------------------------------------------------------------- back into exid
/// exid -> URDF / MJCF / SDF -> exid: the model read back from each exported file gives the same
/// joint torques as the model written (rigid body; with the drive terms each format carries).
struct Format {
  const char* name;
  std::string (*write)(const RobotModel&);
  RobotModel (*load)(const std::string&, const std::string&, const exid::LoadOptions&);
  bool rotor, transmission;  // carries rotor inertias / the transmission and every drive term
};

const std::vector<Format>& formats() {
  static const std::vector<Format> f = {
      {"urdf", [](const RobotModel& m) { return exid::writeUrdf(m); }, &exid::loadUrdfString, true,
       true},
      {"mjcf", [](const RobotModel& m) { return exid::writeMjcf(m); }, &exid::loadMjcfString, true,
       false},
      {"sdf", [](const RobotModel& m) { return exid::writeSdf(m); }, &exid::loadSdfString, false,
       false}};
  return f;
}

Eigen::VectorXd randomState(const RobotModel& m, std::mt19937* rng, double scale) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd x(m.dof());
  for (int j = 0; j < m.dof(); ++j) {
    const auto& L = m.limits[static_cast<std::size_t>(j)];
    const bool bounded = L.q_min > -1e100 && L.q_max < 1e100 && scale == 0.0;
    x(j) = bounded ? 0.5 * (L.q_min + L.q_max) + 0.5 * (L.q_max - L.q_min) * u(*rng)
                   : (scale == 0.0 ? 3.0 : scale) * u(*rng);
  }
  return x;
}

TEST(ExportFormats, EveryFormatReadBackGivesTheSameTorques) {
  std::mt19937 rng(19);
  for (const Shipped& s : shippedRobots()) {
    const RobotModel& m = s.model;
    const int n = m.dof();
    auto d0 = exid::makeDynamicsData(m);
    for (const Format& f : formats()) {
      SCOPED_TRACE(s.name + " " + f.name);
      std::vector<std::string> sink, own;
      exid::LoadOptions o;
      o.warnings = &sink;
      o.urdf_dynamics_as_friction = true;
      RobotModel r;
      try {
        r = f.load(f.write(m), s.name + "." + f.name, o);
      } catch (const exid::Error& e) {
        // a massless body with rotational inertia (the PUMA 560's first link): URDF cannot say it
        ASSERT_STREQ(f.name, "urdf") << e.what();
        EXPECT_NE(std::string(e.what()).find("has mass 0 and non-zero inertial parameters"),
                  std::string::npos)
            << e.what();
        continue;
      }
      // what the loader finds is what the model written has (the PUMA 560's massless first
      // link with rotational inertia; MJCF writes MuJoCo's minimum mass 1e-15 instead)
      exid::LoadOptions mine;
      mine.warnings = &own;
      exid::checkModelPhysical(m, mine);
      EXPECT_EQ(sink.size(), std::string(f.name) == "mjcf" ? 0u : own.size());
      ASSERT_EQ(r.dof(), n);
      EXPECT_EQ(r.name, m.name);
      if (std::string(f.name) == "sdf") {
        EXPECT_TRUE(mentions(r.notes, "carries no gravity"));
        r.gravity = m.gravity;  // (the writer's notes say that SDF leaves it out)
      }
      EXPECT_EQ(r.sensorBody(), m.sensorBody());
      auto d1 = exid::makeDynamicsData(r);
      double worst = 0.0;
      for (int k = 0; k < 40; ++k) {
        const Eigen::VectorXd q = randomState(m, &rng, 0.0), qd = randomState(m, &rng, 2.0),
                              qdd = randomState(m, &rng, 4.0);
        for (int j = 0; j < n; ++j) {
          EXPECT_EQ(r.bodies[static_cast<std::size_t>(j)].joint_name,
                    m.bodies[static_cast<std::size_t>(j)].joint_name);
          EXPECT_EQ(r.bodies[static_cast<std::size_t>(j)].parent,
                    m.bodies[static_cast<std::size_t>(j)].parent);
        }
        // rigid body, joint coordinates
        const Eigen::VectorXd t0 = exid::inverseDynamics(m, *d0, q, qd, qdd);
        const Eigen::VectorXd t1 = exid::inverseDynamics(r, *d1, q, qd, qdd);
        const double scale = std::max(1.0, t0.cwiseAbs().maxCoeff());
        worst = std::max(worst, (t1 - t0).cwiseAbs().maxCoeff() / scale);
        // the sensor frame goes along: its pose in the base frame
        const Pose S0 = exid::bodyPose(m, *d0, q, m.sensorBody()) * m.sensor_pose;
        const Pose S1 = exid::bodyPose(r, *d1, q, r.sensorBody()) * r.sensor_pose;
        EXPECT_LE((S0.R - S1.R).cwiseAbs().maxCoeff(), 1e-12);
        EXPECT_LE((S0.p - S1.p).cwiseAbs().maxCoeff(), 1e-12);
        // with the drive terms the format carries: exid's own format (URDF) all of them, in
        // measured coordinates; MJCF and SDF the terms of the coordinates that move one joint
        if (f.transmission) {
          const exid::DriveColumns all{true, true, true, true};
          Eigen::VectorXd qm, qdm, qddm;
          exid::jointToMeasured(m, q, qd, qdd, &qm, &qdm, &qddm);
          const Eigen::VectorXd a0 = exid::actuatorTorque(m, *d0, all, qm, qdm, qddm);
          const Eigen::VectorXd a1 = exid::actuatorTorque(r, *d1, all, qm, qdm, qddm);
          worst = std::max(worst, (a1 - a0).cwiseAbs().maxCoeff() / scale);
        } else {
          Shipped e = s;
          if (!f.rotor)
            for (auto& d : e.model.drives) d.rotor_inertia = 0;
          const Eigen::VectorXd a0 = expectedJointTorque(e, *d0, q, qd, qdd);
          const exid::DriveColumns cols{true, false, true, false};
          const Eigen::VectorXd a1 = exid::actuatorTorque(r, *d1, cols, q, qd, qdd);
          worst = std::max(worst, (a1 - a0).cwiseAbs().maxCoeff() / scale);
        }
      }
      EXPECT_LE(worst, 1e-12);
      std::printf("%s via %s: largest torque difference %.3g (relative)\n", s.name.c_str(), f.name,
                  worst);
      // Coulomb friction and the limits of the joints that one coordinate moves
      for (int j = 0; j < n && !m.hasTransmission(); ++j) {
        const auto J = static_cast<std::size_t>(j);
        const double c = m.drives[J].coulomb;
        EXPECT_EQ(r.drives[J].coulomb, std::string(f.name) == "mjcf" ? std::max(c, 0.0) : c);
        EXPECT_EQ(r.limits[J].q_min, m.limits[J].q_min);
        EXPECT_EQ(r.limits[J].q_max, m.limits[J].q_max);
        EXPECT_EQ(r.limits[J].tau_max, m.limits[J].tau_max);
      }
    }
  }
}

TEST(ExportFormats, DriveTermsOfASimulatorFileAreUsedOnlyWhenAskedFor) {
  const RobotModel m = shippedRobots()[0].model;  // the Panda: friction on every joint
  for (const Format& f : formats()) {
    if (std::string(f.name) == "urdf") continue;  // (exid's own <exid> drives: always used)
    SCOPED_TRACE(f.name);
    exid::LoadOptions o;
    std::vector<std::string> sink;
    o.warnings = &sink;
    const RobotModel r = f.load(f.write(m), std::string("panda.") + f.name, o);
    for (const auto& d : r.drives) {
      EXPECT_EQ(d.viscous, 0.0);
      EXPECT_EQ(d.coulomb, 0.0);
      EXPECT_EQ(d.rotor_inertia, 0.0);
    }
    EXPECT_TRUE(mentions(r.notes, "dynamics_as_friction: true uses them"));
    o.urdf_dynamics_as_friction = true;
    const RobotModel u = f.load(f.write(m), std::string("panda.") + f.name, o);
    EXPECT_FALSE(mentions(u.notes, "dynamics_as_friction: true uses them"));
    EXPECT_EQ(u.drives[0].viscous, m.drives[0].viscous);
  }
}

// A hand-written MJCF using what exid's writer does not (degrees, euler sequences, default
// classes, fullinertia, joint positions off the body origin, welded bodies, axisangle, xyaxes):
// exid's model of it and MuJoCo's give the same inverse dynamics.
TEST(ExportFormats, MujocoAndExidReadTheSameHandWrittenMjcf) {
#ifndef EXID_HAVE_MUJOCO
  FAIL() << "built without MuJoCo (libmujoco-dev; scripts/install-deps.sh installs it)";
#else
  const std::string text = R"(<mujoco model="hand">
  <compiler angle="degree" eulerseq="zyx" inertiafromgeom="false" autolimits="true"/>
  <option gravity="0.5 -1 -9.7"/>
  <default>
    <joint damping="0.2" armature="0.05"/>
    <default class="wrist"><joint axis="1 0 0" range="-120 120"/></default>
  </default>
  <worldbody>
    <body name="l1" pos="0 0 0.3" euler="30 0 0">
      <joint name="j1" axis="0 0 1" range="-170 170"/>
      <inertial pos="0.02 0.01 0.1" mass="4" fullinertia="0.05 0.06 0.03 0.002 -0.001 0.003"/>
      <body name="l2" pos="0.1 0 0.2" axisangle="1 0 0 -90">
        <joint name="j2" pos="0 0 0.05" axis="0 0 1"/>
        <inertial pos="0.2 0 0" quat="0.9 0.1 0.2 0.3" mass="3" diaginertia="0.02 0.08 0.09"/>
        <body name="bracket" pos="0.4 0 0" xyaxes="0 1 0 -1 0 0">
          <inertial pos="0 0 0.02" mass="0.5" diaginertia="0.001 0.001 0.001"/>
          <body name="l3" pos="0 0 0.05" childclass="wrist">
            <joint name="j3" pos="0.01 0 0"/>
            <inertial pos="0 0 0.05" mass="1" diaginertia="0.004 0.005 0.002"/>
            <body name="l4" pos="0 0 0.1" zaxis="0 1 1">
              <joint name="j4" type="slide" axis="0 0 1" range="-0.1 0.1" class="wrist"/>
              <inertial pos="0 0.01 0.02" mass="0.7" diaginertia="0.002 0.002 0.001"/>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
)";
  // (MuJoCo diagonalises a fullinertia with its own iterative eigensolver, mju_eig3, whose
  // principal axes carry errors of about 1e-11 of the torques; with diaginertia the comparison
  // is to rounding)
  const std::string diag =
      std::regex_replace(text, std::regex("fullinertia=\"0.05 0.06 0.03 0.002 -0.001 0.003\""),
                         "diaginertia=\"0.05 0.06 0.03\"");
  ASSERT_NE(diag, text);
  for (const auto& [file, tolerance] :
       std::vector<std::pair<std::string, double>>{{diag, 1e-12}, {text, 1e-10}}) {
    std::string err;
    const MjModelPtr mm = loadMjcf("hand", file, &err);
    ASSERT_NE(mm.m, nullptr) << err;
    mm.m->opt.disableflags |= mjDSBL_FRICTIONLOSS | mjDSBL_LIMIT | mjDSBL_CONTACT;
    exid::LoadOptions o;
    o.urdf_dynamics_as_friction = true;
    const RobotModel m = exid::loadMjcfString(file, "hand.xml", o);
    ASSERT_EQ(m.dof(), 4);
    ASSERT_EQ(mm.m->nv, 4);
    EXPECT_EQ(m.gravity, Eigen::Vector3d(0.5, -1, -9.7));
    EXPECT_NEAR(m.limits[2].q_max, 120.0 * M_PI / 180.0, 1e-15);
    EXPECT_EQ(m.limits[3].q_max, 0.1);
    MjDataPtr md;
    md.d = mj_makeData(mm.m);
    auto data = exid::makeDynamicsData(m);
    std::mt19937 rng(23);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    double worst = 0.0;
    for (int k = 0; k < 50; ++k) {
      Eigen::VectorXd q(4), qd(4), qdd(4);
      for (int j = 0; j < 4; ++j) {
        q(j) = (j == 3 ? 0.1 : 2.0) * u(rng);
        qd(j) = 2.0 * u(rng);
        qdd(j) = 4.0 * u(rng);
        md.d->qpos[j] = q(j);
        md.d->qvel[j] = qd(j);
        md.d->qacc[j] = qdd(j);
      }
      mj_inverse(mm.m, md.d);
      const exid::DriveColumns cols{true, false, true, false};
      const Eigen::VectorXd tau = exid::actuatorTorque(m, *data, cols, q, qd, qdd);
      const Eigen::Map<const Eigen::VectorXd> mj(md.d->qfrc_inverse, 4);
      worst = std::max(worst,
                       (tau - mj).cwiseAbs().maxCoeff() / std::max(1.0, mj.cwiseAbs().maxCoeff()));
    }
    EXPECT_LE(worst, tolerance);
    std::printf("hand-written MJCF: exid vs MuJoCo, largest torque difference %.3g (relative)\n",
                worst);
  }
#endif
}

// ---------------------------------------------------------------- closed chains
std::vector<std::pair<std::string, RobotModel>> closedChains() {
  const std::string dir = std::string(EXID_SOURCE_DIR);
  std::vector<std::pair<std::string, RobotModel>> out;
  for (const char* name : {"fourbar", "palletizer"})
    out.emplace_back(name, exid::loadRobotFile(dir + "/robots/" + name + "/" + name + ".yaml"));
  return out;
}

/// Measured states within the limits (positions), with velocities and accelerations.
void closedState(const RobotModel& m, std::mt19937* rng, Eigen::VectorXd* qa, Eigen::VectorXd* qda,
                 Eigen::VectorXd* qdda) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const int n = m.dof();
  qa->resize(n), qda->resize(n), qdda->resize(n);
  for (int k = 0; k < n; ++k) {
    const exid::JointLimits& L = m.limits[static_cast<std::size_t>(k)];
    const double lo = std::max(L.q_min, -M_PI), hi = std::min(L.q_max, M_PI);
    (*qa)[k] = lo + (hi - lo) * u(*rng);
    (*qda)[k] = 2.0 * (2 * u(*rng) - 1);
    (*qdda)[k] = 5.0 * (2 * u(*rng) - 1);
  }
}

// A closed chain exported as URDF (<exid><loop>), MJCF (connect constraints, joint `ref` at the
// reference configuration, motors on the actuated joints) and SDF (cut joints,
// <exid:closed_chain>) comes back with the same loops, actuated joints and torques.
TEST(ExportFormats, ClosedChainsComeBackWithTheSameTorques) {
  std::mt19937 rng(29);
  for (const auto& [name, m] : closedChains()) {
    ASSERT_TRUE(m.hasLoops());
    auto d0 = exid::makeDynamicsData(m);
    for (const Format& f : formats()) {
      SCOPED_TRACE(name + " " + f.name);
      const std::string text = f.write(m);
      exid::LoadOptions o;
      o.urdf_dynamics_as_friction = true;
      RobotModel r = f.load(text, name + "." + f.name, o);
      ASSERT_TRUE(r.hasLoops());
      ASSERT_EQ(r.dof(), m.dof());
      ASSERT_EQ(r.numJoints(), m.numJoints());
      for (int k = 0; k < m.dof(); ++k)  // (the same joints; the tree's order may differ)
        EXPECT_EQ(r.bodies[static_cast<std::size_t>(r.actuatedJoint(k))].joint_name,
                  m.bodies[static_cast<std::size_t>(m.actuatedJoint(k))].joint_name);
      EXPECT_EQ(r.closed.loops.size(), m.closed.loops.size());
      for (std::size_t l = 0; l < m.closed.loops.size(); ++l)
        EXPECT_EQ(r.closed.loops[l].kind, m.closed.loops[l].kind);
      if (std::string(f.name) == "sdf") r.gravity = m.gravity;
      auto d1 = exid::makeDynamicsData(r);
      const exid::DriveColumns cols{f.rotor, f.transmission, true, f.transmission};
      double worst = 0.0;
      for (int k = 0; k < 30; ++k) {
        Eigen::VectorXd qa, qda, qdda;
        closedState(m, &rng, &qa, &qda, &qdda);
        const Eigen::VectorXd t0 = exid::actuatorTorque(m, *d0, cols, qa, qda, qdda);
        const Eigen::VectorXd t1 = exid::actuatorTorque(r, *d1, cols, qa, qda, qdda);
        worst = std::max(worst,
                         (t1 - t0).cwiseAbs().maxCoeff() / std::max(1.0, t0.cwiseAbs().maxCoeff()));
      }
      EXPECT_LE(worst, 1e-12);
      std::printf("%s via %s: largest actuated torque difference %.3g (relative)\n", name.c_str(),
                  f.name, worst);
    }
  }
}

// MuJoCo and libsdformat read the closed chains: MuJoCo's connect constraints hold (to rounding)
// at configurations exid assembles, in exid's own joint coordinates (MuJoCo's qpos, thanks to the
// joints' `ref`); libsdformat loads the SDF with its cut joints and exid's element.
TEST(ExportFormats, ConsumersReadTheClosedChains) {
#if !defined(EXID_HAVE_MUJOCO) || !defined(EXID_HAVE_SDFORMAT)
  FAIL() << "built without MuJoCo or libsdformat (scripts/install-deps.sh installs them)";
#else
  std::mt19937 rng(31);
  for (const auto& [name, m] : closedChains()) {
    SCOPED_TRACE(name);
    std::string err;
    const MjModelPtr mm = loadMjcf(name, exid::writeMjcf(m), &err);
    ASSERT_NE(mm.m, nullptr) << err;
    ASSERT_EQ(mm.m->nq, m.numJoints());
    ASSERT_EQ(mm.m->nu, m.dof());
    MjDataPtr md;
    md.d = mj_makeData(mm.m);
    double worst = 0.0;
    for (int k = 0; k < 20; ++k) {
      Eigen::VectorXd qa, qda, qdda, q;
      closedState(m, &rng, &qa, &qda, &qdda);
      exid::closedChainState(m, qa, nullptr, nullptr, &q, nullptr, nullptr, nullptr, nullptr);
      for (int j = 0; j < m.numJoints(); ++j) {
        const int id =
            mj_name2id(mm.m, mjOBJ_JOINT, m.bodies[static_cast<std::size_t>(j)].joint_name.c_str());
        ASSERT_GE(id, 0);
        md.d->qpos[mm.m->jnt_qposadr[id]] = q(j);
      }
      mj_forward(mm.m, md.d);
      int rows = 0;
      for (int e = 0; e < md.d->nefc; ++e)
        if (md.d->efc_type[e] == mjCNSTR_EQUALITY) {
          worst = std::max(worst, std::abs(md.d->efc_pos[e]));
          ++rows;
        }
      EXPECT_EQ(rows, 3 * static_cast<int>(2 * m.closed.loops.size()));  // two connects each
      // and away from the mechanism's configurations the constraints do not hold
      if (k == 0) {
        int passive = 0;
        while (std::count(m.closed.actuated.begin(), m.closed.actuated.end(), passive)) ++passive;
        const int id = mj_name2id(mm.m, mjOBJ_JOINT,
                                  m.bodies[static_cast<std::size_t>(passive)].joint_name.c_str());
        md.d->qpos[mm.m->jnt_qposadr[id]] += 0.3;
        mj_forward(mm.m, md.d);
        double off = 0.0;
        for (int e = 0; e < md.d->nefc; ++e)
          if (md.d->efc_type[e] == mjCNSTR_EQUALITY)
            off = std::max(off, std::abs(md.d->efc_pos[e]));
        EXPECT_GT(off, 1e-3);
      }
    }
    EXPECT_LE(worst, 1e-12);
    std::printf("%s: MuJoCo's loop constraints at exid's assembled configurations: %.3g m\n",
                name.c_str(), worst);
    sdf::Root root;
    const auto errors = root.LoadSdfString(exid::writeSdf(m));
    for (const auto& e : errors) ADD_FAILURE() << e.Message();
    ASSERT_NE(root.Model(), nullptr);
    EXPECT_EQ(root.Model()->JointCount(),
              static_cast<uint64_t>(m.numJoints() + m.closed.loops.size() + 1));
  }
#endif
}

}  // namespace
