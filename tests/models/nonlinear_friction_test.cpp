// Friction beyond Coulomb + viscous in the `differential` model (asymmetric Coulomb, smooth
// sign, Stribeck) and the `varpro` estimator that fits their nonlinear parameters: the columns
// are the friction torque written independently here, their derivatives equal central
// differences, varpro recovers every parameter from noise-free data and stays within its own
// standard deviations on noisy data, and a study reports and validates at the fitted values.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/json.hpp"
#include "exid_cli.hpp"
#include "model_test_util.hpp"

namespace {

namespace fs = std::filesystem;

// Every option on: asymmetric Coulomb levels through a tanh of width eps, and a Stribeck term.
constexpr const char* kModel =
    "{coulomb_asymmetric: true, coulomb_smoothing_rad_s: [0.02], stribeck: true, "
    "stribeck_velocity_rad_s: [0.1]}";

struct Truth {
  std::vector<double> FcP, FcN, Fs, vs, eps;
};

Truth truth(int n) {
  Truth t;
  for (int j = 0; j < n; ++j) {
    t.FcP.push_back(0.6 + 0.1 * j);
    t.FcN.push_back(0.35 + 0.05 * j);
    t.Fs.push_back(0.5 - 0.03 * j);
    t.vs.push_back(0.05 + 0.01 * j);
    t.eps.push_back(0.008 + 0.002 * j);
  }
  return t;
}

// The torque of the robot's rigid body, rotor inertia and viscous friction (exid's inverse
// dynamics), plus the friction written here from its definition.
Eigen::VectorXd plantTorque(const exid::RobotModel& r, const Truth& T, double delta,
                            const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                            const Eigen::VectorXd& qdd) {
  exid::DriveColumns c;
  c.rotor_inertia = true;
  c.viscous = true;
  auto data = exid::makeDynamicsData(r);
  Eigen::VectorXd tau = exid::actuatorTorque(r, *data, c, q, qd, qdd);
  for (int j = 0; j < r.dof(); ++j) {
    const auto u = static_cast<std::size_t>(j);
    const double s = std::tanh(qd[j] / T.eps[u]);
    tau[j] += T.FcP[u] * (1 + s) / 2 - T.FcN[u] * (1 - s) / 2 +
              T.Fs[u] * s * std::exp(-std::pow(std::abs(qd[j]) / T.vs[u], delta));
  }
  return tau;
}

// The full parameters with the truth's friction levels (the rest nominal) and eta in the
// model's order (eps_j, vs_j per joint).
void truthVectors(const exid::ObservationModel& m, const Truth& T, Eigen::VectorXd* full,
                  Eigen::VectorXd* eta) {
  const std::vector<std::string> names = m.fullNames();
  *full = m.fullNominal();
  for (std::size_t i = 0; i < names.size(); ++i) {
    const std::string& s = names[i];
    auto joint = [&](std::size_t pre) {
      return static_cast<std::size_t>(std::stoi(s.substr(pre)) - 1);
    };
    if (s.rfind("FcP", 0) == 0) (*full)[static_cast<Eigen::Index>(i)] = T.FcP[joint(3)];
    if (s.rfind("FcN", 0) == 0) (*full)[static_cast<Eigen::Index>(i)] = T.FcN[joint(3)];
    if (s.rfind("Fs", 0) == 0) (*full)[static_cast<Eigen::Index>(i)] = T.Fs[joint(2)];
  }
  const auto nl = m.nonlinearParameters();
  eta->resize(static_cast<Eigen::Index>(nl.size()));
  for (std::size_t k = 0; k < nl.size(); ++k) {
    const bool e = nl[k].name[0] == 'e';
    const auto j = static_cast<std::size_t>(std::stoi(nl[k].name.substr(e ? 3 : 2)) - 1);
    (*eta)[static_cast<Eigen::Index>(k)] = e ? T.eps[j] : T.vs[j];
  }
}

// A simulated motion (the PUMA tracking its own Fourier reference: reversals, so velocities
// through zero) with the plant torque above, optionally with noise on it.
exid::Dataset recording(const std::shared_ptr<const exid::RobotModel>& r, const Truth& T,
                        double duration_s, double noise_Nm, std::uint64_t seed) {
  exid::Dataset d = mtest::simulate(
      r, fmt::format("{{duration_s: {}, sample_period_s: 0.002, drive_terms: false}}", duration_s),
      7);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd(0.0, noise_Nm);
  for (int k = 0; k < d.size(); ++k) {
    const Eigen::VectorXd tau = plantTorque(*r, T, 2.0, d.q.row(k).transpose(),
                                            d.qd.row(k).transpose(), d.qdd.row(k).transpose());
    for (int j = 0; j < r->dof(); ++j) d.tau(k, j) = tau[j] + (noise_Nm > 0 ? nd(rng) : 0.0);
  }
  return d;
}

// Random samples at slow speeds (around the Stribeck and smoothing velocities) as a dataset with
// a zero torque (only the columns are looked at).
exid::Dataset slowSamples(const exid::RobotModel& r, int K, std::uint64_t seed) {
  const exid::Samples s = mtest::randomSamples(r, K, 0.01, seed);
  exid::Dataset d;
  d.t = s.t;
  d.q = s.q;
  d.qd = 0.05 * s.qd;
  d.qdd = s.qdd;
  d.tau = Eigen::MatrixXd::Zero(s.size(), r.dof());
  return d;
}

TEST(NonlinearFriction, ColumnsAreTheFrictionTorque) {
  auto r = mtest::robot("puma560");
  auto m = mtest::model("differential", kModel, r);
  const Truth T = truth(r->dof());
  Eigen::VectorXd full, eta;
  truthVectors(*m, T, &full, &eta);
  const exid::Dataset d = slowSamples(*r, 40, 5);
  const exid::Rows rows = m->fullRowsAt(d, eta, nullptr, mtest::context());
  double worst = 0, scale = 0;
  for (int k = 0; k < d.size(); ++k) {
    const Eigen::VectorXd tau = plantTorque(*r, T, 2.0, d.q.row(k).transpose(),
                                            d.qd.row(k).transpose(), d.qdd.row(k).transpose());
    const Eigen::VectorXd pred = rows.W.middleRows(k * r->dof(), r->dof()) * full;
    worst = std::max(worst, (pred - tau).cwiseAbs().maxCoeff());
    scale = std::max(scale, tau.cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst, 1e-12 * scale) << worst;
  const std::vector<std::string> names = m->fullNames();
  EXPECT_NE(std::find(names.begin(), names.end(), "FcP3"), names.end());
  EXPECT_NE(std::find(names.begin(), names.end(), "FcN3"), names.end());
  EXPECT_NE(std::find(names.begin(), names.end(), "Fs3"), names.end());
  EXPECT_EQ(std::find(names.begin(), names.end(), "Fc3"), names.end());  // replaced
  EXPECT_EQ(m->nonlinearParameters().size(), 12u);                       // eps_j, vs_j
}

TEST(NonlinearFriction, ColumnDerivativesEqualCentralDifferences) {
  auto r = mtest::robot("puma560");
  auto m = mtest::model("differential", kModel, r);
  const Truth T = truth(r->dof());
  Eigen::VectorXd full, eta;
  truthVectors(*m, T, &full, &eta);
  const exid::Dataset d = slowSamples(*r, 30, 9);
  Eigen::MatrixXd dW;
  m->fullRowsAt(d, eta, &dW, mtest::context());
  const auto nl = m->nonlinearParameters();
  int l = 0;
  double worst = 0;
  for (std::size_t k = 0; k < nl.size(); ++k) {
    const double h = 1e-6 * eta[static_cast<Eigen::Index>(k)];
    Eigen::VectorXd ep = eta, em = eta;
    ep[static_cast<Eigen::Index>(k)] += h;
    em[static_cast<Eigen::Index>(k)] -= h;
    const Eigen::MatrixXd Wp = m->fullRowsAt(d, ep, nullptr, mtest::context()).W;
    const Eigen::MatrixXd Wm = m->fullRowsAt(d, em, nullptr, mtest::context()).W;
    const Eigen::MatrixXd fd_all = (Wp - Wm) / (2 * h);
    Eigen::MatrixXd moved = Eigen::MatrixXd::Zero(fd_all.rows(), fd_all.cols());
    for (int c : nl[k].columns) {
      const Eigen::VectorXd fd = fd_all.col(c);
      worst = std::max(
          worst, (fd - dW.col(l)).cwiseAbs().maxCoeff() / std::max(1.0, fd.cwiseAbs().maxCoeff()));
      moved.col(c) = fd;
      ++l;
    }
    // and nothing else moves
    EXPECT_LT((fd_all - moved).cwiseAbs().maxCoeff(), 1e-6) << nl[k].name;
  }
  EXPECT_EQ(l, dW.cols());
  EXPECT_LT(worst, 1e-6) << worst;
  // the design's derivative in the samples (excitation design) includes the smooth columns
  EXPECT_LT(mtest::vjpError(*m, d.samples(), true), 1e-6);
}

// fullColumnsAt (what varpro's trial points read) gives the very numbers of fullRowsAt's
// columns: the friction columns alone (the model's own path), with every joint's rows and with
// a subset, at other nonlinear parameters, and any other mix of columns (through fullRowsAt);
// a column out of range is refused.
TEST(NonlinearFriction, FullColumnsAtAreTheRowsColumns) {
  auto r = mtest::robot("puma560");
  for (const std::string joints : {"", ", joints: [2, 3, 5]"}) {
    auto m =
        mtest::model("differential",
                     "{coulomb_asymmetric: true, coulomb_smoothing_rad_s: [0.02], stribeck: true, "
                     "stribeck_velocity_rad_s: [0.1]" +
                         joints + "}",
                     r);
    const Truth T = truth(r->dof());
    Eigen::VectorXd full, eta;
    truthVectors(*m, T, &full, &eta);
    eta = eta.cwiseProduct(Eigen::VectorXd::LinSpaced(eta.size(), 0.5, 3.0));
    const exid::Dataset d = slowSamples(*r, 37, 6);
    Eigen::MatrixXd dW_rows;
    const Eigen::MatrixXd W = m->fullRowsAt(d, eta, &dW_rows, mtest::context()).W;
    std::vector<int> friction;  // FcP, FcN, Fs of the 6 joints
    const std::vector<std::string> names = m->fullNames();
    for (std::size_t c = 0; c < names.size(); ++c)
      if (names[c].rfind("FcP", 0) == 0 || names[c].rfind("FcN", 0) == 0 ||
          names[c].rfind("Fs", 0) == 0)
        friction.push_back(static_cast<int>(c));
    ASSERT_EQ(friction.size(), 18u) << fmt::format("{}", fmt::join(names, " "));
    std::vector<std::vector<int>> asks = {friction, {friction[4]}, {friction[17], friction[0]}};
    asks.push_back({0, friction[3], 7});  // with rigid-body columns: through fullRowsAt
    for (const std::vector<int>& cols : asks) {
      const Eigen::MatrixXd C = m->fullColumnsAt(d, eta, cols, mtest::context());
      // with the derivatives: the same columns, and fullRowsAt's dW itself
      Eigen::MatrixXd dW;
      const Eigen::MatrixXd Cd = m->fullColumnsAt(d, eta, cols, mtest::context(), &dW);
      ASSERT_EQ(Cd.rows(), C.rows());
      ASSERT_EQ(Cd.cols(), C.cols());
      EXPECT_EQ(0, std::memcmp(Cd.data(), C.data(), sizeof(double) * C.size()));
      ASSERT_EQ(dW.rows(), dW_rows.rows());
      ASSERT_EQ(dW.cols(), dW_rows.cols());
      ASSERT_EQ(dW.cols(), joints.empty() ? 24 : 12);  // (eps: FcP, FcN, Fs; vs: Fs)
      EXPECT_EQ(0, std::memcmp(dW.data(), dW_rows.data(), sizeof(double) * dW.size()))
          << joints << ": largest difference " << (dW - dW_rows).cwiseAbs().maxCoeff();
      ASSERT_EQ(C.rows(), W.rows());
      ASSERT_EQ(C.cols(), static_cast<Eigen::Index>(cols.size()));
      for (std::size_t i = 0; i < cols.size(); ++i) {
        const Eigen::VectorXd a = C.col(static_cast<Eigen::Index>(i)), b = W.col(cols[i]);
        EXPECT_EQ(0, std::memcmp(a.data(), b.data(), sizeof(double) * a.size()))
            << "column " << cols[i] << joints << ": largest difference "
            << (a - b).cwiseAbs().maxCoeff();
      }
    }
    EXPECT_THROW(m->fullColumnsAt(d, eta, {static_cast<int>(W.cols())}, mtest::context()),
                 exid::Error);
    EXPECT_THROW(m->fullColumnsAt(d, eta, {-1}, mtest::context()), exid::Error);
    Eigen::VectorXd bad = eta;
    bad[0] = -1.0;  // a width must be positive, as for fullRowsAt
    EXPECT_THROW(m->fullColumnsAt(d, bad, friction, mtest::context()), exid::Error);
  }
}

TEST(NonlinearFriction, OptionsWithoutTheirValuesAreRefused) {
  for (const auto& [yaml, what] : std::vector<std::pair<std::string, std::string>>{
           {"{stribeck: true}", "needs stribeck_velocity_rad_s"},
           {"{stribeck_velocity_rad_s: [0.1]}", "stribeck is false"},
           {"{coulomb_smoothing_rad_s: [0]}", "not a positive width"},
           {"{stribeck: true, stribeck_velocity_rad_s: [0.1], friction: subtract}",
            "need friction: model"},
           {"{coulomb_asymmetric: true, coulomb: false}", "need coulomb: true"}}) {
    try {
      exid_test::create<exid::ObservationModel>("differential", yaml);
      ADD_FAILURE() << yaml;
    } catch (const exid::Error& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  }
  // exid validate makes the model: the same message, with the study's place
  const fs::path dir = exid_cli::freshTempDir("exid_varpro_", "validate");
  std::ofstream(dir / "bad.yaml") << "name: bad\nrobot: {type: puma560}\n"
                                  << "model: {type: differential, params: {stribeck: true}}\n"
                                  << "experiment: {type: simulate, params: {duration_s: 1}}\n"
                                  << "estimator: {type: varpro}\n";
  const auto res = exid_cli::runExid("validate " + (dir / "bad.yaml").string());
  EXPECT_NE(res.code, 0) << res.out;
  EXPECT_NE(res.out.find("bad.yaml:3: model"), std::string::npos) << res.out;
  EXPECT_NE(res.out.find("needs stribeck_velocity_rad_s"), std::string::npos) << res.out;
  // a batch fit of a model without nonlinear parameters: varpro says so
  auto r = mtest::robot("puma560");
  auto m = mtest::model("differential", "{}", r);
  const exid::Dataset d = mtest::simulate(r, "{duration_s: 1}");
  auto v = exid_test::create<exid::Estimator>("varpro", "{}");
  try {
    v->estimate(*m, d, nullptr, mtest::context());
    ADD_FAILURE() << "no error";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("no nonlinear parameter"), std::string::npos) << e.what();
  }
}

// coulomb_load: FcL_j |tau_m,j| sign(qdm_j). The recorded torque is made here from its
// definition, tau_m = tau_0 + FcL |tau_m| s, solved exactly: tau_m = tau_0 / (1 - FcL s
// sign(tau_0)), tau_0 the robot's rigid body, rotor inertia, Coulomb and viscous torque.
exid::Dataset loadRecording(const std::shared_ptr<const exid::RobotModel>& r,
                            const std::vector<double>& FcL, double noise_Nm, std::uint64_t seed) {
  exid::Dataset d =
      mtest::simulate(r, "{duration_s: 6, sample_period_s: 0.002, drive_terms: false}", 7);
  exid::DriveColumns c;
  c.rotor_inertia = c.coulomb = c.viscous = true;
  auto data = exid::makeDynamicsData(*r);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd(0.0, 1.0);
  for (int k = 0; k < d.size(); ++k) {
    const Eigen::VectorXd t0 = exid::actuatorTorque(
        *r, *data, c, d.q.row(k).transpose(), d.qd.row(k).transpose(), d.qdd.row(k).transpose());
    for (int j = 0; j < r->dof(); ++j) {
      const double v = d.qd(k, j), s = v > 0 ? 1.0 : (v < 0 ? -1.0 : 0.0);
      const double st = t0[j] > 0 ? 1.0 : (t0[j] < 0 ? -1.0 : 0.0);
      d.tau(k, j) = t0[j] / (1.0 - FcL[static_cast<std::size_t>(j)] * s * st) + noise_Nm * nd(rng);
    }
  }
  return d;
}

TEST(NonlinearFriction, LoadDependentCoulombIsRecoveredFromTheRecordedTorque) {
  auto r = mtest::robot("puma560");
  auto m = mtest::model("differential", "{coulomb_load: true}", r);
  std::vector<double> FcL;
  for (int j = 0; j < r->dof(); ++j) FcL.push_back(0.04 + 0.01 * j);
  Eigen::VectorXd full = m->fullNominal();
  const std::vector<std::string> names = m->fullNames();
  int found = 0;
  for (std::size_t i = 0; i < names.size(); ++i)
    if (names[i].rfind("FcL", 0) == 0) {
      full[static_cast<Eigen::Index>(i)] = FcL[static_cast<std::size_t>(names[i][3] - '1')];
      ++found;
    }
  ASSERT_EQ(found, 6);
  const Eigen::VectorXd want = m->base().reduce(full);
  const std::vector<std::string> base = m->base().names;
  std::vector<Eigen::Index> cols;
  for (std::size_t i = 0; i < base.size(); ++i)
    if (base[i].rfind("FcL", 0) == 0) cols.push_back(static_cast<Eigen::Index>(i));
  EXPECT_EQ(cols.size(), 6u);  // every load term is a base parameter
  {                            // noise-free: every base parameter
    const exid::Dataset d = loadRecording(r, FcL, 0.0, 1);
    auto b = exid_test::create<exid::Estimator>("batch_ls", "{}");
    const exid::Estimate e = exid_test::create<exid::Estimator>("gains_ls", "{}")
                                 ->estimate(*m, d, nullptr, mtest::context());
    const double err = ((e.value - want).array().abs() / want.array().abs().max(1.0)).maxCoeff();
    std::printf("[coulomb_load] noise free (gains_ls): every base parameter to %.2e (relative)\n",
                err);
    // without the term the same data leave a residual the term explains
    auto m0 = mtest::model("differential", "{}", r);
    const exid::Estimate e0 = b->estimate(*m0, d, nullptr, mtest::context());
    EXPECT_GT(e0.residual_rms, 1e4 * std::max(e.residual_rms, 1e-12));
  }
  // 0.05 N m noise: the recorded torque is in the column too (errors in variables), and the
  // estimates are precise enough for batch_ls's bias to be many sigma; gains_ls keeps the torque
  // in the measurement only. 12 draws. (At 0.3 N m the wrist's recorded torque, about 1 N m,
  // has its sign flipped by noise too often: gains_ls refuses it by name, below.)
  int within2 = 0, count = 0, ls_within2 = 0;
  double z2 = 0, ls_z2 = 0;
  for (int seed = 1; seed <= 12; ++seed) {
    const exid::Dataset d = loadRecording(r, FcL, 0.05, static_cast<std::uint64_t>(seed));
    auto g = exid_test::create<exid::Estimator>("gains_ls", "{}");
    const exid::Estimate e = g->estimate(*m, d, nullptr, mtest::context());
    auto b = exid_test::create<exid::Estimator>("batch_ls", "{}");
    const exid::Estimate eb = b->estimate(*m, d, nullptr, mtest::context());
    for (Eigen::Index c : cols) {
      const double z = (e.value[c] - want[c]) / e.std[c];
      const double zb = (eb.value[c] - want[c]) / eb.std[c];
      z2 += z * z;
      ls_z2 += zb * zb;
      within2 += std::abs(z) < 2.0;
      ls_within2 += std::abs(zb) < 2.0;
      ++count;
    }
  }
  const double mean_z2 = z2 / count;
  std::printf(
      "[coulomb_load] noisy: gains_ls %d of %d FcL within 2 sigma, mean z^2 = %.2f; batch_ls %d, "
      "mean z^2 = %.1f\n",
      within2, count, mean_z2, ls_within2, ls_z2 / count);
  EXPECT_LT(ls_within2, count / 2);  // (why gains_ls fits it)
  EXPECT_GE(within2, static_cast<int>(0.8 * count));
  EXPECT_GT(mean_z2, 0.3);
  EXPECT_LT(mean_z2, 2.5);
  {
    const exid::Dataset d = loadRecording(r, FcL, 0.3, 1);
    try {
      (void)exid_test::create<exid::Estimator>("gains_ls", "{}")
          ->estimate(*m, d, nullptr, mtest::context());
      ADD_FAILURE() << "a load term on a drive with its torque near the noise was accepted";
    } catch (const exid::Error& e) {
      EXPECT_NE(std::string(e.what()).find("degenerate branch"), std::string::npos) << e.what();
    }
  }
  // the design (no measurement: the nominal torque in the column) and its exact derivative
  const exid::Samples s = mtest::randomSamples(*r, 6, 0.01, 4);
  const double vjp = mtest::vjpError(*m, s, true);
  std::printf("[coulomb_load] design VJP against central differences: %.2e\n", vjp);
  EXPECT_LT(vjp, 1e-6);
  // refused where it cannot hold
  for (const char* bad : {"{coulomb_load: true, friction: subtract}",
                          "{coulomb_load: true, coulomb_smoothing_rad_s: [0.01]}",
                          "{coulomb_load: true, drive_gains: true, drive_gains_scale: prior}"}) {
    try {
      (void)mtest::model("differential", bad, r);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const exid::Error& e) {
      EXPECT_NE(std::string(e.what()).find("coulomb_load"), std::string::npos) << e.what();
    }
  }
}

// The held-out prediction of a model with the recorded torque in a column solves the row for
// the torque (tau_hat = w theta / (1 - FcL sign(tau_hat qdm))): it never reads the recorded
// torque it predicts. Validation data with the torque scaled by 1.5 then show an error of
// exactly 1/3; a prediction reading it (W theta) would follow part of the scale.
TEST(NonlinearFriction, TheHeldOutPredictionDoesNotReadTheRecordedTorque) {
  auto r = mtest::robot("puma560");
  std::vector<double> FcL;
  for (int j = 0; j < r->dof(); ++j) FcL.push_back(0.04 + 0.01 * j);
  exid::Dataset d = loadRecording(r, FcL, 0.0, 1);
  const fs::path dir = exid_cli::freshTempDir("exid_fcl_", "study");
  const int half = d.size() / 2;
  mtest::writeCsv(d, dir / "id.csv", 0, half);
  mtest::writeCsv(d, dir / "val.csv", half, d.size());
  d.tau *= 1.5;
  mtest::writeCsv(d, dir / "scaled.csv", half, d.size());
  for (const char* val : {"val.csv", "scaled.csv"}) {
    std::ofstream(dir / "s.yaml") << "name: fcl\nrobot: {type: puma560}\n"
                                  << "model: {type: differential, params: {coulomb_load: true}}\n"
                                  << "experiment: {type: csv, params: {file: id.csv}}\n"
                                  << "estimator: {type: gains_ls}\n"
                                  << "validation: {type: csv, params: {file: " << val << "}}\n";
    const fs::path out = dir / (std::string("out_") + val);
    const auto res = exid_cli::runExid(
        fmt::format("-q run {} --out {}", (dir / "s.yaml").string(), out.string()));
    ASSERT_EQ(res.code, 0) << res.out;
    const exid::Json S = exid::Json::parse(exid_cli::slurp(out / "summary.json"));
    const exid::Json& V = *S.find("validation");
    EXPECT_NE(V.find("torque_columns_prediction"), nullptr);
    const double rel = V.find("relative_error")->asDouble();
    std::printf("[coulomb_load] held-out relative error, %s: %.3e\n", val, rel);
    if (std::string(val) == "val.csv")
      EXPECT_LT(rel, 1e-8);
    else
      EXPECT_NEAR(rel, 1.0 / 3.0, 1e-6);
  }
}

TEST(Varpro, RecoversEveryParameterFromNoiseFreeData) {
  auto r = mtest::robot("puma560");
  auto m = mtest::model("differential", kModel, r);
  const Truth T = truth(r->dof());
  Eigen::VectorXd full, eta;
  truthVectors(*m, T, &full, &eta);
  const exid::Dataset d = recording(r, T, 6.0, 0.0, 1);
  auto v = exid_test::create<exid::Estimator>("varpro", "{}");
  const exid::Estimate e = v->estimate(*m, d, nullptr, mtest::context());
  const Eigen::VectorXd theta = m->base().reduce(full);
  ASSERT_EQ(e.nonlinear.size(), eta.size());
  const double eta_err = ((e.nonlinear - eta).array() / eta.array()).abs().maxCoeff();
  const double theta_err = (e.value - theta).cwiseAbs().maxCoeff() / theta.cwiseAbs().maxCoeff();
  std::printf("[varpro] noise free: eta %.2e, theta %.2e, %s evaluations, %s\n", eta_err, theta_err,
              e.details.find("evaluations")->dump().c_str(),
              e.details.find("stop")->asString().c_str());
  EXPECT_LT(eta_err, 1e-6);
  EXPECT_LT(theta_err, 1e-6);
  EXPECT_EQ(e.nonlinear_names[0], "eps1");
  EXPECT_EQ(e.nonlinear_names[1], "vs1");
  // accumulated as normal equations (no factors kept across evaluations: each equation's Gram
  // matrix) and in chunks of 500 samples (several chunks of kept factors): the same fit
  for (const char* yaml : {"{accumulate: normal}", "{chunk_samples: 500}"}) {
    const exid::Estimate o = exid_test::create<exid::Estimator>("varpro", yaml)
                                 ->estimate(*m, d, nullptr, mtest::context());
    EXPECT_LT(((o.nonlinear - eta).array() / eta.array()).abs().maxCoeff(), 1e-6) << yaml;
    EXPECT_LT((o.value - theta).cwiseAbs().maxCoeff() / theta.cwiseAbs().maxCoeff(), 1e-6) << yaml;
  }
  // a linear fit at the study's (wrong) values is far off: the nonlinear fit matters here
  auto b = exid_test::create<exid::Estimator>("batch_ls", "{}");
  const exid::Estimate eb = b->estimate(*m, d, nullptr, mtest::context());
  EXPECT_GT(eb.residual_rms, 1e3 * std::max(e.residual_rms, 1e-12));
}

// End to end: the `simulate` experiment's plant with asymmetric, smoothed Coulomb friction and a
// Stribeck term (closed loop, SUNDIALS), identified by varpro from a model started elsewhere.
TEST(Varpro, RecoversTheSimulatedPlantsFriction) {
  auto r = mtest::robot("puma560");
  const exid::Dataset d = mtest::simulate(
      r,
      "{duration_s: 6, sample_period_s: 0.002, coulomb: tanh, coulomb_velocity_scale: 0.01, "
      "coulomb_negative_Nm: [0.3], stribeck_Nm: [0.4], stribeck_velocity_rad_s: [0.05]}");
  ASSERT_TRUE(d.facts.simulated);
  EXPECT_EQ(d.facts.simulated->stribeck_Nm.size(), 6u);
  auto m = mtest::model("differential", kModel, r);
  auto v = exid_test::create<exid::Estimator>("varpro", "{}");
  const exid::Estimate e = v->estimate(*m, d, nullptr, mtest::context());
  for (Eigen::Index k = 0; k < e.nonlinear.size(); ++k) {
    const bool eps = e.nonlinear_names[static_cast<std::size_t>(k)][0] == 'e';
    EXPECT_NEAR(e.nonlinear[k], eps ? 0.01 : 0.05, 1e-6 * (eps ? 0.01 : 0.05))
        << e.nonlinear_names[static_cast<std::size_t>(k)];
  }
  double worst = 0;
  for (std::size_t i = 0; i < e.names.size(); ++i) {
    const std::string& n = e.names[i];
    const int j = std::isdigit(static_cast<unsigned char>(n.back())) ? n.back() - '1' : -1;
    // The plant's drive offset OFF (no offset column here) is the constant part of the
    // asymmetric levels, (FcP - FcN)/2: FcP + OFF and FcN - OFF are identified.
    const double off = j >= 0 ? r->drives[static_cast<std::size_t>(j)].offset : 0.0;
    const double want = n.rfind("FcN", 0) == 0  ? 0.3 - off
                        : n.rfind("Fs", 0) == 0 ? 0.4
                        : n.rfind("FcP", 0) == 0
                            ? r->drives[static_cast<std::size_t>(j)].coulomb + off
                            : NAN;
    if (std::isnan(want)) continue;
    worst = std::max(worst, std::abs(e.value[static_cast<Eigen::Index>(i)] - want));
  }
  EXPECT_LT(worst, 1e-6);
  EXPECT_GT(std::abs(r->drives[0].offset), 0.1);  // (so the offset's part is tested)
}

TEST(Varpro, NoisyEstimatesLieWithinTheirReportedStandardDeviations) {
  // Joints 2 and 3 alone, Stribeck only (two nonlinear parameters): 24 noise draws.
  auto r = mtest::robot("puma560");
  auto m = mtest::model("differential",
                        "{joints: [2, 3], stribeck: true, stribeck_velocity_rad_s: [0.08]}", r);
  Truth T = truth(r->dof());
  for (auto& e : T.eps) e = 1e-9;  // sign() in the model: a width far below any sample's speed
  for (int j = 0; j < r->dof(); ++j)
    T.FcN[static_cast<std::size_t>(j)] = T.FcP[static_cast<std::size_t>(j)];
  const auto nl = m->nonlinearParameters();
  ASSERT_EQ(nl.size(), 2u);
  const Eigen::Vector2d eta(T.vs[1], T.vs[2]);
  int within2 = 0, draws = 24;
  double z2 = 0;
  for (int seed = 1; seed <= draws; ++seed) {
    const exid::Dataset d = recording(r, T, 4.0, 0.2, static_cast<std::uint64_t>(seed));
    auto v = exid_test::create<exid::Estimator>("varpro", "{}");
    const exid::Estimate e = v->estimate(*m, d, nullptr, mtest::context());
    for (int k = 0; k < 2; ++k) {
      const double z = (e.nonlinear[k] - eta[k]) / e.nonlinear_std[k];
      z2 += z * z;
      within2 += std::abs(z) < 2.0;
    }
  }
  const double mean_z2 = z2 / (2 * draws);
  std::printf("[varpro] noisy: %d of %d within 2 sigma, mean z^2 = %.2f\n", within2, 2 * draws,
              mean_z2);
  EXPECT_GE(within2, static_cast<int>(0.8 * 2 * draws));
  EXPECT_GT(mean_z2, 0.3);
  EXPECT_LT(mean_z2, 2.5);
}

TEST(Varpro, AStudyReportsTheFittedValuesAndValidatesAtThem) {
  auto r = mtest::robot("puma560");
  const Truth T = truth(r->dof());
  const exid::Dataset d = recording(r, T, 6.0, 0.0, 1);
  const fs::path dir = exid_cli::freshTempDir("exid_varpro_", "study");
  mtest::writeCsv(d, dir / "rec.csv");
  for (const char* est : {"varpro", "batch_ls"}) {
    std::ofstream(dir / fmt::format("{}.yaml", est))
        << "name: nl_" << est << "\nrobot: {type: puma560}\n"
        << "model: {type: differential, params: " << kModel << "}\n"
        << "experiment: {type: csv, params: {file: rec.csv}}\n"
        << "estimator: {type: " << est << "}\n"
        << "validation: {type: csv, params: {file: rec.csv}}\n"
        << "report: {type: standard, params: {plots: false}}\n";
    const auto res = exid_cli::runExid(fmt::format(
        "-q run {} --out {}", (dir / fmt::format("{}.yaml", est)).string(), (dir / est).string()));
    ASSERT_EQ(res.code, 0) << res.out;
    const exid::Json S = exid::Json::parse(exid_cli::slurp(dir / est / "summary.json"));
    const exid::Json& I = *S.find("identification");
    const double verr = S.find("validation")->find("relative_error")->asDouble();
    if (std::string(est) == "varpro") {
      const exid::Json* nl = I.find("nonlinear_parameters");
      ASSERT_NE(nl, nullptr);
      ASSERT_EQ(nl->size(), 12u);
      EXPECT_EQ(nl->at(1).find("name")->asString(), "vs1");
      EXPECT_NEAR(nl->at(1).find("value")->asDouble(), T.vs[0], 1e-6 * T.vs[0]);
      EXPECT_EQ(nl->at(1).find("initial")->asDouble(), 0.1);
      EXPECT_LT(verr, 1e-6);  // held-out rows at the fitted values
      EXPECT_NE(exid_cli::slurp(dir / est / "report.md").find("| vs1 | 0.05 |"), std::string::npos);
    } else {
      EXPECT_EQ(I.find("nonlinear_parameters"), nullptr);
      EXPECT_GT(verr, 1e-3);
      EXPECT_NE(S.dump().find("kept the model's nonlinear parameters"), std::string::npos);
    }
  }
}

}  // namespace
