// exid — errors. Expected failures (bad input, singular problems) throw exid::Error with a message
// that names the file, the place (line, key, link, joint, row) and what was expected.
#pragma once

#include <stdexcept>
#include <string>

#include "exid/export.hpp"

namespace exid {

class EXID_API Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

/// Throws exid::Error(message) when cond is false. The message should say expected vs found.
inline void check(bool cond, const std::string& message) {
  if (!cond) throw Error(message);
}
/// The same for a literal message: no string is built unless the check fails (hot paths).
inline void check(bool cond, const char* message) {
  if (!cond) throw Error(message);
}

}  // namespace exid
