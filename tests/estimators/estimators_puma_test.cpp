// Estimators on the PUMA 560 with the real `differential` model and `simulate` experiment.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "exid/error.hpp"
#include "exid_test.hpp"

namespace {

struct Puma {
  std::shared_ptr<const exid::RobotModel> robot;
  std::shared_ptr<exid::ObservationModel> model;
};

Puma puma() {
  Puma p;
  p.robot = exid_test::robot("puma560");
  p.model = exid_test::create<exid::ObservationModel>("differential", "{offset: true}");
  exid::RunContext ctx;
  ctx.seed = 11;
  p.model->bind(p.robot, ctx);
  return p;
}

exid::Dataset simulate(const Puma& p, const std::string& yaml, std::uint64_t seed) {
  exid::RunContext ctx;
  ctx.seed = seed;
  return exid_test::create<exid::Experiment>("simulate", yaml)->run(p.robot, nullptr, ctx);
}

int countOutside(const exid::Estimate& e, const Eigen::VectorXd& truth, double k,
                 const char* label) {
  int outside = 0;
  for (Eigen::Index i = 0; i < e.value.size(); ++i) {
    const double z = (e.value(i) - truth(i)) / e.std(i);
    if (std::abs(z) > k) {
      ++outside;
      std::printf("[%s] %-8s %+.4e vs true %+.4e  std %.2e (%.1f %%)  z %+.1f\n", label,
                  e.names[static_cast<std::size_t>(i)].c_str(), e.value(i), truth(i), e.std(i),
                  100 * e.std(i) / std::abs(e.value(i)), z);
    }
  }
  return outside;
}

TEST(EstimatorsPuma, FilteredLsFromNoisyPositionsOnly) {
  Puma p;
  try {
    p = puma();
  } catch (const exid::Error& e) {
    FAIL() << "PUMA 560 / differential unavailable: " << e.what();
  }
  // 1 kHz, positions with encoder-like noise, noisy torques, no qd / qdd: the real-data setting.
  const exid::Dataset d = simulate(p,
                                   "{sample_period_s: 0.001, duration_s: 10, noise_q_rad: 2e-5, "
                                   "noise_tau_Nm: 0.2, output_qd_qdd: false}",
                                   5);
  ASSERT_FALSE(d.hasVelocity());
  exid::RunContext ctx;
  const exid::Estimate e = exid_test::create<exid::Estimator>("filtered_ls", "{cutoff_hz: 20}")
                               ->estimate(*p.model, d, nullptr, ctx);
  const Eigen::VectorXd truth = p.model->baseNominal();
  std::printf(
      "filtered_ls PUMA: %d base parameters, %ld rows after decimation %ld, cond_W %.3g, sigma "
      "%.3g\n",
      static_cast<int>(e.value.size()), e.rows,
      static_cast<long>(e.details.find("decimation")->asInt()), e.cond_W, e.sigma);
  // Within 3 of its own standard deviations, allowing 2 of 52 outside (filtering leaves a small
  // errors-in-variables bias).
  EXPECT_LE(countOutside(e, truth, 3.0, "filtered_ls"), 2);
  EXPECT_LT((e.value - truth).norm() / truth.norm(), 0.05);
}

TEST(EstimatorsPuma, AllEstimatorsAgreeOnMeasuredDerivatives) {
  Puma p;
  try {
    p = puma();
  } catch (const exid::Error& e) {
    FAIL() << "PUMA 560 / differential unavailable: " << e.what();
  }
  const exid::Dataset d = simulate(p, "{duration_s: 20, noise_tau_Nm: 0.2}", 9);
  exid::RunContext ctx;
  const Eigen::VectorXd truth = p.model->baseNominal();
  const exid::Estimate b =
      exid_test::create<exid::Estimator>("batch_ls")->estimate(*p.model, d, nullptr, ctx);
  const exid::Estimate r =
      exid_test::create<exid::Estimator>("rls", "{p0: 1e8, history_stride: 100}")
          ->estimate(*p.model, d, nullptr, ctx);
  const exid::Estimate w =
      exid_test::create<exid::Estimator>("wls")->estimate(*p.model, d, nullptr, ctx);
  std::printf("PUMA batch_ls: p %d, rows %ld, cond_W %.3g, sigma %.3g (noise 0.2)\n",
              static_cast<int>(b.value.size()), b.rows, b.cond_W, b.sigma);
  EXPECT_NEAR(b.sigma, 0.2, 0.02);
  EXPECT_LE(countOutside(b, truth, 4.0, "batch_ls"), 0);
  EXPECT_LE(countOutside(w, truth, 4.0, "wls"), 0);
  EXPECT_LE(((r.value - b.value).cwiseQuotient(b.std)).cwiseAbs().maxCoeff(), 0.05);
}

}  // namespace
