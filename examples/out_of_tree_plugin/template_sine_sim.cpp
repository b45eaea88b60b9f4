// TEMPLATE (experiment): simulated data without an integrator. The motion is the excitation
// trajectory's samples when the study has one (followed exactly), else one sine per joint,
//   q_j(t) = c_j + A_j sin((j + 1) w t),  w = 2 pi frequency_hz,
// about the centre c_j of the joint's range, A_j a fraction of what its limits allow. The torques
// are the robot's inverse dynamics (exid::inverseDynamics, recursive Newton-Euler with its own
// parameters), mapped to measured coordinates, plus (drive_terms) the drives' Ia qdd + Fc sign(qd)
// + Fv qd + OFF, plus seeded Gaussian noise. facts.simulated (the plant's truth: drive terms or
// none, no payload) tells the runner to judge the estimate against the true parameters (the
// model's fullTruth(plant): here the nominal ones); meta says, for people, what was done.
// Shows: Experiment::run, a Dataset (t, q, qd, qdd, tau, source, meta, facts), the core dynamics
// API.
// To make it yours: change the motion, the plant (friction law, payload) or add sensor effects.
#include <fmt/format.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"

namespace {

double known(double x, double fallback) { return std::abs(x) < 1e100 ? x : fallback; }

class TemplateSineSim final : public exid::Experiment {
 public:
  static constexpr const char* kName = "template_sine_sim";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "simulated data: the excitation trajectory or one sine per joint, torques by inverse "
      "dynamics (RNEA) + drive terms + seeded noise (out-of-tree template)";
  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_double("frequency_hz", 0.2, "Hz", "own motion: joint j moves at (j + 1) f", 0.0,
                           {}, true),
        exid::param_double("amplitude_fraction", 0.5, "",
                           "own motion: fraction of the largest amplitude the limits allow", 0.0,
                           1.0, true),
        exid::param_double("duration_s", 0.0, "s", "own motion: recorded time (0: one period)",
                           0.0),
        exid::param_double("sample_period_s", 0.01, "s", "own motion: sampling period", 0.0, {},
                           true),
        exid::param_bool("drive_terms", true, "add the robot's drive torques"),
        exid::param_double("noise_tau_Nm", 0.0, "N m", "std of Gaussian noise on tau", 0.0),
        exid::param_int("seed", 0, "noise seed (0: the study seed)", 0.0),
    };
  }
  explicit TemplateSineSim(const exid::ParamSet& p) : P_(p) {}

  exid::Dataset run(std::shared_ptr<const exid::RobotModel> robot, const exid::Samples* reference,
                    const exid::RunContext& ctx) override {
    exid::check(robot != nullptr, fmt::format("experiment '{}': no robot", kName));
    const exid::RobotModel& R = *robot;
    exid::Dataset d;
    exid::Json motion = exid::Json::object();
    if (reference) {  // the study's excitation trajectory
      exid::check(reference->dof() == R.dof() && reference->size() >= 2,
                  fmt::format("experiment '{}': the reference has {} joints and {} samples", kName,
                              reference->dof(), reference->size()));
      d.t = reference->t;
      d.q = reference->q;
      d.qd = reference->qd;
      d.qdd = reference->qdd;
      motion["type"] = "the excitation trajectory's samples, followed exactly";
    } else {
      sineMotion(R, &d, &motion);
    }
    const bool drives = P_.getBool("drive_terms");
    const int n = R.dof(), K = d.size();
    d.tau.resize(K, n);
    auto data = exid::makeDynamicsData(R);
    Eigen::VectorXd q, qd, qdd;
    for (int k = 0; k < K; ++k) {
      const Eigen::VectorXd qm = d.q.row(k).transpose(), qdm = d.qd.row(k).transpose(),
                            qddm = d.qdd.row(k).transpose();
      exid::measuredToJoint(R, qm, qdm, qddm, &q, &qd, &qdd);
      Eigen::VectorXd tau = exid::inverseDynamics(R, *data, q, qd, qdd);  // RNEA, rigid bodies
      if (R.hasTransmission()) tau = R.transmission.transpose() * tau;    // tau_m = T^T tau
      for (int j = 0; drives && j < n && j < static_cast<int>(R.drives.size()); ++j) {
        const exid::Drive& D = R.drives[static_cast<std::size_t>(j)];
        const double sg = exid::coulombSign(qdm(j));  // as the models
        tau(j) += D.rotor_inertia * qddm(j) + D.coulomb * sg + D.viscous * qdm(j) + D.offset;
      }
      d.tau.row(k) = tau.transpose();
    }
    const std::uint64_t seed =
        P_.getInt("seed") ? static_cast<std::uint64_t>(P_.getInt("seed")) : ctx.seed;
    const double sigma = P_.getDouble("noise_tau_Nm");
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> N(0.0, 1.0);
    if (sigma > 0)
      for (int k = 0; k < K; ++k)
        for (int j = 0; j < n; ++j) d.tau(k, j) += sigma * N(rng);

    d.source = fmt::format("{} ({}, seed {})", kName, R.name, seed);
    exid::PlantTruth plant;      // the runner compares the estimate with the truth
    plant.drive_terms = drives;  // (no payload: a load model's truth is zero)
    d.facts.simulated = plant;
    d.meta["generator"] = kName;
    d.meta["motion"] = motion;
    d.meta["torques"] = std::string("inverse dynamics (RNEA), the robot's own parameters") +
                        (drives ? " + drive terms Ia qdd + Fc sign(qd) + Fv qd + OFF" : "");
    d.meta["noise"]["tau_Nm"] = sigma;
    d.meta["seed"] = exid::Json(static_cast<long long>(seed));
    d.meta["recorded"] = "t q qd qdd tau (exact q, qd, qdd)";
    return d;
  }

 private:
  void sineMotion(const exid::RobotModel& R, exid::Dataset* d, exid::Json* motion) const {
    const int n = R.dof();
    const double f = P_.getDouble("frequency_hz"), dt = P_.getDouble("sample_period_s");
    const double duration = P_.getDouble("duration_s") > 0 ? P_.getDouble("duration_s") : 1.0 / f;
    const double count = std::floor(duration / dt + 1e-9) + 1.0;
    exid::check(count >= 2 && count * n <= 2e7,
                fmt::format("experiment '{}': {:g} samples of {} joints", kName, count, n));
    const int K = static_cast<int>(count);
    d->t = Eigen::VectorXd::LinSpaced(K, 0.0, (K - 1) * dt);
    d->q = d->qd = d->qdd = Eigen::MatrixXd(K, n);
    Eigen::VectorXd c(n), A(n), w(n);
    for (int j = 0; j < n; ++j) {  // joint coordinates: the limits are theirs
      const exid::JointLimits& L = R.limits[static_cast<std::size_t>(j)];
      const double lo = known(L.q_min, -M_PI), hi = known(L.q_max, M_PI);
      w(j) = 2.0 * M_PI * f * (j + 1);
      c(j) = 0.5 * (lo + hi);
      A(j) = P_.getDouble("amplitude_fraction") *
             std::min({0.5 * (hi - lo), known(L.qd_max, HUGE_VAL) / w(j),
                       known(L.qdd_max, HUGE_VAL) / (w(j) * w(j))});
    }
    Eigen::VectorXd q(n), qd(n), qdd(n), qm, qdm, qddm;
    for (int k = 0; k < K; ++k) {
      const double t = d->t(k);
      for (int j = 0; j < n; ++j) {
        q(j) = c(j) + A(j) * std::sin(w(j) * t);
        qd(j) = A(j) * w(j) * std::cos(w(j) * t);
        qdd(j) = -A(j) * w(j) * w(j) * std::sin(w(j) * t);
      }
      exid::jointToMeasured(R, q, qd, qdd, &qm, &qdm, &qddm);
      d->q.row(k) = qm.transpose();
      d->qd.row(k) = qdm.transpose();
      d->qdd.row(k) = qddm.transpose();
    }
    (*motion)["type"] = "sine per joint: q_j = c_j + A_j sin((j + 1) 2 pi f t), joint coordinates";
    (*motion)["frequency_hz"] = f;
    (*motion)["amplitude_rad"] = exid::Json(std::vector<double>(A.data(), A.data() + n));
    (*motion)["centre_rad"] = exid::Json(std::vector<double>(c.data(), c.data() + n));
    (*motion)["sample_period_s"] = dt;
  }

  exid::ParamSet P_;
};

}  // namespace

EXID_REGISTER_PLUGIN(TemplateSineSim)
