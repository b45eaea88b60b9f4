#include "exid/io.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "exid/error.hpp"

namespace exid {

namespace fs = std::filesystem;

bool IoError::outOfSpace() const {
  return errno_value == ENOSPC || errno_value == EDQUOT || errno_value == EFBIG;
}

void writeFileAtomic(const fs::path& path, const std::string& text) {
  std::error_code ec;
  if (path.has_parent_path()) fs::create_directories(path.parent_path(), ec);
  const fs::path tmp = path.string() + fmt::format(".tmp.{}", ::getpid());
  int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    const int err = errno;
    throw IoError(fmt::format("{}: cannot write: {}", path.string(), std::strerror(err)), err);
  }
  std::size_t done = 0;
  while (done < text.size()) {
    ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      int err = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      throw IoError(fmt::format("{}: write failed: {}", path.string(), std::strerror(err)), err);
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    int err = errno;
    ::unlink(tmp.c_str());
    throw IoError(fmt::format("{}: write failed: {}", path.string(), std::strerror(err)), err);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    int err = errno;
    ::unlink(tmp.c_str());
    throw Error(fmt::format("{}: cannot rename into place: {}", path.string(), std::strerror(err)));
  }
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

CsvTable parseCsv(const std::string& text, const std::string& source, const CsvReadOptions& opt,
                  int* dropped_rows) {
  std::istringstream in(text);
  std::string line;
  int lineno = 0;
  // Header: first non-empty line that is not a comment.
  std::string header;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (trim(line).empty() || line[0] == '#') continue;
    header = line;
    break;
  }
  if (header.empty()) throw Error(fmt::format("{}: empty CSV (no header line)", source));
  char d = opt.delimiter;
  if (d == 0) {
    d = ',';
    if (header.find(',') == std::string::npos) {
      if (header.find(';') != std::string::npos)
        d = ';';
      else if (header.find('\t') != std::string::npos)
        d = '\t';
    }
  }
  CsvTable t;
  t.columns = split(header, d);
  for (std::size_t i = 0; i < t.columns.size(); ++i) {
    if (t.columns[i].empty())
      throw Error(fmt::format("{}:{}: column {} has an empty name", source, lineno, i + 1));
    for (std::size_t j = 0; j < i; ++j)
      if (t.columns[j] == t.columns[i])
        throw Error(fmt::format("{}:{}: duplicate column '{}'", source, lineno, t.columns[i]));
  }
  const std::size_t nc = t.columns.size();
  t.not_numeric.assign(nc, std::string());
  std::vector<double> values;
  std::size_t rows = 0;
  int dropped = 0;
  std::vector<double> row(nc);
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (trim(line).empty() || line[0] == '#') continue;
    std::vector<std::size_t> starts;
    auto cells = split(line, d, &starts);
    if (cells.size() != nc)
      throw Error(fmt::format("{}:{}: expected {} values (as in the header), found {}", source,
                              lineno, nc, cells.size()));
    bool bad = false;
    std::string bad_msg;
    for (std::size_t c = 0; c < nc; ++c) {
      const std::string& s = cells[c];
      char* end = nullptr;
      double v = s.empty() ? std::nan("") : std::strtod(s.c_str(), &end);
      // The whole cell must be the number: a NUL or any other byte after it (strtod stops
      // there; the NUL looked like the end of the text) is an error at its column.
      const std::size_t used = s.empty() ? 0 : static_cast<std::size_t>(end - s.c_str());
      if (!s.empty() && (used == 0 || used != s.size())) {
        const unsigned char b = static_cast<unsigned char>(s[used == 0 ? 0 : used]);
        std::string msg =
            fmt::format("{}:{}:{}: column '{}': '{}' is not a number ({} at column {})", source,
                        lineno, starts[c] + used + 1, t.columns[c], printable(s),
                        b >= 0x20 && b < 0x7f ? fmt::format("unexpected '{}'", static_cast<char>(b))
                                              : fmt::format("unexpected byte 0x{:02X}", b),
                        starts[c] + used + 1);
        if (!opt.text_columns) throw Error(msg);
        if (t.not_numeric[c].empty()) t.not_numeric[c] = std::move(msg);
        row[c] = std::nan("");
        continue;
      }
      if (!std::isfinite(v) && !opt.allow_non_finite) {
        bad = true;
        if (bad_msg.empty())
          bad_msg = fmt::format("{}:{}: column '{}': {} value", source, lineno, t.columns[c],
                                s.empty() ? "missing" : "non-finite (" + s + ")");
      }
      row[c] = v;
    }
    if (bad) {
      if (opt.drop_non_finite_rows) {
        ++dropped;
        continue;
      }
      throw Error(bad_msg + " (set drop_bad_rows to drop such rows)");
    }
    values.insert(values.end(), row.begin(), row.end());
    ++rows;
  }
  t.data.resize(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(nc));
  for (std::size_t r = 0; r < rows; ++r)
    for (std::size_t c = 0; c < nc; ++c)
      t.data(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) = values[r * nc + c];
  if (dropped_rows) *dropped_rows = dropped;
  return t;
}

CsvTable readCsv(const fs::path& path, const CsvReadOptions& opt, int* dropped_rows) {
  return parseCsv(readInputFile(path, "CSV", kMaxDataFileBytes), path.string(), opt, dropped_rows);
}

std::string toCsv(const CsvTable& t) {
  std::string out;
  for (std::size_t i = 0; i < t.columns.size(); ++i) out += (i ? "," : "") + t.columns[i];
  out += '\n';
  fmt::memory_buffer buf;
  for (Eigen::Index r = 0; r < t.data.rows(); ++r) {
    buf.clear();
    for (Eigen::Index c = 0; c < t.data.cols(); ++c) {
      if (c) buf.push_back(',');
      fmt::format_to(std::back_inserter(buf), "{}", t.data(r, c));
    }
    buf.push_back('\n');
    out.append(buf.data(), buf.size());
  }
  return out;
}

void writeCsvAtomic(const fs::path& path, const CsvTable& t) { writeFileAtomic(path, toCsv(t)); }

}  // namespace exid
