// exid — files: atomic writes (temporary name, then rename) and CSV tables with a header.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "exid/error.hpp"
#include "exid/export.hpp"
#include "exid/input_file.hpp"

namespace exid {

/// A failed write, with its errno: ENOSPC, EDQUOT and EFBIG (disk or quota full, file size
/// limit) are conditions of the machine, not of the study (a matrix retries such a cell).
class EXID_API IoError : public Error {
 public:
  IoError(const std::string& what, int err) : Error(what), errno_value(err) {}
  int errno_value;
  bool outOfSpace() const;
};

/// Writes text to path atomically: path.tmp.<pid> is written and flushed, then renamed over
/// path. On any failure nothing is left at path (an older file stays as it was) and
/// exid::Error names the file and the reason (e.g. disk full).
EXID_API void writeFileAtomic(const std::filesystem::path& path, const std::string& text);

/// The same written piece by piece (a large file is never held as one string): write() as
/// often as needed, then commit() flushes, syncs and renames over path. Destroyed without a
/// commit (an exception on the way), it removes its temporary file: nothing is left at path.
class EXID_API AtomicFileWriter {
 public:
  explicit AtomicFileWriter(std::filesystem::path path);
  ~AtomicFileWriter();
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;
  void write(std::string_view text);
  void commit();

 private:
  static constexpr std::size_t kBuffer = std::size_t{1} << 20;
  std::filesystem::path path_, tmp_;
  int fd_ = -1;
  std::string buf_;
  void put(const char* p, std::size_t n);
  void flush();
  [[noreturn]] void fail(const std::string& what, int err);
};

/// Removes `*.tmp.PID` files and `.*.staging.PID` folders in dir whose process PID is gone (left
/// by a process killed with SIGKILL). Returns how many were removed; never throws.
EXID_API int cleanStaleTemporaries(const std::filesystem::path& dir);

/// A numeric table with named columns.
struct EXID_API CsvTable {
  std::vector<std::string> columns;
  Eigen::MatrixXd data;  // rows x columns (x the columns read: see slot)
  /// The 1-based line of the file of each data row (comments and blank lines counted).
  std::vector<int> line_of;
  /// Empty: data holds every column. Else, per column of the file, its column in data, or -1
  /// for a column that was not read (readCsvColumns).
  std::vector<int> slot;
  int col(const std::string& name) const;  // -1 when absent
  /// The column of data holding column c of the file (-1: not read).
  int dataCol(int c) const { return slot.empty() ? c : slot[static_cast<std::size_t>(c)]; }
  bool has(const std::string& name) const { return col(name) >= 0; }
  Eigen::VectorXd column(const std::string& name) const;
  /// With CsvReadOptions::text_columns: per column, the error of its first cell that is not a
  /// number ("" when every cell is one). Such cells read as NaN; a reader that uses the column
  /// throws this message (a column of labels nobody asked for is not an error).
  std::vector<std::string> not_numeric;
  /// The message for column c, "" when it is numeric (or not checked).
  const std::string& notNumeric(int c) const;
};

struct EXID_API CsvReadOptions {
  bool allow_non_finite = false;      // NaN/Inf cells are an error naming row and column unless set
  bool drop_non_finite_rows = false;  // drop (and count) rows with NaN/Inf/empty cells instead
  char delimiter = 0;                 // 0: detect ',' ';' or tab from the header
  bool text_columns = false;          // a cell that is not a number reads as NaN and is recorded in
                                      // CsvTable::not_numeric instead of being an error
};

/// A cell [a, b), already trimmed and not empty, as CsvReader reads it: std::from_chars (a
/// leading '+' allowed), else strtod (hex, NaN payloads, out of range). True when the whole cell
/// is the number; *used: the bytes strtod read (for the error's column).
EXID_API bool parseCsvNumber(const char* a, const char* b, double* v, std::size_t* used);

/// A CSV file with a header line read as a stream: in blocks of a fixed size (a line may straddle
/// blocks), in constant memory whatever the file's size, each row's cells found by pointer
/// scanning and converted with std::from_chars (strtod where from_chars does not say the same:
/// hex, a NaN payload, out of range). Only the selected columns are converted: the others are
/// counted, never read. Errors are those of parseCsv: they name the file, the line and the
/// column. Input files: regular files only (input_file.hpp), with no size limit.
class EXID_API CsvReader {
 public:
  static constexpr std::size_t kDefaultBlockBytes = std::size_t{1} << 20;
  /// Opens path and reads its header; `what` names the file in errors ("cannot open the CSV
  /// file"). block_bytes: the size of each read (tests use tiny blocks).
  explicit CsvReader(const std::filesystem::path& path, const CsvReadOptions& opt = {},
                     const std::string& what = "CSV", std::size_t block_bytes = kDefaultBlockBytes);
  /// Text in memory, named `source` in errors; it must outlive the reader. block_bytes 0: the
  /// whole text at once (no copy).
  CsvReader(std::string_view text, const std::string& source, const CsvReadOptions& opt = {},
            std::size_t block_bytes = 0);
  /// The rows that follow `like`'s rows, in memory: `body` holds whole lines of the same file
  /// (as takeRows() copied them), the first being file line like_line + 1. Same columns,
  /// delimiter, options and selection as `like`; no header is read. `body` must outlive the
  /// reader. For parsing pieces of one file on several threads.
  CsvReader(std::string_view body, const CsvReader& like, int like_line);
  ~CsvReader();
  CsvReader(const CsvReader&) = delete;
  CsvReader& operator=(const CsvReader&) = delete;

  const std::string& source() const { return source_; }
  const std::vector<std::string>& columns() const { return columns_; }
  int headerLine() const { return header_line_; }
  char delimiter() const { return delim_; }
  /// The columns to convert, as indices into columns() (any order, no repeats); every column
  /// until called. Call before the first row.
  void select(const std::vector<int>& columns);
  const std::vector<int>& selected() const { return sel_; }
  /// The next data row: the selected columns' values into values[0 .. selected().size()).
  /// False at the end of the file. Rows with non-finite values are dropped (and counted) with
  /// drop_non_finite_rows; any other error throws exid::Error.
  bool next(double* values);
  /// The next `count` data rows (fewer at the end of the file) as text, unparsed: their lines,
  /// with the blank and comment lines between them, appended to *out, each ending in '\n'.
  /// *line_before: the file line before the first copied (a reader made with the body
  /// constructor from *out then numbers its lines as the file does). Returns the data rows
  /// taken.
  int takeRows(int count, std::string* out, int* line_before);
  /// Passes over the next `count` data rows without reading them; returns how many.
  int skipRows(int count);
  /// 1-based file line of the row that next() returned last.
  int line() const { return line_; }
  /// Rows dropped so far (drop_non_finite_rows).
  int dropped() const { return dropped_; }
  /// With text_columns: per column, the first cell that was not a number ("" when none).
  const std::vector<std::string>& notNumeric() const { return not_numeric_; }
  /// Bytes consumed so far.
  std::uint64_t bytesRead() const { return bytes_; }

 private:
  bool nextLine(const char** b, const char** e);
  bool refill();
  void readHeader();
  [[noreturn]] void readFailed(int err);
  void countValues(std::size_t c, const char* ce, const char* e) const;

  CsvReadOptions opt_;
  std::string source_, what_;
  int fd_ = -1;
  std::string_view text_;  // memory source
  std::size_t text_pos_ = 0;
  std::size_t block_;
  // (bytes left uninitialised on resize: every byte used is read into first)
  template <class T>
  struct Uninitialised : std::allocator<T> {
    template <class U>
    struct rebind {
      using other = Uninitialised<U>;
    };
    Uninitialised() = default;
    template <class U>
    Uninitialised(const Uninitialised<U>&) noexcept {}
    template <class U>
    void construct(U* p) noexcept {
      ::new (static_cast<void*>(p)) U;
    }
  };
  std::vector<char, Uninitialised<char>> buf_;  // [beg_, end_) not consumed yet
  const char* beg_ = nullptr;
  const char* end_ = nullptr;
  std::size_t scanned_ = 0;  // bytes after beg_ known to hold no newline
  bool eof_ = false;
  std::uint64_t bytes_ = 0;
  int lineno_ = 0, line_ = 0, header_line_ = 0, dropped_ = 0;
  char delim_ = ',';
  std::vector<std::string> columns_, not_numeric_;
  std::vector<int> sel_, slot_;  // slot_: per column, its place in the values of a row (-1)
  std::size_t cells_read_ = 0;   // cells split per line: up to the last selected column
};

/// Reads a CSV with a header line. Errors name the file, the line and the column.
EXID_API CsvTable readCsv(const std::filesystem::path& path, const CsvReadOptions& opt = {},
                          int* dropped_rows = nullptr);
EXID_API CsvTable parseCsv(const std::string& text, const std::string& source,
                           const CsvReadOptions& opt = {}, int* dropped_rows = nullptr);
/// A table from a reader (its header read): the columns wanted(name) selects (every column
/// when wanted is empty), rows to the end. CsvTable::columns lists every column of the file,
/// CsvTable::slot says where the selected ones are in data. Memory: the numbers read, plus one
/// block of the file.
template <class Wanted>
CsvTable readCsvColumns(CsvReader& reader, const Wanted& wanted);
EXID_API CsvTable readCsvTable(CsvReader& reader, const std::vector<int>& columns, bool all);
template <class Wanted>
CsvTable readCsvColumns(CsvReader& reader, const Wanted& wanted) {
  std::vector<int> cols;
  for (std::size_t c = 0; c < reader.columns().size(); ++c)
    if (wanted(reader.columns()[c])) cols.push_back(static_cast<int>(c));
  return readCsvTable(reader, cols, false);
}
/// CSV text (full double precision).
EXID_API std::string toCsv(const CsvTable& table);
/// The same text into a writer, a row at a time.
EXID_API void writeCsv(AtomicFileWriter& out, const CsvTable& table);
EXID_API void writeCsvAtomic(const std::filesystem::path& path, const CsvTable& table);

}  // namespace exid
