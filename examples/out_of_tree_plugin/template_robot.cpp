// TEMPLATE (robot): a 3-joint arm described in code with the installed core API alone
// (exid/dh.hpp, exid/robot_model.hpp; target exid::core): a vertical base joint, a shoulder and
// an elbow (standard DH), each link a uniform rod whose mass, centre of mass and inertia tensor
// become the 10 standard parameters (exid::inertialFromCom), with joint limits and drive data; a
// tool mass and the drives are set by parameters; checked like a loaded description (structure
// and physical consistency). The numbers are round values for the example, not a real robot's.
// To make it yours: change kName, the DH rows, the link data, the limits and the drives (and
// cite their source in kDoc). A description that sits in a file needs no plugin (the robot
// plugins `dh` and `urdf` read it); a plugin pays when the robot is computed from parameters
// (as tool_mass_kg and drives here) or must work from an installation without its file.
#include <fmt/format.h>

#include <cmath>
#include <string>
#include <vector>

#include "exid/dh.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"

namespace {

class TemplateRobot final : public exid::Robot {
 public:
  static constexpr const char* kName = "template_robot";
  static constexpr const char* kVersion = "1.0";
  static constexpr const char* kDoc =
      "3-joint arm (vertical base joint, shoulder, elbow; standard DH) described in code, uniform "
      "rod links, limits and drives (round example numbers; out-of-tree template)";
  static std::vector<exid::ParamDecl> params() {
    return {
        exid::param_double("tool_mass_kg", 0.0, "kg",
                           "point mass at the end of link 3 (added to its parameters)", 0.0),
        exid::param_bool("drives", true,
                         "give the joints their drive data (rotor inertia, Coulomb and viscous "
                         "friction); false: ideal drives (rigid bodies alone)"),
        exid::param_doubles("gravity", std::vector<double>{0.0, 0.0, -9.81}, "m/s^2",
                            "gravity [gx, gy, gz] in the base frame", 3, 3),
        exid::param_bool("strict", false,
                         "physically impossible inertial data is an error instead of a warning"),
    };
  }
  explicit TemplateRobot(const exid::ParamSet& p)
      : tool_mass_(p.getDouble("tool_mass_kg")),
        drives_(p.getBool("drives")),
        gravity_(p.getDoubles("gravity")),
        strict_(p.getBool("strict")) {}

  std::shared_ptr<const exid::RobotModel> build(const exid::RunContext&) override {
    // Standard DH (exid/dh.hpp): A_i = Rz(theta_i + q_i) Tz(d_i) Tx(a_i) Rx(alpha_i); body i's
    // frame is DH frame i, at the far end of link i; joint i turns about z_{i-1}.
    std::vector<exid::DhRow> rows(3);
    rows[0].d = 0.35;          // base column up to the shoulder,
    rows[0].alpha = M_PI / 2;  // then the shoulder axis horizontal
    rows[1].a = 0.40;          // upper arm
    rows[2].a = 0.30;          // forearm
    exid::RobotModel m = exid::serialDh(rows, exid::DhConvention::Standard);
    m.name = kName;
    m.source = "plugin template_robot (described in code)";
    m.gravity = Eigen::Vector3d(gravity_[0], gravity_[1], gravity_[2]);

    // One row per link: name, joint, mass [kg], rod length and radius [m], the rod's axis in the
    // body frame (0: x, 1: y), centre of mass in the body frame [m], limits {q_min, q_max [rad],
    // qd_max [rad/s], qdd_max [rad/s^2], tau_max [N m]}, drive {gear ratio, rotor inertia
    // [kg m^2], Coulomb [N m], viscous [N m s/rad], offset [N m]}. Frame 1 sits at the shoulder
    // with y1 pointing up (the column hangs below it); frames 2, 3 at the far ends of the links.
    struct Link {
      const char *name, *joint;
      double mass, length, radius;
      int axis;
      Eigen::Vector3d com;
      exid::JointLimits lim;
      exid::Drive drive;
    };
    // clang-format off
    const Link links[3] = {
        {"column", "base_yaw", 4.0, 0.35, 0.05, 1, {0.0, -0.175, 0.0},
         {-2.9, 2.9, 2.0, 8.0, 60.0}, {100.0, 0.05, 0.4, 0.6, 0.0}},
        {"upper_arm", "shoulder", 2.5, 0.40, 0.04, 0, {-0.20, 0.0, 0.0},
         {-2.0, 2.0, 2.0, 8.0, 60.0}, {100.0, 0.04, 0.3, 0.5, 0.0}},
        {"forearm", "elbow", 1.5, 0.30, 0.03, 0, {-0.15, 0.0, 0.0},
         {-2.4, 2.4, 2.5, 10.0, 30.0}, {80.0, 0.02, 0.2, 0.3, 0.0}},
    };
    // clang-format on
    for (int i = 0; i < 3; ++i) {
      const Link& L = links[i];
      // a uniform rod about its centre of mass: m r^2 / 2 about its axis, m (3 r^2 + l^2) / 12
      // about the others
      Eigen::Vector3d I = Eigen::Vector3d::Constant(
          L.mass * (3 * L.radius * L.radius + L.length * L.length) / 12.0);
      I(L.axis) = L.mass * L.radius * L.radius / 2.0;
      exid::Body& b = m.bodies[static_cast<std::size_t>(i)];
      b.name = L.name;
      b.joint_name = L.joint;
      b.inertia = exid::inertialFromCom(L.mass, L.com, I.asDiagonal().toDenseMatrix());
      m.limits[static_cast<std::size_t>(i)] = L.lim;
      if (drives_) m.drives[static_cast<std::size_t>(i)] = L.drive;  // else Drive{}: ideal
    }
    // the tool: a point mass at the origin of frame 3 (the tip of the forearm)
    m.bodies[2].inertia +=
        exid::inertialFromCom(tool_mass_, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Zero());
    m.validateStructure();  // throws exid::Error naming the body and the rule
    for (int i = 0; i < m.dof(); ++i) {
      const exid::InertiaCheck c =
          exid::checkPhysical(m.bodies[static_cast<std::size_t>(i)].inertia);
      if (c.ok) continue;
      const std::string msg =
          fmt::format("{}: link '{}' (body {}): physically impossible inertia: {}", m.source,
                      m.bodies[static_cast<std::size_t>(i)].name, i + 1, c.rule);
      if (strict_) throw exid::Error(msg);
      exid::logWarn(msg);
      m.warnings.push_back(msg);  // the runner puts them into summary.json `warnings`
    }
    return std::make_shared<const exid::RobotModel>(std::move(m));
  }

 private:
  double tool_mass_;
  bool drives_;
  std::vector<double> gravity_;
  bool strict_;
};

}  // namespace

EXID_REGISTER_PLUGIN(TemplateRobot)
