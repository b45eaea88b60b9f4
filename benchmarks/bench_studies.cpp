// Time to quality of the excitation studies (examples/bench, examples/paper): what the optimisers
// reach within a CPU-time budget on this machine, and how long the reproducible runs (the
// studies as shipped, bounded by evaluations; the test suite asserts their results) take.
//
// Each figure is also given as a ratio to a baseline measured in the same run: the CPU time of
// one criterion value + adjoint gradient of the study's own problem at its initial trajectory
// ("gradient evaluations' worth of time"), so that a faster or slower machine moves the seconds
// but hardly the ratio. The goals (docs/excitation.md): Panda cond <= 33.3 in < 1 s and <= 30
// within 10 s; PUMA 560 <= 6.04 in < 2 s; the paper's experiments 1-4 in < 1 s each (the
// paper: 20-60 h on a PC/486) with their reduction ratios.
//
//   bash scripts/bench.sh studies        (or build/bin/bench_studies) prints the table at the end
#include <benchmark/benchmark.h>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <time.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "exid/config.hpp"
#include "exid/excitation.hpp"
#include "exid/interfaces.hpp"
#include "exid/registry.hpp"
#include "exid/runner.hpp"

namespace {

namespace fs = std::filesystem;

exid::Registry& registry() {
  static exid::Registry* reg = [] {
    auto* r = new exid::Registry();
    char buf[4096];
    const ssize_t len = readlink("/proc/self/exe", buf, sizeof(buf) - 1);
    fs::path exe = len > 0 ? fs::path(std::string(buf, static_cast<std::size_t>(len))) : ".";
    r->addSearchPath(exe.parent_path().parent_path() / "plugins");
    r->scan();
    return r;
  }();
  return *reg;
}

double processCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

/// CPU seconds of one value + gradient of the study's criterion at its initial trajectory, and
/// (torque_s, when the study sets torque limits) of the torque rows with their exact Jacobian at
/// the same point.
double baselineSeconds(const exid::StudyConfig& cfg, double* torque_s = nullptr) {
  exid::RunContext ctx;
  ctx.study_dir = cfg.dir;
  ctx.seed = cfg.seed;
  auto robot = registry().create<exid::Robot>(cfg.robot->type, cfg.robot->params)->build(ctx);
  auto model = registry().create<exid::ObservationModel>(cfg.models[0].type, cfg.models[0].params);
  auto traj = registry().create<exid::Trajectory>(cfg.trajectory->type, cfg.trajectory->params);
  traj->bind(robot, ctx);
  std::vector<int> moving = traj->specs().moving_joints;
  if (!moving.empty() && static_cast<int>(moving.size()) < robot->dof()) {
    const exid::Samples s0 = traj->evaluate(traj->initial());
    model->restrictMotion(std::move(moving), s0.q.row(0).transpose());
  }
  model->bind(robot, ctx);
  auto crit = registry().create<exid::Criterion>(cfg.criterion->type, cfg.criterion->params);
  exid::ExcitationOptions xo;
  xo.position_margin = traj->positionMargin();
  xo.scale_columns = crit->specs().scale_columns;
  xo.torque_margin = cfg.excitation_constraints.getDouble("torque_margin");
  xo.torque_max = cfg.excitation_constraints.getDoubles("torque_max_Nm");
  xo.collision = cfg.excitation_collision;
  auto problem = exid::makeExcitationProblem(traj, model, crit, xo);
  const Eigen::VectorXd z = problem->initial();
  Eigen::VectorXd g;
  Eigen::MatrixXd J;
  auto timeIt = [](const std::function<void()>& f) {
    f();  // warm up
    int reps = 0;
    const double t0 = processCpuSeconds();
    double t = 0;
    do {
      f();
      ++reps;
      t = processCpuSeconds() - t0;
    } while (t < 0.2);
    return t / reps;
  };
  const double base = timeIt([&] { problem->value(z, &g); });
  if (torque_s)
    *torque_s = problem->numNonlinearConstraints() > 0
                    ? timeIt([&] { problem->nonlinearConstraints(z, &g, &J); })
                    : NAN;
  return base;
}

struct Row {
  std::string study, budget, goal;
  double cond = NAN, ratio = NAN, cpu_s = NAN, baseline_ms = NAN;
  double torque_ms = NAN, torque_ratio_max = NAN;  // torque rows + Jacobian; worst |tau|/tau_max
  long evaluations = 0;
  std::string stop;
  bool met = false;
};
std::vector<Row>& rows() {
  static std::vector<Row> r;
  return r;
}

/// Runs examples/<file>; cpu_s > 0 replaces the optimiser's evaluation/iteration budget by a
/// CPU-time budget (the time-to-quality question), 0 runs the study as shipped (reproducible).
void runStudy(benchmark::State& state, const std::string& file, double cpu_s, double goal_cond,
              double goal_ratio, const std::string& goal, bool pivoted = false) {
  exid::StudyConfig cfg =
      exid::loadStudy(fs::path(EXID_SOURCE_DIR) / "examples" / file, registry());
  if (pivoted) {  // the baselines' rule (docs/excitation.md §10)
    cfg.base_columns.clear();
    cfg.base_columns_pivoted = true;
  }
  cfg.experiment.reset();
  cfg.estimator.reset();
  cfg.validation.reset();
  double torque_s = NAN;
  const double base = baselineSeconds(cfg, &torque_s);
  if (cpu_s > 0) {
    auto& p = cfg.optimizer->params;
    p.set("max_cpu_s", cpu_s);
    p.set("max_time_s", 0.0);
    p.set("max_evaluations", static_cast<std::int64_t>(0));
    if (cfg.optimizer->type != "nlopt")
      p.set("max_iterations", static_cast<std::int64_t>(1000000));
    else if (p.has("start_evaluations"))
      p.set("start_evaluations", static_cast<std::int64_t>(0));
  }
  exid::RunOptions opt;  // nothing written
  Row row;
  for (auto _ : state) {
    const double t0 = processCpuSeconds();
    exid::StudyResult r = exid::runStudy(cfg, registry(), opt);
    const double cpu = processCpuSeconds() - t0;
    state.SetIterationTime(cpu);
    if (!r.ok) {
      state.SkipWithError(r.message.c_str());
      return;
    }
    const exid::Json& X = *r.summary.find("excitation");
    row.cond = X.find("cond_W_final")->asDouble();
    row.ratio = X.find("cond_W_initial")->asDouble() / row.cond;
    row.evaluations = static_cast<long>(X.find("evaluations")->asDouble());
    row.stop = X.find("stop_reason")->asString();
    const exid::Json* d = X.find("details");
    row.cpu_s = d && d->find("cpu_s") ? d->find("cpu_s")->asDouble() : cpu;
    const exid::Json* feasible = d ? d->find("feasible") : nullptr;
    if (feasible && !feasible->asBool()) row.stop += " (infeasible)";
    if (const exid::Json* tr = X.find("torque_ratio_max")) row.torque_ratio_max = tr->asDouble();
  }
  row.torque_ms = 1e3 * torque_s;
  row.study = fs::path(file).stem().string();
  if (pivoted) row.study += " on pivoted columns";
  row.budget = cpu_s > 0 ? fmt::format("{:g} s CPU", cpu_s) : "as shipped (evaluations)";
  row.goal = goal;
  row.baseline_ms = 1e3 * base;
  row.met = (std::isnan(goal_cond) || row.cond <= goal_cond) &&
            (std::isnan(goal_ratio) || row.ratio >= goal_ratio) &&
            row.stop.find("infeasible") == std::string::npos;
  if (!std::isnan(torque_s)) {
    state.counters["torque_ms"] = row.torque_ms;
    state.counters["torque_over_baseline"] = torque_s / base;
  }
  state.counters["cond_W"] = row.cond;
  state.counters["ratio"] = row.ratio;
  state.counters["evaluations"] = static_cast<double>(row.evaluations);
  state.counters["baseline_ms"] = row.baseline_ms;
  state.counters["cpu_over_baseline"] = row.cpu_s / base;
  state.counters["goal_met"] = row.met ? 1 : 0;
  rows().push_back(row);
}

// the CPU's model name (/proc/cpuinfo, as lscpu prints it) and the number of CPUs online
std::string machineName() {
  std::ifstream in("/proc/cpuinfo");
  std::string line, model = "unknown CPU";
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) {
      model = line.substr(line.find(':') + 2);
      break;
    }
  return fmt::format("{}, {} CPUs online", model, std::thread::hardware_concurrency());
}

void registerAll() {
  struct B {
    const char* file;
    double cpu_s, cond, ratio;
    const char* goal;
    bool pivoted = false;  // base_columns: pivoted (the baselines' rule, docs/excitation.md §10)
  };
  const double no = NAN;
  const bool pivoted = true;
  const std::vector<B> all = {
      {"bench/panda_fourier.yaml", 1.0, 33.3, no, "cond <= 33.3 in < 1 s"},
      {"bench/panda_fourier.yaml", 10.0, 30.0, no, "cond <= 30 in 10 s"},
      {"bench/panda_fourier.yaml", 0.0, 30.0, no, "cond <= 30"},
      {"bench/panda_fourier_torque.yaml", 2.0, 33.3, no, "cond <= 33.3 in < 2 s, torque limits on"},
      {"bench/panda_fourier_torque.yaml", 0.0, 33.3, no, "cond <= 33.3, torque limits on"},
      {"bench/panda_fourier_table.yaml", 10.0, 40.0, no,
       "cond <= 40 in < 10 s, torque limits, self-collision and a table"},
      {"bench/panda_fourier_table.yaml", 0.0, 40.0, no,
       "cond <= 40, torque limits, self-collision and a table"},
      {"bench/puma560_fourier.yaml", 2.0, 6.04, no, "cond <= 6.04 in < 2 s"},
      {"bench/puma560_fourier.yaml", 0.0, 6.04, no, "cond <= 6.04"},
      {"bench/puma560_fourier.yaml", 2.0, 6.04, no, "cond <= 6.04 in < 2 s", pivoted},
      {"bench/puma560_fourier.yaml", 0.0, 6.04, no, "cond <= 6.04", pivoted},
      {"bench/panda_fourier.yaml", 1.0, 33.25, no, "cond <= 33.25 in < 1 s", pivoted},
      {"bench/panda_fourier.yaml", 0.0, 30.0, no, "cond <= 30", pivoted},
      {"paper/exp1_differential_3joints.yaml", 1.0, no, 10.0, "ratio >= 10 in < 1 s"},
      {"paper/exp1_differential_3joints.yaml", 0.0, no, 10.0, "ratio >= 10"},
      {"paper/exp2_differential_joint1.yaml", 1.0, no, 1.9e5 / 88.0, "ratio >= 2159 in < 1 s"},
      {"paper/exp2_differential_joint1.yaml", 0.0, no, 1.9e5 / 88.0, "ratio >= 2159"},
      {"paper/exp3_integral_joint2.yaml", 1.0, no, 6.0, "ratio >= 6 in < 1 s"},
      {"paper/exp3_integral_joint2.yaml", 0.0, no, 6.0, "ratio >= 6"},
      {"paper/exp4_load_wrench.yaml", 1.0, no, 90830.0 / 3000.0, "ratio >= 30.3 in < 1 s"},
      {"paper/exp4_load_wrench.yaml", 0.0, no, 90830.0 / 3000.0, "ratio >= 30.3"},
  };
  for (const B& b : all) {
    const std::string name = fmt::format(
        "{}{}/{}", fs::path(b.file).stem().string(), b.pivoted ? "_pivoted_columns" : "",
        b.cpu_s > 0 ? fmt::format("cpu_{:g}s", b.cpu_s) : std::string("shipped"));
    benchmark::RegisterBenchmark(name.c_str(),
                                 [b](benchmark::State& st) {
                                   runStudy(st, b.file, b.cpu_s, b.cond, b.ratio, b.goal,
                                            b.pivoted);
                                 })
        ->Iterations(1)
        ->UseManualTime()
        ->Unit(benchmark::kSecond);
  }
}

}  // namespace

int main(int argc, char** argv) {
  registerAll();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  std::cout << "\nMachine: " << machineName() << "\n";
  std::cout << "\n| study | budget | cond(W) | ratio initial/final | evaluations | CPU s | "
               "CPU / baseline | baseline (value + gradient) | goal | met |\n"
               "|---|---|---|---|---|---|---|---|---|---|\n";
  for (const Row& r : rows())
    std::cout << fmt::format(
        "| {} | {} | {:.4f} | {:.4g} | {} | {:.2f} | {:.0f} | {:.3f} ms | {} | {} |\n", r.study,
        r.budget, r.cond, r.ratio, r.evaluations, r.cpu_s, r.cpu_s / (1e-3 * r.baseline_ms),
        r.baseline_ms, r.goal, r.met ? "yes" : "**no**");
  std::cout << "\n| study | budget | nonlinear rows (torque, collision) + exact Jacobian | value + "
               "gradient | "
               "ratio | "
               "max |tau| / tau_max |\n|---|---|---|---|---|---|\n";
  for (const Row& r : rows())
    if (!std::isnan(r.torque_ms))
      std::cout << fmt::format("| {} | {} | {:.3f} ms | {:.3f} ms | {:.2f} | {:.3f} |\n", r.study,
                               r.budget, r.torque_ms, r.baseline_ms, r.torque_ms / r.baseline_ms,
                               r.torque_ratio_max);
  return 0;
}
