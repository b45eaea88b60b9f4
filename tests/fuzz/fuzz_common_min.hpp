// exid — helpers of the loader-only fuzz targets (no registry).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace exid_fuzz {
inline std::string text(const uint8_t* data, size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}
}  // namespace exid_fuzz
