// exid — the files embedded into the robots plugin library (generated table,
// robots/CMakeLists.txt): robots/catalogue.yaml and every description file of the robot folders, by
// path relative to robots/ (e.g. "panda/panda.yaml").
#pragma once

struct ExidShippedFile {
  const char* path;
  const char* const* text;
};

extern const ExidShippedFile exid_shipped_files[];
extern const int exid_shipped_file_count;
