// exid — the one way in for every file exid reads (studies, robot descriptions, CSV data,
// priors, references, meshes, a bag's metadata.yaml and storage files): only regular files,
// checked before they are opened and again on the open descriptor; no control byte in the path;
// a size cap per kind (docs/hostile_input.md, "Limits"); and, during a run, an entry in the
// run's input manifest (path, size, FNV-1a 64 content hash), written in summary.json `inputs`.
// Compiled into exid_dynamics (framework/base/src/input_file.cpp), the library every other
// links: the robot loaders and the bag reader, which do not link the core, use it too.
#pragma once

#include <sys/stat.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/export.hpp"

namespace exid {

/// Size caps on input files, one per kind: a bigger file is refused before it is read.
// A YAML file costs about 250 bytes of memory per byte in the worst case (a list of one-digit
// numbers: 1 MiB parsed into 250 MB), hence the small caps on YAML and robot files (the shipped
// studies and robots are below 100 KB; a 100-link URDF is about 60 KB).
inline constexpr std::uintmax_t kMaxStudyFileBytes = std::uintmax_t{1} << 20;  // study, matrix
inline constexpr std::uintmax_t kMaxRobotFileBytes = std::uintmax_t{2} << 20;  // URDF, DH YAML
// A bag's metadata.yaml (YAML, as a study; a real one is a few KB).
inline constexpr std::uintmax_t kMaxBagMetadataBytes = std::uintmax_t{1} << 20;
// Data files read whole (a prior's parameters.csv, covariance.csv). CSV data is read as a
// stream (exid::CsvReader) with no size limit.
inline constexpr std::uintmax_t kMaxDataFileBytes = std::uintmax_t{256} << 20;
// STL meshes (read whole; 64 MiB is a binary STL of 1.3 million triangles, about 110 MB once
// read).
inline constexpr std::uintmax_t kMaxMeshFileBytes = std::uintmax_t{64} << 20;
// An MCAP storage file of a bag (read whole into memory).
inline constexpr std::uintmax_t kMaxMcapFileBytes = std::uintmax_t{4} << 30;
// Files read as a stream or by another library (CSV data, a bag's SQLite .db3): no size limit.
inline constexpr std::uintmax_t kStreamedFileBytes = UINTMAX_MAX;

/// FNV-1a, 64 bits: the hash of a matrix cell's key and of a study's configuration
/// (StudyConfig::hash): short texts. h: the hash so far (kFnv1aOffset to start). The
/// offset basis is FNV's 14695981039346656037 (0xcbf29ce484222325); the two copies before lacked
/// its last digit (1469598103934665603), so their hashes were not FNV-1a's.
inline constexpr std::uint64_t kFnv1aOffset = 14695981039346656037ull;
EXID_API std::uint64_t fnv1a64(const void* data, std::size_t size, std::uint64_t h = kFnv1aOffset);
inline std::uint64_t fnv1a64(const std::string& text, std::uint64_t h = kFnv1aOffset) {
  return fnv1a64(text.data(), text.size(), h);
}
/// XXH3, 64 bits, seed 0 (Debian's libxxhash, header only): the hash of a file's contents in
/// the input manifest and in a matrix cell's key. FNV-1a multiplies once per byte, at the
/// multiplier's latency: on a 283 MB recording it took a tenth of a whole batch_ls run; XXH3
/// reads 8 bytes per lane and vectorises (about 0.01 s there).
EXID_API std::uint64_t xxh3_64(const void* data, std::size_t size);
inline std::uint64_t xxh3_64(const std::string& text) { return xxh3_64(text.data(), text.size()); }
/// The XXH3 64 of a file's contents, read in blocks through openInputFile (no size limit).
EXID_API std::uint64_t xxh3File(const std::filesystem::path& path,
                                const std::string& what = "input");
/// 16 lower-case hex digits.
EXID_API std::string hashHex(std::uint64_t h);

/// One file a run read.
struct EXID_API InputRecord {
  std::string path;  // absolute
  std::string kind;  // what the reader calls it ("CSV data", "bag metadata", "mesh", ...)
  std::uintmax_t size_bytes = 0;
  std::uint64_t xxh3_64 = 0;  // the contents' hash (xxh3_64())
};

/// The files a run read, one entry per path (the first read; read again unchanged: the same
/// entry). Thread-safe.
class EXID_API InputManifest {
 public:
  /// True when path was recorded with this identity (device, inode, size, modification
  /// time): no need to hash it again.
  bool knows(const std::string& path, const struct stat& st) const;
  void add(const InputRecord& r, const struct stat& st);
  /// The entries in path order.
  std::vector<InputRecord> entries() const;

 private:
  struct Entry {
    InputRecord record;
    dev_t dev = 0;
    ino_t ino = 0;
    off_t size = 0;
    std::int64_t mtime_ns = 0;
  };
  mutable std::mutex m_;
  std::map<std::string, Entry> entries_;
};

/// The manifest files opened on this thread are recorded in (none: not recorded). A run sets
/// it for its stages (runStudy); a thread the run starts sets it again (InputManifestScope).
EXID_API InputManifest* currentInputManifest();
/// Sets the current manifest of this thread for the scope's life (nested scopes restore).
class EXID_API InputManifestScope {
 public:
  explicit InputManifestScope(InputManifest* m);
  ~InputManifestScope();
  InputManifestScope(const InputManifestScope&) = delete;
  InputManifestScope& operator=(const InputManifestScope&) = delete;

 private:
  InputManifest* previous_;
};

/// The path with control bytes shown as \xNN (for messages).
EXID_API std::string printablePath(const std::string& path);

/// The storage of a ROS 2 bag a file is, by its first bytes: "mcap" (the MCAP magic), "sqlite3"
/// (the SQLite header), "" (neither, or unreadable).
EXID_API std::string bagStorageOf(const std::filesystem::path& file);
/// Refuses a path holding a NUL or another control byte (0x01-0x1F, 0x7F): a NUL silently cut
/// the path where the system reads it (`good.csv\0.ignored` opened good.csv).
EXID_API void checkInputPath(const std::filesystem::path& path, const std::string& what);

/// The checks of readInputFile without reading: no control byte in the path, and the path
/// (symbolic links followed) must name a regular file of at most max_bytes.
EXID_API void checkInputFile(const std::filesystem::path& path, const std::string& what,
                             std::uintmax_t max_bytes);

/// Opens an input file for reading after the checks of checkInputFile (checked again on the
/// open descriptor: it may have been replaced; the open never blocks). During a run the file
/// is recorded in the manifest (its contents hashed through the descriptor, which stays at
/// offset 0). Returns the descriptor; the caller closes it.
EXID_API int openInputFile(const std::filesystem::path& path, const std::string& what,
                           std::uintmax_t max_bytes, struct stat* out = nullptr);

/// Reads a whole input file: anything that is not a regular file (a FIFO, a device such as
/// /dev/zero, a directory) is refused BEFORE it is opened for reading; a file larger than
/// max_bytes is refused (also one that grows while it is read). Recorded as openInputFile.
EXID_API std::string readInputFile(const std::filesystem::path& path, const std::string& what,
                                   std::uintmax_t max_bytes);

/// For a file another library opens by its path (SQLite): the checks of openInputFile and the
/// manifest entry, the file closed again.
EXID_API void admitInputFile(const std::filesystem::path& path, const std::string& what,
                             std::uintmax_t max_bytes);

}  // namespace exid
