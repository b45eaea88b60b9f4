// Observation models `load_wrench` and `load_torque`: a 10-parameter payload on the PUMA 560,
// simulated with the payload attached to the sensor body; rows reproduce the wrench / torque
// difference and least squares recovers the payload; VJPs match finite differences.
#include "model_test_util.hpp"

namespace {

const std::string kPayload =
    "payload_mass_kg: 2.5, payload_com_m: [0.02, -0.015, 0.08], "
    "payload_inertia_kg_m2: [0.012, 0.0007, -0.0004, 0.015, 0.0009, 0.009]";

const exid::Dataset& pumaWithPayload() {
  static exid::Dataset d =
      mtest::simulate(mtest::robot("puma560"),
                      "{rtol: 1e-10, atol: 1e-12, duration_s: 10, wrench: true, " + kPayload + "}");
  return d;
}

TEST(LoadWrench, RecoversPayload) {
  auto r = mtest::robot("puma560");
  auto m = mtest::model("load_wrench", "{" + kPayload + "}", r);
  EXPECT_EQ(m->numBase(), 10);
  const mtest::Recovery rec = mtest::recover(*m, pumaWithPayload());
  mtest::print("puma560 load_wrench", rec);
  EXPECT_LT(rec.rows_rel, 1e-9);
  EXPECT_LT(rec.est_rel, 1e-6);
  EXPECT_EQ(m->base().names.front(), "L_M");
}

TEST(LoadWrench, SensorOffsetColumns) {
  auto r = mtest::robot("puma560");
  auto m = mtest::model("load_wrench", "{sensor_offset: true, " + kPayload + "}", r);
  EXPECT_EQ(m->numBase(), 16);
  exid::Dataset d = pumaWithPayload();
  const double off[6] = {1.5, -2.0, 0.7, 0.05, -0.03, 0.02};
  for (int e = 0; e < 6; ++e) d.wrench.col(e).array() += off[e];
  const exid::Rows rows = m->rows(d, mtest::context());
  const Eigen::VectorXd th = Eigen::ColPivHouseholderQR<Eigen::MatrixXd>(rows.W).solve(rows.y);
  Eigen::VectorXd truth = m->baseNominal();
  for (int e = 0; e < 6; ++e) truth[10 + e] = off[e];
  std::printf("[load_wrench + offset] estimate error %.2e\n", (th - truth).norm() / truth.norm());
  EXPECT_LT((th - truth).norm() / truth.norm(), 1e-6);
}

TEST(LoadTorque, RecoversPayload) {
  auto r = mtest::robot("puma560");
  auto m = mtest::model("load_torque", "{" + kPayload + "}", r);
  const mtest::Recovery rec = mtest::recover(*m, pumaWithPayload());
  mtest::print("puma560 load_torque", rec);
  EXPECT_EQ(m->numBase(), 10);
  EXPECT_LT(rec.rows_rel, 1e-9);
  EXPECT_LT(rec.est_rel, 1e-6);
}

TEST(LoadTorque, WithoutPayloadTheRowsAreZero) {
  auto r = mtest::robot("puma560");
  auto m = mtest::model("load_torque", "{}", r);
  const exid::Dataset d = mtest::simulate(r, "{duration_s: 1}");
  const exid::Rows rows = m->fullRows(d, mtest::context());
  EXPECT_LT(rows.y.cwiseAbs().maxCoeff(), 1e-8 * d.tau.cwiseAbs().maxCoeff());
}

TEST(LoadModels, VjpMatchesFiniteDifferences) {
  for (const char* name : {"puma560", "panda", "irp6"}) {
    auto r = mtest::robot(name);
    if (!r) continue;
    const exid::Samples s = mtest::randomSamples(*r, 3, 0.01, 17);
    for (const char* model : {"load_wrench", "load_torque"}) {
      auto m = mtest::model(
          model,
          "{" + kPayload + (std::string(model) == "load_wrench" ? ", sensor_offset: true}" : "}"),
          r);
      const double err = mtest::vjpError(*m, s, true);
      std::printf("[%s %s] VJP vs FD relative error %.2e\n", name, model, err);
      EXPECT_LT(err, 1e-6) << name << " " << model;
    }
  }
}

}  // namespace
