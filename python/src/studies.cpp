// exid — studies, matrices and CSV files from Python (module exid._exid): run_study (its progress
// forwarded to a Python callable), resolved_study, run_matrix (stopped by Ctrl-C as the exid
// program is), read_csv.
#include <Python.h>
#include <fmt/format.h>
#include <pybind11/stl.h>
#include <signal.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "exid/config.hpp"
#include "exid/io.hpp"
#include "exid/matrix.hpp"
#include "exid/runner.hpp"
#include "exid/study_check.hpp"
#include "module.hpp"

namespace fs = std::filesystem;

namespace exid_python {

namespace {

// ---------------------------------------------------------------- cancellation (Ctrl-C)
// A run or matrix started from Python's main thread stops on SIGINT as the exid program does:
// while it runs (GIL released, stages possibly in other threads, where Python could not run
// its own handler) SIGINT sets a flag that the run polls through RunOptions::cancelled; the
// run ends as "cancelled", Python's handler is put back and KeyboardInterrupt is raised.
std::atomic<bool> g_interrupted{false};
extern "C" void onInterrupt(int) { g_interrupted = true; }

class InterruptScope {
 public:
  InterruptScope() {
    g_interrupted = false;
    py::object threading = py::module_::import("threading");
    if (!threading.attr("current_thread")().is(threading.attr("main_thread")())) return;
    struct sigaction sa {};
    sa.sa_handler = onInterrupt;
    sigemptyset(&sa.sa_mask);
    installed_ = sigaction(SIGINT, &sa, &old_) == 0;
  }
  ~InterruptScope() {
    if (installed_) sigaction(SIGINT, &old_, nullptr);
  }
  InterruptScope(const InterruptScope&) = delete;
  InterruptScope& operator=(const InterruptScope&) = delete;
  static std::function<bool()> flag() {
    return [] { return g_interrupted.load(); };
  }
  /// After the run, with the GIL: KeyboardInterrupt when SIGINT stopped it.
  void rethrow() {
    if (installed_) sigaction(SIGINT, &old_, nullptr);
    installed_ = false;
    if (g_interrupted.exchange(false)) {
      PyErr_SetNone(PyExc_KeyboardInterrupt);
      throw py::error_already_set();
    }
  }

 private:
  struct sigaction old_ {};
  bool installed_ = false;
};

// ---------------------------------------------------------------- progress
// RunOptions::progress is called by the stages, with the GIL released and possibly from another
// thread than the one that started the run. Each call that passes the throttle takes the GIL and
// calls the Python callable (stage, fraction, text); an exception it raises is reported as
// unraisable (sys.unraisablehook) and never reaches the C++ stage. The throttle passes a stage's
// first call, its end (fraction >= 1) and otherwise one call every kProgressInterval_s at most,
// so a stage that reports per iteration costs a few GIL round trips a second, not one per
// iteration.
constexpr double kProgressInterval_s = 0.25;

class ProgressForwarder {
 public:
  explicit ProgressForwarder(py::object callback) : callback_(std::move(callback)) {}
  void operator()(const std::string& stage, double fraction, const std::string& text) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      const auto now = std::chrono::steady_clock::now();
      const bool due = stage != last_stage_ || fraction >= 1.0 ||
                       std::chrono::duration<double>(now - last_).count() >= kProgressInterval_s;
      if (!due) return;
      last_stage_ = stage;
      last_ = now;
    }
    py::gil_scoped_acquire gil;
    try {
      callback_(stage, fraction, text);
    } catch (py::error_already_set& e) {
      e.discard_as_unraisable("exid.run_study progress callback");
    }
  }

 private:
  py::object callback_;
  std::mutex mutex_;
  std::string last_stage_;
  std::chrono::steady_clock::time_point last_{};
};

// ---------------------------------------------------------------- studies
exid::StudyConfig studyConfig(const std::string& path, const std::string& text,
                              const std::string& source, const std::string& base_dir) {
  exid::Registry& reg = registry();
  if (!path.empty()) return exid::loadStudy(path, reg);
  const fs::path dir = base_dir.empty() ? fs::current_path() : fs::path(base_dir);
  return exid::parseStudy(text, source, dir, reg);
}

py::dict runStudy(const std::string& path, const std::string& text, const std::string& source,
                  const std::string& base_dir, const std::string& out, const std::string& stage,
                  const std::string& data, const py::object& progress) {
  exid::StudyConfig cfg = studyConfig(path, text, source, base_dir);
  if (!stage.empty())
    cfg = exid::stageStudy(std::move(cfg), stage, registry(), data);
  else if (!data.empty())
    throw py::value_error("run_study: data applies to stage='identify' alone");
  exid::RunOptions opt;
  // What exid validate checks, before anything runs (as exid run): exid.Error at once
  opt.robot = exid::checkStudy(cfg, registry(), source.empty() ? path : source);
  opt.out_dir = out;
  InterruptScope interrupt;
  opt.cancelled = InterruptScope::flag();
  std::shared_ptr<ProgressForwarder> forward;
  if (!progress.is_none()) {
    forward = std::make_shared<ProgressForwarder>(progress);
    opt.progress = [forward](const std::string& at, double f, const std::string& what) {
      (*forward)(at, f, what);
    };
  }
  exid::StudyResult r;
  {
    py::gil_scoped_release nogil;
    r = exid::runStudy(cfg, registry(), opt);
  }
  opt.progress = nullptr;
  interrupt.rethrow();
  py::dict d;
  d["ok"] = r.ok;
  d["cancelled"] = r.cancelled;
  d["message"] = r.message;
  d["summary"] = r.summary.dump(-1);
  d["written_to"] = r.written_to.string();
  d["name"] = cfg.name;
  return d;
}

std::string resolvedStudy(const std::string& path, const std::string& text,
                          const std::string& source, const std::string& base_dir) {
  const exid::StudyConfig cfg = studyConfig(path, text, source, base_dir);
  exid::checkStudy(cfg, registry(), source.empty() ? path : source);  // as exid validate
  return cfg.resolvedYaml();
}

py::dict runMatrix(const std::string& file, const std::string& out, int jobs, bool retry_failed,
                   bool force) {
  exid::Registry& reg = registry();
  const exid::MatrixSpec spec = exid::loadMatrix(file, reg);
  exid::MatrixOptions opt;
  opt.out_dir = out.empty() ? fs::path("out") / spec.name : fs::path(out);
  opt.jobs = std::max(1, jobs);
  opt.retry_failed = retry_failed;
  opt.force = force;
  InterruptScope interrupt;
  opt.cancelled = InterruptScope::flag();
  exid::MatrixRunSummary s;
  {
    py::gil_scoped_release nogil;
    s = exid::runMatrix(spec, reg, opt);
  }
  interrupt.rethrow();
  py::dict d;
  d["name"] = spec.name;
  d["out"] = opt.out_dir.string();
  d["database"] = (opt.out_dir / opt.database).string();
  d["total"] = s.total;
  d["ok"] = s.ok;
  d["failed"] = s.failed;
  d["timeout"] = s.timeout;
  d["skipped"] = s.skipped;
  d["not_run"] = s.not_run;
  d["wall_s"] = s.wall_s;
  return d;
}

py::tuple readCsv(const std::string& path) {
  exid::CsvTable t;
  {
    py::gil_scoped_release nogil;
    t = exid::readCsv(path);
  }
  OutArray a({static_cast<py::ssize_t>(t.data.rows()), static_cast<py::ssize_t>(t.data.cols())});
  Eigen::Map<RowMajor>(a.mutable_data(), t.data.rows(), t.data.cols()) = t.data;
  return py::make_tuple(t.columns, a);
}

}  // namespace

void bindStudies(py::module_& m) {
  m.def("run_study", &runStudy, py::arg("path"), py::arg("text"), py::arg("source"),
        py::arg("base_dir"), py::arg("out"), py::arg("stage"), py::arg("data"),
        py::arg("progress") = py::none());
  m.def("resolved_study", &resolvedStudy, py::arg("path"), py::arg("text"), py::arg("source"),
        py::arg("base_dir"));
  m.def("run_matrix", &runMatrix, py::arg("file"), py::arg("out"), py::arg("jobs"),
        py::arg("retry_failed"), py::arg("force"));
  m.def("read_csv", &readCsv, py::arg("path"));
}

}  // namespace exid_python
