// MJCF and SDF descriptions exid cannot read faithfully: each is refused with a message naming
// the file, the line and what is wrong (never a model that moves differently from the file).
// And what the loaders do read, checked against hand-computed values: MuJoCo's conventions
// (degrees by default, euler sequences, default classes, fullinertia's order, welded bodies)
// and SDFormat's (frame graph, expressed_in, defaults).
#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"

namespace {

using exid::RobotModel;

template <class F>
std::string errorOf(F&& f) {
  try {
    f();
  } catch (const exid::Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "no error thrown";
  return "";
}

RobotModel mjcf(const std::string& body, const std::string& head = "",
                std::vector<std::string>* warnings = nullptr) {
  std::vector<std::string> sink;
  exid::LoadOptions o;
  o.warnings = warnings ? warnings : &sink;
  return exid::loadMjcfString(
      "<mujoco model=\"m\">\n" + head + "<worldbody>\n" + body + "</worldbody>\n</mujoco>\n",
      "arm.xml", o);
}

std::string mjcfError(const std::string& body, const std::string& head = "") {
  return errorOf([&] { mjcf(body, head); });
}

const std::string kLink = "<inertial pos=\"0.1 0 0\" mass=\"2\" diaginertia=\"0.1 0.2 0.25\"/>";

RobotModel sdf(const std::string& model, const std::string& version = "1.9",
               std::vector<std::string>* warnings = nullptr, bool strict = false) {
  std::vector<std::string> sink;
  exid::LoadOptions o;
  o.warnings = warnings ? warnings : &sink;
  o.strict = strict;
  return exid::loadSdfString(
      "<sdf version=\"" + version + "\">\n<model name=\"m\">\n" + model + "</model>\n</sdf>\n",
      "arm.sdf", o);
}

std::string sdfError(const std::string& model, const std::string& version = "1.9") {
  return errorOf([&] { sdf(model, version); });
}

const std::string kBase =
    "<link name=\"base\"/>\n<joint name=\"fix\" type=\"fixed\"><parent>world</parent>"
    "<child>base</child></joint>\n";
const std::string kInertial =
    "<inertial><mass>2</mass><inertia><ixx>0.1</ixx><ixy>0</ixy><ixz>0</ixz><iyy>0.2</iyy>"
    "<iyz>0</iyz><izz>0.25</izz></inertia></inertial>";

std::string sdfLink(const std::string& name, const std::string& pose = "") {
  return "<link name=\"" + name + "\">" + pose + kInertial + "</link>\n";
}
std::string sdfJoint(const std::string& name, const std::string& parent, const std::string& child,
                     const std::string& type = "revolute", const std::string& extra = "") {
  return "<joint name=\"" + name + "\" type=\"" + type + "\"><parent>" + parent +
         "</parent><child>" + child + "</child>" + extra +
         "<axis><xyz>0 0 1</xyz></axis></joint>\n";
}

// ---------------------------------------------------------------- MJCF refusals
TEST(MjcfErrors, WhatExidDoesNotModelIsRefusedWithItsLine) {
  struct Case {
    std::string body, head, expected;
  };
  const std::vector<Case> cases = {
      // a free joint only on a body of the worldbody (the floating base), alone in it
      {"<body name=\"b\"><joint name=\"j\"/>" + kLink + "<body name=\"c\"><freejoint/>" + kLink +
           "</body></body>\n",
       "",
       "arm.xml:3: <freejoint>: a free joint below another body: only a body of the "
       "worldbody can float"},
      {"<body name=\"b\"><joint name=\"j\"/>" + kLink +
           "<body name=\"c\"><joint name=\"f\" type=\"free\"/>" + kLink + "</body></body>\n",
       "", "only a body of the worldbody can float"},
      {"<body name=\"b\"><freejoint/><joint name=\"j\"/>" + kLink + "</body>\n", "",
       "a free joint and another joint in body 'b'"},
      {"<body name=\"b\"><freejoint/>" + kLink + "<body name=\"c\"><joint name=\"j\"/>" + kLink +
           "</body></body>\n<body name=\"d\"><joint name=\"k\"/>" + kLink + "</body>\n",
       "", "a floating base (free joint) and other bodies in the worldbody"},
      {"<body><freejoint/>" + kLink + "<body name=\"c\"><joint name=\"j\"/>" + kLink +
           "</body></body>\n",
       "", "the floating base's body needs a name"},
      {"<body name=\"b\"><freejoint/>" + kLink +
           "<site name=\"exid_sensor\"/><body name=\"c\"><joint name=\"j\"/>" + kLink +
           "</body></body>\n",
       "", "the exid_sensor site must be on a moving body (not the floating base)"},
      {"<body name=\"b\"><freejoint/>" + kLink + "</body>\n", "", "no moving joint"},
      {"<body name=\"b\"><joint name=\"j\" type=\"ball\"/>" + kLink + "</body>\n", "",
       "type 'ball' is not supported"},
      {"<body name=\"b\"><joint name=\"j1\"/><joint name=\"j2\"/>" + kLink + "</body>\n", "",
       "a second joint in body 'b'"},
      {"<body name=\"b\"><joint name=\"j\" stiffness=\"3\"/>" + kLink + "</body>\n", "",
       "stiffness is not zero"},
      {"<body name=\"b\"><joint name=\"j\"/><geom type=\"sphere\" size=\"0.1\"/></body>\n", "",
       "no <inertial>: MuJoCo would compute the inertia from the geoms"},
      {"<body name=\"b\"><joint name=\"j\" class=\"nope\"/>" + kLink + "</body>\n", "",
       "unknown default class 'nope'"},
      {"<body name=\"b\"><joint/>" + kLink + "</body>\n", "", "a joint needs a name"},
      {"<body name=\"b\"><joint name=\"j\" range=\"1 x\"/>" + kLink + "</body>\n", "",
       "attribute 'range': expected a number, found 'x'"},
      {"<body name=\"b\"><joint name=\"j\" range=\"1 0\"/>" + kLink + "</body>\n", "",
       "range: the lower bound must be below the upper"},
      // an attribute given empty (fuzz_xml_robots: axis="" was read as an empty vector)
      {"<body name=\"b\"><joint name=\"j\" axis=\"\"/>" + kLink + "</body>\n", "",
       "attribute 'axis': expected 3 number(s), found 0"},
      {"<body name=\"b\"><joint name=\"j\" damping=\" \"/>" + kLink + "</body>\n", "",
       "attribute 'damping': expected 1 number(s), found 0"},
      {"<body name=\"b\" quat=\"1 0 0 0\" euler=\"0 0 1\"><joint name=\"j\"/>" + kLink +
           "</body>\n",
       "", "more than one of quat, axisangle, euler"},
      {"<body name=\"b\"><joint name=\"j\"/><inertial pos=\"0 0 0\" mass=\"1\"/></body>\n", "",
       "expected exactly one of diaginertia and fullinertia"},
      {"<body name=\"b\"><joint name=\"j\"/>" + kLink + "</body>\n",
       "<include file=\"other.xml\"/>\n", "<include> is not supported"},
      {"<body name=\"b\"><joint name=\"j\"/>" + kLink + "</body>\n",
       "<equality><weld body1=\"b\"/></equality>\n", "only `connect` equality constraints"},
      {"<body name=\"b\"><joint name=\"j\"/>" + kLink + "</body>\n",
       "<equality><connect body1=\"b\" body2=\"world\" anchor=\"0 0 0\"/></equality>\n",
       "loop-closure `connect` constraints but no motor"},
      {"<body name=\"b\"><joint name=\"j\"/>" + kLink + "</body>\n",
       "<equality><connect body1=\"nope\" anchor=\"0 0 0\"/></equality>\n",
       "body1: unknown body 'nope'"},
      {"<body name=\"b\">" + kLink + "</body>\n", "", "no moving joint"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.expected);
    const std::string e = mjcfError(c.body, c.head);
    EXPECT_NE(e.find("arm.xml:"), std::string::npos) << e;
    EXPECT_NE(e.find(c.expected), std::string::npos) << e;
  }
  EXPECT_NE(errorOf([] {
              exid::loadMjcfString("<robot name=\"r\"/>", "arm.xml");
            }).find("the root element of an MJCF file must be <mujoco>, found <robot>"),
            std::string::npos);
  // (empty and unparsable files: the message, and the document freed once; CI's second stage
  // runs this folder under AddressSanitizer)
  EXPECT_NE(errorOf([] { exid::loadMjcfString("", "arm.xml"); }).find("invalid XML"),
            std::string::npos);
  EXPECT_NE(errorOf([] { exid::loadSdfString("", "arm.sdf"); }).find("invalid XML"),
            std::string::npos);
  EXPECT_NE(errorOf([] { exid::loadSdfString("<", "arm.sdf"); }).find("arm.sdf"),
            std::string::npos);
  EXPECT_NE(
      errorOf([] { exid::loadMjcfString("<mujoco><worldbody>", "arm.xml"); }).find("invalid XML"),
      std::string::npos);
  EXPECT_NE(errorOf([] {
              exid::loadMjcfString(std::string("<mujoco>\xff</mujoco>"), "arm.xml");
            }).find("is not valid UTF-8 here; an MJCF (XML) file must be UTF-8 text"),
            std::string::npos);
}

// ---------------------------------------------------------------- floating bases
// A free joint on a body of the worldbody (<freejoint/> or <joint type="free">): that body is
// the floating base link, its frame the base frame (its pos/quat, the reference pose, do not
// enter), a body welded to it joins its inertia, the bodies with joints hang from it.
TEST(Mjcf, AFreeJointInABodyOfTheWorldbodyIsTheFloatingBase) {
  for (const std::string free :
       {"<freejoint name=\"root\"/>", "<joint name=\"root\" type=\"free\"/>"}) {
    SCOPED_TRACE(free);
    const RobotModel m = mjcf("<body name=\"torso\" pos=\"1 2 3\" quat=\"0 1 0 0\">" + free +
                                  kLink + "<body name=\"w\" pos=\"0 0 0.1\">" + kLink +
                                  "</body><body name=\"a\" pos=\"0.2 0 0\"><joint name=\"j\" "
                                  "axis=\"0 1 0\"/>" +
                                  kLink + "</body></body>\n",
                              "<compiler angle=\"radian\"/>\n");
    ASSERT_TRUE(m.floating_base);
    EXPECT_EQ(m.base.link, "torso");
    EXPECT_EQ(m.base.joint_name, "root");
    ASSERT_EQ(m.dof(), 1);
    EXPECT_EQ(m.bodies[0].parent, -1);
    EXPECT_LE((m.bodies[0].pre.p - Eigen::Vector3d(0.2, 0, 0)).norm(), 1e-15);
    EXPECT_LE((m.bodies[0].pre.R - Eigen::Matrix3d::Identity()).norm(), 1e-15);
    // kLink: 2 kg at (0.1, 0, 0), diag(0.1, 0.2, 0.25) about the centre; twice, the second
    // 0.1 m up: 4 kg, first moments (0.4, 0, 0.2), XX = 0.1 + 0.1 + 2 * 0.1^2, ...
    Eigen::Matrix<double, 10, 1> expected;
    expected << 0.1 + 0.1 + 2 * 0.01, 0.0, -2 * 0.1 * 0.1, 0.2 + 0.02 + 0.2 + 2 * 0.02, 0.0,
        0.25 + 0.02 + 0.25 + 2 * 0.01, 0.4, 0.0, 0.2, 4.0;
    EXPECT_LE((m.base.inertia - expected).cwiseAbs().maxCoeff(), 1e-14)
        << m.base.inertia.transpose();
  }
  // (a robot fixed to the world is not floating)
  EXPECT_FALSE(mjcf("<body name=\"b\"><joint name=\"j\"/>" + kLink + "</body>\n").floating_base);
}

// An SDF model with no joint to the world is free (SDFormat's meaning): its one link that is no
// joint's child is the floating base link, and a note says so; a model welded to the world is not.
TEST(Sdf, AModelWithNoJointToTheWorldIsAFloatingBase) {
  const RobotModel m =
      sdf(sdfLink("torso", "<pose>1 2 3 0 0 0.5</pose>") +
          sdfLink("w", "<pose>1 2 3.1 0 0 0.5</pose>") + sdfJoint("weld", "torso", "w", "fixed") +
          sdfLink("a", "<pose>1 2 3 0 0 0.5</pose>") + sdfJoint("j", "torso", "a"));
  ASSERT_TRUE(m.floating_base);
  EXPECT_EQ(m.base.link, "torso");
  EXPECT_EQ(m.base.joint_name, "");
  ASSERT_EQ(m.dof(), 1);
  EXPECT_EQ(m.bodies[0].parent, -1);
  // kInertial: 2 kg at the link origin, diag(0.1, 0.2, 0.25); twice, the second 0.1 m up
  Eigen::Matrix<double, 10, 1> expected;
  expected << 0.2 + 2 * 0.01, 0.0, 0.0, 0.4 + 2 * 0.01, 0.0, 0.5, 0.0, 0.0, 0.2, 4.0;
  EXPECT_LE((m.base.inertia - expected).cwiseAbs().maxCoeff(), 1e-14) << m.base.inertia.transpose();
  bool noted = false;
  for (const auto& n : m.notes)
    noted |= n.find(
                 "arm.sdf: no joint to the world: a free model in SDFormat, read as a floating "
                 "base (base link 'torso'") != std::string::npos;
  EXPECT_TRUE(noted);
  const RobotModel fixed = sdf(kBase + sdfLink("a") + sdfJoint("j", "base", "a"));
  EXPECT_FALSE(fixed.floating_base);
  for (const auto& n : fixed.notes) EXPECT_EQ(n.find("floating"), std::string::npos) << n;
}

// ---------------------------------------------------------------- MJCF conventions
TEST(Mjcf, DegreesByDefaultRadiansWhenSaid) {
  const std::string body =
      "<body name=\"b\" euler=\"0 0 90\"><joint name=\"j\" range=\"-90 "
      "45\"/>" +
      kLink + "</body>\n";
  const RobotModel d = mjcf(body);
  EXPECT_NEAR(d.limits[0].q_min, -M_PI / 2, 1e-15);
  EXPECT_NEAR(d.limits[0].q_max, M_PI / 4, 1e-15);
  EXPECT_NEAR(d.bodies[0].pre.R(1, 0), 1.0, 1e-15);  // x axis turned onto y
  const RobotModel r =
      mjcf("<body name=\"b\" euler=\"0 0 1.5\"><joint name=\"j\" range=\"-1 0.5\"/>" + kLink +
               "</body>\n",
           "<compiler angle=\"radian\"/>\n");
  EXPECT_EQ(r.limits[0].q_min, -1.0);
  EXPECT_NEAR(r.bodies[0].pre.R(1, 0), std::sin(1.5), 1e-15);
  // a slide joint's range is a length, never converted
  const RobotModel s =
      mjcf("<body name=\"b\"><joint name=\"j\" type=\"slide\" range=\"-0.5 0.25\"/>" + kLink +
           "</body>\n");
  EXPECT_EQ(s.limits[0].q_min, -0.5);
  EXPECT_EQ(s.bodies[0].type, exid::JointType::Prismatic);
}

TEST(Mjcf, EulerSequencesRotatingAndFixedAxes) {
  // "xyz" (rotating axes): R = Rx(a) Ry(b) Rz(c); "XYZ" (fixed axes): R = Rz(c) Ry(b) Rx(a)
  const double a = 0.3, b = -0.7, c = 1.1;
  auto R = [&](const std::string& seq) {
    return mjcf("<body name=\"b\" euler=\"0.3 -0.7 1.1\"><joint name=\"j\"/>" + kLink + "</body>\n",
                "<compiler angle=\"radian\" eulerseq=\"" + seq + "\"/>\n")
        .bodies[0]
        .pre.R;
  };
  const Eigen::Matrix3d Rx = Eigen::AngleAxisd(a, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Matrix3d Ry = Eigen::AngleAxisd(b, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Eigen::Matrix3d Rz = Eigen::AngleAxisd(c, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_LE((R("xyz") - Rx * Ry * Rz).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_LE((R("XYZ") - Rz * Ry * Rx).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_NE(mjcfError("<body name=\"b\"><joint name=\"j\"/>" + kLink + "</body>\n",
                      "<compiler eulerseq=\"xyw\"/>\n")
                .find("eulerseq: expected three of x y z X Y Z"),
            std::string::npos);
}

TEST(Mjcf, DefaultClassesFullInertiaAndWeldedBodies) {
  const std::string head =
      "<compiler angle=\"radian\"/>\n<default><joint damping=\"0.5\" axis=\"0 1 0\"/>"
      "<default class=\"wrist\"><joint axis=\"1 0 0\" range=\"-1 1\"/></default></default>\n";
  const std::string body =
      "<body name=\"b1\"><joint name=\"j1\"/>"
      "<inertial pos=\"0 0 0.1\" mass=\"3\" fullinertia=\"0.3 0.4 0.5 0.01 0.02 0.03\"/>"
      "<body name=\"tool\" pos=\"0 0 0.5\"><inertial pos=\"0 0 0\" mass=\"1\" "
      "diaginertia=\"0.01 0.01 0.01\"/>"
      "<body name=\"b2\" pos=\"0 0 0.2\" childclass=\"wrist\"><joint name=\"j2\"/>" +
      kLink + "</body></body></body>\n";
  exid::LoadOptions o;
  std::vector<std::string> sink;
  o.warnings = &sink;
  o.urdf_dynamics_as_friction = true;
  const RobotModel m = exid::loadMjcfString(
      "<mujoco model=\"m\">" + head + "<worldbody>" + body + "</worldbody></mujoco>", "arm.xml", o);
  ASSERT_EQ(m.dof(), 2);
  EXPECT_EQ(m.bodies[0].axis, Eigen::Vector3d::UnitY());  // the main class
  EXPECT_EQ(m.bodies[1].axis, Eigen::Vector3d::UnitX());  // childclass wrist
  EXPECT_EQ(m.drives[1].viscous, 0.5);                    // inherited from main
  EXPECT_EQ(m.limits[1].q_max, 1.0);
  EXPECT_EQ(m.limits[0].q_max, 1e300);  // no range: unlimited
  EXPECT_EQ(m.bodies[1].parent, 0);     // through the welded tool body
  EXPECT_NEAR(m.bodies[1].pre.p.z(), 0.7, 1e-15);
  // body 1: its own inertia (fullinertia is Ixx Iyy Izz Ixy Ixz Iyz) plus the welded tool's
  Eigen::Matrix3d I1;
  I1 << 0.3, 0.01, 0.02, 0.01, 0.4, 0.03, 0.02, 0.03, 0.5;
  const Eigen::Matrix<double, 10, 1> own =
      exid::inertialFromCom(3.0, Eigen::Vector3d(0, 0, 0.1), I1);
  const Eigen::Matrix<double, 10, 1> tool =
      exid::inertialFromCom(1.0, Eigen::Vector3d(0, 0, 0.5), Eigen::Matrix3d::Identity() * 0.01);
  EXPECT_LE((m.bodies[0].inertia - own - tool).cwiseAbs().maxCoeff(), 1e-15);
}

TEST(Mjcf, MotorRangeIsTheTorqueLimitAndTheSensorSiteTheSensorFrame) {
  const std::string text =
      "<mujoco><compiler angle=\"radian\"/><worldbody><body name=\"b\"><joint name=\"j\"/>" +
      kLink +
      "<body name=\"flange\" pos=\"0 0 0.3\"><site name=\"exid_sensor\" pos=\"0 0 0.05\"/></body>"
      "</body></worldbody><actuator><motor joint=\"j\" gear=\"50\" ctrlrange=\"-2 2\" "
      "ctrllimited=\"true\"/></actuator></mujoco>";
  const RobotModel m = exid::loadMjcfString(text, "arm.xml");
  EXPECT_EQ(m.limits[0].tau_max, 100.0);
  EXPECT_EQ(m.sensor_body, 0);
  EXPECT_NEAR(m.sensor_pose.p.z(), 0.35, 1e-15);
  EXPECT_NE(errorOf([] {
              exid::loadMjcfString("<mujoco><worldbody><body name=\"b\"><joint name=\"j\"/>" +
                                       kLink +
                                       "</body></worldbody><actuator><motor joint=\"k\"/>"
                                       "</actuator></mujoco>",
                                   "arm.xml");
            }).find("unknown joint 'k'"),
            std::string::npos);
}

// ---------------------------------------------------------------- SDF refusals
TEST(SdfErrors, WhatExidDoesNotModelIsRefusedWithItsLine) {
  struct Case {
    std::string model, version, expected;
  };
  const std::vector<Case> cases = {
      {sdfLink("a") + sdfLink("b"), "1.9",
       "no joint to the world and 2 links that are no joint's child ('a', 'b'): a free "
       "(floating-base) model has exactly one"},
      {kBase + sdfLink("a") + sdfLink("b") + sdfJoint("j", "base", "a"), "1.9",
       "link 'b' is not attached to the world nor to another link: it would float freely while "
       "the rest is fixed to the world (link 'base')"},
      {sdfLink("t") + sdfLink("a") + sdfJoint("j", "t", "a") + "<static>true</static>", "1.9",
       "a static model does not move"},
      {sdfLink("t") + sdfLink("a") + sdfJoint("j", "t", "a") +
           "<frame name=\"exid_sensor\" attached_to=\"t\"/>",
       "1.9", "the exid_sensor frame must be on a moving link"},
      {sdfLink("a"), "1.9", "no moving joint"},
      {sdfLink("a") + sdfJoint("j", "world", "a"), "1.9", "a revolute joint to the world"},
      {kBase + sdfLink("a") + sdfLink("b") + sdfJoint("j1", "base", "a") +
           sdfJoint("j2", "a", "b") + sdfJoint("j3", "base", "b"),
       "1.9", "a closed kinematic chain"},
      {kBase + sdfLink("a") + sdfJoint("j", "base", "a", "ball"), "1.9",
       "type 'ball' is not supported"},
      {kBase + sdfLink("a") + sdfJoint("j", "base", "nope"), "1.9",
       "<child> 'nope' is not a link of the model"},
      {kBase + sdfLink("a", "<pose relative_to=\"ghost\">0 0 1 0 0 0</pose>") +
           sdfJoint("j", "base", "a"),
       "1.9", "relative_to / attached_to 'ghost': no link, joint or frame"},
      {kBase + sdfLink("a", "<pose relative_to=\"f\">0 0 1 0 0 0</pose>") +
           "<frame name=\"f\"><pose relative_to=\"a\">0 0 0 0 0 0</pose></frame>" +
           sdfJoint("j", "base", "a"),
       "1.9", "the poses form a cycle"},
      {kBase + sdfLink("a") + sdfJoint("j", "base", "a"), "1.4", "SDFormat version 1.4"},
      {kBase + sdfLink("a", "<pose>0 0 1 0 0</pose>") + sdfJoint("j", "base", "a"), "1.9",
       "expected 6 number(s), found 5"},
      {kBase + sdfLink("a") + sdfLink("a") + sdfJoint("j", "base", "a"), "1.9",
       "the name 'a' is given twice"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.expected);
    const std::string e = sdfError(c.model, c.version);
    EXPECT_NE(e.find("arm.sdf"), std::string::npos) << e;
    EXPECT_NE(e.find(c.expected), std::string::npos) << e;
  }
  EXPECT_NE(errorOf([] {
              exid::loadSdfString("<sdf version=\"1.9\"><world name=\"w\"/></sdf>", "arm.sdf");
            }).find("a world file"),
            std::string::npos);
}

// ---------------------------------------------------------------- SDF conventions
TEST(Sdf, FrameGraphExpressedInAndDefaults) {
  // link a 0.5 m above the base; link b placed relative to a frame on a; the joint of b at its
  // own pose relative to the child (the default), the axis expressed in the model frame
  const std::string model =
      kBase + sdfLink("a", "<pose>0 0 0.5 0 0 0</pose>") +
      "<frame name=\"elbow\" attached_to=\"a\"><pose relative_to=\"a\">0.3 0 0 0 0 "
      "1.5707963267948966</pose></frame>" +
      sdfLink("b", "<pose relative_to=\"elbow\">0 0 0 0 0 0</pose>") + sdfJoint("j1", "base", "a") +
      "<joint name=\"j2\" type=\"prismatic\"><parent>a</parent><child>b</child>"
      "<pose>0 0 0.1 0 0 0</pose><axis><xyz expressed_in=\"__model__\">1 0 0</xyz>"
      "<limit><lower>-0.2</lower><upper>0.3</upper><effort>40</effort></limit></axis></joint>\n";
  const RobotModel m = sdf(model);
  ASSERT_EQ(m.dof(), 2);
  EXPECT_NEAR(m.bodies[0].pre.p.z(), 0.5, 1e-15);
  // b's frame in a at q = 0: 0.3 along x, turned 90 degrees about z
  const exid::Pose X = m.bodies[1].pre * m.bodies[1].post;
  EXPECT_NEAR(X.p.x(), 0.3, 1e-15);
  EXPECT_NEAR(X.R(1, 0), 1.0, 1e-15);
  // the model's x axis is b's -y axis (b is turned by +90 degrees about z)
  const Eigen::Vector3d axis_in_b = m.bodies[1].post.inverse().R * m.bodies[1].axis;
  EXPECT_LE((axis_in_b - Eigen::Vector3d(0, -1, 0)).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_EQ(m.limits[1].q_min, -0.2);
  EXPECT_EQ(m.limits[1].tau_max, 40.0);
  EXPECT_EQ(m.bodies[1].type, exid::JointType::Prismatic);
  // the default inertial (SDFormat: 1 kg, unit inertia) is used and said; strict refuses it
  std::vector<std::string> w;
  const RobotModel d = sdf(kBase + "<link name=\"a\"/>" + sdfJoint("j", "base", "a"), "1.9", &w);
  EXPECT_EQ(d.bodies[0].inertia(9), 1.0);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w[0].find("link(s) a without a complete <inertial>"), std::string::npos);
  EXPECT_NE(errorOf([&] {
              sdf(kBase + "<link name=\"a\"/>" + sdfJoint("j", "base", "a"), "1.9", nullptr, true);
            }).find("strict mode"),
            std::string::npos);
}

TEST(RobotFiles, XmlIsDispatchedByItsRootElement) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("exid_simfiles_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name) << text;
    return dir / name;
  };
  std::vector<std::string> sink;
  exid::LoadOptions o;
  o.warnings = &sink;
  const RobotModel a = exid::loadRobotFile(
      write("a.xml", "<mujoco model=\"mj\"><worldbody><body name=\"b\"><joint name=\"j\"/>" +
                         kLink + "</body></worldbody></mujoco>"),
      o);
  EXPECT_EQ(a.name, "mj");
  const RobotModel b = exid::loadRobotFile(
      write("b.xml", "<sdf version=\"1.9\"><model name=\"sd\">" + kBase + sdfLink("a") +
                         sdfJoint("j", "base", "a") + "</model></sdf>"),
      o);
  EXPECT_EQ(b.name, "sd");
  const RobotModel c = exid::loadRobotFile(
      write("c.sdf", "<sdf version=\"1.9\"><model name=\"sd2\">" + kBase + sdfLink("a") +
                         sdfJoint("j", "base", "a") + "</model></sdf>"),
      o);
  EXPECT_EQ(c.name, "sd2");
  EXPECT_NE(errorOf([&] {
              exid::loadRobotFile(write("d.stl", "solid"), o);
            }).find("expected .urdf, .sdf, .mjcf, .xml, .yaml or .yml"),
            std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
