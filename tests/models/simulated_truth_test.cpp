// What a simulated study is judged against: the `differential` model's fullTruth reads the
// `simulate` experiment's plant from the dataset's facts (Dataset::facts.simulated: payload,
// drive terms, friction beyond Coulomb + viscous, gain errors). Noise-free data and a consistent
// estimator reproduce that truth exactly; the robot description's nominal values are off.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>

#include "exid/drive.hpp"
#include "exid/json.hpp"
#include "exid/payload.hpp"
#include "model_test_util.hpp"

namespace {

double relErr(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).norm() / b.norm();
}

// A plant with a 2 kg payload, asymmetric Coulomb and a Stribeck term: batch_ls on its exact
// data equals the base truth read from the plant's, and differs from the nominal.
TEST(SimulatedTruth, ThePlantsPayloadAndFrictionAreTheTruth) {
  auto r = mtest::robot("puma560");
  const exid::Dataset d = mtest::simulate(
      r,
      "{duration_s: 8, sample_period_s: 0.01, coulomb: tanh, coulomb_velocity_scale: 0.05, "
      "coulomb_negative_Nm: [3.0, 4.0, 2.0, 0.5, 0.4, 0.3], stribeck_Nm: [1.0], "
      "stribeck_velocity_rad_s: [0.2], payload_mass_kg: 2.0, payload_com_m: [0.01, 0.02, 0.05], "
      "payload_inertia_kg_m2: [0.01, 0, 0, 0.012, 0, 0.008]}");
  auto model = mtest::model("differential",
                            "{offset: true, coulomb_asymmetric: true, coulomb_smoothing_rad_s: "
                            "[0.05], stribeck: true, stribeck_velocity_rad_s: [0.2]}",
                            r);
  const Eigen::VectorXd truth = model->base().reduce(model->fullTruth(*d.facts.simulated));
  const Eigen::VectorXd nominal = model->baseNominal();
  auto ls = exid_test::create<exid::Estimator>("batch_ls", "{}");
  const exid::Estimate e = ls->estimate(*model, d, nullptr, mtest::context());
  std::printf(
      "[truth] plant with payload and friction: batch_ls against the truth %.2e, "
      "against the nominal %.2e\n",
      relErr(e.value, truth), relErr(e.value, nominal));
  EXPECT_LT(relErr(e.value, truth), 1e-6);
  EXPECT_GT(relErr(e.value, nominal), 1e-2);
  // the full values by name
  const std::vector<std::string> names = model->fullNames();
  const Eigen::VectorXd full = model->fullTruth(*d.facts.simulated);
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (names[i] == "FcN2") {
      EXPECT_DOUBLE_EQ(full[static_cast<Eigen::Index>(i)], 4.0);
    }
    if (names[i] == "Fs5") {
      EXPECT_DOUBLE_EQ(full[static_cast<Eigen::Index>(i)], 1.0);
    }
  }
}

// drive_terms: false: the truth has no drive terms.
TEST(SimulatedTruth, APlantWithoutDriveTermsHasNone) {
  auto r = mtest::robot("puma560");
  const exid::Dataset d =
      mtest::simulate(r, "{duration_s: 8, sample_period_s: 0.01, drive_terms: false}");
  auto model = mtest::model("differential", "{offset: true}", r);
  const Eigen::VectorXd full = model->fullTruth(*d.facts.simulated);
  const std::vector<std::string> names = model->fullNames();
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (exid::isDriveParameterName(names[i])) {
      EXPECT_EQ(full[static_cast<Eigen::Index>(i)], 0.0);
    }
  }
  auto ls = exid_test::create<exid::Estimator>("batch_ls", "{}");
  const exid::Estimate e = ls->estimate(*model, d, nullptr, mtest::context());
  const Eigen::VectorXd truth = model->base().reduce(full);
  EXPECT_LT((e.value - truth).norm() / truth.norm(), 1e-6);
}

// Gain errors and the load term: dK = 1/g - 1 for a recorded gain, g - 1 for a drive gain;
// FcL as given.
TEST(SimulatedTruth, GainsAndLoadTermsComeFromThePlantsTruth) {
  auto r = mtest::robot("puma560");
  auto gains = mtest::model("differential", "{drive_gains: true, drive_gains_scale: prior}", r);
  exid::PlantTruth plant;
  plant.recorded_torque_gain = {0.8};
  Eigen::VectorXd full = gains->fullTruth(plant);
  std::vector<std::string> names = gains->fullNames();
  int found = 0;
  for (std::size_t i = 0; i < names.size(); ++i)
    if (exid::torqueColumnKind(names[i]) == 1) {
      EXPECT_NEAR(full[static_cast<Eigen::Index>(i)], 0.25, 1e-15) << names[i];
      ++found;
    }
  EXPECT_EQ(found, 6);
  plant = exid::PlantTruth();
  plant.drive_torque_gain = {1, 1.1, 1, 1, 1, 0.9};
  full = gains->fullTruth(plant);
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (names[i] == "dK2") {
      EXPECT_NEAR(full[static_cast<Eigen::Index>(i)], 0.1, 1e-15);
    }
    if (names[i] == "dK6") {
      EXPECT_NEAR(full[static_cast<Eigen::Index>(i)], -0.1, 1e-15);
    }
  }
  auto load = mtest::model("differential", "{coulomb_load: true}", r);
  plant = exid::PlantTruth();
  plant.coulomb_load_Nm_per_Nm = {0.02};
  full = load->fullTruth(plant);
  names = load->fullNames();
  found = 0;
  for (std::size_t i = 0; i < names.size(); ++i)
    if (exid::torqueColumnKind(names[i]) == 2) {
      EXPECT_EQ(full[static_cast<Eigen::Index>(i)], 0.02) << names[i];
      ++found;
    }
  EXPECT_EQ(found, 6);
}

}  // namespace
