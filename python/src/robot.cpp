// exid — exid.Robot (module exid._exid): a robot built by a robot plugin with an observation model
// bound to it, its parameters, and its dynamics vectorised over samples (arrays as module.cpp
// describes).
#include <Python.h>
#include <fmt/format.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "exid/config.hpp"
#include "exid/context.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/floating_base.hpp"
#include "exid/interfaces.hpp"
#include "module.hpp"

namespace fs = std::filesystem;

namespace exid_python {

namespace {

// ---------------------------------------------------------------- arrays
/// Samples given as (N, n) or (n,) (one sample): their count; a ValueError otherwise.
struct SampleArg {
  InArray a;
  Eigen::Index rows = 0;
  bool single = false;
};

SampleArg sampleArg(const py::handle& obj, const char* name, int n, const char* method,
                    const std::string& robot) {
  SampleArg s;
  try {
    s.a = InArray::ensure(obj);
  } catch (const py::error_already_set&) {
  }
  if (!s.a)
    throw py::value_error(
        fmt::format("{}: {} must be an array of numbers shaped (N, {})", method, name, n));
  if (s.a.ndim() == 1 && s.a.shape(0) == n) {
    s.rows = 1;
    s.single = true;
  } else if (s.a.ndim() == 2 && s.a.shape(1) == n) {
    s.rows = s.a.shape(0);
  } else {
    std::string shape = "(";
    for (py::ssize_t i = 0; i < s.a.ndim(); ++i)
      shape += (i ? ", " : "") + std::to_string(s.a.shape(i));
    shape += s.a.ndim() == 1 ? ",)" : ")";
    throw py::value_error(
        std::string(name) == "base"
            ? fmt::format("{}: base has shape {}; expected (N, 9) or (9,): omega, alpha, f = "
                          "a - g of the base, base frame",
                          method, shape)
            : fmt::format("{}: {} has shape {}; expected (N, {}) or ({},) for robot '{}' ({} "
                          "joints)",
                          method, name, shape, n, n, robot, n));
  }
  return s;
}

/// The same number of samples in every argument (each a SampleArg).
void sameRows(const std::vector<const SampleArg*>& args, const std::vector<const char*>& names,
              const char* method) {
  for (std::size_t i = 1; i < args.size(); ++i)
    if (args[i]->rows != args[0]->rows || args[i]->single != args[0]->single)
      throw py::value_error(fmt::format("{}: {} has {} samples but {} has {}", method, names[i],
                                        args[i]->rows, names[0], args[0]->rows));
}

/// A new C-order array: (N, dims...) or (dims...) for a single sample.
OutArray newArray(Eigen::Index rows, bool single, std::vector<py::ssize_t> dims) {
  if (!single) dims.insert(dims.begin(), static_cast<py::ssize_t>(rows));
  return OutArray(dims);
}

// ---------------------------------------------------------------- Robot
/// A robot built by a robot plugin, with an observation model bound to it (the columns of the
/// standard and base parameters). Coordinates are the robot's MEASURED coordinates (joint
/// coordinates unless the robot has a transmission), as in studies and `exid eval`.
class PyRobot {
 public:
  PyRobot(const std::string& type, const std::string& params, const std::string& model,
          const std::string& model_params, const std::string& base_dir, std::uint64_t seed) {
    exid::Registry& reg = registry();
    const fs::path dir = base_dir.empty() ? fs::current_path() : fs::path(base_dir);
    const exid::PluginInfo& info = reg.get(exid::PluginKind::Robot, type);
    exid::ParamSet ps = exid::resolveParams(info, params, "robot " + type, dir);
    exid::RunContext ctx;
    ctx.study_dir = dir;
    ctx.seed = seed;
    plugin_ = reg.create<exid::Robot>(type, ps);
    robot_ = plugin_->build(ctx);
    // A floating base: only the floating_base model's rows apply (they take the base motion).
    if (robot_->floating_base && model != "floating_base")
      throw py::value_error(fmt::format(
          "Robot: robot '{}' has a floating base: give model='floating_base' (model '{}' needs "
          "a fixed base); its per-sample dynamics are floating_regressor and "
          "floating_inverse_dynamics, which take the base motion",
          robot_->name, model));
    type_ = type;
    const exid::PluginInfo& mi = reg.get(exid::PluginKind::Model, model);
    model_ = reg.create<exid::ObservationModel>(
        model, exid::resolveParams(mi, model_params, "model " + model, dir));
    model_->bind(robot_, ctx);
    per_sample_ = model_->specs().per_sample;
  }

  const exid::RobotModel& r() const { return *robot_; }
  int dof() const { return robot_->dof(); }
  std::string name() const { return robot_->name; }
  std::string type() const { return type_; }
  std::string modelType() const { return model_->pluginName(); }

  std::vector<std::string> jointNames() const {
    std::vector<std::string> out;
    for (const auto& b : r().bodies) out.push_back(b.joint_name);
    return out;
  }
  std::vector<std::string> linkNames() const {
    std::vector<std::string> out;
    for (const auto& b : r().bodies) out.push_back(b.name);
    return out;
  }
  std::vector<std::string> jointTypes() const {
    std::vector<std::string> out;
    for (const auto& b : r().bodies)
      out.push_back(b.type == exid::JointType::Revolute ? "revolute" : "prismatic");
    return out;
  }
  std::vector<int> parents() const {
    std::vector<int> out;
    for (const auto& b : r().bodies) out.push_back(b.parent);
    return out;
  }
  py::dict limits() const {
    const int n = dof();
    Eigen::VectorXd lo(n), hi(n), qd(n), qdd(n), tau(n);
    for (int j = 0; j < n; ++j) {
      const auto& L = r().limits[static_cast<std::size_t>(j)];
      auto inf = [](double v) { return std::abs(v) >= 1e300 ? std::copysign(INFINITY, v) : v; };
      lo(j) = inf(L.q_min);
      hi(j) = inf(L.q_max);
      qd(j) = inf(L.qd_max);
      qdd(j) = inf(L.qdd_max);
      tau(j) = inf(L.tau_max);
    }
    py::dict d;
    d["q_min"] = vec(lo);
    d["q_max"] = vec(hi);
    d["qd_max"] = vec(qd);
    d["qdd_max"] = vec(qdd);
    d["tau_max"] = vec(tau);
    return d;
  }
  py::array_t<double> gravity() const { return vec(r().gravity); }
  py::object transmission() const {
    if (!r().hasTransmission()) return py::none();
    return mat(r().transmission);
  }
  std::vector<std::string> notes() const { return r().notes; }
  std::vector<std::string> warnings() const { return r().warnings; }
  int sensorBody() const { return r().sensorBody(); }
  py::array_t<double> sensorPose() const { return pose(r().sensor_pose); }

  // Parameters.
  std::vector<std::string> inertialNames() const { return r().inertialParameterNames(); }
  py::array_t<double> inertialValues() const { return vec(r().inertialParameters()); }
  std::vector<std::string> standardNames() const { return model_->fullNames(); }
  py::array_t<double> standardValues() const { return vec(model_->fullNominal()); }
  std::vector<std::string> baseNames() const { return model_->base().names; }
  std::vector<std::string> baseExpressions() const { return model_->base().expressions; }
  py::array_t<double> baseValues() const { return vec(model_->baseNominal()); }
  py::array_t<double> baseMatrix() const { return mat(model_->base().K); }
  std::vector<int> baseIndependent() const { return model_->base().independent; }
  double baseTolerance() const { return model_->base().tolerance; }

  py::tuple randomSamples(int count, std::uint64_t seed) const {
    if (count < 1) throw py::value_error("random_samples: count must be at least 1");
    const exid::Samples s = model_->randomSamples(count, seed);
    return py::make_tuple(mat(s.q), mat(s.qd), mat(s.qdd));
  }

  // A closed chain (loop-closure joints) is not handled by the per-sample methods yet.
  void refuseLoops(const char* method) const {
    if (r().floating_base)
      throw py::value_error(fmt::format(
          "{}: robot '{}' has a floating base: the fixed-base per-sample dynamics do not apply; "
          "use floating_regressor and floating_inverse_dynamics (they take the base motion: "
          "omega, alpha, f = a - g in the base frame)",
          method, name()));
    if (r().hasLoops())
      throw py::value_error(fmt::format(
          "{}: robot '{}' is a closed chain ({} actuated of {} tree joints); the Python "
          "per-sample dynamics do not handle loop-closure joints yet (use a study)",
          method, name(), r().dof(), r().numJoints()));
  }

  // ------------------------------------------------ dynamics, vectorised over samples
  enum class What { Rnea, Torque, Inertial, Payload, Wrench, Mass };

  /// One loop for the per-sample quantities: q, qd, qdd (measured) -> joint coordinates -> out.
  OutArray perSample(What what, const py::handle& q_in, const py::handle& qd_in,
                     const py::handle& qdd_in, const py::object& pi_in, const char* method) const {
    refuseLoops(method);
    const int n = dof();
    const SampleArg q = sampleArg(q_in, "q", n, method, name());
    const bool needs_rates = what != What::Mass;
    SampleArg qd, qdd;
    if (needs_rates) {
      qd = sampleArg(qd_in, "qd", n, method, name());
      qdd = sampleArg(qdd_in, "qdd", n, method, name());
      sameRows({&q, &qd, &qdd}, {"q", "qd", "qdd"}, method);
    }
    Eigen::VectorXd pi;
    const bool own_pi = !pi_in.is_none();
    if (own_pi) {
      InArray p = InArray::ensure(pi_in);
      if (!p || p.ndim() != 1 || p.shape(0) != 10 * n)
        throw py::value_error(fmt::format(
            "{}: parameters must be a vector of {} standard inertial parameters (10 per body, "
            "Robot.inertial_parameter_names)",
            method, 10 * n));
      pi = Eigen::Map<const Eigen::VectorXd>(p.data(), 10 * n);
    }
    const Eigen::Index K = q.rows;
    std::vector<py::ssize_t> dims;
    switch (what) {
      case What::Rnea:
      case What::Torque:
        dims = {n};
        break;
      case What::Inertial:
        dims = {n, 10 * n};
        break;
      case What::Payload:
        dims = {n, 10};
        break;
      case What::Wrench:
        dims = {6, 10};
        break;
      case What::Mass:
        dims = {n, n};
        break;
    }
    OutArray out = newArray(K, q.single, dims);
    double* o = out.mutable_data();
    const double* Q = q.a.data();
    const double* QD = needs_rates ? qd.a.data() : nullptr;
    const double* QDD = needs_rates ? qdd.a.data() : nullptr;
    const exid::RobotModel& R = r();
    {
      py::gil_scoped_release nogil;
      auto data = exid::makeDynamicsData(R);
      exid::DriveColumns drives;
      drives.rotor_inertia = drives.coulomb = drives.viscous = drives.offset = true;
      const bool T = R.hasTransmission();
      Eigen::VectorXd qm(n), qdm = Eigen::VectorXd::Zero(n), qddm = Eigen::VectorXd::Zero(n);
      Eigen::VectorXd qj(n), qdj(n), qddj(n), tau(n);
      Eigen::MatrixXd Y(n, 10 * n), Yp(n, 10), M(n, n);
      Eigen::Matrix<double, 6, 10> A;
      std::size_t block = 1;
      for (py::ssize_t d : dims) block *= static_cast<std::size_t>(d);
      for (Eigen::Index k = 0; k < K; ++k) {
        qm = Eigen::Map<const Eigen::VectorXd>(Q + k * n, n);
        if (needs_rates) {
          qdm = Eigen::Map<const Eigen::VectorXd>(QD + k * n, n);
          qddm = Eigen::Map<const Eigen::VectorXd>(QDD + k * n, n);
        }
        double* ok = o + static_cast<std::size_t>(k) * block;
        if (what == What::Torque) {
          Eigen::Map<Eigen::VectorXd>(ok, n) =
              exid::actuatorTorque(R, *data, drives, qm, qdm, qddm);
          continue;
        }
        exid::measuredToJoint(R, qm, qdm, qddm, &qj, &qdj, &qddj);
        switch (what) {
          case What::Rnea:
            tau = exid::inverseDynamics(R, *data, qj, qdj, qddj, own_pi ? &pi : nullptr);
            if (T) tau = R.transmission.transpose() * tau;
            Eigen::Map<Eigen::VectorXd>(ok, n) = tau;
            break;
          case What::Inertial:
            exid::torqueRegressor(R, *data, qj, qdj, qddj, Y);
            if (T)
              Eigen::Map<RowMajor>(ok, n, 10 * n) = R.transmission.transpose() * Y;
            else
              Eigen::Map<RowMajor>(ok, n, 10 * n) = Y;
            break;
          case What::Payload:
            exid::payloadTorqueRegressor(R, *data, qj, qdj, qddj, Yp);
            if (T)
              Eigen::Map<RowMajor>(ok, n, 10) = R.transmission.transpose() * Yp;
            else
              Eigen::Map<RowMajor>(ok, n, 10) = Yp;
            break;
          case What::Wrench: {
            exid::wrenchRegressor(R, *data, qj, qdj, qddj, A);
            Eigen::Map<Eigen::Matrix<double, 6, 10, Eigen::RowMajor>> out_A(ok);
            out_A = A;
            break;
          }
          case What::Mass:
            M = exid::massMatrix(R, *data, qj, own_pi ? &pi : nullptr);
            if (T)
              Eigen::Map<RowMajor>(ok, n, n) = R.transmission.transpose() * M * R.transmission;
            else
              Eigen::Map<RowMajor>(ok, n, n) = M;
            break;
          case What::Torque:
            break;
        }
      }
    }
    return out;
  }

  py::tuple energyRegressor(const py::handle& q_in, const py::handle& qd_in) const {
    const char* method = "energy_regressor";
    refuseLoops(method);
    const int n = dof(), p = 10 * n;
    const SampleArg q = sampleArg(q_in, "q", n, method, name());
    const SampleArg qd = sampleArg(qd_in, "qd", n, method, name());
    sameRows({&q, &qd}, {"q", "qd"}, method);
    const Eigen::Index K = q.rows;
    OutArray kin = newArray(K, q.single, {p}), pot = newArray(K, q.single, {p});
    double* ko = kin.mutable_data();
    double* po = pot.mutable_data();
    const double* Q = q.a.data();
    const double* QD = qd.a.data();
    const exid::RobotModel& R = r();
    {
      py::gil_scoped_release nogil;
      auto data = exid::makeDynamicsData(R);
      Eigen::VectorXd qm(n), qdm(n), zero = Eigen::VectorXd::Zero(n), qj(n), qdj(n), qddj(n);
      Eigen::RowVectorXd kr(p), pr(p);
      for (Eigen::Index k = 0; k < K; ++k) {
        qm = Eigen::Map<const Eigen::VectorXd>(Q + k * n, n);
        qdm = Eigen::Map<const Eigen::VectorXd>(QD + k * n, n);
        exid::measuredToJoint(R, qm, qdm, zero, &qj, &qdj, &qddj);
        exid::energyRegressor(R, *data, qj, qdj, kr, pr);
        Eigen::Map<Eigen::RowVectorXd>(ko + k * p, p) = kr;
        Eigen::Map<Eigen::RowVectorXd>(po + k * p, p) = pr;
      }
    }
    return py::make_tuple(kin, pot);
  }

  /// The model's rows on samples: full (standard) columns or base columns. A per-sample model
  /// gives (N, rows per sample, columns), computed in chunks of samples; another model (rows
  /// over windows of samples) gives its stacked rows (rows, columns).
  OutArray modelRows(bool base, const py::handle& q_in, const py::handle& qd_in,
                     const py::handle& qdd_in, const py::object& t_in,
                     const py::object& base_in) const {
    const char* method = base ? "base_regressor" : "regressor";
    const int n = dof();
    const SampleArg q = sampleArg(q_in, "q", n, method, name());
    const SampleArg qd = sampleArg(qd_in, "qd", n, method, name());
    const SampleArg qdd = sampleArg(qdd_in, "qdd", n, method, name());
    sameRows({&q, &qd, &qdd}, {"q", "qd", "qdd"}, method);
    SampleArg bm;
    if (r().floating_base) {
      if (base_in.is_none())
        throw py::value_error(fmt::format(
            "{}: robot '{}' has a floating base: give its motion base (N, 9): omega, alpha, "
            "f = a - g in the base frame",
            method, name()));
      bm = sampleArg(base_in, "base", 9, method, name());
      sameRows({&q, &bm}, {"q", "base"}, method);
    } else if (!base_in.is_none()) {
      throw py::value_error(fmt::format(
          "{}: base (the motion of a floating base) is given, but robot '{}' has a fixed base",
          method, name()));
    }
    const Eigen::Index K = q.rows;
    Eigen::VectorXd t;
    if (!t_in.is_none()) {
      InArray ta = InArray::ensure(t_in);
      if (!ta || ta.ndim() != 1 || ta.shape(0) != K)
        throw py::value_error(fmt::format("{}: t must be a vector of {} times [s]", method, K));
      t = Eigen::Map<const Eigen::VectorXd>(ta.data(), K);
    } else if (!per_sample_) {
      throw py::value_error(fmt::format(
          "{}: model '{}' forms rows over windows of samples: give their times t (N,) [s]", method,
          model_->pluginName()));
    } else {
      t = Eigen::VectorXd::LinSpaced(K, 0.0, static_cast<double>(K - 1));
    }
    const int cols = base ? model_->numBase() : static_cast<int>(model_->fullNames().size());
    auto samplesOf = [&](Eigen::Index b, Eigen::Index e) {
      exid::Samples s;
      s.t = t.segment(b, e - b);
      s.q = Eigen::Map<const RowMajor>(q.a.data() + b * n, e - b, n);
      s.qd = Eigen::Map<const RowMajor>(qd.a.data() + b * n, e - b, n);
      s.qdd = Eigen::Map<const RowMajor>(qdd.a.data() + b * n, e - b, n);
      if (r().floating_base) s.base = Eigen::Map<const RowMajor>(bm.a.data() + b * 9, e - b, 9);
      return s;
    };
    auto rowsOf = [&](const exid::Samples& s) {
      return base ? model_->design(s) : model_->fullDesign(s);
    };
    if (!per_sample_) {
      Eigen::MatrixXd W;
      {
        py::gil_scoped_release nogil;
        W = rowsOf(samplesOf(0, K));
      }
      OutArray out({static_cast<py::ssize_t>(W.rows()), static_cast<py::ssize_t>(cols)});
      Eigen::Map<RowMajor>(out.mutable_data(), W.rows(), cols) = W;
      return out;
    }
    // Rows per sample, from the first sample.
    Eigen::Index per = 0;
    {
      py::gil_scoped_release nogil;
      per = rowsOf(K > 0 ? samplesOf(0, 1) : model_->randomSamples(1, 1)).rows();
    }
    OutArray out = newArray(K, q.single, {static_cast<py::ssize_t>(per), cols});
    double* o = out.mutable_data();
    {
      py::gil_scoped_release nogil;
      const Eigen::Index chunk = 512;
      for (Eigen::Index b = 0; b < K; b += chunk) {
        const Eigen::Index e = std::min(K, b + chunk);
        const Eigen::MatrixXd W = rowsOf(samplesOf(b, e));
        exid::check(W.rows() == (e - b) * per,
                    fmt::format("{}: model '{}' gave {} rows for {} samples (expected {} per "
                                "sample)",
                                method, model_->pluginName(), W.rows(), e - b, per));
        Eigen::Map<RowMajor>(o + b * per * cols, W.rows(), cols) = W;
      }
    }
    return out;
  }

  /// A floating base's per-sample dynamics: the floating regressor (N, 6 + n, 10 (n + 1)) or
  /// the inverse dynamics [w_base; tau] (N, 6 + n) by Newton-Euler, with the description's
  /// floating parameters or `parameters` (10 (n + 1): the base link's, then the bodies').
  OutArray floatingDynamics(bool regressor, const py::handle& q_in, const py::handle& qd_in,
                            const py::handle& qdd_in, const py::handle& base_in,
                            const py::object& pi_in) const {
    const char* method = regressor ? "floating_regressor" : "floating_inverse_dynamics";
    if (!r().floating_base)
      throw py::value_error(fmt::format(
          "{}: robot '{}' has a fixed base (use rnea, inertial_regressor)", method, name()));
    if (r().hasTransmission())
      throw py::value_error(
          fmt::format("{}: robot '{}' has a transmission; the floating-base functions take joint "
                      "coordinates",
                      method, name()));
    const int n = dof(), m = 6 + n, p = 10 * (n + 1);
    const SampleArg q = sampleArg(q_in, "q", n, method, name());
    const SampleArg qd = sampleArg(qd_in, "qd", n, method, name());
    const SampleArg qdd = sampleArg(qdd_in, "qdd", n, method, name());
    const SampleArg bm = sampleArg(base_in, "base", 9, method, name());
    sameRows({&q, &qd, &qdd, &bm}, {"q", "qd", "qdd", "base"}, method);
    Eigen::VectorXd pi;
    if (!pi_in.is_none()) {
      InArray a = InArray::ensure(pi_in);
      if (!a || a.ndim() != 1 || a.shape(0) != p)
        throw py::value_error(fmt::format(
            "{}: parameters must be a vector of {} floating parameters (10 for the base link, "
            "then 10 per body: floating_parameter_names)",
            method, p));
      pi = Eigen::Map<const Eigen::VectorXd>(a.data(), p);
    }
    const Eigen::Index K = q.rows;
    OutArray out = regressor ? newArray(K, q.single, {m, p}) : newArray(K, q.single, {m});
    double* o = out.mutable_data();
    {
      py::gil_scoped_release nogil;
      Eigen::MatrixXd Y;
      for (Eigen::Index k = 0; k < K; ++k) {
        const Eigen::VectorXd qk = Eigen::Map<const Eigen::VectorXd>(q.a.data() + k * n, n);
        const Eigen::VectorXd qdk = Eigen::Map<const Eigen::VectorXd>(qd.a.data() + k * n, n);
        const Eigen::VectorXd qddk = Eigen::Map<const Eigen::VectorXd>(qdd.a.data() + k * n, n);
        const exid::BaseMotion b = Eigen::Map<const exid::BaseMotion>(bm.a.data() + k * 9);
        if (regressor) {
          exid::floatingRegressor(r(), qk, qdk, qddk, b, Y);
          Eigen::Map<RowMajor>(o + k * m * p, m, p) = Y;
        } else {
          Eigen::Map<Eigen::VectorXd>(o + k * m, m) =
              exid::floatingInverseDynamics(r(), qk, qdk, qddk, b, pi.size() ? &pi : nullptr);
        }
      }
    }
    return out;
  }
  bool floatingBase() const { return r().floating_base; }
  std::vector<std::string> floatingNames() const {
    if (!r().floating_base) return {};
    return exid::floatingParameterNames(r());
  }
  py::object floatingValues() const {
    if (!r().floating_base) return py::none();
    return vec(exid::floatingParameters(r()));
  }

  py::array_t<double> bodyPose(const py::handle& q_in, int body) const {
    const int n = dof();
    if (body < -1 || body >= n)
      throw py::value_error(
          fmt::format("body_pose: body {} out of range [0, {}) (-1: the sensor "
                      "frame)",
                      body, n));
    const SampleArg q = sampleArg(q_in, "q", n, "body_pose", name());
    const Eigen::Index K = q.rows;
    OutArray out = newArray(K, q.single, {4, 4});
    double* o = out.mutable_data();
    const exid::RobotModel& R = r();
    {
      py::gil_scoped_release nogil;
      auto data = exid::makeDynamicsData(R);
      Eigen::VectorXd qm(n), z = Eigen::VectorXd::Zero(n), qj(n), qdj(n), qddj(n);
      for (Eigen::Index k = 0; k < K; ++k) {
        qm = Eigen::Map<const Eigen::VectorXd>(q.a.data() + k * n, n);
        exid::measuredToJoint(R, qm, z, z, &qj, &qdj, &qddj);
        exid::Pose X = body < 0 ? exid::bodyPose(R, *data, qj, R.sensorBody()) * R.sensor_pose
                                : exid::bodyPose(R, *data, qj, body);
        Eigen::Map<Eigen::Matrix<double, 4, 4, Eigen::RowMajor>> H(o + k * 16);
        H.setIdentity();
        H.topLeftCorner<3, 3>() = X.R;
        H.topRightCorner<3, 1>() = X.p;
      }
    }
    return out;
  }

 private:
  static py::array_t<double> vec(const Eigen::VectorXd& v) {
    py::array_t<double> a(static_cast<py::ssize_t>(v.size()));
    std::copy(v.data(), v.data() + v.size(), a.mutable_data());
    return a;
  }
  static py::array_t<double> mat(const Eigen::MatrixXd& m) {
    OutArray a({static_cast<py::ssize_t>(m.rows()), static_cast<py::ssize_t>(m.cols())});
    Eigen::Map<RowMajor>(a.mutable_data(), m.rows(), m.cols()) = m;
    return a;
  }
  static py::array_t<double> pose(const exid::Pose& X) {
    Eigen::Matrix4d H = Eigen::Matrix4d::Identity();
    H.topLeftCorner<3, 3>() = X.R;
    H.topRightCorner<3, 1>() = X.p;
    return mat(H);
  }

  std::string type_;
  std::shared_ptr<exid::Robot> plugin_;  // keeps the plugin that built the model
  std::shared_ptr<const exid::RobotModel> robot_;
  std::shared_ptr<exid::ObservationModel> model_;
  bool per_sample_ = true;
};

}  // namespace

void bindRobot(py::module_& m) {
  using R = PyRobot;
  py::class_<R>(m, "Robot")
      .def(py::init<const std::string&, const std::string&, const std::string&, const std::string&,
                    const std::string&, std::uint64_t>(),
           py::arg("type"), py::arg("params"), py::arg("model"), py::arg("model_params"),
           py::arg("base_dir"), py::arg("seed"))
      .def_property_readonly("name", &R::name)
      .def_property_readonly("type", &R::type)
      .def_property_readonly("model", &R::modelType)
      .def_property_readonly("dof", &R::dof)
      .def_property_readonly("joint_names", &R::jointNames)
      .def_property_readonly("link_names", &R::linkNames)
      .def_property_readonly("joint_types", &R::jointTypes)
      .def_property_readonly("parents", &R::parents)
      .def_property_readonly("limits", &R::limits)
      .def_property_readonly("gravity", &R::gravity)
      .def_property_readonly("transmission", &R::transmission)
      .def_property_readonly("notes", &R::notes)
      .def_property_readonly("warnings", &R::warnings)
      .def_property_readonly("sensor_body", &R::sensorBody)
      .def_property_readonly("sensor_pose", &R::sensorPose)
      .def_property_readonly("inertial_parameter_names", &R::inertialNames)
      .def_property_readonly("inertial_parameter_values", &R::inertialValues)
      .def_property_readonly("standard_names", &R::standardNames)
      .def_property_readonly("standard_values", &R::standardValues)
      .def_property_readonly("base_names", &R::baseNames)
      .def_property_readonly("base_expressions", &R::baseExpressions)
      .def_property_readonly("base_values", &R::baseValues)
      .def_property_readonly("base_matrix", &R::baseMatrix)
      .def_property_readonly("base_independent", &R::baseIndependent)
      .def_property_readonly("base_tolerance", &R::baseTolerance)
      .def_property_readonly("floating_base", &R::floatingBase)
      .def_property_readonly("floating_parameter_names", &R::floatingNames)
      .def_property_readonly("floating_parameter_values", &R::floatingValues)
      .def("random_samples", &R::randomSamples, py::arg("count"), py::arg("seed") = 1)
      .def(
          "rnea",
          [](const R& r, py::handle q, py::handle qd, py::handle qdd, py::object pi) {
            return r.perSample(R::What::Rnea, q, qd, qdd, pi, "rnea");
          },
          py::arg("q"), py::arg("qd"), py::arg("qdd"), py::arg("parameters") = py::none())
      .def(
          "torque",
          [](const R& r, py::handle q, py::handle qd, py::handle qdd) {
            return r.perSample(R::What::Torque, q, qd, qdd, py::none(), "torque");
          },
          py::arg("q"), py::arg("qd"), py::arg("qdd"))
      .def(
          "inertial_regressor",
          [](const R& r, py::handle q, py::handle qd, py::handle qdd) {
            return r.perSample(R::What::Inertial, q, qd, qdd, py::none(), "inertial_regressor");
          },
          py::arg("q"), py::arg("qd"), py::arg("qdd"))
      .def(
          "payload_torque_regressor",
          [](const R& r, py::handle q, py::handle qd, py::handle qdd) {
            return r.perSample(R::What::Payload, q, qd, qdd, py::none(),
                               "payload_torque_regressor");
          },
          py::arg("q"), py::arg("qd"), py::arg("qdd"))
      .def(
          "wrench_regressor",
          [](const R& r, py::handle q, py::handle qd, py::handle qdd) {
            return r.perSample(R::What::Wrench, q, qd, qdd, py::none(), "wrench_regressor");
          },
          py::arg("q"), py::arg("qd"), py::arg("qdd"))
      .def(
          "mass_matrix",
          [](const R& r, py::handle q, py::object pi) {
            return r.perSample(R::What::Mass, q, py::none(), py::none(), pi, "mass_matrix");
          },
          py::arg("q"), py::arg("parameters") = py::none())
      .def("energy_regressor", &R::energyRegressor, py::arg("q"), py::arg("qd"))
      .def(
          "regressor",
          [](const R& r, py::handle q, py::handle qd, py::handle qdd, py::object t,
             py::object base) { return r.modelRows(false, q, qd, qdd, t, base); },
          py::arg("q"), py::arg("qd"), py::arg("qdd"), py::arg("t") = py::none(),
          py::arg("base") = py::none())
      .def(
          "base_regressor",
          [](const R& r, py::handle q, py::handle qd, py::handle qdd, py::object t,
             py::object base) { return r.modelRows(true, q, qd, qdd, t, base); },
          py::arg("q"), py::arg("qd"), py::arg("qdd"), py::arg("t") = py::none(),
          py::arg("base") = py::none())
      .def(
          "floating_regressor",
          [](const R& r, py::handle q, py::handle qd, py::handle qdd, py::handle base) {
            return r.floatingDynamics(true, q, qd, qdd, base, py::none());
          },
          py::arg("q"), py::arg("qd"), py::arg("qdd"), py::arg("base"))
      .def(
          "floating_inverse_dynamics",
          [](const R& r, py::handle q, py::handle qd, py::handle qdd, py::handle base,
             py::object pi) { return r.floatingDynamics(false, q, qd, qdd, base, pi); },
          py::arg("q"), py::arg("qd"), py::arg("qdd"), py::arg("base"),
          py::arg("parameters") = py::none())
      .def("body_pose", &R::bodyPose, py::arg("q"), py::arg("body"));
}

}  // namespace exid_python
