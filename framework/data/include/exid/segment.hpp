// exid — the segment of a recording to use and its split into an identification and a
// validation part: the plugin parameters (t_start_s, t_end_s, split_part, split_fraction,
// split_at_s), their checks against the recording, and the meta that states them. Shared by the
// experiments that read recordings (csv, rosbag2) so that both cut the same way.
#pragma once

#include <string>
#include <vector>

#include "exid/export.hpp"
#include "exid/json.hpp"
#include "exid/params.hpp"

namespace exid {

/// The five parameters; `first` names the time origin in their docs (e.g. "sample",
/// "joint-state sample").
EXID_API std::vector<ParamDecl> segmentParams(const std::string& first = "sample");

/// A resolved segment, times in seconds after the recording's first sample. The part is the
/// half-open range [lo_s, hi_s) of the segment (closed at the segment's end): no sample belongs
/// to both parts of a split.
struct EXID_API RecordingSegment {
  double t_start_s = 0.0;
  double t_end_s = 0.0;       // as given (0: to the end)
  double end_s = 0.0;         // the segment's end
  std::string part = "none";  // none, identification, validation
  double fraction = 0.0;      // split_fraction (0: split_at_s was given)
  double split_s = 0.0;       // the split point (part != none)
  double lo_s = 0.0, hi_s = 0.0;

  /// `rel` (seconds after the first sample) lies in the segment.
  bool inSegment(double rel) const {
    return rel >= t_start_s && (t_end_s <= 0.0 || rel <= t_end_s);
  }
  /// `rel` lies in the segment's part (the whole segment when part is none).
  bool inPart(double rel) const {
    return inSegment(rel) && rel >= lo_s && !(part == "identification" && rel >= hi_s);
  }
  /// summary meta `split` (null when part is none): the part, the split point, both ranges and
  /// the sample counts.
  Json splitMeta(long segment_samples, long part_samples) const;
};

/// Reads the parameters and checks them against a recording spanning span_s seconds whose
/// median step is about step_tol / 0.5 (t_end_s may exceed span_s by step_tol, never more: the
/// segment is never clamped). Throws exid::Error starting with `pre` (e.g. "experiment 'csv': ")
/// and naming `file`.
EXID_API RecordingSegment resolveSegment(const ParamSet& p, double span_s, double step_tol,
                                         const std::string& pre, const std::string& file,
                                         const std::string& first = "sample");

}  // namespace exid
