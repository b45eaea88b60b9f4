// exid — benchmarks of the rigid-body algorithms on the PUMA 560 (one core).
// Baseline measured in the same run: the plain RNEA inverseDynamics (BM_Baseline_InverseDynamics).
//
// The hot kernels (exid/isa.hpp) run once per instruction set this CPU has (BM_<kernel>/portable,
// BM_<kernel>/avx2, one after the other), each with its operations per call (kernelFlops: counted
// from the source; the joints' sines and cosines, exid's own code, with the fewest operations any
// angle takes: those of |q| <= pi/4), the machine's peak for that instruction set, the resulting
// lower bound and the ratio of the measured time to it; the table at the end gives them per kernel
// (medians when run with --benchmark_repetitions). Peak: clock x flops per cycle, SSE2 (portable) 2
// doubles x 2 (one add, one multiply) = 4, AVX2 + FMA 4 doubles x 2 FMA units x 2 = 16; the clock
// is the highest "cpu MHz" of /proc/cpuinfo, or EXID_BENCH_GHZ.
//
// PUMA 560: standard DH and inertial data as in Corke's Robotics Toolbox (mdl_puma560.m):
// I = [Ixx Iyy Izz Ixy Iyz Ixz] about the COM r.
#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "exid/dh.hpp"
#include "exid/dynamics.hpp"
#include "exid/isa.hpp"

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

// ---- the hot kernels, once per instruction set ----

constexpr int kGramSamples = 10000;  // samples per iteration of the regressor + Gram benchmark
constexpr int kBatch = 64;           // samples per call of torqueRegressors

// Operations of GramAccumulator::add(Y) for one sample: per row, its first non-zero column s
// leaves m = 60 - s entries: m products for the weight, m(m + 1) / 2 multiply-adds for the lower
// triangle (the padding of the AVX2 copy is not counted).
double gramFlops(const Eigen::MatrixXd& Y) {
  double f = 0;
  for (Eigen::Index r = 0; r < Y.rows(); ++r) {
    Eigen::Index s = 0;
    while (s < Y.cols() && Y(r, s) == 0.0) ++s;
    const double m = static_cast<double>(Y.cols() - s);
    f += m + m * (m + 1);
  }
  return f;
}

double clockGHz() {
  if (const char* e = std::getenv("EXID_BENCH_GHZ")) return std::atof(e);
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  double mhz = 0;
  while (std::getline(in, line))
    if (line.rfind("cpu MHz", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) mhz = std::max(mhz, std::atof(line.c_str() + colon + 1));
    }
  return mhz / 1000.0;
}

double flopsPerCycle(Isa isa) { return isa == Isa::Avx2 ? 16.0 : 4.0; }

struct KernelInfo {
  std::string kernel;
  Isa isa;
  double flops;  // per sample: the rigid-body algorithm's
  int sincos;
  double sincos_flops;  // the sines' and cosines' (each pair's fewest: |q| <= pi/4)
  double samples_per_iteration;
  std::string label;     // the copy: "portable", "avx2", "lanes-sse2", "lanes-avx"
  double per_cycle = 0;  // the copy's peak flops per cycle
};
std::map<std::string, KernelInfo>& kernelInfo() {
  static std::map<std::string, KernelInfo> m;
  return m;
}

template <class Body>
void registerKernel(const std::string& kernel, FlopCount c, Body body, double samples = 1,
                    benchmark::TimeUnit unit = benchmark::kNanosecond) {
  const double flops = c.flops + c.sincos_flops;
  for (Isa isa : availableIsas()) {
    const std::string name = "BM_" + kernel + "/" + isaName(isa);
    kernelInfo()[name] = {kernel,         isa,     c.flops,      c.sincos,
                          c.sincos_flops, samples, isaName(isa), flopsPerCycle(isa)};
    benchmark::RegisterBenchmark(name.c_str(), [isa, body, flops, samples](benchmark::State& st) {
      setActiveIsa(isa);
      body(st);
      st.counters["flop/s"] =
          benchmark::Counter(flops * samples, benchmark::Counter::kIsIterationInvariantRate);
    })->Unit(unit);
  }
}

// kBatch samples of the fixture, as the several-samples kernels take them
struct Batch {
  Eigen::MatrixXd Q, QD, QDD;
};

// A kernel of several samples at once on each lane copy; the table gives the time per sample
// against the copy's own peak.
template <class Body>
void registerLanes(const std::string& bench, const std::string& kernel, FlopCount c, Body body) {
  for (Lanes lanes : availableLanes()) {
    const std::string name = "BM_" + bench + "/" + lanesName(lanes);
    const bool avx = lanes == Lanes::Avx;
    kernelInfo()[name] = {kernel,
                          Isa::Portable,
                          c.flops,
                          c.sincos,
                          c.sincos_flops,
                          kBatch,
                          avx ? "lanes-avx" : "lanes-sse2",
                          avx ? 8.0 : 4.0};
    benchmark::RegisterBenchmark(name.c_str(), [lanes, flops = c.flops + c.sincos_flops,
                                                body](benchmark::State& st) {
      setActiveIsa(Isa::Portable);
      setActiveLanes(lanes);
      Fixture& f = fx();
      Batch b{Eigen::MatrixXd(kBatch, 6), Eigen::MatrixXd(kBatch, 6), Eigen::MatrixXd(kBatch, 6)};
      int k0 = 0;
      for (auto _ : st) {
        for (int s = 0; s < kBatch; ++s) {
          b.Q.row(s) = f.q[static_cast<size_t>(k0 + s)].transpose();
          b.QD.row(s) = f.qd[static_cast<size_t>(k0 + s)].transpose();
          b.QDD.row(s) = f.qdd[static_cast<size_t>(k0 + s)].transpose();
        }
        body(b);
        k0 = (k0 + kBatch) & (Fixture::kSamples - 1);
      }
      st.counters["flop/s"] =
          benchmark::Counter(flops * kBatch, benchmark::Counter::kIsIterationInvariantRate);
    });
  }
}

void registerKernels() {
  const RobotModel& m = fx().model;
  const auto flops = [&](Kernel k) { return kernelFlops(m, k); };
  FlopCount c = flops(Kernel::InverseDynamics);
  registerKernel("InverseDynamics", c, [](benchmark::State& st) {
    Fixture& f = fx();
    int k = 0;
    for (auto _ : st) {
      benchmark::DoNotOptimize(inverseDynamics(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k]));
      k = (k + 1) & (Fixture::kSamples - 1);
    }
  });
  c = flops(Kernel::TorqueRegressor);
  registerKernel("TorqueRegressor", c, [](benchmark::State& st) {
    Fixture& f = fx();
    Eigen::MatrixXd Y(6, 60);
    int k = 0;
    for (auto _ : st) {
      torqueRegressor(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k], Y);
      benchmark::DoNotOptimize(Y.data());
      k = (k + 1) & (Fixture::kSamples - 1);
    }
  });
  // The same regressor, 64 samples per call of torqueRegressors (the portable kernels, four
  // samples at once in the vector lanes: exid/isa.hpp's Lanes; the same bits). Peak: SSE2 as
  // above; AVX without FMA 4 doubles x 2 (one add, one multiply) = 8. Likewise the RNEA
  // (inverseDynamicsSamples) and the energy regressor (energyRegressors).
  registerLanes("TorqueRegressors", "TorqueRegressor", c, [](const Batch& b) {
    Fixture& f = fx();
    static Eigen::MatrixXd Y(kBatch * 6, 60);
    torqueRegressors(f.model, *f.data, b.Q, b.QD, b.QDD, Y);
    benchmark::DoNotOptimize(Y.data());
  });
  registerLanes("InverseDynamicsSamples", "InverseDynamics", flops(Kernel::InverseDynamics),
                [](const Batch& b) {
                  Fixture& f = fx();
                  static Eigen::MatrixXd T(kBatch, 6);
                  inverseDynamicsSamples(f.model, *f.data, b.Q, b.QD, b.QDD, T);
                  benchmark::DoNotOptimize(T.data());
                });
  registerLanes("EnergyRegressors", "EnergyRegressor", flops(Kernel::EnergyRegressor),
                [](const Batch& b) {
                  Fixture& f = fx();
                  static Eigen::MatrixXd K(kBatch, 60), U(kBatch, 60);
                  energyRegressors(f.model, *f.data, b.Q, b.QD, K, U);
                  benchmark::DoNotOptimize(K.data());
                  benchmark::DoNotOptimize(U.data());
                });
  // Their vector-Jacobian products of several samples (torqueRegressorVjps, energyRegressorVjps;
  // the same bits as the one-sample VJPs of the portable copy), with fixed random G
  registerLanes("TorqueRegressorVjps", "TorqueRegressorVjp", flops(Kernel::TorqueRegressorVjp),
                [](const Batch& b) {
                  Fixture& f = fx();
                  static const Eigen::MatrixXd G = Eigen::MatrixXd::Random(kBatch * 6, 60);
                  static Eigen::MatrixXd gq, gqd, gqdd;
                  torqueRegressorVjps(f.model, *f.data, b.Q, b.QD, b.QDD, G, &gq, &gqd, &gqdd);
                  benchmark::DoNotOptimize(gq.data());
                  benchmark::DoNotOptimize(gqd.data());
                  benchmark::DoNotOptimize(gqdd.data());
                });
  registerLanes("EnergyRegressorVjps", "EnergyRegressorVjp", flops(Kernel::EnergyRegressorVjp),
                [](const Batch& b) {
                  Fixture& f = fx();
                  static const Eigen::MatrixXd Gk = Eigen::MatrixXd::Random(kBatch, 60),
                                               Gu = Eigen::MatrixXd::Random(kBatch, 60);
                  static Eigen::MatrixXd gq, gqd;
                  energyRegressorVjps(f.model, *f.data, b.Q, b.QD, Gk, Gu, &gq, &gqd);
                  benchmark::DoNotOptimize(gq.data());
                  benchmark::DoNotOptimize(gqd.data());
                });
  // Regressor + information matrix W^T W over 10,000 samples; the table gives the time per sample.
  {
    Eigen::MatrixXd Y(6, 60);
    torqueRegressor(m, *fx().data, fx().q[0], fx().qd[0], fx().qdd[0], Y);
    registerKernel(
        "RegressorPlusGram", FlopCount{c.flops + gramFlops(Y), c.sincos, c.sincos_flops},
        [](benchmark::State& st) {
          Fixture& f = fx();
          Eigen::MatrixXd Y(6, 60);
          GramAccumulator acc(60);
          for (auto _ : st) {
            acc.reset();
            for (int s = 0; s < kGramSamples; ++s) {
              const int k = s & (Fixture::kSamples - 1);
              torqueRegressor(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k], Y);
              acc.add(Y);
            }
            benchmark::DoNotOptimize(acc.matrix().data());
          }
          st.SetItemsProcessed(st.iterations() * kGramSamples);
        },
        kGramSamples, benchmark::kMillisecond);
  }
  c = flops(Kernel::EnergyRegressor);
  registerKernel("EnergyRegressor", c, [](benchmark::State& st) {
    Fixture& f = fx();
    Eigen::RowVectorXd K(60), U(60);
    int k = 0;
    for (auto _ : st) {
      energyRegressor(f.model, *f.data, f.q[k], f.qd[k], K, U);
      benchmark::DoNotOptimize(K.data());
      benchmark::DoNotOptimize(U.data());
      k = (k + 1) & (Fixture::kSamples - 1);
    }
  });
  c = flops(Kernel::TorqueRegressorVjp);
  registerKernel("TorqueRegressorVjp", c, [](benchmark::State& st) {
    Fixture& f = fx();
    const Eigen::MatrixXd G = Eigen::MatrixXd::Random(6, 60);
    Eigen::VectorXd a(6), b(6), cc(6);
    int k = 0;
    for (auto _ : st) {
      torqueRegressorVjp(f.model, *f.data, f.q[k], f.qd[k], f.qdd[k], G, &a, &b, &cc);
      benchmark::DoNotOptimize(a.data());
      k = (k + 1) & (Fixture::kSamples - 1);
    }
  });
  c = flops(Kernel::EnergyRegressorVjp);
  registerKernel("EnergyRegressorVjp", c, [](benchmark::State& st) {
    Fixture& f = fx();
    const Eigen::RowVectorXd Gk = Eigen::RowVectorXd::Random(60),
                             Gu = Eigen::RowVectorXd::Random(60);
    Eigen::VectorXd a(6), b(6);
    int k = 0;
    for (auto _ : st) {
      energyRegressorVjp(f.model, *f.data, f.q[k], f.qd[k], Gk, Gu, &a, &b);
      benchmark::DoNotOptimize(a.data());
      k = (k + 1) & (Fixture::kSamples - 1);
    }
  });
}

// The console output, then the table of the hot kernels: operations, bound, time (the median of
// the repetitions, else the one run; CPU time), ratio to the bound, speed-up over portable.
class KernelTableReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs) {
      const bool median = r.run_type == Run::RT_Aggregate && r.aggregate_name == "median";
      if (r.run_type != Run::RT_Iteration && !median) continue;
      const std::string& name = r.run_name.function_name;
      if (!kernelInfo().count(name)) continue;
      const KernelInfo& k = kernelInfo()[name];
      const double to_ns = r.time_unit == benchmark::kMillisecond   ? 1e6
                           : r.time_unit == benchmark::kMicrosecond ? 1e3
                                                                    : 1.0;
      if (median || !ns_.count(name))
        ns_[name] = r.GetAdjustedCPUTime() * to_ns / k.samples_per_iteration;
    }
    ConsoleReporter::ReportRuns(runs);
  }
  void Finalize() override {
    ConsoleReporter::Finalize();
    const double ghz = clockGHz();
    std::printf(
        "\nHot kernels, PUMA 560, per sample (clock %.2f GHz; peak %.1f GFlop/s portable "
        "(SSE2), %.1f GFlop/s avx2 (AVX2 + FMA))\n",
        ghz, ghz * flopsPerCycle(Isa::Portable), ghz * flopsPerCycle(Isa::Avx2));
    std::printf("%-20s %-10s %8s %7s %9s %10s %10s %8s %9s\n", "kernel", "copy", "flops", "sin/cos",
                "their ops", "bound ns", "time ns", "ratio", "speed-up");
    std::map<std::string, double> portable_ns;
    for (const auto& [name, k] : kernelInfo())
      if (k.label == "portable" && ns_.count(name)) portable_ns[k.kernel] = ns_[name];
    for (const auto& [name, k] : kernelInfo()) {
      if (!ns_.count(name)) continue;
      const double bound = (k.flops + k.sincos_flops) / (ghz * k.per_cycle);
      const double t = ns_[name];
      std::printf("%-20s %-10s %8.0f %7d %9.0f %10.1f %10.1f %8.2f", k.kernel.c_str(),
                  k.label.c_str(), k.flops, k.sincos, k.sincos_flops, bound, t, t / bound);
      if (portable_ns.count(k.kernel))
        std::printf(" %9.2f\n", portable_ns[k.kernel] / t);
      else
        std::printf(" %9s\n", "-");
    }
  }

 private:
  std::map<std::string, double> ns_;
};

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  registerKernels();
  KernelTableReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  return 0;
}
