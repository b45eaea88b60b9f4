// Excitation design: cost of the criterion J(z) = cond(W(z)) and of its adjoint gradient
// (value(z, &grad): forward pass + backward costate sweep) for the paper's pointwise trajectory,
// K = 300 samples, n = 3 (PUMA 560 joints 1-3) and n = 6 (PUMA 560), and the Fourier Panda
// benchmark problem. The counter grad_over_value is time(value + gradient) / time(value):
// the adjoint method promises a small constant (<= 5) independent of the number of variables.
//   build/bin/bench_excitation [--benchmark_filter=...]
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>

#include "exid/collision.hpp"
#include "exid/config.hpp"
#include "exid/excitation.hpp"
#include "exid/interfaces.hpp"
#include "exid/registry.hpp"

namespace {

exid::Registry& registry() {
  static exid::Registry* reg = [] {
    auto* r = new exid::Registry();
    char buf[4096];
    const ssize_t len = readlink("/proc/self/exe", buf, sizeof(buf) - 1);
    std::filesystem::path exe =
        len > 0 ? std::filesystem::path(std::string(buf, static_cast<std::size_t>(len)))
                : std::filesystem::path(".");
    r->addSearchPath(exe.parent_path().parent_path() / "plugins");
    r->scan();
    return r;
  }();
  return *reg;
}

template <class T>
std::shared_ptr<T> create(const std::string& name, const std::string& params) {
  const exid::PluginInfo& info = registry().get(T::kKind, name);
  exid::ParamSet ps =
      exid::resolveParams(info, params, name, std::filesystem::path(EXID_SOURCE_DIR));
  return registry().create<T>(name, ps);
}

struct Problem {
  std::shared_ptr<exid::Trajectory> traj;
  std::unique_ptr<exid::ExcitationProblem> problem;
};

Problem make(const std::string& robot, int n_keep, const std::string& model_params,
             const std::string& traj, const std::string& traj_params) {
  exid::RunContext ctx;
  auto r0 = create<exid::Robot>(robot, "{}")->build(ctx);
  auto r = std::make_shared<exid::RobotModel>(*r0);
  if (n_keep > 0 && n_keep < r->dof()) {  // the first n_keep bodies of a serial chain
    r->bodies.resize(static_cast<std::size_t>(n_keep));
    r->limits.resize(static_cast<std::size_t>(n_keep));
    r->drives.resize(static_cast<std::size_t>(n_keep));
  }
  auto model = create<exid::ObservationModel>("differential", model_params);
  model->bind(r, ctx);
  Problem p;
  p.traj = create<exid::Trajectory>(traj, traj_params);
  p.traj->bind(r, ctx);
  auto crit = create<exid::Criterion>("cond", "{}");
  exid::ExcitationOptions xo;
  xo.position_margin = p.traj->positionMargin();
  p.problem = exid::makeExcitationProblem(p.traj, model, crit, xo);
  return p;
}

double secondsPer(const std::function<void()>& f, int reps) {
  auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < reps; ++i) f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / reps;
}

void run(benchmark::State& state, Problem& p, bool gradient) {
  Eigen::VectorXd z = p.problem->initial(), g;
  for (auto _ : state) {
    double J = p.problem->value(z, gradient ? &g : nullptr);
    benchmark::DoNotOptimize(J);
  }
  // the ratio, measured inside the same process for both
  const int reps = 20;
  const double tv = secondsPer([&] { p.problem->value(z, nullptr); }, reps);
  const double tg = secondsPer([&] { p.problem->value(z, &g); }, reps);
  state.counters["value_ms"] = tv * 1e3;
  state.counters["value_grad_ms"] = tg * 1e3;
  state.counters["grad_over_value"] = tg / tv;
  state.counters["variables"] = static_cast<double>(z.size());
}

const char* kPointwise300 = "{duration_s: 3, sample_period_s: 0.01, init_frequency_hz: 0.4}";
const char* kNoFriction = "{rotor_inertia: false, viscous: false, coulomb: false}";

void BM_Pointwise_K300_n3(benchmark::State& state) {
  static Problem p = make("puma560", 3, kNoFriction, "pointwise", kPointwise300);
  run(state, p, state.range(0) != 0);
}
void BM_Pointwise_K300_n6(benchmark::State& state) {
  static Problem p = make("puma560", 0, kNoFriction, "pointwise", kPointwise300);
  run(state, p, state.range(0) != 0);
}
void BM_Fourier_Panda(benchmark::State& state) {
  static Problem p = make(
      "panda", 0, "{rotor_inertia: false, viscous: true, coulomb: true, offset: false}", "fourier",
      "{period_s: 10, harmonics: 5, sample_period_s: 0.1, position_margin_rad: 0.1, "
      "acceleration_limits: false}");
  run(state, p, state.range(0) != 0);
}
void BM_Constraints_Panda(benchmark::State& state) {
  static Problem p = make(
      "panda", 0, "{rotor_inertia: false, viscous: true, coulomb: true, offset: false}", "fourier",
      "{period_s: 10, harmonics: 5, sample_period_s: 0.1, position_margin_rad: 0.1, "
      "acceleration_limits: false}");
  Eigen::VectorXd z = p.problem->initial(), g;
  Eigen::MatrixXd J;
  for (auto _ : state) {
    p.problem->constraints(z, &g, state.range(0) ? &J : nullptr);
    benchmark::DoNotOptimize(g.data());
  }
}

// Collision: one evaluation of every checked pair's signed distance (and, with range(0) = 1, its
// exact derivative) at one configuration of the Panda: its 8 capsule sides and a table (a box),
// 28 pairs. Counters: per pair, and the ratio to the distances alone.
void BM_Collision_Panda(benchmark::State& state) {
  exid::RunContext ctx;
  auto robot = create<exid::Robot>("panda", "{}")->build(ctx);
  exid::CollisionOptions o;
  o.margin_m = 0.02;
  exid::Obstacle table;
  table.name = "table";
  table.shape.kind = exid::CollisionShape::Kind::Box;
  table.shape.size = Eigen::Vector3d(0.6, 1.2, 0.04);
  table.shape.pose.p = Eigen::Vector3d(0.55, 0, 0.23);
  o.obstacles = {table};
  exid::CollisionModel cm(*robot, o);
  Eigen::VectorXd q(7), d;
  q << 0.3, -0.4, 0.2, -2.0, 0.1, 1.6, 0.5;
  Eigen::MatrixXd D;
  const bool grad = state.range(0) != 0;
  for (auto _ : state) {
    cm.distances(q, &d, grad ? &D : nullptr);
    benchmark::DoNotOptimize(d.data());
  }
  const int reps = 2000;
  const double tv = secondsPer([&] { cm.distances(q, &d); }, reps);
  const double tg = secondsPer([&] { cm.distances(q, &d, &D); }, reps);
  state.counters["pairs"] = cm.numPairs();
  state.counters["us_per_pair"] = 1e6 * (grad ? tg : tv) / cm.numPairs();
  state.counters["grad_over_value"] = tg / tv;
}

}  // namespace

BENCHMARK(BM_Collision_Panda)->Arg(0)->Arg(1)->ArgName("grad")->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_Pointwise_K300_n3)->Arg(0)->Arg(1)->ArgName("grad")->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Pointwise_K300_n6)->Arg(0)->Arg(1)->ArgName("grad")->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Fourier_Panda)->Arg(0)->Arg(1)->ArgName("grad")->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Constraints_Panda)->Arg(0)->Arg(1)->ArgName("jacobian")->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
