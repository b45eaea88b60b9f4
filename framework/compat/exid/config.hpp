// exid 0.3: forwarding header, for one release. exid/config.hpp belonged to the core's study,
// which 0.3 no longer installs; a program runs studies through the embedding facade,
// exid/exid.hpp, and resolves a plugin's parameters from YAML text with exid::pluginParams
// (docs/architecture.md, "Public and internal"). Removed in 0.4.
#pragma once
#pragma message( \
    "exid/config.hpp is no longer part of exid's installed API: include exid/exid.hpp (runStudyFile; pluginParams for what resolveParams did); this forwarding header goes in exid 0.4")

#include <filesystem>
#include <string>

#include "exid/exid.hpp"
#include "exid/params.hpp"
#include "exid/plugin.hpp"

namespace exid {
/// 0.2's name of pluginParams (the same function, still exported).
EXID_API ParamSet resolveParams(const PluginInfo& info, const std::string& yaml_params,
                                const std::string& context, const std::filesystem::path& base_dir);
}  // namespace exid
