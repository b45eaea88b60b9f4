// exid — a recording's way to the samples a study uses, shared by the experiments that read
// recordings (csv, rosbag2). One pipeline of small steps:
//   columns -> signals  the experiment's own reader (a file's columns, a bag's messages; bad
//                       rows or messages dropped and counted) with SignalConversion here:
//                       scales, signs, offsets, currents to torques
//   segment / split     exid/segment.hpp: the part of the recording the study uses
//   filters             RecordingPipeline here: resampling onto a uniform grid, a known
//                       measurement delay, a zero-phase low-pass with central differences,
//                       trimmed edges and decimation, each optional
//   samples             the Dataset, with every sample a step dropped counted
//                       (meta.accounting) and what the steps did (meta.differentiated,
//                       meta.measurement_delay)
// The parameters have one declaration (signalConversionParams, recordingStepParams), so an
// experiment that reads recordings offers them all, with the same names, defaults and checks.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "exid/data.hpp"
#include "exid/export.hpp"
#include "exid/json.hpp"
#include "exid/params.hpp"

namespace exid {

/// Whether a recording named by a user is a ROS 2 bag (read by experiment rosbag2, parameter
/// path): a folder holding metadata.yaml or .mcap / .db3 files, or an MCAP or SQLite storage
/// file. Anything else is a CSV file (experiment csv, parameter file).
EXID_API bool isBagPath(const std::filesystem::path& path);

/// The step columns -> signals of a recording, shared by the experiments that read one: the
/// raw values of a joint (a file's column, a message's field) become the robot's measured
/// coordinates. Per joint: q = sign * q_scale * raw + offset_rad; qd, qdd = sign * qd_scale * raw;
/// the torque: raw (torque_from: tau) or a motor current times its torque constant
/// (torque_from: current; current_frame: joint maps the products through the robot's
/// transmission, tau_m = T^T (Kt .* i)), then sign * tau_scale; the wrench: wrench_scale * raw.
struct EXID_API SignalConversion {
  std::vector<double> q_scale, qd_scale, tau_scale, sign, offset_rad;  // one per joint
  std::vector<double> wrench_scale;                                    // fx fy fz mx my mz
  std::vector<double> torque_constants;  // empty: the torque is recorded (torque_from: tau)
  Eigen::MatrixXd transmission;          // set: current_frame joint on a coupled robot

  /// From the parameters of signalConversionParams(), for n joints; `transmission` the robot's
  /// (empty: none). A count or value that does not fit is an exid::Error starting with `who`.
  static SignalConversion fromParams(const ParamSet& p, int n, const Eigen::MatrixXd& transmission,
                                     const std::string& who);
  bool currents() const { return !torque_constants.empty(); }
  double q(int j, double raw) const {
    const auto u = static_cast<std::size_t>(j);
    return sign[u] * q_scale[u] * raw + offset_rad[u];
  }
  /// (qd and qdd alike)
  double qd(int j, double raw) const {
    const auto u = static_cast<std::size_t>(j);
    return sign[u] * qd_scale[u] * raw;
  }
  /// The n raw torque values (torques or currents) into *tau_out (n values): raw[index[j]] for
  /// joint j (index null: raw[j]).
  void torque(const double* raw, const int* index, Eigen::VectorXd* tau_out) const;
  double wrench(int e, double raw) const { return wrench_scale[static_cast<std::size_t>(e)] * raw; }
};

/// The parameters of the signal conversion: q_scale, qd_scale, tau_scale, wrench_scale, sign,
/// offset_rad, torque_from, torque_constants_Nm_per_A, current_frame. `torque_source` says where
/// the torque (or current) values come from, for the documentation of torque_from.
EXID_API std::vector<ParamDecl> signalConversionParams(const std::string& torque_source);

/// The parameters of the filter steps: resample_hz, measurement_delay_s,
/// differentiate_cutoff_hz, filter_order, filter_torque, decimation, trim_edges.
EXID_API std::vector<ParamDecl> recordingStepParams();

/// The filter steps' settings, read from those parameters.
struct EXID_API RecordingSteps {
  double resample_hz = 0.0;          // > 0: linear interpolation onto a uniform grid
  double measurement_delay_s = 0.0;  // != 0: q, qd, qdd read at t - delay (compensateDelay)
  double cutoff_hz = 0.0;            // > 0: zero-phase low-pass of q, central differences
  int filter_order = 4;
  bool filter_torque = false;  // tau and the wrench through the same filter
  int decimation = 1;
  long long trim_edges = -1;  // -1: ceil(2 fs / cutoff), capped at 5 % of the segment per end

  static RecordingSteps fromParams(const ParamSet& p);
  /// Whether a step needs the whole segment in memory (then the recording is not streamed).
  bool needWholeSegment() const {
    return resample_hz > 0.0 || cutoff_hz > 0.0 || measurement_delay_s != 0.0;
  }
  /// Settings that contradict each other (decimation or filter_torque without the filter; a
  /// decimation without filtered torques) are an exid::Error; `who` starts the message.
  void check(const std::string& who) const;
};

/// What the steps did to a segment (counts in samples).
struct EXID_API RecordingStepsDone {
  int segment_samples = 0;  // entering the steps
  int resampled_from = 0;   // > 0: resampled from this many to grid_samples...
  double resample_hz = 0.0;
  int resampled_to = 0;
  double delay_s = 0.0;
  int delay_front = 0, delay_back = 0;  // dropped: no positions at t - delay
  int grid_samples = 0;                 // entering the filter (after resampling and delay)
  double cutoff_hz = 0.0, fs_hz = 0.0;  // the filter (cutoff 0: none) and the rate it saw
  int order = 0, trim = 0, decimation = 1;
  int trim_transient = 0, trim_cap = 0;  // ceil(2 fs / fc), 5 % of the segment
  bool trim_default = false, filter_torque = false;
  int samples_used = 0;  // leaving the steps
};

/// The filter steps run in order on a segment in memory, recording what each did.
/// `who` names the recording in messages (e.g. "experiment 'csv': file.csv").
class EXID_API RecordingPipeline {
 public:
  RecordingPipeline(RecordingSteps steps, std::string who);

  /// Resampling (resample_hz > 0): every signal linearly interpolated onto a uniform grid.
  Dataset resample(Dataset d);
  /// A known measurement delay: q, qd, qdd read at t - delay, the ends without them dropped.
  Dataset compensateDelay(Dataset d);
  /// The low-pass (cutoff_hz > 0): q filtered, qd and qdd its central differences (tau and
  /// the wrench filtered with filter_torque), the edges trimmed, one sample in `decimation`
  /// kept. Without a cut-off the segment passes unchanged.
  Dataset filter(Dataset d);
  /// The three in order.
  Dataset run(Dataset d) { return filter(compensateDelay(resample(std::move(d)))); }
  /// A segment of `samples` the steps leave as it is (a streamed recording: no step is set).
  void unchanged(int samples);

  const RecordingStepsDone& done() const { return done_; }
  /// What the steps did, into the experiment's meta: meta.accounting (resampled_from,
  /// resampled_to, resample_hz, trimmed_edges, trimmed_percent_of_segment, decimated_away,
  /// samples_used, trim_rule), a trim over 10 % of the segment among *warnings,
  /// meta.differentiated and meta.measurement_delay.
  void account(Json* accounting, Json* warnings) const;
  void describe(Json* meta) const;

 private:
  RecordingSteps s_;
  std::string who_;
  RecordingStepsDone done_;
  bool started_ = false;
  void start(const Dataset& d);
};

}  // namespace exid
