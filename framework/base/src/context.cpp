#include "exid/context.hpp"

#include <sched.h>

#include <algorithm>
#include <atomic>
#include <iostream>
#include <limits>
#include <mutex>
#include <thread>

namespace exid {

namespace {
std::atomic<int> g_level{static_cast<int>(LogLevel::Info)};
std::mutex g_log_mutex;
void emit(const char* tag, const std::string& msg) {
  std::lock_guard<std::mutex> lock(g_log_mutex);
  std::cerr << "[exid] " << tag << msg << '\n';
}
}  // namespace

void setLogLevel(LogLevel level) { g_level = static_cast<int>(level); }
LogLevel logLevel() { return static_cast<LogLevel>(g_level.load()); }
void logWarn(const std::string& msg) {
  if (g_level >= static_cast<int>(LogLevel::Warn)) emit("warning: ", msg);
}
void logInfo(const std::string& msg) {
  if (g_level >= static_cast<int>(LogLevel::Info)) emit("", msg);
}
void logDebug(const std::string& msg) {
  if (g_level >= static_cast<int>(LogLevel::Debug)) emit("debug: ", msg);
}

int usableCores() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) == 0) {
    const int n = CPU_COUNT(&set);
    if (n > 0) return n;
  }
  const unsigned hw = std::thread::hardware_concurrency();
  return hw == 0 ? 1 : static_cast<int>(hw);
}

int resolveThreads(long requested) {
  if (requested > 0) return static_cast<int>(std::min<long>(requested, 256));
  return std::max(1, std::min(8, usableCores()));
}

Deadline::Deadline(double seconds) {
  // Over 1e9 s (32 years) is no budget: converting more to clock ticks overflowed (a budget_s of
  // 1e308 wrapped to an end in the past and the study timed out at once).
  if (seconds > 0 && seconds < 1e9) {
    active_ = true;
    end_ = std::chrono::steady_clock::now() +
           std::chrono::duration_cast<std::chrono::steady_clock::duration>(
               std::chrono::duration<double>(seconds));
  }
}
bool Deadline::expired() const { return active_ && std::chrono::steady_clock::now() >= end_; }
double Deadline::remaining_s() const {
  if (!active_) return std::numeric_limits<double>::infinity();
  return std::chrono::duration<double>(end_ - std::chrono::steady_clock::now()).count();
}

}  // namespace exid
