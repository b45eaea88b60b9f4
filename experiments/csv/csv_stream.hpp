// exid — experiment `csv`: the recording read from its file(s) as an exid::DatasetStream.
// The class is defined in three files: csv_columns.cpp (the columns found from the headers,
// the reading options and one row read), csv_scan.cpp (the one scan of the rows before the
// first pass) and csv_stream.cpp (opening, the passes over the samples in chunks or in pieces,
// the meta).
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "exid/context.hpp"
#include "exid/data.hpp"
#include "exid/io.hpp"
#include "exid/json.hpp"
#include "exid/params.hpp"
#include "exid/recording.hpp"
#include "exid/robot_model.hpp"
#include "exid/segment.hpp"
#include "recording_stats.hpp"

namespace exid::csv_experiment {

/// The csv experiment's reading of a recording: its columns found from the headers, one scan
/// of the rows (time stamps; every used column with drop_bad_rows) that checks time, gaps,
/// the segment and the split, and then passes over the samples in chunks, each reading the
/// file(s) again. Memory: 8 bytes per row for the time stamps during the scan (released
/// after it), the dropped rows' numbers, and one chunk.
class CsvStream : public exid::DatasetStream {
  struct Ref {
    int source = 0, column = 0;
  };

 public:
  static std::shared_ptr<CsvStream> open(const exid::ParamSet& P,
                                         std::shared_ptr<const exid::RobotModel> robot,
                                         const exid::RunContext& ctx);

  const std::string& file() const { return files_[0]; }
  int size() const override { return static_cast<int>(i1_ - i0_); }
  int dof() const override { return n_; }
  bool hasVelocity() const override { return !pqd_.empty(); }
  bool hasAcceleration() const override { return !pqdd_.empty(); }
  bool hasTorque() const override { return !ptau_.empty(); }
  bool hasWrench() const override { return !pw_.empty(); }
  /// The file holds a floating base's signals (base_omega_x .. base_f_z, contact<c>_fx ..): read
  /// in memory (Dataset::base and ::contact are not streamed).
  bool hasFloating() const { return !pb_.empty() || !pc_.empty(); }
  double tFirst() const override { return t_first_; }
  double tLast() const override { return t_last_; }
  bool passed() const override { return stats_done_; }
  void collectEvery(int stride) override { stride_ = std::max(1, stride); }
  const exid::Dataset& collected() const override { return collected_; }
  bool samplingRate(double* fs_hz, double* jitter) const override {
    if (!has_rate_) return false;
    *fs_hz = fs_hz_;
    *jitter = jitter_;
    return true;
  }
  exid::Json meta() const override {
    exid::RecordingPipeline none({}, "experiment 'csv': " + file());
    none.unchanged(size());
    return metaAfter(none);
  }

  void rewind() override;
  int read(int count, exid::Dataset* chunk) override;

  // ---- a pass in pieces (fetch, decode on any thread, settle in order)
  struct CsvPiece : Piece {
    std::vector<std::string> text;  // per file: the rows' lines
    std::vector<int> line_before;   // per file: the file line before them
    int first_row = 0;              // file data row of the first line's row (0-based)
    int rows = 0;                   // data rows in text (samples and dropped rows)
    std::vector<double> values;     // decoded: per sample, its used values (for settle)
    std::vector<int> row_of;        // decoded: per sample, its file data row
  };

  std::unique_ptr<Piece> fetch(int count) override;
  void decode(Piece& piece, exid::Dataset* chunk) const override;
  void settle(const Piece& piece, const exid::Dataset& chunk) override;

  /// The meta of the dataset after the filter steps (exid/recording.hpp) ran on the segment.
  exid::Json metaAfter(const exid::RecordingPipeline& steps) const;

 private:
  CsvStream(const exid::ParamSet& P, std::shared_ptr<const exid::RobotModel> robot)
      : P_(P), robot_(std::move(robot)), n_(robot_->dof()) {}

  // ---- columns, from the headers (csv_columns.cpp)
  void resolveColumns(const exid::RunContext& ctx);
  void openFiles(const exid::RunContext& ctx);
  int col(int f, const std::string& c) const;
  std::vector<Ref> namedColumns(int f, const char* key) const;
  std::vector<Ref> columnGroup(const std::string& prefix, bool required, const char* what,
                               int f = 0) const;
  std::vector<Ref> torqueColumns(int ftau);
  std::vector<Ref> wrenchColumns() const;
  void floatingColumns(std::vector<Ref>* cb, std::vector<Ref>* cc) const;
  int timeColumn();
  void readScales();
  void layoutColumns(const std::vector<Ref>& cq, const std::vector<Ref>& cqd,
                     const std::vector<Ref>& cqdd, const std::vector<Ref>& ctau,
                     const std::vector<Ref>& cw, const std::vector<Ref>& cb,
                     const std::vector<Ref>& cc, int ct);
  std::string colName(const Ref& r, bool with_file = true) const;
  bool readRow(std::vector<std::unique_ptr<exid::CsvReader>>& rd);
  bool readRow(std::vector<std::unique_ptr<exid::CsvReader>>& rd,
               std::vector<std::vector<double>>* vals, double* uv) const;
  // The first used column whose value in uv_ (or uv) is not finite, or -1.
  int badColumn() const { return badColumn(uv_.data()); }
  int badColumn(const double* uv) const;
  [[noreturn]] void badValue(const std::vector<std::unique_ptr<exid::CsvReader>>& rd, int u,
                             int row) const;
  int lineOfRow(int f, int row) const;
  std::string lineText(int row) const;

  // ---- the scan (csv_scan.cpp): rows, bad values (drop_bad_rows), time, gaps, segment, split
  // What the scan keeps of the kept rows: the time stamps as written (with a time column)
  // and, only when rows were dropped, each one's file row.
  struct ScanRows {
    std::vector<double> raw;
    std::vector<int> keep;
  };
  int rowOf(const ScanRows& s, std::size_t i) const;
  double timeOf(const ScanRows& s, long i) const;
  void scan();
  void checkRowAligned() const;
  std::vector<double> scanRows();
  bool scanInPieces(const exid::CsvReader& like, std::vector<double>* raw);
  std::vector<int> keptFileRows() const;
  void checkUniformSteps(const ScanRows& s) const;
  void selectSegment(const ScanRows& s);
  void scanSamplingRate(const ScanRows& s);
  void recordTiming(ScanRows* s);

  // ---- a pass (csv_stream.cpp)
  void sizeChunk(int want, exid::Dataset* chunk) const;
  int fileRowsFor(long from, long m);
  bool nextKeptRow();
  void convert(int k, exid::Dataset* d) { convert(k, uv_.data(), row_, d, &tau_); }
  void convert(int k, const double* uv, int row, exid::Dataset* d, Eigen::VectorXd* tau) const;
  void collect(const exid::Dataset& chunk, int k);
  void finishPass();

  exid::ParamSet P_;
  std::shared_ptr<const exid::RobotModel> robot_;
  int n_ = 0;
  std::vector<std::string> files_;
  std::vector<std::vector<std::string>> columns_;
  std::vector<Ref> used_;                         // q, qd, qdd, tau, wrench, t
  std::vector<int> pq_, pqd_, pqdd_, ptau_, pw_;  // positions in used_
  std::vector<int> pb_, pc_;  // the floating base's: base motion (9), contact wrenches (6 each)
  int pt_ = -1;
  bool ct_ = false;                        // a time column
  std::vector<std::vector<int>> select_;   // per source: the columns it reads
  std::vector<Ref> slot_;                  // per used column: (source, place in its values)
  std::vector<std::vector<double>> vals_;  // per source: one row's values
  std::vector<double> uv_;                 // one row's used values
  std::vector<std::string> tau_names_;
  exid::SignalConversion conv_;  // scales, signs, offsets, torque constants
  Eigen::VectorXd tau_;
  bool drop_ = false;
  double tfactor_ = 1.0, dt_ = 0.0;
  std::string tname_, tunit_, tfrom_, part_;
  // the scan
  int rows_ = 0, dropped_ = 0;
  long kept_rows_ = 0;
  int scan_pieces_ = 1, scan_threads_ = 1;  // how the scan read the file (scanInPieces)
  std::vector<int> dropped_rows_;
  long i0_ = 0, i1_ = 0;
  int in_segment_ = 0;
  double ts_ = 0, te_ = 0, tsplit_ = 0, seg_end_ = 0, span_ = 0;
  exid::RecordingSegment seg_;
  double t_first_abs_ = 0, t_first_ = 0, t_last_ = 0;
  bool has_rate_ = false;  // samplingRate(): known from the scan
  double fs_hz_ = 0, jitter_ = 0;
  exid::Json recording_;
  // a pass
  std::vector<std::unique_ptr<exid::CsvReader>> readers_;
  std::vector<std::unique_ptr<exid::CsvReader>> protos_;  // never read: decode()'s template
  int row_ = -1;
  long kept_ = -1;
  std::size_t dptr_ = 0;  // fetch(): dropped_rows_ before row_ + 1
  long settled_ = 0;      // samples of the pass settled
  std::unique_ptr<RecordingStats> stats_;
  bool stats_done_ = false, collecting_ = false;
  int stride_ = 0;  // collectEvery(); 0: nothing kept
  long taken_ = 0;
  exid::Dataset collected_;
};

}  // namespace exid::csv_experiment
