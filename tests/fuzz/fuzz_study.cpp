// Fuzz target: the study YAML loader (exid::parseStudy) with the fuzz build's plugins.
#include "exid/config.hpp"
#include "exid/error.hpp"
#include "fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    const exid::StudyConfig c =
        exid::parseStudy(exid_fuzz::text(data, size), "fuzz.yaml",
                         std::filesystem::temp_directory_path(), exid_fuzz::registry());
    (void)c.resolvedYaml();
    (void)c.hash();
  } catch (const exid::Error&) {
  }
  return 0;
}
