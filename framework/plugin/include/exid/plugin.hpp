// exid — plugin ABI.
//
// A plugin library is a MODULE shared library with one exported C entry point,
// `exid_plugin_manifest`, returning a manifest: ABI version, build fingerprint, and a function
// that lists the plugins inside (kind, name, version, parameter declarations, factory). The
// loader compares ABI version and fingerprint BEFORE calling any C++ code of the library and
// refuses a mismatched library with expected vs found values.
//
// One line at the end of a plugin's source registers it:
//     EXID_REGISTER_PLUGIN(MyCriterion)
// where MyCriterion derives from one of the interfaces in interfaces.hpp and provides
//     static constexpr const char* kName, *kVersion, *kDoc;
//     static std::vector<exid::ParamDecl> params();
//     explicit MyCriterion(const exid::ParamSet&);
// A library whose plugins are known only when it is loaded (data) fills the list itself:
//     EXID_REGISTER_PLUGIN_LIST(fillList)   // void fillList(exid::PluginList&)
#pragma once

#include <Eigen/Core>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "exid/export.hpp"
#include "exid/params.hpp"
#include "exid/version.hpp"

namespace exid {

enum class PluginKind { Robot, Model, Criterion, Trajectory, Optimizer, Experiment, Estimator };
inline constexpr int kNumPluginKinds = 7;
EXID_API const char* toString(PluginKind k);
/// Throws exid::Error listing the valid kinds.
EXID_API PluginKind pluginKindFromString(const std::string& s);
EXID_API std::vector<PluginKind> allPluginKinds();

/// Base of every object a plugin creates. Objects are created by the registry, which keeps the
/// library loaded for as long as any object from it lives.
class EXID_API PluginObject {
 public:
  PluginObject() = default;
  PluginObject(const PluginObject&) = delete;
  PluginObject& operator=(const PluginObject&) = delete;
  virtual ~PluginObject() = default;
  /// Registered name (set by the registry after construction).
  const std::string& pluginName() const { return plugin_name_; }
  void setPluginName(std::string n) { plugin_name_ = std::move(n); }

 private:
  std::string plugin_name_;
};

using PluginFactory = std::function<std::unique_ptr<PluginObject>(const ParamSet&)>;

struct EXID_API PluginInfo {
  PluginKind kind = PluginKind::Robot;
  std::string name;
  std::string version;
  std::string doc;
  std::vector<ParamDecl> params;
  PluginFactory factory;
  std::string library;  // path of the library it came from (set by the loader)
};

using PluginList = std::vector<PluginInfo>;

template <class T>
PluginInfo describePlugin() {
  PluginInfo info;
  info.kind = T::kKind;
  info.name = T::kName;
  info.version = T::kVersion;
  info.doc = T::kDoc;
  info.params = T::params();
  info.factory = [](const ParamSet& p) -> std::unique_ptr<PluginObject> {
    return std::make_unique<T>(p);
  };
  return info;
}

}  // namespace exid

extern "C" {

/// Bump when the manifest layout or any interface in interfaces.hpp changes incompatibly.
#define EXID_PLUGIN_ABI_VERSION 18

struct exid_build_fingerprint {
  const char* compiler;       // e.g. "GNU 12.2.0"
  const char* stdlib_abi;     // e.g. "libstdc++ cxx11-abi=1"
  const char* eigen_version;  // e.g. "3.4.0"
  int eigen_max_align_bytes;  // EIGEN_MAX_ALIGN_BYTES
  const char* exid_version;   // e.g. "0.1.0"
};

struct exid_manifest {
  int abi_version;         // EXID_PLUGIN_ABI_VERSION of the library
  unsigned manifest_size;  // sizeof(exid_manifest) of the library
  exid_build_fingerprint fingerprint;
  /// Fills *out (an exid::PluginList*) with the plugins inside. Called only after the checks.
  void (*list_plugins)(void* out);
};

typedef const exid_manifest* (*exid_plugin_manifest_fn)(void);
}

#define EXID_STRINGIFY2(x) #x
#define EXID_STRINGIFY(x) EXID_STRINGIFY2(x)

#if defined(__clang__)
#define EXID_COMPILER_ID "Clang " __clang_version__
#elif defined(__GNUC__)
#define EXID_COMPILER_ID "GNU " EXID_STRINGIFY(__GNUC__) "." EXID_STRINGIFY(__GNUC_MINOR__)
#else
#define EXID_COMPILER_ID "unknown"
#endif

#if defined(_GLIBCXX_USE_CXX11_ABI)
#define EXID_STDLIB_ABI "libstdc++ cxx11-abi=" EXID_STRINGIFY(_GLIBCXX_USE_CXX11_ABI)
#elif defined(_LIBCPP_VERSION)
#define EXID_STDLIB_ABI "libc++ " EXID_STRINGIFY(_LIBCPP_ABI_VERSION)
#else
#define EXID_STDLIB_ABI "unknown"
#endif

#define EXID_EIGEN_VERSION_STRING     \
  EXID_STRINGIFY(EIGEN_WORLD_VERSION) \
  "." EXID_STRINGIFY(EIGEN_MAJOR_VERSION) "." EXID_STRINGIFY(EIGEN_MINOR_VERSION)

/// The fingerprint of the code being compiled now (core or plugin).
#define EXID_BUILD_FINGERPRINT                                                           \
  exid_build_fingerprint {                                                               \
    EXID_COMPILER_ID, EXID_STDLIB_ABI, EXID_EIGEN_VERSION_STRING, EIGEN_MAX_ALIGN_BYTES, \
        EXID_VERSION_STRING                                                              \
  }

#ifndef EXID_PLUGIN_ABI_OVERRIDE
#define EXID_PLUGIN_ABI_OVERRIDE EXID_PLUGIN_ABI_VERSION
#endif

/// Registers the plugin classes of this library (one or more). Place once, at the end of a file.
#define EXID_REGISTER_PLUGIN(...)                                                                 \
  namespace {                                                                                     \
  template <class... Ts>                                                                          \
  void exid_list_plugins_impl(void* out) {                                                        \
    auto* list = static_cast<exid::PluginList*>(out);                                             \
    (list->push_back(exid::describePlugin<Ts>()), ...);                                           \
  }                                                                                               \
  void exid_list_plugins(void* out) { exid_list_plugins_impl<__VA_ARGS__>(out); }                 \
  }                                                                                               \
  extern "C" __attribute__((visibility("default"))) const exid_manifest* exid_plugin_manifest() { \
    static const exid_manifest m{EXID_PLUGIN_ABI_OVERRIDE, sizeof(exid_manifest),                 \
                                 EXID_BUILD_FINGERPRINT, &exid_list_plugins};                     \
    return &m;                                                                                    \
  }

/// Registers the plugins of this library from a function `void fn(exid::PluginList&)` that fills
/// the list at load time: for a library whose plugins are data (e.g. the shipped robots, one
/// PluginInfo per catalogue entry, each with its own factory). Place once, at the end of a file.
#define EXID_REGISTER_PLUGIN_LIST(fn)                                                             \
  namespace {                                                                                     \
  void exid_list_plugins(void* out) { fn(*static_cast<exid::PluginList*>(out)); }                 \
  }                                                                                               \
  extern "C" __attribute__((visibility("default"))) const exid_manifest* exid_plugin_manifest() { \
    static const exid_manifest m{EXID_PLUGIN_ABI_OVERRIDE, sizeof(exid_manifest),                 \
                                 EXID_BUILD_FINGERPRINT, &exid_list_plugins};                     \
    return &m;                                                                                    \
  }
