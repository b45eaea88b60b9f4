// exid — command line.
#include <fmt/format.h>
#include <unistd.h>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include <CLI/CLI.hpp>
#include <atomic>
#include <chrono>
#include <csignal>
#include <iostream>
#include <mutex>

#include "commands.hpp"
#include "exid/config.hpp"
#include "exid/context.hpp"
#include "exid/error.hpp"
#include "exid/registry.hpp"
#include "exid/runner.hpp"
#include "exid/study_check.hpp"
#include "exid/version.hpp"

namespace {

namespace fs = std::filesystem;

std::atomic<bool> g_stop{false};
std::atomic<int> g_signal{0};
extern "C" void onSignal(int sig) {
  g_signal = sig;
  g_stop = true;
}

// exid run STUDY [--out DIR] / exid validate STUDY.
int runOrValidate(exid::Registry& registry, const std::string& file, bool validate_only,
                  std::string out_dir) {
  exid::StudyConfig cfg = exid::loadStudy(file, registry);
  // The same checks for both, before anything runs: the robot loaded, every plugin made from
  // its parameters (their constructors check them together), a prior's file read.
  std::shared_ptr<const exid::RobotModel> robot = exid::checkStudy(cfg, registry, file);
  if (validate_only) {
    std::cout << fmt::format("{}: valid (configuration hash {})\n", file, cfg.hash());
    std::cout << cfg.resolvedYaml();
    return 0;
  }
  if (out_dir.empty()) out_dir = "out/" + cfg.name;  // a plain name (validated)
  exid::RunOptions opt;
  opt.out_dir = out_dir;
  opt.robot = std::move(robot);
  exid::cli::ProgressPrinter printer;
  opt.progress = printer.callback();
  opt.cancelled = [] { return g_stop.load(); };
  opt.hard_stop_s = 0.5;  // SIGINT/SIGTERM end any stage within about 1 s
  opt.hard_stop_exit_code = exid::cli::signalExitCode;
  exid::logInfo(fmt::format("running study '{}' ({}) -> {}", cfg.name, file, out_dir));
  exid::StudyResult r = exid::runStudy(cfg, registry, opt);
  if (r.ok && r.headline.verdict == "suspect") {
    std::cout << "VERDICT: SUSPECT: the study ran to the end, but its results fail checks of their "
                 "own:\n";
    for (const auto& reason : r.headline.verdict_reasons) std::cout << "  - " << reason << "\n";
    std::cout << "\n";
  }
  std::cout << exid::briefTable(r.headline);
  if (!r.ok) {
    std::cerr << fmt::format(
        "exid: study '{}' {}: {}\n{}\n", cfg.name, r.cancelled ? "cancelled" : "failed", r.message,
        r.written_to.empty()
            ? std::string("(nothing was written)")
            : fmt::format("(details in {}/summary.json{})", r.written_to.string(),
                          r.written_to != fs::path(out_dir).lexically_normal()
                              ? fmt::format("; the earlier results in {} are untouched", out_dir)
                              : ""));
    return r.cancelled ? exid::cli::signalExitCode() : 1;
  }
  std::cout << fmt::format("\nFull report: {}/report.md (summary: {}/summary.json)\n", out_dir,
                           out_dir);
  return 0;
}

// exid plugins [KIND] | exid plugins info NAME | exid plugins paths
int pluginsCommand(const exid::Registry& registry, const std::vector<std::string>& plugins_args) {
  if (!plugins_args.empty() && plugins_args[0] == "paths") {  // where plugins are searched
    if (plugins_args.size() != 1) throw exid::Error("usage: exid plugins paths");
    for (const auto& p : registry.searchPaths()) std::cout << p.string() << "\n";
    return 0;
  }
  if (!plugins_args.empty() && plugins_args[0] == "info") {
    if (plugins_args.size() != 2) throw exid::Error("usage: exid plugins info NAME");
    std::cout << exid::pluginInfoText(registry, plugins_args[1]);
    return 0;
  }
  std::optional<exid::PluginKind> kind;
  if (!plugins_args.empty()) kind = exid::pluginKindFromString(plugins_args[0]);
  std::cout << exid::pluginListText(registry, kind);
  return registry.plugins().empty() ? 1 : 0;
}

}  // namespace

std::function<bool()> exid::cli::cancelled() {
  return [] { return g_stop.load(); };
}

int exid::cli::signalExitCode() { return 128 + (g_signal.load() > 0 ? g_signal.load() : SIGINT); }

namespace {
// glibc's malloc returns the top of its heap to the system whenever more than its trim threshold
// is free there, and serves blocks above its mmap threshold by mmap: an estimator that builds
// and frees a few MB of rows per evaluation (varpro, 777 passes on examples/real/tx40_varpro.yaml)
// faulted those pages in again every time, 4.7 s of system time of its 24 s. Blocks up to 16 MB
// come from the heap, and up to 32 MB of it is kept free for the next pass: the page faults are
// gone, for some MB more of peak resident size (38 -> 47 MB on tx40_varpro, 52 -> 59 MB on
// tx40_didim_open). A recording read whole keeps its numbers in mappings of its own
// (exid::readCsvTable), not in the heap.
void keepFreedMemoryForReuse() {
#if defined(__GLIBC__)
  mallopt(M_MMAP_THRESHOLD, 16 << 20);
  mallopt(M_TRIM_THRESHOLD, 32 << 20);
#endif
}
}  // namespace

int main(int argc, char** argv) {
  keepFreedMemoryForReuse();
  CLI::App app{
      "exid — experimental identification of robot and payload dynamics, and the "
      "design of exciting trajectories"};
  app.require_subcommand(1);
  // Global options are accepted before or after the subcommand (`exid run X -q`): every
  // subcommand, nested ones included, passes the options it does not know to its parent.
  app.fallthrough();
  app.set_version_flag("-V,--version",
                       fmt::format("exid {} (commit {})", EXID_VERSION_STRING, exid::gitCommit()),
                       "print exid's version and the git commit it was built from");
  std::vector<std::string> plugin_paths;
  bool verbose = false, quiet = false;
  app.add_option("--plugin-path", plugin_paths,
                 "extra directory with plugin libraries (searched first)")
      ->take_all();
  app.add_flag("-v,--verbose", verbose, "more log output");
  app.add_flag("-q,--quiet", quiet, "only errors");

  exid::Registry registry;
  auto setup = [&]() {
    exid::setLogLevel(quiet ? exid::LogLevel::Quiet
                            : (verbose ? exid::LogLevel::Debug : exid::LogLevel::Info));
    for (const auto& p : plugin_paths) registry.addSearchPath(p);
    registry.scan();
  };

  // exid run
  std::string study_file, out_dir;
  auto* run = app.add_subcommand("run", "run a whole study");
  run->add_option("study", study_file, "study YAML file")->required();
  run->add_option("--out", out_dir, "output folder (default: out/<study name>)");

  // exid validate
  std::string validate_file;
  auto* validate = app.add_subcommand("validate", "check a study file without running it");
  validate->add_option("study", validate_file, "study YAML file")->required();

  // exid plugins [KIND] | exid plugins info NAME | exid plugins paths
  std::vector<std::string> plugins_args;
  auto* plugins = app.add_subcommand(
      "plugins", "list plugins: exid plugins [KIND] | exid plugins info NAME | exid plugins paths");
  plugins->add_option("args", plugins_args,
                      "KIND, 'info NAME', or 'paths' (where plugins are searched)");

  exid::cli::Commands extra = exid::cli::addCommands(app, registry);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version exit 0; every usage error exits 2 (CLI11's own codes are 100+).
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }

  // Commands that poll the stop flag (runs and matrices) turn SIGINT/SIGTERM into a clean stop;
  // the others (robot info, eval, export, validate, ...) keep the default action and end at once
  // (they write only atomically, so nothing is half written).
  if (*run || app.got_subcommand("matrix") || app.got_subcommand("excite") ||
      app.got_subcommand("simulate") || app.got_subcommand("identify")) {
    std::signal(SIGINT, onSignal);
    std::signal(SIGTERM, onSignal);
  }

  try {
    setup();
    if (*run || *validate)
      return runOrValidate(registry, *run ? study_file : validate_file,
                           static_cast<bool>(*validate), out_dir);
    if (*plugins) return pluginsCommand(registry, plugins_args);
    return extra.run();
  } catch (const exid::Error& e) {
    std::cerr << "exid: " << e.what() << '\n';
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "exid: unexpected error: " << e.what() << '\n';
    return 3;
  }
}
