// exid — observation model `floating_base`: the rows of a floating-base robot
// (exid/floating_base.hpp; docs/models.md, "floating_base"). Per sample, with the base motion
// b = (omega, alpha, f) of Dataset::base and the contact wrenches w_c of Dataset::contact:
//   base rows (6)   Y_base(q, qd, qdd, b) pi_f = sum_c X*_c w_c          (rows: all | base)
//   joint rows (n)  Y_joint(q, qd, qdd, b) pi_f = tau + sum_c J_c^T w_c  (rows: all | joints)
// pi_f = [XX0 .. M0 (the base link); XX1 .. M1; ...]. The base rows need no joint torque
// (torque-free identification, Ayusawa, Venture and Nakamura 2014).
#include "exid/floating_base.hpp"

#include <fmt/format.h>

#include <Eigen/Core>
#include <random>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/models/model_common.hpp"

namespace {

using exid::models::requireSignal;

class FloatingBaseModel : public exid::ObservationModel {
 public:
  static constexpr const char* kName = "floating_base";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "floating-base robot: the base link's six Newton-Euler rows balanced by the measured "
      "contact wrenches and/or the joint rows (torques plus J^T w); needs q, qd, qdd, the base "
      "motion (omega, alpha, f) and the contact wrenches, and tau for the joint rows";

  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_string("rows", std::string("all"),
                           "which rows: all (base and joints), base (the base link's six rows "
                           "alone: no joint torque needed) or joints",
                           {"all", "base", "joints"}),
        exid::param_strings("contact_links", std::vector<std::string>{},
                            "the links carrying the contact (F/T) sensors, one per contact, in "
                            "the order of the dataset's contact columns (the base link or a "
                            "body's link)"),
        exid::param_doubles("contact_poses", std::vector<double>{}, "m, rad",
                            "sensor frame of each contact in its link's frame: x y z roll pitch "
                            "yaw, six numbers per contact (empty: identity poses)"),
    };
  }

  explicit FloatingBaseModel(const exid::ParamSet& p)
      : rows_(p.getString("rows")),
        contact_links_(p.getStrings("contact_links")),
        contact_pose_values_(p.getDoubles("contact_poses")),
        context_(p.context) {
    exid::check(
        contact_pose_values_.empty() || contact_pose_values_.size() == 6 * contact_links_.size(),
        fmt::format("{}: contact_poses: {} numbers for {} contact link(s) (expected six "
                    "per contact: x y z roll pitch yaw, or none)",
                    context_.empty() ? "model 'floating_base'" : context_,
                    contact_pose_values_.size(), contact_links_.size()));
  }

  std::vector<std::string> fullNames() const override {
    return exid::floatingParameterNames(robot());
  }
  Eigen::VectorXd fullNominal() const override { return exid::floatingParameters(robot()); }

  exid::ModelSpecs specs() const override {
    exid::ModelSpecs sp;
    sp.per_sample = true;
    sp.required_signals = {"q", "qd", "qdd"};
    if (rows_ != "base") sp.required_signals.push_back("tau");
    sp.floating_base = true;
    return sp;
  }

  exid::Samples randomSamples(int count, std::uint64_t seed) const override {
    exid::Samples s = ObservationModel::randomSamples(count, seed);
    std::mt19937_64 rng(seed ^ 0xb5ad4eceda1ce2a9ull);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    s.base.resize(count, 9);
    for (int k = 0; k < count; ++k)
      for (int c = 0; c < 9; ++c) s.base(k, c) = (c < 3 ? 2.0 : c < 6 ? 6.0 : 15.0) * u(rng);
    return s;
  }

  exid::Rows fullRows(const exid::Dataset& d, const exid::RunContext&) const override {
    const int n = robot().dof();
    const std::string who = "model 'floating_base'";
    requireSignal(d, d.q, "q", n, who);
    requireSignal(d, d.qd, "qd", n, who);
    requireSignal(d, d.qdd, "qdd", n, who);
    const int K = d.size();
    if (rows_ != "base") requireSignal(d, d.tau, "tau", n, who);
    exid::check(d.base.rows() == K && d.base.cols() == 9,
                fmt::format("{}: the dataset ({}) has no base motion (9 columns: omega, alpha, f "
                            "in the base frame; found {} x {})",
                            who, d.source, d.base.rows(), d.base.cols()));
    const int C = static_cast<int>(contact_links_.size());
    exid::check(
        (C == 0 && d.contact.size() == 0) || (d.contact.rows() == K && d.contact.cols() == 6 * C),
        fmt::format("{}: the dataset ({}) has {} contact column(s); the model declares {} "
                    "contact(s) (contact_links), six columns each",
                    who, d.source, d.contact.cols(), C));
    exid::check(C > 0 || rows_ == "joints",
                fmt::format("{}: no contact declared (contact_links): the base rows equal the "
                            "contact wrenches, so rows '{}' needs at least one (rows: joints "
                            "for a robot with no contact)",
                            who, rows_));
    exid::Rows r;
    r.W = fullDesign(d.samples());
    const int m = rowsPerSample();
    r.y.resize(m * K);
    r.equation.resize(static_cast<std::size_t>(m * K));
    r.t.resize(static_cast<std::size_t>(m * K));
    const std::vector<int> bodies = contactBodies();
    Eigen::VectorXd rhs(6 + n);
    for (int k = 0; k < K; ++k) {
      rhs.setZero();
      if (rows_ != "base") rhs.tail(n) = d.tau.row(k).transpose();
      const Eigen::VectorXd q = d.q.row(k).transpose();
      for (int c = 0; c < C; ++c) {
        const Eigen::MatrixXd Cm =
            exid::contactMap(robot(), q, bodies[static_cast<size_t>(c)], contactPose(c));
        rhs += Cm * d.contact.block(k, 6 * c, 1, 6).transpose();
      }
      const int first = rows_ == "joints" ? 6 : 0;
      for (int e = 0; e < m; ++e) {
        r.y[m * k + e] = rhs[first + e];
        r.equation[static_cast<std::size_t>(m * k + e)] = e;
        r.t[static_cast<std::size_t>(m * k + e)] = d.t[k];
      }
    }
    r.numEquations = m;
    r.equation_names = equationNames();
    return r;
  }

  Eigen::MatrixXd fullDesign(const exid::Samples& s) const override {
    const exid::RobotModel& R = robot();
    const int K = s.size(), n = R.dof();
    exid::models::requireSamples(s, n, true, "model 'floating_base'");
    exid::check(s.base.rows() == K && s.base.cols() == 9,
                fmt::format("model 'floating_base': the samples have no base motion (9 columns: "
                            "omega, alpha, f in the base frame; found {} x {})",
                            s.base.rows(), s.base.cols()));
    const int m = rowsPerSample(), first = rows_ == "joints" ? 6 : 0;
    Eigen::MatrixXd W(m * K, 10 * (n + 1)), Y;
    for (int k = 0; k < K; ++k) {
      const exid::BaseMotion b = s.base.row(k).transpose();
      exid::floatingRegressor(R, s.q.row(k).transpose(), s.qd.row(k).transpose(),
                              s.qdd.row(k).transpose(), b, Y);
      W.middleRows(m * k, m) = Y.middleRows(first, m);
    }
    return W;
  }

  void fullDesignVjp(const exid::Samples&, const Eigen::MatrixXd&, exid::Samples*) const override {
    throw exid::Error(
        "model 'floating_base': excitation design is not available for a floating-base robot "
        "(the regressor's vector-Jacobian product is not written; use a given trajectory)");
  }

  exid::Json describe() const override {
    exid::Json j = exid::Json::object();
    j["equation"] =
        "base rows: Y_base pi_f = sum_c X*_c w_c; joint rows: Y_joint pi_f = tau + sum_c "
        "J_c^T w_c";
    j["rows"] = rows_;
    j["base_motion"] =
        "omega [rad/s], alpha [rad/s^2], f = a - g [m/s^2] of the base origin, base frame";
    j["contact_wrench"] =
        "fx fy fz mx my mz exerted by the environment on the robot, sensor frame, moment about "
        "the sensor origin";
    j["contact_links"] = exid::Json(contact_links_);
    j["parameters"] = "XX0 .. M0 the base link's, then each body's (exid/floating_base.hpp)";
    return j;
  }

 protected:
  void onBind(const exid::RunContext&) override {
    const exid::RobotModel& R = robot();
    exid::requireFloatingBase(R, "the observation model 'floating_base'");
    exid::check(!R.hasTransmission(),
                fmt::format("model 'floating_base': robot '{}' has a transmission matrix (not "
                            "modelled for a floating base: give joint coordinates)",
                            R.name));
    contactBodies();  // the links exist
  }

 private:
  int rowsPerSample() const {
    const int n = robot().dof();
    return rows_ == "all" ? 6 + n : rows_ == "base" ? 6 : n;
  }
  std::vector<int> contactBodies() const {
    std::vector<int> out;
    for (const auto& l : contact_links_)
      out.push_back(exid::floatingBodyIndex(robot(), l, "model 'floating_base': contact_links"));
    return out;
  }
  exid::Pose contactPose(int c) const {
    if (contact_pose_values_.empty()) return exid::Pose{};
    return exid::poseFromXyzRpy(&contact_pose_values_[static_cast<size_t>(6 * c)]);
  }
  std::vector<std::string> equationNames() const {
    std::vector<std::string> names;
    if (rows_ != "joints")
      for (const char* e : {"base fx [N]", "base fy [N]", "base fz [N]", "base mx [N m]",
                            "base my [N m]", "base mz [N m]"})
        names.push_back(e);
    if (rows_ != "base")
      for (int j = 0; j < robot().dof(); ++j)
        names.push_back(fmt::format("tau joint {} ({})", j + 1,
                                    robot().bodies[static_cast<size_t>(j)].joint_name));
    return names;
  }

  std::string rows_;
  std::vector<std::string> contact_links_;
  std::vector<double> contact_pose_values_;
  std::string context_;
};

}  // namespace

EXID_REGISTER_PLUGIN(FloatingBaseModel)
