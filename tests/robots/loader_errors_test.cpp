// Malformed robot descriptions: one test per class of error. Each message must name the source
// (file), the place (YAML line / link / joint) and the rule.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"

namespace {

using exid::LoadOptions;
using exid::RobotModel;

/// The message of the exid::Error thrown by f (fails the test when nothing is thrown).
template <class F>
std::string errorOf(F&& f) {
  try {
    f();
  } catch (const exid::Error& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "not an exid::Error: " << e.what();
    return e.what();
  }
  ADD_FAILURE() << "no error thrown";
  return "";
}

std::string yamlError(const std::string& text) {
  std::vector<std::string> w;
  LoadOptions o;
  o.warnings = &w;
  return errorOf([&] { exid::loadDhYamlString(text, "bad.yaml", o); });
}

std::string urdfError(const std::string& text) {
  std::vector<std::string> w;
  LoadOptions o;
  o.warnings = &w;
  return errorOf([&] { exid::loadUrdfString(text, "bad.urdf", o); });
}

#define EXPECT_HAS(msg, part) EXPECT_NE((msg).find(part), std::string::npos) << (msg)

const char* kGoodHead = "name: t\nconvention: standard\nlinks:\n";

// ------------------------------------------------------------------ YAML
TEST(DhYamlErrors, InvalidYaml) {
  const std::string m = yamlError("name: t\nconvention: standard\nlinks: [\n  {a: 1\n");
  EXPECT_HAS(m, "bad.yaml:");
  EXPECT_HAS(m, "invalid YAML");
}

TEST(DhYamlErrors, UnknownKeyTopLevelAndInLink) {
  std::string m = yamlError(std::string(kGoodHead) + "  - {a: 1}\ncolour: red\n");
  EXPECT_HAS(m, "bad.yaml:5");
  EXPECT_HAS(m, "unknown key 'colour'");
  m = yamlError(std::string(kGoodHead) + "  - a: 1\n    mas: 2\n");
  EXPECT_HAS(m, "bad.yaml:5");
  EXPECT_HAS(m, "links[0]");
  EXPECT_HAS(m, "unknown key 'mas'");
  m = yamlError(std::string(kGoodHead) + "  - a: 1\n    drive: {gear: 2}\n");
  EXPECT_HAS(m, "bad.yaml:5");
  EXPECT_HAS(m, "link 'link1'");
  EXPECT_HAS(m, "unknown key 'gear'");
}

TEST(DhYamlErrors, WrongType) {
  std::string m = yamlError(std::string(kGoodHead) + "  - a: 1\n  - a: 0.5\n    mass: heavy\n");
  EXPECT_HAS(m, "bad.yaml:6");
  EXPECT_HAS(m, "link 'link2'");
  EXPECT_HAS(m, "mass");
  EXPECT_HAS(m, "expected a number, found 'heavy'");
  m = yamlError(std::string(kGoodHead) + "  - com: 1\n");
  EXPECT_HAS(m, "bad.yaml:4");
  EXPECT_HAS(m, "com: expected a list of numbers");
  m = yamlError(std::string(kGoodHead) + "  - com: [1, 2]\n");
  EXPECT_HAS(m, "expected 3 numbers, found 2");
  m = yamlError(std::string(kGoodHead) + "  - type: spherical\n");
  EXPECT_HAS(m, "expected 'revolute' or 'prismatic', found 'spherical'");
  m = yamlError("convention: craig\nlinks:\n  - {a: 1}\n");
  EXPECT_HAS(m, "bad.yaml:1");
  EXPECT_HAS(m, "expected 'standard' or 'modified'");
}

TEST(DhYamlErrors, NonFiniteNumber) {
  const std::string m = yamlError(std::string(kGoodHead) + "  - a: 1\n    d: .nan\n");
  EXPECT_HAS(m, "bad.yaml:5");
  EXPECT_HAS(m, "link 'link1'");
  EXPECT_HAS(m, "expected a finite number");
  const std::string g = yamlError(std::string(kGoodHead) + "  - a: 1\ngravity: [0, 0, .inf]\n");
  EXPECT_HAS(g, "bad.yaml:5");
  EXPECT_HAS(g, "gravity[2]");
}

TEST(DhYamlErrors, MissingAndDuplicateLinksAndJoints) {
  std::string m = yamlError("name: t\nconvention: standard\n");
  EXPECT_HAS(m, "missing key 'links'");
  m = yamlError("name: t\nconvention: standard\nlinks: []\n");
  EXPECT_HAS(m, "bad.yaml:3");
  EXPECT_HAS(m, "non-empty list of links");
  m = yamlError(std::string(kGoodHead) + "  - {name: arm, a: 1}\n  - {name: arm, a: 1}\n");
  EXPECT_HAS(m, "bad.yaml:5");
  EXPECT_HAS(m, "duplicate link name 'arm' (first at line 4)");
  m = yamlError(std::string(kGoodHead) + "  - {joint: j, a: 1}\n  - {joint: j, a: 1}\n");
  EXPECT_HAS(m, "bad.yaml:5");
  EXPECT_HAS(m, "duplicate joint name 'j'");
  m = yamlError(std::string(kGoodHead) + "  - {name: a}\n  - {name: b, parent: c}\n");
  EXPECT_HAS(m, "bad.yaml:5");
  EXPECT_HAS(m, "unknown link 'c'");
  m = yamlError("name: t\nlinks:\n  - {a: 1}\n");
  EXPECT_HAS(m, "missing key 'convention'");
}

TEST(DhYamlErrors, DuplicateKey) {
  const std::string m = yamlError(std::string(kGoodHead) + "  - a: 1\n    a: 2\n");
  EXPECT_HAS(m, "bad.yaml:5");
  EXPECT_HAS(m, "duplicate key 'a'");
  EXPECT_HAS(m, "first at line 4");
  // At the top level the first used to win silently (issue 16): both lines are named.
  const std::string t =
      yamlError(std::string(kGoodHead) + "  - a: 1\ngravity: [0, 0, -9.81]\ngravity: [0, 0, 0]\n");
  EXPECT_HAS(t, "bad.yaml:6: gravity: duplicate key 'gravity' (first at line 5)");
}

// A robot file that is not a regular file (FIFO, /dev/zero) is refused before it is opened:
// the FIFO hung forever, /dev/zero ended in bad_alloc (issue 16).
TEST(DhYamlErrors, NotARegularFileIsRefusedBeforeOpening) {
  const std::string z = errorOf([] { exid::loadDhYaml("/dev/zero"); });
  EXPECT_HAS(z, "/dev/zero: the DH YAML file is a character device, not a regular file");
  const std::string u = errorOf([] { exid::loadUrdf("/dev/zero"); });
  EXPECT_HAS(u, "/dev/zero: the URDF file is a character device");
  const std::string d = errorOf([] { exid::loadUrdf("/"); });
  EXPECT_HAS(d, "is a directory");
}

TEST(DhYamlErrors, ConflictingKeys) {
  std::string m = yamlError(std::string(kGoodHead) + "  - {alpha: 1, alpha_deg: 90}\n");
  EXPECT_HAS(m, "either 'alpha' or 'alpha_deg'");
  m = yamlError(std::string(kGoodHead) +
                "  - mass: 1\n    inertia_com: {xx: 1, yy: 1, zz: 1}\n"
                "    inertia_origin: {xx: 1, yy: 1, zz: 1}\n");
  EXPECT_HAS(m, "bad.yaml:6");
  EXPECT_HAS(m, "inertia_com");
  m = yamlError(std::string(kGoodHead) + "  - drive: {motor_inertia: 1, rotor_inertia: 1}\n");
  EXPECT_HAS(m, "motor_inertia");
  m = yamlError(std::string(kGoodHead) + "  - {type: prismatic, limits: {q_min_deg: 1}}\n");
  EXPECT_HAS(m, "prismatic");
  m = yamlError(std::string(kGoodHead) + "  - limits: {q_min: 1, q_max: 0}\n");
  EXPECT_HAS(m, "q_min must be below q_max");
}

TEST(DhYamlErrors, Transmission) {
  std::string m = yamlError(std::string(kGoodHead) +
                            "  - {a: 1}\n  - {a: 1}\ntransmission:\n  matrix: [[1, 0]]\n");
  EXPECT_HAS(m, "bad.yaml:7");
  EXPECT_HAS(m, "expected 2 rows");
  m = yamlError(std::string(kGoodHead) +
                "  - {a: 1}\n  - {a: 1}\ntransmission:\n  matrix: [[1, 1], [1, 1]]\n");
  EXPECT_HAS(m, "singular");
}

TEST(DhYamlErrors, MissingFile) {
  const std::string m = errorOf([] { exid::loadDhYaml("/nonexistent/robot.yaml"); });
  EXPECT_HAS(m, "/nonexistent/robot.yaml");
  EXPECT_HAS(m, "no such file");
}

TEST(DhYamlErrors, StrictRefusesImpossibleInertia) {
  const std::string text = std::string(kGoodHead) +
                           "  - name: bad\n    mass: -1\n"
                           "    inertia_com: {xx: 1, yy: 1, zz: 1}\n";
  std::vector<std::string> w;
  LoadOptions o;
  o.warnings = &w;
  EXPECT_NO_THROW(exid::loadDhYamlString(text, "bad.yaml", o));
  ASSERT_FALSE(w.empty());
  EXPECT_HAS(w[0], "bad.yaml");
  EXPECT_HAS(w[0], "link 'bad'");
  EXPECT_HAS(w[0], "mass");
  o.strict = true;
  const std::string m = errorOf([&] { exid::loadDhYamlString(text, "bad.yaml", o); });
  EXPECT_HAS(m, "bad.yaml");
  EXPECT_HAS(m, "link 'bad'");
  EXPECT_HAS(m, "strict");
}

TEST(DhYaml, KeysAndUnits) {
  const std::string text =
      std::string(kGoodHead) +
      "  - name: a\n    alpha_deg: 90\n    theta_deg: 30\n    mass: 2\n"
      "    com: [0.1, 0, 0]\n    inertia_origin: {xx: 1, yy: 2, zz: 3, xy: 0.5}\n"
      "    limits: {q_min_deg: -90, q_max_deg: 90, qd_max_deg: 180, tau_max: 5}\n"
      "    drive: {gear_ratio: 10, motor_inertia: 0.001, viscous: 1}\n"
      "sensor: {link: 1, xyz: [0, 0, 0.1], rpy_deg: [0, 0, 90]}\n";
  const RobotModel m = exid::loadDhYamlString(text, "ok.yaml");
  EXPECT_NEAR(m.limits[0].q_max, M_PI / 2, 1e-15);
  EXPECT_NEAR(m.limits[0].qd_max, M_PI, 1e-15);
  EXPECT_NEAR(m.limits[0].tau_max, 5, 1e-15);
  EXPECT_NEAR(m.drives[0].rotor_inertia, 0.1, 1e-15);
  EXPECT_NEAR(m.bodies[0].inertia(0), 1, 1e-15);  // about the origin, as given
  EXPECT_NEAR(m.bodies[0].inertia(1), 0.5, 1e-15);
  EXPECT_NEAR(m.bodies[0].inertia(6), 0.2, 1e-15);
  EXPECT_EQ(m.sensor_body, 0);
  EXPECT_NEAR(m.sensor_pose.R(1, 0), 1.0, 1e-12);
  EXPECT_NEAR(m.sensor_pose.p.z(), 0.1, 1e-15);
  EXPECT_NEAR(m.bodies[0].post.R(2, 1), 1.0, 1e-12);  // Rx(90 deg) in the standard DH post
}

// ------------------------------------------------------------------ URDF
std::string urdf(const std::string& body) {
  return "<?xml version=\"1.0\"?>\n<robot name=\"r\">\n" + body + "</robot>\n";
}

const char* kInertial =
    "<inertial><origin xyz=\"0.1 0 0\"/><mass value=\"1\"/>"
    "<inertia ixx=\"0.01\" ixy=\"0\" ixz=\"0\" iyy=\"0.01\" iyz=\"0\" izz=\"0.01\"/></inertial>";

std::string link(const std::string& name) {
  return "  <link name=\"" + name + "\">" + kInertial + "</link>\n";
}
std::string joint(const std::string& name, const std::string& type, const std::string& parent,
                  const std::string& child, const std::string& extra = "") {
  return "  <joint name=\"" + name + "\" type=\"" + type + "\"><parent link=\"" + parent +
         "\"/><child link=\"" + child +
         "\"/><origin xyz=\"0 0 0.5\"/><axis xyz=\"0 0 1\"/>"
         "<limit lower=\"-1\" upper=\"1\" effort=\"10\" velocity=\"2\"/>" +
         extra + "</joint>\n";
}

TEST(UrdfErrors, InvalidXml) {
  const std::string m = urdfError("<robot name=\"r\">\n  <link name=\"a\">\n</robot>\n");
  EXPECT_HAS(m, "bad.urdf:");
  EXPECT_HAS(m, "invalid XML");
  EXPECT_HAS(urdfError("<robt/>"), "root element must be <robot>");
}

TEST(UrdfErrors, DuplicateLinkAndJoint) {
  std::string m = urdfError(urdf(link("base") + link("a") + link("a")));
  EXPECT_HAS(m, "bad.urdf:5");
  EXPECT_HAS(m, "link 'a'");
  EXPECT_HAS(m, "duplicate link (first at line 4)");
  m = urdfError(urdf(link("base") + link("a") + link("b") + joint("j", "revolute", "base", "a") +
                     joint("j", "revolute", "a", "b")));
  EXPECT_HAS(m, "bad.urdf:7");
  EXPECT_HAS(m, "joint 'j'");
  EXPECT_HAS(m, "duplicate joint");
}

TEST(UrdfErrors, MissingLink) {
  const std::string m =
      urdfError(urdf(link("base") + link("a") + joint("j1", "revolute", "base", "ghost")));
  EXPECT_HAS(m, "bad.urdf:5");
  EXPECT_HAS(m, "joint 'j1'");
  EXPECT_HAS(m, "unknown link 'ghost'");
  const std::string p = urdfError(urdf(link("base") + "  <joint name=\"j\" type=\"fixed\">"
                                                      "<child link=\"base\"/></joint>\n"));
  EXPECT_HAS(p, "joint 'j'");
  EXPECT_HAS(p, "missing <parent");
}

TEST(UrdfErrors, KinematicLoop) {
  // b has two parents (a closed chain).
  std::string m =
      urdfError(urdf(link("base") + link("a") + link("b") + joint("j1", "revolute", "base", "a") +
                     joint("j2", "revolute", "base", "b") + joint("j3", "revolute", "a", "b")));
  EXPECT_HAS(m, "bad.urdf:8");
  EXPECT_HAS(m, "joint 'j3'");
  EXPECT_HAS(m, "kinematic loop");
  // A cycle a -> b -> a beside a root.
  m = urdfError(urdf(link("base") + link("a") + link("b") + joint("j1", "revolute", "a", "b") +
                     joint("j2", "revolute", "b", "a")));
  EXPECT_HAS(m, "kinematic loop");
  EXPECT_HAS(m, "link '");
}

TEST(UrdfErrors, SeveralRoots) {
  const std::string m = urdfError(
      urdf(link("base") + link("other") + link("a") + joint("j1", "revolute", "base", "a")));
  EXPECT_HAS(m, "several root links");
  EXPECT_HAS(m, "'other'");
}

// A floating joint is a floating base only from the world (root) link to the base link; every
// other use is refused, naming the joint and the rule.
TEST(UrdfErrors, FloatingJointRules) {
  const std::string world = "  <link name=\"world\"/>\n";  // massless
  // not from the root
  std::string m =
      urdfError(urdf(world + link("a") + link("b") + joint("j", "revolute", "world", "a") +
                     joint("free", "floating", "a", "b")));
  EXPECT_HAS(m, "joint 'free'");
  EXPECT_HAS(m, "must connect the world (root) link 'world'");
  // the world link holds more than the floating joint
  m = urdfError(urdf(world + link("a") + link("b") + joint("free", "floating", "world", "a") +
                     joint("j", "revolute", "world", "b")));
  EXPECT_HAS(m, "has other joints besides the floating one");
  // two floating joints
  m = urdfError(urdf(world + link("a") + link("b") + joint("free", "floating", "world", "a") +
                     joint("free2", "floating", "a", "b")));
  EXPECT_HAS(m, "joint 'free2'");
  // a planar joint is still refused
  m = urdfError(urdf(world + link("a") + joint("p", "planar", "world", "a")));
  EXPECT_HAS(m, "planar joints are not supported");
  // the world link of a floating base has no mass
  m = urdfError(
      urdf("  <link name=\"world\"><inertial><mass value=\"1\"/><inertia ixx=\"1\" ixy=\"0\" "
           "ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link>\n" +
           link("a") + link("b") + joint("free", "floating", "world", "a") +
           joint("j", "revolute", "a", "b")));
  EXPECT_HAS(m, "the world link of floating joint 'free' has a mass");
  // a floating base alone moves nothing the joints could measure
  m = urdfError(urdf(world + link("a") + joint("free", "floating", "world", "a")));
  EXPECT_HAS(m, "no movable joint");
}

TEST(UrdfErrors, WrongTypeInUrdfdomValues) {
  const std::string m = urdfError(urdf(
      "  <link name=\"base\"/>\n  <link name=\"a\"><inertial><mass value=\"heavy\"/>"
      "<inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link>\n" +
      joint("j1", "revolute", "base", "a")));
  EXPECT_HAS(m, "bad.urdf:4");
  EXPECT_HAS(m, "link 'a'");
  EXPECT_HAS(m, "expected a number, found 'heavy'");
}

TEST(UrdfErrors, NonFiniteNumber) {
  const std::string m =
      urdfError(urdf(link("base") + link("a") + joint("j1", "revolute", "base", "a") +
                     "  <exid><drive joint=\"j1\" viscous=\"nan\"/></exid>\n"));
  EXPECT_HAS(m, "bad.urdf:6");
  EXPECT_HAS(m, "<drive>");
  EXPECT_HAS(m, "non-finite");
}

// (found by fuzz_urdf: an empty <gravity/> read three numbers from none)
TEST(UrdfErrors, ExtensionGravityWithoutItsVector) {
  const std::string m =
      urdfError(urdf(link("base") + link("a") + joint("j1", "revolute", "base", "a") +
                     "  <exid><gravity/></exid>\n"));
  EXPECT_HAS(m, "bad.urdf:6");
  EXPECT_HAS(m, "<gravity>");
  EXPECT_HAS(m, "missing attribute 'xyz'");
}

TEST(UrdfErrors, ExtensionUnknownElementAttributeJoint) {
  std::string m = urdfError(urdf(link("base") + link("a") + joint("j1", "revolute", "base", "a") +
                                 "  <exid>\n    <motor joint=\"j1\"/>\n  </exid>\n"));
  EXPECT_HAS(m, "bad.urdf:7");
  EXPECT_HAS(m, "unknown element");
  m = urdfError(urdf(link("base") + link("a") + joint("j1", "revolute", "base", "a") +
                     "  <exid><drive joint=\"j1\" gear=\"3\"/></exid>\n"));
  EXPECT_HAS(m, "unknown attribute 'gear'");
  m = urdfError(urdf(link("base") + link("a") + joint("j1", "revolute", "base", "a") +
                     "  <exid><drive joint=\"j9\"/></exid>\n"));
  EXPECT_HAS(m, "joint 'j9'");
}

TEST(UrdfErrors, MissingFile) {
  const std::string m = errorOf([] { exid::loadUrdf("/nonexistent/robot.urdf"); });
  EXPECT_HAS(m, "/nonexistent/robot.urdf");
}

TEST(UrdfErrors, StrictRefusesImpossibleInertia) {
  const std::string text = urdf(
      "  <link name=\"base\"/>\n  <link name=\"a\"><inertial><mass value=\"1\"/>"
      "<inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"3\"/></inertial></link>\n" +
      joint("j1", "revolute", "base", "a"));
  std::vector<std::string> w;
  LoadOptions o;
  o.warnings = &w;
  EXPECT_NO_THROW(exid::loadUrdfString(text, "tri.urdf", o));
  ASSERT_EQ(w.size(), 1u);
  EXPECT_HAS(w[0], "tri.urdf");
  EXPECT_HAS(w[0], "link 'a'");
  EXPECT_HAS(w[0], "triangle");
  o.strict = true;
  const std::string m = errorOf([&] { exid::loadUrdfString(text, "tri.urdf", o); });
  EXPECT_HAS(m, "link 'a'");
  EXPECT_HAS(m, "triangle");
}

// ------------------------------------------------------------------ URDF semantics
TEST(Urdf, FixedJointMergingPreservesMassAndCom) {
  // a (1 kg, COM 0.1 on x of a) carries b through a fixed joint (rotated, offset) and c through a
  // revolute joint. The merged body "a" must have 2 kg and the combined COM.
  const std::string text =
      urdf(link("base") + link("a") + link("b") + link("c") + joint("j1", "revolute", "base", "a") +
           "  <joint name=\"fix\" type=\"fixed\"><parent link=\"a\"/><child link=\"b\"/>"
           "<origin xyz=\"0 0.2 0\" rpy=\"0 0 1.5707963267948966\"/></joint>\n" +
           joint("j2", "continuous", "b", "c") +
           "  <exid><sensor link=\"b\" xyz=\"0 0 0.05\"/></exid>\n");
  const RobotModel m = exid::loadUrdfString(text, "merge.urdf");
  ASSERT_EQ(m.dof(), 2);
  EXPECT_EQ(m.bodies[0].name, "a");
  EXPECT_EQ(m.bodies[1].name, "c");
  EXPECT_EQ(m.bodies[1].parent, 0);
  EXPECT_NEAR(m.bodies[0].inertia(9), 2.0, 1e-15);
  // COM of b: its frame at (0, 0.2, 0) rotated 90 deg about z: (0.1, 0, 0)_b -> (0, 0.3, 0)_a.
  // Combined: ((0.1, 0, 0) + (0, 0.3, 0)) / 2.
  EXPECT_NEAR(m.bodies[0].inertia(6) / 2.0, 0.05, 1e-12);
  EXPECT_NEAR(m.bodies[0].inertia(7) / 2.0, 0.15, 1e-12);
  EXPECT_NEAR(m.bodies[0].inertia(8), 0.0, 1e-12);
  // Body c's joint frame: b's frame, then the joint origin (0, 0, 0.5).
  EXPECT_NEAR(m.bodies[1].pre.p.y(), 0.2, 1e-12);
  EXPECT_NEAR(m.bodies[1].pre.p.z(), 0.5, 1e-12);
  EXPECT_NEAR(m.bodies[1].pre.R(1, 0), 1.0, 1e-12);
  // Continuous joint: no position limits, velocity and effort from <limit>.
  EXPECT_GT(m.limits[1].q_max, 1e100);
  EXPECT_NEAR(m.limits[1].qd_max, 2.0, 1e-15);
  EXPECT_NEAR(m.limits[1].tau_max, 10.0, 1e-15);
  // The sensor on the merged link b lands on body a.
  EXPECT_EQ(m.sensor_body, 0);
  EXPECT_NEAR(m.sensor_pose.p.y(), 0.2, 1e-12);
  EXPECT_NEAR(m.sensor_pose.p.z(), 0.05, 1e-12);
  // The merged inertia about the COM equals the sum of both parts' (parallel axis check).
  double mass = 0;
  Eigen::Vector3d com;
  Eigen::Matrix3d Ic;
  exid::comFromInertial(m.bodies[0].inertia, &mass, &com, &Ic);
  const double d2 = (Eigen::Vector3d(0.1, 0, 0) - com).squaredNorm();  // both parts at same dist
  EXPECT_NEAR(Ic.trace(), 2 * 0.03 + 2 * 2 * d2, 1e-12);
}

TEST(Urdf, TreeWithSeveralChildrenOfTheRoot) {
  const std::string text =
      urdf(link("base") + link("left") + link("right") + link("left2") +
           joint("jl", "revolute", "base", "left") + joint("jr", "prismatic", "base", "right") +
           joint("jl2", "revolute", "left", "left2"));
  const RobotModel m = exid::loadUrdfString(text, "tree.urdf");
  ASSERT_EQ(m.dof(), 3);
  for (int i = 0; i < 3; ++i) EXPECT_LT(m.bodies[i].parent, i);
  int right = -1, left2 = -1, left = -1;
  for (int i = 0; i < 3; ++i) {
    if (m.bodies[i].name == "right") right = i;
    if (m.bodies[i].name == "left") left = i;
    if (m.bodies[i].name == "left2") left2 = i;
  }
  ASSERT_GE(right, 0);
  ASSERT_GE(left2, 0);
  EXPECT_EQ(m.bodies[right].parent, -1);
  EXPECT_EQ(m.bodies[right].type, exid::JointType::Prismatic);
  EXPECT_EQ(m.bodies[left2].parent, left);
}

}  // namespace

TEST(UrdfErrors, XacroGetsAHintToExpandItFirst) {
  const std::string text =
      "<?xml version=\"1.0\"?>\n<robot name=\"r\" xmlns:xacro=\"http://www.ros.org/wiki/xacro\">\n"
      "  <xacro:macro name=\"arm\" params=\"prefix\">\n"
      "    <link name=\"${prefix}base\"/>\n  </xacro:macro>\n  <xacro:arm prefix=\"\"/>\n"
      "</robot>\n";
  std::vector<std::string> w;
  LoadOptions o;
  o.warnings = &w;
  const std::string m = errorOf([&] { exid::loadUrdfString(text, "arm.urdf.xacro", o); });
  EXPECT_HAS(m, "this is a xacro file");
  EXPECT_HAS(m, "expand it first: xacro arm.urdf.xacro > robot.urdf");
  EXPECT_HAS(urdfError(urdf("")), "no <link> in the robot");
}

TEST(UrdfFiles, GazeboDynamicsAreNotNominalFrictionUnlessAsked) {
  const std::string text =
      urdf(link("base") + link("a") +
           joint("j1", "revolute", "base", "a", "<dynamics damping=\"0.7\" friction=\"0.2\"/>"));
  const RobotModel m = exid::loadUrdfString(text, "gz.urdf");
  EXPECT_EQ(m.drives[0].viscous, 0.0);
  EXPECT_EQ(m.drives[0].coulomb, 0.0);
  ASSERT_EQ(m.notes.size(), 1u);
  EXPECT_HAS(m.notes[0], "<dynamics damping friction> of joint(s) j1 not used");
  LoadOptions o;
  o.urdf_dynamics_as_friction = true;
  const RobotModel u = exid::loadUrdfString(text, "gz.urdf", o);
  EXPECT_EQ(u.drives[0].viscous, 0.7);
  EXPECT_EQ(u.drives[0].coulomb, 0.2);
  EXPECT_TRUE(u.notes.empty());
}
