// The base layer's values: JSON (exid/json.hpp) and parameter declarations with their ranges
// (exid/params.hpp).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "exid/error.hpp"
#include "exid/json.hpp"
#include "exid/params.hpp"

namespace {
std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(Json, DumpParseRoundTrip) {
  exid::Json j = exid::Json::object();
  j["status"] = "ok";
  j["n"] = 3;
  j["x"] = 0.25;
  j["nan"] = std::nan("");
  j["list"] = std::vector<double>{1, 2.5};
  j["nested"]["s"] = "a \"quoted\"\nline";
  exid::Json back = exid::Json::parse(j.dump());
  EXPECT_EQ(back.find("status")->asString(), "ok");
  EXPECT_EQ(back.find("n")->asInt(), 3);
  EXPECT_DOUBLE_EQ(back.find("x")->asDouble(), 0.25);
  EXPECT_TRUE(back.find("nan")->isNull());
  EXPECT_DOUBLE_EQ(back.find("list")->at(1).asDouble(), 2.5);
  EXPECT_EQ(back.find("nested")->find("s")->asString(), "a \"quoted\"\nline");
  EXPECT_EQ(j.items().front().first, "status");  // insertion order kept
  std::string msg = errorOf([] { exid::Json::parse("{\"a\": }"); });
  EXPECT_NE(msg.find("offset"), std::string::npos);
}

TEST(Params, RangeTextAndViolations) {
  auto d = exid::param_double("ff", 1.0, "", "forgetting factor", 0.0, 1.0, true, false);
  EXPECT_EQ(d.rangeText(), "(0, 1]");
  EXPECT_EQ(d.violation(exid::ParamValue(0.0)), "must be in (0, 1]");
  EXPECT_EQ(d.violation(exid::ParamValue(1.0)), "");
  EXPECT_EQ(d.violation(exid::ParamValue(std::nan(""))), "must be in (0, 1]");
  auto l = exid::param_doubles("w", std::nullopt, "N m", "weights", 2, 3);
  EXPECT_NE(l.violation(exid::ParamValue(std::vector<double>{1.0})).find("at least 2"),
            std::string::npos);
  exid::ParamSet ps;
  ps.context = "estimator.params";
  ps.set("n", exid::ParamValue(std::int64_t{3}));
  EXPECT_DOUBLE_EQ(ps.getDouble("n"), 3.0);
  std::string msg = errorOf([&] { ps.getString("n"); });
  EXPECT_NE(msg.find("estimator.params.n: expected a string"), std::string::npos) << msg;
  msg = errorOf([&] { ps.getDouble("absent"); });
  EXPECT_NE(msg.find("'absent' is not set"), std::string::npos) << msg;
}

// Integer parameters declared without bounds still have a range that fits an int (samples:
// 2^63 - 1 was accepted and narrowed to 40, issue 16).
TEST(Params, IntegersAlwaysHaveARangeThatFitsAnInt) {
  const auto d = exid::param_int("n", 1, "count", 0.0);
  EXPECT_EQ(d.rangeText(), "[0, 1000000000]");
  EXPECT_EQ(d.violation(exid::ParamValue(std::int64_t{1000000000})), "");
  EXPECT_EQ(d.violation(exid::ParamValue(std::int64_t{9223372036854775807})),
            "must be in [0, 1000000000]");
  const auto u = exid::param_int("m", 1, "count");
  EXPECT_EQ(u.violation(exid::ParamValue(std::int64_t{-2147483648})),
            "must be in [-1000000000, 1000000000]");
  const auto l = exid::param_ints("j", std::nullopt, "joints", 1.0);
  EXPECT_EQ(l.violation(exid::ParamValue(std::vector<std::int64_t>{1, 4294967297})),
            "element 1 must be in [1, 1000000000]");
}
