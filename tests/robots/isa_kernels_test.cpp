// The hot dynamics kernels on every instruction set this build has and this CPU runs
// (exid/isa.hpp) give the portable copy's results to rounding, on the shipped robots at random
// states: max |x - x_portable| <= 1e-13 max |x_portable| over each output (FMA contracts a*b + c
// with one rounding instead of two, so the copies differ in the last bits, not more).
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "exid/dynamics.hpp"
#include "exid/isa.hpp"
#include "exid/robot_loaders.hpp"

namespace {

using exid::Isa;
using exid::RobotModel;

constexpr double kTol = 1e-13;

// The shipped robots; the TX40 is its published URDF (data/staubli_tx40) with the exid extension
// robots/tx40/tx40_exid.xml, as the urdf plugin loads it.
const char* const kRobots[] = {
    "panda/panda.yaml",       "puma560/puma560.yaml", "puma560/puma560.urdf",  "tx40/tx40_exid.xml",
    "stanford/stanford.yaml", "irp6/irp6.yaml",       "planar2r/planar2r.yaml"};

RobotModel load(const std::string& rel) {
  exid::LoadOptions o;
  std::vector<std::string> warnings;
  o.warnings = &warnings;
  const std::string src(EXID_SOURCE_DIR);
  if (rel == "tx40/tx40_exid.xml") {
    o.urdf_extension = src + "/robots/" + rel;
    return exid::loadUrdf(src + "/data/staubli_tx40/urdf/tx40_mdh_modified.urdf", o);
  }
  return exid::loadRobotFile(src + "/robots/" + rel, o);
}

Eigen::VectorXd random(std::mt19937& rng, Eigen::Index n, double s) {
  std::uniform_real_distribution<double> u(-s, s);
  Eigen::VectorXd x(n);
  for (Eigen::Index i = 0; i < n; ++i) x[i] = u(rng);
  return x;
}

// Every kernel's outputs for a set of random states, in one vector per output.
struct Outputs {
  std::vector<std::pair<std::string, Eigen::MatrixXd>> items;
  void add(const std::string& what, const Eigen::MatrixXd& x) { items.emplace_back(what, x); }
};

Outputs runAll(const RobotModel& m, unsigned seed) {
  const int n = m.dof();
  std::mt19937 rng(seed);
  auto d = exid::makeDynamicsData(m);
  Outputs out;
  Eigen::MatrixXd Y(n, 10 * n);
  exid::GramAccumulator gram(10 * n);
  for (int s = 0; s < 16; ++s) {
    const std::string at = " sample " + std::to_string(s);
    const Eigen::VectorXd q = random(rng, n, 3.0), qd = random(rng, n, 2.0),
                          qdd = random(rng, n, 5.0), pi = random(rng, 10 * n, 1.0);
    const Eigen::MatrixXd G = random(rng, 10 * n * n, 1.0).reshaped(n, 10 * n);
    const Eigen::RowVectorXd Gk = random(rng, 10 * n, 1.0).transpose(),
                             Gu = random(rng, 10 * n, 1.0).transpose();
    exid::torqueRegressor(m, *d, q, qd, qdd, Y);
    out.add("torqueRegressor" + at, Y);
    gram.add(Y);
    out.add("inverseDynamics" + at, exid::inverseDynamics(m, *d, q, qd, qdd));
    out.add("inverseDynamics(pi)" + at, exid::inverseDynamics(m, *d, q, qd, qdd, &pi));
    Eigen::RowVectorXd K(10 * n), U(10 * n);
    exid::energyRegressor(m, *d, q, qd, K, U);
    out.add("energyRegressor kinetic" + at, K);
    out.add("energyRegressor potential" + at, U);
    Eigen::VectorXd a, b, c;
    exid::torqueRegressorVjp(m, *d, q, qd, qdd, G, &a, &b, &c);
    out.add("torqueRegressorVjp d_q" + at, a);
    out.add("torqueRegressorVjp d_qd" + at, b);
    out.add("torqueRegressorVjp d_qdd" + at, c);
    exid::energyRegressorVjp(m, *d, q, qd, Gk, Gu, &a, &b);
    out.add("energyRegressorVjp d_q" + at, a);
    out.add("energyRegressorVjp d_qd" + at, b);
  }
  out.add("GramAccumulator", gram.matrix());
  return out;
}

class IsaKernels : public ::testing::Test {
 protected:
  void TearDown() override { exid::setActiveIsa(saved_); }
  Isa saved_ = exid::activeIsa();
};

TEST_F(IsaKernels, EveryCopyGivesThePortableResultsToRounding) {
  const std::vector<Isa> isas = exid::availableIsas();
  ASSERT_FALSE(isas.empty());
  EXPECT_EQ(isas.front(), Isa::Portable);
  for (const char* file : kRobots) {
    const RobotModel m = load(file);
    exid::setActiveIsa(Isa::Portable);
    const Outputs ref = runAll(m, 7);
    for (Isa isa : isas) {
      exid::setActiveIsa(isa);
      ASSERT_EQ(exid::activeIsa(), isa);
      const Outputs got = runAll(m, 7);
      ASSERT_EQ(got.items.size(), ref.items.size());
      double worst = 0.0;
      for (size_t i = 0; i < ref.items.size(); ++i) {
        const Eigen::MatrixXd& r = ref.items[i].second;
        const Eigen::MatrixXd& g = got.items[i].second;
        ASSERT_EQ(g.rows(), r.rows());
        ASSERT_EQ(g.cols(), r.cols());
        const double scale = r.cwiseAbs().maxCoeff();
        const double err = (g - r).cwiseAbs().maxCoeff();
        EXPECT_LE(err, kTol * scale) << file << " " << exid::isaName(isa) << " "
                                     << ref.items[i].first << ": " << err << " vs scale " << scale;
        if (scale > 0) worst = std::max(worst, err / scale);
      }
      std::printf("%-24s %-8s worst relative difference %.2e\n", file, exid::isaName(isa), worst);
    }
  }
}

// EXID_ISA (tests/CMakeLists.txt runs this test with EXID_ISA=auto too) picks the copy in use;
// unset, the portable one (the same numbers on every CPU); auto, the best this CPU runs.
TEST(Isa, FollowsTheEnvironment) {
  const char* e = std::getenv("EXID_ISA");
  const std::vector<Isa> isas = exid::availableIsas();
  if (!e || !*e || std::strcmp(e, "portable") == 0) {
    EXPECT_EQ(exid::activeIsa(), Isa::Portable);
  } else if (std::strcmp(e, "auto") == 0) {
    EXPECT_EQ(exid::activeIsa(), isas.back());
  }
  std::printf("EXID_ISA=%s: %s\n", e ? e : "(unset)", exid::isaName(exid::activeIsa()));
}

TEST(Isa, Names) {
  EXPECT_STREQ(exid::isaName(Isa::Portable), "portable");
  EXPECT_STREQ(exid::isaName(Isa::Avx2), "avx2");
}

}  // namespace
