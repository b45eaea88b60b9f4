#include "exid/registry.hpp"

#include <dlfcn.h>
#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <boost/dll/shared_library.hpp>
#include <cstdlib>
#include <map>
#include <sstream>

#include "exid/context.hpp"

namespace exid {

namespace fs = std::filesystem;

const char* toString(PluginKind k) {
  switch (k) {
    case PluginKind::Robot:
      return "robot";
    case PluginKind::Model:
      return "model";
    case PluginKind::Criterion:
      return "criterion";
    case PluginKind::Trajectory:
      return "trajectory";
    case PluginKind::Optimizer:
      return "optimizer";
    case PluginKind::Experiment:
      return "experiment";
    case PluginKind::Estimator:
      return "estimator";
  }
  return "?";
}

std::vector<PluginKind> allPluginKinds() {
  return {PluginKind::Robot,      PluginKind::Model,     PluginKind::Criterion,
          PluginKind::Trajectory, PluginKind::Optimizer, PluginKind::Experiment,
          PluginKind::Estimator};
}

PluginKind pluginKindFromString(const std::string& s) {
  std::vector<std::string> names;
  for (PluginKind k : allPluginKinds()) {
    if (s == toString(k)) return k;
    names.push_back(toString(k));
  }
  std::string msg = fmt::format("unknown plugin kind '{}'; kinds: {}", s, fmt::join(names, ", "));
  std::string close = closestMatch(s, names);
  if (!close.empty()) msg += fmt::format("; did you mean '{}'?", close);
  throw Error(msg);
}

int editDistance(const std::string& a, const std::string& b) {
  std::vector<int> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = static_cast<int>(j);
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = static_cast<int>(i);
    for (std::size_t j = 1; j <= b.size(); ++j) {
      int sub = prev[j - 1] + (std::tolower(a[i - 1]) == std::tolower(b[j - 1]) ? 0 : 1);
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, sub});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string closestMatch(const std::string& s, const std::vector<std::string>& candidates) {
  std::string best;
  int best_d = 1 << 30;
  for (const auto& c : candidates) {
    int d = editDistance(s, c);
    if (d < best_d) {
      best_d = d;
      best = c;
    }
  }
  // Reasonably close: at most a third of the longer name, and at least one character in common.
  int limit = std::max<int>(2, static_cast<int>(std::max(s.size(), best.size())) / 3);
  return best_d <= limit ? best : std::string();
}

namespace {
exid_build_fingerprint coreFingerprint() { return EXID_BUILD_FINGERPRINT; }

fs::path executableDir() {
  std::error_code ec;
  fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : exe.parent_path();
}

/// The folder of the library this code is in (libexid_core.so): an installed exid keeps its
/// plugins in <that folder>/exid/plugins, whatever the prefix it was installed under.
fs::path coreLibraryDir() {
  Dl_info info{};
  if (dladdr(reinterpret_cast<const void*>(&executableDir), &info) == 0 || !info.dli_fname)
    return {};
  std::error_code ec;
  const fs::path lib = fs::weakly_canonical(fs::path(info.dli_fname), ec);
  return ec ? fs::path() : lib.parent_path();
}

bool isPluginFile(const fs::path& p) {
  const std::string name = p.filename().string();
  return name.rfind("libexid_plugin_", 0) == 0 && p.extension() == ".so";
}
}  // namespace

struct Registry::Impl {
  std::vector<fs::path> user_paths;
  bool default_paths = true;
  // Libraries first: members are destroyed in reverse order, so plugin infos (whose
  // std::function factories live in the libraries) go before the libraries are released.
  std::vector<std::shared_ptr<boost::dll::shared_library>> libraries;
  std::map<std::string, std::shared_ptr<boost::dll::shared_library>> library_of;  // by path
  std::vector<PluginInfo> plugins;
  std::vector<RefusedLibrary> refused;

  std::vector<fs::path> allPaths() const {
    std::vector<fs::path> out = user_paths;
    if (const char* env = std::getenv("EXID_PLUGIN_PATH")) {
      std::stringstream ss(env);
      std::string item;
      while (std::getline(ss, item, ':'))
        if (!item.empty()) out.emplace_back(item);
    }
    fs::path exe = default_paths ? executableDir() : fs::path();
    if (!exe.empty()) {
      out.push_back(exe.parent_path() / "plugins");                   // build tree: build/bin/exid
      out.push_back(exe.parent_path() / "lib" / "exid" / "plugins");  // install: prefix/bin/exid
    }
    // install: prefix/<libdir>/libexid_core.so; the build tree: build/lib/libexid_core.so with
    // build/lib/exid/plugins a link to build/plugins (made by CMake). Only places relative to
    // the running program or the core library: no path of the machine that built exid.
    if (const fs::path lib = default_paths ? coreLibraryDir() : fs::path(); !lib.empty())
      out.push_back(lib / "exid" / "plugins");
    // Drop duplicates (same canonical directory), keep the first.
    std::vector<fs::path> unique;
    std::vector<fs::path> seen;
    for (const auto& p : out) {
      std::error_code ec;
      fs::path c = fs::weakly_canonical(p, ec);
      if (ec) c = p;
      if (std::find(seen.begin(), seen.end(), c) != seen.end()) continue;
      seen.push_back(c);
      unique.push_back(p);
    }
    return unique;
  }

  // Returns "" on success, else the reason the library is refused.
  std::string load(const fs::path& file, bool explicit_request) {
    std::error_code ec;
    fs::path canon = fs::weakly_canonical(file, ec);
    const std::string key = ec ? file.string() : canon.string();
    if (library_of.count(key)) return "";
    auto lib = std::make_shared<boost::dll::shared_library>();
    try {
      lib->load(boost::dll::fs::path(file),
                boost::dll::load_mode::rtld_now | boost::dll::load_mode::rtld_local);
    } catch (const std::exception& e) {
      return fmt::format("cannot be loaded: {}", e.what());
    }
    if (!lib->has("exid_plugin_manifest"))
      return "has no 'exid_plugin_manifest' entry point (not an exid plugin; build it with "
             "exid_add_plugin and EXID_REGISTER_PLUGIN)";
    auto entry = lib->get<const exid_manifest*()>("exid_plugin_manifest");
    const exid_manifest* m = entry();
    if (m == nullptr) return "its entry point returned no manifest";
    if (m->abi_version != EXID_PLUGIN_ABI_VERSION)
      return fmt::format(
          "plugin ABI version mismatch: expected {}, found {} (rebuild the plugin "
          "against this exid)",
          EXID_PLUGIN_ABI_VERSION, m->abi_version);
    if (m->manifest_size != sizeof(exid_manifest))
      return fmt::format("manifest size mismatch: expected {}, found {}", sizeof(exid_manifest),
                         m->manifest_size);
    const exid_build_fingerprint core = coreFingerprint();
    const exid_build_fingerprint& f = m->fingerprint;
    auto same = [](const char* a, const char* b) {
      return a && b && std::string(a) == std::string(b);
    };
    std::vector<std::string> diffs;
    if (!same(core.compiler, f.compiler))
      diffs.push_back(fmt::format("compiler: expected '{}', found '{}'", core.compiler,
                                  f.compiler ? f.compiler : "(null)"));
    if (!same(core.stdlib_abi, f.stdlib_abi))
      diffs.push_back(fmt::format("standard library ABI: expected '{}', found '{}'",
                                  core.stdlib_abi, f.stdlib_abi ? f.stdlib_abi : "(null)"));
    if (!same(core.eigen_version, f.eigen_version))
      diffs.push_back(fmt::format("Eigen version: expected '{}', found '{}'", core.eigen_version,
                                  f.eigen_version ? f.eigen_version : "(null)"));
    if (core.eigen_max_align_bytes != f.eigen_max_align_bytes)
      diffs.push_back(fmt::format("Eigen max alignment: expected {}, found {}",
                                  core.eigen_max_align_bytes, f.eigen_max_align_bytes));
    if (!same(core.exid_version, f.exid_version))
      diffs.push_back(fmt::format("exid version: expected '{}', found '{}'", core.exid_version,
                                  f.exid_version ? f.exid_version : "(null)"));
    if (!diffs.empty())
      return fmt::format("build fingerprint mismatch: {}", fmt::join(diffs, "; "));
    if (m->list_plugins == nullptr) return "manifest lists no plugins";
    PluginList listed;
    try {
      m->list_plugins(&listed);
    } catch (const std::exception& e) {
      return fmt::format("listing its plugins threw: {}", e.what());
    } catch (...) {
      return "listing its plugins threw an unknown exception";
    }
    library_of[key] = lib;
    libraries.push_back(lib);
    for (auto& info : listed) {
      info.library = key;
      auto clash = std::find_if(plugins.begin(), plugins.end(), [&](const PluginInfo& p) {
        return p.kind == info.kind && p.name == info.name;
      });
      if (clash != plugins.end()) {
        if (explicit_request) {
          *clash = std::move(info);  // an explicitly loaded library wins
        } else {
          logDebug(fmt::format("plugin {} '{}' in {} is hidden by the one in {}",
                               toString(info.kind), info.name, key, clash->library));
        }
        continue;
      }
      plugins.push_back(std::move(info));
    }
    return "";
  }
};

Registry::Registry() : impl_(std::make_unique<Impl>()) {}
Registry::~Registry() = default;

void Registry::addSearchPath(const fs::path& dir) { impl_->user_paths.push_back(dir); }
void Registry::searchDefaultPaths(bool on) { impl_->default_paths = on; }
std::vector<fs::path> Registry::searchPaths() const { return impl_->allPaths(); }

void Registry::scan() {
  for (const auto& dir : impl_->allPaths()) {
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) continue;
    std::vector<fs::path> files;
    for (const auto& entry : fs::directory_iterator(dir, ec))
      if (entry.is_regular_file() && isPluginFile(entry.path())) files.push_back(entry.path());
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
      std::string why = impl_->load(f, false);
      if (!why.empty()) {
        auto it = std::find_if(impl_->refused.begin(), impl_->refused.end(),
                               [&](const RefusedLibrary& r) { return r.path == f.string(); });
        if (it == impl_->refused.end()) {
          impl_->refused.push_back({f.string(), why});
          logWarn(fmt::format("plugin library {} refused: {}", f.string(), why));
        }
      }
    }
  }
}

void Registry::loadLibrary(const fs::path& file) {
  std::error_code ec;
  if (!fs::exists(file, ec))
    throw Error(fmt::format("plugin library {}: no such file", file.string()));
  std::string why = impl_->load(file, true);
  if (!why.empty()) {
    impl_->refused.push_back({file.string(), why});
    throw Error(fmt::format("plugin library {} refused: {}", file.string(), why));
  }
}

const std::vector<PluginInfo>& Registry::plugins() const { return impl_->plugins; }

std::vector<const PluginInfo*> Registry::plugins(PluginKind kind) const {
  std::vector<const PluginInfo*> out;
  for (const auto& p : impl_->plugins)
    if (p.kind == kind) out.push_back(&p);
  std::sort(out.begin(), out.end(),
            [](const PluginInfo* a, const PluginInfo* b) { return a->name < b->name; });
  return out;
}

const std::vector<RefusedLibrary>& Registry::refused() const { return impl_->refused; }

const PluginInfo* Registry::find(PluginKind kind, const std::string& name) const {
  for (const auto& p : impl_->plugins)
    if (p.kind == kind && p.name == name) return &p;
  return nullptr;
}

std::string Registry::unknownMessage(PluginKind kind, const std::string& name) const {
  std::vector<std::string> names;
  for (const PluginInfo* p : plugins(kind)) names.push_back(p->name);
  std::string msg = fmt::format(
      "unknown {} '{}'; available: {}", toString(kind), name,
      names.empty() ? std::string("(none found)") : fmt::format("{}", fmt::join(names, ", ")));
  std::string close = closestMatch(name, names);
  if (!close.empty()) msg += fmt::format("; did you mean '{}'?", close);
  if (names.empty()) {
    std::vector<std::string> dirs;
    for (const auto& d : searchPaths()) dirs.push_back(d.string());
    msg += fmt::format(" (searched: {})", fmt::join(dirs, ", "));
  }
  return msg;
}

const PluginInfo& Registry::get(PluginKind kind, const std::string& name) const {
  const PluginInfo* p = find(kind, name);
  if (!p) throw Error(unknownMessage(kind, name));
  return *p;
}

std::shared_ptr<PluginObject> Registry::createObject(const PluginInfo& info,
                                                     const ParamSet& params) const {
  std::shared_ptr<boost::dll::shared_library> lib;
  auto it = impl_->library_of.find(info.library);
  if (it != impl_->library_of.end()) lib = it->second;
  std::unique_ptr<PluginObject> obj;
  try {
    obj = info.factory(params);
  } catch (const std::exception& e) {
    throw Error(
        fmt::format("{} '{}' could not be created: {}", toString(info.kind), info.name, e.what()));
  } catch (...) {
    throw Error(fmt::format("{} '{}' could not be created: unknown exception", toString(info.kind),
                            info.name));
  }
  if (!obj)
    throw Error(fmt::format("{} '{}': factory returned nothing", toString(info.kind), info.name));
  obj->setPluginName(info.name);
  // The deleter holds the library: it stays loaded while the object lives.
  return std::shared_ptr<PluginObject>(obj.release(), [lib](PluginObject* p) { delete p; });
}

std::string Registry::fingerprintText() {
  exid_build_fingerprint f = coreFingerprint();
  return fmt::format("{}; {}; Eigen {} (max align {}); exid {}; plugin ABI {}", f.compiler,
                     f.stdlib_abi, f.eigen_version, f.eigen_max_align_bytes, f.exid_version,
                     EXID_PLUGIN_ABI_VERSION);
}

}  // namespace exid
