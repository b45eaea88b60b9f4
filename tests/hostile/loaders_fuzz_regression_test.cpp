// Regression tests for what the fuzz targets (tests/fuzz) found. Each input is also in the seed
// corpus of its target. Meaningful with assertions on (the sanitizer build is -O1 without NDEBUG).
#include <gtest/gtest.h>

#include <string>

#include "exid/error.hpp"
#include "exid/robot_loaders.hpp"

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
