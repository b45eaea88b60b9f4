// exid — reading input files defensively: only regular files, only up to a size cap. Header-only
// (the robot loaders, which do not link the core library, use it too).
#pragma once

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>

#include "exid/error.hpp"

namespace exid {

/// Size caps on input files (docs/hostile_input.md): a bigger file is refused before it is read.
// A YAML file costs about 250 bytes of memory per byte in the worst case (a list of one-digit
// numbers: 1 MiB parsed into 250 MB), hence the small caps on YAML and robot files (the shipped
// studies and robots are below 100 KB; a 100-link URDF is about 60 KB).
inline constexpr std::uintmax_t kMaxStudyFileBytes = std::uintmax_t{1} << 20;  // study, matrix
inline constexpr std::uintmax_t kMaxRobotFileBytes = std::uintmax_t{2} << 20;  // URDF, DH YAML
// Data files read whole (a prior's parameters.csv). CSV data is read as a
// stream (exid::CsvReader) with no size limit.
inline constexpr std::uintmax_t kMaxDataFileBytes = std::uintmax_t{256} << 20;

namespace detail {
inline std::string fileKind(mode_t m) {
  if (S_ISDIR(m)) return "a directory";
  if (S_ISFIFO(m)) return "a FIFO (named pipe)";
  if (S_ISCHR(m)) return "a character device";
  if (S_ISBLK(m)) return "a block device";
  if (S_ISSOCK(m)) return "a socket";
  return "not a regular file";
}
inline void checkStat(const struct stat& st, const std::string& file, const std::string& what,
                      std::uintmax_t max_bytes) {
  if (!S_ISREG(st.st_mode))
    throw Error(file + ": the " + what + " file is " + fileKind(st.st_mode) +
                ", not a regular file; refused");
  if (static_cast<std::uintmax_t>(st.st_size) > max_bytes)
    throw Error(file + ": the " + what + " file has " + std::to_string(st.st_size) +
                " bytes, more than the limit of " + std::to_string(max_bytes) + " bytes");
}
}  // namespace detail

/// The checks of readInputFile without reading: the path (symbolic links followed) must name a
/// regular file of at most max_bytes.
inline void checkInputFile(const std::filesystem::path& path, const std::string& what,
                           std::uintmax_t max_bytes) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    throw Error(path.string() + ": cannot open the " + what + " file (" +
                (errno == ENOENT ? std::string("no such file") : std::strerror(errno)) + ")");
  detail::checkStat(st, path.string(), what, max_bytes);
}

/// Opens an input file for reading after the checks of readInputFile (the path must name a
/// regular file of at most max_bytes, checked again on the open descriptor: it may have been
/// replaced). Returns the descriptor; the caller closes it.
inline int openInputFile(const std::filesystem::path& path, const std::string& what,
                         std::uintmax_t max_bytes, struct stat* out = nullptr) {
  checkInputFile(path, what, max_bytes);
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
  if (fd < 0)
    throw Error(path.string() + ": cannot open the " + what + " file (" + std::strerror(errno) +
                ")");
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    throw Error(path.string() + ": cannot read the " + what + " file (" + std::strerror(err) + ")");
  }
  try {
    detail::checkStat(st, path.string(), what, max_bytes);
  } catch (...) {
    ::close(fd);
    throw;
  }
  if (out) *out = st;
  return fd;
}

/// Reads a whole input file. Anything that is not a regular file (a FIFO, a device such as
/// /dev/zero, a directory) is refused BEFORE it is opened for reading; the file is then opened
/// non-blocking and checked again on the open descriptor (it may have been replaced), and a
/// file larger than max_bytes is refused (also one that grows while it is read).
inline std::string readInputFile(const std::filesystem::path& path, const std::string& what,
                                 std::uintmax_t max_bytes) {
  struct stat st {};
  const int fd = openInputFile(path, what, max_bytes, &st);
  std::string text;
  text.reserve(static_cast<std::size_t>(st.st_size));
  char buf[1 << 16];
  while (true) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(fd);
      throw Error(path.string() + ": cannot read the " + what + " file (" + std::strerror(err) +
                  ")");
    }
    if (n == 0) break;
    text.append(buf, static_cast<std::size_t>(n));
    if (text.size() > max_bytes) {
      ::close(fd);
      throw Error(path.string() + ": the " + what + " file is larger than the limit of " +
                  std::to_string(max_bytes) + " bytes");
    }
  }
  ::close(fd);
  return text;
}

}  // namespace exid
