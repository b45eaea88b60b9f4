// exid — looking at a recording before trusting it (exid inspect, and the `inspection` of
// summary.json written by exid run; docs/real_data.md "Inspecting a recording").
//
// inspectDataset() checks a Dataset against the robot's nominal model: standstill and moving
// segments, the fraction of each joint's range and velocity limit the data covers, a per-joint
// sign check of the measured torque against the nominal model's full torque (rigid bodies and
// drives) at rest and in motion, the delay between measured and predicted torque, and the
// condition number of the regressor the recording gives. The recording-level statistics of a
// file (rate, jitter, gaps, duplicate and frozen rows, saturation) come from the experiment that
// read it (the csv experiment writes them into meta.recording); inspectDataset() turns them into
// warnings as well. Every threshold is one of the named constants below.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "exid/context.hpp"
#include "exid/data.hpp"
#include "exid/export.hpp"
#include "exid/json.hpp"
#include "exid/recording_stats.hpp"
#include "exid/robot_model.hpp"
#include "exid/signal.hpp"  // medianOfValues (formerly here)

namespace exid {

class ObservationModel;

namespace inspect {
/// A sample moves when the velocity of some joint exceeds this fraction of that joint's
/// velocity range (the 99th percentile of |qd_j| over the recording), and at least
/// kStandstillVelocityFloor [rad/s or m/s].
inline constexpr double kStandstillVelocityFraction = 0.05;
inline constexpr double kStandstillVelocityFloor = 1e-3;
/// Moving or standstill stretches shorter than this are merged into their neighbours [s].
inline constexpr double kMinSegmentS = 0.1;
/// Sign check (inspect_torque.cpp): the gain g of the measured torque on the nominal model's,
/// beside friction columns, and its std (residual autocorrelation included). Every verdict holds
/// at kZ std: flipped when g + kZ std < 0; "does not follow" when |g| + kZ std < kNoFollowGain
/// (g not significantly positive); "scale" when g is significantly outside
/// [1 / kGainFactor, kGainFactor]. A joint is checkable only when the model's torque beyond
/// friction varies by more than kSignalOverNoise times the recording's noise on that torque and
/// kZ std of g is below kMaxGainHalfWidth; otherwise "not checkable" (never a warning).
inline constexpr double kZ = 3.0;
inline constexpr double kSignalOverNoise = 3.0;
inline constexpr double kMaxGainHalfWidth = 0.5;
inline constexpr double kNoFollowGain = 0.2;
inline constexpr double kGainFactor = 5.0;
/// Fewest samples a joint is judged on.
inline constexpr int kMinCorrelationSamples = 20;
/// Delay: the regression's residual over lags |l| <= max(kDelayMaxLagS * rate,
/// kDelayMinLagSamples), at most an eighth of the samples. Warned about only when |delay| >=
/// kDelayMinSamples and > kZ std (the std from the spread of the estimates of kDelayParts
/// contiguous parts of the recording), at least two joints are judged and two thirds agree with
/// it, every part gives the same sign within kDelayAgreeSamples or kDelayAgreeFraction of it, and
/// shifting by it lowers the joints' residuals by kDelayMinImprovement on average.
inline constexpr double kDelayMaxLagS = 0.05;
inline constexpr int kDelayMinLagSamples = 10;
inline constexpr double kDelayMinSamples = 1.0;
inline constexpr double kDelayAgreeSamples = 1.0;
inline constexpr double kDelayAgreeFraction = 0.5;
inline constexpr int kDelayParts = 4;
inline constexpr double kDelayMinImprovement = 0.02;
/// Derivatives absent from the data: a quadratic Savitzky-Golay fit whose -3 dB frequency is
/// about this [Hz] (window half-width M = round((1.5 fs / fc + 4.6) / 3.2), at least 2 samples);
/// the torque is smoothed by the same fit (zero phase: no delay).
inline constexpr double kDifferentiateCutoffHz = 20.0;
/// ... lowered by halves, down to kMinDifferentiateCutoffHz, while the derived accelerations'
/// own error (from the positions' resolution or noise) exceeds kMaxDerivedAccelError of their
/// RMS for some joint.
inline constexpr double kMinDifferentiateCutoffHz = 2.5;
inline constexpr double kMaxDerivedAccelError = 0.25;
/// Condition number of the base regressor with columns scaled to unit norm above which the
/// recording is said to excite the base parameters poorly.
inline constexpr double kCondWarn = 1e5;
/// Recording: relative jitter std above which the time stamps are called uneven, fraction of
/// saturated samples of a torque column above which it is warned about, and the fraction of
/// samples outside a joint's position limits above which the offset or units are suspected.
inline constexpr double kJitterStdWarn = 0.05;
inline constexpr double kSaturationWarnFraction = 1e-3;
inline constexpr double kOutsideLimitsWarnFraction = 0.01;
/// At most this many samples per block when the regressor is assembled (memory bound).
inline constexpr int kRegressorBlockSamples = 2000;
}  // namespace inspect

/// The checks on one dataset (measured coordinates, torques in N m or N). `model` may be null
/// (no condition number). Missing qd/qdd are derived from q (see kDifferentiateCutoffHz).
/// Never throws on data it cannot judge: such a check is null with a `note`.
/// regressor_max_samples > 0: the regressor's condition number from every s-th sample, s the
/// smallest stride that keeps at most that many (`regressor.stride`, `regressor.samples_used`);
/// 0: every sample.
EXID_API Json inspectDataset(const RobotModel& robot, const ObservationModel* model,
                             const Dataset& data, const RunContext& ctx,
                             long regressor_max_samples = 0);

/// What an experiment said of its data (meta.warnings: messages dropped, samples cut, ...), each
/// as "WHAT: warning": the words `exid run` puts among a study's warnings (what = "experiment"
/// or "validation") and `exid inspect` prints.
EXID_API std::vector<std::string> experimentWarnings(const Dataset& data, const std::string& what);

/// `exid inspect`'s look at an experiment's data: inspectDataset() plus what the experiment said
/// of them, as `exid run` reports it: its sample accounting (meta.accounting, as `accounting`)
/// and its warnings (experimentWarnings(data, what), first among `warnings`).
EXID_API Json inspectExperimentData(const RobotModel& robot, const ObservationModel* model,
                                    const Dataset& data, const RunContext& ctx,
                                    const std::string& what);

/// A readable text summary of inspectDataset()'s result (several lines).
EXID_API std::string inspectionText(const Json& inspection);

}  // namespace exid
