// exid — sampling statistics of a recording's time stamps (recording_stats.hpp).
#include "exid/recording_stats.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "exid/signal.hpp"

namespace exid {

namespace {

/// The smallest d in [0, 9] such that every value is a multiple of 10^-d (to within a millionth
/// of that unit and the values' own rounding); -1 when there is none.
int decimalResolution(const std::vector<double>& v) {
  constexpr double eps = std::numeric_limits<double>::epsilon();
  for (int d = 0; d <= 9; ++d) {
    const double s = std::pow(10.0, d);
    bool ok = true;
    for (double x : v) {
      const double y = x * s;
      if (std::abs(y - std::round(y)) > 1e-6 + 16 * eps * std::abs(y)) {
        ok = false;
        break;
      }
    }
    if (ok) return d;
  }
  return -1;
}

Json pair(double a, double b) { return Json(std::vector<double>{a, b}); }

}  // namespace

double rateFromPeriod(double period_s) {
  if (!(period_s > 0)) return NAN;
  const int d = decimalResolution({period_s});
  if (d < 0) return 1.0 / period_s;
  const double units = std::round(period_s * std::pow(10.0, d));
  return std::pow(10.0, d) / units;
}

Json samplingStats(const std::vector<double>& raw, double unit_s, const std::vector<int>& row,
                   double gap_factor) {
  Json J = Json::object();
  J["samples"] = static_cast<long long>(raw.size());
  if (raw.size() < 2 || (!row.empty() && row.size() != raw.size())) {
    J["rate_hz"] = Json();
    J["note"] = "fewer than two time stamps";
    return J;
  }
  // step i, computed where needed (never held: the stamps are the only array)
  auto stepAt = [&](std::size_t i) {
    return (raw[i + 1] - raw[i]) /
           static_cast<double>(row.empty() ? 1 : std::max(1, row[i + 1] - row[i]));
  };
  const std::size_t nsteps = raw.size() - 1;
  const double med = medianOfValues(nsteps, stepAt);
  const int d = decimalResolution(raw);
  double period = med, rate = 1.0 / (med * unit_s);
  if (d >= 0) {
    const double s = std::pow(10.0, d);
    const double units = std::round(med * s);
    if (units >= 1) {
      period = units / s;
      // a decimal unit (s, ms, us, ns) keeps the rate exact: 10^(d + u) / units
      const int u = static_cast<int>(std::lround(-std::log10(unit_s)));
      rate = std::abs(std::pow(10.0, -u) - unit_s) <= 1e-12 * unit_s ? std::pow(10.0, d + u) / units
                                                                     : s / units / unit_s;
    }
  }
  J["rate_hz"] = rate;
  J["period_s"] = period * unit_s;
  J["resolution_s"] = d >= 0 ? Json(std::pow(10.0, -d) * unit_s) : Json();
  double mean = 0, maxrel = 0;
  for (std::size_t i = 0; i < nsteps; ++i) {
    const double rel = (stepAt(i) - period) / period;
    mean += rel;
    maxrel = std::max(maxrel, std::abs(rel));
  }
  mean /= static_cast<double>(nsteps);
  double var = 0;
  for (std::size_t i = 0; i < nsteps; ++i) {
    const double rel = (stepAt(i) - period) / period;
    var += (rel - mean) * (rel - mean);
  }
  Json& jit = J["jitter"];
  jit["std_rel"] = std::sqrt(var / static_cast<double>(nsteps));
  jit["max_rel"] = maxrel;
  Json& g = J["gaps"];
  g["factor"] = gap_factor;
  long long count = 0;
  double largest = 0;
  Json at = Json::array();
  for (std::size_t i = 0; i < nsteps; ++i) {
    if (!(stepAt(i) > gap_factor * period)) continue;
    ++count;
    largest = std::max(largest, (raw[i + 1] - raw[i]) * unit_s);
    if (at.size() < 20) at.push_back(pair(raw[i] * unit_s, raw[i + 1] * unit_s));
  }
  g["count"] = count;
  g["largest_s"] = largest;
  g["at_s"] = at;
  return J;
}

}  // namespace exid
