// The streaming CSV reader (exid::CsvReader): the same tables, line numbers and error messages
// as the whole-text parser it replaced (re-implemented below as the reference), whatever the
// block size (a line straddling blocks), from memory or from a file; from_chars reads the same
// doubles as strtod; only the selected columns are converted.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/io.hpp"

namespace fs = std::filesystem;

namespace {

// ---- The reference: parseCsv as it was before the streaming reader (getline, split, strtod).
namespace ref {
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
    if (starts) {
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
exid::CsvTable parse(const std::string& text, const std::string& source,
                     const exid::CsvReadOptions& opt, int* dropped_rows) {
  std::istringstream in(text);
  std::string line;
  int lineno = 0;
  std::string header;
  while (std::getline(in, line)) {
    ++lineno;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (trim(line).empty() || line[0] == '#') continue;
    header = line;
    break;
  }
  if (header.empty()) throw exid::Error(fmt::format("{}: empty CSV (no header line)", source));
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
  exid::CsvTable t;
  t.columns = split(header, d);
  for (std::size_t i = 0; i < t.columns.size(); ++i) {
    if (t.columns[i].empty())
      throw exid::Error(fmt::format("{}:{}: column {} has an empty name", source, lineno, i + 1));
    for (std::size_t j = 0; j < i; ++j)
      if (t.columns[j] == t.columns[i])
        throw exid::Error(
            fmt::format("{}:{}: duplicate column '{}'", source, lineno, t.columns[i]));
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
      throw exid::Error(fmt::format("{}:{}: expected {} values (as in the header), found {}",
                                    source, lineno, nc, cells.size()));
    bool bad = false;
    std::string bad_msg;
    for (std::size_t c = 0; c < nc; ++c) {
      const std::string& s = cells[c];
      char* end = nullptr;
      double v = s.empty() ? std::nan("") : std::strtod(s.c_str(), &end);
      const std::size_t used = s.empty() ? 0 : static_cast<std::size_t>(end - s.c_str());
      if (!s.empty() && (used == 0 || used != s.size())) {
        const unsigned char b = static_cast<unsigned char>(s[used == 0 ? 0 : used]);
        std::string msg =
            fmt::format("{}:{}:{}: column '{}': '{}' is not a number ({} at column {})", source,
                        lineno, starts[c] + used + 1, t.columns[c], printable(s),
                        b >= 0x20 && b < 0x7f ? fmt::format("unexpected '{}'", static_cast<char>(b))
                                              : fmt::format("unexpected byte 0x{:02X}", b),
                        starts[c] + used + 1);
        if (!opt.text_columns) throw exid::Error(msg);
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
      throw exid::Error(bad_msg + " (set drop_bad_rows to drop such rows)");
    }
    values.insert(values.end(), row.begin(), row.end());
    t.line_of.push_back(lineno);
    ++rows;
  }
  t.data.resize(static_cast<Eigen::Index>(rows), static_cast<Eigen::Index>(nc));
  for (std::size_t r = 0; r < rows; ++r)
    for (std::size_t c = 0; c < nc; ++c)
      t.data(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) = values[r * nc + c];
  if (dropped_rows) *dropped_rows = dropped;
  return t;
}
}  // namespace ref

// The outcome of a parse, comparable bit for bit: the error, or the table.
struct Outcome {
  std::string error;
  exid::CsvTable table;
  int dropped = -1;
};

template <class F>
Outcome outcomeOf(F&& f) {
  Outcome o;
  try {
    o.table = f(&o.dropped);
  } catch (const exid::Error& e) {
    o.error = e.what();
  }
  return o;
}

std::uint64_t bits(double v) {
  std::uint64_t u = 0;
  std::memcpy(&u, &v, sizeof u);
  return u;
}

// "" when equal, else the first difference.
std::string difference(const Outcome& a, const Outcome& b) {
  if (a.error != b.error) return "error '" + a.error + "' vs '" + b.error + "'";
  if (!a.error.empty()) return "";
  if (a.dropped != b.dropped) return fmt::format("dropped {} vs {}", a.dropped, b.dropped);
  const exid::CsvTable &x = a.table, &y = b.table;
  if (x.columns != y.columns) return "columns";
  if (x.not_numeric != y.not_numeric) return "not_numeric";
  if (x.line_of != y.line_of) return "line_of";
  if (x.data.rows() != y.data.rows() || x.data.cols() != y.data.cols())
    return fmt::format("shape {}x{} vs {}x{}", x.data.rows(), x.data.cols(), y.data.rows(),
                       y.data.cols());
  for (Eigen::Index r = 0; r < x.data.rows(); ++r)
    for (Eigen::Index c = 0; c < x.data.cols(); ++c)
      if (bits(x.data(r, c)) != bits(y.data(r, c)))
        return fmt::format("value at row {} column {}: {} vs {}", r, c, x.data(r, c), y.data(r, c));
  return "";
}

std::vector<exid::CsvReadOptions> allOptions() {
  std::vector<exid::CsvReadOptions> v;
  for (int m = 0; m < 8; ++m) {
    exid::CsvReadOptions o;
    o.allow_non_finite = m & 1;
    o.drop_non_finite_rows = m & 2;
    o.text_columns = m & 4;
    v.push_back(o);
  }
  return v;
}

exid::CsvTable readWithBlocks(const std::string& text, const exid::CsvReadOptions& o,
                              std::size_t block, int* dropped) {
  exid::CsvReader reader(std::string_view(text), "in.csv", o, block);
  exid::CsvTable t = exid::readCsvTable(reader, {}, true);
  *dropped = reader.dropped();
  return t;
}

fs::path tempDir() {
  fs::path d = fs::temp_directory_path() / ("exid_csv_reader_test_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

void writeFile(const fs::path& p, const std::string& s) {
  std::ofstream o(p, std::ios::binary | std::ios::trunc);
  o << s;
}

// Inputs that reach every branch: CRLF, comments, quotes, blank lines, delimiters, bad cells.
std::vector<std::string> trickyInputs() {
  std::vector<std::string> v = {
      "t,q1\n0,1\n0.1,2\n",
      "t,q1\r\n0,1\r\n0.1,2\r\n",
      "t,q1\r\n0,1\r\n0.1,2",  // no newline at the end
      "# recorded by a logger\n\n  \n\"\"\n\"t\",\"q1\"\n# a comment\n\"0\", \"1.5\"\n\n 0.1 "
      ",\t2\n",
      "t;q1;q2\n0;1;2\n0.1;+3;-4\n",
      "t\tq1\n0\t1\n0.1\t2e-3\n",
      "t q1\n0 1\n",  // no delimiter found: one column "t q1"
      "t,q1\n0,1\n0.1,abc\n",
      "t,q1\n0,1\n0.1,nan\n0.2,3\n",
      "t,q1\n0,1\n0.1,\n0.2,3\n",
      "t,q1\n0,1,2\n",
      "t,q1\n0\n",
      "t,t\n0,1\n",
      "t,,q\n0,1,2\n",
      "",
      "\n\n# only comments\n",
      "t,q1\n",
      "t,q1\n0,1.5\n0.1,2" + std::string("\0", 1) + "5\n",
      "t,q1\n0,  1.5x\n",
      "t,q1\n0,\x01\n",
      "t,q1\n0,inf\n1,-inf\n2,NaN\n3,nan(7)\n4,1e400\n5,1e-400\n6,0x1p-3\n",
      "t,q1,label\n0,1,walk\n1,2,run\n2,3,\n",
      "t,q1,label\n0,1,walk,extra\n",
      "t,q1,label\n0,abc,1,2\n",  // a bad cell on a line with too many values: the count first
      "t,q1,label\n0,nan\n",      // a non-finite cell on a line with too few values
      "t,q1\n0,1\n  # not a comment (a space first)\n",
      "t,q1\n0,\v1\n1,1\v\n",
      "t,q1\n0,+-1\n",
      "t,q1\n0,4.9406564584124654e-324\n1,2.2250738585072011e-308\n2,0.1000000000000000055511\n",
      "t,q1\n\r\n\r\n0,1\r\n\r\n",
      "\xEF\xBB\xBFt,q1\n0,1\n",
      "t,q1\n0,1\r2\n",
      "t,q1\n0,\"1,5\"\n",
  };
  // Long lines, each straddling many tiny blocks.
  std::string wide = "t";
  for (int c = 1; c <= 40; ++c) wide += fmt::format(",q{}", c);
  wide += "\n";
  for (int r = 0; r < 20; ++r) {
    wide += fmt::format("{}", r * 0.01);
    for (int c = 1; c <= 40; ++c) wide += fmt::format(",{:.17g}", std::sin(r * 40 + c));
    wide += r % 3 ? "\n" : "\r\n";
  }
  v.push_back(wide);
  return v;
}

}  // namespace

// Every tricky input, every option set, every block size (a line straddling blocks of 1, 2, 3,
// 7 bytes): the same values, line numbers, dropped counts and error messages as the reference.
TEST(CsvReader, SameTablesAndErrorsAsTheWholeTextParserForEveryBlockSize) {
  const std::vector<std::string> inputs = trickyInputs();
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    const std::string& text = inputs[i];
    for (const exid::CsvReadOptions& o : allOptions()) {
      const std::string what =
          fmt::format("input {} (allow {} drop {} text {})", i, o.allow_non_finite,
                      o.drop_non_finite_rows, o.text_columns);
      const Outcome want = outcomeOf([&](int* dr) { return ref::parse(text, "in.csv", o, dr); });
      const Outcome got = outcomeOf([&](int* dr) { return exid::parseCsv(text, "in.csv", o, dr); });
      EXPECT_EQ(difference(want, got), "") << what << " (parseCsv)";
      for (std::size_t block : {1, 2, 3, 7, 64, 4096}) {
        const Outcome b = outcomeOf([&](int* dr) { return readWithBlocks(text, o, block, dr); });
        EXPECT_EQ(difference(want, b), "") << what << ", blocks of " << block;
      }
    }
  }
}

// Random lines built from tricky pieces: the streaming reader and the reference agree.
TEST(CsvReader, RandomInputsAgreeWithTheReference) {
  std::mt19937 rng(12345);
  const std::vector<std::string> cells = {
      "0", "1.5", " 2 ", "\"3\"", "+4", "-5e-3", "", "nan", "inf", "x", "1x", "\t7\t", "0x10",
      "1e400", "1e-400", "-0", "9.999999999999999e22", "\"\"",
      // (cells that end or do not end a short decimal at the delimiter)
      "1e", "1e+", "1.", ".", "-", "-.5", "+.5e+2", "12345678.87654321", "-0.674940672", "1e5",
      "1.5 ", "1.5\""};
  const std::vector<std::string> ends = {"\n", "\r\n", "\n\n", "\n# note\n", "\n \n"};
  for (int trial = 0; trial < 300; ++trial) {
    const int nc = 1 + static_cast<int>(rng() % 4);
    const char d = ",;\t"[rng() % 3];
    std::string text = trial % 5 == 0 ? "# header follows\n" : "";
    for (int c = 0; c < nc; ++c) text += (c ? std::string(1, d) : "") + fmt::format("c{}", c);
    text += ends[rng() % ends.size()];
    const int rows = static_cast<int>(rng() % 12);
    for (int r = 0; r < rows; ++r) {
      int n = nc;
      if (rng() % 40 == 0) n += rng() % 2 ? 1 : -1;
      for (int c = 0; c < n; ++c)
        text += (c ? std::string(1, d) : "") +
                (rng() % 4
                     ? fmt::format("{:.17g}", std::ldexp(double(rng()) - 2e9, int(rng() % 40) - 20))
                     : cells[rng() % cells.size()]);
      if (r + 1 < rows || rng() % 2) text += ends[rng() % ends.size()];
    }
    for (const exid::CsvReadOptions& o : allOptions()) {
      const Outcome want = outcomeOf([&](int* dr) { return ref::parse(text, "r.csv", o, dr); });
      const Outcome got = outcomeOf([&](int* dr) { return exid::parseCsv(text, "r.csv", o, dr); });
      ASSERT_EQ(difference(want, got), "") << text;
      const std::size_t block = 1 + rng() % 9;
      const Outcome b = outcomeOf([&](int* dr) {
        exid::CsvReader reader(std::string_view(text), "r.csv", o, block);
        exid::CsvTable t = exid::readCsvTable(reader, {}, true);
        *dr = reader.dropped();
        return t;
      });
      ASSERT_EQ(difference(want, b), "") << text << " (blocks of " << block << ")";
    }
  }
}

// std::from_chars (the fast path) and strtod (the reference) read the same doubles, bit for
// bit, and refuse the same cells.
TEST(CsvReader, FromCharsReadsTheSameDoublesAsStrtod) {
  std::vector<std::string> numbers = {
      "0", "-0", "+0", "1", "+1.5", "-1.5", "0.1", "0.30000000000000004", ".5", "5.", "1e5", "1E5",
      "1e+5", "+1e-5", "1e308", "1.7976931348623157e308", "1.7976931348623159e308",
      "2.2250738585072011e-308", "2.2250738585072014e-308", "4.9406564584124654e-324",
      "2.4703282292062327e-324", "2.4703282292062328e-324", "1e-320", "1e-400", "1e400",
      "123456789012345678901234567890", "9007199254740993", "0.1000000000000000055511151231257827",
      "1.00000000000000011102230246251565404236316680908203125", "00012.50", "000", "0e0",
      "3.14159265358979323846264338327950288", "6.02214076e23", "-1.602176634e-19", "nan", "NaN",
      "-nan", "+nan", "nan(123)", "inf", "-Infinity", "+inf", "INF", "infinit", "0x1p3", "0X1P-2",
      "0x", "+", "-", ".", "e5", "1e", "1e+", "1.2.3", "+-1", "-+1", "++1", "1 2", "\v1", "1\v",
      "\f2", "1_000", "1,5", "1d5", "0b101", "1e5x", "١",
      // around the exact short-decimal path's bounds
      "9007199254740992", "9007199254740991.5", "900719925474099.3", "1e22", "1e23", "1e-22",
      "1e-23", "123456789012345e-22", "4.5e22", "-0.000", "-0e5", "0.0000000000000000000001",
      "1.e3", ".e3", "1e-", "-.5", "+.5e+2", "1e0000000000000000000000000000000000001",
      // eight digits at a time: whole groups, a non-digit inside a group, past the exact range
      "12345678", "12345678.87654321", "1234567.12345678", "0.12345678", "-0.674940672", "1234567a",
      "1234567.8", "123456789012345678", "90071992547409.92", "9007199.254740993",
      "00000000000000001", "0.000000001234567890123", "12345678e-3", "1234567890123456e5",
      "99999999.99999999", "1234567\x80", "12345678/", "12345678:"};
  std::mt19937_64 rng(7);
  for (int i = 0; i < 20000; ++i) {
    std::uint64_t u = rng();
    double v = 0;
    std::memcpy(&v, &u, sizeof v);
    if (!std::isfinite(v)) continue;
    const char* fmts[] = {"%.17g", "%.16g", "%.15g", "%.6e", "%+.17g", "%.25g"};
    char buf[64];
    std::snprintf(buf, sizeof buf, fmts[i % 6], v);
    numbers.push_back(buf);
    std::snprintf(buf, sizeof buf, "%.17g", double(rng() % 1000000) / 1000.0);  // typical data
    numbers.push_back(buf);
    // as recorders and exid write them: few digits, fixed or scientific
    const double x = std::ldexp(static_cast<double>(rng() % 100000000) - 5e7, -int(rng() % 40));
    const char* short_fmts[] = {"%.3f", "%.9g", "%.7g", "%.6e", "%.15g", "%.12f"};
    std::snprintf(buf, sizeof buf, short_fmts[i % 6], x);
    numbers.push_back(buf);
  }
  for (const std::string& s : numbers) {
    char* end = nullptr;
    const double want = std::strtod(s.c_str(), &end);
    const std::size_t want_used = static_cast<std::size_t>(end - s.c_str());
    const bool want_ok = want_used != 0 && want_used == s.size();
    double got = 0;
    std::size_t used = 0;
    const bool ok = exid::parseCsvNumber(s.data(), s.data() + s.size(), &got, &used);
    ASSERT_EQ(ok, want_ok) << "'" << s << "'";
    if (ok)
      ASSERT_EQ(bits(got), bits(want)) << "'" << s << "': " << got << " vs " << want;
    else
      ASSERT_EQ(used, want_used) << "'" << s << "'";
  }
}

// A file of several MB read from disk in blocks of 1 MB (and of 4093 bytes: lines straddle
// every block): the table of the whole-text parse, line numbers included.
TEST(CsvReader, ManyBlockFileReadsAsTheWholeText) {
  std::string text = "# exid test\nt,q1,q2,q3,q4,q5,q6,tau1,tau2,tau3,tau4,tau5,tau6\n";
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  for (int r = 0; text.size() < (std::size_t{5} << 20); ++r) {
    text += fmt::format("{:.6f}", r * 0.001);
    for (int c = 0; c < 12; ++c) text += fmt::format(",{:.17g}", u(rng));
    text += r % 1000 == 999 ? "\r\n# a comment line\n" : "\n";
  }
  const fs::path d = tempDir();
  writeFile(d / "big.csv", text);
  const exid::CsvTable want = exid::parseCsv(text, (d / "big.csv").string());
  ASSERT_GT(want.data.rows(), 20000);
  Outcome w;
  w.table = want;
  w.dropped = 0;
  for (std::size_t block : {exid::CsvReader::kDefaultBlockBytes, std::size_t{4093}}) {
    const Outcome got = outcomeOf([&](int* dr) {
      exid::CsvReader reader(d / "big.csv", {}, "CSV", block);
      exid::CsvTable t = exid::readCsvTable(reader, {}, true);
      *dr = reader.dropped();
      EXPECT_EQ(reader.bytesRead(), text.size());
      return t;
    });
    EXPECT_EQ(difference(w, got), "") << "blocks of " << block;
  }
  const Outcome viaReadCsv =
      outcomeOf([&](int* dr) { return exid::readCsv(d / "big.csv", {}, dr); });
  EXPECT_EQ(difference(w, viaReadCsv), "");
  EXPECT_EQ(want.line_of.front(), 3);
  fs::remove_all(d);
}

// Only the selected columns are converted: text in the others is no error, and the table says
// where each selected column is.
TEST(CsvReader, UnselectedColumnsAreNeverConverted) {
  const std::string text = "t,label,q1,note\n0,walk,1.5,\n# c\n0.1,run,2.5,x y z\n";
  exid::CsvReader reader(std::string_view(text), "s.csv", {}, 3);
  EXPECT_EQ(reader.columns(), (std::vector<std::string>{"t", "label", "q1", "note"}));
  const exid::CsvTable t =
      exid::readCsvColumns(reader, [](const std::string& c) { return c == "q1" || c == "t"; });
  ASSERT_EQ(t.data.cols(), 2);
  ASSERT_EQ(t.data.rows(), 2);
  EXPECT_EQ(t.dataCol(0), 0);
  EXPECT_EQ(t.dataCol(1), -1);
  EXPECT_EQ(t.dataCol(2), 1);
  EXPECT_EQ(t.dataCol(3), -1);
  EXPECT_EQ(t.data(1, t.dataCol(t.col("q1"))), 2.5);
  EXPECT_EQ(t.data(1, t.dataCol(t.col("t"))), 0.1);
  EXPECT_EQ(t.line_of, (std::vector<int>{2, 4}));
  // The count of values is still checked on every line.
  const std::string short_line = "t,label,q1\n0,walk,1\n0.1,run\n";
  exid::CsvReader r2(std::string_view(short_line), "s.csv");
  std::string msg;
  try {
    exid::readCsvColumns(r2, [](const std::string& c) { return c == "t"; });
  } catch (const exid::Error& e) {
    msg = e.what();
  }
  EXPECT_EQ(msg, "s.csv:3: expected 3 values (as in the header), found 2");
}

// The cells after the last selected one are counted, not split: counts far above a byte's range
// (the counter is byte-wide per block of 255 bytes: a run of 699 delimiters) are exact, one value
// too many or too few is found on any line.
TEST(CsvReader, LongTailsOfUnselectedCellsAreCountedExactly) {
  const int nc = 700;
  std::string header = "t";
  for (int c = 1; c < nc; ++c) header += fmt::format(",c{}", c);
  auto line = [](int values) {  // empty unselected cells: a block of delimiters only
    return "0.5" + std::string(static_cast<std::size_t>(values - 1), ',');
  };
  for (int values : {nc, nc - 1, nc + 1, nc - 256, nc + 255}) {
    const std::string text = header + "\n" + line(nc) + "\n" + line(values) + "\n";
    exid::CsvReader r(std::string_view(text), "w.csv");
    std::string msg;
    try {
      const exid::CsvTable t =
          exid::readCsvColumns(r, [](const std::string& c) { return c == "t"; });
      EXPECT_EQ(t.data.rows(), 2);
      EXPECT_EQ(t.data(1, 0), 0.5);
    } catch (const exid::Error& e) {
      msg = e.what();
    }
    if (values == nc)
      EXPECT_EQ(msg, "") << values;
    else
      EXPECT_EQ(
          msg, fmt::format("w.csv:3: expected {} values (as in the header), found {}", nc, values));
  }
}

// A file: the checks of readInputFile (regular file, readable) without its size limit, and the
// reader's errors name the file as the caller calls it.
TEST(CsvReader, FileChecksAndMessages) {
  const fs::path d = tempDir();
  std::string msg;
  try {
    exid::CsvReader r(d, {}, "CSV data");
  } catch (const exid::Error& e) {
    msg = e.what();
  }
  EXPECT_NE(msg.find("the CSV data file is a directory"), std::string::npos) << msg;
  try {
    exid::CsvReader r(d / "absent.csv", {}, "CSV data");
  } catch (const exid::Error& e) {
    msg = e.what();
  }
  EXPECT_NE(msg.find("absent.csv: cannot open the CSV data file (no such file)"), std::string::npos)
      << msg;
  writeFile(d / "x.csv", "t,q1\n0,1\n0.1,oops\n");
  try {
    exid::readCsv(d / "x.csv");
  } catch (const exid::Error& e) {
    msg = e.what();
  }
  EXPECT_EQ(msg, (d / "x.csv").string() +
                     ":3:5: column 'q1': 'oops' is not a number (unexpected 'o' at column 5)");
  fs::remove_all(d);
}
