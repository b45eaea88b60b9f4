// Study files: the whole file is validated before any work starts, and every problem names the
// file, the line and the key path.
#include "exid/config.hpp"

#include <gtest/gtest.h>

#include "exid/error.hpp"
#include "exid/registry.hpp"

namespace {

const exid::Registry& reg() {
  static exid::Registry* r = [] {
    auto* x = new exid::Registry();
    x->loadLibrary(std::string(EXID_TEST_PLUGIN_DIR) +
                   "/good_plugin/libexid_plugin_good_plugin.so");
    return x;
  }();
  return *r;
}

std::string problems(const std::string& yaml) {
  try {
    exid::parseStudy(yaml, "study.yaml", "/base", reg());
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "";
}

const char* kGood = R"(name: demo
seed: 7
robot: {type: test_throws}
model: {type: test_model}
experiment: {type: test_experiment, params: {file: data/run1.csv}}
estimator:
  type: test_estimator
  params:
    forgetting_factor: 0.99
    joints: [1, 2]
)";

}  // namespace

TEST(StudyConfig, AValidStudyResolvesDefaultsAndPaths) {
  exid::StudyConfig c = exid::parseStudy(kGood, "study.yaml", "/base", reg());
  EXPECT_EQ(c.name, "demo");
  EXPECT_EQ(c.seed, 7u);
  ASSERT_TRUE(c.estimator);
  EXPECT_DOUBLE_EQ(c.estimator->params.getDouble("forgetting_factor"), 0.99);
  EXPECT_EQ(c.estimator->params.getInt("iterations"), 10);  // default filled in
  EXPECT_EQ(c.estimator->params.getString("method"), "qr");
  EXPECT_EQ(c.experiment->params.getString("file"), "/base/data/run1.csv");
  EXPECT_EQ(c.estimator->line, 7);  // where the section's mapping starts
  // The resolved study lists the defaults, parses again, and has the same hash.
  std::string resolved = c.resolvedYaml();
  EXPECT_NE(resolved.find("iterations: 10"), std::string::npos) << resolved;
  exid::StudyConfig again = exid::parseStudy(resolved, "resolved.yaml", "/base", reg());
  EXPECT_EQ(again.hash(), c.hash());
  EXPECT_EQ(c.hash().size(), 16u);
}

TEST(StudyConfig, HashChangesWithAnyParameter) {
  exid::StudyConfig a = exid::parseStudy(kGood, "s.yaml", "/base", reg());
  std::string other = kGood;
  other.replace(other.find("0.99"), 4, "0.98");
  exid::StudyConfig b = exid::parseStudy(other, "s.yaml", "/base", reg());
  EXPECT_NE(a.hash(), b.hash());
}

TEST(StudyConfig, OutOfRangeValueNamesFileLineKeyAndRule) {
  std::string y = kGood;
  y.replace(y.find("0.99"), 4, "1.2");
  std::string msg = problems(y);
  EXPECT_NE(msg.find("study.yaml:9: estimator.params.forgetting_factor = 1.2: must be in (0, 1]"),
            std::string::npos)
      << msg;
}

TEST(StudyConfig, WrongTypeIsReported) {
  std::string y = kGood;
  y.replace(y.find("0.99"), 4, "fast");
  std::string msg = problems(y);
  EXPECT_NE(
      msg.find("study.yaml:9: estimator.params.forgetting_factor: expected a number, found 'fast'"),
      std::string::npos)
      << msg;
  y = kGood;
  y.replace(y.find("[1, 2]"), 6, "[1, two]");
  msg = problems(y);
  EXPECT_NE(msg.find("estimator.params.joints: expected a list of integers"), std::string::npos)
      << msg;
}

TEST(StudyConfig, UnknownKeysAreErrorsWithTheClosestMatch) {
  std::string y = kGood;
  y.replace(y.find("forgetting_factor"), 17, "forgeting_factor");
  std::string msg = problems(y);
  EXPECT_NE(msg.find("estimator.params.forgeting_factor: unknown key 'forgeting_factor'"),
            std::string::npos)
      << msg;
  EXPECT_NE(msg.find("did you mean 'forgetting_factor'?"), std::string::npos) << msg;
  msg = problems(std::string(kGood) + "estimater: {type: x}\n");
  EXPECT_NE(msg.find("unknown key 'estimater'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("did you mean 'estimator'?"), std::string::npos) << msg;
}

TEST(StudyConfig, UnknownPluginListsAvailableAndClosest) {
  std::string y = kGood;
  y.replace(y.find("type: test_estimator"), 20, "type: test_estimater");
  std::string msg = problems(y);
  EXPECT_NE(
      msg.find("estimator.type: unknown estimator 'test_estimater'; available: test_estimator; "
               "did you mean 'test_estimator'?"),
      std::string::npos)
      << msg;
}

TEST(StudyConfig, ChoicesIntegerRangesAndListElementsAreChecked) {
  std::string y = kGood;
  y.replace(y.find("    joints: [1, 2]"), 18,
            "    joints: [1, 9]\n    method: lu\n    iterations: 0");
  std::string msg = problems(y);
  EXPECT_NE(msg.find("estimator.params.joints = [1, 9]: element 1 must be in [1, 7]"),
            std::string::npos)
      << msg;
  EXPECT_NE(msg.find("estimator.params.method = lu: must be one of: qr, svd"), std::string::npos)
      << msg;
  EXPECT_NE(msg.find("estimator.params.iterations = 0: must be in [1, 1000]"), std::string::npos)
      << msg;
  // Every problem is reported at once.
  EXPECT_NE(msg.find("3 problems"), std::string::npos) << msg;
}

TEST(StudyConfig, MissingRequiredParameterAndSections) {
  std::string msg = problems(
      "robot: {type: test_throws}\nmodel: {type: test_model}\n"
      "experiment: {type: test_experiment}\nestimator: {type: test_estimator}\n");
  EXPECT_NE(msg.find("experiment.params.file: required parameter is missing"), std::string::npos)
      << msg;
  msg = problems("model: {type: test_model}\nestimator: {type: test_estimator}\n");
  EXPECT_NE(msg.find("robot: missing section"), std::string::npos) << msg;
  EXPECT_NE(msg.find("experiment: missing section"), std::string::npos) << msg;
}

TEST(StudyConfig, MalformedYamlNamesTheLine) {
  std::string msg = problems("robot: {type: test_throws\nmodel: [\n");
  EXPECT_NE(msg.find("study.yaml:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("malformed YAML"), std::string::npos) << msg;
  msg = problems("- just\n- a list\n");
  EXPECT_NE(msg.find("expected a mapping"), std::string::npos) << msg;
}

// Found by tests/fuzz/fuzz_study (corpus/fuzz_study/crash-map-as-key.yaml, the minimised input
// first below): a mapping key that is itself a map or a list threw yaml-cpp's bad conversion out
// of parseStudy; it is a problem with its line, wherever it is.
TEST(StudyConfig, KeysThatAreNotNamesAreProblemsWithTheirLine) {
  std::string msg = problems("s: nop}\nmodel: [{l,&\xd0\xd0 {ng}}]\nfo 1\n");
  EXPECT_NE(msg.find("study.yaml:2: model[0]: a key must be a plain name, found '{...}'"),
            std::string::npos)
      << msg;
  msg = problems(
      "robot: {type: test_throws, {a: 1}: x}\n"
      "model: {type: test_model, params: {[1, 2]: 3}}\n"
      "? [top, level]\n"
      ": 1\n"
      "excitation: {{x: 1}: 2}\n"
      "report: {[r]: 1}\n"
      "experiment: {type: test_experiment, params: {file: a.csv}}\n"
      "estimator: {type: test_estimator}\n"
      "prior: {from: robot, {p: 1}: 2}\n");
  for (const char* want : {"study.yaml:1: robot: a key must be a plain name, found '{...}'",
                           "study.yaml:2: model.params: a key must be a plain name, found '[...]'",
                           "study.yaml:3: a key must be a plain name, found '[...]'",
                           "study.yaml:5: excitation: a key must be a plain name, found '{...}'",
                           "study.yaml:6: report: a key must be a plain name, found '[...]'",
                           "study.yaml:9: prior: a key must be a plain name, found '{...}'"}) {
    EXPECT_NE(msg.find(want), std::string::npos) << want << "\n" << msg;
  }
}

TEST(StudyConfig, SectionShapeErrors) {
  std::string msg = problems("robot: test_throws\n");
  EXPECT_NE(msg.find("study.yaml:1: robot: expected a mapping {type: NAME, params: {...}}"),
            std::string::npos)
      << msg;
  msg = problems("robot: {type: test_throws, param: {}}\n");
  EXPECT_NE(msg.find("robot.param: unknown key 'param'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("did you mean 'params'?"), std::string::npos) << msg;
  msg = problems("robot: {type: test_throws}\nseed: -3\n");
  EXPECT_NE(msg.find("seed = -3: must be a non-negative integer"), std::string::npos) << msg;
}

TEST(StudyConfig, StackedModelsTakeWeights) {
  exid::StudyConfig c = exid::parseStudy(
      "robot: {type: test_throws}\nmodel:\n  - {type: test_model, weight: 2}\n  - {type: "
      "test_model}\n",
      "s.yaml", "/b", reg());
  ASSERT_EQ(c.models.size(), 2u);
  EXPECT_DOUBLE_EQ(c.models[0].weight, 2.0);
  EXPECT_DOUBLE_EQ(c.models[1].weight, 1.0);
  EXPECT_EQ(c.models[1].key_path, "model[1]");
  std::string msg =
      problems("robot: {type: test_throws}\nmodel:\n  - {type: test_model, weight: -1}\n");
  EXPECT_NE(msg.find("model[0].weight = -1: must be a number in (0, inf)"), std::string::npos)
      << msg;
}

TEST(StudyConfig, EmptyOptionalPathsSurviveTheResolvedStudy) {
  // test_experiment's `file` is required; an optional path with an empty default round-trips.
  exid::PluginInfo info;
  info.name = "x";
  info.params = {exid::param_path("extra", std::string(), "optional file")};
  exid::ParamSet ps = exid::resolveParams(info, "{extra: ''}", "x.params", "/base");
  EXPECT_EQ(ps.getString("extra"), "");
  ps = exid::resolveParams(info, "{}", "x.params", "/base");
  EXPECT_EQ(ps.getString("extra"), "");
  // A required path may not be empty.
  std::string msg = problems(
      "robot: {type: test_throws}\nmodel: {type: test_model}\n"
      "experiment: {type: test_experiment, params: {file: ''}}\nestimator: {type: "
      "test_estimator}\n");
  EXPECT_NE(msg.find("experiment.params.file: expected a file path"), std::string::npos) << msg;
  // Every resolved study parses again to the same configuration.
  exid::StudyConfig c = exid::parseStudy(kGood, "s.yaml", "/base", reg());
  EXPECT_EQ(exid::parseStudy(c.resolvedYaml(), "r.yaml", "/base", reg()).hash(), c.hash());
}

// Duplicate keys: yaml-cpp keeps both and a lookup answers the first, so a second `estimator:`
// at the end of a study was silently ignored (issue 16). Both lines are named, at any depth.
TEST(StudyConfig, DuplicateKeysAreRefusedNamingBothLines) {
  std::string m = problems(std::string(kGood) + "estimator: {type: test_estimator}\n");
  EXPECT_NE(m.find("study.yaml:11: estimator: duplicate key 'estimator' (first at line 6)"),
            std::string::npos)
      << m;
  m = problems(
      "robot: {type: test_throws}\nmodel:\n  type: test_model\n  params:\n"
      "    a: 1\n    a: 2\n");
  EXPECT_NE(m.find("study.yaml:6: model.params.a: duplicate key 'a' (first at line 5)"),
            std::string::npos)
      << m;
}

// The name becomes out/<name>: `name: "../../x"` wrote outside out/ (issue 16).
TEST(StudyConfig, TheNameIsAPlainFolderName) {
  for (const char* name : {"../../x", "a/b", "..", ".", ".x", "a\\\\b"}) {
    SCOPED_TRACE(name);
    const std::string m =
        problems(std::string("name: \"") + name + "\"\nrobot: {type: test_throws}\n");
    EXPECT_NE(m.find("study.yaml:1: name = "), std::string::npos) << m;
  }
  EXPECT_EQ(problems("name: run_1-b.c\nrobot: {type: test_throws}\n"), "");
}

// A huge list is refused by its length, and the message stays short (a 25-million-element list
// gave a 75 MB message, issue 16).
TEST(StudyConfig, HugeListsAreRefusedWithAShortMessage) {
  std::string list = "[";
  for (int i = 0; i < 100001; ++i) list += (i ? ",1" : "1");
  list += "]";
  const std::string m = problems(
      "robot: {type: test_throws}\nmodel: {type: test_model}\nexperiment: {type: "
      "test_experiment, params: {file: a.csv}}\nestimator: {type: test_estimator, params: "
      "{joints: " +
      list + "}}\n");
  EXPECT_NE(m.find("a list of 100001 elements; at most 100000"), std::string::npos) << m;
  EXPECT_LT(m.size(), 2000u);
}
