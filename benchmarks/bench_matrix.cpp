// Matrix overhead and parallel speed-up.
//  - BM_MatrixOverheadPerCell: cells whose study is only a robot (nothing to compute), so the
//    time per cell is the matrix's own cost: validation, fork, result transport, one SQLite
//    transaction. Goal: < 20 ms per cell.
//  - BM_MatrixCpuBound/jobs: the same CPU-bound matrix (PUMA 560 simulations + identification)
//    with -j 1 and -j 2; the ratio of the two is the speed-up (goal >= 1.8 on 2 cores).
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "exid/context.hpp"
#include "exid/matrix.hpp"
#include "exid/registry.hpp"

namespace fs = std::filesystem;

namespace {

exid::Registry& reg() {
  static exid::Registry* r = [] {
    auto* x = new exid::Registry();
    x->addSearchPath(fs::path(EXID_BINARY_DIR) / "plugins");
    x->scan();
    return x;
  }();
  return *r;
}

fs::path writeMatrix(const std::string& name, const std::string& text) {
  fs::path d = fs::temp_directory_path() / ("exid_bench_matrix_" + std::to_string(::getpid()));
  fs::create_directories(d);
  std::ofstream(d / (name + ".yaml")) << text;
  return d / (name + ".yaml");
}

void BM_MatrixOverheadPerCell(benchmark::State& state) {
  exid::setLogLevel(exid::LogLevel::Quiet);
  std::string seeds;
  for (int i = 0; i < 50; ++i) seeds += (i ? ", " : "") + std::to_string(i);
  fs::path file = writeMatrix(
      "overhead", "name: o\nstudy: {robot: {type: planar2r}}\naxes: {seed: [" + seeds + "]}\n");
  for (auto _ : state) {
    exid::MatrixSpec spec = exid::loadMatrix(file, reg());
    exid::MatrixOptions opt;
    opt.out_dir = file.parent_path() / "out_overhead";
    fs::remove_all(opt.out_dir);
    opt.jobs = 1;
    opt.write_cell_files = false;
    exid::runMatrix(spec, reg(), opt);
  }
  state.counters["s_per_cell"] =
      benchmark::Counter(50.0 * static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_MatrixOverheadPerCell)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

void BM_MatrixCpuBound(benchmark::State& state) {
  exid::setLogLevel(exid::LogLevel::Quiet);
  fs::path file = writeMatrix("cpu", R"(name: cpu
study:
  robot: {type: puma560}
  model: {type: differential, params: {offset: true}}
  experiment: {type: simulate, params: {duration_s: 30, sample_period_s: 0.002, noise_tau_Nm: 0.05}}
  estimator: {type: wls}
axes: {seed: [1, 2, 3, 4, 5, 6, 7, 8]}
)");
  for (auto _ : state) {
    exid::MatrixSpec spec = exid::loadMatrix(file, reg());
    exid::MatrixOptions opt;
    opt.out_dir = file.parent_path() / ("out_cpu_" + std::to_string(state.range(0)));
    fs::remove_all(opt.out_dir);
    opt.jobs = static_cast<int>(state.range(0));
    opt.write_cell_files = false;
    exid::runMatrix(spec, reg(), opt);
  }
}
BENCHMARK(BM_MatrixCpuBound)
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(2);

}  // namespace

BENCHMARK_MAIN();
