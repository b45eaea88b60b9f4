// exid — a study's run folder as a unit, and the watchdog that ends a run which does not stop
// when asked (runner.cpp's helpers; private to the study layer).
#pragma once

#include <fmt/format.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>

#include "exid/config.hpp"
#include "exid/io.hpp"
#include "exid/json.hpp"
#include "exid/runner.hpp"

namespace exid {

namespace fs = std::filesystem;

// A run writes into a fresh staging folder beside the output folder (.NAME.staging.PID, same
// file system) and publishes it at the end in one rename (renameat2 RENAME_EXCHANGE when the
// output folder exists). A failed or cancelled run beside an earlier successful one leaves that
// one untouched and is published as NAME.failed; a successful run removes NAME.failed.
struct RunFolder {
  fs::path final_dir, parent, staging, failed_dir;
  fs::path named;  // final_dir as the user named it (a symbolic link to final_dir, or the same)
};

/// A folder that holds a run (its summary.json or study.resolved.yaml).
bool isRunFolder(const fs::path& dir);
/// A folder whose summary.json says status ok.
bool holdsOkRun(const fs::path& dir);
/// The staging folder beside `out` (created) and the names the run is published under.
RunFolder prepareRunFolder(const fs::path& out, bool clean_stale);
/// Moves the staging folder to `to` (which may exist: exchanged atomically, then the old one
/// removed).
void publish(const fs::path& staging, const fs::path& to);

/// Seconds since a time point.
inline double secondsSince(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// Ends the process when a cancelled run does not stop by itself in time (RunOptions::
// hard_stop_s). The main thread holds finishing() while it writes the final summary and
// publishes; the watchdog takes it before it acts, so only one of them publishes.
class Watchdog {
 public:
  Watchdog(const RunOptions& opt, RunFolder folder, const StudyConfig& cfg,
           const std::atomic<const char*>& stage, std::chrono::steady_clock::time_point t0)
      : opt_(opt), folder_(std::move(folder)), stage_(stage), t0_(t0) {
    if (!(opt.hard_stop_s > 0) || !opt.cancelled) return;
    study_ = cfg.name;
    hash_ = cfg.hash();
    thread_ = std::thread([this] { watch(); });
  }
  ~Watchdog() {
    {
      std::lock_guard<std::mutex> l(m_);
      done_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }
  Watchdog(const Watchdog&) = delete;
  Watchdog& operator=(const Watchdog&) = delete;
  std::mutex& finishing() { return finishing_; }
  void finished() {
    std::lock_guard<std::mutex> l(m_);
    done_ = true;
    cv_.notify_all();
  }

 private:
  void watch() {
    std::unique_lock<std::mutex> l(m_);
    std::optional<std::chrono::steady_clock::time_point> since;
    while (!done_) {
      cv_.wait_for(l, std::chrono::milliseconds(20));
      if (done_) return;
      if (!since && opt_.cancelled()) since = std::chrono::steady_clock::now();
      if (since && secondsSince(*since) > opt_.hard_stop_s) break;
    }
    if (done_) return;
    l.unlock();
    std::unique_lock<std::mutex> fin(finishing_, std::try_to_lock);
    if (!fin.owns_lock()) return;  // the main thread is already writing the final summary
    hardStop();
  }

  void hardStop() {
    const int code = opt_.hard_stop_exit_code ? opt_.hard_stop_exit_code() : 130;
    const std::string stage = stage_.load();
    if (!folder_.staging.empty()) {
      // Move the staging folder away first: a file the stage is writing can no longer be
      // renamed into place, and its temporary is removed below.
      std::error_code ec;
      const fs::path moved =
          folder_.parent /
          fmt::format(".{}.cancel.{}", folder_.final_dir.filename().string(), ::getpid());
      fs::remove_all(moved, ec);
      fs::rename(folder_.staging, moved, ec);
      if (!ec) {
        for (auto it = fs::directory_iterator(moved, ec); !ec && it != fs::directory_iterator();
             it.increment(ec))
          if (it->path().filename().string().find(".tmp.") != std::string::npos)
            fs::remove(it->path(), ec);
        Json S = Json::object();
        S["status"] = "cancelled";
        S["study"] = study_;
        S["exid_version"] = EXID_VERSION_STRING;
        S["config_hash"] = hash_;
        S["failed_stage"] = stage;
        S["message"] = fmt::format(
            "stage '{}': stopped: interrupted (the stage had not reached a stop check {} s after "
            "the request; ended by the watchdog, results of the stage discarded)",
            stage, opt_.hard_stop_s);
        S["wall_s"] = secondsSince(t0_);
        try {
          writeFileAtomic(moved / "summary.json", S.dump(2) + "\n");
          const bool beside = holdsOkRun(folder_.final_dir);
          publish(moved, beside ? folder_.failed_dir : folder_.final_dir);
        } catch (const std::exception&) {
          fs::remove_all(moved, ec);
        }
      }
      std::fprintf(stderr,
                   "exid: stage '%s' cancelled: stopped by the watchdog %.1f s after the "
                   "stop request\n",
                   stage.c_str(), opt_.hard_stop_s);
    }
    std::fflush(nullptr);
    ::_exit(code);
  }

  const RunOptions& opt_;
  RunFolder folder_;
  const std::atomic<const char*>& stage_;
  std::chrono::steady_clock::time_point t0_;
  std::string study_, hash_;
  std::thread thread_;
  std::mutex m_, finishing_;
  std::condition_variable cv_;
  bool done_ = false;
};

}  // namespace exid
