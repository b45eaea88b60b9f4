// Long recordings, whole process: `exid run` of a study reading a recorded CSV, timed from the
// outside (wall time and the child's maximum resident set size, from wait4), as a user sees it.
//
//   - recorded PUMA 560 CSV (t, q, qd, qdd, tau: 25 columns, 1 kHz) of 100 k and 1 M samples
//     (EXID_BENCH_LONG_SAMPLES=10000000 adds 10 M on 1 and 2 threads) -> batch_ls on 1 thread, and
//     1 M on 2 (the recording is streamed from the file: summary experiment.streamed; the
//     experiment's scan of the time stamps uses as many threads as the estimator);
//   - the same 1 M samples without qd, qdd -> filtered_ls {cutoff_hz: 20} on 1 and 2 threads;
//   - examples/real/tx40_filtered_ls.yaml (30 k samples at 5 kHz), tx40_varpro.yaml and
//     tx40_didim_open.yaml (output error; wall and CPU time).
//
// Baselines in the same run: reading the same file once (std::fread into a 4 MB buffer), and
// reading it with every number parsed (std::from_chars on each cell), so that the figures are
// quoted as "times the plain read" and "times the read and parse" as well as in seconds.
//
//   build/bin/bench_long            (the files are generated once into $TMPDIR/exid_bench_long)
#include <benchmark/benchmark.h>
#include <fmt/format.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

fs::path workDir() {
  const fs::path d = fs::temp_directory_path() / "exid_bench_long";
  fs::create_directories(d);
  return d;
}

/// A recorded-looking CSV: smooth motion of the 6 joints, torques with a little noise.
fs::path recording(long samples, bool derivatives) {
  const fs::path f =
      workDir() / fmt::format("puma_{}_{}.csv", samples, derivatives ? "qdqdd" : "raw");
  if (fs::exists(f)) return f;
  std::FILE* out = std::fopen((f.string() + ".part").c_str(), "w");
  std::string line = "t";
  for (const char* g : {"q", "qd", "qdd", "tau"}) {
    if (!derivatives && (std::string(g) == "qd" || std::string(g) == "qdd")) continue;
    for (int j = 1; j <= 6; ++j) line += fmt::format(",{}{}", g, j);
  }
  std::fputs((line + "\n").c_str(), out);
  unsigned long long s = 88172645463325252ULL;  // xorshift noise
  auto noise = [&] {
    s ^= s << 13;
    s ^= s >> 7;
    s ^= s << 17;
    return (static_cast<double>(s % 2000001) / 1e6 - 1.0) * 0.05;
  };
  for (long k = 0; k < samples; ++k) {
    const double t = 1e-3 * static_cast<double>(k);
    line = fmt::format("{:.3f}", t);
    for (int j = 0; j < 6; ++j)
      line += fmt::format(",{:.9g}", 0.8 * std::sin(0.5 * (j + 1) * t + j));
    if (derivatives) {
      for (int j = 0; j < 6; ++j)
        line += fmt::format(",{:.9g}", 0.4 * (j + 1) * std::cos(0.5 * (j + 1) * t + j));
      for (int j = 0; j < 6; ++j)
        line += fmt::format(",{:.9g}", -0.2 * (j + 1) * (j + 1) * std::sin(0.5 * (j + 1) * t + j));
    }
    for (int j = 0; j < 6; ++j)
      line += fmt::format(",{:.7g}", 20.0 * std::cos(0.3 * (j + 1) * t) + noise());
    std::fputs((line + "\n").c_str(), out);
  }
  std::fclose(out);
  fs::rename(f.string() + ".part", f);
  return f;
}

struct Child {
  double wall_s = 0;
  double cpu_s = 0;  // user + system
  long max_rss_kb = 0;
  int status = -1;
};

Child runExid(const std::vector<std::string>& args) {
  const auto t0 = std::chrono::steady_clock::now();
  const pid_t pid = fork();
  if (pid == 0) {
    std::vector<char*> argv;
    const std::string exe = std::string(EXID_BINARY_DIR) + "/bin/exid";
    argv.push_back(const_cast<char*>(exe.c_str()));
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    std::freopen("/dev/null", "w", stdout);
    execv(exe.c_str(), argv.data());
    _exit(127);
  }
  Child c;
  rusage ru{};
  wait4(pid, &c.status, 0, &ru);
  c.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  c.max_rss_kb = ru.ru_maxrss;
  c.cpu_s = static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
            1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
  return c;
}

double plainRead(const fs::path& f) {
  const auto t0 = std::chrono::steady_clock::now();
  std::FILE* in = std::fopen(f.c_str(), "rb");
  std::vector<char> buf(4 << 20);
  std::size_t total = 0;
  while (std::size_t n = std::fread(buf.data(), 1, buf.size(), in)) total += n;
  std::fclose(in);
  benchmark::DoNotOptimize(total);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// The plain read with the numbers: the same blocks, every cell of every line after the header
// parsed by std::from_chars (libstdc++'s, the Eisel-Lemire/fast_float algorithm: the fastest
// double parser on the machine), nothing checked or kept. The floor of any reader of the text.
double plainReadParse(const fs::path& f) {
  const auto t0 = std::chrono::steady_clock::now();
  std::FILE* in = std::fopen(f.c_str(), "rb");
  std::vector<char> buf(4 << 20);
  std::size_t keep = 0;  // the bytes of an incomplete last line, moved to the front
  bool header = true;
  double sum = 0;
  long cells = 0;
  while (std::size_t n = std::fread(buf.data() + keep, 1, buf.size() - keep, in)) {
    const char* p = buf.data();
    const char* end = buf.data() + keep + n;
    while (true) {
      const char* nl =
          static_cast<const char*>(std::memchr(p, '\n', static_cast<std::size_t>(end - p)));
      if (!nl) break;
      if (header) {
        header = false;
      } else {
        for (const char* c = p; c < nl;) {
          double v = 0;
          const auto r = std::from_chars(c, nl, v);
          sum += v;
          ++cells;
          c = r.ptr + 1;  // past the delimiter
        }
      }
      p = nl + 1;
    }
    keep = static_cast<std::size_t>(end - p);
    std::memmove(buf.data(), p, keep);
  }
  std::fclose(in);
  benchmark::DoNotOptimize(sum);
  benchmark::DoNotOptimize(cells);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::map<std::string, std::string>& table() {
  static std::map<std::string, std::string> t;
  return t;
}

// threads: the estimator's and the experiment's (its scan of the time stamps)
void runStudyBench(benchmark::State& state, const std::string& label, const fs::path& data,
                   const std::string& estimator, long threads) {
  const fs::path study = workDir() / (label + ".yaml");
  std::ofstream(study) << "name: " << label << "\nrobot: {type: puma560}\n"
                       << "model: {type: differential}\n"
                       << "experiment: {type: csv, params: {file: " << data.string()
                       << ", threads: " << threads << "}}\n"
                       << "estimator: " << estimator << "\n"
                       << "report: {type: standard, params: {plots: false}}\n";
  Child c;
  double read_s = 0, parse_s = 0;
  for (auto _ : state) {
    read_s = plainRead(data);
    parse_s = plainReadParse(data);
    c = runExid({"-q", "run", study.string(), "--out", (workDir() / ("out_" + label)).string()});
    state.SetIterationTime(c.wall_s);
  }
  if (c.status != 0) state.SkipWithError("exid run failed");
  state.counters["wall_s"] = c.wall_s;
  state.counters["cpu_s"] = c.cpu_s;
  state.counters["max_rss_MB"] = static_cast<double>(c.max_rss_kb) / 1024.0;
  state.counters["x_plain_read"] = c.wall_s / read_s;
  state.counters["x_read_parse"] = c.wall_s / parse_s;
  table()[label] = fmt::format(
      "{:8.2f} s {:8.0f} MB  (CPU {:.2f} s; {:.0f} x the plain read of {:.0f} MB, {:.1f} x its "
      "read and parse: {:.2f} s)",
      c.wall_s, c.max_rss_kb / 1024.0, c.cpu_s, c.wall_s / read_s,
      static_cast<double>(fs::file_size(data)) / 1e6, c.wall_s / parse_s, parse_s);
}

// range(1): threads of batch_ls and of the scan (0: the cores the process may run on)
void BM_BatchLs(benchmark::State& state) {
  const long n = state.range(0);
  const long threads = state.range(1);
  runStudyBench(state, fmt::format("batch_ls_{}_threads{}", n, threads), recording(n, true),
                fmt::format("{{type: batch_ls, params: {{threads: {}}}}}", threads), threads);
}

void BM_FilteredLs(benchmark::State& state) {
  const long n = state.range(0);
  const int threads = static_cast<int>(state.range(1));
  runStudyBench(
      state, fmt::format("filtered_ls_{}_threads{}", n, threads), recording(n, false),
      fmt::format("{{type: filtered_ls, params: {{cutoff_hz: 20, threads: {}}}}}", threads),
      threads);
}

/// examples/real/STUDY.yaml, whole process (wall, CPU and max RSS under `label` in the table).
void runExample(benchmark::State& state, const std::string& study, const std::string& label) {
  Child c;
  for (auto _ : state) {
    c = runExid({"-q", "run", std::string(EXID_SOURCE_DIR) + "/examples/real/" + study + ".yaml",
                 "--out", (workDir() / ("out_" + label)).string()});
    state.SetIterationTime(c.wall_s);
  }
  if (c.status != 0) state.SkipWithError("exid run failed");
  state.counters["wall_s"] = c.wall_s;
  state.counters["cpu_s"] = c.cpu_s;
  state.counters["max_rss_MB"] = static_cast<double>(c.max_rss_kb) / 1024.0;
  table()[label] =
      fmt::format("{:8.2f} s {:8.0f} MB  (CPU {:.2f} s)", c.wall_s, c.max_rss_kb / 1024.0, c.cpu_s);
}

void BM_Tx40FilteredLs(benchmark::State& state) {
  runExample(state, "tx40_filtered_ls", "tx40_filtered_ls");
}

// Variable projection on the real recording (examples/real/tx40_varpro.yaml: 12 nonlinear
// friction parameters and 64 base parameters), whole process.
void BM_Tx40Varpro(benchmark::State& state) { runExample(state, "tx40_varpro", "tx40_varpro"); }

// Output error on the real recording (examples/real/tx40_didim_open.yaml: 30 torque-driven
// windows of 0.2 s, 64 parameters; CVODES and the sensitivities on one thread), whole process.
void BM_Tx40DidimOpen(benchmark::State& state) {
  runExample(state, "tx40_didim_open", "tx40_didim_open");
}

}  // namespace

BENCHMARK(BM_Tx40Varpro)->UseManualTime()->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_Tx40DidimOpen)->UseManualTime()->Iterations(1)->Unit(benchmark::kSecond);
BENCHMARK(BM_BatchLs)
    ->Args({100000, 1})
    ->Args({1000000, 1})
    ->Args({1000000, 2})
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kSecond);
BENCHMARK(BM_FilteredLs)
    ->Args({1000000, 1})
    ->Args({1000000, 2})
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kSecond);
BENCHMARK(BM_Tx40FilteredLs)->UseManualTime()->Iterations(1)->Unit(benchmark::kSecond);

int main(int argc, char** argv) {
  if (const char* ten = std::getenv("EXID_BENCH_LONG_SAMPLES"))
    benchmark::RegisterBenchmark("BM_BatchLs_env", BM_BatchLs)
        ->Args({std::atol(ten), 1})
        ->Args({std::atol(ten), 2})
        ->UseManualTime()
        ->Iterations(1)
        ->Unit(benchmark::kSecond);
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  std::printf("\nwhole process, exid run (wall, max RSS, CPU user + system):\n");
  for (const auto& [k, v] : table()) std::printf("  %-28s %s\n", k.c_str(), v.c_str());
  return 0;
}
