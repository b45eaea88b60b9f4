// Monte-Carlo checks of the estimators on the test model: over many noise seeds the estimates
// are unbiased within their reported std, and the reported std matches the empirical spread
// within 20 %. WLS beats OLS when the equations' noise levels differ.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "estimator_test_model.hpp"
#include "exid_test.hpp"

namespace {

using est_test::DataOptions;

constexpr int kSeeds = 200;

struct Stats {
  Eigen::VectorXd mean_err, emp_sd, rep_sd;
};

Stats monteCarlo(const std::string& name, const std::string& params,
                 const est_test::PendulumModel& m, int n, DataOptions o) {
  auto est = exid_test::create<exid::Estimator>(name, params);
  const int p = m.numBase();
  const Eigen::VectorXd truth = m.baseNominal();
  Eigen::MatrixXd err(kSeeds, p), sd(kSeeds, p);
  exid::RunContext ctx;
  for (int s = 0; s < kSeeds; ++s) {
    o.seed = 1000 + static_cast<std::uint64_t>(s);
    const exid::Dataset d = est_test::makeData(m, n, o);
    const exid::Estimate e = est->estimate(m, d, nullptr, ctx);
    err.row(s) = (e.value - truth).transpose();
    sd.row(s) = e.std.transpose();
  }
  Stats st;
  st.mean_err = err.colwise().mean().transpose();
  st.emp_sd = ((err.rowwise() - st.mean_err.transpose()).colwise().squaredNorm() / (kSeeds - 1.0))
                  .cwiseSqrt()
                  .transpose();
  st.rep_sd = sd.colwise().mean().transpose();
  return st;
}

void expectConsistent(const std::string& label, const Stats& st,
                      const std::vector<std::string>& names) {
  for (Eigen::Index i = 0; i < st.mean_err.size(); ++i) {
    const double ratio = st.rep_sd(i) / st.emp_sd(i);
    std::printf("[%s] %-6s bias %+.2e  (%.2f sd of mean)  reported/empirical std %.3f\n",
                label.c_str(), names[static_cast<std::size_t>(i)].c_str(), st.mean_err(i),
                st.mean_err(i) / (st.emp_sd(i) / std::sqrt(kSeeds)), ratio);
    // Unbiased: the mean error is within 4 standard errors of the mean, and within one reported
    // std.
    EXPECT_LE(std::abs(st.mean_err(i)), 4.0 * st.emp_sd(i) / std::sqrt(kSeeds))
        << label << " " << i;
    EXPECT_LE(std::abs(st.mean_err(i)), st.rep_sd(i)) << label << " " << i;
    EXPECT_NEAR(ratio, 1.0, 0.2) << label << " " << names[static_cast<std::size_t>(i)];
  }
}

TEST(EstimatorsMonteCarlo, UnbiasedWithHonestStd) {
  const int n = 2;
  auto m = est_test::makeModel(n);
  DataOptions o;
  o.samples = 400;
  o.dt = 0.01;
  o.tau_noise = {0.1, 0.1};
  const auto& names = m->base().names;
  expectConsistent("batch_ls", monteCarlo("batch_ls", "{}", *m, n, o), names);
  expectConsistent("rls", monteCarlo("rls", "{history_stride: 1000}", *m, n, o), names);
  expectConsistent("wls", monteCarlo("wls", "{}", *m, n, o), names);
  // filtered_ls on exact positions and noisy torques: the parallel decimation filters the noise.
  DataOptions of = o;
  of.samples = 1600;
  of.dt = 0.0025;
  expectConsistent("filtered_ls",
                   monteCarlo("filtered_ls", "{cutoff_hz: 0, decimation: 4}", *m, n, of), names);
}

TEST(EstimatorsMonteCarlo, WlsBeatsOlsWhenNoiseLevelsDiffer) {
  const int n = 2;
  auto m = est_test::makeModel(n);
  DataOptions o;
  o.samples = 400;
  o.dt = 0.01;
  o.tau_noise = {0.02, 0.4};
  const auto& names = m->base().names;
  const Stats w = monteCarlo("wls", "{}", *m, n, o);
  const Stats b = monteCarlo("batch_ls", "{}", *m, n, o);
  expectConsistent("wls hetero", w, names);
  for (int i = 0; i < 5; ++i) {  // the parameters shared by both equations
    std::printf("[wls vs ols] %-6s empirical std %.3e vs %.3e\n",
                names[static_cast<std::size_t>(i)].c_str(), w.emp_sd(i), b.emp_sd(i));
    EXPECT_LT(w.emp_sd(i), 0.5 * b.emp_sd(i)) << names[static_cast<std::size_t>(i)];
  }
}

}  // namespace
