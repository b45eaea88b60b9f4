// The inspection's warnings over many random simulated recordings (docs/real_data.md, "How often
// the inspection is wrong"): no torque, delay or row warning on any clean recording (random
// robots, rates 100-1000 Hz, torque noise 0.01-0.3 N m, segment lengths 2-12 s, friction the
// description lacks, derivatives from the data or derived from q), and every planted fault found
// (one joint's torque flipped, every joint's flipped, a torque delay, frozen and duplicated rows
// while moving; positions held at a standstill are not a fault). The rates are printed; the
// docs' figures come from this test's output.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <set>

#include "../models/model_test_util.hpp"
#include "exid/drive.hpp"
#include "exid/dynamics.hpp"
#include "exid/inspect.hpp"
#include "exid/io.hpp"

namespace {

namespace fs = std::filesystem;

struct Case {
  std::string robot;
  double rate_hz = 100, noise = 0.05, duration_s = 5, period_s = 5;
  bool friction_only_in_data = false;  // the description lacks the data's friction
  bool derivatives = true;             // qd, qdd in the file (else derived from q)
  bool standstill = false;             // 1 s at rest first, positions quantised
  std::uint64_t seed = 1;
};

std::string describe(const Case& c) {
  return fmt::format("{} {:g} Hz noise {:.3g} N m {:.3g} s period {:.3g} s{}{}{} seed {}", c.robot,
                     c.rate_hz, c.noise, c.duration_s, c.period_s,
                     c.friction_only_in_data ? " friction-only-in-data" : "",
                     c.derivatives ? "" : " derived-qd", c.standstill ? " standstill" : "", c.seed);
}

Case randomCase(std::mt19937_64& rng, std::uint64_t seed) {
  static const char* robots[] = {"planar2r", "puma560", "panda", "stanford", "irp6"};
  static const double rates[] = {100, 200, 250, 500, 1000};
  std::uniform_real_distribution<double> u(0, 1);
  Case c;
  c.robot = robots[rng() % 5];
  c.rate_hz = rates[rng() % 5];
  c.noise = 0.01 * std::pow(30.0, u(rng));  // 0.01 .. 0.3, log-uniform
  c.duration_s = 2 + 10 * u(rng);
  c.period_s = 2 + 8 * u(rng);
  c.friction_only_in_data = u(rng) < 0.25;
  c.derivatives = u(rng) < 0.7;
  c.standstill = u(rng) < 0.2;
  c.seed = seed;
  return c;
}

/// The recorded data of a case, and the description the inspection judges it with.
struct Recording {
  std::shared_ptr<const exid::RobotModel> description;
  exid::Dataset data;
};

Recording record(const Case& c) {
  auto r = mtest::robot(c.robot);
  Recording rec;
  rec.description = r;
  auto plant = std::make_shared<exid::RobotModel>(*r);
  if (c.friction_only_in_data) {
    // friction on every joint that the description does not have: Coulomb 2 N m, viscous 1.5
    auto desc = std::make_shared<exid::RobotModel>(*r);
    for (std::size_t j = 0; j < plant->drives.size(); ++j) {
      plant->drives[j].coulomb = 2.0;
      plant->drives[j].viscous = 1.5;
      desc->drives[j].coulomb = 0.0;
      desc->drives[j].viscous = 0.0;
    }
    rec.description = desc;
  }
  const double dt = 1.0 / c.rate_hz;
  exid::Dataset d = mtest::simulate(
      plant,
      fmt::format("{{duration_s: {:.6f}, sample_period_s: {:.10g}, noise_tau_Nm: {:.6g}, "
                  "period_s: {:.6f}, harmonics: 3}}",
                  c.duration_s, dt, c.noise, c.period_s),
      c.seed);
  if (c.standstill) {
    // 1 s at rest at the simulation's first pose, then a motion that starts from rest smoothly
    // (q, qd and qdd continuous): q_j = q0_j + A_j (1 - cos(w_j u))^2 / 4, u = t - 1; the
    // torque from the plant's own model (rigid bodies and drives) plus noise; the positions
    // quantised to 1e-4 (an encoder)
    const int n = plant->dof(), K = static_cast<int>(std::lround(c.duration_s / dt)) + 1;
    const int R = static_cast<int>(std::lround(1.0 / dt));
    // the motion spans [q0, q0 + A] in the middle of each joint's range
    Eigen::VectorXd q0(n), amp(n);
    for (int j = 0; j < n; ++j) {
      const auto& lim = plant->limits[static_cast<std::size_t>(j)];
      // (limits are in joint coordinates: with a transmission, around the first pose instead)
      const bool known = lim.q_max < 1e299 && lim.q_min > -1e299 && !plant->hasTransmission();
      amp(j) = known ? std::min(0.6 + 0.1 * j, 0.6 * (lim.q_max - lim.q_min)) : 0.3;
      q0(j) = known ? 0.5 * (lim.q_min + lim.q_max) - 0.5 * amp(j) : d.q(0, j);
    }
    exid::Dataset s;
    s.t.resize(R + K);
    s.q.resize(R + K, n);
    s.qd.resize(R + K, n);
    s.qdd.resize(R + K, n);
    s.tau.resize(R + K, n);
    auto dd = exid::makeDynamicsData(*plant);
    exid::DriveColumns cols;
    cols.rotor_inertia = cols.coulomb = cols.viscous = cols.offset = true;
    std::mt19937_64 rng(c.seed + 99);
    std::normal_distribution<double> nz(0.0, c.noise);
    for (int k = 0; k < R + K; ++k) {
      const double t = k * dt, u = std::max(0.0, t - R * dt);
      Eigen::VectorXd q(n), qd(n), qdd(n);
      for (int j = 0; j < n; ++j) {
        const double A = amp(j), w = 2 * M_PI / (c.period_s / (1 + 0.4 * (j % 3)));
        const double ph = w * u, cp = std::cos(ph), sp = std::sin(ph);
        q(j) = q0(j) + A * (1 - cp) * (1 - cp) / 4;
        qd(j) = A * w * (1 - cp) * sp / 2;
        qdd(j) = A * w * w * (sp * sp + (1 - cp) * cp) / 2;
      }
      s.t(k) = t;
      s.q.row(k) = q.transpose();
      s.qd.row(k) = qd.transpose();
      s.qdd.row(k) = qdd.transpose();
      s.tau.row(k) = exid::actuatorTorque(*plant, *dd, cols, q, qd, qdd).transpose();
      for (int j = 0; j < n; ++j) s.tau(k, j) += nz(rng);
    }
    s.q = (s.q / 1e-4).array().round().matrix() * 1e-4;
    s.source = d.source;
    d = std::move(s);
  }
  rec.data = std::move(d);
  return rec;
}

fs::path tmpDir() {
  fs::path p = fs::temp_directory_path() / ("exid_inspect_sweep_" + std::to_string(::getpid()));
  fs::create_directories(p);
  return p;
}

/// The data as a csv file (time stamps at the rate's resolution), read back by the csv
/// experiment and inspected.
exid::Json inspectCsv(const Recording& rec, const Case& c, const std::string& name) {
  const exid::Dataset& d = rec.data;
  const int n = d.dof();
  exid::CsvTable T;
  T.columns = {"t"};
  std::vector<const Eigen::MatrixXd*> groups = {&d.q};
  std::vector<std::string> prefix = {"q"};
  if (c.derivatives) {
    groups.insert(groups.end(), {&d.qd, &d.qdd});
    prefix.insert(prefix.end(), {"qd", "qdd"});
  }
  groups.push_back(&d.tau);
  prefix.push_back("tau");
  for (const auto& p : prefix)
    for (int j = 1; j <= n; ++j) T.columns.push_back(p + std::to_string(j));
  T.data.resize(d.size(), static_cast<Eigen::Index>(T.columns.size()));
  for (int k = 0; k < d.size(); ++k) {
    T.data(k, 0) = std::round(d.t(k) * c.rate_hz * 1e3) / (c.rate_hz * 1e3);
    int col = 1;
    for (const Eigen::MatrixXd* M : groups)
      for (int j = 0; j < n; ++j) T.data(k, col++) = (*M)(k, j);
  }
  const fs::path f = tmpDir() / (name + ".csv");
  exid::writeCsvAtomic(f, T);
  auto e = exid_test::create<exid::Experiment>("csv", "{file: " + f.string() + "}");
  const exid::Dataset read = e->run(rec.description, nullptr, mtest::context());
  fs::remove(f);
  auto m = mtest::model("differential", "{}", rec.description);
  return exid::inspectDataset(*rec.description, m.get(), read, mtest::context());
}

std::vector<std::string> warnings(const exid::Json& J) {
  std::vector<std::string> w;
  const exid::Json* W = J.find("warnings");
  for (std::size_t i = 0; W && i < W->size(); ++i) w.push_back(W->at(i).asString());
  return w;
}

/// A warning about the torque's sign, scale or delay, or about the rows.
bool isDataAlarm(const std::string& w) {
  for (const char* k : {"flipped", "does not follow", "negative of", "gain of", " lags ", " leads ",
                        "delay", "duplicat", "hold every joint position"})
    if (w.find(k) != std::string::npos) return true;
  return false;
}

std::string verdictOf(const exid::Json& J, int j) {
  return J.find("joints")
      ->at(static_cast<std::size_t>(j))
      .find("sign_check")
      ->find("verdict")
      ->asString();
}

/// The joint whose model torque stands highest above the noise (checkable, ok) or -1.
int bestJoint(const exid::Json& J) {
  int best = -1;
  double ratio = 0;
  const exid::Json& js = *J.find("joints");
  for (std::size_t j = 0; j < js.size(); ++j) {
    const exid::Json& s = *js.at(j).find("sign_check");
    if (s.find("verdict")->asString() != "ok") continue;
    const double r = s.find("model_signal")->asDouble() / s.find("noise")->asDouble();
    if (r > ratio) {
      ratio = r;
      best = static_cast<int>(j);
    }
  }
  return best;
}

/// Indices of samples in motion, away from the ends.
std::vector<int> movingRows(const exid::Dataset& d, int count, std::mt19937_64& rng) {
  std::vector<int> rows;
  const int K = d.size();
  std::set<int> taken;
  for (int tries = 0; tries < 100000 && static_cast<int>(rows.size()) < count; ++tries) {
    const int k = 20 + static_cast<int>(rng() % static_cast<std::uint64_t>(K - 40));
    if (d.qd.row(k).cwiseAbs().maxCoeff() < 0.5) continue;  // moving well
    bool near = false;
    for (int t : taken) near = near || std::abs(t - k) < 10;
    if (near) continue;
    taken.insert(k);
    rows.push_back(k);
  }
  return rows;
}

struct Tally {
  int cases = 0, alarms = 0;
  std::vector<std::string> examples;
  void add(bool bad, const std::string& what) {
    ++cases;
    if (bad) {
      ++alarms;
      if (examples.size() < 8) examples.push_back(what);
    }
  }
  std::string text() const {
    std::string s;
    for (const auto& e : examples) s += "  " + e + "\n";
    return s;
  }
};

/// The sweep from one seed: its tallies, one method per kind of recording it inspects.
/// strict: every figure asserted (the seed the docs' table is from); otherwise the false alarms
/// and the verdicts' stability only, the found faults printed.
struct Sweep {
  bool strict = false;
  // delay: on recordings of 6 s and more / shorter (where a short recording's halves vote while
  // their own white std is within twice the agreement tolerance)
  Tally clean, flip_one, flip_all, delay, delay_long, frozen, dups, rest, stable;
  // planted delays neither warned about nor called "not checkable here" (said "none found")
  Tally delay_denied;
  int delay_uncheckable = 0, clean_none_found = 0, clean_uncheckable = 0;
  int other_warnings = 0, not_checkable = 0, joints_judged = 0;

  /// The clean recording: no alarm; its verdicts counted.
  void cleanCase(const Recording& rec, const Case& c, const exid::Json& J) {
    std::string alarms;
    for (const auto& w : warnings(J)) {
      if (isDataAlarm(w))
        alarms += w + " | ";
      else if (++other_warnings <= 5)
        std::printf("other warning (%s): %s\n", describe(c).c_str(), w.c_str());
    }
    clean.add(!alarms.empty(), describe(c) + ": " + alarms +
                                   (alarms.empty() ? std::string() : J.find("joints")->dump()));
    {
      const std::string v = J.find("delay")->find("verdict")->asString();
      clean_none_found += v == "none found";
      clean_uncheckable += v.rfind("not checkable here", 0) == 0;
    }
    const int n = rec.data.dof();
    for (int j = 0; j < n; ++j) {
      ++joints_judged;
      not_checkable += verdictOf(J, j) == "not checkable";
    }
    if (c.standstill) {  // held positions at rest: counted apart, no frozen rows
      const exid::Json& R = *J.find("recording");
      rest.add(R.find("frozen_rows")->find("rows")->asInt() != 0 ||
                   R.find("held_at_rest")->find("rows")->asInt() < c.rate_hz / 2,
               describe(c) + ": " + R.dump());
    }
  }

  /// One sample fewer: the same verdicts (the sums change by one sample).
  void shorterCase(const Recording& rec, const Case& c, const exid::Json& J) {
    const int n = rec.data.dof();
    // one sample fewer: the same verdicts (the sums change by one sample)
    Recording shorter = rec;
    const int K = shorter.data.size() - 1;
    exid::Dataset& d = shorter.data;
    d.t = d.t.head(K).eval();
    d.q = d.q.topRows(K).eval();
    d.qd = d.qd.topRows(K).eval();
    d.qdd = d.qdd.topRows(K).eval();
    d.tau = d.tau.topRows(K).eval();
    const exid::Json S = inspectCsv(shorter, c, "shorter");
    bool same = warnings(S).size() == warnings(J).size();
    for (int j = 0; j < n; ++j) same = same && verdictOf(S, j) == verdictOf(J, j);
    stable.add(!same, describe(c));
  }

  /// One joint flipped: found on that joint, the others unchanged.
  void flipOneCase(const Recording& rec, const Case& c, int jb) {
    const int n = rec.data.dof();
    // one joint flipped: found on that joint, the others unchanged
    Recording f = rec;
    f.data.tau.col(jb) *= -1.0;
    const exid::Json F = inspectCsv(f, c, "flip1");
    bool ok = verdictOf(F, jb) == "flipped";
    for (int j = 0; j < n; ++j)
      if (j != jb) ok = ok && verdictOf(F, j) != "flipped";
    std::string all;
    for (const auto& w : warnings(F)) all += w + " | ";
    ok = ok && all.find(fmt::format("tau{} is the negative", jb + 1)) != std::string::npos;
    flip_one.add(!ok, describe(c) + fmt::format(" joint {}: ", jb + 1) + all);
  }

  /// Every joint flipped: one whole-robot verdict.
  void flipAllCase(const Recording& rec, const Case& c, const exid::Json& J) {
    const int n = rec.data.dof();
    // every joint flipped: one whole-robot verdict
    Recording f = rec;
    f.data.tau *= -1.0;
    const exid::Json F = inspectCsv(f, c, "flipall");
    int checkable = 0;
    for (int j = 0; j < n; ++j) checkable += verdictOf(J, j) == "ok";
    std::string all;
    for (const auto& w : warnings(F)) all += w + " | ";
    const bool ok = checkable >= 2 ? all.find("tau_scale -1 for every joint") != std::string::npos
                                   : all.find("is the negative") != std::string::npos;
    flip_all.add(!ok, describe(c) + ": " + all + F.find("joints")->dump());
  }

  /// The torque delayed by max(10 ms, 3 samples): tau(k) = tau_sim(k - s).
  void delayCase(const Recording& rec, const Case& c) {
    // torque delayed by max(10 ms, 3 samples): tau(k) = tau_sim(k - s)
    const int s = std::max(3, static_cast<int>(std::lround(0.01 * c.rate_hz)));
    Recording f = rec;
    const int K = f.data.size();
    exid::Dataset& d = f.data;
    const Eigen::MatrixXd tau = d.tau.topRows(K - s);
    d.t = d.t.tail(K - s).eval();
    d.q = d.q.bottomRows(K - s).eval();
    d.qd = d.qd.bottomRows(K - s).eval();
    d.qdd = d.qdd.bottomRows(K - s).eval();
    d.tau = tau;
    const exid::Json F = inspectCsv(f, c, "delay");
    const exid::Json& D = *F.find("delay");
    std::string all;
    for (const auto& w : warnings(F)) all += w + " | ";
    const double est =
        D.find("delay_samples")->isNumber() ? D.find("delay_samples")->asDouble() : NAN;
    const bool ok = all.find(" lags ") != std::string::npos && std::abs(est - s) < 1.0;
    const std::string verdict = D.find("verdict")->asString();
    const bool uncheckable = verdict.rfind("not checkable here", 0) == 0;
    EXPECT_EQ(ok, verdict == "delay") << describe(c) << ": " << verdict;
    delay_uncheckable += !ok && uncheckable;
    delay_denied.add(!ok && !uncheckable, describe(c) + ": " + verdict);
    // (the estimate is right whether or not the recording can confirm it)
    if (strict) {
      EXPECT_LT(std::abs(est - s), 1.0) << describe(c);
    }
    (c.duration_s >= 6 ? delay_long : delay)
        .add(!ok,
             describe(c) + fmt::format(" delay {} samples, estimate {:.2f}: {}", s, est, D.dump()));
  }

  /// Frozen rows and duplicated rows while moving.
  void rowsCase(const Recording& rec, const Case& c, std::mt19937_64& frng) {
    // frozen rows and duplicated rows while moving
    Recording f = rec;
    exid::Dataset& d = f.data;
    const std::vector<int> at = movingRows(d, 8, frng);
    if (at.size() < 8) return;
    int planted_frozen = 0, planted_dups = 0;
    for (std::size_t m = 0; m < 4; ++m) {  // 4 runs of 2 rows: q held, the rest changes
      for (int k : {at[m], at[m] + 1}) d.q.row(k) = d.q.row(at[m] - 1);
      planted_frozen += 2;
    }
    for (std::size_t m = 4; m < 8; ++m) {  // 4 rows written twice (the time stamp goes on)
      const int k = at[m];
      d.q.row(k) = d.q.row(k - 1);
      d.qd.row(k) = d.qd.row(k - 1);
      d.qdd.row(k) = d.qdd.row(k - 1);
      d.tau.row(k) = d.tau.row(k - 1);
      ++planted_dups;
    }
    const exid::Json F = inspectCsv(f, c, "rows");
    const exid::Json& R = *F.find("recording");
    const long long fr = R.find("frozen_rows")->find("rows")->asInt();
    const long long du = R.find("duplicate_rows")->find("count")->asInt();
    std::string all;
    for (const auto& w : warnings(F)) all += w + " | ";
    frozen.add(fr != planted_frozen || all.find("hold every joint position") == std::string::npos,
               describe(c) + fmt::format(": frozen {} of {} planted", fr, planted_frozen));
    dups.add(du != planted_dups || all.find("duplicated rows") == std::string::npos,
             describe(c) + fmt::format(": duplicates {} of {} planted", du, planted_dups));
  }

  /// The figures printed, and asserted.
  void finish() {
    std::printf(
        "inspection sweep: clean recordings with a torque/delay/row alarm: %d of %d\n"
        "  (other warnings on clean recordings: %d; joints not checkable: %d of %d)\n"
        "  planted faults found: one joint flipped %d of %d, every joint flipped %d of %d, delay "
        "%d of %d (recordings of 6 s or more) and %d of %d (shorter), frozen rows %d of %d, "
        "duplicated rows %d of %d; standstill held rows not called frozen %d of %d; the same "
        "verdicts one sample shorter %d of %d\n",
        clean.alarms, clean.cases, other_warnings, not_checkable, joints_judged,
        flip_one.cases - flip_one.alarms, flip_one.cases, flip_all.cases - flip_all.alarms,
        flip_all.cases, delay_long.cases - delay_long.alarms, delay_long.cases,
        delay.cases - delay.alarms, delay.cases, frozen.cases - frozen.alarms, frozen.cases,
        dups.cases - dups.alarms, dups.cases, rest.cases - rest.alarms, rest.cases,
        stable.cases - stable.alarms, stable.cases);
    std::printf("  clean recordings' delay verdicts: 'none found' %d, 'not checkable here' %d\n",
                clean_none_found, clean_uncheckable);
    std::printf(
        "  planted delays not warned about: %d, of which said 'not checkable here' %d, 'none "
        "found' %d\n",
        delay.alarms + delay_long.alarms, delay_uncheckable, delay_denied.alarms);
    EXPECT_EQ(clean.alarms, 0) << clean.text();
    EXPECT_EQ(stable.alarms, 0) << stable.text();
    // a delay the recording cannot confirm is said to be not checkable, never "none found"
    EXPECT_EQ(delay_denied.alarms, 0) << delay_denied.text();
    // and where it can, a clean recording's verdict is "none found"
    EXPECT_GE(clean_none_found, 150);
    if (!strict) {
      std::printf("  faults not found:\n%s%s%s%s%s%s", flip_one.text().c_str(),
                  flip_all.text().c_str(), delay.text().c_str(), delay_long.text().c_str(),
                  frozen.text().c_str(), dups.text().c_str());
      return;
    }
    EXPECT_GE(flip_one.cases, 30);
    EXPECT_EQ(flip_one.alarms, 0) << flip_one.text();
    EXPECT_GE(flip_all.cases, 30);
    EXPECT_EQ(flip_all.alarms, 0) << flip_all.text();
    EXPECT_GE(delay_long.cases, 10);
    EXPECT_EQ(delay_long.alarms, 0) << delay_long.text();
    if (delay.alarms) std::printf("  delays not warned about:\n%s", delay.text().c_str());
    EXPECT_GE(delay.cases, 10);
    EXPECT_EQ(delay.alarms, 0) << delay.text();  // (13 of 15 before the halves' vote)
    EXPECT_GE(frozen.cases, 30);
    EXPECT_EQ(frozen.alarms, 0) << frozen.text();
    EXPECT_EQ(dups.alarms, 0) << dups.text();
    EXPECT_GE(rest.cases, 20);
    EXPECT_EQ(rest.alarms, 0) << rest.text();
    fs::remove_all(tmpDir());
  }
};

void sweep(std::uint64_t seed, bool strict) {
  constexpr int kCases = 200;
  std::mt19937_64 rng(seed);
  Sweep S;
  S.strict = strict;
  for (int i = 0; i < kCases; ++i) {
    const Case c = randomCase(rng, 1000 + static_cast<std::uint64_t>(i));
    Recording rec = record(c);
    const exid::Json J = inspectCsv(rec, c, "clean");
    S.cleanCase(rec, c, J);
    if (i % 5 == 0) S.shorterCase(rec, c, J);
    const int jb = bestJoint(J);
    std::mt19937_64 frng(c.seed * 7 + 3);
    if (i % 4 == 0 && jb >= 0) S.flipOneCase(rec, c, jb);
    if (i % 4 == 1 && jb >= 0) S.flipAllCase(rec, c, J);
    if (i % 4 == 2 && jb >= 0 && c.derivatives) S.delayCase(rec, c);
    if (i % 4 == 3) S.rowsCase(rec, c, frng);
  }
  EXPECT_EQ(S.clean.cases, kCases);
  EXPECT_EQ(S.stable.cases, kCases / 5);
  S.finish();
}

}  // namespace

TEST(InspectSweep, NoFalseAlarmOnCleanRecordingsAndEveryPlantedFaultFound) {
  sweep(20261127, true);
}

// Two more seeds, 400 other clean recordings: no false alarm, and the same verdicts one sample
// shorter (seed 99 held a false "the torque leads by 7.39 samples" on a short recording with
// derived velocities after a standstill, before the delay left out the samples within the
// Savitzky-Golay half-width of the motion's starts and stops). The planted faults they find are
// printed (docs/real_data.md).
TEST(InspectSweep, NoFalseAlarmOnOtherSeeds) {
  sweep(7, false);
  sweep(99, false);
}
