// Test helpers for tests that use plugins through the real registry (link exid_core).
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "exid/config.hpp"
#include "exid/context.hpp"
#include "exid/interfaces.hpp"
#include "exid/registry.hpp"

namespace exid_test {

/// The registry of the build tree's plugins (scanned once per process).
inline exid::Registry& registry() {
  static exid::Registry* reg = [] {
    auto* r = new exid::Registry();
    r->addSearchPath(std::filesystem::path(EXID_BINARY_DIR) / "plugins");
    r->scan();
    return r;
  }();
  return *reg;
}

/// Creates plugin `name` of T's kind with parameters given as YAML text ("{a: 1}").
template <class T>
std::shared_ptr<T> create(const std::string& name, const std::string& yaml_params = "{}") {
  const exid::PluginInfo& info = registry().get(T::kKind, name);
  exid::ParamSet ps =
      exid::resolveParams(info, yaml_params, std::string(exid::toString(T::kKind)) + " " + name,
                          std::filesystem::path(EXID_SOURCE_DIR));
  return registry().create<T>(name, ps);
}

/// A robot model from a robot plugin.
inline std::shared_ptr<const exid::RobotModel> robot(const std::string& name,
                                                     const std::string& yaml_params = "{}") {
  exid::RunContext ctx;
  return create<exid::Robot>(name, yaml_params)->build(ctx);
}

inline std::filesystem::path sourceDir() { return EXID_SOURCE_DIR; }
/// Recordings shipped in the repository (data/).
inline std::filesystem::path dataDir() { return std::filesystem::path(EXID_SOURCE_DIR) / "data"; }

}  // namespace exid_test
