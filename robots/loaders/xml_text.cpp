// exid — robot loaders: private helpers for the XML formats (see xml_text.hpp).
#include "xml_text.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include "exid/error.hpp"

namespace exid::detail {

std::string xmlAt(const std::string& source, const TiXmlNode* node) {
  return node && node->Row() > 0 ? source + ":" + std::to_string(node->Row()) : source;
}

void checkXmlUtf8(const std::string& text, const std::string& src, const char* what) {
  const auto* b = reinterpret_cast<const unsigned char*>(text.data());
  const std::size_t n = text.size();
  int line = 1;
  std::size_t line_start = 0;
  for (std::size_t i = 0; i < n;) {
    const unsigned c = b[i];
    int len = 0;
    unsigned min = 0;
    if (c == 0) {
      len = -1;
    } else if (c < 0x80) {
      len = 1;
    } else if (c >= 0xC2 && c <= 0xDF) {
      len = 2;
      min = 0x80;
    } else if (c >= 0xE0 && c <= 0xEF) {
      len = 3;
      min = 0x800;
    } else if (c >= 0xF0 && c <= 0xF4) {
      len = 4;
      min = 0x10000;
    } else {
      len = -1;
    }
    unsigned cp = len > 1 ? (c & (0xFFu >> (len + 1))) : c;
    for (int k = 1; k < len && len > 0; ++k) {
      if (i + static_cast<std::size_t>(k) >= n || (b[i + k] & 0xC0) != 0x80) {
        len = -1;
        break;
      }
      cp = (cp << 6) | (b[i + k] & 0x3F);
    }
    if (len > 1 && (cp < min || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF))) len = -1;
    if (len < 0) {
      char byte[8];
      std::snprintf(byte, sizeof byte, "0x%02X", c);
      throw Error(src + ":" + std::to_string(line) + ": column " +
                  std::to_string(i - line_start + 1) + ": byte " + byte + (c == 0 ? " (NUL)" : "") +
                  " is not valid UTF-8 here; " + std::string(what) + " must be UTF-8 text");
    }
    if (c == '\n') {
      ++line;
      line_start = i + 1;
    }
    i += static_cast<std::size_t>(len);
  }
}

void readXml(const std::string& text, const std::string& src, const char* what,
             TiXmlDocument* doc) {
  checkXmlUtf8(text, src, what);
  doc->Parse(text.c_str());
  if (doc->Error())
    throw Error(src + ":" + std::to_string(doc->ErrorRow()) + ": invalid XML: " + doc->ErrorDesc());
}

std::string xmlRootName(const std::string& text) {
  try {
    checkXmlUtf8(text, "", "");
  } catch (const Error&) {
    return "";  // the loader it goes to says what is wrong
  }
  TiXmlDocument doc;
  doc.Parse(text.c_str());
  const TiXmlElement* root = doc.Error() ? nullptr : doc.RootElement();
  return root ? root->Value() : "";
}

std::string xmlAttr(const TiXmlElement* e, const char* name) {
  const char* v = e->Attribute(name);
  return v ? std::string(v) : std::string();
}

std::vector<double> parseNumbers(const std::string& text, const std::string& where, int count) {
  std::istringstream ss(text);
  std::string tok;
  std::vector<double> out;
  while (ss >> tok) {
    errno = 0;
    char* end = nullptr;
    const double d = std::strtod(tok.c_str(), &end);
    if (end == tok.c_str() || *end != '\0' || errno == ERANGE)
      throw Error(where + ": expected a number, found '" + tok + "'");
    if (!std::isfinite(d)) throw Error(where + ": expected a finite number, found '" + tok + "'");
    out.push_back(d);
  }
  if (count >= 0 && static_cast<int>(out.size()) != count)
    throw Error(where + ": expected " + std::to_string(count) + " number(s), found " +
                std::to_string(out.size()));
  return out;
}

std::vector<double> xmlNumbers(const TiXmlElement* e, const char* name, const std::string& src,
                               int count) {
  const char* v = e->Attribute(name);
  if (!v) return {};
  std::string owner = "<" + std::string(e->Value()) + ">";
  if (const char* n = e->Attribute("name")) owner += std::string(" '") + n + "'";
  return parseNumbers(v, xmlAt(src, e) + ": " + owner + " attribute '" + name + "'", count);
}

std::vector<double> xmlTextNumbers(const TiXmlElement* e, const std::string& src, int count) {
  const char* v = e->GetText();
  return parseNumbers(v ? v : "", xmlAt(src, e) + ": <" + std::string(e->Value()) + ">", count);
}

double xmlChildNumber(const TiXmlElement* e, const char* name, const std::string& src,
                      double fallback) {
  const TiXmlElement* c = e->FirstChildElement(name);
  return c ? xmlTextNumbers(c, src, 1).front() : fallback;
}

std::string xmlChildText(const TiXmlElement* e, const char* name) {
  const TiXmlElement* c = e->FirstChildElement(name);
  const char* v = c ? c->GetText() : nullptr;
  if (!v) return {};
  std::string s(v);
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return {};
  return s.substr(b, s.find_last_not_of(" \t\r\n") - b + 1);
}

}  // namespace exid::detail
