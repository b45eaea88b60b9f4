// The plugin loader: manifests are checked before any C++ object is touched, refused libraries
// say why (expected vs found), factories that throw are reported, objects keep their library.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>

#include "exid/config.hpp"
#include "exid/error.hpp"
#include "exid/interfaces.hpp"
#include "exid/registry.hpp"

namespace fs = std::filesystem;

namespace {
fs::path testLib(const std::string& name) {
  return fs::path(EXID_TEST_PLUGIN_DIR) / name / ("libexid_plugin_" + name + ".so");
}
std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(PluginLoader, LoadsALibraryAndCreatesItsPlugin) {
  exid::Registry reg;
  reg.loadLibrary(testLib("good_plugin"));
  const exid::PluginInfo* info = reg.find(exid::PluginKind::Criterion, "test_trace");
  ASSERT_NE(info, nullptr);
  EXPECT_EQ(info->version, "0.1");
  ASSERT_EQ(info->params.size(), 1u);
  EXPECT_EQ(info->params[0].name, "scale");
  exid::ParamSet ps = exid::resolveParams(*info, "{scale: 2}", "test", "");
  auto crit = reg.create<exid::Criterion>("test_trace", ps);
  EXPECT_EQ(crit->pluginName(), "test_trace");
  Eigen::MatrixXd M = Eigen::MatrixXd::Identity(3, 3);
  Eigen::MatrixXd dM;
  EXPECT_DOUBLE_EQ(crit->evaluate(M, &dM), 6.0);
  EXPECT_DOUBLE_EQ(dM(1, 1), 2.0);
}

TEST(PluginLoader, ObjectKeepsItsLibraryLoadedAfterTheRegistryIsGone) {
  std::shared_ptr<exid::Criterion> crit;
  {
    exid::Registry reg;
    reg.loadLibrary(testLib("good_plugin"));
    const exid::PluginInfo& info = reg.get(exid::PluginKind::Criterion, "test_trace");
    crit = reg.create<exid::Criterion>("test_trace", exid::resolveParams(info, "{}", "test", ""));
  }
  // The registry (and its handle on the library) is destroyed; the object's code must still be
  // mapped, or this call would crash.
  Eigen::MatrixXd M = 3.0 * Eigen::MatrixXd::Identity(2, 2);
  EXPECT_DOUBLE_EQ(crit->evaluate(M, nullptr), 6.0);
  crit.reset();  // the last owner unloads the library here
}

TEST(PluginLoader, RefusesAWrongAbiVersionWithExpectedAndFound) {
  exid::Registry reg;
  std::string msg = errorOf([&] { reg.loadLibrary(testLib("wrong_abi_plugin")); });
  EXPECT_NE(msg.find("ABI version mismatch"), std::string::npos) << msg;
  EXPECT_NE(msg.find("expected " + std::to_string(EXID_PLUGIN_ABI_VERSION)), std::string::npos)
      << msg;
  EXPECT_NE(msg.find("found 999"), std::string::npos) << msg;
  EXPECT_NE(msg.find("wrong_abi_plugin"), std::string::npos) << msg;
  EXPECT_EQ(reg.find(exid::PluginKind::Criterion, "test_stale"), nullptr);
  ASSERT_EQ(reg.refused().size(), 1u);
}

TEST(PluginLoader, RefusesAMismatchedBuildFingerprint) {
  exid::Registry reg;
  std::string msg = errorOf([&] { reg.loadLibrary(testLib("wrong_fingerprint_plugin")); });
  EXPECT_NE(msg.find("fingerprint mismatch"), std::string::npos) << msg;
  EXPECT_NE(msg.find("exid version: expected '" EXID_VERSION_STRING "', found '9.9.9'"),
            std::string::npos)
      << msg;
  EXPECT_NE(msg.find("Eigen max alignment"), std::string::npos) << msg;
}

TEST(PluginLoader, RefusesALibraryWithoutTheEntryPoint) {
  exid::Registry reg;
  std::string msg = errorOf([&] { reg.loadLibrary(testLib("no_entry_plugin")); });
  EXPECT_NE(msg.find("no 'exid_plugin_manifest' entry point"), std::string::npos) << msg;
}

TEST(PluginLoader, RefusesAFileThatIsNotALibrary) {
  const fs::path bogus = fs::temp_directory_path() / "libexid_plugin_bogus.so";
  { std::ofstream(bogus) << "not an ELF file"; }
  exid::Registry reg;
  std::string msg = errorOf([&] { reg.loadLibrary(bogus); });
  EXPECT_NE(msg.find("cannot be loaded"), std::string::npos) << msg;
  fs::remove(bogus);
}

TEST(PluginLoader, ScanRecordsRefusedLibrariesAndGoesOn) {
  exid::Registry reg;
  for (const char* d : {"wrong_abi_plugin", "no_entry_plugin", "good_plugin"})
    reg.addSearchPath(fs::path(EXID_TEST_PLUGIN_DIR) / d);
  reg.scan();
  EXPECT_NE(reg.find(exid::PluginKind::Criterion, "test_trace"), nullptr);
  EXPECT_GE(reg.refused().size(), 2u);
}

TEST(PluginLoader, AFactoryThatThrowsIsReportedAndTheProcessSurvives) {
  exid::Registry reg;
  reg.loadLibrary(testLib("good_plugin"));
  const exid::PluginInfo& info = reg.get(exid::PluginKind::Robot, "test_throws");
  std::string msg = errorOf(
      [&] { reg.create<exid::Robot>("test_throws", exid::resolveParams(info, "{}", "t", "")); });
  EXPECT_NE(msg.find("robot 'test_throws' could not be created"), std::string::npos) << msg;
  EXPECT_NE(msg.find("deliberate failure in the factory"), std::string::npos) << msg;
  // Still usable afterwards.
  EXPECT_NE(reg.find(exid::PluginKind::Criterion, "test_trace"), nullptr);
}

TEST(PluginLoader, UnknownNameListsTheAvailableOnesAndTheClosestMatch) {
  exid::Registry reg;
  reg.loadLibrary(testLib("good_plugin"));
  std::string msg = errorOf([&] { reg.get(exid::PluginKind::Criterion, "test_trase"); });
  EXPECT_NE(msg.find("unknown criterion 'test_trase'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("available: test_trace"), std::string::npos) << msg;
  EXPECT_NE(msg.find("did you mean 'test_trace'?"), std::string::npos) << msg;
}

TEST(PluginLoader, SearchOrderPutsPluginPathThenEnvironmentFirst) {
  ::setenv("EXID_PLUGIN_PATH", "/env/one:/env/two", 1);
  exid::Registry reg;
  reg.addSearchPath("/cli/dir");
  auto paths = reg.searchPaths();
  ::unsetenv("EXID_PLUGIN_PATH");
  ASSERT_GE(paths.size(), 4u);
  EXPECT_EQ(paths[0], fs::path("/cli/dir"));
  EXPECT_EQ(paths[1], fs::path("/env/one"));
  EXPECT_EQ(paths[2], fs::path("/env/two"));
}

TEST(PluginKinds, RoundTripAndUnknownKind) {
  for (exid::PluginKind k : exid::allPluginKinds())
    EXPECT_EQ(exid::pluginKindFromString(exid::toString(k)), k);
  std::string msg = errorOf([] { exid::pluginKindFromString("estimater"); });
  EXPECT_NE(msg.find("did you mean 'estimator'?"), std::string::npos) << msg;
}
