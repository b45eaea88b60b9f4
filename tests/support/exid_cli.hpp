// Helpers for tests that run the exid program (the test target defines EXID_EXE): run it with
// arguments and capture its output, read a file whole, make a fresh temporary folder.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

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

}  // namespace exid_cli
