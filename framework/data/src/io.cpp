#include "exid/io.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <new>
#include <sstream>

#include "exid/error.hpp"

namespace exid {

namespace fs = std::filesystem;

bool IoError::outOfSpace() const {
  return errno_value == ENOSPC || errno_value == EDQUOT || errno_value == EFBIG;
}

AtomicFileWriter::AtomicFileWriter(fs::path path) : path_(std::move(path)) {
  std::error_code ec;
  if (path_.has_parent_path()) fs::create_directories(path_.parent_path(), ec);
  tmp_ = path_.string() + fmt::format(".tmp.{}", ::getpid());
  fd_ = ::open(tmp_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) {
    const int err = errno;
    throw IoError(fmt::format("{}: cannot write: {}", path_.string(), std::strerror(err)), err);
  }
  buf_.reserve(kBuffer);
}

AtomicFileWriter::~AtomicFileWriter() {
  if (fd_ >= 0) {  // not committed: nothing is left
    ::close(fd_);
    ::unlink(tmp_.c_str());
  }
}

void AtomicFileWriter::fail(const std::string& what, int err) {
  ::close(fd_);
  fd_ = -1;
  ::unlink(tmp_.c_str());
  throw IoError(fmt::format("{}: {}: {}", path_.string(), what, std::strerror(err)), err);
}

void AtomicFileWriter::put(const char* p, std::size_t n) {
  std::size_t done = 0;
  while (done < n) {
    const ssize_t w = ::write(fd_, p + done, n - done);
    if (w < 0) {
      if (errno == EINTR) continue;
      fail("write failed", errno);
    }
    done += static_cast<std::size_t>(w);
  }
}

void AtomicFileWriter::flush() {
  put(buf_.data(), buf_.size());
  buf_.clear();
}

void AtomicFileWriter::write(std::string_view text) {
  check(fd_ >= 0, fmt::format("{}: written after its commit", path_.string()));
  if (buf_.size() + text.size() > kBuffer) flush();
  if (text.size() > kBuffer)  // (a large piece goes out as it is, never copied)
    put(text.data(), text.size());
  else
    buf_.append(text.data(), text.size());
}

void AtomicFileWriter::commit() {
  check(fd_ >= 0, fmt::format("{}: committed twice", path_.string()));
  flush();
  if (::fsync(fd_) != 0) fail("write failed", errno);
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp_.c_str());
    throw IoError(fmt::format("{}: write failed: {}", path_.string(), std::strerror(err)), err);
  }
  if (std::rename(tmp_.c_str(), path_.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp_.c_str());
    throw Error(
        fmt::format("{}: cannot rename into place: {}", path_.string(), std::strerror(err)));
  }
}

void writeFileAtomic(const fs::path& path, const std::string& text) {
  AtomicFileWriter out(path);
  out.write(text);
  out.commit();
}

int cleanStaleTemporaries(const fs::path& dir) {
  int removed = 0;
  std::error_code ec;
  fs::directory_iterator it(dir, ec), end;
  for (; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    // NAME.tmp.PID (writeFileAtomic) and .NAME.staging.PID (runStudy's staging folder)
    std::size_t dot = name.rfind('.');
    if (dot == std::string::npos || dot + 1 >= name.size()) continue;
    const std::string pid_text = name.substr(dot + 1);
    if (pid_text.find_first_not_of("0123456789") != std::string::npos || pid_text.size() > 9)
      continue;
    const std::string stem = name.substr(0, dot);
    const bool tmp = stem.size() > 4 && stem.compare(stem.size() - 4, 4, ".tmp") == 0;
    const bool staging =
        name[0] == '.' && stem.size() > 8 && stem.compare(stem.size() - 8, 8, ".staging") == 0;
    if (!tmp && !staging) continue;
    const pid_t pid = static_cast<pid_t>(std::stol(pid_text));
    if (pid <= 0 || pid == ::getpid()) continue;
    if (::kill(pid, 0) == 0 || errno != ESRCH) continue;  // its writer may still be running
    std::error_code rm;
    if (fs::remove_all(it->path(), rm) > 0 && !rm) ++removed;
  }
  return removed;
}

int CsvTable::col(const std::string& name) const {
  for (std::size_t i = 0; i < columns.size(); ++i)
    if (columns[i] == name) return static_cast<int>(i);
  return -1;
}

const std::string& CsvTable::notNumeric(int c) const {
  static const std::string none;
  return c >= 0 && static_cast<std::size_t>(c) < not_numeric.size()
             ? not_numeric[static_cast<std::size_t>(c)]
             : none;
}

Eigen::VectorXd CsvTable::column(const std::string& name) const {
  int c = col(name);
  if (c < 0) throw Error(fmt::format("CSV: no column '{}'", name));
  return data.col(c);
}

namespace {
std::string trim(const std::string& s) {
  std::size_t a = s.find_first_not_of(" \t\r\"");
  if (a == std::string::npos) return "";
  std::size_t b = s.find_last_not_of(" \t\r\"");
  return s.substr(a, b - a + 1);
}
std::vector<std::string> split(const std::string& line, char d,
                               std::vector<std::size_t>* starts = nullptr) {
  std::vector<std::string> out;
  std::string cur;
  std::size_t start = 0;
  auto push = [&](std::size_t end) {
    out.push_back(trim(cur));
    if (starts) {  // 0-based offset in the line of the cell's first byte after trimming
      const std::size_t a = cur.find_first_not_of(" \t\r\"");
      starts->push_back(start + (a == std::string::npos ? 0 : a));
    }
    cur.clear();
    start = end + 1;
  };
  for (std::size_t i = 0; i < line.size(); ++i) {
    if (line[i] == d)
      push(i);
    else
      cur += line[i];
  }
  push(line.size());
  return out;
}

std::string printable(const std::string& s) {
  std::string out;
  for (unsigned char c : s) {
    if (c >= 0x20 && c < 0x7f)
      out += static_cast<char>(c);
    else
      out += fmt::format("\\x{:02X}", c);
    if (out.size() > 60) return out + "...";
  }
  return out;
}
}  // namespace

namespace {
inline bool isTrim(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '"'; }

// The error of a cell [a, b) (trimmed, not empty) that strtod does not read whole: `used` bytes
// were read, col0 is the 0-based offset of a in its line.
std::string notANumber(const std::string& source, int lineno, std::size_t col0,
                       const std::string& column, const std::string& s, std::size_t used) {
  const unsigned char b = static_cast<unsigned char>(s[used == 0 ? 0 : used]);
  return fmt::format("{}:{}:{}: column '{}': '{}' is not a number ({} at column {})", source,
                     lineno, col0 + used + 1, column, printable(s),
                     b >= 0x20 && b < 0x7f ? fmt::format("unexpected '{}'", static_cast<char>(b))
                                           : fmt::format("unexpected byte 0x{:02X}", b),
                     col0 + used + 1);
}

// A cell as strtod reads it, the reference: how many bytes it used (0: none).
double strtodCell(const std::string& s, std::size_t* used) {
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  *used = static_cast<std::size_t>(end - s.c_str());
  return v;
}
}  // namespace

namespace {
// Eight ASCII digits at p (the bytes p[0..7], all inside the cell) as their value, false when
// one of them is not a digit: one 64-bit load and three multiplications (the classic SWAR
// conversion) instead of eight dependent steps.
inline bool eightDigits(const char* p, std::uint64_t* v) {
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
  (void)p;
  (void)v;
  return false;  // (the digit by digit path)
#else
  std::uint64_t x = 0;
  std::memcpy(&x, p, 8);
  // every byte in '0'..'9' (0x30..0x39): neither x - '0' nor x + 0x46 sets a byte's high bit
  if (((x + 0x4646464646464646ULL) | (x - 0x3030303030303030ULL)) & 0x8080808080808080ULL)
    return false;
  x -= 0x3030303030303030ULL;  // (little-endian: the first digit in the low byte)
  x = (x * 10) + (x >> 8);     // pairs
  x = (((x & 0x000000FF000000FFULL) * (100 + (1000000ULL << 32))) +
       (((x >> 16) & 0x000000FF000000FFULL) * (1 + (10000ULL << 32)))) >>
      32;
  *v = x;
  return true;
#endif
}

// Clinger's exact case: a decimal [+-]digits[.digits][(e|E)[+-]digits] whose digits make an
// integer m <= 2^53 and whose power of ten e is within [-22, 22]: m and 10^|e| are exact
// doubles, so the one IEEE multiplication or division is the correctly rounded value, the
// same bits as std::from_chars and strtod. Here the one that starts at p and ends at b or at the
// byte `until` (a cell's delimiter): the byte where it ends, or nullptr (nothing decided) for
// anything else.
const char* shortDecimalPrefix(const char* p, const char* b, char until, double* v) {
  static constexpr double kPow10[] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                      1e8,  1e9,  1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                                      1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};
  constexpr std::uint64_t kMaxExact = std::uint64_t{1} << 53;
  bool neg = false;
  if (p < b && (*p == '-' || *p == '+')) neg = *p++ == '-';
  // (eight digits at a time while m stays exact: m <= kMaxExact after them; the same m as
  // digit by digit, and a digit that would leave the exact range still returns false)
  constexpr std::uint64_t kMaxBefore8 = (kMaxExact - 99999999) / 100000000;
  std::uint64_t m = 0, eight = 0;
  int digits = 0, frac = 0;
  while (b - p >= 8 && m <= kMaxBefore8 && eightDigits(p, &eight)) {
    m = 100000000 * m + eight;
    p += 8;
    digits += 8;
  }
  for (; p < b && static_cast<unsigned>(*p - '0') < 10u; ++p, ++digits) {
    if (m > (kMaxExact - 9) / 10) return nullptr;
    m = 10 * m + static_cast<unsigned>(*p - '0');
  }
  if (p < b && *p == '.') {
    ++p;
    while (b - p >= 8 && m <= kMaxBefore8 && eightDigits(p, &eight)) {
      m = 100000000 * m + eight;
      p += 8;
      digits += 8;
      frac += 8;
    }
    for (; p < b && static_cast<unsigned>(*p - '0') < 10u; ++p, ++digits, ++frac) {
      if (m > (kMaxExact - 9) / 10) return nullptr;
      m = 10 * m + static_cast<unsigned>(*p - '0');
    }
  }
  if (digits == 0) return nullptr;
  int e = 0;
  if (p < b && (*p == 'e' || *p == 'E')) {
    ++p;
    bool eneg = false;
    if (p < b && (*p == '-' || *p == '+')) eneg = *p++ == '-';
    const char* first = p;
    for (; p < b && static_cast<unsigned>(*p - '0') < 10u; ++p) {
      if (e > 1000) return nullptr;
      e = 10 * e + (*p - '0');
    }
    if (p == first) return nullptr;  // (an exponent without digits)
    if (eneg) e = -e;
  }
  if (p != b && *p != until) return nullptr;
  e -= frac;
  if (e < -22 || e > 22) return nullptr;
  double x = static_cast<double>(m);
  x = e < 0 ? x / kPow10[-e] : x * kPow10[e];
  *v = neg ? -x : x;
  return p;
}

// The same for the whole of [p, b).
bool parseShortDecimal(const char* p, const char* b, double* v) {
  return shortDecimalPrefix(p, b, '\0', v) == b;
}
}  // namespace

bool parseCsvNumber(const char* a, const char* b, double* v, std::size_t* used) {
  // The common short decimal, exactly; then std::from_chars on the whole cell, a leading '+'
  // skipped (strtod takes it).
  if (parseShortDecimal(a, b, v)) {
    *used = static_cast<std::size_t>(b - a);
    return true;
  }
  const char* p = a;
  if (b - a >= 2 && *p == '+' && p[1] != '+' && p[1] != '-') ++p;
  double x = 0;
  const auto r = std::from_chars(p, b, x);
  if (r.ec == std::errc() && r.ptr == b && std::isfinite(x)) {
    *v = x;
    *used = static_cast<std::size_t>(b - a);
    return true;
  }
  // Anything else as strtod says it (hex, NaN payloads, out of range, a stray byte).
  const std::string s(a, b);
  *v = strtodCell(s, used);
  return *used != 0 && *used == s.size();
}

CsvReader::CsvReader(const fs::path& path, const CsvReadOptions& opt, const std::string& what,
                     std::size_t block_bytes)
    : opt_(opt),
      source_(path.string()),
      what_(what),
      block_(std::max<std::size_t>(1, block_bytes)) {
  fd_ = openInputFile(path, what, UINTMAX_MAX);
  try {
    readHeader();
  } catch (...) {
    ::close(fd_);
    fd_ = -1;
    throw;
  }
}

CsvReader::CsvReader(std::string_view text, const std::string& source, const CsvReadOptions& opt,
                     std::size_t block_bytes)
    : opt_(opt), source_(source), text_(text), block_(block_bytes) {
  if (block_ == 0) {  // the whole text is the one block
    beg_ = text.data();
    end_ = text.data() + text.size();
    text_pos_ = text.size();
    eof_ = true;
  }
  readHeader();
}

CsvReader::CsvReader(std::string_view body, const CsvReader& like, int like_line)
    : opt_(like.opt_),
      source_(like.source_),
      what_(like.what_),
      text_(body),
      text_pos_(body.size()),
      block_(0),
      beg_(body.data()),
      end_(body.data() + body.size()),
      eof_(true),
      lineno_(like_line),
      header_line_(like.header_line_),
      delim_(like.delim_),
      columns_(like.columns_),
      not_numeric_(like.columns_.size()),
      sel_(like.sel_),
      slot_(like.slot_),
      cells_read_(like.cells_read_) {}

CsvReader::~CsvReader() {
  if (fd_ >= 0) ::close(fd_);
}

void CsvReader::readFailed(int err) {
  throw Error(fmt::format("{}: cannot read the {} file ({})", source_, what_, std::strerror(err)));
}

// More bytes after [beg_, end_): false at the end of the input.
bool CsvReader::refill() {
  if (eof_) return false;
  const std::size_t have = static_cast<std::size_t>(end_ - beg_);
  if (buf_.size() < have + block_) {  // (a file's first: room for a block and a line left over)
    decltype(buf_) bigger(
        std::max(have + block_, buf_.empty() && fd_ >= 0 ? 2 * block_ : 2 * buf_.size()));
    if (have) std::memcpy(bigger.data(), beg_, have);
    buf_.swap(bigger);
  } else if (have && beg_ != buf_.data()) {
    std::memmove(buf_.data(), beg_, have);
  }
  beg_ = buf_.data();
  end_ = beg_ + have;
  std::size_t n = 0;
  if (fd_ >= 0) {
    while (true) {
      const ssize_t r = ::read(fd_, buf_.data() + have, block_);
      if (r < 0) {
        if (errno == EINTR) continue;
        readFailed(errno);
      }
      n = static_cast<std::size_t>(r);
      break;
    }
  } else {
    n = std::min(block_, text_.size() - text_pos_);
    if (n) std::memcpy(buf_.data() + have, text_.data() + text_pos_, n);
    text_pos_ += n;
  }
  if (n == 0) {
    eof_ = true;
    return false;
  }
  end_ += n;
  return true;
}

// The next line [b, e) without its '\n' (nor one '\r' before it): false at the end. As
// std::getline: a last line without '\n' counts when it is not empty.
bool CsvReader::nextLine(const char** b, const char** e) {
  while (true) {
    const char* nl = static_cast<const char*>(
        beg_ + scanned_ < end_
            ? std::memchr(beg_ + scanned_, '\n', static_cast<std::size_t>(end_ - beg_) - scanned_)
            : nullptr);
    if (nl) {
      *b = beg_;
      *e = nl;
      bytes_ += static_cast<std::uint64_t>(nl + 1 - beg_);
      beg_ = nl + 1;
      scanned_ = 0;
      break;
    }
    scanned_ = static_cast<std::size_t>(end_ - beg_);
    if (!refill()) {
      if (beg_ == end_) return false;
      *b = beg_;
      *e = end_;
      bytes_ += static_cast<std::uint64_t>(end_ - beg_);
      beg_ = end_;
      scanned_ = 0;
      break;
    }
  }
  ++lineno_;
  if (*e > *b && (*e)[-1] == '\r') --*e;
  return true;
}

namespace {
// The number of bytes d in [b, e). Counted in blocks of at most 255 bytes into a byte-wide
// counter, which the compiler vectorises without widening each comparison to 64 bits: twice
// std::count's speed (9.7 against 4.7 GB/s on the lines of a 25-column CSV).
inline std::size_t countByte(const char* b, const char* e, char d) {
  std::size_t total = 0;
  while (b < e) {
    const std::size_t m = std::min<std::size_t>(static_cast<std::size_t>(e - b), 255);
    unsigned char c = 0;
    for (std::size_t i = 0; i < m; ++i) c = static_cast<unsigned char>(c + (b[i] == d));
    total += c;
    b += m;
  }
  return total;
}

// Blank (only spaces, tabs, CRs and quotes) or a comment ('#' first).
inline bool skipLine(const char* b, const char* e) {
  if (b == e) return true;
  if (*b == '#') return true;
  for (const char* p = b; p < e; ++p)
    if (!isTrim(*p)) return false;
  return true;
}
}  // namespace

void CsvReader::readHeader() {
  const char *b = nullptr, *e = nullptr;
  bool found = false;
  while (nextLine(&b, &e)) {
    if (skipLine(b, e)) continue;
    found = true;
    break;
  }
  if (!found) throw Error(fmt::format("{}: empty CSV (no header line)", source_));
  header_line_ = lineno_;
  const std::string header(b, e);
  char d = opt_.delimiter;
  if (d == 0) {
    d = ',';
    if (header.find(',') == std::string::npos) {
      if (header.find(';') != std::string::npos)
        d = ';';
      else if (header.find('\t') != std::string::npos)
        d = '\t';
    }
  }
  delim_ = d;
  columns_ = split(header, d);
  for (std::size_t i = 0; i < columns_.size(); ++i) {
    if (columns_[i].empty())
      throw Error(fmt::format("{}:{}: column {} has an empty name", source_, lineno_, i + 1));
    for (std::size_t j = 0; j < i; ++j)
      if (columns_[j] == columns_[i])
        throw Error(fmt::format("{}:{}: duplicate column '{}'", source_, lineno_, columns_[i]));
  }
  not_numeric_.assign(columns_.size(), std::string());
  std::vector<int> all(columns_.size());
  for (std::size_t c = 0; c < all.size(); ++c) all[c] = static_cast<int>(c);
  select(all);
}

void CsvReader::select(const std::vector<int>& columns) {
  slot_.assign(columns_.size(), -1);
  for (std::size_t k = 0; k < columns.size(); ++k) {
    const int c = columns[k];
    check(c >= 0 && static_cast<std::size_t>(c) < columns_.size() &&
              slot_[static_cast<std::size_t>(c)] < 0,
          fmt::format("{}: CSV reader: column index {} is out of range or repeated", source_, c));
    slot_[static_cast<std::size_t>(c)] = static_cast<int>(k);
  }
  sel_ = columns;
  // the cells after the last selected column are only counted (one pass over the rest of the
  // line), never split one by one
  cells_read_ = 0;
  for (int c : columns)
    cells_read_ = std::max<std::size_t>(cells_read_, static_cast<std::size_t>(c) + 1);
}

// Throws when the line (cell c ends at ce, the line at e) does not hold one value per column.
void CsvReader::countValues(std::size_t c, const char* ce, const char* e) const {
  std::size_t found = c + 1;
  found += countByte(ce, e, delim_);
  if (found != columns_.size())
    throw Error(fmt::format("{}:{}: expected {} values (as in the header), found {}", source_,
                            lineno_, columns_.size(), found));
}

bool CsvReader::next(double* values) {
  const std::size_t nc = columns_.size();
  // (a delimiter that no number holds ends one: the fast path of the cells below)
  const bool number_delim = (static_cast<unsigned>(delim_ - '0') >= 10u) && delim_ != '.' &&
                            delim_ != '+' && delim_ != '-' && delim_ != 'e' && delim_ != 'E';
  const char *b = nullptr, *e = nullptr;
  while (nextLine(&b, &e)) {
    if (skipLine(b, e)) continue;
    // Cells: nc - 1 delimiters, each cell's bytes found once.
    const char* cell = b;
    std::size_t c = 0;
    bool bad = false;
    std::string bad_msg;
    while (true) {
      if (c >= cells_read_) {  // the rest: counted, not read
        c += 1 + countByte(cell, e, delim_);
        break;
      }
      if (number_delim && c < nc && slot_[c] >= 0) {
        // A selected cell that is a short decimal up to the delimiter or the line's end: its
        // value and its end at once (what the general path below gives it, without finding
        // the delimiter first); anything else takes that path.
        double v = 0;
        if (const char* end = shortDecimalPrefix(cell, e, delim_, &v)) {
          values[slot_[c]] = v;
          ++c;
          if (end == e) break;
          cell = end + 1;
          continue;
        }
      }
      const char* stop =
          static_cast<const char*>(std::memchr(cell, delim_, static_cast<std::size_t>(e - cell)));
      const char* ce = stop ? stop : e;
      if (c < nc) {
        const int k = slot_[c];
        if (k >= 0) {
          const char* a = cell;
          const char* z = ce;
          while (a < z && isTrim(*a)) ++a;
          while (z > a && isTrim(z[-1])) --z;
          double v = std::nan("");
          bool number = true;
          std::size_t used = 0;
          if (a != z && !parseCsvNumber(a, z, &v, &used)) {
            // the count of values first, as before: the whole line was split before any cell
            countValues(c, ce, e);
            std::string msg = notANumber(source_, lineno_, static_cast<std::size_t>(a - b),
                                         columns_[c], std::string(a, z), used);
            if (!opt_.text_columns) throw Error(msg);
            if (not_numeric_[c].empty()) not_numeric_[c] = std::move(msg);
            v = std::nan("");
            number = false;
          }
          if (number && !std::isfinite(v) && !opt_.allow_non_finite) {
            if (!bad) {
              countValues(c, ce, e);
              bad_msg = fmt::format(
                  "{}:{}: column '{}': {} value", source_, lineno_, columns_[c],
                  a == z ? std::string("missing") : "non-finite (" + std::string(a, z) + ")");
            }
            bad = true;
          }
          values[k] = v;
        }
      }
      ++c;
      if (!stop) break;
      cell = stop + 1;
    }
    if (c != nc)
      throw Error(fmt::format("{}:{}: expected {} values (as in the header), found {}", source_,
                              lineno_, nc, c));
    if (bad) {
      if (opt_.drop_non_finite_rows) {
        ++dropped_;
        continue;
      }
      throw Error(bad_msg + " (set drop_bad_rows to drop such rows)");
    }
    line_ = lineno_;
    return true;
  }
  return false;
}

int CsvReader::takeRows(int count, std::string* out, int* line_before) {
  *line_before = lineno_;
  // room for the lines at the mean length of those read so far (and a tenth more): the text is
  // copied once, not again each time the string's capacity doubles
  if (count > 0 && lineno_ > 0) {
    const std::uint64_t mean = bytes_ / static_cast<std::uint64_t>(lineno_);
    out->reserve(out->size() +
                 static_cast<std::size_t>(mean + mean / 10 + 1) * static_cast<std::size_t>(count));
  }
  int taken = 0;
  const char *b = nullptr, *e = nullptr;
  while (taken < count && nextLine(&b, &e)) {
    // the line as it is in the file (its '\r' kept), then '\n'
    const char* end = e;
    if (end < end_ && *end == '\r') ++end;
    out->append(b, static_cast<std::size_t>(end - b));
    out->push_back('\n');
    if (!skipLine(b, e)) ++taken;
  }
  return taken;
}

int CsvReader::skipRows(int count) {
  int skipped = 0;
  const char *b = nullptr, *e = nullptr;
  while (skipped < count && nextLine(&b, &e))
    if (!skipLine(b, e)) ++skipped;
  return skipped;
}

CsvTable readCsvTable(CsvReader& reader, const std::vector<int>& columns, bool all) {
  CsvTable t;
  t.columns = reader.columns();
  if (!all) {
    reader.select(columns);
    t.slot.assign(t.columns.size(), -1);
    for (std::size_t k = 0; k < columns.size(); ++k)
      t.slot[static_cast<std::size_t>(columns[k])] = static_cast<int>(k);
  }
  const std::size_t nc = reader.selected().size();
  // Rows in chunks (row-major), copied into the matrix at the end chunk by chunk, each unmapped
  // once copied: the numbers are held about once, never as one vector that doubles. Each chunk
  // has pages of its own (mmap): malloc would keep freed chunks in its heap once its mmap
  // threshold has risen, and the process would hold the numbers twice. MAP_POPULATE: the pages
  // of a chunk are mapped at once, not one fault at a time (a third of readCsv's time).
  constexpr std::size_t kChunkRows = 16384;
  const std::size_t chunk_bytes = std::max<std::size_t>(1, kChunkRows * nc * sizeof(double));
  struct Chunks {
    std::vector<double*> list;
    std::size_t bytes = 0;
    ~Chunks() {
      for (double* p : list)
        if (p) ::munmap(p, bytes);
    }
  } chunks;
  chunks.bytes = chunk_bytes;
  std::size_t rows = 0;
  while (true) {
    if (rows % kChunkRows == 0) {
      void* p = ::mmap(nullptr, chunk_bytes, PROT_READ | PROT_WRITE,
                       MAP_PRIVATE | MAP_ANONYMOUS | MAP_POPULATE, -1, 0);
      if (p == MAP_FAILED) throw std::bad_alloc();
      chunks.list.push_back(static_cast<double*>(p));
    }
    if (!reader.next(chunks.list.back() + (rows % kChunkRows) * nc)) break;
    t.line_of.push_back(reader.line());
    ++rows;
  }
  t.data.resize(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(nc));
  for (std::size_t k = 0; k < chunks.list.size(); ++k) {
    const std::size_t r0 = k * kChunkRows;
    const std::size_t n = std::min(kChunkRows, rows - std::min(rows, r0));
    const double* ch = chunks.list[k];
    for (std::size_t c = 0; c < nc; ++c) {  // down each column of the matrix (column-major)
      double* out = t.data.col(static_cast<Eigen::Index>(c)).data() + r0;
      for (std::size_t r = 0; r < n; ++r) out[r] = ch[r * nc + c];
    }
    ::munmap(chunks.list[k], chunk_bytes);
    chunks.list[k] = nullptr;
  }
  t.not_numeric = reader.notNumeric();
  return t;
}

CsvTable parseCsv(const std::string& text, const std::string& source, const CsvReadOptions& opt,
                  int* dropped_rows) {
  CsvReader reader(std::string_view(text), source, opt);
  CsvTable t = readCsvTable(reader, {}, true);
  if (dropped_rows) *dropped_rows = reader.dropped();
  return t;
}

CsvTable readCsv(const fs::path& path, const CsvReadOptions& opt, int* dropped_rows) {
  CsvReader reader(path, opt);
  CsvTable t = readCsvTable(reader, {}, true);
  if (dropped_rows) *dropped_rows = reader.dropped();
  return t;
}

namespace {
// The header line, then each row's line, to `put`.
template <class Put>
void csvLines(const CsvTable& t, Put&& put) {
  std::string head;
  for (std::size_t i = 0; i < t.columns.size(); ++i) head += (i ? "," : "") + t.columns[i];
  head += '\n';
  put(std::string_view(head));
  fmt::memory_buffer buf;
  for (Eigen::Index r = 0; r < t.data.rows(); ++r) {
    buf.clear();
    for (Eigen::Index c = 0; c < t.data.cols(); ++c) {
      if (c) buf.push_back(',');
      fmt::format_to(std::back_inserter(buf), "{}", t.data(r, c));
    }
    buf.push_back('\n');
    put(std::string_view(buf.data(), buf.size()));
  }
}
}  // namespace

std::string toCsv(const CsvTable& t) {
  std::string out;
  csvLines(t, [&](std::string_view s) { out.append(s.data(), s.size()); });
  return out;
}

void writeCsv(AtomicFileWriter& out, const CsvTable& t) {
  csvLines(t, [&](std::string_view s) { out.write(s); });
}

void writeCsvAtomic(const fs::path& path, const CsvTable& t) {
  AtomicFileWriter out(path);
  writeCsv(out, t);
  out.commit();
}

}  // namespace exid
