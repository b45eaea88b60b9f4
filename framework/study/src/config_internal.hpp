// exid — what the study file's sources share (private to the study layer): the problems a study
// collects, reading YAML scalars, and a plugin's section resolved against its declared parameters
// (config_params.cpp). The study's keys are read in config.cpp, its excitation section in
// config_excitation.cpp; the resolved study (text, JSON, hash) is written in config_yaml.cpp.
#pragma once

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "exid/config.hpp"
#include "exid/registry.hpp"

namespace exid::config_detail {

struct Problems {
  std::string source;
  std::vector<std::string> items;
  void add(const YAML::Node& at, const std::string& msg) {
    int line = (at && at.Mark().line >= 0) ? at.Mark().line + 1 : 0;
    add(line, msg);
  }
  void add(int line, const std::string& msg) {
    items.push_back(line > 0 ? fmt::format("{}:{}: {}", source, line, msg)
                             : fmt::format("{}: {}", source, msg));
  }
};

// The text of a node for a message: its scalar, "[...]", "{...}" or "null".
std::string scalarText(const YAML::Node& n);
// A YAML scalar as an integer, a number (.inf, .nan included) or a truth value; nullopt when it
// is not one.
std::optional<std::int64_t> toInt(const std::string& s);
std::optional<double> toDouble(const std::string& s);
std::optional<bool> toBool(const std::string& s);

// `path.key`: an unknown key, with the allowed ones and the closest.
void unknownKey(Problems& pr, const YAML::Node& at, const std::string& path, const std::string& key,
                const std::vector<std::string>& allowed);
// The text of a mapping key; a key that is not a plain scalar (`{a: 1}: x`, `[a]: x`, `? ...`) is
// a problem at its line (found by tests/fuzz/fuzz_study: converting it to a string threw
// YAML::TypedBadConversion out of parseStudy).
std::optional<std::string> keyName(Problems& pr, const YAML::Node& key, const std::string& path);

// Fills `out` from a params mapping node (may be null) and the declarations.
void resolveInto(const PluginInfo& info, const YAML::Node& params, const std::string& path,
                 const std::filesystem::path& base_dir, Problems& pr, ParamSet& out);

// A plugin's section {type, params (, weight)} of the given kind; nullopt when it cannot be read.
std::optional<PluginSpec> parseSpec(const YAML::Node& node, PluginKind kind,
                                    const std::string& path, const std::filesystem::path& base_dir,
                                    const Registry& reg, Problems& pr, bool allow_weight);

// `excitation:` trajectory, criterion, optimizer, constraints, collision and information
// (config_excitation.cpp).
void parseExcitation(const YAML::Node& root, const std::filesystem::path& base_dir,
                     const Registry& reg, Problems& pr, StudyConfig& cfg);

}  // namespace exid::config_detail
