// exid — what a stage gets from the runner: where to write, logging, progress, a wall-clock
// budget and a seed.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>

#include "exid/export.hpp"

namespace exid {

enum class LogLevel { Quiet = 0, Warn = 1, Info = 2, Debug = 3 };

/// Logging to stderr with levels (-q, -v); one instance per process, thread-safe.
EXID_API void setLogLevel(LogLevel level);
EXID_API LogLevel logLevel();
EXID_API void logWarn(const std::string& msg);
EXID_API void logInfo(const std::string& msg);
EXID_API void logDebug(const std::string& msg);

/// The CPUs this process may run on (its affinity mask, as `taskset` sets it; the machine's
/// count where the mask cannot be read), at least 1.
EXID_API int usableCores();
/// Threads for a `threads` parameter: n > 0 as given (at most 256), 0 usableCores() (at most 8).
EXID_API int resolveThreads(long requested);

/// A wall-clock budget; zero or negative seconds means none.
class EXID_API Deadline {
 public:
  Deadline() = default;
  explicit Deadline(double seconds);
  bool expired() const;
  double remaining_s() const;  // +inf without a budget
  bool active() const { return active_; }

 private:
  bool active_ = false;
  std::chrono::steady_clock::time_point end_{};
};

struct EXID_API RunContext {
  std::filesystem::path study_dir;  // relative paths in the study resolve here
  std::filesystem::path out_dir;    // where the stage may write files ("" = nowhere)
  std::uint64_t seed = 1;
  Deadline deadline;
  /// Progress of a long stage: fraction in [0, 1] and a short text. Optional.
  std::function<void(double, const std::string&)> progress;
  /// Set by the runner when the process is asked to stop (SIGINT/SIGTERM) or the budget ends.
  std::function<bool()> cancelled;

  void report(double fraction, const std::string& text) const {
    if (progress) progress(fraction, text);
  }
  bool shouldStop() const { return deadline.expired() || (cancelled && cancelled()); }
};

}  // namespace exid
