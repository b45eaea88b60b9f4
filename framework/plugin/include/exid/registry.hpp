// exid — the plugin registry: finds plugin libraries, checks their manifests, lists their
// plugins, and creates objects that keep their library loaded while they live.
//
// Search order for plugin libraries (files named libexid_plugin_*.so):
//   1. directories given with --plugin-path (addSearchPath, in order),
//   2. EXID_PLUGIN_PATH (colon-separated),
//   3. the defaults: beside the executable (build/bin/exid -> build/plugins, prefix/bin/exid ->
//      prefix/lib/exid/plugins) and beside libexid_core (<libdir>/exid/plugins; in the build
//      tree a link to build/plugins). No path of the building machine is compiled in. A host
//      that knows where its plugins are (the Python module, whose executable is python3) turns
//      them off (searchDefaultPaths(false)).
// A plugin name found in an earlier directory hides the same name found later.
#pragma once

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/export.hpp"
#include "exid/plugin.hpp"

namespace exid {

/// A library that was refused (wrong ABI, fingerprint, no entry point, listing threw).
struct EXID_API RefusedLibrary {
  std::string path;
  std::string reason;
};

class EXID_API Registry {
 public:
  Registry();
  ~Registry();
  Registry(const Registry&) = delete;
  Registry& operator=(const Registry&) = delete;

  void addSearchPath(const std::filesystem::path& dir);
  /// Whether scan() also searches the default folders after EXID_PLUGIN_PATH (default: yes).
  void searchDefaultPaths(bool on);
  /// The directories searched, in order (after defaults are added by scan()).
  std::vector<std::filesystem::path> searchPaths() const;
  /// Loads every plugin library found on the search paths. Refused libraries are recorded, not
  /// fatal. Safe to call again (rescans).
  void scan();
  /// Loads one library explicitly; throws exid::Error (expected vs found) when refused.
  void loadLibrary(const std::filesystem::path& file);

  const std::vector<PluginInfo>& plugins() const;
  std::vector<const PluginInfo*> plugins(PluginKind kind) const;
  const std::vector<RefusedLibrary>& refused() const;
  /// nullptr when absent.
  const PluginInfo* find(PluginKind kind, const std::string& name) const;
  /// Throws exid::Error naming the kind, listing the available names and the closest match.
  const PluginInfo& get(PluginKind kind, const std::string& name) const;
  /// "unknown estimator 'bach_ls'; available: batch_ls, rls; did you mean 'batch_ls'?"
  std::string unknownMessage(PluginKind kind, const std::string& name) const;

  /// Creates an object. params must already be resolved (every declared parameter set, see
  /// config.hpp). The object keeps its library loaded. A throwing factory becomes an exid::Error
  /// naming the plugin.
  template <class T>
  std::shared_ptr<T> create(const std::string& name, const ParamSet& params) const {
    const PluginInfo& info = get(T::kKind, name);
    std::shared_ptr<PluginObject> obj = createObject(info, params);
    return std::shared_ptr<T>(obj, static_cast<T*>(obj.get()));
  }
  std::shared_ptr<PluginObject> createObject(const PluginInfo& info, const ParamSet& params) const;

  /// The fingerprint of this build of the core, for messages and summaries.
  static std::string fingerprintText();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Levenshtein distance, for "did you mean".
EXID_API int editDistance(const std::string& a, const std::string& b);
/// The closest of candidates to s (empty when none is reasonably close).
EXID_API std::string closestMatch(const std::string& s, const std::vector<std::string>& candidates);

}  // namespace exid

namespace exid {
/// `exid plugins [KIND]`: every plugin with its parameters, grouped by kind; refused libraries.
EXID_API std::string pluginListText(const Registry& reg, std::optional<PluginKind> kind);
/// `exid plugins info NAME`: one plugin in full (all kinds with that name).
EXID_API std::string pluginInfoText(const Registry& reg, const std::string& name);
}  // namespace exid
