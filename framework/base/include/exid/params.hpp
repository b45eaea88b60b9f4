// exid — declared, typed, range-checked plugin parameters.
// Every plugin declares its parameters (name, type, default, unit, range, one-line doc); a study
// file sets them by name; the framework validates them before any work starts.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "exid/export.hpp"

namespace exid {

enum class ParamType { Bool, Int, Double, String, Path, IntList, DoubleList, StringList };
EXID_API const char* toString(ParamType t);

using ParamValue = std::variant<bool, std::int64_t, double, std::string, std::vector<std::int64_t>,
                                std::vector<double>, std::vector<std::string>>;

/// Printable form of a value as it would appear in YAML ("0.5", "[1, 2]", "true", "name").
EXID_API std::string formatValue(const ParamValue& v);

struct EXID_API ParamDecl {
  std::string name;
  ParamType type = ParamType::Double;
  std::optional<ParamValue> default_value;  // none: the parameter is required
  std::string unit;                         // SI unit, "" when dimensionless
  std::string doc;                          // one line
  // Numeric range (applies to every element of a list). Open ends exclude the bound.
  std::optional<double> min, max;
  bool min_open = false, max_open = false;
  std::vector<std::string> choices;  // for String / StringList: the allowed values
  int min_size = 0, max_size = -1;   // for lists; -1: unbounded

  /// "(0, 1]", "[0, inf)", "one of: a, b", or "" when unconstrained.
  std::string rangeText() const;
  /// Checks a value of the right type against the range, choices and size. Returns "" when it
  /// is acceptable, else the rule it breaks ("must be in (0, 1]").
  std::string violation(const ParamValue& v) const;
};

/// Builder helpers: ParamDecl entries read like a table in the plugin's source.
EXID_API ParamDecl param_double(std::string name, std::optional<double> def, std::string unit,
                                std::string doc, std::optional<double> min = std::nullopt,
                                std::optional<double> max = std::nullopt, bool min_open = false,
                                bool max_open = false);
/// Integer parameters declared without a bound get [-kMaxIntParam, kMaxIntParam]: every integer
/// has a range, and every accepted value fits an int (no narrowing conversion can wrap).
inline constexpr double kMaxIntParam = 1e9;
EXID_API ParamDecl param_int(std::string name, std::optional<std::int64_t> def, std::string doc,
                             std::optional<double> min = std::nullopt,
                             std::optional<double> max = std::nullopt);
EXID_API ParamDecl param_bool(std::string name, bool def, std::string doc);
EXID_API ParamDecl param_string(std::string name, std::optional<std::string> def, std::string doc,
                                std::vector<std::string> choices = {});
EXID_API ParamDecl param_path(std::string name, std::optional<std::string> def, std::string doc);
EXID_API ParamDecl param_doubles(std::string name, std::optional<std::vector<double>> def,
                                 std::string unit, std::string doc, int min_size = 0,
                                 int max_size = -1);
EXID_API ParamDecl param_ints(std::string name, std::optional<std::vector<std::int64_t>> def,
                              std::string doc, std::optional<double> min = std::nullopt,
                              std::optional<double> max = std::nullopt);
EXID_API ParamDecl param_strings(std::string name, std::optional<std::vector<std::string>> def,
                                 std::string doc, std::vector<std::string> choices = {});

/// Resolved parameters of one plugin instance: every declared parameter has a value.
class EXID_API ParamSet {
 public:
  ParamSet() = default;
  void set(const std::string& name, ParamValue v) { values_[name] = std::move(v); }
  bool has(const std::string& name) const { return values_.count(name) > 0; }
  const ParamValue& at(const std::string& name) const;

  bool getBool(const std::string& name) const;
  std::int64_t getInt(const std::string& name) const;
  double getDouble(const std::string& name) const;              // accepts Int values too
  const std::string& getString(const std::string& name) const;  // String and Path
  std::vector<std::int64_t> getInts(const std::string& name) const;
  std::vector<double> getDoubles(const std::string& name) const;
  const std::vector<std::string>& getStrings(const std::string& name) const;

  const std::map<std::string, ParamValue>& values() const { return values_; }
  /// Context for messages, e.g. "estimator.params" in "study.yaml".
  std::string context;

 private:
  std::map<std::string, ParamValue> values_;
};

}  // namespace exid
