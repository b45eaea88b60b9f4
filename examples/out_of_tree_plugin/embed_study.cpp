// A program that embeds exid: it runs a study file through the facade (exid/exid.hpp), as
// `exid run` does, and prints the status and the results' own verdict.
//   embed_study STUDY.yaml OUT_DIR [PLUGIN_DIR...]
// Exit status: 0 for a study whose status is ok, 1 otherwise (the reason on stderr).
#include <iostream>

#include "exid/exid.hpp"
#include "exid/registry.hpp"

int main(int argc, char** argv) {
  if (argc < 3) {
    std::cerr << "usage: embed_study STUDY.yaml OUT_DIR [PLUGIN_DIR...]\n";
    return 2;
  }
  exid::Registry plugins;
  for (int i = 3; i < argc; ++i) plugins.addSearchPath(argv[i]);
  plugins.scan();  // the given folders, then the installed plugins
  exid::StudySettings settings;
  settings.out_dir = argv[2];
  const exid::StudyOutcome r = exid::runStudyFile(argv[1], plugins, settings);
  std::cout << "status: " << r.status << "\n";
  if (!r.ok) {
    std::cerr << "embed_study: " << r.message << "\n";
    return 1;
  }
  std::cout << "verdict: " << r.verdict << "\n";
  for (const auto& reason : r.verdict_reasons) std::cout << "  " << reason << "\n";
  std::cout << "written to: " << r.written_to.string() << "\n";
  return 0;
}
