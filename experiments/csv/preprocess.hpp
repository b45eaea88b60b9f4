// exid — experiment `csv`: the optional preprocessing of a segment held in memory (zero-phase
// low-pass, central differences, trimmed edges, decimation) and what it did (meta).
#pragma once

#include <string>

#include "exid/data.hpp"
#include "exid/params.hpp"

namespace exid::csv_experiment {

/// What preprocess() did: the filter, the trim (and how it was chosen) and the decimation.
struct Preprocessed {
  double cutoff_hz = 0, fs = 0;
  int order = 0, trim = 0, decimation = 1;
  int trim_transient = 0, trim_cap = 0, samples_before_trim = 0;
  bool trim_default = false;
  bool filter_torque = false;
};

/// Optional: zero-phase low-pass of q (and tau, wrench), central differences, trim, decimate.
/// P: the experiment's parameters (differentiate_cutoff_hz, filter_order, filter_torque,
/// decimation, trim_edges); file names the recording in messages.
Preprocessed preprocess(const exid::ParamSet& P, exid::Dataset* d, const std::string& file);

}  // namespace exid::csv_experiment
