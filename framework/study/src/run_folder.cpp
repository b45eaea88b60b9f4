// exid — a study's run folder as a unit (run_folder.hpp).
#include "run_folder.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <stdio.h>
#include <unistd.h>

#include <system_error>

#include "exid/error.hpp"
#include "exid/input_file.hpp"

namespace exid {

bool isRunFolder(const fs::path& dir) {
  std::error_code ec;
  return fs::exists(dir / "summary.json", ec) || fs::exists(dir / "study.resolved.yaml", ec);
}

bool holdsOkRun(const fs::path& dir) {
  try {
    const std::string text = readInputFile(dir / "summary.json", "summary", 64u << 20);
    const Json S = Json::parse(text);
    return S.find("status") && S.find("status")->asString() == "ok";
  } catch (const std::exception&) {
    return false;
  }
}

RunFolder prepareRunFolder(const fs::path& out, bool clean_stale) {
  RunFolder f;
  fs::path d = out.lexically_normal();
  if (d.has_filename() == false && d.has_parent_path()) d = d.parent_path();  // "x/" -> "x"
  const std::string name = d.filename().string();
  check(!name.empty() && name != "." && name != "..",
        fmt::format("--out {}: name an output folder (not '.', '..' or a root)", out.string()));
  std::error_code ec;
  const fs::path named = d;
  // A symbolic link to a folder: the run is published into the link's target (the staging
  // folder beside the target, on its file system); the link stays. Renaming over the link
  // itself would replace it by a folder.
  if (fs::is_symlink(fs::symlink_status(d, ec))) {
    const fs::path target = fs::read_symlink(d, ec);
    const fs::path resolved = fs::canonical(d, ec);
    check(!ec, fmt::format("--out {}: a symbolic link to {}, which does not exist (a dangling "
                           "link); create the folder it names, or choose another output folder",
                           out.string(), target.string()));
    d = resolved;
  }
  f.final_dir = d;
  f.named = named;
  f.parent = d.has_parent_path() ? d.parent_path() : fs::path(".");
  f.failed_dir = f.parent / (d.filename().string() + ".failed");
  if (fs::exists(d, ec)) {
    check(fs::is_directory(d, ec),
          fmt::format("{}: exists and is not a folder; choose another output folder", d.string()));
    check(fs::is_empty(d, ec) || isRunFolder(d),
          fmt::format("{}: exists and does not hold an exid run (no summary.json or "
                      "study.resolved.yaml); refusing to replace it: choose another output folder",
                      d.string()));
  }
  fs::create_directories(f.parent);
  if (clean_stale) {
    cleanStaleTemporaries(f.parent);
    cleanStaleTemporaries(d);
  }
  f.staging = f.parent / fmt::format(".{}.staging.{}", d.filename().string(), ::getpid());
  fs::remove_all(f.staging, ec);
  fs::create_directory(f.staging);
  return f;
}

void publish(const fs::path& staging, const fs::path& to) {
  std::error_code ec;
  if (!fs::exists(to, ec)) {
    fs::rename(staging, to);
    return;
  }
  if (::renameat2(AT_FDCWD, staging.c_str(), AT_FDCWD, to.c_str(), RENAME_EXCHANGE) == 0) {
    fs::remove_all(staging, ec);  // now the old folder
    return;
  }
  // No RENAME_EXCHANGE on this file system: the old folder moves aside first.
  const fs::path aside = to.string() + fmt::format(".old.{}", ::getpid());
  fs::remove_all(aside, ec);
  fs::rename(to, aside);
  fs::rename(staging, to);
  fs::remove_all(aside, ec);
}

}  // namespace exid
