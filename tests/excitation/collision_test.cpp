// Collision avoidance in excitation design: distances against closed forms, their derivatives
// (witness points and point Jacobians) against central differences, separated and penetrating,
// the pair rules, geometry from DH YAML, URDF and STL, the problem's collision rows, and an
// optimiser that ends clear of an obstacle its unconstrained design hits, checked again at the
// controller rate on the exported file.
#include "exid/collision.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "exid/config.hpp"
#include "exid/error.hpp"
#include "exid/excitation.hpp"
#include "exid/interfaces.hpp"
#include "exid/robot_loaders.hpp"
#include "exid/runner.hpp"
#include "exid/trajectory_export.hpp"
#include "exid_test.hpp"

namespace fs = std::filesystem;

namespace {

exid::Obstacle obstacle(const std::string& name, exid::CollisionShape::Kind kind,
                        const Eigen::Vector3d& at, double radius, double length = 0,
                        const Eigen::Vector3d& size = Eigen::Vector3d::Zero()) {
  exid::Obstacle o;
  o.name = name;
  o.shape.kind = kind;
  o.shape.pose.p = at;
  o.shape.radius = radius;
  o.shape.length = length;
  o.shape.size = size;
  return o;
}

std::string message(const std::function<void()>& f) {
  try {
    f();
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "(no error)";
}

// Central differences of the distances along each coordinate.
Eigen::MatrixXd centralDifferences(exid::CollisionModel& cm, const Eigen::VectorXd& q, double h) {
  Eigen::MatrixXd D(cm.numPairs(), q.size());
  for (int i = 0; i < q.size(); ++i) {
    Eigen::VectorXd qp = q, qm = q, dp, dm;
    qp(i) += h;
    qm(i) -= h;
    cm.distances(qp, &dp);
    cm.distances(qm, &dm);
    D.col(i) = (dp - dm) / (2 * h);
  }
  return D;
}

}  // namespace

TEST(Collision, DistancesAgreeWithTheClosedForm) {
  // Panda at q = 0: link 1's capsule is the segment z in [0, 0.283] on the base z axis, radius
  // 0.06. A ball of radius 0.05 at (0.5, 0, 0.1) is 0.5 - 0.06 - 0.05 = 0.39 m from it.
  auto robot = exid_test::robot("panda");
  exid::CollisionOptions o;
  o.self = false;
  o.obstacles = {obstacle("ball", exid::CollisionShape::Kind::Sphere, {0.5, 0, 0.1}, 0.05)};
  exid::CollisionModel cm(*robot, o);
  const auto& names = cm.pairNames();
  const auto it = std::find(names.begin(), names.end(), "link1 ~ ball");
  ASSERT_NE(it, names.end());
  Eigen::VectorXd d;
  cm.distances(Eigen::VectorXd::Zero(7), &d);
  const auto p = static_cast<Eigen::Index>(it - names.begin());
  EXPECT_NEAR(d(p), 0.39, 1e-9);
  const auto& [a, b] = cm.witnessPoints()[static_cast<std::size_t>(p)];
  EXPECT_NEAR((a - Eigen::Vector3d(0.06, 0, 0.1)).norm(), 0.0, 1e-6);
  EXPECT_NEAR((b - Eigen::Vector3d(0.45, 0, 0.1)).norm(), 0.0, 1e-6);
  // Turning joint 1 does not move link 1's capsule (on the axis): derivative 0 along q1.
  Eigen::MatrixXd D;
  cm.distances(Eigen::VectorXd::Zero(7), &d, &D);
  EXPECT_NEAR(D(p, 0), 0.0, 1e-12);
  // the base is not paired with the environment (both fixed)
  for (const auto& n : names) EXPECT_EQ(n.rfind("base ~", 0), std::string::npos) << n;
}

TEST(Collision, DerivativesMatchCentralDifferencesSeparatedAndPenetrating) {
  auto robot = exid_test::robot("panda");
  exid::CollisionOptions o;
  o.obstacles = {
      obstacle("table", exid::CollisionShape::Kind::Box, {0.5, 0, 0.2}, 0, 0, {0.6, 0.8, 0.04}),
      obstacle("ball", exid::CollisionShape::Kind::Sphere, {0.3, 0.3, 0.6}, 0.08),
      obstacle("post", exid::CollisionShape::Kind::Cylinder, {-0.3, 0.2, 0.5}, 0.05, 1.0)};
  exid::CollisionModel cm(*robot, o);
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  int separated = 0, penetrating = 0, penetrating_estimated = 0, deep = 0;
  for (int trial = 0; trial < 40; ++trial) {
    Eigen::VectorXd q(7);
    for (int j = 0; j < 7; ++j) {
      const auto& L = robot->limits[static_cast<std::size_t>(j)];
      q(j) = 0.5 * (L.q_min + L.q_max) + 0.45 * (L.q_max - L.q_min) * U(rng);
    }
    Eigen::VectorXd d;
    Eigen::MatrixXd D;
    cm.distances(q, &d, &D);
    const Eigen::MatrixXd fd = centralDifferences(cm, q, 1e-6);
    for (int p = 0; p < cm.numPairs(); ++p) {
      // skip rows where the closest shapes of the pair may switch within the step
      Eigen::VectorXd dp;
      if (std::abs(d(p)) < 1e-4) continue;
      const std::string& name = cm.pairNames()[static_cast<std::size_t>(p)];
      // the table (a box, 4 cm thick): closed form, exact while no capsule's axis crosses its
      // middle plane (deeper, the nearest face switches along the axis: a kink)
      if (name.find("table") != std::string::npos && d(p) < -0.02) {
        ++deep;
        continue;
      }
      if (d(p) < 0 && name.find("post") != std::string::npos) {
        // a cylinder penetrated: FCL's contact depth is an estimate; its normal points the way
        // out
        const double cosine = fd.row(p).dot(D.row(p)) / (fd.row(p).norm() * D.row(p).norm());
        EXPECT_GT(cosine, 0.9) << name << " at trial " << trial << ": d = " << d(p);
        ++penetrating_estimated;
        continue;
      }
      const double err = (fd.row(p) - D.row(p)).cwiseAbs().maxCoeff();
      const double scale = std::max(1.0, D.row(p).cwiseAbs().maxCoeff());
      if (err > 1e-5 * scale) {
        // a switch between two shape pairs of the same bodies, or a box edge: accept only
        // when the one-sided differences disagree as well (a kink, not a wrong derivative)
        const Eigen::MatrixXd fd2 = centralDifferences(cm, q, 1e-8);
        EXPECT_LE((fd2.row(p) - D.row(p)).cwiseAbs().maxCoeff(), 1e-4 * scale)
            << cm.pairNames()[static_cast<std::size_t>(p)] << " at trial " << trial
            << ": d = " << d(p) << "\n analytic " << D.row(p) << "\n fd " << fd.row(p);
      }
      (d(p) > 0 ? separated : penetrating) += 1;
    }
  }
  EXPECT_GT(separated, 200);
  EXPECT_GT(penetrating, 5) << "the poses should make some capsule pairs penetrate";
  EXPECT_GT(penetrating_estimated, 0) << "and some penetrate the post";
  EXPECT_LT(deep, penetrating) << "most penetrations are shallow enough to compare";
}

TEST(Collision, PairRules) {
  auto robot = exid_test::robot("panda");
  exid::CollisionOptions o;
  exid::CollisionModel self(*robot, o);
  const auto& names = self.pairNames();
  auto has = [&](const std::vector<std::string>& v, const std::string& s) {
    return std::find(v.begin(), v.end(), s) != v.end();
  };
  EXPECT_FALSE(has(names, "link3 ~ link4"));  // parent and child
  EXPECT_FALSE(has(names, "base ~ link1"));
  EXPECT_TRUE(has(names, "base ~ link2"));
  EXPECT_TRUE(has(names, "link1 ~ link7"));
  EXPECT_TRUE(has(self.excludedPairs(), "link3 ~ link4 (parent and child)"));
  // 8 sides with geometry (base + 7 links): 28 pairs, 7 parent-child
  EXPECT_EQ(self.numPairs(), 28 - 7);
  o.allowed_pairs = {{"link5", "link7"}};
  exid::CollisionModel allowed(*robot, o);
  EXPECT_EQ(allowed.numPairs(), 28 - 8);
  EXPECT_TRUE(has(allowed.excludedPairs(), "link5 ~ link7 (allowed by the study)"));
  o.allowed_pairs = {{"link5", "wall"}};
  EXPECT_NE(message([&] {
              exid::CollisionModel x(*robot, o);
            }).find("'wall' is neither a body of robot 'panda' nor an obstacle"),
            std::string::npos);
  // no geometry at all
  exid::RobotModel bare = *robot;
  bare.collision.clear();
  EXPECT_NE(message([&] {
              exid::CollisionModel x(bare, exid::CollisionOptions{});
            }).find("the robot description has no collision geometry"),
            std::string::npos);
  // self off, obstacles only: link sides against each obstacle
  exid::CollisionOptions env;
  env.self = false;
  env.obstacles = {obstacle("ball", exid::CollisionShape::Kind::Sphere, {1, 1, 1}, 0.1)};
  EXPECT_EQ(exid::CollisionModel(*robot, env).numPairs(), 7);
  env.obstacles.push_back(env.obstacles[0]);
  EXPECT_NE(message([&] { exid::CollisionModel x(*robot, env); }).find("'ball' is used twice"),
            std::string::npos);
  exid::CollisionOptions neg;
  neg.margin_m = -0.1;
  EXPECT_NE(message([&] { exid::CollisionModel x(*robot, neg); }).find("margin_m"),
            std::string::npos);
}

TEST(Collision, GeometryFromDhYamlUrdfAndStl) {
  const std::string dh =
      "name: two\nconvention: modified\n"
      "links:\n"
      "  - {a: 0, alpha: 0, d: 0, mass: 1, collision: [{sphere: {radius_m: 0.1}, xyz_m: [0.5, 0, "
      "0]}]}\n"
      "  - {a: 1, alpha: 0, d: 0, mass: 1, collision: [{box: {size_m: [0.2, 0.2, 0.2]}}]}\n"
      "base_collision: [{cylinder: {radius_m: 0.1, length_m: 0.2}, rpy_rad: [1.5707963267948966, "
      "0, 0]}]\n";
  const exid::RobotModel r = exid::loadDhYamlString(dh, "two.yaml");
  ASSERT_EQ(r.collision.size(), 3u);
  EXPECT_EQ(r.collision[0].body, 0);
  EXPECT_EQ(r.collision[0].kind, exid::CollisionShape::Kind::Sphere);
  EXPECT_EQ(r.collision[1].body, 1);
  EXPECT_EQ(r.collision[2].body, -1);
  EXPECT_NEAR(r.collision[2].pose.R(2, 1), 1.0, 1e-12);  // Rx(pi/2): sin(roll)
  EXPECT_NE(r.collision[0].where.find("two.yaml:4"), std::string::npos) << r.collision[0].where;
  // errors name the line and the key
  const std::string bad =
      "convention: modified\nlinks:\n  - {a: 0, d: 0, alpha: 0,\n     collision: [{sphere: "
      "{radius_m: -1}}]}\n";
  const std::string e1 = message([&] { exid::loadDhYamlString(bad, "bad.yaml"); });
  EXPECT_NE(
      e1.find("bad.yaml:4: links[0] (link 'link1').collision[0].sphere.radius_m: must be > 0"),
      std::string::npos)
      << e1;
  const std::string two =
      "convention: modified\nlinks:\n  - {a: 0, d: 0, alpha: 0, collision: [{sphere: {radius_m: "
      "1}, box: {size_m: [1, 1, 1]}}]}\n";
  EXPECT_NE(message([&] { exid::loadDhYamlString(two, "two.yaml"); }).find("give exactly one of"),
            std::string::npos);

  // URDF: a box on the moving link, a sphere on a link fixed to it (merged with its pose), a
  // cylinder on the base, and an STL mesh relative to the URDF's folder.
  const fs::path dir = fs::temp_directory_path() / ("exid_collision_" + std::to_string(getpid()));
  fs::create_directories(dir);
  {
    std::ofstream stl(dir / "tet.stl");
    stl << "solid tet\n";
    const double v[4][3] = {{0, 0, 0}, {0.1, 0, 0}, {0, 0.1, 0}, {0, 0, 0.1}};
    const int f[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
    for (const auto& t : f) {
      stl << " facet normal 0 0 0\n  outer loop\n";
      for (int k : t) stl << "   vertex " << v[k][0] << " " << v[k][1] << " " << v[k][2] << "\n";
      stl << "  endloop\n endfacet\n";
    }
    stl << "endsolid tet\n";
  }
  const std::string urdf = R"(<robot name="one">
  <link name="base"><collision><origin xyz="0 0 -0.5"/><geometry><cylinder radius="0.2" length="0.1"/></geometry></collision></link>
  <link name="arm">
    <inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0.5 0 0"/><geometry><box size="1 0.1 0.1"/></geometry></collision>
  </link>
  <link name="tip"><collision><geometry><sphere radius="0.05"/></geometry></collision>
    <collision><origin xyz="0 0 0.2"/><geometry><mesh filename="tet.stl"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
  <joint name="fix" type="fixed"><parent link="arm"/><child link="tip"/><origin xyz="1 0 0"/></joint>
</robot>)";
  std::ofstream(dir / "one.urdf") << urdf;
  const exid::RobotModel u = exid::loadUrdf(dir / "one.urdf");
  ASSERT_EQ(u.collision.size(), 4u);
  int tip_sphere = -1, mesh = -1;
  for (int i = 0; i < 4; ++i) {
    const auto& s = u.collision[static_cast<std::size_t>(i)];
    if (s.kind == exid::CollisionShape::Kind::Sphere) tip_sphere = i;
    if (s.kind == exid::CollisionShape::Kind::Mesh) mesh = i;
    if (s.kind == exid::CollisionShape::Kind::Cylinder) {
      EXPECT_EQ(s.body, -1);
    }
  }
  ASSERT_GE(tip_sphere, 0);
  ASSERT_GE(mesh, 0);
  EXPECT_EQ(u.collision[static_cast<std::size_t>(tip_sphere)].body, 0);
  EXPECT_NEAR(
      (u.collision[static_cast<std::size_t>(tip_sphere)].pose.p - Eigen::Vector3d(1, 0, 0)).norm(),
      0.0, 1e-15);
  EXPECT_EQ(u.collision[static_cast<std::size_t>(mesh)].mesh_file, (dir / "tet.stl").string());
  // a wall at x = 1.5: the tip sphere at (1, 0, 0) is 0.45 from it; the tetrahedron (0.2 above
  // the tip, corner at x = 1.1) 0.4 - and it is the closer
  exid::CollisionOptions o;
  o.self = false;
  o.obstacles = {
      obstacle("wall", exid::CollisionShape::Kind::Box, {1.6, 0, 0}, 0, 0, {0.2, 2.0, 2.0})};
  exid::CollisionModel cm(u, o);
  ASSERT_EQ(cm.numPairs(), 1);
  Eigen::VectorXd d;
  Eigen::MatrixXd D;
  cm.distances(Eigen::VectorXd::Zero(1), &d, &D);
  EXPECT_NEAR(d(0), 0.4, 1e-6);
  // turning by a: the tet's x-most corner at 1.1 (cos a, sin a): d = 1.5 - 1.1 cos a
  const double a = 0.1;
  cm.distances(Eigen::VectorXd::Constant(1, a), &d, &D);
  EXPECT_NEAR(d(0), 1.5 - 1.1 * std::cos(a), 1e-6);
  EXPECT_NEAR(D(0, 0), 1.1 * std::sin(a), 1e-6);
  // a mesh that cannot be read is named
  exid::RobotModel missing = u;
  missing.collision[static_cast<std::size_t>(mesh)].mesh_file = (dir / "none.stl").string();
  EXPECT_NE(message([&] {
              exid::CollisionModel x(missing, o);
            }).find("none.stl: cannot open the mesh file (no such file)"),
            std::string::npos);
  missing.collision[static_cast<std::size_t>(mesh)].mesh_file = "package://robot/link.stl";
  EXPECT_NE(message([&] { exid::CollisionModel x(missing, o); }).find("package:// URIs"),
            std::string::npos);
  fs::remove_all(dir);
}

namespace {

const char* kFourier =
    "{period_s: 10, harmonics: 5, sample_period_s: 0.1, position_margin_rad: 0.1, "
    "acceleration_limits: false, init: random, init_scale: 0.5}";

struct ProblemSetup {
  std::shared_ptr<const exid::RobotModel> robot;
  std::shared_ptr<exid::Trajectory> traj;
  std::unique_ptr<exid::ExcitationProblem> problem;
};

ProblemSetup make(std::shared_ptr<const exid::CollisionOptions> collision) {
  ProblemSetup s;
  exid::RunContext ctx;
  ctx.seed = 5;
  s.robot = exid_test::robot("panda");
  auto model =
      exid_test::create<exid::ObservationModel>("differential", "{coulomb: true, viscous: true}");
  model->bind(s.robot, ctx);
  s.traj = exid_test::create<exid::Trajectory>("fourier", kFourier);
  s.traj->bind(s.robot, ctx);
  exid::ExcitationOptions xo;
  xo.position_margin = s.traj->positionMargin();
  xo.velocity_limits = s.traj->velocityLimits();
  xo.acceleration_limits = s.traj->accelerationLimits();
  xo.collision = std::move(collision);
  s.problem = exid::makeExcitationProblem(s.traj, model,
                                          exid_test::create<exid::Criterion>("cond", "{}"), xo);
  return s;
}

std::shared_ptr<exid::CollisionOptions> table(double margin, double height) {
  auto o = std::make_shared<exid::CollisionOptions>();
  o->margin_m = margin;
  o->obstacles = {obstacle("table", exid::CollisionShape::Kind::Box, {0.55, 0, height - 0.02}, 0, 0,
                           {0.6, 1.2, 0.04})};
  return o;
}

}  // namespace

TEST(Collision, ProblemRowsAndTheirJacobianMatchCentralDifferences) {
  // self-collision and a ball: exact distances (capsules and a sphere) in every row
  auto ball = std::make_shared<exid::CollisionOptions>();
  ball->margin_m = 0.03;
  ball->obstacles = {obstacle("ball", exid::CollisionShape::Kind::Sphere, {0.4, 0.2, 0.5}, 0.1)};
  ProblemSetup s = make(ball);
  exid::ExcitationProblem& p = *s.problem;
  exid::CollisionModel cm(*s.robot, *ball);
  const int K = s.traj->evaluate(p.initial()).size();
  ASSERT_EQ(p.numNonlinearConstraints(), cm.numPairs() * K);
  const Eigen::VectorXd z = p.initial();
  Eigen::VectorXd g, gall;
  Eigen::MatrixXd J, Jall;
  p.nonlinearConstraints(z, &g, &J);
  p.constraints(z, &gall, &Jall);
  EXPECT_EQ((gall.tail(g.size()) - g).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ((Jall.bottomRows(g.size()) - J).cwiseAbs().maxCoeff(), 0.0);
  // row p K + k is margin - d_p(q(t_k))
  const exid::Samples smp = s.traj->evaluate(z);
  Eigen::VectorXd d;
  cm.distances(smp.q.row(7).transpose(), &d);
  EXPECT_NEAR(g(3 * K + 7), 0.03 - d(3), 1e-15);
  const Eigen::MatrixXd fd = exid_test::nonlinearConstraintDifferences(p, z, 1e-6);
  double worst = 0;
  int compared = 0;
  for (int i = 0; i < p.numVariables(); ++i)
    for (Eigen::Index r = 0; r < g.size(); ++r) {
      if (std::abs(g(r) - 0.03) < 1e-4) continue;  // touching: not differentiable
      worst = std::max(worst, std::abs(fd(r, i) - J(r, i)));
      ++compared;
    }
  EXPECT_GT(compared, 1000);
  EXPECT_LE(worst, 1e-5 * std::max(1.0, J.cwiseAbs().maxCoeff())) << worst;
}

// The unconstrained design of a seeded, budgeted run passes through a table; with the table as
// an obstacle the optimiser ends clear of it by the margin at the design samples, and the
// exported trajectory, re-sampled at 1 kHz, is checked again (worst distance reported).
TEST(Collision, AStudyEndsClearOfATableTheUnconstrainedDesignHits) {
  const fs::path dir =
      fs::temp_directory_path() / ("exid_collision_st_" + std::to_string(getpid()));
  fs::remove_all(dir);
  auto study = [&](bool obstacle_on) {
    std::string y =
        "name: table\nseed: 3\n"
        "robot: {type: panda}\n"
        "model: {type: differential, params: {coulomb: true, viscous: true}}\n"
        "excitation:\n"
        "  trajectory: {type: fourier, params: " +
        std::string(kFourier) +
        "}\n"
        "  criterion: {type: cond}\n"
        "  optimizer: {type: nlopt, params: {algorithm: LD_SLSQP, objective: log, "
        "constraint_mode: aggregated, ks_rho: 300, final_polish: 0.3, starts: 1, "
        "max_evaluations: 600}}\n";
    if (obstacle_on)
      y += "  collision:\n"
           "    margin_m: 0.02\n"
           "    obstacles:\n"
           "      - {name: table, box: {size_m: [0.6, 1.2, 0.04]}, xyz_m: [0.55, 0, 0.23]}\n";
    return y;
  };
  // without the obstacle: the design passes through the table (checked at 1 kHz)
  {
    auto cfg =
        exid::parseStudy(study(false), "free.yaml", exid_test::sourceDir(), exid_test::registry());
    exid::RunOptions o;
    o.export_dir = dir / "free";
    const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), o);
    ASSERT_TRUE(r.ok) << r.message;
    EXPECT_FALSE(r.summary.find("excitation")->find("collision"));
    const exid::TrajectoryCheck c = exid::checkTrajectoryCsv(
        dir / "free" / "trajectory.csv", *exid_test::robot("panda"), {}, table(0.02, 0.25).get());
    EXPECT_LT(c.worst.back().value, 0.0) << "the free design should hit the table";
    EXPECT_FALSE(c.ok);
  }
  auto cfg =
      exid::parseStudy(study(true), "table.yaml", exid_test::sourceDir(), exid_test::registry());
  ASSERT_TRUE(cfg.excitation_collision);
  // the resolved study says the same and parses again to the same hash
  const std::string resolved = cfg.resolvedYaml();
  EXPECT_NE(resolved.find("collision:"), std::string::npos) << resolved;
  auto again =
      exid::parseStudy(resolved, "resolved.yaml", exid_test::sourceDir(), exid_test::registry());
  EXPECT_EQ(again.hash(), cfg.hash());
  exid::RunOptions o;
  o.out_dir = dir / "run";
  o.export_dir = dir / "export";
  o.export_rate_Hz = 1000;
  const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), o);
  ASSERT_TRUE(r.ok) << r.message;
  const auto& x = *r.headline.excitation;
  ASSERT_TRUE(x.distance_margin_m);
  EXPECT_LT(*x.min_distance_initial_m, 0.0) << "the initial trajectory should hit the table";
  EXPECT_GE(*x.min_distance_final_m, 0.02 - 1e-9) << x.min_distance_pair;
  EXPECT_TRUE(x.feasible);
  EXPECT_LE(x.max_constraint_violation, 1e-9);
  EXPECT_LT(x.cond_W_final, x.cond_W_initial);
  EXPECT_GT(x.collision_pairs, 20);
  // the export's check at 1 kHz reports the worst distance between the design samples
  const exid::Json* C = r.summary.find("excitation")->find("export")->find("check");
  ASSERT_TRUE(C);
  const exid::Json* W = C->find("worst")->find("distance");
  ASSERT_TRUE(W);
  EXPECT_TRUE(W->find("checked")->asBool());
  const double worst_1kHz = W->find("value")->asDouble();
  EXPECT_LE(worst_1kHz, *x.min_distance_final_m + 1e-12);  // 1 kHz includes the design samples
  EXPECT_GT(worst_1kHz, 0.0) << "collision between the design samples";
  EXPECT_GT(worst_1kHz, 0.02 - 0.005) << "more than 5 mm inside the margin between samples";
  EXPECT_EQ(W->find("limit")->asDouble(), 0.0);  // contact is the limit; the margin is design's
  EXPECT_EQ(W->find("margin")->asDouble(), worst_1kHz);
  EXPECT_NEAR(W->find("ratio")->asDouble(), 0.02 / worst_1kHz, 1e-12);
  // the check run on the written file alone agrees
  const exid::TrajectoryCheck again_check =
      exid::checkTrajectoryCsv(dir / "export" / "trajectory.csv", *exid_test::robot("panda"), {},
                               cfg.excitation_collision.get());
  EXPECT_NEAR(again_check.worst.back().value, worst_1kHz, 1e-12);
  EXPECT_EQ(again_check.worst.back().what, "distance");
  fs::remove_all(dir);
}

TEST(Collision, StudyKeysAreCheckedWithTheirLines) {
  auto parse = [](const std::string& collision) {
    const std::string y =
        "robot: {type: panda}\nmodel: {type: differential}\nexcitation:\n"
        "  trajectory: {type: fourier}\n  criterion: {type: cond}\n  optimizer: {type: nlopt}\n"
        "  collision:\n" +
        collision;
    return message(
        [&] { exid::parseStudy(y, "s.yaml", exid_test::sourceDir(), exid_test::registry()); });
  };
  EXPECT_NE(parse("    self: true\n").find("s.yaml:8: excitation.collision.margin_m: missing"),
            std::string::npos)
      << parse("    self: true\n");
  EXPECT_NE(parse("    margin_m: -1\n").find("expected a finite distance >= 0"), std::string::npos);
  EXPECT_NE(parse("    margin_m: 0.01\n    margin: 2\n").find("unknown key 'margin'"),
            std::string::npos);
  const std::string bad_shape =
      parse("    margin_m: 0.01\n    obstacles:\n      - {name: t, box: {size_m: [1, 1]}}\n");
  EXPECT_NE(bad_shape.find("s.yaml:10: excitation.collision.obstacles[0].box.size_m: expected a "
                           "list of three numbers"),
            std::string::npos)
      << bad_shape;
  EXPECT_NE(parse("    margin_m: 0.01\n    obstacles:\n      - {sphere: {radius_m: 1}}\n")
                .find("missing name"),
            std::string::npos);
  EXPECT_NE(parse("    margin_m: 0.01\n    allowed_pairs: [link1]\n").find("expected [name, name]"),
            std::string::npos);
}

// The Panda's capsules of links 1 and 3 are 2.6 cm apart with joint 2 at zero, whatever the
// other joints do: a 3 cm margin cannot be held there. The study ends with a warning that names
// the pair and says what to do, and summary.json says feasible: false (never a silent "ok").
TEST(Collision, AnInfeasibleDesignIsSaidAndThePairNamed) {
  auto robot = exid_test::robot("panda");
  exid::CollisionOptions o;
  exid::CollisionModel cm(*robot, o);
  Eigen::VectorXd d;
  cm.distances(Eigen::VectorXd::Zero(7), &d);
  const auto& names = cm.pairNames();
  const auto p = std::find(names.begin(), names.end(), "link1 ~ link3") - names.begin();
  EXPECT_NEAR(d(p), 0.429 - 0.283 - 0.12,
              1e-9);  // link 3's capsule from z 0.429, link 1's to 0.283
  const std::string y =
      "robot: {type: panda}\n"
      "model: {type: differential}\n"
      "excitation:\n"
      "  trajectory: {type: fourier, params: " +
      std::string(kFourier) +
      "}\n"
      "  criterion: {type: cond}\n"
      "  optimizer: {type: nlopt, params: {algorithm: LD_SLSQP, constraint_mode: aggregated, "
      "starts: 1, max_evaluations: 100}}\n"
      "  collision: {margin_m: 0.03}\n";
  auto cfg = exid::parseStudy(y, "tight.yaml", exid_test::sourceDir(), exid_test::registry());
  const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), exid::RunOptions{});
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_FALSE(r.headline.excitation->feasible);
  EXPECT_FALSE(r.summary.find("excitation")->find("feasible")->asBool());
  std::string warnings;
  for (const auto& w : r.headline.warnings) warnings += w + "\n";
  EXPECT_NE(warnings.find("no feasible trajectory found"), std::string::npos) << warnings;
  EXPECT_NE(warnings.find("allowed_pairs"), std::string::npos) << warnings;
}

// An export into the run folder would be replaced with it: refused before anything is written.
TEST(Collision, AnExportInsideTheRunFolderIsRefused) {
  const fs::path dir = fs::temp_directory_path() / ("exid_export_in_" + std::to_string(getpid()));
  fs::remove_all(dir);
  const std::string y =
      "robot: {type: planar2r}\nmodel: {type: differential}\nexcitation:\n"
      "  trajectory: {type: fourier, params: {period_s: 4, harmonics: 2, sample_period_s: 0.1}}\n"
      "  criterion: {type: cond}\n  optimizer: {type: nlopt, params: {max_evaluations: 5}}\n";
  auto cfg = exid::parseStudy(y, "in.yaml", exid_test::sourceDir(), exid_test::registry());
  exid::RunOptions o;
  o.out_dir = dir / "run";
  o.export_dir = dir / "run" / "export";
  const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), o);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.message.find("inside the output folder"), std::string::npos) << r.message;
  EXPECT_FALSE(fs::exists(dir / "run" / "summary.json"));
  o.export_dir = dir / "export";  // beside it: fine
  const exid::StudyResult ok = exid::runStudy(cfg, exid_test::registry(), o);
  EXPECT_TRUE(ok.ok) << ok.message;
  EXPECT_TRUE(fs::exists(dir / "export" / "trajectory.csv"));
  fs::remove_all(dir);
}

// Every optimiser takes the collision rows: from a start that passes through the table,
// adjoint_gradient (augmented Lagrangian) ends clear by the margin; sundials (a penalty that
// grows while the point is infeasible) moves out of the table within a few passes. (The pair of
// links 1 and 3, 2.6 cm apart at q2 = 0, is allowed here: the table is what is tested.)
TEST(Collision, EveryOptimiserTakesTheRows) {
  const char* small =
      "{period_s: 10, harmonics: 5, sample_period_s: 0.2, position_margin_rad: 0.1, "
      "acceleration_limits: false, init: random, init_scale: 0.5}";
  for (const auto& [name, params] : std::vector<std::pair<std::string, std::string>>{
           {"adjoint_gradient", "{constraints: augmented_lagrangian, max_iterations: 150}"},
           {"sundials", "{max_iterations: 6}"}}) {
    const std::string y =
        "seed: 3\nrobot: {type: panda}\nmodel: {type: differential}\nexcitation:\n"
        "  trajectory: {type: fourier, params: " +
        std::string(small) + "}\n  criterion: {type: cond}\n  optimizer: {type: " + name +
        ", params: " + params +
        "}\n"
        "  collision:\n    margin_m: 0.02\n    allowed_pairs: [[link1, link3]]\n"
        "    obstacles:\n"
        "      - {name: table, box: {size_m: [0.6, 1.2, 0.04]}, xyz_m: [0.55, 0, 0.23]}\n";
    auto cfg = exid::parseStudy(y, name + ".yaml", exid_test::sourceDir(), exid_test::registry());
    const exid::StudyResult r = exid::runStudy(cfg, exid_test::registry(), exid::RunOptions{});
    ASSERT_TRUE(r.ok) << name << ": " << r.message;
    const auto& x = *r.headline.excitation;
    EXPECT_LT(*x.min_distance_initial_m, 0.0) << name << ": the start should hit the table";
    if (name == "adjoint_gradient") {
      EXPECT_TRUE(x.feasible) << name;
      EXPECT_GE(*x.min_distance_final_m, 0.02 - 1e-6) << name << " " << x.min_distance_pair;
    } else {
      EXPECT_GT(*x.min_distance_final_m, 0.0) << name << ": still in the table";
    }
  }
}
