// exid — the filter steps of a recording's pipeline (recording.hpp).
#include "exid/recording.hpp"

#include <fmt/format.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>

#include "exid/delay.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/signal.hpp"

namespace exid {

bool isBagPath(const std::filesystem::path& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    if (fs::exists(path / "metadata.yaml", ec)) return true;
    for (const auto& e : fs::directory_iterator(path, ec)) {
      const std::string ext = e.path().extension().string();
      if (ext == ".mcap" || ext == ".db3") return true;
    }
    return false;
  }
  return fs::is_regular_file(path, ec) && !bagStorageOf(path).empty();
}

std::vector<ParamDecl> signalConversionParams(const std::string& torque_source) {
  return {
      param_doubles("q_scale", std::vector<double>{}, "",
                    "per joint, multiplies the recorded position (after which sign and "
                    "offset_rad apply), e.g. 0.0174533 for degrees; empty: 1"),
      param_doubles("qd_scale", std::vector<double>{}, "",
                    "per joint, multiplies the recorded velocity and acceleration; empty: as "
                    "q_scale"),
      param_doubles("tau_scale", std::vector<double>{}, "",
                    "per joint, multiplies the torque alone (after torque constants), e.g. -1 "
                    "for a torque recorded with the opposite sign to the joint; empty: 1"),
      param_doubles("wrench_scale", std::vector<double>{}, "",
                    "6 values multiplying fx fy fz mx my mz (a unit, a sign); empty: 1"),
      param_doubles("sign", std::vector<double>{}, "",
                    "per joint +1 or -1, applied to q, qd, qdd and tau of that joint; empty: "
                    "all +1"),
      param_doubles("offset_rad", std::vector<double>{}, "rad",
                    "per joint, added to q after the sign; empty: zeros"),
      param_string("torque_from", std::string("tau"),
                   "tau: " + torque_source +
                       " hold torques; current: they hold motor currents, "
                       "times torque_constants_Nm_per_A",
                   {"tau", "current"}),
      param_doubles("torque_constants_Nm_per_A", std::vector<double>{}, "N m/A",
                    "per joint: torque per ampere of current j, referred to the coordinate "
                    "named by current_frame (gear ratio included)"),
      param_string("current_frame", std::string("measured"),
                   "measured: tau_m = Kt .* i directly; joint: the products act on the joint "
                   "coordinates and tau_m = T^T (Kt .* i) with the robot's transmission T",
                   {"measured", "joint"}),
  };
}

namespace {
// A per-joint scale: n finite non-zero values (empty: dflt for every joint).
std::vector<double> perJoint(const std::string& who, const char* key, std::vector<double> v,
                             double dflt, int n) {
  if (v.empty()) v.assign(static_cast<std::size_t>(n), dflt);
  check(static_cast<int>(v.size()) == n,
        fmt::format("{}: {}: expected {} values (one per joint), found {}", who, key, n, v.size()));
  for (double x : v)
    check(std::isfinite(x) && x != 0.0,
          fmt::format("{}: {}: {} is not a usable scale", who, key, x));
  return v;
}
}  // namespace

SignalConversion SignalConversion::fromParams(const ParamSet& p, int n,
                                              const Eigen::MatrixXd& transmission,
                                              const std::string& who) {
  SignalConversion c;
  c.q_scale = perJoint(who, "q_scale", p.getDoubles("q_scale"), 1.0, n);
  c.qd_scale = p.getDoubles("qd_scale").empty()
                   ? c.q_scale
                   : perJoint(who, "qd_scale", p.getDoubles("qd_scale"), 1.0, n);
  c.tau_scale = perJoint(who, "tau_scale", p.getDoubles("tau_scale"), 1.0, n);
  c.wrench_scale = p.getDoubles("wrench_scale");
  if (c.wrench_scale.empty()) c.wrench_scale.assign(6, 1.0);
  check(c.wrench_scale.size() == 6,
        fmt::format("{}: wrench_scale: expected 6 values (fx fy fz mx my mz), found {}", who,
                    c.wrench_scale.size()));
  for (double x : c.wrench_scale)
    check(std::isfinite(x) && x != 0.0,
          fmt::format("{}: wrench_scale: {} is not a usable scale", who, x));
  c.sign = p.getDoubles("sign");
  c.offset_rad = p.getDoubles("offset_rad");
  if (c.sign.empty()) c.sign.assign(static_cast<std::size_t>(n), 1.0);
  if (c.offset_rad.empty()) c.offset_rad.assign(static_cast<std::size_t>(n), 0.0);
  check(
      static_cast<int>(c.sign.size()) == n,
      fmt::format("{}: sign: expected {} values (one per joint), found {}", who, n, c.sign.size()));
  check(static_cast<int>(c.offset_rad.size()) == n,
        fmt::format("{}: offset_rad: expected {} values (one per joint), found {}", who, n,
                    c.offset_rad.size()));
  for (int j = 0; j < n; ++j)
    check(c.sign[static_cast<std::size_t>(j)] == 1.0 || c.sign[static_cast<std::size_t>(j)] == -1.0,
          fmt::format("{}: sign: joint {}: expected +1 or -1, found {}", who, j + 1,
                      c.sign[static_cast<std::size_t>(j)]));
  for (double x : c.offset_rad)
    check(std::isfinite(x), fmt::format("{}: offset_rad: {} is not finite", who, x));
  if (p.getString("torque_from") == "current") {
    c.torque_constants = p.getDoubles("torque_constants_Nm_per_A");
    check(static_cast<int>(c.torque_constants.size()) == n,
          fmt::format("{}: torque_constants_Nm_per_A: expected {} values (one per joint), "
                      "found {}",
                      who, n, c.torque_constants.size()));
    for (double x : c.torque_constants)
      check(std::isfinite(x) && x != 0.0,
            fmt::format("{}: torque_constants_Nm_per_A: {} is not a usable constant", who, x));
    if (p.getString("current_frame") == "joint") c.transmission = transmission;
  } else {
    check(p.getDoubles("torque_constants_Nm_per_A").empty(),
          fmt::format("{}: torque_constants_Nm_per_A is given but torque_from is tau: the "
                      "constants would be ignored; give torque_from: current",
                      who));
  }
  return c;
}

void SignalConversion::torque(const double* raw, const int* index, Eigen::VectorXd* tau_out) const {
  Eigen::VectorXd& tau = *tau_out;
  const auto n = static_cast<Eigen::Index>(sign.size());
  tau.resize(n);
  for (Eigen::Index j = 0; j < n; ++j) {
    const auto u = static_cast<std::size_t>(j);
    const double v = raw[index ? static_cast<std::size_t>(index[u]) : u];
    tau[j] = currents() ? v * torque_constants[u] : v;
  }
  if (currents() && transmission.size() > 0) tau = transmission.transpose() * tau;
  for (Eigen::Index j = 0; j < n; ++j) {
    const auto u = static_cast<std::size_t>(j);
    tau[j] *= sign[u] * tau_scale[u];
  }
}

std::vector<ParamDecl> recordingStepParams() {
  return {
      param_double("resample_hz", 0.0, "Hz",
                   "> 0: the segment is linearly interpolated onto a uniform grid at this rate "
                   "(uneven time stamps, e.g. a logger's jitter, are then accepted; a gap longer "
                   "than max_gap_ratio times the median step is still an error: nothing is "
                   "invented across it); 0: the stamps must be uniform",
                   0.0),
      param_double("measurement_delay_s", 0.0, "s",
                   "a known delay of the torque (and wrench) behind the positions: q, qd, qdd "
                   "of sample k are read at t_k - measurement_delay_s (cubic Hermite "
                   "interpolation, before any filter), the torque stays as recorded; the "
                   "samples at the ends without positions then are dropped and counted "
                   "(meta.measurement_delay); the dataset is then held in memory; 0: none "
                   "(varpro can fit an unknown delay)"),
      param_double("differentiate_cutoff_hz", 0.0, "Hz",
                   "> 0: q of the segment is low-passed (zero-phase Butterworth, filter_order) "
                   "and qd, qdd are its central differences (replacing recorded velocities); "
                   "0: off",
                   0.0),
      param_int("filter_order", 4, "order of that Butterworth filter (per pass)", 1, 12),
      param_bool("filter_torque", false,
                 "with differentiate_cutoff_hz: tau (and the wrench) pass through the same "
                 "zero-phase filter"),
      param_int("decimation", 1,
                "keep one sample in this many after filtering (> 1 needs "
                "differentiate_cutoff_hz and filter_torque, and the cut-off below the new "
                "Nyquist frequency)",
                1, 1e6),
      param_int("trim_edges", -1,
                "samples dropped at each end of the segment after filtering; -1: "
                "ceil(2 fs / cutoff) when filtering, else 0",
                -1, 1e9),
  };
}

RecordingSteps RecordingSteps::fromParams(const ParamSet& p) {
  RecordingSteps s;
  s.resample_hz = p.getDouble("resample_hz");
  s.measurement_delay_s = p.getDouble("measurement_delay_s");
  s.cutoff_hz = p.getDouble("differentiate_cutoff_hz");
  s.filter_order = static_cast<int>(p.getInt("filter_order"));
  s.filter_torque = p.getBool("filter_torque");
  s.decimation = static_cast<int>(p.getInt("decimation"));
  s.trim_edges = p.getInt("trim_edges");
  return s;
}

void RecordingSteps::check(const std::string& who) const {
  if (cutoff_hz <= 0)
    exid::check(
        decimation == 1 && !filter_torque,
        fmt::format("{}: decimation and filter_torque need differentiate_cutoff_hz > 0", who));
  exid::check(decimation == 1 || filter_torque,
              fmt::format("{}: decimation > 1 needs filter_torque: true (the torque must be "
                          "low-passed before samples are dropped)",
                          who));
}

RecordingPipeline::RecordingPipeline(RecordingSteps steps, std::string who)
    : s_(steps), who_(std::move(who)) {
  s_.check(who_);
}

void RecordingPipeline::start(const Dataset& d) {
  if (started_) return;
  started_ = true;
  done_.segment_samples = d.size();
  done_.grid_samples = d.size();
  done_.samples_used = d.size();
}

void RecordingPipeline::unchanged(int samples) {
  check(!s_.needWholeSegment(),
        fmt::format("{}: the filter steps need the segment in memory", who_));
  started_ = true;
  done_.segment_samples = done_.grid_samples = done_.samples_used = samples;
}

Dataset RecordingPipeline::resample(Dataset d) {
  check(!d.streamed(), fmt::format("{}: the filter steps need the segment in memory", who_));
  start(d);
  if (s_.resample_hz <= 0.0) return d;
  done_.resampled_from = d.size();
  done_.resample_hz = s_.resample_hz;
  d = resampleUniform(d, s_.resample_hz, who_);
  done_.resampled_to = done_.grid_samples = done_.samples_used = d.size();
  return d;
}

Dataset RecordingPipeline::compensateDelay(Dataset d) {
  start(d);
  if (s_.measurement_delay_s == 0.0) return d;
  done_.delay_s = s_.measurement_delay_s;
  d = exid::compensateDelay(d, s_.measurement_delay_s, who_ + ": measurement_delay_s",
                            &done_.delay_front, &done_.delay_back);
  done_.grid_samples = done_.samples_used = d.size();
  return d;
}

namespace {
// Rows keep of every signal of d.
void keepRows(const std::vector<Eigen::Index>& keep, Dataset* d) {
  auto pick = [&](const Eigen::MatrixXd& M) {
    Eigen::MatrixXd out(static_cast<Eigen::Index>(keep.size()), M.cols());
    for (std::size_t i = 0; i < keep.size(); ++i)
      out.row(static_cast<Eigen::Index>(i)) = M.row(keep[i]);
    return out;
  };
  Eigen::VectorXd t(static_cast<Eigen::Index>(keep.size()));
  for (std::size_t i = 0; i < keep.size(); ++i) t[static_cast<Eigen::Index>(i)] = d->t[keep[i]];
  d->t = t;
  d->q = pick(d->q);
  d->qd = pick(d->qd);
  d->qdd = pick(d->qdd);
  if (d->tau.rows() > 0) d->tau = pick(d->tau);
  if (d->wrench.rows() > 0) d->wrench = pick(d->wrench);
  if (d->base.rows() > 0) d->base = pick(d->base);
  if (d->contact.rows() > 0) d->contact = pick(d->contact);
}
}  // namespace

Dataset RecordingPipeline::filter(Dataset d) {
  start(d);
  RecordingStepsDone& pp = done_;
  pp.cutoff_hz = s_.cutoff_hz;
  pp.order = s_.filter_order;
  pp.filter_torque = s_.filter_torque;
  pp.decimation = s_.decimation;
  if (pp.cutoff_hz <= 0) return d;
  const Eigen::Index K = d.size();
  check(K >= 8, fmt::format("{}: {} samples in the segment are too few to filter and "
                            "differentiate",
                            who_, K));
  double jitter = 0;
  pp.fs_hz = samplingRate(d.t, &jitter);
  check(pp.cutoff_hz < 0.5 * pp.fs_hz,
        fmt::format("{}: differentiate_cutoff_hz = {} Hz must be below the Nyquist frequency {} "
                    "Hz of the data",
                    who_, pp.cutoff_hz, 0.5 * pp.fs_hz));
  check(pp.decimation == 1 || pp.cutoff_hz < 0.5 * pp.fs_hz / pp.decimation,
        fmt::format("{}: decimation {} leaves a Nyquist frequency of {} Hz, below "
                    "differentiate_cutoff_hz = {} Hz (aliasing)",
                    who_, pp.decimation, 0.5 * pp.fs_hz / pp.decimation, pp.cutoff_hz));
  const Sos sos = butterworthLowpass(pp.order, pp.cutoff_hz, pp.fs_hz);
  d.q = filtfiltColumns(sos, d.q);
  d.qd = centralFirstDerivative(d.t, d.q);
  d.qdd = centralSecondDerivative(d.t, d.q);
  if (pp.filter_torque) {
    if (d.hasTorque()) d.tau = filtfiltColumns(sos, d.tau);
    if (d.hasWrench()) d.wrench = filtfiltColumns(sos, d.wrench);
    if (d.hasContact()) d.contact = filtfiltColumns(sos, d.contact);
  }
  // the base motion is a measured motion (like q): filtered always, not differentiated
  if (d.hasBase()) d.base = filtfiltColumns(sos, d.base);
  // Default trim: the filter's edge transient, 2 fs / fc samples (two periods of the cut-off)
  // at each end, but at most 5 % of the segment at each end, so that a default never discards
  // more than 10 % of a short recording (the zero-phase filter pads its ends by reflection:
  // what is left of the transient there is small). fs is the median step's rate, rounded to
  // the file's resolution (a 100 Hz log is 100 Hz, not 100.0000001: 2 fs / fc = 100, not 101).
  // Every count in double first: ceil(2 fs / cutoff) of a tiny cut-off, or a huge trim_edges,
  // does not fit an int (it was narrowed, wrapped and indexed before the data); a transient
  // longer than the whole segment leaves nothing the filter has not smeared.
  const double transient = 2.0 * pp.fs_hz / pp.cutoff_hz;
  check(std::isfinite(transient) && transient <= static_cast<double>(K),
        fmt::format("{}: differentiate_cutoff_hz = {} Hz is too low for the {} samples of the "
                    "segment at {} Hz: its edge transient 2 fs / fc = {:g} samples is longer "
                    "than the segment; raise the cut-off",
                    who_, pp.cutoff_hz, K, pp.fs_hz, transient));
  pp.trim_transient = static_cast<int>(std::ceil(transient - 1e-6 * std::max(1.0, transient)));
  pp.trim_cap = static_cast<int>(std::floor(0.05 * static_cast<double>(K)));
  pp.trim_default = s_.trim_edges < 0;
  const double trim = s_.trim_edges >= 0
                          ? static_cast<double>(s_.trim_edges)
                          : static_cast<double>(std::min(pp.trim_transient, pp.trim_cap));
  check(static_cast<double>(K) - 2.0 * trim >= 2.0,
        fmt::format("{}: trimming {} samples at each end of the {} of the segment leaves too few "
                    "({}); lower trim_edges or raise differentiate_cutoff_hz = {} Hz",
                    who_, trim, K,
                    s_.trim_edges >= 0 ? "trim_edges" : "trim_edges: -1 trims ceil(2 fs / cutoff)",
                    pp.cutoff_hz));
  pp.trim = static_cast<int>(trim);
  for (const Eigen::MatrixXd* M : {&d.q, &d.qd, &d.qdd})
    check(M->allFinite(),
          fmt::format("{}: the low-pass filter (differentiate_cutoff_hz = {} Hz, filter_order {}, "
                      "sample rate {} Hz) gave non-finite values; raise the cut-off",
                      who_, pp.cutoff_hz, pp.order, pp.fs_hz));
  std::vector<Eigen::Index> keep;
  for (Eigen::Index k = pp.trim; k < K - pp.trim; k += pp.decimation) keep.push_back(k);
  keepRows(keep, &d);
  pp.samples_used = d.size();
  return d;
}

void RecordingPipeline::account(Json* accounting, Json* warnings) const {
  Json& a = *accounting;
  const RecordingStepsDone& pp = done_;
  const int K_grid = pp.grid_samples;
  if (pp.resampled_from > 0) {
    a["resampled_from"] = pp.resampled_from;
    a["resampled_to"] = pp.resampled_to;
    a["resample_hz"] = pp.resample_hz;
  }
  const int trimmed = pp.cutoff_hz > 0 ? 2 * pp.trim : 0;
  a["trimmed_edges"] = trimmed;
  a["trimmed_percent_of_segment"] = 100.0 * trimmed / std::max(1, K_grid);
  a["decimated_away"] = K_grid - trimmed - pp.samples_used;
  a["samples_used"] = pp.samples_used;
  if (trimmed > 0.1 * K_grid)
    warnings->push_back(Json(fmt::format(
        "{}: trim_edges = {} discards {} of the segment's {} samples ({:.1f} %, more than 10 %)",
        who_, pp.trim, trimmed, K_grid, 100.0 * trimmed / K_grid)));
  if (pp.cutoff_hz > 0 && pp.trim_default && pp.trim < pp.trim_transient)
    a["trim_rule"] =
        fmt::format("ceil(2 fs / fc) = {} samples capped at 5 % of the segment: {} at each end",
                    pp.trim_transient, pp.trim);
  else if (pp.cutoff_hz > 0 && pp.trim_default)
    a["trim_rule"] = fmt::format("ceil(2 fs / fc) = {} samples at each end", pp.trim);
}

void RecordingPipeline::describe(Json* meta) const {
  Json& m = *meta;
  const RecordingStepsDone& pp = done_;
  if (pp.cutoff_hz > 0) {
    Json& f = m["differentiated"];
    f = Json::object();
    f["cutoff_hz"] = pp.cutoff_hz;
    f["filter_order"] = pp.order;
    f["filter_torque"] = pp.filter_torque;
    f["trimmed_samples_each_end"] = pp.trim;
    f["decimation"] = pp.decimation;
    f["sample_rate_hz"] = pp.fs_hz;
  }
  if (pp.delay_s != 0.0) {
    Json& td = m["measurement_delay"];
    td["delay_s"] = pp.delay_s;
    td["dropped_samples_front"] = pp.delay_front;
    td["dropped_samples_back"] = pp.delay_back;
  }
}

}  // namespace exid
