// The data layer's files (exid/io.hpp): atomic writes, CSV with errors that name
// file/line/column, input files that are not regular files.
#include "exid/io.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>

#include "exid/error.hpp"

namespace fs = std::filesystem;

namespace {
std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "";
}
fs::path tempDir() {
  fs::path d = fs::temp_directory_path() / ("exid_io_test_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}
}  // namespace

TEST(AtomicWrite, ReplacesWholeFileAndLeavesNoTemporary) {
  fs::path d = tempDir();
  exid::writeFileAtomic(d / "a.txt", "first");
  exid::writeFileAtomic(d / "a.txt", "second");
  std::ifstream in(d / "a.txt");
  std::string s((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(s, "second");
  int files = 0;
  for (auto& e : fs::directory_iterator(d)) files += e.is_regular_file();
  EXPECT_EQ(files, 1);
  fs::remove_all(d);
}

// Piece by piece: small and large pieces (beside and beyond its 1 MB buffer) give exactly their
// concatenation; nothing is at the path before the commit; a writer destroyed without a commit
// (an exception on the way) leaves the old file and no temporary; toCsv and writeCsv agree.
TEST(AtomicWrite, PieceByPieceIsTheConcatenationAndAnUncommittedWriterLeavesNothing) {
  const fs::path d = tempDir() / "pieces";
  fs::remove_all(d);
  std::string expect;
  {
    exid::AtomicFileWriter out(d / "p.txt");
    for (std::size_t n : {1u, 1000u, (1u << 20) - 5u, 7u, (3u << 20) + 11u, 0u, 12345u}) {
      const std::string piece(n, static_cast<char>('a' + n % 26));
      out.write(piece);
      expect += piece;
    }
    EXPECT_FALSE(fs::exists(d / "p.txt"));
    out.commit();
    EXPECT_THROW(out.write("x"), exid::Error);
  }
  std::ifstream in(d / "p.txt", std::ios::binary);
  const std::string got((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(got.size(), expect.size());
  EXPECT_TRUE(got == expect);
  exid::writeFileAtomic(d / "keep.txt", "old");
  try {
    exid::AtomicFileWriter out(d / "keep.txt");
    out.write(std::string(3u << 20, 'n'));
    throw std::runtime_error("on the way");
  } catch (const std::runtime_error&) {
  }
  std::ifstream keep(d / "keep.txt");
  EXPECT_EQ(std::string((std::istreambuf_iterator<char>(keep)), std::istreambuf_iterator<char>()),
            "old");
  for (const auto& e : fs::directory_iterator(d))
    EXPECT_EQ(e.path().string().find(".tmp."), std::string::npos) << e.path();
  exid::CsvTable t;
  t.columns = {"t", "q1"};
  t.data.resize(3, 2);
  t.data << 0.0, 0.1, 0.001, 1.0 / 3.0, 0.002, -2.5e-17;
  exid::writeCsvAtomic(d / "t.csv", t);
  std::ifstream tc(d / "t.csv");
  EXPECT_EQ(std::string((std::istreambuf_iterator<char>(tc)), std::istreambuf_iterator<char>()),
            exid::toCsv(t));
  fs::remove_all(d);
}

TEST(AtomicWrite, FailureLeavesTheOldFileAndNamesThePath) {
  if (::geteuid() == 0) {
    // root ignores directory permissions; use a path whose parent is a file instead
    fs::path d = tempDir();
    exid::writeFileAtomic(d / "plain", "x");
    std::string msg = errorOf([&] { exid::writeFileAtomic(d / "plain" / "child.txt", "y"); });
    EXPECT_NE(msg.find("child.txt"), std::string::npos) << msg;
    fs::remove_all(d);
    return;
  }
  fs::path d = tempDir();
  exid::writeFileAtomic(d / "keep.txt", "old");
  ::chmod(d.c_str(), 0500);
  std::string msg = errorOf([&] { exid::writeFileAtomic(d / "keep.txt", "new"); });
  ::chmod(d.c_str(), 0700);
  EXPECT_NE(msg.find("keep.txt"), std::string::npos) << msg;
  std::ifstream in(d / "keep.txt");
  std::string s((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(s, "old");
  fs::remove_all(d);
}

TEST(AtomicWrite, UnwritableTargetIsReportedAndNothingIsLeft) {
  // A target that cannot be created: the error names it and nothing is left behind.
  std::string msg =
      errorOf([&] { exid::writeFileAtomic("/proc/exid_cannot_write_here.txt", "data"); });
  EXPECT_NE(msg.find("/proc/exid_cannot_write_here.txt"), std::string::npos) << msg;
  EXPECT_FALSE(fs::exists("/proc/exid_cannot_write_here.txt"));
}

TEST(Csv, RoundTripKeepsFullPrecision) {
  exid::CsvTable t;
  t.columns = {"t", "q1"};
  t.data.resize(2, 2);
  t.data << 0.1, 1.0 / 3.0, 0.2, -2e-17;
  exid::CsvTable back = exid::parseCsv(exid::toCsv(t), "mem.csv");
  EXPECT_EQ(back.columns, t.columns);
  EXPECT_EQ(back.data, t.data);
}

TEST(Csv, ErrorsNameFileLineAndColumn) {
  std::string msg = errorOf([] { exid::parseCsv("t,q1\n0,1\n0.1,abc\n", "run.csv"); });
  EXPECT_NE(msg.find("run.csv:3:5: column 'q1': 'abc' is not a number"), std::string::npos) << msg;
  msg = errorOf([] { exid::parseCsv("t,q1\n0,1\n0.1,nan\n", "run.csv"); });
  EXPECT_NE(msg.find("run.csv:3: column 'q1': non-finite (nan) value"), std::string::npos) << msg;
  msg = errorOf([] { exid::parseCsv("t,q1\n0,1\n0.1,\n", "run.csv"); });
  EXPECT_NE(msg.find("run.csv:3: column 'q1': missing value"), std::string::npos) << msg;
  msg = errorOf([] { exid::parseCsv("t,q1\n0,1,2\n", "run.csv"); });
  EXPECT_NE(msg.find("run.csv:2: expected 2 values"), std::string::npos) << msg;
  msg = errorOf([] { exid::parseCsv("t,t\n0,1\n", "run.csv"); });
  EXPECT_NE(msg.find("duplicate column 't'"), std::string::npos) << msg;
  msg = errorOf([] { exid::readCsv("/nonexistent/file.csv"); });
  EXPECT_NE(msg.find("/nonexistent/file.csv: cannot open"), std::string::npos) << msg;
}

TEST(Csv, DropsBadRowsWhenAskedAndCountsThem) {
  exid::CsvReadOptions o;
  o.drop_non_finite_rows = true;
  int dropped = 0;
  exid::CsvTable t = exid::parseCsv("t;q1\n0;1\n0.1;nan\n0.2;3\n", "x.csv", o, &dropped);
  EXPECT_EQ(dropped, 1);
  ASSERT_EQ(t.data.rows(), 2);
  EXPECT_EQ(t.data(1, 1), 3.0);
}

// A NUL (or any other byte) inside a number: strtod stopped at the NUL, which looked like the
// end of the text, and the number was silently truncated (issue 16). Now file:line:column.
TEST(Csv, NulOrStrayByteInsideANumberIsAnErrorWithItsColumn) {
  std::string text = "t,q1\n0,1.5\n0.1,2";
  text += std::string("\0", 1) + "5\n";
  std::string m = errorOf([&] { exid::parseCsv(text, "d.csv"); });
  EXPECT_NE(m.find("d.csv:3:6: column 'q1': '2\\x005' is not a number (unexpected byte 0x00 at "
                   "column 6)"),
            std::string::npos)
      << m;
  m = errorOf([&] { exid::parseCsv("t,q1\n0,  1.5x\n", "d.csv"); });
  EXPECT_NE(m.find("d.csv:2:8: column 'q1'"), std::string::npos) << m;
  EXPECT_NE(m.find("unexpected 'x'"), std::string::npos) << m;
  m = errorOf([&] { exid::parseCsv("t,q1\n0,\x01\n", "d.csv"); });
  EXPECT_NE(m.find("d.csv:2:3: column 'q1'"), std::string::npos) << m;
  EXPECT_NE(m.find("unexpected byte 0x01"), std::string::npos) << m;
}

// Input files: only regular files, only up to a cap; a FIFO is refused without blocking.
TEST(InputFile, NonRegularAndOversizedFilesAreRefused) {
  const fs::path d = tempDir();
  const fs::path fifo = d / "pipe.csv";
  fs::remove(fifo);
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  std::string m = errorOf([&] { exid::readCsv(fifo); });
  EXPECT_NE(m.find("pipe.csv: the CSV file is a FIFO (named pipe), not a regular file"),
            std::string::npos)
      << m;
  m = errorOf([&] { exid::readInputFile("/dev/zero", "robot", 100); });
  EXPECT_NE(m.find("/dev/zero: the robot file is a character device"), std::string::npos) << m;
  m = errorOf([&] { exid::readInputFile(d, "study", 100); });
  EXPECT_NE(m.find("is a directory"), std::string::npos) << m;
  std::ofstream(d / "big.yaml") << std::string(101, 'x');
  m = errorOf([&] { exid::readInputFile(d / "big.yaml", "study", 100); });
  EXPECT_NE(m.find("big.yaml: the study file has 101 bytes, more than the limit of 100 bytes"),
            std::string::npos)
      << m;
  EXPECT_EQ(exid::readInputFile(d / "big.yaml", "study", 101).size(), 101u);
  fs::remove(fifo);
  fs::remove(d / "big.yaml");
}
