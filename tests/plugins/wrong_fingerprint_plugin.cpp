// Test plugin library whose manifest claims another exid version and Eigen alignment.
#include "exid/plugin.hpp"

namespace {
void listNothing(void*) {}
}  // namespace

extern "C" __attribute__((visibility("default"))) const exid_manifest* exid_plugin_manifest() {
  static const exid_manifest m{EXID_PLUGIN_ABI_VERSION, sizeof(exid_manifest),
                               exid_build_fingerprint{EXID_COMPILER_ID, EXID_STDLIB_ABI,
                                                      EXID_EIGEN_VERSION_STRING, 8, "9.9.9"},
                               &listNothing};
  return &m;
}
