// exid — experiment `simulate`: closed-loop forward dynamics of the TRUE robot, integrated by
// SUNDIALS (CVODE BDF with a dense Newton solver, or ARKODE explicit Runge-Kutta), sampled at a
// fixed period, with optional payload, wrist wrench, measurement noise and encoder quantisation.
//
// Plant, in measured coordinates qm (q = T qm + q0, tau_m = T^T tau):
//   Mm(q) qddm + hm(q, qd, qdm) = tau_m
//   Mm = T^T M(q) T + diag(Ia),  hm = T^T h(q, qd) + Fc s(qdm) + Fv qdm + OFF
// M, h from exid::massMatrix / exid::inverseDynamics (gravity included in h) with the payload
// merged into the sensor body; s = sign (exact, default) or tanh(qdm / v_s). Friction beyond
// that (docs/experiments.md): a Coulomb level FcN_j for qdm < 0 (Fc s becomes
// Fc (1 + s)/2 - FcN (1 - s)/2) and a Stribeck term Fs_j s exp(-(|qdm_j| / vs_j)^delta), the
// forms of the `differential` model's nonlinear friction.
// Controllers (reference qr, qdr, qddr in measured coordinates):
//   computed_torque: tau_m = Mm (qddr + kd (qdr - qdm) + kp (qr - qm)) + hm   (true model)
//   pd_feedforward:  tau_m = tau_ff(qr, qdr, qddr) + D0 (kp (qr - qm) + kd (qdr - qdm)),
//                    tau_ff from the robot description WITHOUT payload (all drive terms),
//                    D0 = diag(Mm) at the start of the reference.
// A floating base (runFloating): the base's motion prescribed, the contact wrench solved with the
// joints' accelerations; computed_torque an exact inverse-dynamics simulation, pd_feedforward
// the joints' loop integrated as above.
// The SUNDIALS integrator is integrator.hpp.
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <sundials/sundials_config.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <chrono>
#include <cmath>
#include <initializer_list>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "exid/closed_chain.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/eigen_instances.hpp"
#include "exid/error.hpp"
#include "exid/floating_base.hpp"
#include "exid/interfaces.hpp"
#include "exid/payload.hpp"
#include "exid/sampled_reference.hpp"
#include "integrator.hpp"

namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

// ---------------------------------------------------------------- references
struct Reference {
  virtual ~Reference() = default;
  virtual void eval(double t, VectorXd* q, VectorXd* qd, VectorXd* qdd) const = 0;
  virtual double t0() const = 0;
  virtual double t1() const = 0;  // last time the reference is defined
};

/// Quintic Hermite interpolation of samples (q, qd, qdd at every knot): C2 and exact at knots.
struct SampledReference : Reference {
  exid::Samples s;
  explicit SampledReference(const exid::Samples& r) : s(r) {}
  double t0() const override { return s.t[0]; }
  double t1() const override { return s.t[s.size() - 1]; }
  void eval(double t, VectorXd* q, VectorXd* qd, VectorXd* qdd) const override {
    exid::quinticHermite(s, t, q, qd, qdd);
  }
};

/// q_j(t) = c_j + sum_l a_jl sin(l w t) + b_jl cos(l w t) in JOINT coordinates, mapped to
/// measured coordinates through the transmission.
struct FourierReference : Reference {
  const exid::RobotModel* robot = nullptr;
  double period = 10.0, w = 0.0, duration = 0.0;
  VectorXd c;
  MatrixXd a, b;  // n x H
  double t0() const override { return 0.0; }
  double t1() const override { return duration; }
  void evalJoint(double t, VectorXd* q, VectorXd* qd, VectorXd* qdd) const {
    const int n = static_cast<int>(c.size()), H = static_cast<int>(a.cols());
    *q = c;
    qd->setZero(n);
    qdd->setZero(n);
    for (int l = 1; l <= H; ++l) {
      const double wl = l * w, sn = std::sin(wl * t), cs = std::cos(wl * t);
      for (int j = 0; j < n; ++j) {
        const double A = a(j, l - 1), B = b(j, l - 1);
        (*q)[j] += A * sn + B * cs;
        (*qd)[j] += wl * (A * cs - B * sn);
        (*qdd)[j] += -wl * wl * (A * sn + B * cs);
      }
    }
  }
  void eval(double t, VectorXd* q, VectorXd* qd, VectorXd* qdd) const override {
    VectorXd qj, qdj, qddj;
    evalJoint(t, &qj, &qdj, &qddj);
    exid::jointToMeasured(*robot, qj, qdj, qddj, q, qd, qdd);
  }
};

double finiteOr(double x, double limit, double fallback) {
  return (std::isfinite(x) && std::abs(x) < limit) ? x : fallback;
}

// ---------------------------------------------------------------- the experiment
class SimulateExperiment : public exid::Experiment {
 public:
  static constexpr const char* kName = "simulate";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "closed-loop forward dynamics of the true robot (rigid body + drives + payload), SUNDIALS "
      "CVODE BDF or ARKODE ERK, tracking the excitation trajectory or, without one, a seeded "
      "finite Fourier series per joint (q = c + sum_l a_l sin(l w t) + b_l cos(l w t), "
      "a_l, b_l ~ U(-1,1)/l scaled to amplitude_fraction of the half range about the centre c of "
      "the joint limits and within velocity_fraction of the velocity limits); noise, quantisation";

  static std::vector<exid::ParamDecl> params() {
    using namespace exid;
    std::vector<ParamDecl> p = {
        param_string("integrator", std::string("cvode"),
                     "cvode: CVODE BDF with dense Newton solver; arkode: ARKODE explicit "
                     "Runge-Kutta (ERKStep, default order 4 table)",
                     {"cvode", "arkode"}),
        param_double("rtol", 1e-8, "", "relative tolerance of the integrator", 0.0, 1.0, true),
        param_double("atol", 1e-10, "", "absolute tolerance of the integrator (rad, rad/s)", 0.0,
                     std::nullopt, true),
        param_int("max_steps", 100000, "maximum internal steps between two samples", 1, 1e9),
        param_string("controller", std::string("computed_torque"),
                     "computed_torque (true model, perfect tracking from a state on the "
                     "reference) or pd_feedforward (feedforward from the description without "
                     "payload, PD scaled by the start mass-matrix diagonal)",
                     {"computed_torque", "pd_feedforward"}),
        param_double("kp", 100.0, "1/s^2", "position gain (closed-loop stiffness per unit inertia)",
                     0.0),
        param_double("kd", 20.0, "1/s", "velocity gain (closed-loop damping per unit inertia)",
                     0.0),
        param_bool("drive_terms", true,
                   "include the robot's drive terms (rotor inertia, Coulomb, viscous, offset) in "
                   "the plant"),
        param_string("coulomb", std::string("sign"),
                     "Coulomb friction law of the plant: sign (exact, as the models) or tanh "
                     "(smooth, tanh(qd / coulomb_velocity_scale))",
                     {"sign", "tanh"}),
        param_double("coulomb_velocity_scale", 1e-3, "rad/s",
                     "velocity scale of the tanh Coulomb law", 0.0, std::nullopt, true),
        param_doubles("coulomb_negative_Nm", std::vector<double>{}, "N m",
                      "plant: the Coulomb level for qdm < 0 per drive (one value: every drive); "
                      "the robot's Fc is then the level for qdm > 0; empty: symmetric"),
        param_doubles("stribeck_Nm", std::vector<double>{}, "N m",
                      "plant: Stribeck level Fs per drive (one value: every drive), term Fs s "
                      "exp(-(|qdm| / vs)^stribeck_exponent); empty: none"),
        param_doubles("stribeck_velocity_rad_s", std::vector<double>{}, "rad/s",
                      "plant: Stribeck velocity vs per drive (one value: every drive); required "
                      "with stribeck_Nm"),
        param_double("stribeck_exponent", 2.0, "", "plant: the Stribeck exponent delta", 0.5, 4.0),
        param_double("period_s", 10.0, "s", "own reference: period of the Fourier series", 0.0,
                     std::nullopt, true),
        param_int("harmonics", 5, "own reference: harmonics per joint", 1, 100),
        param_double("amplitude_fraction", 0.5, "",
                     "own reference: peak excursion as a fraction of the half range of each joint",
                     0.0, 1.0, true),
        param_double("velocity_fraction", 0.8, "",
                     "own reference: peak speed as a fraction of each joint's velocity limit", 0.0,
                     1.0, true),
        param_double("sample_period_s", 0.01, "s", "sampling period of the recorded data", 0.0,
                     std::nullopt, true),
        param_double("duration_s", 0.0, "s",
                     "recorded duration; 0: one period (own reference) or the reference's duration",
                     0.0),
        param_double("torque_delay_s", 0.0, "s",
                     "the recorded torque lags the positions by this: tau recorded at t_k is the "
                     "plant's torque at t_k - torque_delay_s (a second integration gives it); "
                     "the samples without one are dropped and counted (meta.torque_delay)"),
        param_doubles("recorded_torque_gain", std::vector<double>{}, "",
                      "per joint (one value: every joint): the recorded torque is this times the "
                      "plant's (a drive gain's error: differential's drive_gains identifies dK = "
                      "1 / gain - 1); empty: 1"),
        param_doubles("drive_torque_gain", std::vector<double>{}, "",
                      "plant: each drive delivers this times the controller's command, which is "
                      "the recorded torque (a true torque constant over the controller's nominal "
                      "one: differential's drive_gains identifies dK = gain - 1; the `iv` and "
                      "`didim` closed loop's convention); one value: every drive; empty: 1"),
        param_doubles("coulomb_load_Nm_per_Nm", std::vector<double>{}, "",
                      "plant: a Coulomb friction FcL |tau_c| s(qdm) growing with the drive's "
                      "command tau_c (differential's coulomb_load); one value: every drive; "
                      "empty: none"),
        param_bool("wrench", false, "record the wrist wrench fx..mz (sensor frame)"),
        param_double("noise_q_rad", 0.0, "rad", "std of Gaussian noise on the recorded q", 0.0),
        param_double("noise_tau_Nm", 0.0, "N m", "std of Gaussian noise on the recorded tau", 0.0),
        param_doubles("noise_wrench", std::vector<double>{0.0}, "N, N m",
                      "std of Gaussian noise on the wrench: [all], [force, moment] or six values",
                      1, 6),
        param_double("encoder_resolution_rad", 0.0, "rad",
                     "quantisation step of the recorded q (after noise); 0: none", 0.0),
        param_bool("output_qd_qdd", true,
                   "record the true qd and qdd; false: only t, q, tau (and wrench), as on a real "
                   "robot"),
        // a floating-base robot (docs/experiments.md, "Floating base")
        param_double("base_omega_rad_s", 0.5, "rad/s",
                     "floating base: amplitude of each harmonic of each base angular velocity "
                     "component (three harmonics of 1/period_s, seeded phases)",
                     0.0),
        param_double("base_acceleration_m_s2", 2.0, "m/s^2",
                     "floating base: amplitude of each harmonic of each world-frame linear "
                     "acceleration component of the base origin",
                     0.0),
        param_string("contact_link", std::string(""),
                     "floating base: the link whose contact (F/T sensor) wrench balances the base "
                     "rows (the base link or a body's link; with controller: pd_feedforward the "
                     "base link)"),
        param_doubles("contact_pose", std::vector<double>{}, "m, rad",
                      "floating base: the contact sensor frame in its link's frame, x y z roll "
                      "pitch yaw (empty: identity)"),
        param_doubles("noise_base", std::vector<double>{0.0}, "rad/s, rad/s^2, m/s^2",
                      "floating base: std of Gaussian noise on the recorded base motion: [all] "
                      "or [omega, alpha, f]"),
        param_doubles("noise_contact", std::vector<double>{0.0}, "N, N m",
                      "floating base: std of Gaussian noise on the contact wrench: [all], "
                      "[force, moment] or six values"),
    };
    for (auto& d : exid::payloadParams("payload attached to the sensor frame")) p.push_back(d);
    return p;
  }

  explicit SimulateExperiment(const exid::ParamSet& p)
      : P_(p), payload_(exid::Payload::fromParams(p)) {
    const auto nw = p.getDoubles("noise_wrench");
    exid::check(nw.size() == 1 || nw.size() == 2 || nw.size() == 6,
                fmt::format("{}: noise_wrench: expected 1, 2 or 6 numbers, found {}", p.context,
                            nw.size()));
    for (int e = 0; e < 6; ++e)
      noise_w_[e] = nw.size() == 1
                        ? nw[0]
                        : (nw.size() == 2 ? nw[e < 3 ? 0 : 1] : nw[static_cast<std::size_t>(e)]);
  }

  exid::Dataset run(std::shared_ptr<const exid::RobotModel> robot, const exid::Samples* reference,
                    const exid::RunContext& ctx) override {
    exid::check(robot != nullptr, "experiment 'simulate': no robot");
    if (robot->floating_base) return runFloating(robot, reference, ctx);
    // what only a floating base uses, refused by name (a fixed base has no base motion or
    // contact wrench to record)
    const std::vector<std::string> fb =
        changedFromDefault({"base_omega_rad_s", "base_acceleration_m_s2", "contact_link",
                            "contact_pose", "noise_base", "noise_contact"});
    exid::check(fb.empty(),
                fmt::format("experiment 'simulate': {} set, but robot '{}' has a fixed base: "
                            "these are a floating base's (its base motion and contact wrench)",
                            fmt::join(fb, ", "), robot->name));
    const auto wall0 = std::chrono::steady_clock::now();
    setUpPlant(robot);
    const int n = n_;
    double duration = P_.getDouble("duration_s");
    const exid::Json refmeta = setUpReference(*robot, reference, ctx, &duration);
    setPdScale();

    // Sample times.
    const double dt = P_.getDouble("sample_period_s"), t0 = ref_->t0();
    const int N = sampleCount(duration, dt);

    exid::Dataset d;
    d.t.resize(N);
    d.q.resize(N, n);
    MatrixXd qd(N, n), qdd(N, n);
    d.tau.resize(N, n);
    const bool want_wrench = P_.getBool("wrench");
    if (want_wrench) d.wrench.resize(N, 6);

    // Integrate.
    VectorXd x(2 * n), qr, qdr, qddr;
    ref_->eval(t0, &qr, &qdr, &qddr);
    x << qr, qdr;
    Integrator integ(loop(), x, t0, P_.getString("integrator"), P_.getDouble("rtol"),
                     P_.getDouble("atol"), P_.getInt("max_steps"));
    const Tracking tr = record(integ, x, t0, dt, N, duration, want_wrench, ctx, &d, &qd, &qdd);
    if (tr.recorded < N) {
      d.t.conservativeResize(tr.recorded);
      d.q.conservativeResize(tr.recorded, n);
      qd.conservativeResize(tr.recorded, n);
      qdd.conservativeResize(tr.recorded, n);
      d.tau.conservativeResize(tr.recorded, n);
      if (want_wrench) d.wrench.conservativeResize(tr.recorded, 6);
      exid::logWarn(
          fmt::format("experiment 'simulate': stopped (cancelled or out of time) after "
                      "{} of {} samples",
                      tr.recorded, N));
    }
    exid::Json delay_meta;
    if (const double delay = P_.getDouble("torque_delay_s"); delay != 0.0 && tr.recorded > 0) {
      VectorXd x0(2 * n);
      ref_->eval(t0, &qr, &qdr, &qddr);
      x0 << qr, qdr;
      delay_meta = delayTorque(delay, t0, x0, &d, &qd, &qdd);
    }
    if (const std::vector<double> g = P_.getDoubles("recorded_torque_gain"); !g.empty()) {
      exid::check(g.size() == 1 || static_cast<int>(g.size()) == n,
                  fmt::format("experiment 'simulate': recorded_torque_gain: expected 1 or {} "
                              "values, found {}",
                              n, g.size()));
      for (int j = 0; j < n; ++j)
        d.tau.col(j) *= g[g.size() == 1 ? 0 : static_cast<std::size_t>(j)];
    }
    addMeasurementNoise(d.size(), want_wrench, ctx.seed, &d);
    if (P_.getBool("output_qd_qdd")) {
      d.qd = std::move(qd);
      d.qdd = std::move(qdd);
    }
    d.source = fmt::format("simulate ({}, seed {})", robot->name, ctx.seed);
    describe(*robot, ctx.seed, integ, refmeta, dt, tr, &d.meta);
    if (!delay_meta.isNull()) d.meta["torque_delay"] = delay_meta;
    d.facts.simulated = plantTruth();
    d.meta["wall_s"] =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    return d;
  }

  struct Tracking {
    double max_err = 0.0;  // the largest |qr - qm| at the samples
    int recorded = 0;
    bool stopped = false;  // cancelled or out of time
  };

  // Sample k's time (the last clamped to the reference's end) into *tk and the state there into
  // *x; false when the run is cancelled or out of time (tr->stopped).
  bool toSample(exid::simulate_experiment::Integrator& integ, int k, int N, double t0, double dt,
                const exid::RunContext& ctx, VectorXd* x, Tracking* tr, double* tk) const {
    *tk = k == N - 1 ? std::min(t0 + k * dt, ref_->t1()) : t0 + k * dt;
    if (k == 0) return true;
    if (ctx.shouldStop()) {
      tr->stopped = true;
      return false;
    }
    integ.advance(*tk, x);
    return true;
  }

  // ---------------------------------------------------------------- floating base
  // A floating-base robot. The base moves along prescribed smooth motions: omega_b(t) three
  // harmonics per component, alpha_b its exact derivative, the orientation R(t) integrated from
  // omega_b, f_b = R^T (a_w(t) - g) with a_w three harmonics per world component and g = the
  // robot's gravity (world frame). The wrench w of ONE contact balances the base rows. Rows:
  // Y pi = [0; tau_delivered] + C w (exid/floating_base.hpp), plus the drive terms of the
  // fixed-base plant on the joint rows (drive_terms: Ia qdd + friction, driveFriction; a joint's
  // friction acts between its two bodies and leaves the base rows unchanged).
  //   computed_torque: an inverse-dynamics simulation, the joints on the reference exactly (the
  //     true model's computed torque from a state on the reference tracks it exactly; kp, kd act
  //     on a zero error): w = (X*_c)^-1 Y_base pi, tau = Y_joint pi - J_c^T w + drive terms; the
  //     orientation by midpoint exponential steps (20 per sample). With coulomb_load_Nm_per_Nm
  //     the drive delivers u = tau_c - FcL |tau_c| s(qd) of its command tau_c (recorded):
  //     tau_c = u / (1 - FcL s sign(u)).
  //   pd_feedforward: the joints' closed loop integrated by SUNDIALS, state [q; qd; quaternion
  //     of R]; at each instant qdd and w solve the base and joint rows together (floatingSolve);
  //     tau_c = tau_ff(qr, qdr, qddr on the base motion; description, all drive terms) +
  //     D0 (kp (qr - q) + kd (qdr - qd)), D0 = the diagonal of the joints' block of the floating
  //     mass matrix (base acceleration prescribed) plus the rotor inertias, at the reference's
  //     start.
  static void fourier3(const Eigen::Matrix<double, 3, 3>& A, const Eigen::Matrix<double, 3, 3>& P,
                       double w, double t, Eigen::Vector3d* x, Eigen::Vector3d* xd) {
    x->setZero();
    xd->setZero();
    for (int c = 0; c < 3; ++c)
      for (int l = 1; l <= 3; ++l) {
        (*x)[c] += A(c, l - 1) / l * std::sin(l * w * t + P(c, l - 1));
        (*xd)[c] += A(c, l - 1) * w * std::cos(l * w * t + P(c, l - 1));
      }
  }

  // The base motion at t with the base's orientation R_wb.
  exid::BaseMotion baseAt(double t, const Eigen::Matrix3d& Rwb) const {
    Eigen::Vector3d w, al, a, ad;
    fourier3(fb_.Aw, fb_.Pw, fb_.wb, t - fb_.t0, &w, &al);
    fourier3(fb_.Aa, fb_.Pa, fb_.wb, t - fb_.t0, &a, &ad);
    exid::BaseMotion b;
    b << w, al, Rwb.transpose() * (a - truth_.gravity);
    return b;
  }

  // The keys among `keys` whose value is not the declared default.
  std::vector<std::string> changedFromDefault(std::initializer_list<const char*> keys) const {
    std::vector<std::string> out;
    for (const exid::ParamDecl& d : params())
      for (const char* k : keys) {
        if (d.name != k || !d.default_value) continue;
        const bool same = d.type == exid::ParamType::Double
                              ? P_.getDouble(k) == std::get<double>(*d.default_value)
                              : exid::formatValue(P_.at(k)) == exid::formatValue(*d.default_value);
        if (!same) out.emplace_back(k);
      }
    return out;
  }

  // What a floating base does not simulate, refused by name.
  void refuseOnFloatingBase(const exid::RobotModel& R, const std::string& who) const {
    exid::check(payload_.empty(), who + ": a payload is not simulated on a floating-base robot");
    exid::check(!P_.getBool("wrench"),
                who +
                    ": the wrist wrench is not simulated on a floating-base robot (the "
                    "contact wrench is recorded: contact_link)");
    for (double v : P_.getDoubles("noise_wrench"))
      exid::check(v == 0.0, who +
                                ": noise_wrench is the wrist wrench's noise, not recorded on a "
                                "floating base: the contact wrench's is noise_contact");
    exid::check(!R.hasTransmission(), who + ": robot '" + R.name +
                                          "' has a transmission (not modelled for a floating "
                                          "base)");
    exid::check(P_.getDouble("torque_delay_s") == 0.0 &&
                    P_.getDoubles("recorded_torque_gain").empty() &&
                    P_.getDoubles("drive_torque_gain").empty(),
                who +
                    ": torque_delay_s, recorded_torque_gain and drive_torque_gain are for "
                    "fixed-base robots");
    if (P_.getString("controller") == "computed_torque") {
      const std::vector<std::string> c =
          changedFromDefault({"integrator", "rtol", "atol", "max_steps"});
      exid::check(c.empty(),
                  fmt::format("{}: {} set, but controller: computed_torque on a floating base is "
                              "an inverse-dynamics simulation (exact tracking, nothing "
                              "integrated): the integrator's settings apply to controller: "
                              "pd_feedforward",
                              who, fmt::join(c, ", ")));
    }
  }

  exid::Dataset runFloating(std::shared_ptr<const exid::RobotModel> robot,
                            const exid::Samples* reference, const exid::RunContext& ctx) {
    const auto wall0 = std::chrono::steady_clock::now();
    const exid::RobotModel& R = *robot;
    const std::string who = "experiment 'simulate' (floating base)";
    refuseOnFloatingBase(R, who);
    const std::string link = P_.getString("contact_link");
    exid::check(!link.empty(),
                who +
                    ": contact_link is needed: the wrench of one contact balances the base "
                    "rows (e.g. a foot's link)");
    fb_.body = exid::floatingBodyIndex(R, link, who + ": contact_link");
    // a wrench on a limb's link reaches the base only through the joints, whose torques are the
    // controller's: about the first joint's axis the base feels that joint's torque alone, so
    // the prescribed base motion cannot be held by it (the rows are singular)
    exid::check(P_.getString("controller") == "computed_torque" || fb_.body == -1,
                fmt::format("{}: contact_link = '{}': controller: pd_feedforward needs the "
                            "contact on the base link ('{}'): a wrench on another link reaches "
                            "the base only through joints whose torques the controller sets, and "
                            "cannot hold the prescribed base motion",
                            who, link, R.base.link));
    const std::vector<double> cp = P_.getDoubles("contact_pose");
    exid::check(cp.empty() || cp.size() == 6,
                fmt::format("{}: contact_pose: expected 6 numbers (x y z roll pitch yaw), found "
                            "{}",
                            who, cp.size()));
    fb_.sensor = cp.empty() ? exid::Pose{} : exid::poseFromXyzRpy(cp.data());
    auto noise3 = [&](const char* key, int k) {
      const std::vector<double> v = P_.getDoubles(key);
      exid::check(v.size() == 1 || v.size() == 3,
                  fmt::format("{}: {}: expected 1 or 3 numbers, found {}", who, key, v.size()));
      return v.size() == 1 ? v[0] : v[static_cast<std::size_t>(k)];
    };
    const std::vector<double> nc = P_.getDoubles("noise_contact");
    exid::check(
        nc.size() == 1 || nc.size() == 2 || nc.size() == 6,
        fmt::format("{}: noise_contact: expected 1, 2 or 6 numbers, found {}", who, nc.size()));
    const std::vector<double> nb = {noise3("noise_base", 0), noise3("noise_base", 1),
                                    noise3("noise_base", 2)};
    n_ = R.dof();
    const int n = n_;
    nominal_ = robot;
    truth_ = R;  // (no payload on a floating base)
    drive_terms_ = P_.getBool("drive_terms");
    tanh_ = P_.getString("coulomb") == "tanh";
    vs_ = P_.getDouble("coulomb_velocity_scale");
    frictionOptions();
    for (std::size_t j = 0; j < fcl_.size(); ++j)
      exid::check(std::abs(fcl_[j]) < 1.0,
                  fmt::format("{}: coulomb_load_Nm_per_Nm: {} (|FcL| < 1 expected: the drive "
                              "must deliver a torque of the command's sign)",
                              who, fcl_[j]));
    computed_torque_ = P_.getString("controller") == "computed_torque";
    kp_ = P_.getDouble("kp");
    kd_ = P_.getDouble("kd");
    double duration = P_.getDouble("duration_s");
    const exid::Json refmeta = setUpReference(R, reference, ctx, &duration);
    const double dt = P_.getDouble("sample_period_s");
    const int N = sampleCount(duration, dt);
    // the base's harmonics (seeded)
    std::mt19937_64 rng(ctx.seed ^ 0x243f6a8885a308d3ull);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int c = 0; c < 3; ++c)
      for (int l = 0; l < 3; ++l) {
        fb_.Aw(c, l) = P_.getDouble("base_omega_rad_s") * u(rng);
        fb_.Pw(c, l) = M_PI * u(rng);
        fb_.Aa(c, l) = P_.getDouble("base_acceleration_m_s2") * u(rng);
        fb_.Pa(c, l) = M_PI * u(rng);
      }
    const double period = reference ? std::max(duration, 1e-9) : P_.getDouble("period_s");
    fb_.wb = 2.0 * M_PI / period;
    fb_.t0 = ref_->t0();
    exid::Dataset d;
    d.t.resize(N);
    d.q.resize(N, n);
    MatrixXd qd(N, n), qdd(N, n);
    d.tau.resize(N, n);
    d.base.resize(N, 9);
    d.contact.resize(N, 6);
    exid::Json& m = d.meta;
    const Tracking tr = computed_torque_
                            ? recordFloatingExact(N, dt, ctx, &d, &qd, &qdd)
                            : recordFloatingLoop(N, dt, duration, ctx, &d, &qd, &qdd, &m);
    if (tr.recorded < N) {
      exid::logWarn(fmt::format("{}: stopped (cancelled or out of time) after {} of {} samples",
                                who, tr.recorded, N));
      d = exid::sliceDataset(d, 0, tr.recorded);
      qd.conservativeResize(tr.recorded, n);
      qdd.conservativeResize(tr.recorded, n);
    }
    // measurement noise
    std::mt19937_64 nrng(ctx.seed ^ 0x5DEECE66Dull);
    std::normal_distribution<double> nd(0.0, 1.0);
    const double sq = P_.getDouble("noise_q_rad"), st = P_.getDouble("noise_tau_Nm"),
                 res = P_.getDouble("encoder_resolution_rad");
    for (int k = 0; k < d.size(); ++k) {
      for (int j = 0; j < n; ++j) {
        if (sq > 0) d.q(k, j) += sq * nd(nrng);
        if (res > 0) d.q(k, j) = res * std::round(d.q(k, j) / res);
        if (st > 0) d.tau(k, j) += st * nd(nrng);
      }
      for (int c = 0; c < 9; ++c)
        if (const double sb = nb[static_cast<std::size_t>(c / 3)]; sb > 0)
          d.base(k, c) += sb * nd(nrng);
      for (int e = 0; e < 6; ++e) {
        const double sc = nc.size() == 1   ? nc[0]
                          : nc.size() == 2 ? nc[e < 3 ? 0 : 1]
                                           : nc[static_cast<std::size_t>(e)];
        if (sc > 0) d.contact(k, e) += sc * nd(nrng);
      }
    }
    if (P_.getBool("output_qd_qdd")) {
      d.qd = std::move(qd);
      d.qdd = std::move(qdd);
    }
    d.source = fmt::format("simulate ({}, floating base, seed {})", R.name, ctx.seed);
    m["robot"] = R.name;
    m["seed"] = exid::Json(static_cast<long long>(ctx.seed));
    m["controller"] = P_.getString("controller");
    m["kp"] = kp_;
    m["kd"] = kd_;
    m["floating_base"] =
        computed_torque_
            ? "inverse-dynamics simulation (computed_torque: the true model's computed torque "
              "from a state on the reference tracks it exactly; kp, kd act on a zero error): the "
              "joints follow the reference exactly; base motion prescribed (three harmonics of "
              "omega and of the world acceleration), orientation integrated; the contact wrench "
              "balances the base rows; the joint torques with the drive terms (drive_terms) and "
              "the plant's friction options"
            : "closed loop (pd_feedforward) integrated by SUNDIALS on the prescribed base motion "
              "(three harmonics of omega and of the world acceleration, orientation integrated "
              "with the joints): at each instant the joints' accelerations and the contact wrench "
              "solve the base and joint rows together; tau = tau_ff(reference on the base "
              "motion; description, all drive terms) + D0 (kp (qr - q) + kd (qdr - qd)), D0 the "
              "diagonal of the joints' block of the floating mass matrix plus the rotor inertias "
              "at the reference's start";
    m["max_tracking_error_rad"] = tr.max_err;
    m["stopped_early"] = tr.stopped;
    m["coulomb"] = tanh_ ? fmt::format("tanh(qd / {})", vs_) : std::string("sign(qd)");
    m["contact_link"] = link;
    m["reference"] = refmeta;
    m["sample_period_s"] = dt;
    m["samples"] = d.size();
    exid::Json& nz = m["noise"];
    nz = exid::Json::object();
    nz["q_rad"] = sq;
    nz["tau_Nm"] = st;
    nz["base"] = exid::Json(nb);
    nz["contact"] = exid::Json(nc);
    nz["encoder_resolution_rad"] = res;
    m["recorded"] = P_.getBool("output_qd_qdd")
                        ? "t q qd qdd tau base contact (true states, noisy q)"
                        : "t q tau base contact (noisy q)";
    d.facts.simulated = plantTruth();
    m["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    return d;
  }

  // computed_torque on a floating base: the joints on the reference, the orientation by midpoint
  // exponential steps, the contact wrench and the torques by inverse dynamics.
  Tracking recordFloatingExact(int N, double dt, const exid::RunContext& ctx, exid::Dataset* d,
                               MatrixXd* qd, MatrixXd* qdd) {
    const exid::RobotModel& R = truth_;
    const int n = n_;
    const double t0 = fb_.t0;
    Tracking tr;
    Eigen::Matrix3d Rwb = Eigen::Matrix3d::Identity();
    double t_prev = t0;
    VectorXd q, qdv, qddv;
    Eigen::Vector3d w, al;
    for (int k = 0; k < N; ++k) {
      if (k > 0 && ctx.shouldStop()) {
        tr.stopped = true;
        break;
      }
      const double tk = t0 + k * dt;
      // orientation: midpoint exponential steps from the previous sample
      constexpr int kSub = 20;
      const double h = (tk - t_prev) / kSub;
      for (int s = 0; s < kSub && h > 0; ++s) {
        fourier3(fb_.Aw, fb_.Pw, fb_.wb, t_prev + (s + 0.5) * h - t0, &w, &al);
        const double ang = w.norm() * h;
        if (ang > 0) Rwb = Rwb * Eigen::AngleAxisd(ang, w.normalized()).toRotationMatrix();
      }
      t_prev = tk;
      const exid::BaseMotion b = baseAt(tk, Rwb);
      ref_->eval(tk, &q, &qdv, &qddv);
      const VectorXd id = exid::floatingInverseDynamics(R, q, qdv, qddv, b);
      const MatrixXd C = exid::contactMap(R, q, fb_.body, fb_.sensor);
      const Eigen::Matrix<double, 6, 1> wc = C.topRows(6).partialPivLu().solve(id.head(6));
      d->t[k] = tk;
      d->q.row(k) = q.transpose();
      qd->row(k) = qdv.transpose();
      qdd->row(k) = qddv.transpose();
      d->tau.row(k) = (id.tail(n) - C.bottomRows(n) * wc).transpose();
      for (int j = 0; j < n && drive_terms_; ++j) {
        const exid::Drive D = exid::driveAt(R, j);
        d->tau(k, j) += D.rotor_inertia * qddv[j] + driveFriction(D, j, qdv[j]);
      }
      for (int j = 0; j < static_cast<int>(fcl_.size()); ++j) {
        const double del = d->tau(k, j);  // what the drive delivers
        const double fl = fcl_[static_cast<std::size_t>(j)] * coulombShape(qdv[j]);
        d->tau(k, j) = del / (1.0 - fl * (del > 0 ? 1.0 : (del < 0 ? -1.0 : 0.0)));
      }
      d->base.row(k) = b.transpose();
      d->contact.row(k) = wc.transpose();
      ++tr.recorded;
    }
    return tr;
  }

  // The joints' accelerations qdd and the contact wrench w at (q, qd) on base motion b under the
  // command tau_c: [A_b, -C_b; A_j + Ia, -C_j] [qdd; w] = [-h_b; u - h_j - friction], A and h
  // from floatingInverseDynamics (exact: it is linear in qdd), u what the drives deliver.
  // `A_joint`: the joint block of A with the rotor inertias (for D0).
  void floatingSolve(double t, const VectorXd& q, const VectorXd& qd, const exid::BaseMotion& b,
                     const VectorXd& tau_c, VectorXd* qdd, Eigen::Matrix<double, 6, 1>* w,
                     MatrixXd* A_joint = nullptr) const {
    const exid::RobotModel& R = truth_;
    const int n = n_;
    const VectorXd h0 = exid::floatingInverseDynamics(R, q, qd, VectorXd::Zero(n), b);
    MatrixXd S(6 + n, n + 6);
    for (int i = 0; i < n; ++i)
      S.col(i) = exid::floatingInverseDynamics(R, q, qd, VectorXd::Unit(n, i), b) - h0;
    S.rightCols(6) = -exid::contactMap(R, q, fb_.body, fb_.sensor);
    VectorXd rhs = -h0;
    for (int j = 0; j < n; ++j) {
      const exid::Drive D = exid::driveAt(R, j);
      if (drive_terms_) {
        S(6 + j, j) += D.rotor_inertia;
        rhs[6 + j] -= driveFriction(D, j, qd[j]);
      }
      double uj = tau_c[j];
      if (!fcl_.empty())
        uj -= fcl_[static_cast<std::size_t>(j)] * std::abs(tau_c[j]) * coulombShape(qd[j]);
      rhs[6 + j] += uj;
    }
    if (A_joint) *A_joint = S.block(6, 0, n, n);
    const Eigen::PartialPivLU<MatrixXd> lu(S);
    const double rc = lu.rcond();
    exid::check(rc > 1e-13,
                fmt::format("experiment 'simulate' (floating base): the contact at '{}' cannot "
                            "hold the prescribed base motion at t = {} s (the joint and base rows "
                            "are singular in the joints' accelerations and the contact wrench: "
                            "reciprocal condition {:.1e}); choose another contact_link",
                            P_.getString("contact_link"), t, rc));
    const VectorXd x = lu.solve(rhs);
    *qdd = x.head(n);
    *w = x.tail(6);
  }

  // The command of pd_feedforward on a floating base at (t, q, qd) on base motion b.
  VectorXd floatingCommand(double t, const VectorXd& q, const VectorXd& qd,
                           const exid::BaseMotion& b) const {
    VectorXd qr, qdr, qddr;
    ref_->eval(std::min(t, ref_->t1()), &qr, &qdr, &qddr);
    VectorXd tau = exid::floatingInverseDynamics(*nominal_, qr, qdr, qddr, b).tail(n_);
    for (int j = 0; j < n_ && drive_terms_; ++j)  // the description's drive terms
      tau[j] += exid::driveTorque(exid::driveAt(*nominal_, j), qdr[j], qddr[j]);
    return tau + D0_.cwiseProduct(kp_ * (qr - q) + kd_ * (qdr - qd));
  }

  // x = [q; qd; quaternion w x y z of R_wb] -> its rate (the quaternion's: q (x) (0, omega_b)/2).
  void floatingRhs(double t, const double* x, double* xd) const {
    const int n = n_;
    Eigen::Map<const VectorXd> q(x, n), qd(x + n, n);
    const Eigen::Quaterniond Q(x[2 * n], x[2 * n + 1], x[2 * n + 2], x[2 * n + 3]);
    const exid::BaseMotion b = baseAt(t, Q.normalized().toRotationMatrix());
    VectorXd qdd;
    Eigen::Matrix<double, 6, 1> w;
    floatingSolve(t, q, qd, b, floatingCommand(t, q, qd, b), &qdd, &w);
    for (int j = 0; j < n; ++j) {
      xd[j] = x[n + j];
      xd[n + j] = qdd[j];
    }
    const Eigen::Vector3d om = b.head<3>(), v(Q.x(), Q.y(), Q.z());
    const Eigen::Vector3d vd = 0.5 * (Q.w() * om + v.cross(om));
    xd[2 * n] = -0.5 * v.dot(om);
    xd[2 * n + 1] = vd[0];
    xd[2 * n + 2] = vd[1];
    xd[2 * n + 3] = vd[2];
  }

  // pd_feedforward on a floating base: the closed loop integrated from a state on the reference
  // (and R_wb = I), sampled every dt; the integrator's and the gains' meta into *m.
  Tracking recordFloatingLoop(int N, double dt, double duration, const exid::RunContext& ctx,
                              exid::Dataset* d, MatrixXd* qd, MatrixXd* qdd, exid::Json* m) {
    const int n = n_;
    const double t0 = fb_.t0;
    VectorXd qr, qdr, qddr;
    ref_->eval(t0, &qr, &qdr, &qddr);
    {  // D0: the joints' block of the floating mass matrix with the rotor inertias, at the start
      MatrixXd A;
      VectorXd a;
      Eigen::Matrix<double, 6, 1> w;
      floatingSolve(t0, qr, qdr, baseAt(t0, Eigen::Matrix3d::Identity()), VectorXd::Zero(n), &a, &w,
                    &A);
      D0_ = A.diagonal();
    }
    VectorXd x(2 * n + 4);
    x << qr, qdr, 1.0, 0.0, 0.0, 0.0;
    Integrator integ([this](double t, const double* y, double* yd) { floatingRhs(t, y, yd); }, x,
                     t0, P_.getString("integrator"), P_.getDouble("rtol"), P_.getDouble("atol"),
                     P_.getInt("max_steps"));
    Tracking tr;
    for (int k = 0; k < N; ++k) {
      double tk = 0.0;
      if (!toSample(integ, k, N, t0, dt, ctx, &x, &tr, &tk)) break;
      const VectorXd q = x.head(n), v = x.segment(n, n);
      const Eigen::Quaterniond Q(x[2 * n], x[2 * n + 1], x[2 * n + 2], x[2 * n + 3]);
      const exid::BaseMotion b = baseAt(tk, Q.normalized().toRotationMatrix());
      const VectorXd tau = floatingCommand(tk, q, v, b);
      VectorXd a;
      Eigen::Matrix<double, 6, 1> w;
      floatingSolve(tk, q, v, b, tau, &a, &w);
      ref_->eval(std::min(tk, ref_->t1()), &qr, &qdr, &qddr);
      tr.max_err = std::max(tr.max_err, (qr - q).cwiseAbs().maxCoeff());
      d->t[k] = tk;
      d->q.row(k) = q.transpose();
      qd->row(k) = v.transpose();
      qdd->row(k) = a.transpose();
      d->tau.row(k) = tau.transpose();
      d->base.row(k) = b.transpose();
      d->contact.row(k) = w.transpose();
      ++tr.recorded;
      if (k % 50 == 0 || k == N - 1)
        ctx.report(static_cast<double>(k + 1) / N,
                   fmt::format("t = {:.3f} s of {:.3f} s", tk - t0, duration));
    }
    exid::Json& M = *m;
    M["integrator"] = integ.description();
    M["sundials_version"] = SUNDIALS_VERSION;
    M["rtol"] = P_.getDouble("rtol");
    M["atol"] = P_.getDouble("atol");
    M["steps"] = exid::Json(static_cast<long long>(integ.steps()));
    M["rhs_evaluations"] = exid::Json(static_cast<long long>(integ.rhsEvals()));
    exid::Json g = exid::Json::object();  // the gains the PD applies: D0 kp, D0 kd
    const VectorXd kp = D0_ * kp_, kd = D0_ * kd_;
    g["kp_Nm_per_rad"] = exid::Json(std::vector<double>(kp.data(), kp.data() + kp.size()));
    g["kd_Nm_s_per_rad"] = exid::Json(std::vector<double>(kd.data(), kd.data() + kd.size()));
    g["scale"] =
        "D0 = diagonal of the joints' block of the floating mass matrix (base acceleration "
        "prescribed) plus the rotor inertias, at the reference's start";
    M["pd_gains"] = g;
    return tr;
  }
  // ---------------------------------------------------------------- dynamics
  // Mm, hm of the plant at measured state (qm, qdm).
  void plantTerms(const VectorXd& qm, const VectorXd& qdm, MatrixXd* Mm, VectorXd* hm) {
    const exid::RobotModel& R = truth_;
    VectorXd q, qd;
    if (R.hasLoops()) {
      // M_a = G^T M G, h_a = G^T tau_tree(q, qd, g) (g = the acceleration bias G'qd_a)
      MatrixXd G;
      VectorXd g;
      exid::closedChainState(R, qm, &qdm, nullptr, &q, &qd, nullptr, &G, &g);
      *Mm = G.transpose() * exid::massMatrix(R, *data_, q) * G;
      *hm = G.transpose() * exid::inverseDynamics(R, *data_, q, qd, g);
    } else {
      exid::measuredToJoint(R, qm, qdm, qdm, &q, &qd, nullptr);
      const MatrixXd M = exid::massMatrix(R, *data_, q);
      const VectorXd h = exid::inverseDynamics(R, *data_, q, qd, VectorXd::Zero(n_));
      if (R.hasTransmission()) {
        *Mm = R.transmission.transpose() * M * R.transmission;
        *hm = R.transmission.transpose() * h;
      } else {
        *Mm = M;
        *hm = h;
      }
    }
    if (!drive_terms_) return;
    for (int j = 0; j < n_; ++j) {
      const exid::Drive D = exid::driveAt(R, j);
      (*Mm)(j, j) += D.rotor_inertia;
      (*hm)[j] += driveFriction(D, j, qdm[j]);
    }
  }

  // The plant's friction torque of drive j (parameters D) at velocity v: Coulomb (symmetric,
  // or asymmetric with coulomb_negative_Nm), Stribeck, viscous and offset.
  double driveFriction(const exid::Drive& D, int j, double v) const {
    const double s = coulombShape(v);
    const auto u = static_cast<std::size_t>(j);
    const double coulomb =
        fcn_.empty() ? D.coulomb * s : D.coulomb * 0.5 * (1 + s) - fcn_[u] * 0.5 * (1 - s);
    const double stribeck =
        fs_.empty() ? 0.0 : fs_[u] * s * std::exp(-std::pow(std::abs(v) / svs_[u], sdelta_));
    return coulomb + stribeck + D.viscous * v + D.offset;
  }

  // The plant's Coulomb law: sign(v) or tanh(v / coulomb_velocity_scale).
  double coulombShape(double v) const {
    return tanh_ ? std::tanh(v / vs_) : (v > 0 ? 1.0 : (v < 0 ? -1.0 : 0.0));
  }

  // Controller torque and the resulting plant acceleration at (t, qm, qdm).
  void control(double t, const VectorXd& qm, const VectorXd& qdm, VectorXd* tau, VectorXd* acc) {
    VectorXd qr, qdr, qddr;
    ref_->eval(std::min(t, ref_->t1()), &qr, &qdr, &qddr);
    MatrixXd Mm;
    VectorXd hm;
    plantTerms(qm, qdm, &Mm, &hm);
    if (computed_torque_) {
      *tau = Mm * (qddr + kd_ * (qdr - qdm) + kp_ * (qr - qm)) + hm;
    } else {
      exid::DriveColumns cols;
      cols.rotor_inertia = cols.coulomb = cols.viscous = cols.offset = drive_terms_;
      *tau = exid::actuatorTorque(*nominal_, *nominal_data_, cols, qr, qdr, qddr) +
             D0_.cwiseProduct(kp_ * (qr - qm) + kd_ * (qdr - qdm));
    }
    Eigen::LLT<MatrixXd> llt(Mm);
    exid::check(llt.info() == Eigen::Success,
                fmt::format("experiment 'simulate': the mass matrix of robot '{}' is not positive "
                            "definite at t = {} s (check masses, inertias and rotor inertias)",
                            truth_.name, t));
    // what the drives deliver for the command *tau (the recorded torque)
    VectorXd u = *tau;
    for (int j = 0; j < n_; ++j) {
      const auto k = static_cast<std::size_t>(j);
      if (!gain_.empty()) u[j] *= gain_[k];
      if (!fcl_.empty()) u[j] -= fcl_[k] * std::abs((*tau)[j]) * coulombShape(qdm[j]);
    }
    *acc = llt.solve(u - hm);
  }

  // x = [qm; qdm] -> xdot = [qdm; qddm]
  void rhs(double t, const double* x, double* xd) {
    Eigen::Map<const VectorXd> X(x, 2 * n_);
    VectorXd tau, acc;
    control(t, X.head(n_), X.tail(n_), &tau, &acc);
    for (int j = 0; j < n_; ++j) {
      xd[j] = x[n_ + j];
      xd[n_ + j] = acc[j];
    }
  }

 private:
  using Integrator = exid::simulate_experiment::Integrator;
  /// The right-hand side of the closed loop for the integrator (rhs()).
  exid::simulate_experiment::Rhs loop() {
    return [this](double t, const double* x, double* xd) { rhs(t, x, xd); };
  }

  std::unique_ptr<FourierReference> buildFourier(const exid::RobotModel& R,
                                                 std::uint64_t seed) const {
    const int n = R.dof(), H = static_cast<int>(P_.getInt("harmonics"));
    auto F = std::make_unique<FourierReference>();
    F->robot = &R;
    F->period = P_.getDouble("period_s");
    F->w = 2.0 * M_PI / F->period;
    F->c.resize(n);
    F->a.resize(n, H);
    F->b.resize(n, H);
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const double af = P_.getDouble("amplitude_fraction"), vf = P_.getDouble("velocity_fraction");
    const int G = 2000;
    for (int j = 0; j < n; ++j) {
      const exid::JointLimits L = j < static_cast<int>(R.limits.size())
                                      ? R.limits[static_cast<std::size_t>(j)]
                                      : exid::JointLimits{};
      double lo = finiteOr(L.q_min, 1e3, -M_PI), hi = finiteOr(L.q_max, 1e3, M_PI);
      if (!(hi > lo)) {
        lo = -M_PI;
        hi = M_PI;
      }
      F->c[j] = 0.5 * (lo + hi);
      for (int l = 1; l <= H; ++l) {
        F->a(j, l - 1) = u(rng) / l;
        F->b(j, l - 1) = u(rng) / l;
      }
      double pmax = 0.0, vmax = 0.0;
      for (int g = 0; g < G; ++g) {
        const double t = F->period * g / G;
        double p = 0.0, v = 0.0;
        for (int l = 1; l <= H; ++l) {
          const double wl = l * F->w;
          p += F->a(j, l - 1) * std::sin(wl * t) + F->b(j, l - 1) * std::cos(wl * t);
          v += wl * (F->a(j, l - 1) * std::cos(wl * t) - F->b(j, l - 1) * std::sin(wl * t));
        }
        pmax = std::max(pmax, std::abs(p));
        vmax = std::max(vmax, std::abs(v));
      }
      double s = pmax > 0 ? af * 0.5 * (hi - lo) / pmax : 0.0;
      const double vlim = finiteOr(L.qd_max, 1e3, HUGE_VAL);
      if (std::isfinite(vlim) && vmax > 0) s = std::min(s, vf * vlim / vmax);
      F->a.row(j) *= s;
      F->b.row(j) *= s;
    }
    return F;
  }

  // The true robot (the description with the payload merged into the sensor body), its
  // dynamics data and the plant's and controller's settings.
  void setUpPlant(const std::shared_ptr<const exid::RobotModel>& robot) {
    nominal_ = robot;
    n_ = robot->dof();
    truth_ = *robot;
    if (!payload_.empty()) {
      const int b = truth_.sensorBody();
      truth_.bodies[static_cast<std::size_t>(b)].inertia +=
          exid::transformInertial(payload_.pi(), truth_.sensor_pose);
    }
    data_ = exid::makeDynamicsData(truth_);
    nominal_data_ = exid::makeDynamicsData(*robot);
    drive_terms_ = P_.getBool("drive_terms");
    tanh_ = P_.getString("coulomb") == "tanh";
    vs_ = P_.getDouble("coulomb_velocity_scale");
    frictionOptions();
    computed_torque_ = P_.getString("controller") == "computed_torque";
    kp_ = P_.getDouble("kp");
    kd_ = P_.getDouble("kd");
  }

  // The reference tracked: the excitation trajectory, or without one a seeded Fourier series;
  // duration: duration_s, 0 replaced by the reference's own. Returns meta.reference.
  exid::Json setUpReference(const exid::RobotModel& robot, const exid::Samples* reference,
                            const exid::RunContext& ctx, double* duration) {
    const int n = n_;
    exid::Json refmeta = exid::Json::object();
    if (reference) {
      exid::check(
          reference->size() >= 1 && reference->dof() == n && reference->qd.cols() == n &&
              reference->qdd.cols() == n && reference->qd.rows() == reference->size() &&
              reference->qdd.rows() == reference->size(),
          fmt::format("experiment 'simulate': the reference trajectory must have q, qd, qdd "
                      "with {} columns (found q {} x {}, qd {} x {}, qdd {} x {})",
                      n, reference->q.rows(), reference->q.cols(), reference->qd.rows(),
                      reference->qd.cols(), reference->qdd.rows(), reference->qdd.cols()));
      for (int k = 1; k < reference->size(); ++k)
        exid::check(reference->t[k] > reference->t[k - 1],
                    fmt::format("experiment 'simulate': reference time must increase (sample {} "
                                "has t = {} after {})",
                                k + 1, reference->t[k], reference->t[k - 1]));
      ref_ = std::make_unique<SampledReference>(*reference);
      const double span = ref_->t1() - ref_->t0();
      if (*duration == 0.0) *duration = span;
      exid::check(*duration <= span * (1 + 1e-12) + 1e-12,
                  fmt::format("experiment 'simulate': duration_s = {} exceeds the reference "
                              "trajectory's duration {} s",
                              *duration, span));
      refmeta["type"] = "excitation trajectory (quintic Hermite through its samples)";
      refmeta["samples"] = reference->size();
    } else {
      auto F = buildFourier(robot, ctx.seed);
      if (*duration == 0.0) *duration = F->period;
      F->duration = *duration;
      refmeta["type"] = "fourier";
      refmeta["period_s"] = F->period;
      refmeta["harmonics"] = static_cast<int>(F->a.cols());
      refmeta["amplitude_fraction"] = P_.getDouble("amplitude_fraction");
      refmeta["velocity_fraction"] = P_.getDouble("velocity_fraction");
      refmeta["seed"] = exid::Json(static_cast<long long>(ctx.seed));
      ref_ = std::move(F);
    }
    exid::check(*duration > 0.0,
                "experiment 'simulate': the duration is zero (a reference with one "
                "sample needs duration_s)");
    return refmeta;
  }

  // D0 for the PD controller: the plant's mass-matrix diagonal at the start of the reference.
  void setPdScale() {
    VectorXd q, qd, qdd;
    ref_->eval(ref_->t0(), &q, &qd, &qdd);
    MatrixXd Mm;
    VectorXd hm;
    plantTerms(q, qd, &Mm, &hm);
    D0_ = Mm.diagonal();
  }

  // The number of samples of `duration` at period dt. The count is checked in double before it
  // sizes anything (the int overflowed, or a huge count ended in bad_alloc): at most kMaxValues
  // values per recorded signal.
  int sampleCount(double duration, double dt) const {
    const int n = n_;
    constexpr double kMaxValues = 2e7;
    const double count = std::floor(duration / dt + 1e-9) + 1.0;
    exid::check(std::isfinite(count) && count * n <= kMaxValues,
                fmt::format("experiment 'simulate': duration_s = {} s / sample_period_s = {} s "
                            "gives {:g} samples x {} joints, more than {:g} values per signal; "
                            "shorten duration_s or lengthen sample_period_s",
                            duration, dt, count, n, kMaxValues));
    const int N = static_cast<int>(count);
    exid::check(N >= 2, fmt::format("experiment 'simulate': duration {} s holds fewer than two "
                                    "samples of {} s",
                                    duration, dt));
    return N;
  }

  // The torque channel `delay` behind the positions: the torque recorded at t_k is the plant's
  // at t_k - delay, from a second integration from the same start (x0 at t0) to those times.
  // The samples whose t_k - delay lies outside [t0, t_last] have none: they are dropped from
  // every signal and counted.
  exid::Json delayTorque(double delay, double t0, const VectorXd& x0, exid::Dataset* d,
                         MatrixXd* qd, MatrixXd* qdd) {
    const int K = static_cast<int>(d->t.size());
    const double t_last = d->t[K - 1];
    int a = 0, b = K;
    while (a < K && d->t[a] - delay < t0) ++a;
    while (b > a && d->t[b - 1] - delay > t_last) --b;
    exid::check(b - a >= 2, fmt::format("experiment 'simulate': torque_delay_s = {} s leaves {} "
                                        "of {} samples",
                                        delay, b - a, K));
    Integrator integ(loop(), x0, t0, P_.getString("integrator"), P_.getDouble("rtol"),
                     P_.getDouble("atol"), P_.getInt("max_steps"));
    VectorXd x = x0, tau, acc;
    double at = t0;
    MatrixXd tau_d(b - a, n_);
    for (int k = a; k < b; ++k) {
      const double tk = d->t[k] - delay;
      if (tk > at) {
        integ.advance(tk, &x);
        at = tk;
      }
      control(tk, x.head(n_), x.tail(n_), &tau, &acc);
      tau_d.row(k - a) = tau.transpose();
    }
    auto keep = [&](MatrixXd* M) {
      if (M->rows() == K) {
        MatrixXd kept = M->middleRows(a, b - a);
        M->swap(kept);
      }
    };
    Eigen::VectorXd t = d->t.segment(a, b - a);
    d->t.swap(t);
    keep(&d->q);
    keep(qd);
    keep(qdd);
    keep(&d->wrench);
    d->tau = std::move(tau_d);
    exid::Json m = exid::Json::object();
    m["delay_s"] = delay;
    m["dropped_samples_front"] = a;
    m["dropped_samples_back"] = K - b;
    m["convention"] = "tau recorded at t is the plant's torque at t - delay_s";
    return m;
  }

  // The closed loop from state x at t0, sampled every dt (N samples; the last at most at the
  // reference's end): states, torques and (want_wrench) the wrist wrench into d, qd, qdd.
  Tracking record(Integrator& integ, VectorXd x, double t0, double dt, int N, double duration,
                  bool want_wrench, const exid::RunContext& ctx, exid::Dataset* d, MatrixXd* qd,
                  MatrixXd* qdd) {
    const int n = n_;
    Tracking tr;
    VectorXd qr, qdr, qddr;
    for (int k = 0; k < N; ++k) {
      double tk = 0.0;
      if (!toSample(integ, k, N, t0, dt, ctx, &x, &tr, &tk)) break;
      const VectorXd qm = x.head(n), qdm = x.tail(n);
      VectorXd tau, acc;
      control(tk, qm, qdm, &tau, &acc);
      ref_->eval(tk, &qr, &qdr, &qddr);
      tr.max_err = std::max(tr.max_err, (qr - qm).cwiseAbs().maxCoeff());
      d->t[k] = tk;
      d->q.row(k) = qm.transpose();
      qd->row(k) = qdm.transpose();
      qdd->row(k) = acc.transpose();
      d->tau.row(k) = tau.transpose();
      if (want_wrench) {
        VectorXd q, v, a;
        exid::measuredToJoint(truth_, qm, qdm, acc, &q, &v, &a);
        Eigen::Matrix<double, 6, 10> A;
        exid::wrenchRegressor(truth_, *data_, q, v, a, A);
        d->wrench.row(k) = (A * payload_.phi()).transpose();
      }
      ++tr.recorded;
      if (k % 50 == 0 || k == N - 1)
        ctx.report(static_cast<double>(k + 1) / N,
                   fmt::format("t = {:.3f} s of {:.3f} s", tk - t0, duration));
    }
    return tr;
  }

  // Measurement noise and quantisation of the recorded samples.
  void addMeasurementNoise(int recorded, bool want_wrench, std::uint64_t seed,
                           exid::Dataset* d) const {
    const int n = n_;
    std::mt19937_64 rng(seed ^ 0x5DEECE66Dull);
    std::normal_distribution<double> nd(0.0, 1.0);
    const double sq = P_.getDouble("noise_q_rad"), st = P_.getDouble("noise_tau_Nm"),
                 res = P_.getDouble("encoder_resolution_rad");
    for (int k = 0; k < recorded; ++k) {
      for (int j = 0; j < n; ++j) {
        if (sq > 0) d->q(k, j) += sq * nd(rng);
        if (res > 0) d->q(k, j) = res * std::round(d->q(k, j) / res);
        if (st > 0) d->tau(k, j) += st * nd(rng);
      }
      if (want_wrench)
        for (int e = 0; e < 6; ++e)
          if (noise_w_[e] > 0) d->wrench(k, e) += noise_w_[e] * nd(rng);
    }
  }

  // What the plant held beyond the robot's parameters (the truth the study is judged against).
  exid::PlantTruth plantTruth() const {
    exid::PlantTruth p;
    p.drive_terms = drive_terms_;
    p.payload = exid::LoadMass{payload_.mass, payload_.com, payload_.I_com};
    p.coulomb_negative_Nm = fcn_;
    p.stribeck_Nm = fs_;
    p.coulomb_load_Nm_per_Nm = fcl_;
    p.recorded_torque_gain = P_.getDoubles("recorded_torque_gain");
    p.drive_torque_gain = gain_;
    return p;
  }

  // The dataset's meta (without wall_s and the plant's truth: Dataset::facts).

  void describe(const exid::RobotModel& robot, std::uint64_t seed, const Integrator& integ,
                const exid::Json& refmeta, double dt, const Tracking& tr, exid::Json* meta) const {
    exid::Json& m = *meta;
    m["robot"] = robot.name;
    m["seed"] = exid::Json(static_cast<long long>(seed));
    m["integrator"] = integ.description();
    m["sundials_version"] = SUNDIALS_VERSION;
    m["rtol"] = P_.getDouble("rtol");
    m["atol"] = P_.getDouble("atol");
    m["steps"] = exid::Json(static_cast<long long>(integ.steps()));
    m["rhs_evaluations"] = exid::Json(static_cast<long long>(integ.rhsEvals() + rhs_calls_extra_));
    m["controller"] = P_.getString("controller");
    m["kp"] = kp_;
    m["kd"] = kd_;
    if (!computed_torque_) {  // the gains the PD applies: D0 kp, D0 kd (the `iv` estimator's)
      exid::Json g = exid::Json::object();
      const VectorXd kp = D0_ * kp_, kd = D0_ * kd_;
      g["kp_Nm_per_rad"] = exid::Json(std::vector<double>(kp.data(), kp.data() + kp.size()));
      g["kd_Nm_s_per_rad"] = exid::Json(std::vector<double>(kd.data(), kd.data() + kd.size()));
      m["pd_gains"] = g;
    }
    m["coulomb"] = tanh_ ? fmt::format("tanh(qd / {})", vs_) : std::string("sign(qd)");
    if (!fs_.empty()) {
      m["stribeck_velocity_rad_s"] = exid::Json(svs_);
      m["stribeck_exponent"] = sdelta_;
    }
    m["reference"] = refmeta;
    m["sample_period_s"] = dt;
    m["samples"] = tr.recorded;
    m["stopped_early"] = tr.stopped;
    m["max_tracking_error_rad"] = tr.max_err;
    exid::Json& nz = m["noise"];
    nz = exid::Json::object();
    nz["q_rad"] = P_.getDouble("noise_q_rad");
    nz["tau_Nm"] = P_.getDouble("noise_tau_Nm");
    nz["wrench"] = exid::Json(std::vector<double>(noise_w_, noise_w_ + 6));
    nz["encoder_resolution_rad"] = P_.getDouble("encoder_resolution_rad");
    m["recorded"] =
        P_.getBool("output_qd_qdd") ? "t q qd qdd tau (true states, noisy q)" : "t q tau (noisy q)";
  }

  // The plant's friction beyond Fc s + Fv qdm, per drive (empty: none).
  void frictionOptions() {
    auto perDrive = [&](const char* key) {
      std::vector<double> v = P_.getDoubles(key);
      exid::check(v.empty() || v.size() == 1 || static_cast<int>(v.size()) == n_,
                  fmt::format("experiment 'simulate': {}: {} values for robot '{}' of {} drives "
                              "(expected one, or one per drive)",
                              key, v.size(), truth_.name, n_));
      if (v.size() == 1) v.assign(static_cast<std::size_t>(n_), v[0]);
      return v;
    };
    fcn_ = perDrive("coulomb_negative_Nm");
    gain_ = perDrive("drive_torque_gain");
    fcl_ = perDrive("coulomb_load_Nm_per_Nm");
    for (double v : gain_)
      exid::check(v > 0 && std::isfinite(v),
                  fmt::format("experiment 'simulate': drive_torque_gain: {} is not positive", v));
    exid::check(gain_.empty() || P_.getDoubles("recorded_torque_gain").empty(),
                "experiment 'simulate': drive_torque_gain and recorded_torque_gain are two "
                "conventions of one gain error: give one");
    fs_ = perDrive("stribeck_Nm");
    svs_ = perDrive("stribeck_velocity_rad_s");
    sdelta_ = P_.getDouble("stribeck_exponent");
    exid::check(fs_.empty() == svs_.empty(),
                "experiment 'simulate': stribeck_Nm and stribeck_velocity_rad_s go together (the "
                "level and the velocity of the Stribeck term)");
    for (double v : svs_)
      exid::check(v > 0, fmt::format("experiment 'simulate': stribeck_velocity_rad_s: {} is not "
                                     "positive",
                                     v));
    exid::check((fcn_.empty() && fs_.empty()) || drive_terms_,
                "experiment 'simulate': coulomb_negative_Nm and stribeck_Nm are drive terms: "
                "they need drive_terms: true");
  }

  exid::ParamSet P_;
  exid::Payload payload_;
  double noise_w_[6] = {0, 0, 0, 0, 0, 0};
  std::shared_ptr<const exid::RobotModel> nominal_;
  exid::RobotModel truth_;
  exid::DynamicsDataPtr data_, nominal_data_;
  std::unique_ptr<Reference> ref_;
  int n_ = 0;
  bool drive_terms_ = true, tanh_ = false, computed_torque_ = true;
  double vs_ = 1e-3, kp_ = 100.0, kd_ = 20.0;
  std::vector<double> fcn_, fs_, svs_;  // plant friction beyond Fc s + Fv qdm (empty: none)
  std::vector<double> gain_, fcl_;      // drive_torque_gain, coulomb_load_Nm_per_Nm (empty: none)
  double sdelta_ = 2.0;
  VectorXd D0_;
  long rhs_calls_extra_ = 0;
  struct FloatingBase {              // a floating base's prescribed motion and its contact
    Eigen::Matrix3d Aw, Pw, Aa, Pa;  // harmonics' amplitudes and phases: omega, world acceleration
    double wb = 0.0, t0 = 0.0;       // fundamental [rad/s], time origin [s]
    int body = -1;                   // the contact's body (-1: the base link)
    exid::Pose sensor;               // the contact sensor frame in its body's frame
  } fb_;
};

}  // namespace

EXID_REGISTER_PLUGIN(SimulateExperiment)
