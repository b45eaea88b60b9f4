// exid — the one way in for every input file (see exid/input_file.hpp).
#include "exid/input_file.hpp"

#include <fcntl.h>
#include <unistd.h>
// (the whole implementation, inline: the .deb needs no libxxhash0 at run time)
#define XXH_INLINE_ALL
#include <xxhash.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

namespace exid {

namespace fs = std::filesystem;

std::uint64_t fnv1a64(const void* data, std::size_t size, std::uint64_t h) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < size; ++i) {
    h ^= p[i];
    h *= 1099511628211ull;
  }
  return h;
}

std::uint64_t xxh3_64(const void* data, std::size_t size) { return XXH3_64bits(data, size); }

std::string hashHex(std::uint64_t h) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

// ------------------------------------------------------------------ the manifest
namespace {
thread_local InputManifest* t_manifest = nullptr;

std::int64_t mtimeNs(const struct stat& st) {
  return static_cast<std::int64_t>(st.st_mtim.tv_sec) * 1000000000LL + st.st_mtim.tv_nsec;
}
}  // namespace

bool InputManifest::knows(const std::string& path, const struct stat& st) const {
  std::lock_guard<std::mutex> l(m_);
  const auto it = entries_.find(path);
  return it != entries_.end() && it->second.dev == st.st_dev && it->second.ino == st.st_ino &&
         it->second.size == st.st_size && it->second.mtime_ns == mtimeNs(st);
}

void InputManifest::add(const InputRecord& r, const struct stat& st) {
  std::lock_guard<std::mutex> l(m_);
  Entry e;
  e.record = r;
  e.dev = st.st_dev;
  e.ino = st.st_ino;
  e.size = st.st_size;
  e.mtime_ns = mtimeNs(st);
  entries_[r.path] = e;  // read again after a change: what was read last
}

std::vector<InputRecord> InputManifest::entries() const {
  std::lock_guard<std::mutex> l(m_);
  std::vector<InputRecord> out;
  out.reserve(entries_.size());
  for (const auto& [path, e] : entries_) out.push_back(e.record);
  return out;
}

InputManifest* currentInputManifest() { return t_manifest; }

InputManifestScope::InputManifestScope(InputManifest* m) : previous_(t_manifest) { t_manifest = m; }
InputManifestScope::~InputManifestScope() { t_manifest = previous_; }

// ------------------------------------------------------------------ checks
std::string printablePath(const std::string& path) {
  std::string out;
  for (const char c : path) {
    const auto u = static_cast<unsigned char>(c);
    if (u < 0x20 || u == 0x7F) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02X", u);
      out += buf;
    } else {
      out += c;
    }
  }
  return out;
}

void checkInputPath(const fs::path& path, const std::string& what) {
  const std::string& s = path.native();
  for (std::size_t i = 0; i < s.size(); ++i) {
    const auto u = static_cast<unsigned char>(s[i]);
    if (u < 0x20 || u == 0x7F) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "0x%02X", u);
      throw Error(printablePath(s) + ": the path of the " + what + " file holds the control byte " +
                  buf + " at byte " + std::to_string(i + 1) +
                  " (a file name must not hold control bytes; a NUL would cut the path short); "
                  "refused");
    }
  }
}

namespace {

std::string fileKind(mode_t m) {
  if (S_ISDIR(m)) return "a directory";
  if (S_ISFIFO(m)) return "a FIFO (named pipe)";
  if (S_ISCHR(m)) return "a character device";
  if (S_ISBLK(m)) return "a block device";
  if (S_ISSOCK(m)) return "a socket";
  return "not a regular file";
}

void checkStat(const struct stat& st, const std::string& file, const std::string& what,
               std::uintmax_t max_bytes) {
  if (!S_ISREG(st.st_mode))
    throw Error(file + ": the " + what + " file is " + fileKind(st.st_mode) +
                ", not a regular file; refused");
  if (static_cast<std::uintmax_t>(st.st_size) > max_bytes)
    throw Error(file + ": the " + what + " file has " + std::to_string(st.st_size) +
                " bytes, more than the limit of " + std::to_string(max_bytes) + " bytes");
}

// The checks, then the file opened (never blocking) and checked again on the descriptor.
int openChecked(const fs::path& path, const std::string& what, std::uintmax_t max_bytes,
                struct stat* out) {
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
    checkStat(st, path.string(), what, max_bytes);
  } catch (...) {
    ::close(fd);
    throw;
  }
  *out = st;
  return fd;
}

std::string manifestPath(const fs::path& path) {
  std::error_code ec;
  const fs::path abs = fs::absolute(path, ec);
  return (ec ? path : abs).lexically_normal().string();
}

// The contents' hash through fd from offset 0 (the descriptor's own offset is not moved).
std::uint64_t hashDescriptor(int fd, const fs::path& path, const std::string& what,
                             std::uintmax_t* bytes) {
  std::vector<char> buf(std::size_t{1} << 20);
  XXH3_state_t state;
  XXH3_64bits_reset(&state);
  off_t at = 0;
  while (true) {
    const ssize_t n = ::pread(fd, buf.data(), buf.size(), at);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0)
      throw Error(path.string() + ": cannot read the " + what + " file (" + std::strerror(errno) +
                  ")");
    if (n == 0) break;
    XXH3_64bits_update(&state, buf.data(), static_cast<std::size_t>(n));
    at += n;
  }
  *bytes = static_cast<std::uintmax_t>(at);
  return XXH3_64bits_digest(&state);
}

// Records the file open on fd in the current manifest (if any), hashing it unless known.
void record(int fd, const struct stat& st, const fs::path& path, const std::string& what) {
  InputManifest* m = currentInputManifest();
  if (!m) return;
  const std::string p = manifestPath(path);
  if (m->knows(p, st)) return;
  InputRecord r;
  r.path = p;
  r.kind = what;
  r.xxh3_64 = hashDescriptor(fd, path, what, &r.size_bytes);
  m->add(r, st);
}

}  // namespace

void checkInputFile(const fs::path& path, const std::string& what, std::uintmax_t max_bytes) {
  checkInputPath(path, what);
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    throw Error(path.string() + ": cannot open the " + what + " file (" +
                (errno == ENOENT ? std::string("no such file") : std::strerror(errno)) + ")");
  checkStat(st, path.string(), what, max_bytes);
}

int openInputFile(const fs::path& path, const std::string& what, std::uintmax_t max_bytes,
                  struct stat* out) {
  struct stat st {};
  const int fd = openChecked(path, what, max_bytes, &st);
  try {
    record(fd, st, path, what);
  } catch (...) {
    ::close(fd);
    throw;
  }
  if (out) *out = st;
  return fd;
}

std::string readInputFile(const fs::path& path, const std::string& what, std::uintmax_t max_bytes) {
  struct stat st {};
  const int fd = openChecked(path, what, max_bytes, &st);
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
  if (InputManifest* m = currentInputManifest()) {
    InputRecord r;
    r.path = manifestPath(path);
    r.kind = what;
    r.size_bytes = text.size();
    r.xxh3_64 = xxh3_64(text);
    m->add(r, st);
  }
  return text;
}

void admitInputFile(const fs::path& path, const std::string& what, std::uintmax_t max_bytes) {
  ::close(openInputFile(path, what, max_bytes));
}

std::uint64_t xxh3File(const fs::path& path, const std::string& what) {
  struct stat st {};
  const int fd = openChecked(path, what, kStreamedFileBytes, &st);
  std::uintmax_t bytes = 0;
  std::uint64_t h = 0;
  try {
    h = hashDescriptor(fd, path, what, &bytes);
  } catch (...) {
    ::close(fd);
    throw;
  }
  ::close(fd);
  return h;
}

std::string bagStorageOf(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  char b[16] = {};
  in.read(b, sizeof b);
  const std::string head(b, static_cast<std::size_t>(in.gcount()));
  if (head.compare(0, 8, std::string("\x89MCAP0\r\n", 8)) == 0) return "mcap";
  if (head == std::string("SQLite format 3\0", 16)) return "sqlite3";
  return "";
}

}  // namespace exid
