// Regression tests for what the fuzz targets (tests/fuzz) found. Each input is also in the seed
// corpus of its target. Meaningful with assertions on (the sanitizer build is -O1 without NDEBUG).
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <string>
#include <utility>

#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"
#include "exid_test.hpp"

// fuzz_dh: a non-number inside inertia_com threw inside Eigen's comma initialiser; unwinding ran
// its destructor, which asserts "too few coefficients" and aborted the process.
TEST(FuzzRegression, DhBadNumberInInertiaIsAnErrorNotAnAbort) {
  const std::string yaml =
      "convention: standard\n"
      "links:\n"
      "  - {a: 1, mass: 1, inertia_com: {xx: 0.0, yy: 0.08, zz: 0.08;33}}\n";
  try {
    exid::loadDhYamlString(yaml, "bad.yaml");
    FAIL() << "accepted";
  } catch (const exid::Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("bad.yaml:3"), std::string::npos) << m;
    EXPECT_NE(m.find("inertia_com.zz"), std::string::npos) << m;
  }
}

// The same, as libFuzzer minimised it (corpus/fuzz_dh/crash-inertia-comma-initializer-min.yaml):
// keys without values inside inertia_com.
TEST(FuzzRegression, DhKeyWithoutValueInInertiaIsAnErrorNotAnAbort) {
  const std::string yaml =
      "convention: standard\n"
      "links:\n"
      "- inertia_com: {xx: 0,yy,zz}\n";
  try {
    exid::loadDhYamlString(yaml, "min.yaml");
    FAIL() << "accepted";
  } catch (const exid::Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("min.yaml:3"), std::string::npos) << m;
    EXPECT_NE(m.find("inertia_com.yy: expected a number, found nothing"), std::string::npos) << m;
  }
}

// fuzz_urdf: a text ending in the lead byte of a multi-byte UTF-8 sequence made TinyXML step
// past the terminating NUL (heap-buffer-overflow in TiXmlBase::ReadName; the input is
// corpus/fuzz_urdf/crash-utf8-truncated-at-end.urdf). Malformed UTF-8 is now refused before
// parsing, with the line, the column and the byte.
TEST(FuzzRegression, UrdfWithMalformedUtf8IsAnErrorNotAnOverflow) {
  const std::string head = "<robot name=\"r\">\n  <link name=\"base\"/>\n";
  const std::pair<std::string, std::string> cases[] = {
      {head + "  <link name=\"a\"/> i\xdf", "bad.urdf:3: column 21: byte 0xDF"},      // truncated
      {head + "  <!-- \xe0\x20 -->\n</robot>\n", "bad.urdf:3: column 8: byte 0xE0"},  // bad tail
      {head + "  <!-- \xc0\xaf -->\n</robot>\n", "bad.urdf:3: column 8: byte 0xC0"},  // overlong
      {head + "  <!-- \xed\xa0\x80 -->\n</robot>\n",
       "bad.urdf:3: column 8: byte 0xED"},  // surrogate
      {head + std::string("  <!-- \0 -->\n</robot>\n", 14),
       "bad.urdf:3: column 8: byte 0x00 (NUL)"},
  };
  for (const auto& [xml, expected] : cases) {
    SCOPED_TRACE(expected);
    try {
      exid::loadUrdfString(xml, "bad.urdf");
      FAIL() << "accepted";
    } catch (const exid::Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(expected), std::string::npos) << m;
      EXPECT_NE(m.find("not valid UTF-8"), std::string::npos) << m;
    }
  }
  // well-formed UTF-8 (2-, 3- and 4-byte sequences) is still read
  const exid::RobotModel m = exid::loadUrdfString(
      "<robot name=\"r\"> <!-- \xc3\xa9 \xe2\x82\xac \xf0\x9f\xa4\x96 -->\n"
      "  <link name=\"base\"/>\n"
      "  <link name=\"a\"><inertial><mass value=\"1\"/><inertia ixx=\"0.01\" ixy=\"0\" ixz=\"0\" "
      "iyy=\"0.01\" iyz=\"0\" izz=\"0.01\"/></inertial></link>\n"
      "  <joint name=\"j\" type=\"continuous\"><parent link=\"base\"/><child link=\"a\"/>"
      "<axis xyz=\"0 0 1\"/></joint>\n</robot>\n",
      "ok.urdf");
  EXPECT_EQ(m.dof(), 1);
}

// The input as the fuzzer found it (under the sanitizers, the old code aborted on it).
TEST(FuzzRegression, UrdfFuzzerCrashInputIsRefused) {
  const auto file =
      exid_test::sourceDir() / "tests/fuzz/corpus/fuzz_urdf/crash-utf8-truncated-at-end.urdf";
  std::ifstream in(file, std::ios::binary);
  ASSERT_TRUE(in) << file;
  const std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  try {
    exid::loadUrdfString(xml, "crash.urdf");
    FAIL() << "accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("not valid UTF-8"), std::string::npos) << e.what();
  }
}
