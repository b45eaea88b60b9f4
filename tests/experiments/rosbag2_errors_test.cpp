// Experiment `rosbag2`: damaged bags (truncated messages and files, corrupt chunks, bad
// messages, negative storage stamps), unknown topics, wrong types and storage are errors naming
// the place, or dropped and counted (the bags are written by rosbag2_test_util.hpp).

#include "rosbag2_test_util.hpp"

using namespace rbtest;

TEST(Rosbag2, UnknownTopicWrongTypeAndWrongStorageAreErrors) {
  const fs::path dir = bagOf(kVariants[2]);
  std::string e = errorOf(dir, "joint_states_topic: /robot/joint_states");
  EXPECT_NE(e.find("no such topic"), std::string::npos) << e;
  EXPECT_NE(e.find("/joint_states (sensor_msgs/msg/JointState)"), std::string::npos) << e;
  EXPECT_NE(e.find("metadata.yaml"), std::string::npos) << e;
  e = errorOf(dir, "wrench_topic: /cmd");
  EXPECT_NE(e.find("has type 'std_msgs/msg/String', expected geometry_msgs/msg/WrenchStamped"),
            std::string::npos)
      << e;
  // metadata.yaml says sqlite3 for MCAP files, mcap for SQLite files, or something else
  BagSpec s;
  s.storage = "mcap";
  s.metadata_storage = "sqlite3";
  s.msgs = messages();
  e = errorOf(writeBag(tmpDir() / "mcap_said_sqlite", s));
  EXPECT_NE(e.find("not a rosbag2 SQLite file"), std::string::npos) << e;
  EXPECT_NE(e.find("mcap_said_sqlite_0.mcap"), std::string::npos) << e;
  s.storage = "sqlite3";
  s.metadata_storage = "mcap";
  e = errorOf(writeBag(tmpDir() / "sqlite_said_mcap", s));
  EXPECT_NE(e.find("not an MCAP file"), std::string::npos) << e;
  s.metadata_storage = "rosbag_v2";
  e = errorOf(writeBag(tmpDir() / "bad_storage_id", s));
  EXPECT_NE(e.find("storage_identifier 'rosbag_v2': expected sqlite3 or mcap"), std::string::npos)
      << e;
  e = errorOf(tmpDir() / "no_such_bag");
  EXPECT_NE(e.find("no_such_bag: not found"), std::string::npos) << e;
  // a file that is neither a bag's storage nor anything exid reads as a bag
  std::ofstream(tmpDir() / "notes.txt") << "not a bag\n";
  e = errorOf(tmpDir() / "notes.txt");
  EXPECT_NE(e.find("not a rosbag2 bag: expected a bag folder"), std::string::npos) << e;
}

TEST(Rosbag2, ATruncatedMessageIsAnErrorNamingItsIndexAndTopic) {
  for (const char* storage : {"sqlite3", "mcap"}) {
    SCOPED_TRACE(storage);
    BagSpec s;
    s.storage = storage;
    s.msgs = messages();
    int js = 0;
    for (Msg& m : s.msgs)
      if (m.topic == "/joint_states" && ++js == 9) m.data.resize(m.data.size() - 30);
    const std::string e = errorOf(writeBag(tmpDir() / (std::string("trunc_") + storage), s));
    EXPECT_NE(e.find("topic '/joint_states', message 9"), std::string::npos) << e;
    EXPECT_NE(e.find("truncated message"), std::string::npos) << e;
    EXPECT_NE(e.find(std::string("trunc_") + storage), std::string::npos) << e;
    std::printf("%s\n", e.c_str());
  }
}

TEST(Rosbag2, ACorruptChunkIsAnErrorNamingTheRecord) {
  for (const char* comp : {"", "zstd", "lz4"}) {
    SCOPED_TRACE(comp);
    BagSpec s;
    s.storage = "mcap";
    s.compression = comp;
    s.msgs = messages();
    s.corrupt_chunk = 2;
    const std::string e = errorOf(writeBag(tmpDir() / "corrupt_chunk", s));
    EXPECT_NE(e.find("corrupt chunk"), std::string::npos) << e;
    EXPECT_NE(e.find("opcode 0x06"), std::string::npos) << e;
    EXPECT_NE(e.find("corrupt_chunk_0.mcap: record"), std::string::npos) << e;
    std::printf("%s\n", e.c_str());
  }
  // an unknown compression
  EXPECT_NE(std::string([] {
              try {
                const std::uint8_t b[4] = {1, 2, 3, 4};
                exid::rosbag2::decompressChunk("brotli", b, 4, 4, "here");
              } catch (const exid::Error& e) {
                return std::string(e.what());
              }
              return std::string();
            }())
                .find("expected \"\" (none), zstd or lz4"),
            std::string::npos);
}

TEST(Rosbag2, TruncatedOrDamagedMcapFilesAreErrorsNeverCrashes) {
  BagSpec s;
  s.storage = "mcap";
  s.compression = "zstd";
  s.chunk_msgs = 40;
  s.msgs = messages();
  s.msgs.resize(300);
  const fs::path dir = writeBag(tmpDir() / "damaged", s);
  const fs::path file = dir / "damaged_0.mcap";
  std::ifstream in(file, std::ios::binary);
  const Bytes whole((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  // every joint-state sample up to the last wrench message (each has one at its own stamp)
  const auto n_ft =
      std::count_if(s.msgs.begin(), s.msgs.end(), [](const Msg& m) { return m.topic == "/ft"; });
  ASSERT_EQ(readBag(dir, "wrench_topic: /ft").size(), n_ft);
  auto writeFile = [&](const Bytes& b) {
    std::ofstream(file, std::ios::binary)
        .write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
  };
  // Every truncation of the data section (up to the DataEnd record; after it come the summary
  // and the footer, which a sequential reader does not need).
  const std::size_t data_end = whole.size() - 8 - (9 + 20) - (9 + 46) - (9 + 4);
  ASSERT_EQ(whole[data_end], 0x0F);
  writeFile(Bytes(whole.begin(), whole.begin() + 5));
  EXPECT_NE(errorOf(dir).find("not an MCAP file"), std::string::npos);
  std::vector<std::size_t> cuts;
  for (std::size_t cut = 8; cut < data_end; cut += 37) cuts.push_back(cut);
  cuts.push_back(data_end);
  int errors = 0, cases = 0;
  for (std::size_t cut : cuts) {
    writeFile(Bytes(whole.begin(), whole.begin() + static_cast<std::ptrdiff_t>(cut)));
    ++cases;
    const std::string e = errorOf(dir, "wrench_topic: /ft");
    errors += e != "(no error)";
    EXPECT_NE(e.find("truncated"), std::string::npos) << "cut at " << cut << ": " << e;
  }
  EXPECT_EQ(errors, cases);
  std::mt19937 rng(5);
  for (int k = 0; k < 300; ++k) {  // random byte changes: an error or a result, never a crash
    Bytes b = whole;
    for (int f = 0; f < 3; ++f) b[rng() % b.size()] ^= static_cast<std::uint8_t>(1 + rng() % 255);
    writeFile(b);
    try {
      readBag(dir, "wrench_topic: /ft");
    } catch (const exid::Error&) {
    }
  }
}

TEST(Rosbag2, BadMessagesAreErrorsOrDroppedAndEveryMessageIsCounted) {
  std::vector<Msg> msgs = messages({0, 1, 2, 3, 4, 5}, false);
  msgs.resize(700);
  // message 5: effort empty; message 12: effort of the wrong length; message 20: a NaN; and
  // messages of another publisher naming only a gripper joint
  const Recording& r = recording();
  int js = 0;
  std::vector<Msg> out;
  for (Msg& m : msgs) {
    if (m.topic == "/joint_states") {
      ++js;
      const std::size_t k = static_cast<std::size_t>(js - 1);
      std::vector<double> q(r.d.q.cols()), tau(r.d.q.cols());
      for (int j = 0; j < 6; ++j) {
        q[static_cast<std::size_t>(j)] = r.d.q(js - 1, j);
        tau[static_cast<std::size_t>(j)] = r.d.tau(js - 1, j);
      }
      if (js == 5) tau.clear();
      if (js == 12) tau.pop_back();
      if (js == 20) q[2] = std::nan("");
      m.data = jointState(r.ns[k], r.names, q, {}, tau);
      if (js % 100 == 0)
        out.push_back({"/joint_states", m.receive_ns + 1,
                       jointState(r.ns[k] + 1000, {"gripper_finger"}, {0.0}, {}, {0.0})});
    }
    out.push_back(m);
  }
  BagSpec s;
  s.storage = "mcap";
  s.compression = "lz4";
  s.msgs = out;
  const fs::path dir = writeBag(tmpDir() / "bad_messages", s);
  std::string e = errorOf(dir);
  EXPECT_NE(e.find("topic '/joint_states', message 5"), std::string::npos) << e;
  EXPECT_NE(e.find("effort has 0 values for 6 names"), std::string::npos) << e;
  EXPECT_NE(e.find("drop_bad_messages"), std::string::npos) << e;
  const exid::Dataset d = readBag(dir, "drop_bad_messages: true, t_start_s: 0.5, t_end_s: 2.5");
  EXPECT_EQ(acc(d, "dropped_bad_messages"), 3);
  EXPECT_EQ(acc(d, "other_joints_messages"), 6);
  // said as a note (skipped without being wrong), never a warning
  const exid::Json* notes = d.meta.find("notes");
  ASSERT_NE(notes, nullptr);
  ASSERT_EQ(notes->size(), 1u);
  EXPECT_NE(notes->at(0).asString().find("6 of "), std::string::npos) << notes->at(0).asString();
  EXPECT_NE(notes->at(0).asString().find("name none of the robot's joints"), std::string::npos);
  for (const std::string& w : exid::experimentWarnings(d, "experiment"))
    EXPECT_EQ(w.find("name none of the robot's joints"), std::string::npos) << w;
  const std::int64_t total = acc(d, "joint_state_messages");
  EXPECT_EQ(total, js + 6);
  EXPECT_EQ(acc(d, "other_joints_messages") + acc(d, "dropped_bad_messages") +
                acc(d, "dropped_repeated_stamps") + acc(d, "outside_segment") +
                acc(d, "segment_samples"),
            total);
  EXPECT_EQ(d.size(), 401);  // t = 0.5 .. 2.5 s at 200 Hz
  EXPECT_NE(d.meta.find("warnings")->at(0).asString().find(fmt::format("3 of {} messages", total)),
            std::string::npos)
      << d.meta.find("warnings")->at(0).asString();
  // a dropped message is no gap (the step is divided among the publisher's messages), but a
  // real gap is an error naming the message
  std::vector<Msg> gapped;
  js = 0;
  for (const Msg& m : msgs)
    if (m.topic != "/joint_states" || ++js < 100 || js > 110) gapped.push_back(m);
  s.msgs = gapped;
  e = errorOf(writeBag(tmpDir() / "js_gap", s), "drop_bad_messages: true");
  EXPECT_NE(e.find("message 99"), std::string::npos) << e;
  EXPECT_NE(e.find("a gap"), std::string::npos) << e;
  // the advice names the keys that bridge it, with the value that does, and it does
  const std::string key = "resample_hz > 0 with max_gap_ratio: ";
  const std::size_t at = e.find(key);
  ASSERT_NE(at, std::string::npos) << e;
  const double need = std::stod(e.substr(at + key.size()));
  EXPECT_NEAR(need, 12.0, 0.011);  // 11 messages missing: a step of 12 median steps
  const fs::path gap_bag = tmpDir() / "js_gap";
  e = errorOf(gap_bag, "drop_bad_messages: true, resample_hz: 200");
  EXPECT_NE(e.find("bridges this gap"), std::string::npos) << e;
  EXPECT_EQ(e.find("resample_hz > 0 with"), std::string::npos) << e;  // already given
  EXPECT_EQ(errorOf(gap_bag, fmt::format("drop_bad_messages: true, resample_hz: 200, "
                                         "max_gap_ratio: {}",
                                         need)),
            "(no error)");
}

TEST(Rosbag2, ANegativeStorageTimestampIsAnError) {
  std::vector<Msg> msgs = messages({0, 1, 2, 3, 4, 5}, false);
  msgs.resize(60);
  msgs[7].receive_ns = -5;
  BagSpec s;
  s.msgs = msgs;
  const std::string e = errorOf(writeBag(tmpDir() / "negative_stamp", s));
  EXPECT_NE(e.find("timestamp -5: expected nanoseconds since the epoch"), std::string::npos) << e;
  EXPECT_NE(e.find("negative_stamp_0.db3: messages row id"), std::string::npos) << e;
}
