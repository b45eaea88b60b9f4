// exid — the torque checks of inspectDataset (private to the core): each joint's measured torque
// against the nominal model's, and the delay between them, with statistics whose thresholds come
// from the recording itself (docs/real_data.md, "Inspecting a recording").
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "exid/json.hpp"

namespace exid::inspect_torque {

/// What the checks read: per sample (rows) and joint (columns).
struct Input {
  const Eigen::MatrixXd* tau = nullptr;         // the torque the checks compare (maybe smoothed)
  const Eigen::MatrixXd* tau_raw = nullptr;     // the recorded torque (its noise level)
  const Eigen::MatrixXd* pred = nullptr;        // the nominal model's full torque
  const Eigen::MatrixXd* pred_rest = nullptr;   // its torque at rest (zero where moving)
  const Eigen::MatrixXd* qd = nullptr;          // velocities
  const std::vector<char>* moving = nullptr;    // per sample: the robot moves
  const Eigen::VectorXd* pred_noise = nullptr;  // per joint: std of pred from derived signals
  double dt = 0;                                // sample period [s]
};

/// The per-joint sign check (jrows[j]["sign_check"]) and its warnings; returns, per joint,
/// whether its torque can carry the delay estimate (checkable and following the model, either
/// sign).
std::vector<char> signCheck(const Input& in, std::vector<Json>* jrows,
                            std::vector<std::string>* warnings);

/// D = J["delay"]: per joint and overall, with standard deviations; a warning only when the
/// delay is significant, consistent across joints and across the two halves of the recording,
/// and shifting by it improves the fit.
void delayCheck(const Input& in, const std::vector<char>& usable, Json& D,
                std::vector<std::string>* warnings);

/// The recording's noise level on one signal: the robust standard deviation of its second
/// differences over sqrt(6) (white noise of std s gives second differences of std s sqrt(6); a
/// smooth signal adds little at the sampling rates of robot logs). NaN for fewer than 8 values.
double noiseLevel(const Eigen::Ref<const Eigen::VectorXd>& x);

}  // namespace exid::inspect_torque
