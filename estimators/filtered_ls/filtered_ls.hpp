// exid — estimator `filtered_ls` (filtered_ls.cpp): the plugin class, shared by its sources (not
// installed). filtered_ls.cpp: the plugin, its parameters, the least squares and the details;
// filtered_ls_rows.cpp: steps 1-4, the samples filtered, differentiated, turned into rows,
// decimated and accumulated in chunks.
#pragma once

#include <string>
#include <vector>

#include "exid/estimators/common.hpp"
#include "exid/interfaces.hpp"

namespace exid::filtered_ls {

namespace estimators = exid::estimators;

class FilteredLs : public exid::Estimator {
 public:
  static constexpr const char* kName = "filtered_ls";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "least squares on real data: zero-phase Butterworth filtering of q, central differences for "
      "qd/qdd, parallel decimation of W and y, then batch_ls's solver";

  static std::vector<exid::ParamDecl> params();

  explicit FilteredLs(const exid::ParamSet& p);

  exid::EstimatorSpecs specs() const override {
    exid::EstimatorSpecs s;
    s.needs_raw_dataset = true;
    s.accepts_prior = true;
    s.streams = true;  // chunks of samples with the filters' margins (process())
    return s;
  }

  /// Steps 1-4 (also used for the validation rows of raw validation data, so that the held-out
  /// error is measured on rows processed exactly like the identification rows).
  struct Processed {
    exid::Rows rows;                 // with keep_rows
    estimators::RowAccumulator acc;  // every kept row
    bool streamed = false, per_sample = true;
    long chunk_samples = 0, margin_samples = 0, signal_margin = 0;
    long chunks = 0;
    int threads = 1;
    long column_blocks = 1;   // most blocks of the rows' columns a chunk was filtered in
    double buffer_bytes = 0;  // the largest rows buffer of one chunk (one per thread)
    double fs = 0.0, jitter = 0.0, dec_cut = 0.0, kappa = 1.0;
    bool filter_q = false, diff_qd = false, diff_qdd = false;
    long trim = 0, trim_transient = 0;
    bool trim_default = false;
    int R = 1;
    long rows_before = 0, slow_removed = 0, samples_after_decimation = 0;
    std::string standstill;                   // the mode in force (auto resolved)
    long rest_min = 0;                        // standstill: shortest run [samples]; 0: off
    long rest_samples = 0, rest_removed = 0;  // trimmed samples at rest; rows removed (drop)
    long rest_edge_samples = 0;               // trimmed samples at a standstill's edges (drop)
    std::string dec_note;
    long parts = 1;          // recordings processed on their own (DatasetFacts::parts)
    long trimmed_total = 0;  // samples trimmed, every part's ends
  };

  void plan(const exid::ObservationModel& model, const exid::Dataset& data, Processed* P,
            estimators::Sos* sos, estimators::Sos* dsos) const;

  std::vector<char> standstill(const exid::Dataset& raw, const Processed& P) const;

  exid::Dataset filtered(exid::Dataset raw, const Processed& P, const estimators::Sos& sos,
                         const std::vector<char>& rest) const;

  struct ChunkOut {
    exid::Rows rows;
    estimators::RowAccumulator acc;
    long slow = 0, kept = 0, rows_before = 0, rest = 0, rest_edge = 0, rest_removed = 0;
    long column_blocks = 1;
    double buffer_bytes = 0;
  };

  void chunkRows(const exid::ObservationModel& model, const Processed& P,
                 const estimators::Sos& dsos, const exid::Dataset& f, const std::vector<char>& rest,
                 long lo, long ca, long cb, bool keep_rows, const exid::RunContext& ctx,
                 ChunkOut* o) const;

  /// The model's rows of the filtered samples f (from sample lo; chunk [ca, cb)) in one row of
  /// s->M per sample: of the columns where equation g's p base columns and its y lie at
  /// [g (p + 1), (g + 1)(p + 1)), the block [c0, c0 + width) (clipped to the last column),
  /// built a block of samples at a time (the model's rows of the whole chunk are never held).
  /// The first block (c0 = 0) also sets the labels, the times and o->rows_before.
  struct SampleRows {
    estimators::LargeRows M;    // huge pages: written once, tens of MB
    std::vector<int> labels;    // equation label of each group, ascending
    std::vector<double> times;  // (keep_rows) per sample and group: the row's time
    exid::Rows head;            // numEquations, equation_names
  };
  void sampleRows(const exid::ObservationModel& model, const Processed& P, const exid::Dataset& f,
                  long lo, long ca, long cb, bool keep_rows, const exid::RunContext& ctx,
                  Eigen::Index c0, Eigen::Index width, SampleRows* s, ChunkOut* o) const;

  std::vector<long> keptSamples(const exid::ObservationModel& model, const Processed& P,
                                const exid::Dataset& f, const std::vector<char>& rest, long lo,
                                long ca, long cb, ChunkOut* o) const;

  /// Steps 1-4 on the data; a dataset of several recordings (DatasetFacts::parts) part by part,
  /// each filtered, differentiated, trimmed and decimated on its own, the rows merged in order.
  Processed process(const exid::ObservationModel& model, const exid::Dataset& data,
                    const exid::RunContext& ctx, bool keep_rows) const;
  Processed processPart(const exid::ObservationModel& model, const exid::Dataset& data,
                        const exid::RunContext& ctx, bool keep_rows) const;

  static void appendRows(exid::Rows* all, const exid::Rows& r, int p);

  exid::Rows validationRows(const exid::ObservationModel& model, const exid::Dataset& data,
                            const exid::RunContext& ctx) const override {
    return process(model, data, ctx, true).rows;
  }

  exid::Estimate estimate(const exid::ObservationModel& model, const exid::Dataset& data,
                          const exid::Prior* prior, const exid::RunContext& ctx) override;

 private:
  using Json = exid::Json;

  exid::Estimate solve(const exid::ObservationModel& model, const Processed& P,
                       const exid::Prior* prior) const;

  void describeFilters(const Processed& P, const exid::Dataset& data, exid::Json* dp) const;

  void describeStandstill(const Processed& P, int K, exid::Json* dp) const;

  double cutoff_;
  int order_;
  bool differentiate_;
  int decimation_, dec_order_;
  double dec_ratio_;
  long trim_;
  bool correct_;
  std::vector<double> min_speed_;
  bool min_speed_joint_ = false;
  std::string standstill_;
  double standstill_min_s_ = 0.0;
  std::vector<double> standstill_tol_;
  long chunk_samples_ = 8192;
  double chunk_memory_mb_ = 16.0;
  int threads_ = 0;
  estimators::SolveOptions opt_;
};

}  // namespace exid::filtered_ls
