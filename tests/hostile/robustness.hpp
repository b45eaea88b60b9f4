// exid — helpers of the robustness tests (robustness_test.cpp, robustness_matrix_test.cpp): the
// exid program run as a child process, and what it leaves in its output folders.
#pragma once

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "exid/json.hpp"
#include "exid_cli.hpp"

namespace fs = std::filesystem;

namespace robustness {

inline fs::path tempDir(const std::string& name) {
  return exid_cli::freshTempDir("exid_robust_", name);
}

using exid_cli::contains;
using exid_cli::slurp;
using CmdResult = exid_cli::RunResult;

/// Runs exid with args in dir (exid_cli::runExidIn): killed after timeout_s; file_size_bytes > 0
/// caps the size of any file it writes (as on a full disk).
inline CmdResult runExid(const std::vector<std::string>& args, const fs::path& dir,
                         double timeout_s = 120, long file_size_bytes = 0) {
  return exid_cli::runExidIn(args, dir, timeout_s, exid_cli::Limits{0, file_size_bytes});
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
