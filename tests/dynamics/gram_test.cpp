// GramAccumulator == W^T W.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "dyn_reference.hpp"
#include "dyn_robots.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/isa.hpp"

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

// gramUpdate: the lower triangle of G + B^T B, with the same bits from every lane copy this CPU
// runs (exid/isa.hpp: the baseline's SSE2 and AVX without FMA), for sizes around the vector
// widths and row counts around the four-row groups.
TEST(GramUpdate, LowerTriangleOfBtBWithTheSameBitsFromEveryLaneCopy) {
  std::mt19937 rng(72);
  std::normal_distribution<double> N(0.0, 1.0);
  const Isa isa0 = activeIsa();
  const Lanes lanes0 = activeLanes();
  setActiveIsa(Isa::Portable);
  int compared = 0;
  for (int m : {1, 3, 4, 5, 8, 13, 53}) {
    for (int k : {1, 3, 4, 7, 130}) {
      const int ld = (m + 3) & ~3;
      std::vector<double> B(static_cast<std::size_t>(k * ld), 0.0);
      Eigen::MatrixXd Bd(k, m);
      for (int r = 0; r < k; ++r)
        for (int c = 0; c < m; ++c) B[static_cast<std::size_t>(r * ld + c)] = Bd(r, c) = N(rng);
      std::vector<double> G0(static_cast<std::size_t>(m * ld));
      for (double& g : G0) g = N(rng);
      std::vector<std::vector<double>> out;
      for (Lanes lanes : availableLanes()) {
        setActiveLanes(lanes);
        std::vector<double> G = G0;
        gramUpdate(G.data(), ld, B.data(), ld, k, m);
        out.push_back(G);
      }
      const Eigen::MatrixXd ref = Bd.transpose() * Bd;
      for (int i = 0; i < m; ++i)
        for (int j = 0; j < m; ++j) {
          const double g = out[0][static_cast<std::size_t>(i * ld + j)],
                       g0 = G0[static_cast<std::size_t>(i * ld + j)];
          if (j <= i)
            EXPECT_NEAR(g, g0 + ref(i, j), 1e-12 * (1.0 + std::abs(ref(i, j)))) << m << " " << k;
          else
            EXPECT_EQ(g, g0) << "above the diagonal: " << m << " " << k;
        }
      for (std::size_t c = 1; c < out.size(); ++c) {
        EXPECT_EQ(0, std::memcmp(out[c].data(), out[0].data(), sizeof(double) * out[0].size()))
            << "m " << m << " k " << k;
        ++compared;
      }
    }
  }
  setActiveIsa(isa0);
  setActiveLanes(lanes0);
  if (availableLanes().size() > 1) {
    EXPECT_EQ(compared, 35);
  }
  std::vector<double> G(16), B(16);
  EXPECT_THROW(gramUpdate(G.data(), 3, B.data(), 4, 2, 3), Error);  // ld below 4
  EXPECT_THROW(gramUpdate(G.data(), 4, B.data(), 3, 2, 3), Error);
  EXPECT_NO_THROW(gramUpdate(G.data(), 4, B.data(), 4, 2, 3));
}
