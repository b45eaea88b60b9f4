// GramAccumulator == W^T W.
#include <gtest/gtest.h>

#include <random>

#include "dyn_reference.hpp"
#include "dyn_robots.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"

using namespace exid;
using namespace exid::testing;

TEST(GramAccumulator, MatchesDenseProduct) {
  std::mt19937 rng(71);
  const RobotModel m = puma560Standard();
  auto d = makeDynamicsData(m);
  const int N = 1000;  // not a multiple of the batch size
  Eigen::MatrixXd W(6 * N, 60);
  GramAccumulator acc(60);
  Eigen::MatrixXd Y(6, 60);
  for (int s = 0; s < N; ++s) {
    torqueRegressor(m, *d, randomVec(rng, 6, 3), randomVec(rng, 6, 2), randomVec(rng, 6, 5), Y);
    W.middleRows(6 * s, 6) = Y;
    acc.add(Y);
  }
  const Eigen::MatrixXd ref = W.transpose() * W;
  EXPECT_LT((acc.matrix() - ref).cwiseAbs().maxCoeff(), 1e-12 * ref.cwiseAbs().maxCoeff());
  EXPECT_EQ(acc.rowsAdded(), 6L * N);
  // more rows after reading, weights, odd sizes, reset
  const Eigen::MatrixXd R = Eigen::MatrixXd::Random(7, 60);
  acc.addWeighted(R, 2.5);
  EXPECT_LT((acc.matrix() - (ref + 2.5 * R.transpose() * R)).cwiseAbs().maxCoeff(),
            1e-12 * ref.cwiseAbs().maxCoeff());
  acc.reset(13);
  Eigen::MatrixXd S = Eigen::MatrixXd::Random(301, 13);
  S.topLeftCorner(100, 5).setZero();
  acc.add(S);
  EXPECT_LT((acc.matrix() - S.transpose() * S).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_THROW(acc.add(Eigen::MatrixXd::Zero(2, 12)), Error);
}
