// MuJoCo 2.2 as the consumer of exported MJCF in the robots tests (export_formats_test.cpp,
// floating_export_test.cpp): owning handles and a model loaded from MJCF text.
#pragma once

#include <mujoco/mujoco.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace mjtest {

struct MjModelPtr {
  mjModel* m = nullptr;
  MjModelPtr() = default;
  MjModelPtr(const MjModelPtr&) = delete;
  MjModelPtr(MjModelPtr&& o) noexcept : m(o.m) { o.m = nullptr; }
  ~MjModelPtr() {
    if (m) mj_deleteModel(m);
  }
};
struct MjDataPtr {
  mjData* d = nullptr;
  ~MjDataPtr() {
    if (d) mj_deleteData(d);
  }
};

/// MuJoCo's warnings on stdout (by default it appends them to MUJOCO_LOG.TXT in the working
/// folder).
inline void sayMujocoWarning(const char* text) { std::printf("MuJoCo warning: %s\n", text); }

/// mj_loadXML of `text` (written to a file of this process, removed after); null and *error set
/// when MuJoCo refuses it.
inline MjModelPtr loadMjcf(const std::string& name, const std::string& text, std::string* error) {
  mju_user_warning = sayMujocoWarning;
  const std::filesystem::path f =
      std::filesystem::temp_directory_path() /
      ("exid_mujoco_test_" + std::to_string(::getpid()) + "_" + name + ".xml");
  std::ofstream(f) << text;
  char err[1000] = "";
  MjModelPtr p;
  p.m = mj_loadXML(f.string().c_str(), nullptr, err, sizeof err);
  std::filesystem::remove(f);
  *error = err;
  return p;
}

}  // namespace mjtest
