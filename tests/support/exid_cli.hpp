// Helpers for tests that run the exid program (the test target defines EXID_EXE): run it with
// arguments and capture its output (in a folder, with a timeout, an address-space cap and a
// file-size cap: runExidIn), read a file whole, make a fresh temporary folder.
#pragma once

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

namespace exid_cli {

struct CmdResult {
  int code = -1;
  std::string out;  // stdout and stderr
};

/// Runs `EXID_EXE args` with stderr merged into stdout.
inline CmdResult runExid(const std::string& args) {
  std::string cmd = std::string(EXID_EXE) + " " + args + " 2>&1";
  CmdResult r;
  FILE* p = ::popen(cmd.c_str(), "r");
  std::array<char, 4096> buf{};
  while (p && std::fgets(buf.data(), buf.size(), p)) r.out += buf.data();
  int status = p ? ::pclose(p) : -1;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// An empty folder $TMPDIR/<prefix><name>_<pid>.
inline std::filesystem::path freshTempDir(const std::string& prefix, const std::string& name) {
  const std::filesystem::path d =
      std::filesystem::temp_directory_path() / (prefix + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(d);
  std::filesystem::create_directories(d);
  return d;
}

inline bool contains(const std::string& s, const std::string& what) {
  return s.find(what) != std::string::npos;
}

/// True in a build under AddressSanitizer (its shadow memory exceeds any address-space cap).
inline bool underAddressSanitizer() {
#if defined(__SANITIZE_ADDRESS__)
  return true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
  return true;
#else
  return false;
#endif
#else
  return false;
#endif
}

struct RunResult {
  int code = -1;    // exit code; -1 when killed by a signal
  int signal = 0;   // the signal that killed it (9: the timeout)
  std::string out;  // stdout and stderr
};

/// Caps on the exid child of runExidIn (0: none).
struct Limits {
  /// RLIMIT_AS, in MiB (never under AddressSanitizer): an unbounded allocation fails there
  /// instead of taking the machine's memory.
  long address_space_mb = 0;
  /// RLIMIT_FSIZE, in bytes, SIGXFSZ ignored: a write past it fails with EFBIG, as on a full disk.
  long file_size_bytes = 0;
};

/// Runs `EXID_EXE args` (no shell) in dir, stdout and stderr captured through dir/exid_log.txt;
/// killed after timeout_s (reported as signal 9), so that a hang is a failure, not a stuck test.
inline RunResult runExidIn(const std::vector<std::string>& args, const std::filesystem::path& dir,
                           double timeout_s, const Limits& limits = {}) {
  const std::filesystem::path log = dir / "exid_log.txt";
  const bool cap_as = limits.address_space_mb > 0 && !underAddressSanitizer();
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (::chdir(dir.c_str()) != 0) ::_exit(126);
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    if (cap_as) {
      const auto bytes = static_cast<rlim_t>(limits.address_space_mb) * 1048576u;
      rlimit rl{bytes, bytes};
      ::setrlimit(RLIMIT_AS, &rl);
    }
    if (limits.file_size_bytes > 0) {
      ::signal(SIGXFSZ, SIG_IGN);
      const auto bytes = static_cast<rlim_t>(limits.file_size_bytes);
      rlimit rl{bytes, bytes};
      ::setrlimit(RLIMIT_FSIZE, &rl);
    }
    std::vector<char*> argv;
    argv.push_back(const_cast<char*>(EXID_EXE));
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(EXID_EXE, argv.data());
    ::_exit(127);
  }
  RunResult r;
  int status = 0;
  const auto t0 = std::chrono::steady_clock::now();
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > timeout_s) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.signal = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  r.out = slurp(log);
  return r;
}

}  // namespace exid_cli
