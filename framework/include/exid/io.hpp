// exid — files: atomic writes (temporary name, then rename) and CSV tables with a header.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/input_file.hpp"

namespace exid {

/// A failed write, with its errno: ENOSPC, EDQUOT and EFBIG (disk or quota full, file size
/// limit) are conditions of the machine, not of the study (a matrix retries such a cell).
class IoError : public Error {
 public:
  IoError(const std::string& what, int err) : Error(what), errno_value(err) {}
  int errno_value;
  bool outOfSpace() const;
};

/// Writes text to path atomically: path.tmp.<pid> is written and flushed, then renamed over
/// path. On any failure nothing is left at path (an older file stays as it was) and
/// exid::Error names the file and the reason (e.g. disk full).
void writeFileAtomic(const std::filesystem::path& path, const std::string& text);

/// Removes `*.tmp.PID` files and `.*.staging.PID` folders in dir whose process PID is gone (left
/// by a process killed with SIGKILL). Returns how many were removed; never throws.
int cleanStaleTemporaries(const std::filesystem::path& dir);

/// A numeric table with named columns.
struct CsvTable {
  std::vector<std::string> columns;
  Eigen::MatrixXd data;                    // rows x columns
  int col(const std::string& name) const;  // -1 when absent
  bool has(const std::string& name) const { return col(name) >= 0; }
  Eigen::VectorXd column(const std::string& name) const;
  /// With CsvReadOptions::text_columns: per column, the error of its first cell that is not a
  /// number ("" when every cell is one). Such cells read as NaN; a reader that uses the column
  /// throws this message (a column of labels nobody asked for is not an error).
  std::vector<std::string> not_numeric;
  /// The message for column c, "" when it is numeric (or not checked).
  const std::string& notNumeric(int c) const;
};

struct CsvReadOptions {
  bool allow_non_finite = false;      // NaN/Inf cells are an error naming row and column unless set
  bool drop_non_finite_rows = false;  // drop (and count) rows with NaN/Inf/empty cells instead
  char delimiter = 0;                 // 0: detect ',' ';' or tab from the header
  bool text_columns = false;          // a cell that is not a number reads as NaN and is recorded in
                                      // CsvTable::not_numeric instead of being an error
};

/// Reads a CSV with a header line. Errors name the file, the line and the column.
CsvTable readCsv(const std::filesystem::path& path, const CsvReadOptions& opt = {},
                 int* dropped_rows = nullptr);
CsvTable parseCsv(const std::string& text, const std::string& source,
                  const CsvReadOptions& opt = {}, int* dropped_rows = nullptr);
/// CSV text (full double precision).
std::string toCsv(const CsvTable& table);
void writeCsvAtomic(const std::filesystem::path& path, const CsvTable& table);

}  // namespace exid
