#include <fmt/format.h>

#include "exid/registry.hpp"

namespace exid {

namespace {
std::string paramLine(const ParamDecl& d) {
  std::string def = d.default_value ? formatValue(*d.default_value) : std::string("(required)");
  std::string range = d.rangeText();
  return fmt::format("      {:<22} {:<15} default {:<12}{}{}  {}\n", d.name, toString(d.type), def,
                     d.unit.empty() ? "" : " [" + d.unit + "]", range.empty() ? "" : " " + range,
                     d.doc);
}
}  // namespace

std::string pluginListText(const Registry& reg, std::optional<PluginKind> kind) {
  std::string out;
  for (PluginKind k : allPluginKinds()) {
    if (kind && *kind != k) continue;
    auto list = reg.plugins(k);
    out += fmt::format("{} ({}):\n", toString(k), list.size());
    for (const PluginInfo* p : list) {
      out += fmt::format("  {} {} — {}\n", p->name, p->version, p->doc);
      for (const auto& d : p->params) out += paramLine(d);
    }
  }
  if (!reg.refused().empty()) {
    out += "refused libraries:\n";
    for (const auto& r : reg.refused()) out += fmt::format("  {}: {}\n", r.path, r.reason);
  }
  if (reg.plugins().empty()) {
    out += "no plugins found; searched:\n";
    for (const auto& p : reg.searchPaths()) out += "  " + p.string() + "\n";
  }
  return out;
}

std::string pluginInfoText(const Registry& reg, const std::string& name) {
  std::string out;
  std::vector<std::string> all;
  for (const auto& p : reg.plugins()) {
    all.push_back(p.name);
    if (p.name != name) continue;
    out += fmt::format("{} '{}' version {}\n  {}\n  library: {}\n  parameters:\n", toString(p.kind),
                       p.name, p.version, p.doc, p.library);
    if (p.params.empty()) out += "      (none)\n";
    for (const auto& d : p.params) out += paramLine(d);
  }
  if (out.empty()) {
    std::string msg = fmt::format("no plugin named '{}'", name);
    std::string close = closestMatch(name, all);
    if (!close.empty()) msg += fmt::format("; did you mean '{}'?", close);
    throw Error(msg);
  }
  return out;
}

}  // namespace exid
