// exid — benchmarks of the rigid-body algorithms on the PUMA 560 (one core).
// Baseline measured in the same run: the plain RNEA inverseDynamics (BM_Baseline_InverseDynamics).
//
// PUMA 560: standard DH and inertial data as in Corke's Robotics Toolbox (mdl_puma560.m):
// I = [Ixx Iyy Izz Ixy Iyz Ixz] about the COM r.
#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <random>
#include <vector>

#include "exid/dh.hpp"
#include "exid/dynamics.hpp"

using namespace exid;

namespace {

RobotModel puma560() {
  struct Row {
    double d, a, alpha, m, r[3], I[6];
  };
  const double h = 1.5707963268;
  const Row rows[6] = {
      {0.0, 0.0, h, 0.0, {0, 0, 0}, {0, 0.35, 0, 0, 0, 0}},
      {0.0, 0.4318, 0.0, 17.4, {-0.3638, 0.006, 0.2275}, {0.13, 0.524, 0.539, 0, 0, 0}},
      {0.15005, 0.0203, -h, 4.8, {-0.0203, -0.0141, 0.070}, {0.066, 0.086, 0.0125, 0, 0, 0}},
      {0.4318, 0.0, h, 0.82, {0, 0.019, 0}, {1.8e-3, 1.3e-3, 1.8e-3, 0, 0, 0}},
      {0.0, 0.0, -h, 0.34, {0, 0, 0}, {0.3e-3, 0.4e-3, 0.3e-3, 0, 0, 0}},
      {0.0, 0.0, 0.0, 0.09, {0, 0, 0.032}, {0.15e-3, 0.15e-3, 0.04e-3, 0, 0, 0}}};
  std::vector<DhRow> dh;
  for (const Row& r : rows) dh.push_back({JointType::Revolute, r.a, r.alpha, r.d, 0.0});
  RobotModel m = serialDh(dh, DhConvention::Standard);
  m.name = "puma560";
  for (int j = 0; j < 6; ++j) {
    const Row& r = rows[j];
    Eigen::Matrix3d I;
    I << r.I[0], r.I[3], r.I[5], r.I[3], r.I[1], r.I[4], r.I[5], r.I[4], r.I[2];
    m.bodies[static_cast<size_t>(j)].inertia = inertialFromCom(r.m, {r.r[0], r.r[1], r.r[2]}, I);
  }
  return m;
}

struct Fixture {
  RobotModel model = puma560();
  DynamicsDataPtr data = makeDynamicsData(model);
  static constexpr int kSamples = 1024;
  std::vector<Eigen::VectorXd> q, qd, qdd;
  Fixture() {
    std::mt19937 rng(1);
    std::uniform_real_distribution<double> U(-1, 1);
    for (int s = 0; s < kSamples; ++s) {
      Eigen::VectorXd a(6), b(6), c(6);
      for (int j = 0; j < 6; ++j) {
        a[j] = 3 * U(rng);
        b[j] = 2 * U(rng);
        c[j] = 5 * U(rng);
      }
      q.push_back(a);
      qd.push_back(b);
      qdd.push_back(c);
    }
  }
};

Fixture& fx() {
  static Fixture f;
  return f;
}

void BM_Baseline_InverseDynamics(benchmark::State& st) {
  Fixture& f = fx();
  int k = 0;
  for (auto _ : st) {
    benchmark::DoNotOptimize(inverseDynamics(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k]));
    k = (k + 1) & (Fixture::kSamples - 1);
  }
}
BENCHMARK(BM_Baseline_InverseDynamics);

void BM_TorqueRegressor(benchmark::State& st) {
  Fixture& f = fx();
  Eigen::MatrixXd Y(6, 60);
  int k = 0;
  for (auto _ : st) {
    torqueRegressor(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k], Y);
    benchmark::DoNotOptimize(Y.data());
    k = (k + 1) & (Fixture::kSamples - 1);
  }
}
BENCHMARK(BM_TorqueRegressor);

// Regressor + information matrix W^T W over 10,000 samples; time reported per sample.
void BM_RegressorPlusGram_Eigen(benchmark::State& st) {
  Fixture& f = fx();
  Eigen::MatrixXd Y(6, 60), M = Eigen::MatrixXd::Zero(60, 60);
  for (auto _ : st) {
    M.setZero();
    for (int s = 0; s < 10000; ++s) {
      const int k = s & (Fixture::kSamples - 1);
      torqueRegressor(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k], Y);
      M.selfadjointView<Eigen::Lower>().rankUpdate(Y.transpose());
    }
    benchmark::DoNotOptimize(M.data());
  }
  st.SetItemsProcessed(st.iterations() * 10000);
}
BENCHMARK(BM_RegressorPlusGram_Eigen)->Unit(benchmark::kMillisecond);

void BM_RegressorPlusGram(benchmark::State& st) {
  Fixture& f = fx();
  Eigen::MatrixXd Y(6, 60);
  GramAccumulator acc(60);
  for (auto _ : st) {
    acc.reset();
    for (int s = 0; s < 10000; ++s) {
      const int k = s & (Fixture::kSamples - 1);
      torqueRegressor(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k], Y);
      acc.add(Y);
    }
    benchmark::DoNotOptimize(acc.matrix().data());
  }
  st.SetItemsProcessed(st.iterations() * 10000);
}
BENCHMARK(BM_RegressorPlusGram)->Unit(benchmark::kMillisecond);

void BM_EnergyRegressor(benchmark::State& st) {
  Fixture& f = fx();
  Eigen::RowVectorXd K(60), U(60);
  int k = 0;
  for (auto _ : st) {
    energyRegressor(f.model, *f.data, f.q[k], f.qd[k], K, U);
    benchmark::DoNotOptimize(K.data());
    benchmark::DoNotOptimize(U.data());
    k = (k + 1) & (Fixture::kSamples - 1);
  }
}
BENCHMARK(BM_EnergyRegressor);

void BM_TorqueRegressorVjp(benchmark::State& st) {
  Fixture& f = fx();
  const Eigen::MatrixXd G = Eigen::MatrixXd::Random(6, 60);
  Eigen::VectorXd a(6), b(6), c(6);
  int k = 0;
  for (auto _ : st) {
    torqueRegressorVjp(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k], G, &a, &b, &c);
    benchmark::DoNotOptimize(a.data());
    k = (k + 1) & (Fixture::kSamples - 1);
  }
}
BENCHMARK(BM_TorqueRegressorVjp);

void BM_EnergyRegressorVjp(benchmark::State& st) {
  Fixture& f = fx();
  const Eigen::RowVectorXd Gk = Eigen::RowVectorXd::Random(60), Gu = Eigen::RowVectorXd::Random(60);
  Eigen::VectorXd a(6), b(6);
  int k = 0;
  for (auto _ : st) {
    energyRegressorVjp(f.model, *f.data, f.q[k], f.qd[k], Gk, Gu, &a, &b);
    benchmark::DoNotOptimize(a.data());
    k = (k + 1) & (Fixture::kSamples - 1);
  }
}
BENCHMARK(BM_EnergyRegressorVjp);

void BM_WrenchRegressor(benchmark::State& st) {
  Fixture& f = fx();
  Eigen::Matrix<double, 6, 10> A;
  int k = 0;
  for (auto _ : st) {
    wrenchRegressor(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k], A);
    benchmark::DoNotOptimize(A.data());
    k = (k + 1) & (Fixture::kSamples - 1);
  }
}
BENCHMARK(BM_WrenchRegressor);

void BM_WrenchRegressorVjp(benchmark::State& st) {
  Fixture& f = fx();
  const Eigen::Matrix<double, 6, 10> G = Eigen::Matrix<double, 6, 10>::Random();
  Eigen::VectorXd a(6), b(6), c(6);
  int k = 0;
  for (auto _ : st) {
    wrenchRegressorVjp(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k], G, &a, &b, &c);
    benchmark::DoNotOptimize(a.data());
    k = (k + 1) & (Fixture::kSamples - 1);
  }
}
BENCHMARK(BM_WrenchRegressorVjp);

void BM_PayloadTorqueRegressorVjp(benchmark::State& st) {
  Fixture& f = fx();
  const Eigen::MatrixXd G = Eigen::MatrixXd::Random(6, 10);
  Eigen::VectorXd a(6), b(6), c(6);
  int k = 0;
  for (auto _ : st) {
    payloadTorqueRegressorVjp(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k], G, &a, &b, &c);
    benchmark::DoNotOptimize(a.data());
    k = (k + 1) & (Fixture::kSamples - 1);
  }
}
BENCHMARK(BM_PayloadTorqueRegressorVjp);

void BM_MassMatrix(benchmark::State& st) {
  Fixture& f = fx();
  int k = 0;
  for (auto _ : st) {
    benchmark::DoNotOptimize(massMatrix(f.model, *f.data, f.q[k]));
    k = (k + 1) & (Fixture::kSamples - 1);
  }
}
BENCHMARK(BM_MassMatrix);

void BM_ForwardDynamics(benchmark::State& st) {
  Fixture& f = fx();
  int k = 0;
  for (auto _ : st) {
    benchmark::DoNotOptimize(forwardDynamics(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k]));
    k = (k + 1) & (Fixture::kSamples - 1);
  }
}
BENCHMARK(BM_ForwardDynamics);

}  // namespace

BENCHMARK_MAIN();
