// Experiment `rosbag2`: bags written here in both storage formats (SQLite; MCAP with chunks
// uncompressed, zstd and LZ4) from a simulated PUMA 560 give exactly the dataset of the same
// samples written as CSV, and the same identification (filtered_ls, through the study path);
// the robot's joints are found by name in any order, the wrench is interpolated at the
// joint-state times and every message dropped or cut is counted. Damaged bags:
// rosbag2_errors_test.cpp; decoders that validate everything: rosbag2_hostile_test.cpp; the
// bag writer and the recording: rosbag2_test_util.hpp.

#include "exid/recording.hpp"
#include "rosbag2_test_util.hpp"

using namespace rbtest;

TEST(Rosbag2, Crc32OfTheCheckString) {
  const std::string s = "123456789";
  EXPECT_EQ(exid::rosbag2::crc32(reinterpret_cast<const std::uint8_t*>(s.data()), s.size()),
            0xCBF43926u);
}

TEST(Rosbag2, EveryStorageGivesExactlyTheDatasetOfTheCsv) {
  auto csv =
      exid_test::create<exid::Experiment>("csv", "{file: " + csvOfRecording().string() + "}");
  const exid::Dataset c = csv->run(mtest::robot("puma560"), nullptr, mtest::context());
  ASSERT_EQ(c.size(), recording().d.size());
  for (const Variant& v : kVariants) {
    SCOPED_TRACE(v.tag);
    const exid::Dataset b = readBag(bagOf(v), "wrench_topic: /ft");
    ASSERT_EQ(b.size(), c.size());
    EXPECT_EQ(b.t, c.t);
    EXPECT_EQ(b.q, c.q);  // the bag's joints are in another order: mapped by name
    EXPECT_EQ(b.tau, c.tau);
    EXPECT_EQ(b.wrench, c.wrench);  // the same stamps: interpolation weight 0, exact
    EXPECT_FALSE(b.hasVelocity());
    EXPECT_FALSE(b.hasAcceleration());
    EXPECT_EQ(b.meta.find("storage")->asString(), v.storage);
    EXPECT_EQ(b.meta.find("time_origin_ns")->asInt(), kEpoch);
    EXPECT_EQ(acc(b, "joint_state_messages"), c.size());
    EXPECT_EQ(acc(b, "samples_used"), c.size());
    EXPECT_EQ(acc(b, "wrench_messages"), c.size());
    EXPECT_EQ(acc(b, "outside_wrench_range"), 0);
    EXPECT_NEAR(b.meta.find("recording")->find("timing")->find("rate_hz")->asDouble(), 200.0, 1e-9);
  }
}

TEST(Rosbag2, EveryStorageGivesTheIdentificationOfTheCsv) {
  // The same study (PUMA 560, differential model, filtered_ls differentiating q itself, split
  // into identification and validation) on the CSV and on each bag, through the study path.
  auto run = [](const std::string& experiment) {
    const std::string study =
        "robot: {type: puma560}\n"
        "model: {type: differential, params: {rotor_inertia: true, viscous: true, coulomb: true, "
        "offset: true}}\n"
        "experiment: " +
        experiment +
        "\n"
        "estimator: {type: filtered_ls, params: {cutoff_hz: 8}}\n"
        "split: {identification_fraction: 0.7}\n";
    exid::StudyConfig cfg =
        exid::parseStudy(study, "rosbag2_study.yaml", tmpDir(), exid_test::registry());
    exid::RunOptions opt;
    return exid::runStudy(cfg, exid_test::registry(), opt);
  };
  csvOfRecording();
  const exid::StudyResult ref = run("{type: csv, params: {file: recording.csv}}");
  ASSERT_TRUE(ref.ok) << ref.message;
  const exid::Json& rp = *ref.summary.find("identification")->find("parameters");
  ASSERT_GT(rp.size(), 20u);
  double scale = 0;
  for (std::size_t i = 0; i < rp.size(); ++i)
    scale = std::max(scale, std::abs(rp.at(i).find("value")->asDouble()));
  for (const Variant& v : kVariants) {
    SCOPED_TRACE(v.tag);
    bagOf(v);
    const exid::StudyResult r =
        run(fmt::format("{{type: rosbag2, params: {{path: {}, wrench_topic: /ft}}}}", v.tag));
    ASSERT_TRUE(r.ok) << r.message;
    const exid::Json& p = *r.summary.find("identification")->find("parameters");
    ASSERT_EQ(p.size(), rp.size());
    for (std::size_t i = 0; i < p.size(); ++i) {
      EXPECT_EQ(p.at(i).find("name")->asString(), rp.at(i).find("name")->asString());
      EXPECT_NEAR(p.at(i).find("value")->asDouble(), rp.at(i).find("value")->asDouble(),
                  1e-9 * scale)
          << p.at(i).find("name")->asString();
    }
    std::printf("[%s] %zu parameters equal to the CSV's (scale %.3g)\n", v.tag, p.size(), scale);
  }
}

TEST(Rosbag2, JointNamesMapTheRobotsJointsInAnyOrder) {
  const Recording& r = recording();
  // The bag names the joints differently and lists them in reverse order.
  std::vector<Msg> msgs;
  const std::vector<std::string> alias = {"a1", "a2", "a3", "a4", "a5", "a6"};
  for (int k = 0; k < 40; ++k) {
    std::vector<std::string> names;
    std::vector<double> pos, eff;
    for (int j = 5; j >= 0; --j) {
      names.push_back(alias[static_cast<std::size_t>(j)]);
      pos.push_back(r.d.q(k, j));
      eff.push_back(r.d.tau(k, j));
    }
    msgs.push_back({"/joint_states", r.ns[static_cast<std::size_t>(k)],
                    jointState(r.ns[static_cast<std::size_t>(k)], names, pos, {}, eff)});
  }
  BagSpec s;
  s.msgs = msgs;
  const fs::path dir = writeBag(tmpDir() / "aliases", s);
  // the robot's names are not in the messages: an error listing the names found
  const std::string e = errorOf(dir);
  EXPECT_NE(e.find("no message names any joint of robot"), std::string::npos) << e;
  EXPECT_NE(e.find("a6, a5, a4, a3, a2, a1"), std::string::npos) << e;
  const exid::Dataset d = readBag(dir,
                                  "joint_names: [a1, a2, a3, a4, a5, a6], sign: [1, -1, 1, "
                                  "1, 1, 1]");
  ASSERT_EQ(d.size(), 40);
  for (int k = 0; k < 40; ++k)
    for (int j = 0; j < 6; ++j) {
      const double sg = j == 1 ? -1.0 : 1.0;
      EXPECT_EQ(d.q(k, j), sg * r.d.q(k, j));
      EXPECT_EQ(d.tau(k, j), sg * r.d.tau(k, j));
    }
  // a mapping naming a joint the messages lack: the missing name and the names found
  const std::string m = errorOf(dir, "joint_names: [a1, a2, a3, a4, a5, wrist]");
  EXPECT_NE(m.find("no joint wrist"), std::string::npos) << m;
  EXPECT_NE(m.find("names in the message: a6, a5"), std::string::npos) << m;
  EXPECT_NE(m.find("message 1"), std::string::npos) << m;
  EXPECT_NE(errorOf(dir, "joint_names: [a1, a2]").find("expected 6 names"), std::string::npos);
  EXPECT_NE(errorOf(dir, "joint_names: [a1, a1, a3, a4, a5, a6]").find("named twice"),
            std::string::npos);
}

TEST(Rosbag2, VelocityOnRequestAndReceiveTime) {
  const fs::path dir = bagOf(kVariants[0]);
  const exid::Dataset v = readBag(dir, "use_velocity: true");
  ASSERT_TRUE(v.hasVelocity());
  EXPECT_EQ(v.qd(7, 0), 100.0);  // the bag's velocity field (100 + joint index)
  EXPECT_EQ(v.qd(7, 5), 105.0);
  // receive stamps: 2 ms + (k % 3) us after the header stamps
  const exid::Dataset r = readBag(dir, "time: receive");
  const exid::Dataset h = readBag(dir);
  EXPECT_EQ(r.meta.find("time_origin_ns")->asInt(), kEpoch + 2000000);
  EXPECT_NEAR(r.t[4] - h.t[4], 1e-6, 1e-12);
  EXPECT_EQ(r.q, h.q);
}

TEST(Rosbag2, WrenchIsInterpolatedAtTheJointStateTimesAndSamplesOutsideItAreCut) {
  // Joint states at 200 Hz; the wrench at 500 Hz from 0.1013 s to 0.8003 s, linear in time:
  // interpolation is exact, and the samples before and after its range are cut and counted.
  const Recording& r = recording();
  std::vector<Msg> msgs;
  for (int k = 0; k < 200; ++k)
    msgs.push_back({"/joint_states", r.ns[static_cast<std::size_t>(k)],
                    jointState(r.ns[static_cast<std::size_t>(k)], r.names,
                               {0, 0, 0, 0, 0, 0.001 * k}, {}, {1, 2, 3, 4, 5, 6})});
  auto wv = [](double t, double out[6]) {
    for (int c = 0; c < 6; ++c) out[c] = (c + 1) * 10.0 * t - c;
  };
  for (int i = 0; i < 350; ++i) {
    const std::int64_t ns = kEpoch + 101300000LL + 2000000LL * i;
    double w[6];
    wv(static_cast<double>(ns - kEpoch) / 1e9, w);
    msgs.push_back({"/ft", ns, wrenchStamped(ns, w)});
  }
  BagSpec s;
  s.msgs = msgs;
  const fs::path dir = writeBag(tmpDir() / "wrench_interp", s);
  const exid::Dataset d = readBag(dir, "wrench_topic: /ft");
  // joint-state samples at 0.105 .. 0.800 s are inside the wrench's range [0.1013, 0.7993] s
  EXPECT_EQ(d.size(), 139);  // k = 21 .. 159
  EXPECT_NEAR(d.t[0], 0.105, 1e-12);
  EXPECT_NEAR(d.t[d.size() - 1], 0.795, 1e-12);
  for (int k = 0; k < d.size(); ++k) {
    double w[6];
    wv(d.t[k], w);
    for (int c = 0; c < 6; ++c) EXPECT_NEAR(d.wrench(k, c), w[c], 1e-9) << k << " " << c;
  }
  EXPECT_EQ(acc(d, "outside_wrench_range"), 200 - 139);
  EXPECT_EQ(acc(d, "joint_state_messages"), 200);
  EXPECT_EQ(acc(d, "samples_used"), 139);
  ASSERT_NE(d.meta.find("warnings"), nullptr);
  EXPECT_NE(d.meta.find("warnings")->at(0).asString().find("outside the time range"),
            std::string::npos);
  EXPECT_NE(d.meta.find("wrench_matching")->asString().find("linear interpolation"),
            std::string::npos);
  // a gap in the wrench around a joint-state sample is an error, never bridged
  std::vector<Msg> gap;
  for (const Msg& m : msgs) {
    if (m.topic == "/ft" && m.receive_ns > kEpoch + 400000000LL &&
        m.receive_ns < kEpoch + 450000000LL)
      continue;
    gap.push_back(m);
  }
  s.msgs = gap;
  const std::string e = errorOf(writeBag(tmpDir() / "wrench_gap", s), "wrench_topic: /ft");
  EXPECT_NE(e.find("wrench_topic '/ft': a gap of"), std::string::npos) << e;
  EXPECT_NE(e.find("between messages 150 and 151"), std::string::npos) << e;
}

TEST(Rosbag2, SplitAndSegmentAsTheCsvExperiment) {
  const fs::path dir = bagOf(kVariants[3]);
  auto csv = [](const std::string& extra) {
    auto e = exid_test::create<exid::Experiment>(
        "csv", "{file: " + csvOfRecording().string() + ", " + extra + "}");
    return e->run(mtest::robot("puma560"), nullptr, mtest::context());
  };
  for (const std::string extra :
       {"t_start_s: 1, t_end_s: 8, split_part: identification, split_fraction: 0.6",
        "t_start_s: 1, t_end_s: 8, split_part: validation, split_fraction: 0.6",
        "split_part: validation, split_at_s: 4"}) {
    SCOPED_TRACE(extra);
    const exid::Dataset b = readBag(dir, extra);
    const exid::Dataset c = csv(extra);
    EXPECT_EQ(b.t, c.t);
    EXPECT_EQ(b.q, c.q);
    EXPECT_EQ(acc(b, "segment_samples") + acc(b, "outside_segment") +
                  (b.meta.find("split") ? acc(b, "other_part_of_split") : 0),
              recording().d.size());
  }
  EXPECT_NE(errorOf(dir, "t_end_s: 12").find("past the end of the recording"), std::string::npos);
  EXPECT_NE(errorOf(dir, "split_fraction: 0.5").find("need split_part"), std::string::npos);
}

// The filter steps (exid/recording.hpp) are one pipeline for both experiments: a bag and the
// CSV of the same recording, with the same resampling, delay, low-pass, trim and decimation,
// give the same samples to the bit and the same accounting.
TEST(Rosbag2, TheFilterStepsAreTheCsvExperiments) {
  const fs::path dir = bagOf(kVariants[3]);
  for (const std::string& extra :
       {std::string("differentiate_cutoff_hz: 20, filter_torque: true, decimation: 2"),
        std::string("measurement_delay_s: 0.012, differentiate_cutoff_hz: 15, trim_edges: 7"),
        std::string("resample_hz: 150, t_start_s: 1, t_end_s: 8")}) {
    SCOPED_TRACE(extra);
    auto csv = exid_test::create<exid::Experiment>(
        "csv", "{file: " + csvOfRecording().string() + ", " + extra + "}");
    const exid::Dataset c = csv->run(mtest::robot("puma560"), nullptr, mtest::context());
    const exid::Dataset b = readBag(dir, extra);
    ASSERT_EQ(b.size(), c.size());
    EXPECT_LT(b.size(), recording().d.size());  // the steps did drop samples
    EXPECT_EQ(b.t, c.t);
    EXPECT_EQ(b.q, c.q);
    EXPECT_EQ(b.qd, c.qd);
    EXPECT_EQ(b.qdd, c.qdd);
    EXPECT_EQ(b.tau, c.tau);
    for (const char* key : {"segment_samples", "trimmed_edges", "decimated_away", "samples_used"})
      EXPECT_EQ(acc(b, key), acc(c, key)) << key;
    const exid::Json* fb = b.meta.find("differentiated");
    const exid::Json* fc = c.meta.find("differentiated");
    ASSERT_EQ(fb == nullptr, fc == nullptr);
    if (fb) {
      EXPECT_EQ(fb->dump(), fc->dump());
    }
    const exid::Json* db = b.meta.find("measurement_delay");
    const exid::Json* dc = c.meta.find("measurement_delay");
    ASSERT_EQ(db == nullptr, dc == nullptr);
    if (db) {
      EXPECT_EQ(db->dump(), dc->dump());
      EXPECT_GT(
          db->find("dropped_samples_front")->asInt() + db->find("dropped_samples_back")->asInt(),
          0);
    }
  }
  // the same refusals, naming the bag
  const std::string e = errorOf(dir, "decimation: 2");
  EXPECT_NE(e.find("decimation and filter_torque need differentiate_cutoff_hz > 0"),
            std::string::npos)
      << e;
}

// A real arm's bag: the effort fields hold motor currents and there are no velocities. With
// the csv experiment's signal options (one implementation, exid/recording.hpp) and its filter,
// it identifies with batch_ls, wls, rls and consistent_ls exactly as the CSV of the same currents
// does, in both storages.
TEST(Rosbag2, CurrentsWithoutVelocitiesIdentifyAsTheirCsvWithEveryEstimator) {
  const Recording& r = recording();
  const std::vector<double> Kt = {0.5, 0.8, 0.3, 0.2, 0.25, 0.1};  // N m / A
  const int n = 6;
  std::vector<Msg> msgs;
  exid::CsvTable table;
  table.columns = {"t"};
  for (int j = 1; j <= n; ++j) table.columns.push_back(fmt::format("q{}", j));
  for (int j = 1; j <= n; ++j) table.columns.push_back(fmt::format("i{}", j));
  table.data.resize(r.d.size(), 1 + 2 * n);
  for (int k = 0; k < r.d.size(); ++k) {
    std::vector<double> pos, cur;
    table.data(k, 0) = r.d.t[k];
    for (int j = 0; j < n; ++j) {
      pos.push_back(r.d.q(k, j));
      cur.push_back(r.d.tau(k, j) / Kt[static_cast<std::size_t>(j)]);
      table.data(k, 1 + j) = pos.back();
      table.data(k, 1 + n + j) = cur.back();
    }
    msgs.push_back({"/joint_states", r.ns[static_cast<std::size_t>(k)] + 1000,
                    jointState(r.ns[static_cast<std::size_t>(k)], r.names, pos, {}, cur)});
  }
  const fs::path csv = tmpDir() / "currents.csv";
  exid::writeCsvAtomic(csv, table);
  const std::string signal =
      "torque_from: current, torque_constants_Nm_per_A: [0.5, 0.8, 0.3, 0.2, 0.25, 0.1], "
      "offset_rad: [0.01, 0, 0, -0.02, 0, 0], differentiate_cutoff_hz: 10, filter_torque: true";
  auto study = [&](const std::string& experiment, const std::string& estimator) {
    const std::string text =
        "robot: {type: puma560}\n"
        "model: {type: differential, params: {rotor_inertia: true, viscous: "
        "true, coulomb: true, offset: true}}\n"
        "experiment: " +
        experiment + "\nestimator: {type: " + estimator + "}\n";
    exid::StudyConfig cfg =
        exid::parseStudy(text, "currents_study.yaml", tmpDir(), exid_test::registry());
    return exid::runStudy(cfg, exid_test::registry(), exid::RunOptions());
  };
  for (const char* storage : {"sqlite3", "mcap"}) {
    BagSpec spec;
    spec.storage = storage;
    spec.compression = std::string(storage) == "mcap" ? "zstd" : "";
    spec.types = {{"/joint_states", "sensor_msgs/msg/JointState"}};
    spec.msgs = msgs;
    const fs::path bag = writeBag(tmpDir() / fmt::format("currents_{}", storage), spec);
    for (const char* estimator : {"batch_ls", "wls", "rls", "consistent_ls"}) {
      SCOPED_TRACE(fmt::format("{} {}", storage, estimator));
      const exid::StudyResult c = study(
          fmt::format("{{type: csv, params: {{file: {}, {}}}}}", csv.string(), signal), estimator);
      const exid::StudyResult b =
          study(fmt::format("{{type: rosbag2, params: {{path: {}, {}}}}}", bag.string(), signal),
                estimator);
      ASSERT_TRUE(c.ok) << c.message;
      ASSERT_TRUE(b.ok) << b.message;
      const exid::Json& pc = *c.summary.find("identification")->find("parameters");
      const exid::Json& pb = *b.summary.find("identification")->find("parameters");
      ASSERT_EQ(pb.size(), pc.size());
      ASSERT_GT(pc.size(), 20u);
      for (std::size_t i = 0; i < pc.size(); ++i)
        EXPECT_EQ(pb.at(i).find("value")->asDouble(), pc.at(i).find("value")->asDouble())
            << pc.at(i).find("name")->asString();
      EXPECT_EQ(b.summary.find("experiment")->find("meta")->find("torque_from")->asString(),
                "current");
    }
  }
}

// A bag as a user names it: the storage file itself, a folder of storage files without
// metadata.yaml, a bare MCAP or SQLite file: the same samples as the bag folder, and the meta
// says how it was opened. The csv experiment given a bag says to read it with rosbag2.
TEST(Rosbag2, TheStorageFileItselfOrAFolderWithoutMetadataIsTheSameBag) {
  for (const Variant& v : {kVariants[0], kVariants[2]}) {
    SCOPED_TRACE(v.tag);
    const fs::path dir = bagOf(v);
    const exid::Dataset ref = readBag(dir);
    const std::string ext = std::string(v.storage) == "mcap" ? "mcap" : "db3";
    const fs::path file = dir / fmt::format("{}_0.{}", v.tag, ext);
    const exid::Dataset own = readBag(file);
    EXPECT_EQ(own.q, ref.q);
    EXPECT_EQ(own.tau, ref.tau);
    EXPECT_NE(own.meta.find("opened_as")->asString().find("storage file"), std::string::npos);
    // without metadata.yaml: the folder, and the file alone (topics from the storage)
    const fs::path bare = tmpDir() / fmt::format("bare_{}", v.tag);
    fs::remove_all(bare);
    fs::create_directories(bare);
    fs::copy_file(file, bare / file.filename());
    for (const fs::path& p : {bare, bare / file.filename()}) {
      SCOPED_TRACE(p.string());
      const exid::Dataset b = readBag(p);
      EXPECT_EQ(b.t, ref.t);
      EXPECT_EQ(b.q, ref.q);
      EXPECT_EQ(b.tau, ref.tau);
      EXPECT_NE(b.meta.find("opened_as")->asString().find("topics from the storage"),
                std::string::npos)
          << b.meta.find("opened_as")->asString();
    }
    EXPECT_TRUE(exid::isBagPath(bare));
    EXPECT_TRUE(exid::isBagPath(bare / file.filename()));
    EXPECT_FALSE(exid::isBagPath(csvOfRecording()));
    EXPECT_FALSE(exid::isBagPath(tmpDir() / "no_such_thing"));
    auto csv = exid_test::create<exid::Experiment>(
        "csv", "{file: " + (bare / file.filename()).string() + "}");
    try {
      (void)csv->run(mtest::robot("puma560"), nullptr, mtest::context());
      ADD_FAILURE() << "a bag was read as a CSV file";
    } catch (const exid::Error& e) {
      EXPECT_NE(std::string(e.what()).find("read it with experiment rosbag2"), std::string::npos)
          << e.what();
    }
  }
}

// exid inspect lists a bag's topics: type, messages, rate, and what exid made of each.
TEST(Rosbag2, InspectListsTheTopicsOfTheBag) {
  const fs::path dir = bagOf(kVariants[3]);
  const exid::Dataset d = readBag(dir, "wrench_topic: /ft");
  const exid::Json* topics = d.meta.find("topics");
  ASSERT_NE(topics, nullptr);
  ASSERT_EQ(topics->size(), 3u);  // /cmd, /ft, /joint_states
  std::map<std::string, const exid::Json*> by;
  for (std::size_t i = 0; i < topics->size(); ++i)
    by[topics->at(i).find("topic")->asString()] = &topics->at(i);
  EXPECT_EQ(by.at("/joint_states")->find("messages")->asInt(), recording().d.size());
  EXPECT_NEAR(by.at("/joint_states")->find("rate_hz")->asDouble(), 200.0, 0.5);
  EXPECT_EQ(by.at("/joint_states")->find("used_as")->asString(), "joint states");
  EXPECT_EQ(by.at("/ft")->find("used_as")->asString(), "wrench");
  EXPECT_EQ(by.at("/cmd")->find("used_as")->asString(), "not used");
  EXPECT_EQ(by.at("/cmd")->find("type")->asString(), "std_msgs/msg/String");
  const exid_cli::CmdResult r =
      exid_cli::runExid("inspect puma560 " + dir.string() + " --set wrench_topic=/ft");
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("topics of the bag:"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("/cmd  std_msgs/msg/String"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("note: "), std::string::npos) << r.out;  // nothing skipped here
}

// Publishers: metadata.yaml's offered_qos_profiles when it lists them, else the storage's own
// (an MCAP channel's metadata, a SQLite topics row), one entry per publisher; unknown (absent)
// when neither holds a list.
TEST(Rosbag2, PublishersFromTheStorageWhenMetadataDoesNotListThem) {
  const std::string two =
      "- history: 1\n  depth: 10\n  reliability: 1\n- history: 1\n  depth: 1\n  "
      "reliability: 2";
  for (const char* storage : {"sqlite3", "mcap"}) {
    SCOPED_TRACE(storage);
    BagSpec spec;
    spec.storage = storage;
    spec.msgs = messages();
    spec.qos = {{"/joint_states", two}, {"/ft", "- history: 1\n  depth: 5"}};
    const fs::path dir = writeBag(tmpDir() / fmt::format("qos_{}", storage), spec);
    const exid::Dataset d = readBag(dir);
    const exid::Json* topics = d.meta.find("topics");
    ASSERT_NE(topics, nullptr);
    std::map<std::string, const exid::Json*> by;
    for (std::size_t i = 0; i < topics->size(); ++i)
      by[topics->at(i).find("topic")->asString()] = &topics->at(i);
    ASSERT_NE(by.at("/joint_states")->find("publishers"), nullptr);
    EXPECT_EQ(by.at("/joint_states")->find("publishers")->asInt(), 2);
    EXPECT_EQ(by.at("/ft")->find("publishers")->asInt(), 1);
    EXPECT_EQ(by.at("/cmd")->find("publishers"), nullptr);  // "" in the storage: not known
  }
}

TEST(Rosbag2, InspectAndIdentifyTakeABagFolderOnTheCommandLine) {
  const fs::path dir = bagOf(kVariants[2]);
  const exid_cli::CmdResult r =
      exid_cli::runExid("inspect puma560 " + dir.string() + " --set t_end_s=5");
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("recording: 200 Hz (header stamps of topic '/joint_states')"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("(1001 samples"), std::string::npos) << r.out;  // 0 .. 5 s at 200 Hz
  // exid identify --data BAG_FOLDER replaces the study's experiment by the bag
  const fs::path work = exid_cli::freshTempDir("exid_rosbag2_cli_", "identify");
  std::ofstream(work / "study.yaml")
      << "robot: {type: puma560}\n"
         "model: {type: differential}\n"
         "experiment: {type: csv, params: {file: does_not_exist.csv}}\n"
         "estimator: {type: filtered_ls, params: {cutoff_hz: 8}}\n";
  const exid_cli::CmdResult id =
      exid_cli::runExid("-q identify " + (work / "study.yaml").string() + " --data " +
                        dir.string() + " --out " + (work / "out").string());
  ASSERT_EQ(id.code, 0) << id.out;
  const exid::Json S = exid::Json::parse(exid_cli::slurp(work / "out" / "summary.json"));
  EXPECT_EQ(S.find("status")->asString(), "ok");
  EXPECT_EQ(S.find("experiment")->find("type")->asString(), "rosbag2");
  fs::remove_all(work);
}

TEST(Rosbag2, BigEndianCdrAndAlignmentOfEmptySequences) {
  // The same message in both byte orders, with a frame_id and names whose lengths leave the
  // float64 sequences misaligned by 4 unless padded, and an empty velocity (no padding).
  const std::vector<std::string> names = {"j", "joint_two", "x3"};
  for (const char* frame : {"", "b", "base_link"})
    for (bool big : {false, true}) {
      SCOPED_TRACE(std::string(frame) + (big ? " big endian" : " little endian"));
      const Bytes m = jointState(kEpoch, names, {1.5, -2.25, 3e-7}, {}, {4, 5, 6}, frame, big);
      const exid::rosbag2::JointStateMsg d =
          exid::rosbag2::decodeJointState(m.data(), m.size(), "here");
      EXPECT_EQ(d.stamp.ns(), kEpoch);
      EXPECT_EQ(d.frame_id, frame);
      EXPECT_EQ(d.name, names);
      EXPECT_EQ(d.position, (std::vector<double>{1.5, -2.25, 3e-7}));
      EXPECT_TRUE(d.velocity.empty());
      EXPECT_EQ(d.effort, (std::vector<double>{4, 5, 6}));
      // one byte short anywhere: an error naming the place, never a read past the end
      for (std::size_t cut = 0; cut < m.size(); ++cut) {
        try {
          exid::rosbag2::decodeJointState(m.data(), cut, "here");
          ADD_FAILURE() << "a message cut to " << cut << " bytes was accepted";
        } catch (const exid::Error& e) {
          EXPECT_EQ(std::string(e.what()).rfind("here: ", 0), 0u) << e.what();
        }
      }
    }
  const Bytes other = {0x00, 0x03, 0x00, 0x00, 1, 2, 3, 4};  // PL_CDR_LE: not a plain CDR message
  try {
    exid::rosbag2::decodeJointState(other.data(), other.size(), "here");
    ADD_FAILURE() << "PL_CDR accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("expected 00 01 (CDR little endian)"), std::string::npos)
        << e.what();
  }
}

TEST(Rosbag2, MessagesOutOfOrderAreSortedAndARepeatedStampIsAnErrorOrDropped) {
  // Header stamps of messages 10 and 11 swapped (received in that order): sorted by time and
  // counted; then a message 21 received after message 20 repeats its stamp.
  const Recording& r = recording();
  auto build = [&](bool repeat) {
    std::vector<Msg> msgs;
    for (int k = 0; k < 100; ++k) {
      const int src = k == 10 ? 11 : k == 11 ? 10 : k;
      std::vector<double> q(6), tau(6);
      for (int j = 0; j < 6; ++j) {
        q[static_cast<std::size_t>(j)] = r.d.q(src, j);
        tau[static_cast<std::size_t>(j)] = r.d.tau(src, j);
      }
      const std::int64_t recv = r.ns[static_cast<std::size_t>(k)] + 1000000;
      msgs.push_back({"/joint_states", recv,
                      jointState(r.ns[static_cast<std::size_t>(src)], r.names, q, {}, tau)});
      if (repeat && k == 19)
        msgs.push_back({"/joint_states", recv + 500,
                        jointState(r.ns[static_cast<std::size_t>(src)], r.names, q, {}, tau)});
    }
    BagSpec s;
    s.storage = "mcap";
    s.msgs = msgs;
    return writeBag(tmpDir() / (repeat ? "repeat" : "swapped"), s);
  };
  const exid::Dataset d = readBag(build(false));
  ASSERT_EQ(d.size(), 100);
  for (int k = 0; k < 100; ++k) EXPECT_EQ(d.q.row(k), r.d.q.row(k)) << k;
  EXPECT_EQ(acc(d, "reordered_messages"), 1);
  const fs::path rep = build(true);
  const std::string e = errorOf(rep);
  EXPECT_NE(e.find("topic '/joint_states', message 21: its time stamp"), std::string::npos) << e;
  EXPECT_NE(e.find("repeats that of message 20"), std::string::npos) << e;
  const exid::Dataset k = readBag(rep, "drop_bad_messages: true");
  EXPECT_EQ(k.size(), 100);
  EXPECT_EQ(k.q, d.q);
  EXPECT_EQ(acc(k, "dropped_repeated_stamps"), 1);
}

TEST(Rosbag2, InspectReportsTheSampleAccountingAndWarningsOfRun) {
  // The wrench starts 1.5 s after the joint states: of the 401 samples of [0, 2] s, 300 lie
  // outside its range and are cut. exid run warned, exid inspect said "warnings: none".
  BagSpec s;
  s.storage = "mcap";
  for (const Msg& m : messages())
    if (m.topic != "/ft" || m.receive_ns > kEpoch + 1500000000LL + 2000000LL) s.msgs.push_back(m);
  const fs::path dir = writeBag(tmpDir() / "wrench_late", s);
  const exid::Dataset d = readBag(dir, "wrench_topic: /ft, t_end_s: 2");
  EXPECT_EQ(acc(d, "outside_wrench_range"), 300);
  EXPECT_EQ(acc(d, "samples_used"), 101);
  const std::vector<std::string> w = exid::experimentWarnings(d, "experiment");
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w[0].find("300 joint-state samples of the segment lie outside the time range of "
                      "wrench_topic '/ft' and were cut"),
            std::string::npos)
      << w[0];
  const fs::path work = exid_cli::freshTempDir("exid_rosbag2_cli_", "inspect_accounting");
  const exid_cli::CmdResult r = exid_cli::runExid(
      "inspect puma560 " + dir.string() + " --set wrench_topic=/ft --set t_end_s=2 --json " +
      (work / "i.json").string());
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("  - " + w[0] + "\n"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("warnings: none"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("outside_wrench_range 300"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("samples_used 101"), std::string::npos) << r.out;
  const exid::Json J = exid::Json::parse(exid_cli::slurp(work / "i.json"));
  ASSERT_NE(J.find("accounting"), nullptr);
  EXPECT_EQ(J.find("accounting")->find("outside_wrench_range")->asInt(), 300);
  // exid run says the same words
  std::ofstream(work / "study.yaml") << "robot: {type: puma560}\nmodel: {type: differential}\n"
                                        "experiment: {type: rosbag2, params: {path: "
                                     << dir.string()
                                     << ", wrench_topic: /ft, t_end_s: 2}}\n"
                                        "estimator: {type: filtered_ls, params: {cutoff_hz: 8}}\n";
  const exid_cli::CmdResult run = exid_cli::runExid("-q run " + (work / "study.yaml").string() +
                                                    " --out " + (work / "out").string());
  const std::string summary = exid_cli::slurp(work / "out" / "summary.json");
  EXPECT_NE(summary.find(w[0]), std::string::npos) << run.out << summary;
  // and nothing of the kind when nothing is cut: the wrench over the whole recording
  const exid_cli::CmdResult all =
      exid_cli::runExid("inspect puma560 " + bagOf(kVariants[2]).string() +
                        " --set wrench_topic=/ft --set t_end_s=2");
  EXPECT_EQ(all.code, 0) << all.out;
  EXPECT_EQ(all.out.find("were cut"), std::string::npos) << all.out;
  EXPECT_EQ(all.out.find("experiment: "), std::string::npos) << all.out;
  EXPECT_NE(all.out.find("outside_wrench_range 0"), std::string::npos) << all.out;
  fs::remove_all(work);
}
