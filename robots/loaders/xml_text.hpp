// exid — robot loaders: private helpers for the XML formats (URDF, MJCF, SDF), on TinyXML.
#pragma once

#include <tinyxml.h>

#include <Eigen/Core>
#include <string>
#include <vector>

namespace exid::detail {

/// "source:line" of a node (the source alone when TinyXML has no line for it).
std::string xmlAt(const std::string& source, const TiXmlNode* node);

/// Throws exid::Error unless `text` is well-formed UTF-8 with no NUL byte, naming the line, the
/// column and the byte; `what` ends the message ("a URDF (XML) file"). TinyXML steps over a
/// multi-byte sequence by the length its lead byte announces, so a truncated sequence at the end
/// of the text would make it read past the terminating NUL (found by fuzz_urdf).
void checkXmlUtf8(const std::string& text, const std::string& src, const char* what);

/// Parses `text` (checked with checkXmlUtf8) into *doc (the caller's: a TinyXML document is not
/// returned by value); a syntax error is an exid::Error naming the line.
void readXml(const std::string& text, const std::string& src, const char* what, TiXmlDocument* doc);

/// The name of the root element of XML text ("" when there is none or the text is not XML).
std::string xmlRootName(const std::string& text);

/// The value of attribute `name`, or "" when absent.
std::string xmlAttr(const TiXmlElement* e, const char* name);

/// The finite numbers of a whitespace-separated list; `where` starts the message of an error
/// ("file:12: <joint> 'j1' attribute 'range'"). count >= 0: exactly that many.
std::vector<double> parseNumbers(const std::string& text, const std::string& where, int count);

/// Attribute `name` of e as `count` numbers (count < 0: any); empty when the attribute is absent.
std::vector<double> xmlNumbers(const TiXmlElement* e, const char* name, const std::string& src,
                               int count);

/// The text of element e as `count` numbers (count < 0: any).
std::vector<double> xmlTextNumbers(const TiXmlElement* e, const std::string& src, int count);

/// The text of child element `name` of e as one number; `fallback` when the child is absent.
double xmlChildNumber(const TiXmlElement* e, const char* name, const std::string& src,
                      double fallback);

/// The trimmed text of child element `name` of e ("" when absent or empty).
std::string xmlChildText(const TiXmlElement* e, const char* name);

}  // namespace exid::detail
