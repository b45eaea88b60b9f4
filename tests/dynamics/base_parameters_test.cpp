// Numerical base parameters (Gautier 1990): counts against theory / literature, exactness.
#include "exid/base_parameters.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "dyn_reference.hpp"
#include "dyn_robots.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"

using namespace exid;
using namespace exid::testing;

namespace {

Eigen::VectorXd randomInLimits(const RobotModel& m, std::mt19937& rng) {
  Eigen::VectorXd q(m.dof());
  for (int j = 0; j < m.dof(); ++j) {
    const JointLimits& L = m.limits[static_cast<size_t>(j)];
    const double lo = std::max(L.q_min, -M_PI), hi = std::min(L.q_max, M_PI);
    q[j] = std::uniform_real_distribution<double>(lo, hi)(rng);
  }
  return q;
}

// Stacked actuator regressor over random samples (qd away from zero so sign(qd) is excited).
Eigen::MatrixXd stack(const RobotModel& m, const DriveColumns& cols, int samples,
                      std::mt19937& rng) {
  auto d = makeDynamicsData(m);
  const int n = m.dof(), p = numParameters(m, cols);
  Eigen::MatrixXd W(samples * n, p);
  for (int s = 0; s < samples; ++s) {
    const Eigen::VectorXd q = randomInLimits(m, rng), qd = randomVec(rng, n, 2.0),
                          qdd = randomVec(rng, n, 5.0);
    actuatorRegressor(m, *d, cols, q, qd, qdd, W.middleRows(s * n, n));
  }
  return W;
}

BaseParameters base(const RobotModel& m, const DriveColumns& cols, std::mt19937& rng) {
  return computeBaseParameters(stack(m, cols, 150, rng), parameterNames(m, cols));
}

void checkExact(const RobotModel& m, const DriveColumns& cols, const BaseParameters& bp,
                std::mt19937& rng) {
  const Eigen::MatrixXd W = stack(m, cols, 30, rng);
  const Eigen::VectorXd pi = randomVec(rng, numParameters(m, cols), 1.0);
  const Eigen::VectorXd full = W * pi, red = bp.columns(W) * bp.reduce(pi);
  EXPECT_LT((full - red).cwiseAbs().maxCoeff(), 1e-9 * (1 + full.cwiseAbs().maxCoeff())) << m.name;
  EXPECT_EQ(static_cast<int>(bp.names.size()), bp.rank());
  EXPECT_EQ(static_cast<int>(bp.expressions.size()), bp.rank());
  EXPECT_EQ(bp.K.rows(), bp.rank());
  EXPECT_EQ(bp.K.cols(), bp.numFull());
  EXPECT_EQ(bp.rank() + static_cast<int>(bp.dependent.size()), bp.numFull());
  EXPECT_TRUE(std::is_sorted(bp.independent.begin(), bp.independent.end()));
}

}  // namespace

TEST(BaseParameters, Puma560Counts) {
  std::mt19937 rng(41);
  for (const RobotModel& m : {puma560Standard(), puma560Akb()}) {
    DriveColumns none, ia, all;
    ia.rotor_inertia = true;
    all.rotor_inertia = all.viscous = all.coulomb = true;
    const BaseParameters b0 = base(m, none, rng), b1 = base(m, ia, rng), b2 = base(m, all, rng);
    EXPECT_EQ(b0.rank(), 36) << m.name;  // classical value (Mayeda et al.; Gautier & Khalil)
    EXPECT_EQ(b1.rank(), 40) << m.name;  // Ia1, Ia2 regroup with ZZ1R, ZZ2R
    EXPECT_EQ(b2.rank(), 52) << m.name;
    checkExact(m, none, b0, rng);
    checkExact(m, all, b2, rng);
  }
}

TEST(BaseParameters, PandaCount) {
  std::mt19937 rng(42);
  const RobotModel m = panda();
  const BaseParameters b = base(m, {}, rng);
  EXPECT_EQ(b.rank(), 43);  // Gaz et al. 2019, Table III
  checkExact(m, {}, b, rng);
}

TEST(BaseParameters, Planar2R) {
  // Planar 2R, parallel z axes, standard DH (frames at the link tips). Only ZZj, MXj, MYj and Mj
  // enter the planar dynamics (rotation about z only, motion in the x-y plane), i.e. 8 columns.
  // M1 and M2 are absorbed by the parallel-axis and first-moment shifts (M_j into ZZ_j, MX_j and
  // the previous link's ZZ/MX): vertical plane (gravity in the plane) -> 6 base parameters
  // ZZ1R, MX1R, MY1, ZZ2R, MX2R, MY2. In a horizontal plane the first link's first moments do
  // not produce torque except through qdd1 (MX1 regroups into ZZ1R, MY1 vanishes) -> 4:
  // ZZ1R, ZZ2R, MX2R, MY2.
  std::mt19937 rng(43);
  const BaseParameters bv = base(planar2R(true), {}, rng);
  EXPECT_EQ(bv.rank(), 6);
  EXPECT_EQ(bv.names, (std::vector<std::string>{"ZZ1R", "MX1R", "MY1", "ZZ2R", "MX2R", "MY2"}));
  for (size_t k = 0; k < bv.names.size(); ++k)
    std::cout << bv.names[k] << " = " << bv.expressions[k] << "\n";
  checkExact(planar2R(true), {}, bv, rng);
  const BaseParameters bh = base(planar2R(false), {}, rng);
  EXPECT_EQ(bh.rank(), 4);
  EXPECT_EQ(bh.names, (std::vector<std::string>{"ZZ1R", "ZZ2R", "MX2R", "MY2"}));
  checkExact(planar2R(false), {}, bh, rng);
}

TEST(BaseParameters, ExpressionsAndRandomTrees) {
  std::mt19937 rng(44);
  for (int t = 0; t < 5; ++t) {
    const RobotModel m = randomTree(rng, 2 + t, false);
    const BaseParameters b = base(m, {}, rng);
    EXPECT_GT(b.rank(), 0);
    checkExact(m, {}, b, rng);
  }
  // A hand-made example: column 2 = 2*col0 - col1, column 3 zero.
  Eigen::MatrixXd W = Eigen::MatrixXd::Random(20, 4);
  W.col(2) = 2 * W.col(0) - 0.5 * W.col(1);
  W.col(3).setZero();
  const BaseParameters b = computeBaseParameters(W, {"A", "B", "C", "D"});
  EXPECT_EQ(b.rank(), 2);
  EXPECT_EQ(b.independent, (std::vector<int>{0, 1}));
  EXPECT_EQ(b.dependent, (std::vector<int>{2, 3}));
  EXPECT_EQ(b.names, (std::vector<std::string>{"AR", "BR"}));
  EXPECT_EQ(b.expressions[0], "A + 2*C");
  EXPECT_EQ(b.expressions[1], "B - 0.5*C");
}

// A coefficient at the level of rounding (its share of the dependent column, on the columns'
// scale, far below the rank tolerance) neither renames a parameter nor enters its expression;
// a small but real one does. B's column is a thousandth of A's: the raw coefficient of a 1e-12
// share is 2e-9 (an absolute threshold would keep it), of a 1e-6 share 2e-3.
TEST(BaseParameters, CoefficientsBelowRoundingOnTheColumnsScaleAreZero) {
  Eigen::MatrixXd W = Eigen::MatrixXd::Random(30, 3);
  W.col(1) *= 1e-3;
  const double ratio = W.col(0).norm() / W.col(1).norm();  // ~1e3
  for (const double share : {1e-12, 1e-6}) {
    SCOPED_TRACE(share);
    const double delta = share * 2 * ratio;  // C = 2 A + delta B: B's share of C is ~share
    W.col(2) = 2 * W.col(0) + delta * W.col(1);
    const BaseParameters b = computeBaseParameters(W, {"A", "B", "C"});
    ASSERT_EQ(b.rank(), 2);
    EXPECT_EQ(b.names[0], "AR");
    EXPECT_EQ(b.expressions[0], "A + 2*C");
    if (share < 1e-10) {
      EXPECT_EQ(b.names[1], "B");
      EXPECT_EQ(b.expressions[1], "B");
      EXPECT_EQ(b.K(1, 2), 0.0);
    } else {
      EXPECT_EQ(b.names[1], "BR");
      EXPECT_NEAR(b.K(1, 2), delta, 1e-9 * delta);
    }
  }
}

// A study may name the base columns to keep (BaseParameterOptions::preferred): the same
// identifiable space (rank, exactness), other columns and regroupings; a dependent or unknown
// name is an error naming it.
TEST(BaseParameters, PreferredColumnsAreKeptAndTheSpaceIsTheSame) {
  std::mt19937 rng(44);
  const RobotModel m = planar2R(true);
  const Eigen::MatrixXd W = stack(m, {}, 150, rng);
  const auto names = parameterNames(m, {});
  BaseParameterOptions o;
  o.preferred = {"M2", "M1"};
  const BaseParameters b = computeBaseParameters(W, names, o);
  EXPECT_EQ(b.rank(), 6);
  // In the natural order M2 regroups into ZZ2R = ZZ2 - a2^2 M2 and MX2R = MX2 + a2 M2 (and M1
  // likewise): the column of M2 is a combination of those of ZZ2 and MX2. With M2 and M1
  // named they are kept and MX2, MX1 regroup into them instead (names in the natural order).
  EXPECT_EQ(b.names, (std::vector<std::string>{"ZZ1R", "MY1", "M1R", "ZZ2R", "MY2", "M2R"}))
      << "got " << ::testing::PrintToString(b.names);
  checkExact(m, {}, b, rng);
  // Same identifiable space as the natural choice: each set's columns span the other's.
  const BaseParameters nat = computeBaseParameters(W, names);
  const Eigen::MatrixXd Wb = b.columns(W), Wn = nat.columns(W);
  const Eigen::MatrixXd X = Wb.colPivHouseholderQr().solve(Wn);
  EXPECT_LT((Wb * X - Wn).norm(), 1e-9 * Wn.norm());
  // The PUMA 560: 36 base parameters whatever the (independent) choice.
  const RobotModel puma = puma560Standard();
  const Eigen::MatrixXd Wp = stack(puma, {}, 150, rng);
  BaseParameterOptions op;
  op.preferred = {"YY2", "M3", "YY3"};
  const BaseParameters bp = computeBaseParameters(Wp, parameterNames(puma, {}), op);
  EXPECT_EQ(bp.rank(), 36);
  for (const char* kept : {"YY2", "M3", "YY3"}) {
    const auto it = std::find(bp.names.begin(), bp.names.end(), std::string(kept));
    const auto itR = std::find(bp.names.begin(), bp.names.end(), std::string(kept) + "R");
    EXPECT_TRUE(it != bp.names.end() || itR != bp.names.end()) << kept;
  }
  checkExact(puma, {}, bp, rng);
}

TEST(BaseParameters, APreferredColumnThatIsDependentOrUnknownIsAnErrorNamingIt) {
  std::mt19937 rng(45);
  const RobotModel m = planar2R(true);
  const Eigen::MatrixXd W = stack(m, {}, 150, rng);
  const auto names = parameterNames(m, {});
  auto message = [&](std::vector<std::string> preferred) {
    BaseParameterOptions o;
    o.preferred = std::move(preferred);
    try {
      computeBaseParameters(W, names, o);
    } catch (const exid::Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  // M2 regroups into ZZ1R, MX1R, ZZ2R and MX2R: its column is a combination of those four.
  const std::string dep = message({"ZZ1", "MX1", "ZZ2", "MX2", "M2"});
  EXPECT_NE(dep.find("'M2' is a combination of the columns named before it (ZZ1, MX1, ZZ2, MX2)"),
            std::string::npos)
      << dep;
  const std::string zero = message({"XX1"});  // no torque in a planar arm
  EXPECT_NE(zero.find("'XX1' is not identifiable"), std::string::npos) << zero;
  const std::string unknown = message({"ZZ9"});
  EXPECT_NE(unknown.find("'ZZ9' is not a parameter of the model"), std::string::npos) << unknown;
  const std::string twice = message({"ZZ1", "ZZ1"});
  EXPECT_NE(twice.find("'ZZ1' is named twice"), std::string::npos) << twice;
}

// Rule::Pivoted keeps the columns of a QR with column pivoting on the unit-norm columns: on a
// stack without close residuals, the set Eigen's ColPivHouseholderQR (norm downdating, an
// independent implementation) keeps; and where a later column's residual is larger than an
// earlier one's by rounding alone, the earlier one.
TEST(BaseParameters, PivotedRuleKeepsTheColumnPivotedQrsColumns) {
  std::mt19937 rng(46);
  // Rank 7 in 12 columns of very different scales.
  auto randomMatrix = [&](int r, int c) {
    Eigen::MatrixXd M(r, c);
    for (int k = 0; k < c; ++k) M.col(k) = randomVec(rng, r, 1.0);
    return M;
  };
  const Eigen::MatrixXd G = randomMatrix(200, 7), H = randomMatrix(7, 12);
  Eigen::MatrixXd W = G * H;
  for (int k = 0; k < W.cols(); ++k) W.col(k) *= std::pow(10.0, (k % 5) - 2);
  const std::vector<int> order = pivotedBaseColumns(W);
  ASSERT_EQ(order.size(), 7u);
  // Every unit-norm column ties at the first step: the lowest index is kept. Eigen's QR picks
  // by the rounding of its norms there, so that column is made larger by 1e-6 for it (which
  // leaves every later residual as it was).
  EXPECT_EQ(order[0], 0);
  Eigen::MatrixXd A = W;
  for (int k = 0; k < A.cols(); ++k) A.col(k).normalize();
  A.col(0) *= 1.0 + 1e-6;
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
  for (int k = 0; k < 7; ++k) EXPECT_EQ(order[k], qr.colsPermutation().indices()[k]) << k;

  // Where the rules differ: x, x + 1e-3 y, y. The natural order keeps the first two; pivoting
  // keeps x, then y (residual 1 against 1e-3).
  Eigen::MatrixXd D(50, 3);
  D.col(0) = randomVec(rng, 50, 1.0);
  D.col(2) = randomVec(rng, 50, 1.0);
  D.col(2) -= D.col(0) * (D.col(0).dot(D.col(2)) / D.col(0).squaredNorm());
  D.col(1) = D.col(0) + 1e-3 * D.col(2);
  EXPECT_EQ(pivotedBaseColumns(D), (std::vector<int>{0, 2}));
  BaseParameterOptions o;
  o.rule = BaseParameterOptions::Rule::Pivoted;
  const BaseParameters piv = computeBaseParameters(D, {"x", "x2", "y"}, o);
  EXPECT_EQ(piv.independent, (std::vector<int>{0, 2}));
  EXPECT_EQ(computeBaseParameters(D, {"x", "x2", "y"}).independent, (std::vector<int>{0, 1}));

  // Equal residuals: a, then b + 1e-5 a and b. After a, the first's residual is 1 - 5e-11 of
  // the second's: rounding's size, not structure. The lower index is kept.
  Eigen::MatrixXd T(50, 3);
  T.col(0) = randomVec(rng, 50, 1.0);
  T.col(2) = randomVec(rng, 50, 1.0);
  T.col(2) -= T.col(0) * (T.col(0).dot(T.col(2)) / T.col(0).squaredNorm());
  T.col(2) *= T.col(0).norm() / T.col(2).norm();
  T.col(1) = T.col(2) + 1e-5 * T.col(0);
  EXPECT_EQ(pivotedBaseColumns(T), (std::vector<int>{0, 1}));
  // ... and a real difference (1 - 5e-7) is not a tie.
  T.col(1) = T.col(2) + 1e-3 * T.col(0);
  EXPECT_EQ(pivotedBaseColumns(T), (std::vector<int>{0, 2}));

  // The PUMA 560: 36 base parameters, exact, and with named columns it is an error.
  const RobotModel puma = puma560Standard();
  const Eigen::MatrixXd Wp = stack(puma, {}, 150, rng);
  const BaseParameters bp = computeBaseParameters(Wp, parameterNames(puma, {}), o);
  EXPECT_EQ(bp.rank(), 36);
  checkExact(puma, {}, bp, rng);
  o.preferred = {"ZZ1"};
  EXPECT_THROW(computeBaseParameters(Wp, parameterNames(puma, {}), o), exid::Error);
}
