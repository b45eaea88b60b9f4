// exid — helpers of the robustness tests (robustness_test.cpp, robustness_matrix_test.cpp): the
// exid program run as a child process, and what it leaves in its output folders.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "exid/json.hpp"

namespace fs = std::filesystem;

namespace robustness {

inline fs::path tempDir(const std::string& name) {
  fs::path d =
      fs::temp_directory_path() / ("exid_robust_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

inline std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

struct CmdResult {
  int code = -1;    // exit code; -1 when killed by a signal
  int signal = 0;   // the signal that killed it
  std::string out;  // stdout and stderr
};

/// Runs exid with args (no shell) in dir, stdout+stderr captured; killed after timeout_s
/// (reported as signal 9) so that a hang is a failure, not a stuck test.
inline CmdResult runExid(const std::vector<std::string>& args, const fs::path& dir,
                         double timeout_s = 120, long fsize_limit = 0) {
  const fs::path log = dir / "exid_log.txt";
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (::chdir(dir.c_str()) != 0) ::_exit(126);
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    if (fsize_limit > 0) {
      ::signal(SIGXFSZ, SIG_IGN);
      rlimit rl{static_cast<rlim_t>(fsize_limit), static_cast<rlim_t>(fsize_limit)};
      ::setrlimit(RLIMIT_FSIZE, &rl);
    }
    std::vector<char*> argv;
    argv.push_back(const_cast<char*>(EXID_EXE));
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(EXID_EXE, argv.data());
    ::_exit(127);
  }
  CmdResult r;
  int status = 0;
  const auto t0 = std::chrono::steady_clock::now();
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > timeout_s) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.signal = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  r.out = slurp(log);
  return r;
}

inline bool contains(const std::string& s, const std::string& what) {
  return s.find(what) != std::string::npos;
}

inline exid::Json summaryOf(const fs::path& dir) {
  return exid::Json::parse(slurp(dir / "summary.json"));
}

inline std::string statusOf(const fs::path& dir) {
  if (!fs::exists(dir / "summary.json")) return "(no summary.json)";
  const exid::Json s = summaryOf(dir);
  return s.find("status") ? s.find("status")->asString() : "(no status)";
}

inline bool noTemporaries(const fs::path& dir) {
  for (auto& e : fs::recursive_directory_iterator(dir)) {
    const std::string n = e.path().filename().string();
    if (contains(n, ".tmp.") || contains(n, ".staging.")) return false;
  }
  return true;
}

constexpr const char* kPlanar =
    "robot: {type: planar2r}\n"
    "model: {type: differential}\n"
    "estimator: {type: batch_ls}\n";

// A two-joint recording (t, q1, q2, tau1, tau2) that moves both joints, 400 rows at 100 Hz.
inline void writeRecording(const fs::path& file, double tau_scale = 1.0) {
  std::ofstream f(file);
  f << "t,q1,q2,tau1,tau2\n";
  for (int k = 0; k < 400; ++k) {
    const double t = 0.01 * k;
    f << t << "," << std::sin(t) << "," << std::cos(1.3 * t) << "," << tau_scale * std::sin(3 * t)
      << "," << tau_scale * std::cos(2 * t) << "\n";
  }
}

}  // namespace robustness
