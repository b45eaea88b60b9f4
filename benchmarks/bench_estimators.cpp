// Throughput of the estimator plugins in samples per second (items_per_second), including the
// observation model's rows:
//   - on the PUMA 560 with the `differential` model (52 base parameters, 6 rows per sample),
//     data from the `simulate` experiment; goals: batch_ls >= 300,000 samples/s, rls >= 50,000;
//   - on the estimator tests' model (6 equations, p = 52 with extra columns), which costs almost
//     nothing to evaluate, so it measures the estimator alone.
// Memory of batch_ls / rls / wls does not grow with the number of samples: the data are streamed
// through the model in chunks of chunk_samples and folded into a (p+1)^2 factor.
// Single-threaded: items_per_second is per CPU second (one core).
#include <benchmark/benchmark.h>

#include <memory>

#include "../tests/estimators/estimator_test_model.hpp"
#include "exid/config.hpp"
#include "exid/estimators/common.hpp"
#include "exid/registry.hpp"

namespace {

exid::Registry& registry() {
  static exid::Registry* r = [] {
    auto* reg = new exid::Registry();
    reg->scan();
    return reg;
  }();
  return *r;
}

template <class T>
std::shared_ptr<T> create(const std::string& name, const std::string& yaml = "{}") {
  const exid::PluginInfo& info = registry().get(T::kKind, name);
  exid::ParamSet ps = exid::resolveParams(info, yaml, name, EXID_SOURCE_DIR);
  return registry().create<T>(name, ps);
}

struct Setup {
  std::shared_ptr<exid::ObservationModel> model;
  exid::Dataset data;
  std::string error;
};

const Setup& testModel() {
  static Setup s = [] {
    Setup x;
    const int n = 6;
    auto m = est_test::makeModel(n, 41);  // p = 5 + 6 + 41 = 52, like the PUMA 560
    est_test::DataOptions o;
    o.samples = 20000;
    o.tau_noise = std::vector<double>(n, 0.1);
    x.data = est_test::makeData(*m, n, o);
    x.model = m;
    return x;
  }();
  return s;
}

const Setup& puma() {
  static Setup s = [] {
    Setup x;
    try {
      exid::RunContext ctx;
      ctx.seed = 3;
      auto robot = create<exid::Robot>("puma560")->build(ctx);
      x.model = create<exid::ObservationModel>("differential");
      x.model->bind(robot, ctx);
      x.data = create<exid::Experiment>(
                   "simulate", "{sample_period_s: 0.001, duration_s: 20, noise_tau_Nm: 0.2}")
                   ->run(robot, nullptr, ctx);
    } catch (const std::exception& e) {
      x.error = e.what();
      x.model.reset();
    }
    return x;
  }();
  return s;
}

void run(benchmark::State& state, const Setup& s, const std::string& est,
         const std::string& params) {
  if (!s.model) {
    state.SkipWithError(("setup failed: " + s.error).c_str());
    return;
  }
  auto e = create<exid::Estimator>(est, params);
  exid::RunContext ctx;
  for (auto _ : state) {
    try {
      exid::Estimate r = e->estimate(*s.model, s.data, nullptr, ctx);
      benchmark::DoNotOptimize(r.value.data());
    } catch (const std::exception& ex) {
      state.SkipWithError(ex.what());
      return;
    }
  }
  state.SetItemsProcessed(state.iterations() * s.data.size());
  state.counters["p"] = s.model->numBase();
  state.counters["samples"] = s.data.size();
}

void rowsOnly(benchmark::State& state, const Setup& s) {
  if (!s.model) {
    state.SkipWithError(("setup failed: " + s.error).c_str());
    return;
  }
  // The baseline for batch_ls: the model's rows alone, streamed in batch_ls's default chunks.
  exid::RunContext ctx;
  for (auto _ : state)
    exid::estimators::forEachChunk(
        *s.model, s.data, 64, ctx, "rows", 0.0, 1.0,
        [](const exid::Rows& r, int, int) { benchmark::DoNotOptimize(r.W.data()); });
  state.SetItemsProcessed(state.iterations() * s.data.size());
}

}  // namespace

BENCHMARK_CAPTURE(run, puma_batch_ls, puma(), "batch_ls", "{}")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(run, puma_batch_ls_qr, puma(), "batch_ls", "{accumulate: qr}")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(run, puma_batch_ls_normal, puma(), "batch_ls", "{accumulate: normal}")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(run, puma_rls, puma(), "rls", "{history_stride: 1000}")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(run, puma_rls_standard, puma(), "rls", "{history_stride: 1000, update: standard}")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(run, puma_wls, puma(), "wls", "{}")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(rowsOnly, puma_model_rows_only, puma())->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(run, testmodel_batch_ls, testModel(), "batch_ls", "{}")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(run, testmodel_batch_ls_qr, testModel(), "batch_ls", "{accumulate: qr}")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(run, testmodel_batch_ls_normal, testModel(), "batch_ls", "{accumulate: normal}")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(run, testmodel_rls, testModel(), "rls", "{history_stride: 1000}")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(run, testmodel_rls_standard, testModel(), "rls",
                  "{history_stride: 1000, update: standard}")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(run, testmodel_wls, testModel(), "wls", "{}")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(rowsOnly, testmodel_rows_only, testModel())->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();
