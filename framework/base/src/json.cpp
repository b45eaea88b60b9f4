#include "exid/json.hpp"

#include <fmt/format.h>

#include <cmath>
#include <cstdlib>

#include "exid/error.hpp"

namespace exid {

Json::Json(const std::vector<double>& v) : type_(Type::Array) {
  for (double d : v) items_.emplace_back(std::string(), Json(d));
}
Json::Json(const std::vector<std::string>& v) : type_(Type::Array) {
  for (const auto& s : v) items_.emplace_back(std::string(), Json(s));
}

Json& Json::operator[](const std::string& key) {
  if (type_ == Type::Null) type_ = Type::Object;
  if (type_ != Type::Object) throw Error("Json: member access '" + key + "' on a non-object");
  for (auto& kv : items_)
    if (kv.first == key) return kv.second;
  items_.emplace_back(key, Json());
  return items_.back().second;
}

const Json* Json::find(const std::string& key) const {
  if (type_ != Type::Object) return nullptr;
  for (const auto& kv : items_)
    if (kv.first == key) return &kv.second;
  return nullptr;
}

void Json::push_back(Json v) {
  if (type_ == Type::Null) type_ = Type::Array;
  if (type_ != Type::Array) throw Error("Json: push_back on a non-array");
  items_.emplace_back(std::string(), std::move(v));
}

std::size_t Json::size() const { return items_.size(); }

double Json::asDouble() const {
  if (type_ == Type::Int) return static_cast<double>(i_);
  if (type_ == Type::Double) return d_;
  if (type_ == Type::Null) return std::nan("");
  throw Error("Json: not a number");
}
std::int64_t Json::asInt() const {
  if (type_ == Type::Int) return i_;
  if (type_ == Type::Double) return static_cast<std::int64_t>(d_);
  throw Error("Json: not a number");
}

namespace {
void escape(std::string& out, const std::string& s) {
  out += '"';
  for (unsigned char c : s) {
    switch (c) {
      case '"':
        out += "\\\"";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\n':
        out += "\\n";
        break;
      case '\r':
        out += "\\r";
        break;
      case '\t':
        out += "\\t";
        break;
      default:
        if (c < 0x20)
          out += fmt::format("\\u{:04x}", c);
        else
          out += static_cast<char>(c);
    }
  }
  out += '"';
}
}  // namespace

void Json::dumpTo(std::string& out, int indent, int depth) const {
  auto newline = [&](int d) {
    if (indent < 0) return;
    out += '\n';
    out.append(static_cast<std::size_t>(indent * d), ' ');
  };
  switch (type_) {
    case Type::Null:
      out += "null";
      break;
    case Type::Bool:
      out += b_ ? "true" : "false";
      break;
    case Type::Int:
      out += std::to_string(i_);
      break;
    case Type::Double:
      if (std::isfinite(d_))
        out += fmt::format("{}", d_);
      else
        out += "null";
      break;
    case Type::String:
      escape(out, s_);
      break;
    case Type::Array:
    case Type::Object: {
      const bool obj = type_ == Type::Object;
      out += obj ? '{' : '[';
      if (items_.empty()) {
        out += obj ? '}' : ']';
        break;
      }
      // Short arrays of scalars stay on one line.
      bool flat = !obj && items_.size() <= 12;
      for (const auto& kv : items_)
        if (kv.second.isArray() || kv.second.isObject()) flat = false;
      for (std::size_t k = 0; k < items_.size(); ++k) {
        if (k) out += flat ? ", " : ",";
        if (!flat) newline(depth + 1);
        if (obj) {
          escape(out, items_[k].first);
          out += indent < 0 ? ":" : ": ";
        }
        items_[k].second.dumpTo(out, indent, depth + 1);
      }
      if (!flat) newline(depth);
      out += obj ? '}' : ']';
      break;
    }
  }
}

std::string Json::dump(int indent) const {
  std::string out;
  dumpTo(out, indent, 0);
  return out;
}

namespace {
struct Parser {
  const std::string& s;
  std::size_t i = 0;
  [[noreturn]] void fail(const std::string& what) {
    throw Error(fmt::format("JSON: {} at offset {}", what, i));
  }
  void ws() {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\n' || s[i] == '\t' || s[i] == '\r')) ++i;
  }
  bool lit(const char* w) {
    std::size_t n = std::char_traits<char>::length(w);
    if (s.compare(i, n, w) == 0) {
      i += n;
      return true;
    }
    return false;
  }
  std::string str() {
    if (s[i] != '"') fail("expected a string");
    ++i;
    std::string r;
    while (i < s.size() && s[i] != '"') {
      char c = s[i++];
      if (c == '\\') {
        if (i >= s.size()) fail("bad escape");
        char e = s[i++];
        switch (e) {
          case 'n':
            r += '\n';
            break;
          case 't':
            r += '\t';
            break;
          case 'r':
            r += '\r';
            break;
          case 'b':
            r += '\b';
            break;
          case 'f':
            r += '\f';
            break;
          case 'u': {
            if (i + 4 > s.size()) fail("bad \\u escape");
            unsigned cp = static_cast<unsigned>(std::strtoul(s.substr(i, 4).c_str(), nullptr, 16));
            i += 4;
            if (cp < 0x80)
              r += static_cast<char>(cp);
            else if (cp < 0x800) {
              r += static_cast<char>(0xC0 | (cp >> 6));
              r += static_cast<char>(0x80 | (cp & 0x3F));
            } else {
              r += static_cast<char>(0xE0 | (cp >> 12));
              r += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
              r += static_cast<char>(0x80 | (cp & 0x3F));
            }
            break;
          }
          default:
            r += e;
        }
      } else {
        r += c;
      }
    }
    if (i >= s.size()) fail("unterminated string");
    ++i;
    return r;
  }
  Json value() {
    ws();
    if (i >= s.size()) fail("unexpected end");
    char c = s[i];
    if (c == '{') {
      ++i;
      Json o = Json::object();
      ws();
      if (s[i] == '}') {
        ++i;
        return o;
      }
      while (true) {
        ws();
        std::string k = str();
        ws();
        if (i >= s.size() || s[i] != ':') fail("expected ':'");
        ++i;
        o[k] = value();
        ws();
        if (i < s.size() && s[i] == ',') {
          ++i;
          continue;
        }
        if (i < s.size() && s[i] == '}') {
          ++i;
          return o;
        }
        fail("expected ',' or '}'");
      }
    }
    if (c == '[') {
      ++i;
      Json a = Json::array();
      ws();
      if (s[i] == ']') {
        ++i;
        return a;
      }
      while (true) {
        a.push_back(value());
        ws();
        if (i < s.size() && s[i] == ',') {
          ++i;
          continue;
        }
        if (i < s.size() && s[i] == ']') {
          ++i;
          return a;
        }
        fail("expected ',' or ']'");
      }
    }
    if (c == '"') return Json(str());
    if (lit("true")) return Json(true);
    if (lit("false")) return Json(false);
    if (lit("null")) return Json();
    const char* begin = s.c_str() + i;
    char* end = nullptr;
    double d = std::strtod(begin, &end);
    if (end == begin) fail("unexpected character");
    std::string tok(begin, static_cast<std::size_t>(end - begin));
    i += static_cast<std::size_t>(end - begin);
    if (tok.find_first_of(".eE") == std::string::npos)
      return Json(static_cast<long long>(std::strtoll(tok.c_str(), nullptr, 10)));
    return Json(d);
  }
};
}  // namespace

Json Json::parse(const std::string& text) {
  Parser p{text};
  Json v = p.value();
  p.ws();
  if (p.i != text.size()) p.fail("trailing characters");
  return v;
}

}  // namespace exid
