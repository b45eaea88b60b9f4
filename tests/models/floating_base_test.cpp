// The `floating_base` observation model and the `simulate` experiment on the shipped
// floating-base humanoid: noise-free identification to 1e-9 with every estimator that applies,
// noisy within the estimator's own standard deviations, the base rows alone (no joint torque),
// and the refusals of what needs a fixed base. The dataset functions carry the floating-base
// signals.
#include "exid/floating_base.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <tuple>

#include "exid/exid.hpp"
#include "exid/io.hpp"
#include "exid/registry.hpp"
#include "exid/tables.hpp"
#include "model_test_util.hpp"

namespace {

const char* kContact = "contact_link: l_shank, contact_pose: [0.03, 0, -0.36, 0, 0, 0]";
const char* kModel = "contact_links: [l_shank], contact_poses: [0.03, 0, -0.36, 0, 0, 0]";

std::shared_ptr<const exid::RobotModel> humanoid() { return exid_test::robot("humanoid"); }

exid::Dataset simulated(const std::string& extra = "", std::uint64_t seed = 7) {
  return mtest::simulate(humanoid(),
                         fmt::format("{{duration_s: 6, sample_period_s: 0.01, {}{}}}", kContact,
                                     extra.empty() ? "" : ", " + extra),
                         seed);
}

// The largest error relative to the parameter vector's scale: max_i |th_i - tr_i| / max_i |tr_i|
// (a product of inertia of 1e-5 kg m^2 beside a mass of 19 kg is not asked for nine digits of
// its own: roundoff of the 300 N rows times cond(W) ~ 1e5 is 1e-13 absolute).
double scaledErr(const Eigen::VectorXd& th, const Eigen::VectorXd& tr) {
  return (th - tr).cwiseAbs().maxCoeff() / tr.cwiseAbs().maxCoeff();
}

// The humanoid with drives on its ten joints: rotor inertia, Coulomb, viscous friction and an
// offset of plausible sizes, different per joint (the shipped one has none).
exid::Drive driveOf(int j) {
  exid::Drive D;
  D.rotor_inertia = 0.05 + 0.01 * j;
  D.coulomb = 1.5 + 0.2 * j;
  D.viscous = 0.8 + 0.1 * j;
  D.offset = 0.3 - 0.07 * j;
  return D;
}
std::shared_ptr<const exid::RobotModel> humanoidWithDrives() {
  auto r = std::make_shared<exid::RobotModel>(*humanoid());
  r->drives.assign(static_cast<std::size_t>(r->dof()), exid::Drive{});
  for (int j = 0; j < r->dof(); ++j) r->drives[static_cast<std::size_t>(j)] = driveOf(j);
  return r;
}
// The same drives as a URDF <exid> extension of the shipped humanoid, for a study.
std::string drivesExtension() {
  const std::shared_ptr<const exid::RobotModel> r = humanoid();
  std::string xml = "<exid>\n";
  for (int j = 0; j < r->dof(); ++j) {
    const exid::Drive D = driveOf(j);
    xml += fmt::format(
        "  <drive joint=\"{}\" rotor_inertia=\"{:.17g}\" coulomb=\"{:.17g}\" "
        "viscous=\"{:.17g}\" offset=\"{:.17g}\"/>\n",
        r->bodies[static_cast<std::size_t>(j)].joint_name, D.rotor_inertia, D.coulomb, D.viscous,
        D.offset);
  }
  return xml + "</exid>\n";
}
const char* kDrives = "rotor_inertia: true, coulomb: true, viscous: true, offset: true";

}  // namespace

TEST(FloatingBaseModel, SimulatedDataHoldTheEquationsOfMotion) {
  const exid::Dataset d = simulated();
  ASSERT_EQ(d.base.cols(), 9);
  ASSERT_EQ(d.contact.cols(), 6);
  ASSERT_EQ(d.tau.cols(), 10);
  // at rest-like start the contact carries about the weight: |f| of the order of 33 kg g
  EXPECT_GT(d.contact.leftCols(3).rowwise().norm().maxCoeff(), 100.0);
  // gravity is in f: the base's specific force has a magnitude near g on average
  EXPECT_NEAR(d.base.rightCols(3).rowwise().norm().mean(), 9.81, 3.0);
  auto m = mtest::model("floating_base", std::string("{") + kModel + "}", humanoid());
  const exid::Rows r = m->fullRows(d, mtest::context());
  EXPECT_EQ(r.W.rows(), d.size() * 16);
  const double res = (r.W * m->fullNominal() - r.y).cwiseAbs().maxCoeff();
  EXPECT_LT(res, 1e-10 * r.y.cwiseAbs().maxCoeff()) << res;
}

// Noise-free: the base parameters to 1e-9 with batch_ls, wls, rls, consistent_ls and
// filtered_ls (which filters the rows and the measurements alike).
TEST(FloatingBaseModel, NoiseFreeIdentificationEveryEstimator) {
  const exid::Dataset d = simulated();
  auto m = mtest::model("floating_base", std::string("{") + kModel + "}", humanoid());
  const Eigen::VectorXd truth = m->baseNominal();
  std::printf("humanoid: %d standard, %d base parameters (all rows)\n",
              static_cast<int>(m->fullNames().size()), m->numBase());
  // (rls: the prior P0 = p0 I pulls by ~ (W^T W)^-1 theta / p0; filtered_ls with the position
  // filter off filters W and y alike, so noise-free linear data stay exact)
  for (const auto& [est, params] : std::vector<std::pair<std::string, std::string>>{
           {"batch_ls", "{}"},
           {"wls", "{}"},
           {"rls", "{p0: 1e12}"},
           {"consistent_ls", "{}"},
           {"filtered_ls", "{cutoff_hz: 0, decimation: 5}"}}) {
    const exid::Estimate e =
        exid_test::create<exid::Estimator>(est, params)->estimate(*m, d, nullptr, mtest::context());
    const double w = scaledErr(e.value, truth);
    std::printf("  %s: largest error / largest parameter %.2e, relative norm %.2e\n", est.c_str(),
                w, (e.value - truth).norm() / truth.norm());
    EXPECT_LT(w, 1e-9) << est;
  }
}

// The base rows alone (no joint torque in the dataset at all) identify the same number of base
// parameters as all rows (the count of tests/robots/floating_robots_test), exactly.
TEST(FloatingBaseModel, BaseRowsAloneNeedNoTorque) {
  exid::Dataset d = simulated();
  d.tau.resize(0, 0);
  auto mb = mtest::model("floating_base", std::string("{rows: base, ") + kModel + "}", humanoid());
  auto ma = mtest::model("floating_base", std::string("{") + kModel + "}", humanoid());
  auto mj =
      mtest::model("floating_base", std::string("{rows: joints, ") + kModel + "}", humanoid());
  EXPECT_EQ(mb->numBase(), ma->numBase());
  EXPECT_LT(mj->numBase(), ma->numBase());
  const mtest::Recovery r = mtest::recover(*mb, d);
  mtest::print("base rows", r);
  EXPECT_LT(r.est_rel, 1e-9);
  const exid::Estimate e = exid_test::create<exid::Estimator>("batch_ls", "{}")
                               ->estimate(*mb, d, nullptr, mtest::context());
  EXPECT_LT(scaledErr(e.value, mb->baseNominal()), 1e-9);
  // the joint rows need the torque: refused without it
  EXPECT_THROW(mj->fullRows(d, mtest::context()), exid::Error);
  EXPECT_THROW(ma->fullRows(d, mtest::context()), exid::Error);
}

// Noisy torques and contact wrenches: the estimate within 4 of the estimator's own standard
// deviations for (nearly) every parameter, and the noise-free one far closer.
TEST(FloatingBaseModel, NoisyWithinSigma) {
  const exid::Dataset d =
      simulated("noise_tau_Nm: 0.3, noise_contact: [1.0, 0.1], noise_base: [0, 0, 0]", 21);
  auto m = mtest::model("floating_base", std::string("{") + kModel + "}", humanoid());
  const Eigen::VectorXd truth = m->baseNominal();
  for (const char* est : {"batch_ls", "wls"}) {
    const exid::Estimate e =
        exid_test::create<exid::Estimator>(est, "{}")->estimate(*m, d, nullptr, mtest::context());
    int outside = 0;
    double worst_z = 0;
    for (Eigen::Index i = 0; i < truth.size(); ++i) {
      const double z = std::abs(e.value[i] - truth[i]) / e.std[i];
      worst_z = std::max(worst_z, z);
      outside += z > 4.0;
    }
    std::printf("  %s noisy: sigma %.3g, worst |error|/std %.2f, %d of %d beyond 4 std\n", est,
                e.sigma, worst_z, outside, static_cast<int>(truth.size()));
    EXPECT_EQ(outside, 0) << est;
    EXPECT_GT(worst_z, 0.05) << est;  // noise did enter
  }
}

// Joint friction and drive columns on the joint rows: the simulated plant's drive terms (its
// robot's drives) identify noise-free to 1e-9 with batch_ls; the rigid-body model alone does not
// fit those data.
TEST(FloatingBaseModel, JointFrictionIdentifiesNoiseFree) {
  const auto r = humanoidWithDrives();
  const exid::Dataset d =
      mtest::simulate(r, fmt::format("{{duration_s: 6, sample_period_s: 0.01, {}}}", kContact), 7);
  auto m = mtest::model("floating_base", fmt::format("{{{}, {}}}", kModel, kDrives), r);
  const std::vector<std::string> names = m->fullNames();
  ASSERT_EQ(static_cast<int>(names.size()), 110 + 4 * 10);
  EXPECT_EQ(names[110], "Ia1");
  EXPECT_EQ(names[111], "Fc1");
  EXPECT_EQ(names[112], "Fv1");
  EXPECT_EQ(names[113], "OFF1");
  EXPECT_EQ(names[149], "OFF10");
  EXPECT_EQ(m->fullNominal()[111], r->drives[0].coulomb);
  ASSERT_TRUE(d.facts.simulated.has_value());
  EXPECT_EQ(m->fullTruth(*d.facts.simulated), m->fullNominal());
  const exid::Rows rows = m->fullRows(d, mtest::context());
  const double res = (rows.W * m->fullNominal() - rows.y).cwiseAbs().maxCoeff();
  EXPECT_LT(res, 1e-10 * rows.y.cwiseAbs().maxCoeff()) << res;
  const exid::Estimate e = exid_test::create<exid::Estimator>("batch_ls", "{}")
                               ->estimate(*m, d, nullptr, mtest::context());
  const double err = scaledErr(e.value, m->baseNominal());
  std::printf("humanoid with drives: %d base parameters, batch_ls largest error / largest %.2e\n",
              m->numBase(), err);
  EXPECT_LT(err, 1e-9);
  EXPECT_EQ(m->numBase(), 80 + 40);  // every drive column is a base column
  // without the drive columns the same data are not fitted: the drive terms are in tau
  auto rigid = mtest::model("floating_base", std::string("{") + kModel + "}", r);
  const exid::Rows rr = rigid->fullRows(d, mtest::context());
  EXPECT_GT((rr.W * rigid->fullNominal() - rr.y).cwiseAbs().maxCoeff(), 0.1);
  // drive_terms: false: the plant has none, the truth's drive columns are zero
  const exid::Dataset d0 = mtest::simulate(
      r, fmt::format("{{duration_s: 2, sample_period_s: 0.01, drive_terms: false, {}}}", kContact),
      7);
  const Eigen::VectorXd t0 = m->fullTruth(*d0.facts.simulated);
  EXPECT_EQ(t0.tail(40), Eigen::VectorXd::Zero(40));
  const exid::Rows r0 = m->fullRows(d0, mtest::context());
  EXPECT_LT((r0.W * t0 - r0.y).cwiseAbs().maxCoeff(), 1e-10 * r0.y.cwiseAbs().maxCoeff());
}

// A joint's friction acts between its two bodies: the base rows are the same numbers with and
// without the friction options (and zero in the friction columns); only the joint rows carry
// them.
TEST(FloatingBaseModel, FrictionLeavesTheBaseRowsUnchanged) {
  const auto r = humanoidWithDrives();
  const exid::Dataset d =
      mtest::simulate(r, fmt::format("{{duration_s: 2, sample_period_s: 0.01, {}}}", kContact), 7);
  auto plain = mtest::model("floating_base", std::string("{") + kModel + "}", r);
  auto fric = mtest::model(
      "floating_base",
      fmt::format("{{{}, rotor_inertia: true, viscous: true, offset: true, coulomb: true, "
                  "coulomb_smoothing_rad_s: [0.05]}}",
                  kModel),
      r);
  auto load = mtest::model("floating_base", fmt::format("{{{}, coulomb_load: true}}", kModel), r);
  const exid::Rows a = plain->fullRows(d, mtest::context());
  for (const auto* m : {fric.get(), load.get()}) {
    const exid::Rows b = m->fullRows(d, mtest::context());
    ASSERT_EQ(b.W.rows(), a.W.rows());
    ASSERT_GT(b.W.cols(), a.W.cols());
    EXPECT_EQ(b.y, a.y);
    double joint_max = 0.0;
    for (int k = 0; k < d.size(); ++k) {
      const Eigen::Index base = 16 * k;
      EXPECT_EQ(b.W.block(base, 0, 6, 110), a.W.block(base, 0, 6, 110)) << k;
      EXPECT_EQ(b.W.block(base, 110, 6, b.W.cols() - 110).cwiseAbs().maxCoeff(), 0.0) << k;
      EXPECT_EQ(b.W.block(base + 6, 0, 10, 110), a.W.block(base + 6, 0, 10, 110)) << k;
      joint_max =
          std::max(joint_max, b.W.block(base + 6, 110, 10, b.W.cols() - 110).cwiseAbs().maxCoeff());
    }
    EXPECT_GT(joint_max, 0.5);  // the joint rows do carry the columns
  }
  // rows: base has no joint row for them: refused, naming why
  try {
    mtest::model("floating_base", fmt::format("{{rows: base, {}, viscous: true}}", kModel), r);
    ADD_FAILURE() << "no refusal";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("rows: base has no joint rows"), std::string::npos)
        << e.what();
  }
}

// The friction columns are the differential model's: on the same joint motion (the humanoid's
// tree with its base held fixed) the columns of the same names are the same numbers, and by hand
// Fc3 = tanh(qd3 / eps), FcL3 = |tau3| sign(qd3); the width's derivative is exact.
TEST(FloatingBaseModel, FrictionColumnsAreTheDifferentialModels) {
  const auto r = humanoidWithDrives();
  const exid::Dataset d =
      mtest::simulate(r, fmt::format("{{duration_s: 1, sample_period_s: 0.01, {}}}", kContact), 7);
  auto fixed = std::make_shared<exid::RobotModel>(*r);
  fixed->floating_base = false;
  const double eps = 0.07;
  const std::string tanh_opts = fmt::format(
      "rotor_inertia: true, viscous: true, offset: true, coulomb: true, "
      "coulomb_smoothing_rad_s: [{}]",
      eps);
  for (const std::string& opts : {tanh_opts, std::string("coulomb_load: true, viscous: true")}) {
    auto fm = mtest::model("floating_base", fmt::format("{{{}, {}}}", kModel, opts), r);
    auto dm =
        mtest::model("differential",
                     opts == tanh_opts ? "{" + opts + "}"
                                       : "{rotor_inertia: false, coulomb: false, " + opts + "}",
                     fixed);
    const exid::Rows fr = fm->fullRows(d, mtest::context());
    const exid::Rows dr = dm->fullRows(d, mtest::context());
    const std::vector<std::string> fn = fm->fullNames(), dn = dm->fullNames();
    int compared = 0;
    for (std::size_t c = 110; c < fn.size(); ++c) {
      const auto it = std::find(dn.begin(), dn.end(), fn[c]);
      ASSERT_NE(it, dn.end()) << fn[c];
      const auto dc = static_cast<Eigen::Index>(it - dn.begin());
      for (int k = 0; k < d.size(); ++k)
        for (int j = 0; j < 10; ++j)
          ASSERT_EQ(fr.W(16 * k + 6 + j, static_cast<Eigen::Index>(c)), dr.W(10 * k + j, dc))
              << fn[c] << " sample " << k << " joint " << j;
      ++compared;
    }
    EXPECT_EQ(compared, static_cast<int>(fn.size()) - 110);
    // by hand, joint 3
    const std::vector<std::string>::const_iterator c3 =
        std::find(fn.begin(), fn.end(), opts == tanh_opts ? "Fc3" : "FcL3");
    ASSERT_NE(c3, fn.end());
    const auto c = static_cast<Eigen::Index>(c3 - fn.begin());
    for (int k = 0; k < d.size(); ++k) {
      const double v = d.qd(k, 2);
      const double want =
          opts == tanh_opts ? std::tanh(v / eps) : std::abs(d.tau(k, 2)) * (v > 0 ? 1.0 : -1.0);
      EXPECT_NEAR(fr.W(16 * k + 8, c), want, 1e-15 * std::max(1.0, std::abs(want))) << k;
    }
  }
  // d/deps of the Fc columns: exact (against a central difference)
  auto fm = mtest::model("floating_base", fmt::format("{{{}, {}}}", kModel, tanh_opts), r);
  const std::vector<exid::NonlinearParameter> nl = fm->nonlinearParameters();
  ASSERT_EQ(nl.size(), 10u);
  EXPECT_EQ(nl[2].name, "eps3");
  EXPECT_EQ(nl[2].value, eps);
  Eigen::VectorXd eta = Eigen::VectorXd::Constant(10, eps);
  Eigen::MatrixXd dW;
  fm->fullRowsAt(d, eta, &dW, mtest::context());
  ASSERT_EQ(dW.cols(), 10);
  const double h = 1e-6;
  eta[2] = eps + h;
  const exid::Rows up = fm->fullRowsAt(d, eta, nullptr, mtest::context());
  eta[2] = eps - h;
  const exid::Rows dn = fm->fullRowsAt(d, eta, nullptr, mtest::context());
  const Eigen::VectorXd fd = (up.W.col(nl[2].columns[0]) - dn.W.col(nl[2].columns[0])) / (2 * h);
  EXPECT_LT((fd - dW.col(2)).cwiseAbs().maxCoeff(), 1e-6 * dW.col(2).cwiseAbs().maxCoeff());
  EXPECT_GT(dW.col(2).cwiseAbs().maxCoeff(), 1.0);
  EXPECT_EQ(dW.col(3).segment(8, 1)[0], 0.0);  // eps4 moves joint 4's rows only
}

// The asymmetric, smoothed Coulomb and Stribeck columns are the differential model's too: the
// same numbers under the same names (FcP, FcN, Fs) on the same joint motion, the same nonlinear
// parameters (eps_j moving the joint's three columns, vs_j its Fs column) and the same
// derivatives; vs's derivative against a central difference.
TEST(FloatingBaseModel, NonlinearFrictionColumnsAreTheDifferentialModels) {
  const auto r = humanoidWithDrives();
  const exid::Dataset d =
      mtest::simulate(r, fmt::format("{{duration_s: 1, sample_period_s: 0.01, {}}}", kContact), 7);
  auto fixed = std::make_shared<exid::RobotModel>(*r);
  fixed->floating_base = false;
  const std::string opts =
      "rotor_inertia: true, viscous: true, offset: true, coulomb: true, coulomb_asymmetric: "
      "true, coulomb_smoothing_rad_s: [0.07], stribeck: true, stribeck_velocity_rad_s: [0.3], "
      "stribeck_exponent: 1.5";
  auto fm = mtest::model("floating_base", fmt::format("{{{}, {}}}", kModel, opts), r);
  auto dm = mtest::model("differential", "{" + opts + "}", fixed);
  const std::vector<exid::NonlinearParameter> fnl = fm->nonlinearParameters(),
                                              dnl = dm->nonlinearParameters();
  ASSERT_EQ(fnl.size(), 20u);
  ASSERT_EQ(dnl.size(), 20u);
  const std::vector<std::string> fn = fm->fullNames(), dn = dm->fullNames();
  for (std::size_t k = 0; k < fnl.size(); ++k) {
    EXPECT_EQ(fnl[k].name, dnl[k].name);
    EXPECT_EQ(fnl[k].value, dnl[k].value);
    ASSERT_EQ(fnl[k].columns.size(), dnl[k].columns.size()) << fnl[k].name;
    for (std::size_t c = 0; c < fnl[k].columns.size(); ++c)
      EXPECT_EQ(fn[static_cast<std::size_t>(fnl[k].columns[c])],
                dn[static_cast<std::size_t>(dnl[k].columns[c])])
          << fnl[k].name;
  }
  EXPECT_EQ(fnl[4].name, "eps3");
  EXPECT_EQ(fnl[5].name, "vs3");
  EXPECT_EQ(fn[static_cast<std::size_t>(fnl[5].columns[0])], "Fs3");
  Eigen::VectorXd eta(20);
  for (int k = 0; k < 20; ++k) eta[k] = fnl[static_cast<std::size_t>(k)].value * (1.0 + 0.1 * k);
  Eigen::MatrixXd fdW, ddW;
  const exid::Rows fr = fm->fullRowsAt(d, eta, &fdW, mtest::context());
  const exid::Rows dr = dm->fullRowsAt(d, eta, &ddW, mtest::context());
  ASSERT_EQ(fdW.cols(), ddW.cols());
  ASSERT_EQ(fdW.cols(), 40);  // 10 widths of 3 columns, 10 velocities of one
  int compared = 0;
  for (const char* name : {"FcP", "FcN", "Fs"})
    for (int j = 1; j <= 10; ++j) {
      const std::string nm = name + std::to_string(j);
      const auto fc = std::find(fn.begin(), fn.end(), nm), dc = std::find(dn.begin(), dn.end(), nm);
      ASSERT_NE(fc, fn.end()) << nm;
      ASSERT_NE(dc, dn.end()) << nm;
      for (int k = 0; k < d.size(); ++k)
        for (int i = 0; i < 10; ++i)
          ASSERT_EQ(fr.W(16 * k + 6 + i, fc - fn.begin()), dr.W(10 * k + i, dc - dn.begin()))
              << nm << " sample " << k << " joint " << i;
      ++compared;
    }
  EXPECT_EQ(compared, 30);
  for (Eigen::Index c = 0; c < fdW.cols(); ++c)
    for (int k = 0; k < d.size(); ++k)
      for (int i = 0; i < 10; ++i) {
        ASSERT_EQ(fdW(16 * k + 6 + i, c), ddW(10 * k + i, c)) << c;
        ASSERT_EQ(fdW(16 * k + i % 6, c), 0.0) << c;  // the base rows: no friction
      }
  // vs3's column against a central difference
  const double h = 1e-6;
  Eigen::VectorXd up = eta, dn2 = eta;
  up[5] += h;
  dn2[5] -= h;
  const Eigen::Index col = fnl[5].columns[0];
  const Eigen::VectorXd fd = (fm->fullRowsAt(d, up, nullptr, mtest::context()).W.col(col) -
                              fm->fullRowsAt(d, dn2, nullptr, mtest::context()).W.col(col)) /
                             (2 * h);
  const Eigen::Index dvs3 = 11;  // after eps1 (3 columns), vs1 (1), eps2 (3), vs2 (1), eps3 (3)
  EXPECT_LT((fd - fdW.col(dvs3)).cwiseAbs().maxCoeff(), 1e-6 * fdW.col(dvs3).cwiseAbs().maxCoeff());
  EXPECT_GT(fdW.col(dvs3).cwiseAbs().maxCoeff(), 0.1);
}

TEST(FloatingBaseModel, RefusalsNameWhy) {
  const auto r = humanoid();
  auto msg = [](auto&& f) {
    try {
      f();
    } catch (const exid::Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  // a fixed-base model
  std::string m = msg([&] { mtest::model("differential", "{}", r); });
  EXPECT_NE(m.find("floating base"), std::string::npos) << m;
  EXPECT_NE(m.find("differential"), std::string::npos) << m;
  // the floating model on a fixed-base robot
  m = msg([&] { mtest::model("floating_base", "{}", mtest::robot("puma560")); });
  EXPECT_NE(m.find("fixed base"), std::string::npos) << m;
  // the simulation needs the contact that balances the base rows
  m = msg([&] { mtest::simulate(r, "{duration_s: 1}"); });
  EXPECT_NE(m.find("contact_link"), std::string::npos) << m;
  m = msg([&] { mtest::simulate(r, "{duration_s: 1, contact_link: l_foot}"); });
  EXPECT_NE(m.find("unknown link 'l_foot'"), std::string::npos) << m;
  // contacts of the model and of the data must agree
  const exid::Dataset d = simulated();
  auto m2 = mtest::model("floating_base", "{contact_links: [l_shank, r_shank]}", r);
  m = msg([&] { m2->fullRows(d, mtest::context()); });
  EXPECT_NE(m.find("declares 2 contact(s)"), std::string::npos) << m;
  // the friction options' refusals
  m = msg([&] {
    mtest::model("floating_base", fmt::format("{{{}, coulomb_smoothing_rad_s: [0.1]}}", kModel), r);
  });
  EXPECT_NE(m.find("need coulomb: true"), std::string::npos) << m;
  for (const auto& [opts, why] : std::vector<std::pair<std::string, std::string>>{
           {"coulomb_asymmetric: true", "need coulomb: true"},
           {"coulomb: true, stribeck: true", "needs stribeck_velocity_rad_s"},
           {"coulomb: true, stribeck_velocity_rad_s: [0.3]", "given but stribeck is false"},
           {"stribeck_exponent: 1.5", "stribeck_exponent is given but stribeck is false"},
           {"stribeck: true, stribeck_velocity_rad_s: [0]", "0 is not a positive velocity"},
           {"stribeck: true, stribeck_velocity_rad_s: [0.3, 0.2]",
            "stribeck_velocity_rad_s: 2 values given for robot 'humanoid' of 10 joints"}}) {
    m = msg([&] {
      mtest::model("floating_base", fmt::format("{{{}, {}}}", kModel, opts), r)
          ->nonlinearParameters();
    });
    EXPECT_NE(m.find(why), std::string::npos) << opts << ": " << m;
  }
  m = msg([&] {
    mtest::model("floating_base",
                 fmt::format("{{{}, coulomb: true, coulomb_load: true, "
                             "coulomb_smoothing_rad_s: [0.1]}}",
                             kModel),
                 r);
  });
  EXPECT_NE(m.find("not combined with coulomb_smoothing_rad_s"), std::string::npos) << m;
  m = msg([&] {
    mtest::model("floating_base",
                 fmt::format("{{{}, coulomb: true, coulomb_smoothing_rad_s: [0.1, 0.2]}}", kModel),
                 r);
  });
  EXPECT_NE(m.find("2 values given for robot 'humanoid' of 10 joints"), std::string::npos) << m;
  m = msg([&] {
    mtest::model("floating_base",
                 fmt::format("{{{}, coulomb: true, coulomb_smoothing_rad_s: [-0.1]}}", kModel), r);
  });
  EXPECT_NE(m.find("-0.1 is not a positive width"), std::string::npos) << m;
  // without the columns they fit, varpro and gains_ls refuse the floating model, saying why
  auto rigid = mtest::model("floating_base", std::string("{") + kModel + "}", r);
  auto fitted =
      mtest::model("floating_base",
                   fmt::format("{{{}, coulomb: true, coulomb_smoothing_rad_s: [0.1]}}", kModel), r);
  const exid::Dataset dd = simulated();
  for (const auto& [est, what] : std::vector<std::pair<std::string, std::string>>{
           {"varpro", "has no nonlinear parameter"},
           {"gains_ls", "has no column of the recorded torque"}}) {
    m = msg([&] {
      exid_test::create<exid::Estimator>(est, "{}")->estimate(*rigid, dd, nullptr,
                                                              mtest::context());
    });
    EXPECT_NE(m.find(what), std::string::npos) << est << ": " << m;
  }
  m = msg([&] {
    exid_test::create<exid::Estimator>("gains_ls", "{}")
        ->estimate(*fitted, dd, nullptr, mtest::context());
  });
  EXPECT_NE(m.find("has no column of the recorded torque"), std::string::npos) << m;
  // the closed-loop estimators (tests/models/floating_loop_test.cpp) simulate the joints from
  // the joint rows on the recorded base motion: the base rows alone have none, a recording
  // without base motion has nothing to run on; the torque-driven loop fits positions, which the
  // base rows do not measure (tests/models/floating_open_test.cpp: with rows: joints it runs)
  auto fm = mtest::model("floating_base", std::string("{") + kModel + "}", r);
  auto fb = mtest::model("floating_base", std::string("{rows: base, ") + kModel + "}", r);
  exid::Dataset no_base = d;
  no_base.base.resize(0, 0);
  for (const char* est : {"didim", "iv"}) {
    auto e = exid_test::create<exid::Estimator>(
        est, "{reference_file: reference.csv, kp_Nm_per_rad: [100], kd_Nm_s_per_rad: [10]}");
    m = msg([&] { e->estimate(*fb, d, nullptr, mtest::context()); });
    EXPECT_NE(m.find("needs them (rows: all or joints, not base)"), std::string::npos)
        << est << ": " << m;
    m = msg([&] { e->estimate(*fm, no_base, nullptr, mtest::context()); });
    EXPECT_NE(m.find("runs on the recorded base motion: the recording"), std::string::npos)
        << est << ": " << m;
  }
  m = msg([&] {
    exid_test::create<exid::Estimator>("didim", "{loop: open, window_s: 0.2, output: position}")
        ->estimate(*fm, d, nullptr, mtest::context());
  });
  EXPECT_NE(m.find("would fit positions and wrenches together"), std::string::npos) << m;
}

// slice, resample, join, materialize and the recording's decimation carry the base motion and
// the contact wrenches.
TEST(FloatingBaseModel, DatasetFunctionsCarryTheFloatingSignals) {
  exid::Dataset d = simulated();
  const exid::Dataset s = exid::sliceDataset(d, 10, 20);
  ASSERT_EQ(s.base.rows(), 10);
  ASSERT_EQ(s.contact.rows(), 10);
  EXPECT_EQ(s.base.row(0), d.base.row(10));
  EXPECT_EQ(s.contact.row(9), d.contact.row(19));
  const exid::Dataset u = exid::resampleUniform(d, 50.0, "test");
  ASSERT_EQ(u.base.cols(), 9);
  ASSERT_EQ(u.contact.cols(), 6);
  EXPECT_EQ(u.base.rows(), u.size());
  EXPECT_LT((u.base.row(1) - d.base.row(2)).cwiseAbs().maxCoeff(), 1e-9);
  d.facts.simulated.reset();
  exid::Dataset a = exid::sliceDataset(d, 0, 100), b = exid::sliceDataset(d, 100, 200);
  const exid::Dataset j = exid::joinParts({a, b}, "test");
  ASSERT_EQ(j.base.rows(), 200);
  ASSERT_EQ(j.contact.rows(), 200);
  EXPECT_EQ(j.contact.row(150), d.contact.row(150));
  // a part without the floating signals cannot be joined to one with them
  b.base.resize(0, 0);
  EXPECT_THROW(exid::joinParts({a, b}, "test"), exid::Error);
  EXPECT_EQ(exid::materialize(d).base, d.base);
  EXPECT_EQ(d.samples().base, d.base);
}

// Whole studies: the shipped example runs (noisy, wls) with verdict ok, and the same study
// noise-free identifies the base parameters to 1e-9 with batch_ls, wls, rls, filtered_ls and
// consistent_ls, and with the base rows alone.
TEST(FloatingBaseModel, StudiesIdentifyTheHumanoid) {
  const exid::StudyOutcome ex = exid::runStudyFile(
      std::string(EXID_SOURCE_DIR) + "/examples/floating_humanoid.yaml", exid_test::registry());
  ASSERT_TRUE(ex.ok) << ex.message;
  EXPECT_EQ(ex.verdict, "ok");
  const double noisy = ex.summary.find("identification")->find("param_rel_err")->asDouble();
  std::printf("example study (noisy, wls): param_rel_err %.3g\n", noisy);
  EXPECT_LT(noisy, 0.1);
  for (const auto& [est, params, rows] :
       std::vector<std::tuple<std::string, std::string, std::string>>{
           {"batch_ls", "{}", "all"},
           {"wls", "{}", "all"},
           {"rls", "{p0: 1e12}", "all"},
           {"filtered_ls", "{cutoff_hz: 0, decimation: 5}", "all"},
           {"consistent_ls", "{}", "all"},
           {"batch_ls", "{}", "base"}}) {
    const std::string yaml = fmt::format(
        R"(name: floating_noise_free
seed: 3
robot: {{type: humanoid}}
model: {{type: floating_base, params: {{rows: {}, {}}}}}
experiment: {{type: simulate, params: {{duration_s: 8, sample_period_s: 0.01, {}}}}}
estimator: {{type: {}, params: {}}}
)",
        rows, kModel, kContact, est, params);
    const exid::StudyOutcome r =
        exid::runStudyText(yaml, "floating_noise_free.yaml", ".", exid_test::registry());
    ASSERT_TRUE(r.ok) << est << ": " << r.message;
    const double e = r.summary.find("identification")->find("param_rel_err")->asDouble();
    std::printf("  study %s (rows %s): param_rel_err %.2e\n", est.c_str(), rows.c_str(), e);
    EXPECT_LT(e, 1e-9) << est << " rows " << rows;
  }
}

// The csv experiment reads a floating base's columns (base_omega_x .. base_f_z, contact1_fx ..)
// as exid writes them (exid::datasetTable), and the data identify as the simulation's; an
// incomplete group is refused naming the missing columns.
TEST(FloatingBaseModel, CsvColumnsReadBackAndIdentify) {
  const exid::Dataset d = simulated();
  const auto dir = std::filesystem::temp_directory_path() / "exid_floating_csv";
  std::filesystem::create_directories(dir);
  const auto file = dir / "floating.csv";
  exid::writeCsvAtomic(file, exid::datasetTable(d));
  auto csv = exid_test::create<exid::Experiment>(
      "csv", fmt::format("{{file: {}, time_column: t}}", file.string()));
  for (int pass = 0; pass < 2; ++pass) {  // run (in memory) and stream (read in memory too)
    const exid::Dataset r = pass == 0 ? csv->run(humanoid(), nullptr, mtest::context())
                                      : csv->stream(humanoid(), nullptr, mtest::context());
    ASSERT_FALSE(r.streamed());
    ASSERT_EQ(r.base.cols(), 9);
    ASSERT_EQ(r.contact.cols(), 6);
    EXPECT_LT((r.base - d.base).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LT((r.contact - d.contact).cwiseAbs().maxCoeff(), 1e-9);
    auto m = mtest::model("floating_base", std::string("{") + kModel + "}", humanoid());
    const exid::Estimate e = exid_test::create<exid::Estimator>("batch_ls", "{}")
                                 ->estimate(*m, r, nullptr, mtest::context());
    EXPECT_LT(scaledErr(e.value, m->baseNominal()), 1e-9);
  }
  // an incomplete base group
  exid::CsvTable t = exid::datasetTable(d);
  for (std::size_t c = 0; c < t.columns.size(); ++c)
    if (t.columns[c] == "base_f_z") t.columns[c] = "base_fz";
  exid::writeCsvAtomic(file, t);
  try {
    csv->run(humanoid(), nullptr, mtest::context());
    ADD_FAILURE() << "no refusal";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("incomplete base motion: missing column(s) base_f_z"),
              std::string::npos)
        << e.what();
  }
  std::filesystem::remove_all(dir);
}

// varpro and gains_ls on the humanoid with drives (a URDF <exid> extension of the shipped one),
// noise-free, to 1e-9 on the base parameters. varpro: the plant's Coulomb friction is tanh(qd /
// 0.05) and the model's widths start at 0.1 (the nonlinear parameters eps1 .. eps10, fitted to
// the plant's); gains_ls: the plant's drives deliver u = tau - FcL |tau| sign(qd) of the recorded
// torque (FcL = 0.03 on every joint), the model's FcL columns carry the recorded torque and the
// joint rows' measurement is tau + J^T w (Rows::torque tells gains_ls the recorded one).
TEST(FloatingBaseModel, StudiesVarproAndGainsLsOnTheHumanoid) {
  const auto dir = std::filesystem::temp_directory_path() / "exid_floating_drives";
  std::filesystem::create_directories(dir);
  const auto ext = dir / "humanoid_drives.xml";
  {
    std::ofstream f(ext);
    f << drivesExtension();
  }
  const std::string robot = fmt::format(
      "robot: {{type: urdf, params: {{file: {}/robots/humanoid/humanoid.urdf, "
      "extension: {}}}}}\n",
      EXID_SOURCE_DIR, ext.string());
  // (the Stribeck case: 20 nonlinear parameters; the grid's sweeps with two multiples each,
  // starts: 2, on 4 s. From the study's values alone, starts: 1, Levenberg-Marquardt stops at
  // vs7 = 12 rad/s, which the data do not determine, and varpro says so)
  for (const auto& [est, params, model, plant] :
       std::vector<std::tuple<std::string, std::string, std::string, std::string>>{
           {"varpro", "{}", "coulomb_smoothing_rad_s: [0.1]",
            "duration_s: 8, coulomb: tanh, coulomb_velocity_scale: 0.05"},
           {"gains_ls", "{}", "coulomb_load: true",
            "duration_s: 8, coulomb_load_Nm_per_Nm: [0.03]"},
           {"varpro", "{starts: 2}",
            "coulomb_asymmetric: true, coulomb_smoothing_rad_s: [0.1], stribeck: true, "
            "stribeck_velocity_rad_s: [0.4]",
            "duration_s: 4, coulomb: tanh, coulomb_velocity_scale: 0.05, coulomb_negative_Nm: "
            "[1.2], stribeck_Nm: [0.8], stribeck_velocity_rad_s: [0.3]"}}) {
    const std::string yaml = fmt::format(
        R"(name: floating_{}
seed: 3
{}model: {{type: floating_base, params: {{{}, {}, {}}}}}
experiment: {{type: simulate, params: {{sample_period_s: 0.01, {}, {}}}}}
estimator: {{type: {}, params: {}}}
)",
        est, robot, kModel, kDrives, model, kContact, plant, est, params);
    const exid::StudyOutcome r =
        exid::runStudyText(yaml, "floating_friction.yaml", ".", exid_test::registry());
    ASSERT_TRUE(r.ok) << est << ": " << r.message;
    const exid::Json* id = r.summary.find("identification");
    // converged: no warning of a fit that stopped short (varpro says so where it does)
    if (const exid::Json* w = r.summary.find("warnings"); w && w->isArray()) {
      for (std::size_t k = 0; k < w->size(); ++k)
        EXPECT_EQ(w->at(k).dump().find("not converged"), std::string::npos) << w->at(k).dump();
    }
    const double e = id->find("param_rel_err")->asDouble();
    std::printf("  study %s (%s): param_rel_err %.2e\n", est.c_str(), plant.c_str(), e);
    EXPECT_LT(e, 1e-9) << est;
    if (est == "varpro") {  // the widths and Stribeck velocities: the plant's
      const exid::Json* nl = id->find("nonlinear_parameters");
      const bool stribeck = model.find("stribeck") != std::string::npos;
      ASSERT_TRUE(nl && nl->isArray() && nl->size() == (stribeck ? 20u : 10u));
      for (std::size_t k = 0; k < nl->size(); ++k) {
        const bool vs = nl->at(k).find("name")->asString().rfind("vs", 0) == 0;
        EXPECT_NEAR(nl->at(k).find("value")->asDouble(), vs ? 0.3 : 0.05, 1e-9) << k;
        EXPECT_EQ(nl->at(k).find("initial")->asDouble(), vs ? 0.4 : 0.1) << k;
      }
    }
  }
  std::filesystem::remove_all(dir);
}
