// exid — the compiled part of the Python package `exid` (module exid._exid): robots, their
// parameters and dynamics vectorised over samples (robot.cpp), studies, matrices (studies.cpp);
// here the module, its plugin registry, the plugin list and the log level. The pure-Python
// package (python/exid) wraps it; docs/python.md describes the API.
//
// Arrays: samples are float64 numpy arrays shaped (N, dof), C order: each row is one sample's
// contiguous dof-vector, read in place (an array of another dtype or layout is converted once by
// pybind11). Results are new C-order arrays written in place by the loops. The loops release the
// GIL. exid::Error becomes the Python exception exid.Error (a RuntimeError) with exid's message;
// a wrong array shape is a ValueError naming the argument and the expected shape.
#include "module.hpp"

#include <dlfcn.h>
#include <fmt/format.h>
#include <pybind11/stl.h>

#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <string>
#include <vector>

#include "exid/config.hpp"
#include "exid/context.hpp"
#include "exid/error.hpp"
#include "exid/version.hpp"

namespace fs = std::filesystem;

namespace exid_python {

namespace {

// ---------------------------------------------------------------- registry
// One registry per process, scanned on first use. It is never destroyed: the plugin libraries
// it loaded stay mapped until the interpreter exits, whatever order Python frees objects in.
std::mutex g_registry_mutex;
exid::Registry* g_registry = nullptr;
std::vector<std::string> g_extra_paths;

/// The plugin folders of the libexid_core this module runs with: an installed core (the .deb,
/// `cmake --install`, the wheel's exid/lib) keeps its plugins in <libdir>/exid/plugins, the build
/// tree in build/plugins beside build/lib. The registry's other defaults are the exid program's
/// layout, relative to the EXECUTABLE, here python3 (/usr/bin/python3: /usr/lib/exid/plugins, a
/// .deb's, whichever build this module is): when this
/// core's folders are found, they alone are searched (after add_plugin_path and
/// EXID_PLUGIN_PATH), so that no plugin of another exid (and its own libexid_core) is loaded.
std::vector<fs::path> corePluginDirs() {
  Dl_info info{};
  if (dladdr(reinterpret_cast<const void*>(&exid::gitCommit), &info) == 0 || !info.dli_fname)
    return {};
  std::error_code ec;
  const fs::path lib = fs::weakly_canonical(fs::path(info.dli_fname), ec).parent_path();
  std::vector<fs::path> out;
  for (const fs::path& d : {lib / "exid" / "plugins", lib.parent_path() / "plugins"})
    if (fs::is_directory(d, ec)) out.push_back(d);
  return out;
}

}  // namespace

exid::Registry& registry() {
  std::lock_guard<std::mutex> lock(g_registry_mutex);
  if (!g_registry) {
    g_registry = new exid::Registry();
    for (const auto& p : g_extra_paths) g_registry->addSearchPath(p);
    if (const char* env = std::getenv("EXID_PLUGIN_PATH")) {  // still before the defaults
      std::string item;
      for (const char* c = env;; ++c) {
        if (*c == ':' || *c == '\0') {
          if (!item.empty()) g_registry->addSearchPath(item);
          item.clear();
          if (*c == '\0') break;
        } else {
          item += *c;
        }
      }
    }
    const std::vector<fs::path> own = corePluginDirs();
    for (const auto& d : own) g_registry->addSearchPath(d);
    if (!own.empty()) g_registry->searchDefaultPaths(false);
    g_registry->scan();
  }
  return *g_registry;
}

namespace {

/// Searched before every other folder (the latest first): a new registry is made with it (the
/// previous one is left alone, with the libraries that objects made from it still use).
void addPluginPath(const std::string& dir) {
  {
    std::lock_guard<std::mutex> lock(g_registry_mutex);
    g_extra_paths.insert(g_extra_paths.begin(), dir);
    g_registry = nullptr;
  }
  registry();
}

std::vector<py::dict> pluginList(const std::string& kind) {
  exid::Registry& reg = registry();
  std::vector<const exid::PluginInfo*> list;
  if (kind.empty())
    for (const auto& p : reg.plugins()) list.push_back(&p);
  else
    list = reg.plugins(exid::pluginKindFromString(kind));
  std::vector<py::dict> out;
  for (const auto* p : list) {
    py::dict d;
    d["kind"] = exid::toString(p->kind);
    d["name"] = p->name;
    d["version"] = p->version;
    d["doc"] = p->doc;
    d["library"] = p->library;
    std::vector<std::string> params;
    for (const auto& decl : p->params) params.push_back(decl.name);
    d["params"] = params;
    out.push_back(d);
  }
  return out;
}

void setLogLevel(const std::string& level) {
  if (level == "quiet")
    exid::setLogLevel(exid::LogLevel::Quiet);
  else if (level == "warn")
    exid::setLogLevel(exid::LogLevel::Warn);
  else if (level == "info")
    exid::setLogLevel(exid::LogLevel::Info);
  else if (level == "debug")
    exid::setLogLevel(exid::LogLevel::Debug);
  else
    throw py::value_error(fmt::format(
        "set_log_level: unknown level '{}'; expected quiet, warn, info or debug", level));
}

}  // namespace

}  // namespace exid_python

using namespace exid_python;

PYBIND11_MODULE(_exid, m) {
  m.doc() = "exid's compiled core (use the package exid, which wraps it)";
  py::register_exception<exid::Error>(m, "Error", PyExc_RuntimeError);
  exid::setLogLevel(exid::LogLevel::Warn);

  m.attr("__version__") = EXID_VERSION_STRING;
  m.def("git_commit", [] { return exid::gitCommit(); });
  m.def("set_log_level", &setLogLevel, py::arg("level"));
  m.def("add_plugin_path", &addPluginPath, py::arg("directory"));
  m.def("plugin_search_paths", [] {
    std::vector<std::string> out;
    for (const auto& p : registry().searchPaths()) out.push_back(p.string());
    return out;
  });
  m.def("plugins", &pluginList, py::arg("kind") = "");
  m.def("refused_libraries", [] {
    std::vector<std::pair<std::string, std::string>> out;
    for (const auto& r : registry().refused()) out.emplace_back(r.path, r.reason);
    return out;
  });

  bindRobot(m);
  bindStudies(m);
}
