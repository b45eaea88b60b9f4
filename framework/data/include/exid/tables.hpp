// exid — samples and datasets as CSV tables (the columns exid writes and reads: t, q1.., qd1..,
// qdd1.., tau1.., fx..mz).
#pragma once

#include "exid/data.hpp"
#include "exid/export.hpp"
#include "exid/io.hpp"

namespace exid {

/// Samples and datasets as CSV tables (docs/conventions.md §1 column names).
/// A trajectory's samples as a table: t, q1..qn, qd1..qdn, qdd1..qddn.
EXID_API CsvTable samplesTable(const Samples& s);
/// A dataset as a table: t and every signal it has (q, qd, qdd, tau; fx..mz for a wrench).
EXID_API CsvTable datasetTable(const Dataset& d);

}  // namespace exid
