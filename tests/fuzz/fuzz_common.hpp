// exid — helpers of the libFuzzer targets (tests/fuzz, built with -DEXID_FUZZ=ON by clang).
// A target returns normally when exid rejects the input with exid::Error (the documented way to
// fail); any other exception escapes and libFuzzer reports it as a crash (uncaught exception),
// as it does for sanitizer findings, hangs (-timeout) and out-of-memory (-rss_limit_mb).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "exid/registry.hpp"
#include "fuzz_common_min.hpp"

namespace exid_fuzz {

/// The registry of the fuzz build's plugins (EXID_FUZZ_PLUGIN_DIR), scanned once.
inline exid::Registry& registry() {
  static exid::Registry* reg = [] {
    auto* r = new exid::Registry();
    r->addSearchPath(std::filesystem::path(EXID_FUZZ_PLUGIN_DIR));
    r->scan();
    return r;
  }();
  return *reg;
}

}  // namespace exid_fuzz
