// `didim`'s starts: the model's nonlinear parameters (here the friction's tanh widths) started
// on either side of the plant's. Where least squares at the model's widths gives a robot the loop
// cannot simulate, the other starts (x1/2, x2) reach the plant's widths within their std and say
// "converged"; a first start that converges is kept; details.starts and best_start say what each
// start gave, and a warning names the start it kept.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <random>

#include "closed_loop_test_util.hpp"
#include "exid/error.hpp"
#include "exid/json.hpp"
#include "exid_cli.hpp"
#include "model_test_util.hpp"

namespace {

namespace fs = std::filesystem;

using cltest::Loop;

Loop setup(double duration) { return cltest::pumaTracking(duration, "exid_didim_starts_"); }

exid::Dataset noisyTorques(const exid::Dataset& clean, double tau_noise, std::uint64_t seed) {
  exid::Dataset d = clean;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd(0.0, 1.0);
  for (int k = 0; k < d.size(); ++k)
    for (int j = 0; j < d.dof(); ++j) d.tau(k, j) += tau_noise * nd(rng);
  return d;
}

std::shared_ptr<exid::ObservationModel> widthsAt(const Loop& s, double width) {
  return mtest::model("differential",
                      fmt::format("{{offset: true, coulomb_smoothing_rad_s: [{}]}}", width),
                      s.robot);
}

std::string startsSummary(const exid::Estimate& e) {
  std::string out;
  const exid::Json& st = *e.details.find("starts");
  for (std::size_t i = 0; i < st.size(); ++i) {
    const exid::Json& o = st.at(i);
    if (o.find("error"))
      out += fmt::format("  start {}: from {}: not simulated\n", i + 1, o.find("from")->asString());
    else
      out += fmt::format("  start {}: from {} to {}: objective {:.8g}, {} iterations, {}\n", i + 1,
                         o.find("from")->asString(), o.find("to")->asString(),
                         o.find("objective")->asDouble(), o.find("iterations")->dump(),
                         o.find("first_order")->asBool() ? "first order" : "not first order");
  }
  return out;
}

// The plant's tanh widths are 0.05 rad/s; the model's start at 0.025 (x1/2) or 0.15 (x3): least
// squares on the rows there gives a robot the loop cannot simulate (its mass matrix is not
// positive definite), so one start fails; the default starts go on from x2 (or x1/2) of the
// first and reach the plant's widths within their std, "converged".
TEST(DidimStarts, WidthsFromEitherSideOfThePlantAreRecoveredWhereOneStartCannotBeSimulated) {
  const Loop s = setup(6.0);
  const exid::Dataset d = noisyTorques(s.data, 0.1, 11);
  for (double f : {0.5, 3.0}) {
    auto model = widthsAt(s, 0.05 * f);
    auto one = exid_test::create<exid::Estimator>("didim", "{" + s.params + ", starts: 1}");
    EXPECT_THROW(one->estimate(*model, d, nullptr, mtest::context()), exid::Error) << f;
    auto didim = exid_test::create<exid::Estimator>("didim", "{" + s.params + "}");
    const exid::Estimate e = didim->estimate(*model, d, nullptr, mtest::context());
    ASSERT_EQ(e.nonlinear.size(), 6);
    double zmax = 0;
    for (Eigen::Index k = 0; k < e.nonlinear.size(); ++k)
      zmax = std::max(zmax, std::abs(e.nonlinear[k] - 0.05) / e.nonlinear_std[k]);
    const int best = static_cast<int>(e.details.find("best_start")->asDouble());
    std::printf(
        "[didim starts] widths started x%g: best start %d, converged %s, widths within "
        "%.2f std, %.1f s\n%s",
        f, best, e.details.find("converged")->dump().c_str(), zmax,
        e.details.find("wall_s")->asDouble(), startsSummary(e).c_str());
    EXPECT_TRUE(e.details.find("converged")->asBool());
    EXPECT_GT(best, 1);
    EXPECT_LT(zmax, 2.5);
    const exid::Json& first = e.details.find("starts")->at(0);
    ASSERT_TRUE(first.find("error") != nullptr);
    EXPECT_NE(first.find("error")->asString().find("mass matrix"), std::string::npos);
  }
}

// didim on the loop's recording with noisy torques (seed 12), the model's widths at `width`,
// the loop's parameters and `extra`.
exid::Estimate didimAt(const Loop& s, double width, const std::string& extra) {
  const exid::Dataset d = noisyTorques(s.data, 0.1, 12);
  auto model = widthsAt(s, width);
  return exid_test::create<exid::Estimator>("didim", "{" + s.params + extra + "}")
      ->estimate(*model, d, nullptr, mtest::context());
}

// From widths x2 of the plant's the first start converges: the other starts (x1/2 and x4 of
// it) end no lower beyond the first-order test's region (lowest(): first_order_std^2 s^2), so
// the estimate is the single start's. (With the rule of 1e-7 of the objective, the second start,
// 2.2e-6 lower at the same widths to 3e-4, replaced it.)
TEST(DidimStarts, AFirstStartThatConvergesIsKept) {
  const Loop s = setup(6.0);
  const exid::Estimate e1 = didimAt(s, 0.1, ", starts: 1");
  const exid::Estimate e = didimAt(s, 0.1, "");
  std::printf(
      "[didim starts] widths started x2: best start %s, converged %s, %.1f s (one "
      "start: %.1f s)\n%s",
      e.details.find("best_start")->dump().c_str(), e.details.find("converged")->dump().c_str(),
      e.details.find("wall_s")->asDouble(), e1.details.find("wall_s")->asDouble(),
      startsSummary(e).c_str());
  EXPECT_TRUE(e1.details.find("converged")->asBool());
  EXPECT_TRUE(e.details.find("converged")->asBool());
  EXPECT_EQ(e.details.find("best_start")->asDouble(), 1.0);
  EXPECT_EQ(e.details.find("starts")->size(), 3u);
  EXPECT_EQ((e.value - e1.value).norm(), 0.0);
  EXPECT_EQ((e.nonlinear - e1.nonlinear).norm(), 0.0);
}

// The other side of the rule above: a later start lower than the first by more than the
// first-order test's region (first_order_std^2 s^2, s^2 = rss / (m - p - L - D)) replaces it.
// Two iterations from widths x2 leave the first start short of its minimum; the second starts at
// the plant's widths and ends below it by far more than the region.
TEST(DidimStarts, ALaterStartLowerByMoreThanTheFirstOrderRegionIsKept) {
  const exid::Estimate e = didimAt(setup(6.0), 0.1, ", max_iterations: 2");
  std::printf("[didim starts] two iterations from widths x2: best start %s\n%s",
              e.details.find("best_start")->dump().c_str(), startsSummary(e).c_str());
  const exid::Json& st = *e.details.find("starts");
  ASSERT_GE(st.size(), 2u);
  ASSERT_TRUE(st.at(0).find("objective") && st.at(1).find("objective"));
  const double first = st.at(0).find("objective")->asDouble();
  const double second = st.at(1).find("objective")->asDouble();
  const double m = static_cast<double>(e.rows);
  const double region = first / (m - static_cast<double>(e.value.size() + e.nonlinear.size()));
  EXPECT_LT(second, first - 10 * region);  // (first_order_std: 1, the default)
  EXPECT_EQ(e.details.find("best_start")->asDouble(), 2.0);
}

// Stopped early, the warning says which start it kept and where it stopped.
TEST(DidimStarts, ANotConvergedWarningNamesTheStart) {
  const Loop s = setup(6.0);
  const exid::Dataset d = noisyTorques(s.data, 0.1, 11);
  auto model = widthsAt(s, 0.15);
  const exid::Estimate e =
      exid_test::create<exid::Estimator>("didim", "{" + s.params + ", max_iterations: 1}")
          ->estimate(*model, d, nullptr, mtest::context());
  EXPECT_FALSE(e.details.find("converged")->asBool());
  const std::string w = e.details.find("warnings")->at(0).asString();
  std::printf("[didim starts] %s\n", w.c_str());
  const int best = static_cast<int>(e.details.find("best_start")->asDouble());
  EXPECT_NE(w.find(fmt::format("(start {} of 3,", best)), std::string::npos) << w;
  EXPECT_NE(w.find("the model's nonlinear parameters x"), std::string::npos) << w;
  EXPECT_NE(w.find("with rss "), std::string::npos) << w;
  EXPECT_NE(w.find("gradient norm"), std::string::npos) << w;
}

}  // namespace
