#include "exid/params.hpp"

#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <sstream>

#include "exid/error.hpp"

namespace exid {

const char* toString(ParamType t) {
  switch (t) {
    case ParamType::Bool:
      return "bool";
    case ParamType::Int:
      return "int";
    case ParamType::Double:
      return "double";
    case ParamType::String:
      return "string";
    case ParamType::Path:
      return "path";
    case ParamType::IntList:
      return "list of int";
    case ParamType::DoubleList:
      return "list of double";
    case ParamType::StringList:
      return "list of string";
  }
  return "?";
}

namespace {
std::string fmtDouble(double d) {
  if (std::isinf(d)) return d > 0 ? "inf" : "-inf";
  return fmt::format("{}", d);
}
template <class T>
std::string joinList(const std::vector<T>& v) {
  std::string s = "[";
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (i) s += ", ";
    if constexpr (std::is_same_v<T, double>)
      s += fmtDouble(v[i]);
    else if constexpr (std::is_same_v<T, std::string>)
      s += v[i];
    else
      s += std::to_string(v[i]);
  }
  return s + "]";
}
}  // namespace

std::string formatValue(const ParamValue& v) {
  return std::visit(
      [](const auto& x) -> std::string {
        using T = std::decay_t<decltype(x)>;
        if constexpr (std::is_same_v<T, bool>)
          return x ? "true" : "false";
        else if constexpr (std::is_same_v<T, std::int64_t>)
          return std::to_string(x);
        else if constexpr (std::is_same_v<T, double>)
          return fmtDouble(x);
        else if constexpr (std::is_same_v<T, std::string>)
          return x;
        else
          return joinList(x);
      },
      v);
}

std::string ParamDecl::rangeText() const {
  if (!choices.empty()) {
    std::string s = "one of: ";
    for (std::size_t i = 0; i < choices.size(); ++i) s += (i ? ", " : "") + choices[i];
    return s;
  }
  if (!min && !max) return "";
  std::string lo = min ? fmtDouble(*min) : "-inf";
  std::string hi = max ? fmtDouble(*max) : "inf";
  return fmt::format("{}{}, {}{}", (min && !min_open) ? "[" : "(", lo, hi,
                     (max && !max_open) ? "]" : ")");
}

std::string ParamDecl::violation(const ParamValue& v) const {
  auto numberOk = [&](double x) {
    if (!std::isfinite(x)) return false;
    if (min && (min_open ? !(x > *min) : !(x >= *min))) return false;
    if (max && (max_open ? !(x < *max) : !(x <= *max))) return false;
    return true;
  };
  auto rangeMsg = [&]() {
    std::string r = rangeText();
    return r.empty() ? std::string("must be finite") : "must be in " + r;
  };
  auto sizeMsg = [&](std::size_t n) -> std::string {
    if (min_size > 0 && n < static_cast<std::size_t>(min_size))
      return fmt::format("must have at least {} elements (has {})", min_size, n);
    if (max_size >= 0 && n > static_cast<std::size_t>(max_size))
      return fmt::format("must have at most {} elements (has {})", max_size, n);
    return "";
  };
  auto choiceOk = [&](const std::string& s) {
    if (choices.empty()) return true;
    for (const auto& c : choices)
      if (c == s) return true;
    return false;
  };
  if (auto* d = std::get_if<double>(&v)) return numberOk(*d) ? "" : rangeMsg();
  if (auto* i = std::get_if<std::int64_t>(&v))
    return numberOk(static_cast<double>(*i)) ? "" : rangeMsg();
  if (auto* s = std::get_if<std::string>(&v)) return choiceOk(*s) ? "" : "must be " + rangeText();
  if (auto* dl = std::get_if<std::vector<double>>(&v)) {
    if (auto m = sizeMsg(dl->size()); !m.empty()) return m;
    for (std::size_t k = 0; k < dl->size(); ++k)
      if (!numberOk((*dl)[k])) return fmt::format("element {} {}", k, rangeMsg());
    return "";
  }
  if (auto* il = std::get_if<std::vector<std::int64_t>>(&v)) {
    if (auto m = sizeMsg(il->size()); !m.empty()) return m;
    for (std::size_t k = 0; k < il->size(); ++k)
      if (!numberOk(static_cast<double>((*il)[k])))
        return fmt::format("element {} {}", k, rangeMsg());
    return "";
  }
  if (auto* sl = std::get_if<std::vector<std::string>>(&v)) {
    if (auto m = sizeMsg(sl->size()); !m.empty()) return m;
    for (const auto& s : *sl)
      if (!choiceOk(s)) return fmt::format("element '{}' must be {}", s, rangeText());
    return "";
  }
  return "";
}

ParamDecl param_double(std::string name, std::optional<double> def, std::string unit,
                       std::string doc, std::optional<double> min, std::optional<double> max,
                       bool min_open, bool max_open) {
  ParamDecl d;
  d.name = std::move(name);
  d.type = ParamType::Double;
  if (def) d.default_value = *def;
  d.unit = std::move(unit);
  d.doc = std::move(doc);
  d.min = min;
  d.max = max;
  d.min_open = min_open;
  d.max_open = max_open;
  return d;
}
ParamDecl param_int(std::string name, std::optional<std::int64_t> def, std::string doc,
                    std::optional<double> min, std::optional<double> max) {
  ParamDecl d;
  d.name = std::move(name);
  d.type = ParamType::Int;
  if (def) d.default_value = *def;
  d.doc = std::move(doc);
  d.min = min ? min : -kMaxIntParam;
  d.max = max ? max : kMaxIntParam;
  return d;
}
ParamDecl param_bool(std::string name, bool def, std::string doc) {
  ParamDecl d;
  d.name = std::move(name);
  d.type = ParamType::Bool;
  d.default_value = def;
  d.doc = std::move(doc);
  return d;
}
ParamDecl param_string(std::string name, std::optional<std::string> def, std::string doc,
                       std::vector<std::string> choices) {
  ParamDecl d;
  d.name = std::move(name);
  d.type = ParamType::String;
  if (def) d.default_value = *def;
  d.doc = std::move(doc);
  d.choices = std::move(choices);
  return d;
}
ParamDecl param_path(std::string name, std::optional<std::string> def, std::string doc) {
  ParamDecl d;
  d.name = std::move(name);
  d.type = ParamType::Path;
  if (def) d.default_value = *def;
  d.doc = std::move(doc);
  return d;
}
ParamDecl param_doubles(std::string name, std::optional<std::vector<double>> def, std::string unit,
                        std::string doc, int min_size, int max_size) {
  ParamDecl d;
  d.name = std::move(name);
  d.type = ParamType::DoubleList;
  if (def) d.default_value = *def;
  d.unit = std::move(unit);
  d.doc = std::move(doc);
  d.min_size = min_size;
  d.max_size = max_size;
  return d;
}
ParamDecl param_ints(std::string name, std::optional<std::vector<std::int64_t>> def,
                     std::string doc, std::optional<double> min, std::optional<double> max) {
  ParamDecl d;
  d.name = std::move(name);
  d.type = ParamType::IntList;
  if (def) d.default_value = *def;
  d.doc = std::move(doc);
  d.min = min ? min : -kMaxIntParam;
  d.max = max ? max : kMaxIntParam;
  return d;
}
ParamDecl param_strings(std::string name, std::optional<std::vector<std::string>> def,
                        std::string doc, std::vector<std::string> choices) {
  ParamDecl d;
  d.name = std::move(name);
  d.type = ParamType::StringList;
  if (def) d.default_value = *def;
  d.doc = std::move(doc);
  d.choices = std::move(choices);
  return d;
}

const ParamValue& ParamSet::at(const std::string& name) const {
  auto it = values_.find(name);
  if (it == values_.end())
    throw Error(fmt::format("{}: parameter '{}' is not set (not declared by the plugin?)",
                            context.empty() ? "params" : context, name));
  return it->second;
}

namespace {
template <class T>
const T& getAs(const ParamSet& ps, const std::string& name, const char* what) {
  const ParamValue& v = ps.at(name);
  if (auto* p = std::get_if<T>(&v)) return *p;
  throw Error(fmt::format("{}.{}: expected {}, found '{}'",
                          ps.context.empty() ? "params" : ps.context, name, what, formatValue(v)));
}
}  // namespace

bool ParamSet::getBool(const std::string& name) const { return getAs<bool>(*this, name, "a bool"); }
std::int64_t ParamSet::getInt(const std::string& name) const {
  return getAs<std::int64_t>(*this, name, "an int");
}
double ParamSet::getDouble(const std::string& name) const {
  const ParamValue& v = at(name);
  if (auto* i = std::get_if<std::int64_t>(&v)) return static_cast<double>(*i);
  return getAs<double>(*this, name, "a number");
}
const std::string& ParamSet::getString(const std::string& name) const {
  return getAs<std::string>(*this, name, "a string");
}
std::vector<std::int64_t> ParamSet::getInts(const std::string& name) const {
  return getAs<std::vector<std::int64_t>>(*this, name, "a list of int");
}
std::vector<double> ParamSet::getDoubles(const std::string& name) const {
  const ParamValue& v = at(name);
  if (auto* il = std::get_if<std::vector<std::int64_t>>(&v))
    return std::vector<double>(il->begin(), il->end());
  return getAs<std::vector<double>>(*this, name, "a list of numbers");
}
const std::vector<std::string>& ParamSet::getStrings(const std::string& name) const {
  return getAs<std::vector<std::string>>(*this, name, "a list of strings");
}

}  // namespace exid
