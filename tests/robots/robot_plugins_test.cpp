// Robot plugins, loaded straight from their library in the build tree (dlopen + manifest): each
// shipped robot builds a model equal to the one loaded from its description file in the source
// tree (the library carries the files embedded, so it also works when installed), and every
// entry of robots/catalogue.yaml gives a model whose regressor reproduces Newton-Euler.
#include <dlfcn.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <random>
#include <set>

#include "exid/dynamics.hpp"
#include "exid/error.hpp"
#include "exid/floating_base.hpp"
#include "exid/interfaces.hpp"
#include "exid/robot_loaders.hpp"

namespace {

const std::string kLibrary = "robots";

std::string pluginFile(const std::string& library) {
  return std::string(EXID_BINARY_DIR) + "/plugins/libexid_plugin_" + library + ".so";
}

/// Every plugin the robots library lists (from its manifest).
exid::PluginList listRobots() {
  const std::string file = pluginFile(kLibrary);
  void* handle = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);  // kept open: factories live there
  if (!handle) {
    ADD_FAILURE() << dlerror();
    return {};
  }
  auto fn = reinterpret_cast<exid_plugin_manifest_fn>(dlsym(handle, "exid_plugin_manifest"));
  if (!fn) {
    ADD_FAILURE() << "no manifest in " << file;
    return {};
  }
  const auto* m = fn();
  EXPECT_EQ(m->abi_version, EXID_PLUGIN_ABI_VERSION);
  exid::PluginList list;
  m->list_plugins(&list);
  return list;
}

struct LoadedPlugin {
  exid::PluginInfo info;
};

/// The plugin `name` of the robots library.
bool loadPlugin(const std::string& name, LoadedPlugin* out) {
  for (auto& info : listRobots())
    if (info.name == name) {
      out->info = info;
      return true;
    }
  return false;
}

exid::ParamSet defaults(const exid::PluginInfo& info) {
  exid::ParamSet p;
  p.context = "test";
  for (const auto& d : info.params) {
    if (d.default_value) p.set(d.name, *d.default_value);
  }
  return p;
}

std::shared_ptr<const exid::RobotModel> build(const exid::PluginInfo& info,
                                              const exid::ParamSet& p) {
  auto obj = info.factory(p);
  auto* robot = static_cast<exid::Robot*>(obj.get());
  exid::RunContext ctx;
  ctx.study_dir = std::string(EXID_SOURCE_DIR) + "/robots";
  return robot->build(ctx);
}

void expectSameModel(const exid::RobotModel& a, const exid::RobotModel& b) {
  ASSERT_EQ(a.dof(), b.dof());
  EXPECT_EQ(a.name, b.name);
  EXPECT_LT((a.inertialParameters() - b.inertialParameters()).cwiseAbs().maxCoeff(), 1e-15);
  for (int i = 0; i < a.dof(); ++i) {
    EXPECT_LT((a.bodies[i].pre.p - b.bodies[i].pre.p).norm(), 1e-15);
    EXPECT_EQ(a.drives[i].rotor_inertia, b.drives[i].rotor_inertia);
    EXPECT_EQ(a.limits[i].q_max, b.limits[i].q_max);
  }
  EXPECT_EQ(a.transmission.size(), b.transmission.size());
}

TEST(RobotPlugins, NamedRobotsEqualTheirFiles) {
  const std::vector<std::pair<std::string, std::string>> robots = {
      {"planar2r", "planar2r/planar2r.yaml"},
      {"puma560", "puma560/puma560.yaml"},
      {"irp6", "irp6/irp6.yaml"},
      {"stanford", "stanford/stanford.yaml"},
      {"panda", "panda/panda.yaml"}};
  int tested = 0;
  for (const auto& [name, file] : robots) {
    SCOPED_TRACE(name);
    LoadedPlugin p;
    ASSERT_TRUE(loadPlugin(name, &p)) << name << " plugin not built";
    EXPECT_EQ(p.info.kind, exid::PluginKind::Robot);
    EXPECT_EQ(p.info.name, name);
    std::vector<std::string> w;
    exid::LoadOptions o;
    o.warnings = &w;
    const auto fromFile = exid::loadDhYaml(std::string(EXID_SOURCE_DIR) + "/robots/" + file, o);
    const auto built = build(p.info, defaults(p.info));
    expectSameModel(*built, fromFile);
    ++tested;
  }
  ASSERT_GT(tested, 0) << "robot plugins not built in " << EXID_BINARY_DIR;
}

// Every plugin of the library is a robot, the shipped robots are those of the catalogue, and each
// robot folder with a description is in the catalogue (a description nobody can load by name
// would be dead data).
TEST(RobotPlugins, TheLibraryListsDhUrdfAndEveryCatalogueRobot) {
  std::set<std::string> names;
  for (const auto& info : listRobots()) {
    EXPECT_EQ(info.kind, exid::PluginKind::Robot) << info.name;
    EXPECT_FALSE(info.doc.empty()) << info.name;
    EXPECT_TRUE(names.insert(info.name).second) << "listed twice: " << info.name;
  }
  EXPECT_TRUE(names.count("dh"));
  EXPECT_TRUE(names.count("urdf"));
  for (const auto& dir :
       std::filesystem::directory_iterator(std::string(EXID_SOURCE_DIR) + "/robots")) {
    const std::string n = dir.path().filename().string();
    if (!dir.is_directory()) continue;
    const bool described = std::filesystem::exists(dir.path() / (n + ".yaml")) ||
                           std::filesystem::exists(dir.path() / (n + ".urdf"));
    if (described) {
      EXPECT_TRUE(names.count(n)) << "robots/" << n << " is not in catalogue.yaml";
    }
  }
}

// Physics for every catalogue robot and variant: Y(q, qd, qdd) pi equals Newton-Euler at random
// states, so a description that loads but is mis-assembled (a joint axis, a frame) is caught.
TEST(RobotPlugins, EveryCatalogueRobotAndVariantGivesNewtonEulerTorques) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int tested = 0;
  for (const auto& info : listRobots()) {
    if (info.name == "dh" || info.name == "urdf" || info.name == "mjcf" || info.name == "sdf")
      continue;  // (robots from the user's file)
    std::vector<std::string> variants{""};
    for (const auto& d : info.params)
      if (d.name == "variant") variants = d.choices;
    for (const auto& v : variants) {
      SCOPED_TRACE(info.name + " " + v);
      exid::ParamSet p = defaults(info);
      if (!v.empty()) p.set("variant", v);
      const auto model = build(info, p);
      const int n = model->numJoints();  // the tree (a closed chain's spanning tree)
      ASSERT_GT(n, 0);
      if (model->floating_base) {  // the floating regressor against its Newton-Euler pass
        for (int k = 0; k < 3; ++k) {
          Eigen::VectorXd q(n), qd(n), qdd(n);
          exid::BaseMotion b;
          for (int i = 0; i < n; ++i) q(i) = u(rng), qd(i) = u(rng), qdd(i) = u(rng);
          for (int i = 0; i < 9; ++i) b(i) = 5.0 * u(rng);
          Eigen::MatrixXd Y;
          exid::floatingRegressor(*model, q, qd, qdd, b, Y);
          const Eigen::VectorXd id = exid::floatingInverseDynamics(*model, q, qd, qdd, b);
          EXPECT_LT((Y * exid::floatingParameters(*model) - id).cwiseAbs().maxCoeff(),
                    1e-12 * (1.0 + id.cwiseAbs().maxCoeff()));
        }
        ++tested;
        continue;
      }
      auto data = exid::makeDynamicsData(*model);
      for (int k = 0; k < 3; ++k) {
        Eigen::VectorXd q(n), qd(n), qdd(n);
        for (int i = 0; i < n; ++i) q(i) = u(rng), qd(i) = u(rng), qdd(i) = u(rng);
        Eigen::MatrixXd Y(n, 10 * n);
        exid::torqueRegressor(*model, *data, q, qd, qdd, Y);
        const Eigen::VectorXd tau = exid::inverseDynamics(*model, *data, q, qd, qdd);
        EXPECT_LT((Y * model->inertialParameters() - tau).cwiseAbs().maxCoeff(),
                  1e-12 * (1.0 + tau.cwiseAbs().maxCoeff()));
      }
      ++tested;
    }
  }
  EXPECT_GE(tested, 8);  // seven robots, the PUMA 560 twice
}

TEST(RobotPlugins, Puma560VariantsStrictAndGravity) {
  LoadedPlugin p;
  ASSERT_TRUE(loadPlugin("puma560", &p)) << "puma560 plugin not built";
  exid::ParamSet params = defaults(p.info);
  params.set("variant", std::string("urdf"));
  const auto urdf = build(p.info, params);
  EXPECT_EQ(urdf->dof(), 6);
  EXPECT_NE(urdf->source.find("puma560.urdf"), std::string::npos);
  params.set("gravity", std::vector<double>{0, 0, -9.80665});
  EXPECT_EQ(build(p.info, params)->gravity.z(), -9.80665);
  params.set("strict", true);
  EXPECT_THROW(build(p.info, params), exid::Error);
  params.set("gravity", std::vector<double>{0, 0});
  EXPECT_THROW(p.info.factory(params), exid::Error);
}

TEST(RobotPlugins, PublishedDefectsAreANoteAndAUsersFileGetsWarnings) {
  // The shipped PUMA 560: its published data's defects are stated once, as a note.
  LoadedPlugin p;
  ASSERT_TRUE(loadPlugin("puma560", &p)) << "puma560 plugin not built";
  const auto puma = build(p.info, defaults(p.info));
  EXPECT_TRUE(puma->warnings.empty());
  ASSERT_EQ(puma->notes.size(), 1u);
  for (const char* what : {"published", "triangle inequality", "link1", "link3", "zero mass"})
    EXPECT_NE(puma->notes[0].find(what), std::string::npos) << what << ": " << puma->notes[0];
  // The same data as a user's own file (the dh plugin): warnings the user can act on.
  LoadedPlugin dh;
  ASSERT_TRUE(loadPlugin("dh", &dh)) << "dh plugin not built";
  exid::ParamSet params = defaults(dh.info);
  params.set("file", std::string(EXID_SOURCE_DIR) + "/robots/puma560/puma560.yaml");
  const auto own = build(dh.info, params);
  EXPECT_TRUE(own->notes.empty());
  EXPECT_EQ(own->warnings.size(), 3u);
}

TEST(RobotPlugins, FilePluginsResolveRelativePaths) {
  for (const auto& [name, file] : std::vector<std::pair<std::string, std::string>>{
           {"dh", "stanford/stanford.yaml"}, {"urdf", "puma560/puma560.urdf"}}) {
    SCOPED_TRACE(name);
    LoadedPlugin p;
    ASSERT_TRUE(loadPlugin(name, &p)) << name << " plugin not built";
    exid::ParamSet params = defaults(p.info);
    EXPECT_FALSE(params.has("file"));  // required
    params.set("file", file);          // relative to the study directory
    EXPECT_EQ(build(p.info, params)->dof(), 6);
    params.set("file", std::string("missing.yaml"));
    EXPECT_THROW(build(p.info, params), exid::Error);
  }
}

}  // namespace
