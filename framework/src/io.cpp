#include "exid/io.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "exid/error.hpp"

namespace exid {

namespace fs = std::filesystem;

void writeFileAtomic(const fs::path& path, const std::string& text) {
  std::error_code ec;
  if (path.has_parent_path()) fs::create_directories(path.parent_path(), ec);
  const fs::path tmp = path.string() + fmt::format(".tmp.{}", ::getpid());
  int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw Error(fmt::format("{}: cannot write: {}", path.string(), std::strerror(errno)));
  std::size_t done = 0;
  while (done < text.size()) {
    ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      int err = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      throw Error(fmt::format("{}: write failed: {}", path.string(), std::strerror(err)));
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    int err = errno;
    ::unlink(tmp.c_str());
    throw Error(fmt::format("{}: write failed: {}", path.string(), std::strerror(err)));
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    int err = errno;
    ::unlink(tmp.c_str());
    throw Error(fmt::format("{}: cannot rename into place: {}", path.string(), std::strerror(err)));
  }
}

int CsvTable::col(const std::string& name) const {
  for (std::size_t i = 0; i < columns.size(); ++i)
    if (columns[i] == name) return static_cast<int>(i);
  return -1;
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
std::vector<std::string> split(const std::string& line, char d) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : line) {
    if (c == d) {
      out.push_back(trim(cur));
      cur.clear();
    } else {
      cur += c;
    }
  }
  out.push_back(trim(cur));
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
  std::vector<double> values;
  std::size_t rows = 0;
  int dropped = 0;
  std::vector<double> row(nc);
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (trim(line).empty() || line[0] == '#') continue;
    auto cells = split(line, d);
    if (cells.size() != nc)
      throw Error(fmt::format("{}:{}: expected {} values (as in the header), found {}", source,
                              lineno, nc, cells.size()));
    bool bad = false;
    std::string bad_msg;
    for (std::size_t c = 0; c < nc; ++c) {
      const std::string& s = cells[c];
      char* end = nullptr;
      double v = s.empty() ? std::nan("") : std::strtod(s.c_str(), &end);
      if (!s.empty() && (end == s.c_str() || *end != '\0'))
        throw Error(fmt::format("{}:{}: column '{}': '{}' is not a number", source, lineno,
                                t.columns[c], s));
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
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(fmt::format("{}: cannot open ({})", path.string(), std::strerror(errno)));
  std::stringstream ss;
  ss << in.rdbuf();
  return parseCsv(ss.str(), path.string(), opt, dropped_rows);
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
