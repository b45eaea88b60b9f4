// exid — running a matrix (runMatrix): the cells of this shard not finished yet (resume), each
// in its own forked process under its budgets (time, memory), N at a time, their outcomes
// recorded as they end (matrix_db.cpp).
#include <fcntl.h>
#include <fmt/format.h>
#include <poll.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <map>
#include <system_error>

#include "exid/context.hpp"
#include "exid/error.hpp"
#include "exid/io.hpp"
#include "exid/matrix.hpp"
#include "exid/registry.hpp"
#include "exid/runner.hpp"
#include "matrix_internal.hpp"

namespace exid {

namespace fs = std::filesystem;

// ------------------------------------------------------------------ running the cells

using matrix_detail::Db;
using matrix_detail::isoNow;
using matrix_detail::recordMatrixStart;
using matrix_detail::recordRun;

namespace {

/// The output folder belongs to one writer: an exclusive flock on DIR/.lock (released by the
/// kernel when the process ends), holding "pid host" for the message of a second writer.
class FolderLock {
 public:
  FolderLock(const fs::path& dir, const std::string& name) {
    const fs::path file = dir / name;
    fd_ = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0)
      throw Error(
          fmt::format("{}: cannot create the lock file: {}", file.string(), std::strerror(errno)));
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      char buf[256] = {0};
      const ssize_t n = ::pread(fd_, buf, sizeof buf - 1, 0);
      std::string who = n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : "unknown";
      while (!who.empty() && (who.back() == '\n' || who.back() == ' ')) who.pop_back();
      ::close(fd_);
      throw Error(fmt::format(
          "{}: the matrix folder is in use by another exid (pid {}); wait for it to finish or "
          "use another --out",
          dir.string(), who));
    }
    char host[256] = {0};
    ::gethostname(host, sizeof host - 1);
    const std::string me = fmt::format("{} on host {}\n", ::getpid(), host);
    if (::ftruncate(fd_, 0) == 0) {
      const ssize_t w = ::pwrite(fd_, me.data(), me.size(), 0);
      (void)w;
    }
  }
  ~FolderLock() {
    if (fd_ >= 0) ::close(fd_);
  }
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;

 private:
  int fd_ = -1;
};

struct Child {
  pid_t pid = -1;
  int fd = -1;
  const MatrixCell* cell = nullptr;
  std::string output;
  std::chrono::steady_clock::time_point start;
  std::string started;
  bool killed_for_time = false;
};

// A cell gets this long past its budget to stop by itself before it is killed.
constexpr double kCellGraceS = 5.0;

// Why a finished cell's inputs are no longer what it read: the first entry of its input
// manifest (summary.json `inputs`, as the cell's run recorded it) whose file is gone or whose
// size or content hash differs now; "" when every entry still holds. `now` caches the hashes
// (cells share their files).
std::string changedInput(const std::string& inputs_json, std::map<std::string, std::string>* now) {
  if (inputs_json.empty()) return "";
  Json inputs;
  try {
    inputs = Json::parse(inputs_json);
  } catch (const std::exception&) {
    return "its input manifest cannot be read";
  }
  if (!inputs.isArray()) return "its input manifest cannot be read";
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    const Json& e = inputs.at(i);
    const Json* path = e.find("path");
    const Json* hash = e.find("xxh3_64");
    const Json* size = e.find("size_bytes");
    if (path && !hash && size && e.find("fnv1a64"))
      return "its input manifest holds the hashes of an earlier exid (FNV-1a; now XXH3)";
    if (!path || !hash || !size) return "its input manifest cannot be read";
    const std::string& p = path->asString();
    auto it = now->find(p);
    if (it == now->end()) {
      std::string h;
      try {
        h = hashHex(xxh3File(p));
      } catch (const Error&) {
        h = "(not a readable file)";
      }
      it = now->emplace(p, h).first;
    }
    if (it->second != hash->asString())
      return fmt::format("{} changed since the cell ran ({}: content hash {} then, {} now)", p,
                         e.find("kind") ? e.find("kind")->asString() : "input", hash->asString(),
                         it->second);
  }
  return "";
}

// The cells of this shard not finished yet (sum: total and skipped counted). A finished cell
// whose inputs changed since it ran (a file of its manifest: inside a bag folder, a mesh, a
// data file) runs again.
std::vector<const MatrixCell*> cellsToRun(Db& db, const MatrixSpec& spec, const MatrixOptions& opt,
                                          MatrixRunSummary* sum) {
  struct Done {
    std::string status, inputs;
  };
  std::map<std::string, Done> done;  // hash -> status and input manifest
  {
    Db::Stmt s(&db,
               "SELECT hash, status, CASE WHEN json_valid(summary) THEN "
               "json_extract(summary, '$.inputs') END FROM runs");
    while (s.step()) done[s.text(0)] = Done{s.text(1), s.text(2)};
  }
  std::map<std::string, std::string> hashes_now;
  std::vector<const MatrixCell*> todo;
  for (const auto& c : spec.cells) {
    if (c.index % opt.shard_count != opt.shard_index) continue;
    ++sum->total;
    auto it = done.find(c.hash);
    // "incomplete": stopped by the machine (disk full), never a result: always run again.
    if (!opt.force && it != done.end() && it->second.status != "incomplete" &&
        (it->second.status == "ok" || !opt.retry_failed)) {
      const std::string changed = changedInput(it->second.inputs, &hashes_now);
      if (changed.empty()) {
        ++sum->skipped;
        continue;
      }
      logInfo(fmt::format("cell {} ({}): finished before, but {}: run again", c.index, c.label,
                          changed));
    }
    todo.push_back(&c);
  }
  return todo;
}

// The cell's status, message and summary from how its process ended and what it wrote.
void cellOutcome(const MatrixSpec& spec, const Child& ch, int status, double wall, std::string* st,
                 std::string* msg, Json* summary) {
  if (ch.killed_for_time) {
    *st = "timeout";
    *msg = fmt::format("over the cell budget of {} s (killed after {:.1f} s)", spec.cell_budget_s,
                       wall);
  } else if (WIFSIGNALED(status)) {
    *st = "failed";
    *msg = fmt::format("the cell's process died with signal {} ({})", WTERMSIG(status),
                       strsignal(WTERMSIG(status)));
  } else {
    try {
      *summary = Json::parse(ch.output);
      *st = summary->find("status") ? summary->find("status")->asString() : "failed";
      *msg = summary->find("message") ? summary->find("message")->asString() : "";
      const Json* to = summary->find("timed_out");
      if (*st != "ok" && to && to->asBool()) *st = "timeout";
      const Json* full = summary->find("out_of_space");
      if (*st != "ok" && full && full->asBool()) {
        *st = "incomplete";  // run again on resume
        *msg = "no space left on device (or over the file size limit): " + *msg;
      }
      const Json* oom = summary->find("out_of_memory");
      if (*st != "ok" && oom && oom->asBool() && spec.cell_memory_mb > 0)
        *msg += fmt::format(
            " (over the cell memory cap cell_memory_mb = {} MB: too small for this cell; raise "
            "it or make the cell smaller)",
            spec.cell_memory_mb);
    } catch (const std::exception& e) {
      *st = "failed";
      *msg = fmt::format("the cell's process gave no summary (exit {}): {}",
                         WIFEXITED(status) ? WEXITSTATUS(status) : -1, e.what());
    }
  }
}

// How far a run is: the cells it runs and when it started (each cell's line says how many are
// done and about how long the rest takes at the pace so far).
struct Pace {
  std::size_t to_run = 0;
  std::chrono::steady_clock::time_point t0;
  std::string after(const MatrixRunSummary& sum) const {
    const auto done = static_cast<std::size_t>(sum.ok + sum.failed + sum.timeout);
    const std::size_t left = to_run > done ? to_run - done : 0;
    const double spent =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (left == 0 || done == 0) return fmt::format("  [{}/{}]", done, to_run);
    const double eta = spent / static_cast<double>(done) * static_cast<double>(left);
    return fmt::format(
        "  [{}/{}, about {} left]", done, to_run,
        eta < 90 ? fmt::format("{:.0f} s", eta) : fmt::format("{:.0f} min", eta / 60));
  }
};

// A cell's process has ended: its outcome recorded, counted and logged.
void finishCell(Db& db, const MatrixSpec& spec, Child& ch, int status, const Pace& pace,
                MatrixRunSummary* sum) {
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - ch.start).count();
  std::string st, msg;
  Json summary = Json::object();
  cellOutcome(spec, ch, status, wall, &st, &msg, &summary);
  recordRun(db, spec, *ch.cell, st, msg, wall, ch.started, summary);
  if (st == "incomplete") ++sum->incomplete;
  if (st == "ok")
    ++sum->ok;
  else if (st == "timeout")
    ++sum->timeout;
  else
    ++sum->failed;
  logInfo(fmt::format("cell {:>3} {:<8} {:6.2f} s  {}{}{}", ch.cell->index, st, wall,
                      ch.cell->label, st == "ok" ? "" : "  (" + msg + ")", pace.after(*sum)));
}

// A std::system_error saying that memory (or a thread's stack) could not be had.
bool outOfMemory(const std::exception& e) {
  const auto* se = dynamic_cast<const std::system_error*>(&e);
  return se && (se->code() == std::errc::resource_unavailable_try_again ||
                se->code() == std::errc::not_enough_memory);
}

// In the cell's process: caps what the cell adds to the address space it inherits (the
// program, its libraries and plugins are already mapped when it is forked).
void capCellMemory(double cell_memory_mb) {
  double inherited = 0;
  if (std::FILE* f = std::fopen("/proc/self/statm", "r")) {
    unsigned long pages = 0;
    if (std::fscanf(f, "%lu", &pages) == 1)
      inherited = static_cast<double>(pages) * static_cast<double>(::sysconf(_SC_PAGESIZE));
    std::fclose(f);
  }
  const rlim_t bytes = static_cast<rlim_t>(inherited + cell_memory_mb * 1048576.0);
  struct rlimit rl {
    bytes, bytes
  };
  ::setrlimit(RLIMIT_AS, &rl);
}

// The forked cell's process: runs the cell's study and writes its summary (or the failure) to
// fds[1]; never returns.
[[noreturn]] void runCellProcess(const MatrixSpec& spec, const Registry& reg,
                                 const MatrixOptions& opt, const MatrixCell* cell, int fds[2],
                                 pid_t parent) {
  ::close(fds[0]);
  // The cell dies with its parent (no orphans when the parent is killed, even by SIGKILL);
  // the parent may have died before the request took effect.
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (::getppid() != parent) ::_exit(1);
  if (spec.cell_memory_mb > 0) capCellMemory(spec.cell_memory_mb);
  ::signal(SIGINT, SIG_IGN);  // the parent decides
  ::signal(SIGTERM, SIG_DFL);
  setLogLevel(LogLevel::Quiet);
  std::string text;
  try {
    StudyConfig cfg = cell->config;
    cfg.budget_s = spec.cell_budget_s;
    cfg.report.plots = false;  // a cell's plots would dominate the matrix's overhead
    RunOptions ro;
    if (opt.write_cell_files) ro.out_dir = opt.out_dir / "cells" / cell->hash;
    ro.clean_stale = false;  // done once for all cells (a scan of cells/ per cell is O(n^2))
    StudyResult r = runStudy(cfg, reg, ro);
    text = r.summary.dump(-1);
  } catch (const std::exception& e) {
    Json j = Json::object();
    j["status"] = "failed";
    j["message"] = e.what();
    // (a thread or a mapping the cap refused: std::system_error, EAGAIN or ENOMEM)
    if (dynamic_cast<const std::bad_alloc*>(&e) || outOfMemory(e)) j["out_of_memory"] = true;
    text = j.dump(-1);
  }
  std::size_t off = 0;
  while (off < text.size()) {
    ssize_t n = ::write(fds[1], text.data() + off, text.size() - off);
    if (n <= 0) break;
    off += static_cast<std::size_t>(n);
  }
  ::_exit(0);
}

// Forks the cell's process; the parent reads its summary from the returned child's fd.
Child startCell(const MatrixSpec& spec, const Registry& reg, const MatrixOptions& opt,
                const MatrixCell* cell) {
  int fds[2];
  if (::pipe(fds) != 0) throw Error("matrix: cannot create a pipe");
  Child ch;
  ch.cell = cell;
  ch.start = std::chrono::steady_clock::now();
  ch.started = isoNow();
  std::fflush(nullptr);
  const pid_t parent = ::getpid();
  pid_t pid = ::fork();
  if (pid < 0) throw Error("matrix: fork failed");
  if (pid == 0) runCellProcess(spec, reg, opt, cell, fds, parent);
  ::close(fds[1]);
  ::fcntl(fds[0], F_SETFL, O_NONBLOCK);
  ch.pid = pid;
  ch.fd = fds[0];
  return ch;
}

// Appends what the cell's pipe holds now to its output (the pipe does not block).
void readCellOutput(Child& ch) {
  char buf[65536];
  while (true) {
    ssize_t n = ::read(ch.fd, buf, sizeof buf);
    if (n > 0)
      ch.output.append(buf, static_cast<std::size_t>(n));
    else
      break;
  }
}

// Interrupted: the running cells are stopped and waited for, the rest counted as not run.
void stopRunningCells(const MatrixSpec& spec, std::size_t not_started, std::vector<Child>* running,
                      MatrixRunSummary* sum) {
  for (auto& ch : *running) ::kill(ch.pid, SIGTERM);
  for (auto& ch : *running) {
    ::waitpid(ch.pid, nullptr, 0);
    ::close(ch.fd);
  }
  sum->not_run = static_cast<int>(not_started + running->size());
  running->clear();
  logWarn(fmt::format("matrix '{}': interrupted; {} cells not run (finished cells are saved)",
                      spec.name, sum->not_run));
}

// One round over the running cells: their output read, those over budget killed, those ended
// recorded and removed. A cell that cannot be recorded stops every other one, then throws.
void serviceRunningCells(Db& db, const MatrixSpec& spec, std::vector<Child>* running,
                         const Pace& pace, MatrixRunSummary* sum) {
  for (std::size_t i = 0; i < running->size();) {
    Child& ch = (*running)[i];
    readCellOutput(ch);
    const double age =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - ch.start).count();
    if (spec.cell_budget_s > 0 && !ch.killed_for_time && age > spec.cell_budget_s + kCellGraceS) {
      ch.killed_for_time = true;
      ::kill(ch.pid, SIGKILL);
    }
    int status = 0;
    pid_t w = ::waitpid(ch.pid, &status, WNOHANG);
    if (w == ch.pid) {
      readCellOutput(ch);
      ::close(ch.fd);
      try {
        finishCell(db, spec, ch, status, pace, sum);
      } catch (...) {  // e.g. the database cannot be written: stop, leave no cell running
        for (auto& other : *running)
          if (other.pid != ch.pid) {
            ::kill(other.pid, SIGKILL);
            ::waitpid(other.pid, nullptr, 0);
            ::close(other.fd);
          }
        throw;
      }
      running->erase(running->begin() + static_cast<std::ptrdiff_t>(i));
      continue;
    }
    ++i;
  }
}

}  // namespace

MatrixRunSummary runMatrix(const MatrixSpec& spec, const Registry& reg, const MatrixOptions& opt) {
  const auto t0 = std::chrono::steady_clock::now();
  check(opt.shard_count >= 1 && opt.shard_index >= 0 && opt.shard_index < opt.shard_count,
        fmt::format("--shard {}/{}: expected 0 <= i < N", opt.shard_index, opt.shard_count));
  check(opt.jobs >= 1 && opt.jobs <= 1024,
        fmt::format("-j {}: expected 1 to 1024 cells at a time", opt.jobs));
  fs::create_directories(opt.out_dir);
  // Before anything in the folder is touched. MPI ranks share the folder, one database each:
  // each locks its own.
  FolderLock lock(opt.out_dir,
                  opt.database == "results.sqlite" ? ".lock" : "." + opt.database + ".lock");
  cleanStaleTemporaries(opt.out_dir);
  cleanStaleTemporaries(opt.out_dir / "cells");
  Db db(opt.out_dir / opt.database);
  recordMatrixStart(db, spec);
  MatrixRunSummary sum;
  const std::vector<const MatrixCell*> todo = cellsToRun(db, spec, opt, &sum);
  logInfo(fmt::format(
      "matrix '{}': {} cells in this shard, {} already finished, {} to run on {} job{}", spec.name,
      sum.total, sum.skipped, todo.size(), opt.jobs, opt.jobs == 1 ? "" : "s"));

  std::vector<Child> running;
  std::size_t next = 0;
  const Pace pace{todo.size(), std::chrono::steady_clock::now()};
  while ((next < todo.size() || !running.empty())) {
    const bool stop = opt.cancelled && opt.cancelled();
    while (!stop && next < todo.size() && static_cast<int>(running.size()) < std::max(1, opt.jobs))
      running.push_back(startCell(spec, reg, opt, todo[next++]));
    if (stop) {
      stopRunningCells(spec, todo.size() - next, &running, &sum);
      break;
    }
    std::vector<pollfd> pfds;
    for (auto& ch : running) pfds.push_back({ch.fd, POLLIN, 0});
    ::poll(pfds.data(), pfds.size(), 50);
    serviceRunningCells(db, spec, &running, pace, &sum);
  }
  sum.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return sum;
}

}  // namespace exid
