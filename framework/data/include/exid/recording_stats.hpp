// exid — statistics of a recording's rows that any experiment reports (meta.recording): the
// sampling rate exact to the stamps' resolution, jitter and gaps.
#pragma once

#include <vector>

#include "exid/export.hpp"
#include "exid/json.hpp"

namespace exid {

/// Sampling statistics from time stamps as written in a file (raw values in the file's unit,
/// unit_s seconds each; row[i] is the file's data row of stamp i, steps across skipped rows are
/// divided among them; row empty: consecutive rows). rate_hz is exact to the stamps' resolution
/// (the finest power of ten that every stamp is a multiple of): a 100 Hz log is 100 Hz, not
/// 100.0001. Gaps: steps longer than gap_factor times the median step.
EXID_API Json samplingStats(const std::vector<double>& raw, double unit_s,
                            const std::vector<int>& row, double gap_factor);
/// The rate of a given sample period, exact to the period's decimal resolution.
EXID_API double rateFromPeriod(double period_s);

}  // namespace exid
