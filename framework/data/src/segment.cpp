// exid — the segment of a recording and its split (segment.hpp).
#include "exid/segment.hpp"

#include <fmt/format.h>

#include <algorithm>

#include "exid/error.hpp"

namespace exid {

std::vector<ParamDecl> segmentParams(const std::string& first) {
  return {
      param_double("t_start_s", 0.0, "s",
                   "segment start, in seconds after the first " + first + "'s time", 0.0),
      param_double("t_end_s", 0.0, "s",
                   "segment end, in seconds after the first " + first + "'s time; 0: to the end",
                   0.0),
      param_string("split_part", std::string("none"),
                   "none: the whole segment; identification / validation: the part of the "
                   "segment before / after the split point (split_fraction or split_at_s; the "
                   "study key `split` sets these); each part is filtered on its own, so no "
                   "sample of one touches the other",
                   {"none", "identification", "validation"}),
      param_double("split_fraction", 0.0, "",
                   "with split_part: the split point as a fraction of the segment's duration "
                   "(e.g. 0.65: identification = first 65 %); 0: use split_at_s",
                   0.0, 1.0, false, true),
      param_double("split_at_s", 0.0, "s",
                   "with split_part: the split point in seconds after the segment's start; "
                   "0: use split_fraction",
                   0.0),
  };
}

RecordingSegment resolveSegment(const ParamSet& p, double span_s, double step_tol,
                                const std::string& pre, const std::string& file,
                                const std::string& first) {
  RecordingSegment s;
  s.t_start_s = p.getDouble("t_start_s");
  s.t_end_s = p.getDouble("t_end_s");
  check(s.t_end_s == 0.0 || s.t_end_s > s.t_start_s,
        fmt::format("{}t_end_s = {} must be after t_start_s = {} (or 0 for the end)", pre,
                    s.t_end_s, s.t_start_s));
  check(s.t_start_s <= span_s,
        fmt::format("{}{}: t_start_s = {} s is after the end of the recording ({} s after its "
                    "first {})",
                    pre, file, s.t_start_s, span_s, first));
  check(s.t_end_s <= span_s + step_tol,
        fmt::format("{}{}: t_end_s = {} s is past the end of the recording ({} s after its "
                    "first {}); the segment is never clamped (0: to the end)",
                    pre, file, s.t_end_s, span_s, first));
  s.part = p.getString("split_part");
  s.fraction = p.getDouble("split_fraction");
  const double at = p.getDouble("split_at_s");
  s.end_s = s.t_end_s > 0.0 ? std::min(s.t_end_s, span_s) : span_s;
  if (s.part != "none") {
    check((s.fraction > 0.0) != (at > 0.0),
          fmt::format("{}split_part = {} needs exactly one of split_fraction (found {}) and "
                      "split_at_s (found {})",
                      pre, s.part, s.fraction, at));
    s.split_s =
        s.fraction > 0.0 ? s.t_start_s + s.fraction * (s.end_s - s.t_start_s) : s.t_start_s + at;
    check(s.split_s > s.t_start_s && s.split_s < s.end_s,
          fmt::format("{}{}: the split point {} s (split_at_s = {}) is not inside the segment "
                      "[{}, {}] s",
                      pre, file, s.split_s, at, s.t_start_s, s.end_s));
  } else {
    check(s.fraction == 0.0 && at == 0.0,
          fmt::format("{}split_fraction / split_at_s need split_part (identification or "
                      "validation; the study key `split` sets all three)",
                      pre));
  }
  s.lo_s = s.part == "validation" ? s.split_s : s.t_start_s;
  s.hi_s = s.part == "identification" ? s.split_s : s.end_s;
  return s;
}

Json RecordingSegment::splitMeta(long segment_samples, long part_samples) const {
  if (part == "none") return Json();
  Json sp = Json::object();
  sp["part"] = part;
  sp["split_at_s"] = split_s;
  if (fraction > 0.0) sp["fraction"] = fraction;
  sp["identification_s"] = Json(std::vector<double>{t_start_s, split_s});
  sp["validation_s"] = Json(std::vector<double>{split_s, end_s});
  sp["segment_samples"] = segment_samples;
  sp["part_samples"] = part_samples;
  return sp;
}

}  // namespace exid
