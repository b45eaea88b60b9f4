// exid — a small ordered JSON value for summaries and reports (writing only; keys keep the
// order in which they were set, so summary.json reads top to bottom like the study).
#pragma once

#include <cstdint>
#include <initializer_list>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "exid/export.hpp"

namespace exid {

class EXID_API Json {
 public:
  enum class Type { Null, Bool, Int, Double, String, Array, Object };

  Json() = default;
  Json(std::nullptr_t) {}
  Json(bool b) : type_(Type::Bool), b_(b) {}
  Json(int i) : type_(Type::Int), i_(i) {}
  Json(long i) : type_(Type::Int), i_(i) {}
  Json(long long i) : type_(Type::Int), i_(i) {}
  Json(unsigned i) : type_(Type::Int), i_(i) {}
  Json(unsigned long i) : type_(Type::Int), i_(static_cast<std::int64_t>(i)) {}
  Json(double d) : type_(Type::Double), d_(d) {}
  Json(const char* s) : type_(Type::String), s_(s) {}
  Json(std::string s) : type_(Type::String), s_(std::move(s)) {}
  Json(const std::vector<double>& v);
  Json(const std::vector<std::string>& v);

  static Json array() {
    Json j;
    j.type_ = Type::Array;
    return j;
  }
  static Json object() {
    Json j;
    j.type_ = Type::Object;
    return j;
  }

  Type type() const { return type_; }
  bool isNull() const { return type_ == Type::Null; }
  bool isObject() const { return type_ == Type::Object; }
  bool isArray() const { return type_ == Type::Array; }
  bool isNumber() const { return type_ == Type::Int || type_ == Type::Double; }
  bool isString() const { return type_ == Type::String; }

  /// Object access: inserts a null member if missing (turns a null into an object).
  Json& operator[](const std::string& key);
  /// Object lookup without insertion; nullptr when absent.
  const Json* find(const std::string& key) const;
  bool contains(const std::string& key) const { return find(key) != nullptr; }
  void push_back(Json v);  // turns a null into an array
  std::size_t size() const;
  const Json& at(std::size_t i) const { return items_.at(i).second; }
  const std::vector<std::pair<std::string, Json>>& items() const { return items_; }

  double asDouble() const;
  std::int64_t asInt() const;
  bool asBool() const { return b_; }
  const std::string& asString() const { return s_; }

  /// Serialises; indent < 0 gives one line. Non-finite numbers become null.
  std::string dump(int indent = 2) const;
  /// Parses JSON text; throws exid::Error naming the offset on bad input.
  static Json parse(const std::string& text);

 private:
  void dumpTo(std::string& out, int indent, int depth) const;
  Type type_ = Type::Null;
  bool b_ = false;
  std::int64_t i_ = 0;
  double d_ = 0.0;
  std::string s_;
  std::vector<std::pair<std::string, Json>> items_;  // arrays use empty keys
};

}  // namespace exid
