// Experiment `rosbag2`, issue 37: decoders that validate everything they decode
// (docs/hostile_input.md, "rosbag2 bags"): left-over bytes, joints named twice, one
// definition per MCAP channel and schema, bounded decompression, SQLite's plain tables only,
// metadata.yaml capped and strict, storage files above their cap.

#include "rosbag2_test_util.hpp"

using namespace rbtest;

namespace {

namespace rb = exid::rosbag2;

/// A hand-made MCAP file: magic, a Header, the given records, DataEnd, Footer, magic.
Bytes mcapFile(const std::vector<std::pair<std::uint8_t, Bytes>>& records) {
  Bytes out = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
  Bytes h;
  putStr(h, "ros2");
  putStr(h, "exid test");
  record(out, 0x01, h);
  for (const auto& [op, content] : records) record(out, op, content);
  Bytes de;
  put(de, 0, 4);
  record(out, 0x0F, de);
  Bytes f(20, 0);
  record(out, 0x02, f);
  const Bytes magic = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
  out.insert(out.end(), magic.begin(), magic.end());
  return out;
}
std::pair<std::uint8_t, Bytes> schemaRec(std::uint16_t id, const std::string& name) {
  Bytes s;
  put(s, id, 2);
  putStr(s, name);
  putStr(s, "ros2msg");
  putStr(s, "# definition of " + name);
  return {0x03, s};
}
std::pair<std::uint8_t, Bytes> channelRec(std::uint16_t id, std::uint16_t schema,
                                          const std::string& topic) {
  Bytes c;
  put(c, id, 2);
  put(c, schema, 2);
  putStr(c, topic);
  putStr(c, "cdr");
  put(c, 0, 4);  // no metadata
  return {0x04, c};
}
std::pair<std::uint8_t, Bytes> messageRec(std::uint16_t channel, std::int64_t ns,
                                          const Bytes& data) {
  Bytes r;
  put(r, channel, 2);
  put(r, 0, 4);
  put(r, static_cast<std::uint64_t>(ns), 8);
  put(r, static_cast<std::uint64_t>(ns), 8);
  r.insert(r.end(), data.begin(), data.end());
  return {0x05, r};
}
std::pair<std::uint8_t, Bytes> chunkRec(const std::string& compression, const Bytes& records) {
  const Bytes stored = compress(compression, records);
  Bytes c;
  put(c, 0, 8);
  put(c, 0, 8);
  put(c, records.size(), 8);
  put(c, 0, 4);  // no CRC
  putStr(c, compression);
  put(c, stored.size(), 8);
  c.insert(c.end(), stored.begin(), stored.end());
  return {0x06, c};
}

rb::BagInfo fuzzLikeBag() {
  rb::BagInfo bag;
  bag.storage = "mcap";
  bag.metadata_file = "metadata.yaml";
  bag.topics = {{"/joint_states", "sensor_msgs/msg/JointState", "cdr", -1},
                {"/ft", "geometry_msgs/msg/WrenchStamped", "cdr", -1}};
  return bag;
}

/// Messages of the wanted topics readMcapBytes gives for a file, or its error.
std::string readMcapOf(const Bytes& file, int* count = nullptr) {
  int n = 0;
  try {
    rb::readMcapBytes(fuzzLikeBag(), "hand.mcap", file.data(), file.size(),
                      {"/joint_states", "/ft"}, [&](const rb::RawMessage&) { ++n; });
  } catch (const exid::Error& e) {
    return e.what();
  }
  if (count) *count = n;
  return "(no error)";
}

/// Writes `bytes` as the bag's only storage file.
void overwrite(const fs::path& file, const Bytes& bytes) {
  std::ofstream(file, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}

}  // namespace

TEST(Rosbag2, BytesLeftAfterAMessageAreAnErrorNamingFileTopicAndIndex) {
  // JointState bytes on the WrenchStamped topic: they used to decode as a wrench (|f| = 7e223).
  const Recording& r = recording();
  for (const char* storage : {"sqlite3", "mcap"}) {
    SCOPED_TRACE(storage);
    BagSpec s;
    s.storage = storage;
    s.compression = "zstd";
    s.msgs = messages();
    int ft = 0;
    for (Msg& m : s.msgs)
      if (m.topic == "/ft" && ++ft == 3)
        m.data = jointState(r.ns[2], r.names, {1, 2, 3, 4, 5, 6}, {}, {1, 2, 3, 4, 5, 6});
    const fs::path dir = writeBag(tmpDir() / (std::string("js_on_ft_") + storage), s);
    const std::string e = errorOf(dir, "wrench_topic: /ft");
    EXPECT_NE(e.find("topic '/ft', message 3"), std::string::npos) << e;
    EXPECT_NE(e.find("bytes left after the geometry_msgs/msg/WrenchStamped message"),
              std::string::npos)
        << e;
    EXPECT_NE(e.find(std::string("js_on_ft_") + storage + "_0."), std::string::npos) << e;
    std::printf("%s\n", e.c_str());
    // the bag without the wrench topic reads (only /ft is wrong)
    EXPECT_EQ(readBag(dir).size(), r.d.size());
  }
  // a JointState with bytes after it; up to 3 zero bytes of padding are accepted, not 4, and
  // not a non-zero one
  const Bytes m = jointState(kEpoch, {"a", "b"}, {1, 2}, {}, {3, 4});
  for (std::size_t pad = 0; pad <= 4; ++pad)
    for (std::uint8_t byte : {0, 7}) {
      Bytes p = m;
      p.insert(p.end(), pad, byte);
      const bool ok = pad == 0 || (pad <= 3 && byte == 0);
      try {
        const rb::JointStateMsg d = rb::decodeJointState(p.data(), p.size(), "here");
        EXPECT_TRUE(ok) << pad << " bytes " << int(byte) << " after the message were accepted";
        EXPECT_EQ(d.effort, (std::vector<double>{3, 4}));
      } catch (const exid::Error& e) {
        EXPECT_FALSE(ok) << e.what();
        EXPECT_NE(std::string(e.what()).find(fmt::format("here: {} bytes left after the "
                                                         "sensor_msgs/msg/JointState message",
                                                         pad)),
                  std::string::npos)
            << e.what();
      }
    }
  // a string without its terminating NUL, or with one inside
  Bytes nul = jointState(kEpoch, {"ab", "c"}, {1, 2}, {}, {3, 4});
  const auto at = std::search(nul.begin(), nul.end(), std::begin("ab"), std::end("ab") - 1);
  ASSERT_NE(at, nul.end());
  *(at + 1) = 0;  // "a\0\0": a NUL inside the name
  try {
    rb::decodeJointState(nul.data(), nul.size(), "here");
    ADD_FAILURE() << "a NUL inside a name accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("name: a NUL byte inside the string"), std::string::npos)
        << e.what();
  }
  *(at + 1) = 'b';
  *(at + 2) = 'x';  // "abx": no terminating NUL
  try {
    rb::decodeJointState(nul.data(), nul.size(), "here");
    ADD_FAILURE() << "a name without its NUL accepted";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find("does not end with its terminating NUL"),
              std::string::npos)
        << e.what();
  }
}

TEST(Rosbag2, AJointStateNamingAJointTwiceIsRefused) {
  // Joint 3 named twice with different values in message 7: the first used to win.
  const Recording& r = recording();
  BagSpec s;
  s.msgs = messages({0, 1, 2, 3, 4, 5}, false);
  s.msgs.resize(100);
  std::vector<std::string> names = r.names;
  names.push_back(r.names[2]);
  int js = 0;
  for (Msg& m : s.msgs)
    if (m.topic == "/joint_states" && ++js == 7)
      m.data = jointState(r.ns[6], names, {0, 0, 0.5, 0, 0, 0, -0.5}, {}, {1, 1, 1, 1, 1, 1, 9});
  for (const char* storage : {"sqlite3", "mcap"}) {
    SCOPED_TRACE(storage);
    s.storage = storage;
    const fs::path dir = writeBag(tmpDir() / (std::string("named_twice_") + storage), s);
    const std::string e = errorOf(dir, "drop_bad_messages: true");
    EXPECT_NE(e.find("topic '/joint_states', message 7"), std::string::npos) << e;
    EXPECT_NE(e.find(fmt::format("joint '{}' is named twice (names 3 and 7 of 7)", r.names[2])),
              std::string::npos)
        << e;
    EXPECT_NE(e.find(std::string("named_twice_") + storage + "_0."), std::string::npos) << e;
  }
  // names that differ only after a common prefix are distinct
  const Bytes ok = jointState(kEpoch, {"j1", "j10", "j1_", "J1"}, {1, 2, 3, 4}, {}, {1, 2, 3, 4});
  EXPECT_EQ(rb::decodeJointState(ok.data(), ok.size(), "here").name.size(), 4u);
}

TEST(Rosbag2, AnMcapChannelOrSchemaHasOneDefinition) {
  const Bytes js = jointState(kEpoch, {"a"}, {1}, {}, {2});
  const auto schema = schemaRec(1, "sensor_msgs/msg/JointState");
  const auto chan = channelRec(1, 1, "/joint_states");
  // the same definitions repeated (as writers do in chunks and the summary): accepted
  int n = 0;
  EXPECT_EQ(readMcapOf(mcapFile({schema, chan, messageRec(1, kEpoch, js), schema, chan,
                                 messageRec(1, kEpoch + 1, js)}),
                       &n),
            "(no error)");
  EXPECT_EQ(n, 2);
  // channel 1 redefined to another topic: the second half of the recording went elsewhere
  std::string e = readMcapOf(mcapFile({schema, chan, messageRec(1, kEpoch, js),
                                       channelRec(1, 1, "/other"), messageRec(1, kEpoch + 1, js)}));
  EXPECT_NE(e.find("hand.mcap: record 5 (opcode 0x04) at byte"), std::string::npos) << e;
  EXPECT_NE(e.find("channel 1 redefined as topic '/other'"), std::string::npos) << e;
  EXPECT_NE(e.find("defined as topic '/joint_states'"), std::string::npos) << e;
  // ... or to another schema
  e = readMcapOf(mcapFile(
      {schema, schemaRec(2, "std_msgs/msg/String"), chan, channelRec(1, 2, "/joint_states")}));
  EXPECT_NE(e.find("channel 1 redefined as topic '/joint_states' (schema 2 'std_msgs/msg/String'"),
            std::string::npos)
      << e;
  // a schema redefined under the same id, after a channel was checked against it
  e = readMcapOf(mcapFile({schema, chan, schemaRec(1, "std_msgs/msg/String")}));
  EXPECT_NE(e.find("schema 1 redefined as 'std_msgs/msg/String'"), std::string::npos) << e;
  // a topic defined again by another channel with another schema
  e = readMcapOf(mcapFile(
      {schema, schemaRec(2, "std_msgs/msg/String"), chan, channelRec(2, 2, "/joint_states")}));
  EXPECT_NE(e.find("topic '/joint_states' defined again by channel 2"), std::string::npos) << e;
  // inside a chunk too, and through the experiment (the file named)
  Bytes recs;
  for (const auto& [op, c] : {schema, chan, messageRec(1, kEpoch, js), channelRec(1, 1, "/x")})
    record(recs, op, c);
  BagSpec s;
  s.storage = "mcap";
  s.msgs = messages();
  s.msgs.resize(30);
  const fs::path dir = writeBag(tmpDir() / "redefined", s);
  overwrite(dir / "redefined_0.mcap", mcapFile({chunkRec("lz4", recs)}));
  e = errorOf(dir);
  EXPECT_NE(e.find("redefined_0.mcap: record 2 (opcode 0x06) at byte "), std::string::npos) << e;
  EXPECT_NE(e.find(", chunk record 4 (opcode 0x04): channel 1 redefined as topic '/x'"),
            std::string::npos)
      << e;
}

TEST(Rosbag2, DecompressionIsBoundedPerChunkAndPerFile) {
  // A chunk of 64 MiB of zeros (zstd: a few KB): refused from its declared size, before any
  // decompression.
  const Bytes zeros(std::size_t{64} << 20, 0);
  const Bytes z = compress("zstd", zeros);
  ASSERT_LT(z.size(), 10000u);
  const auto t0 = std::chrono::steady_clock::now();
  try {
    rb::decompressChunk("zstd", z.data(), z.size(), zeros.size(), "here");
    ADD_FAILURE() << "a 64 MiB chunk from " << z.size() << " bytes was decompressed";
  } catch (const exid::Error& e) {
    EXPECT_NE(std::string(e.what()).find(fmt::format(
                  "here: chunk uncompressed_size 67108864 bytes from {} compressed bytes (zstd): "
                  "above the limit of 64 times the compressed size plus 1048576 bytes",
                  z.size())),
              std::string::npos)
        << e.what();
  }
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 0.5);
  std::string e = readMcapOf(mcapFile({chunkRec("zstd", zeros)}));
  std::printf("%s\n", e.c_str());
  EXPECT_NE(e.find("hand.mcap: record 2 (opcode 0x06) at byte "), std::string::npos) << e;
  EXPECT_NE(e.find(": chunk uncompressed_size 67108864 bytes from"), std::string::npos) << e;
  // Many chunks, each within its own cap (about 1 MiB of zeros, empty records of 9 bytes, from
  // ~60 bytes), together beyond the file's: 64 times the file's size plus 16 MiB.
  const Bytes mib(std::size_t{9} * 116508, 0);
  const auto one = chunkRec("zstd", mib);
  std::vector<std::pair<std::uint8_t, Bytes>> many(40, one);
  const Bytes bomb = mcapFile(many);
  ASSERT_LT(bomb.size(), 8000u);
  e = readMcapOf(bomb);
  std::printf("%s\n", e.c_str());
  EXPECT_NE(e.find("record 18 (opcode 0x06)"), std::string::npos) << e;  // the 17th chunk
  EXPECT_NE(e.find(fmt::format("would bring the file's decompressed chunks to {} bytes, "
                               "above its limit of {} bytes",
                               17 * mib.size(), 64 * bomb.size() + (16 << 20))),
            std::string::npos)
      << e;
  // the same chunks, fewer: within the file's cap, read (they hold no record a reader keeps)
  many.resize(15);
  EXPECT_EQ(readMcapOf(mcapFile(many)), "(no error)");
  // the output is bounded by the declared size even when the declared size is small
  const Bytes l = compress("lz4", mib);
  try {
    rb::decompressChunk("lz4", l.data(), l.size(), 1000, "here");
    ADD_FAILURE() << "more output than declared";
  } catch (const exid::Error& x) {
    EXPECT_NE(std::string(x.what()).find("gives more than uncompressed_size = 1000"),
              std::string::npos)
        << x.what();
  }
}

TEST(Rosbag2, SqliteIsReadThroughItsPlainTablesOnly) {
  BagSpec s;
  s.msgs = messages();
  s.msgs.resize(200);
  const fs::path dir = writeBag(tmpDir() / "sqlite_schema", s);
  const fs::path db3 = dir / "sqlite_schema_0.db3";
  const exid::Dataset ref = readBag(dir);
  auto alter = [&](const std::vector<std::string>& statements) {
    writeBag(dir, s);
    sqlite3* db = nullptr;
    EXPECT_EQ(sqlite3_open(db3.string().c_str(), &db), SQLITE_OK);
    for (const std::string& st : statements) sql(db, st);
    sqlite3_close(db);
  };
  // the index rosbag2 creates, and messages stored out of time order (read by rowid): the same
  alter({"CREATE INDEX timestamp_idx ON messages (timestamp ASC)",
         "UPDATE messages SET id = 1000000 - id"});
  {
    const exid::Dataset d = readBag(dir);
    EXPECT_EQ(d.t, ref.t);
    EXPECT_EQ(d.q, ref.q);
    EXPECT_EQ(d.tau, ref.tau);
  }
  // messages a view (here over the real rows: it used to be read as if it were the table)
  alter({"ALTER TABLE messages RENAME TO real_messages",
         "CREATE VIEW messages AS SELECT * FROM real_messages"});
  std::string e = errorOf(dir);
  EXPECT_NE(e.find("sqlite_schema_0.db3: the database holds a view 'messages': a rosbag2 file has "
                   "plain tables only"),
            std::string::npos)
      << e;
  // a view over an infinite recursive query (it used to run forever, writing temporary files)
  alter({"DROP TABLE messages",
         "CREATE VIEW messages AS WITH RECURSIVE c(x) AS (SELECT 1 UNION ALL SELECT x + 1 FROM c) "
         "SELECT x AS id, 9 AS topic_id, x AS timestamp, zeroblob(1000) AS data FROM c"});
  e = errorOf(dir);
  EXPECT_NE(e.find("holds a view 'messages'"), std::string::npos) << e;
  // topics a view; a trigger; a virtual table
  alter({"ALTER TABLE topics RENAME TO t2", "CREATE VIEW topics AS SELECT * FROM t2"});
  EXPECT_NE(errorOf(dir).find("holds a view 'topics'"), std::string::npos);
  alter({"CREATE TRIGGER t AFTER INSERT ON messages BEGIN DELETE FROM topics; END"});
  EXPECT_NE(errorOf(dir).find("holds a trigger 't'"), std::string::npos);
  alter({"DROP TABLE messages",
         "CREATE VIRTUAL TABLE messages USING fts4(id, topic_id, timestamp, data)"});
  e = errorOf(dir);
  EXPECT_NE(e.find("table 'messages' is a virtual table"), std::string::npos) << e;
  // a generated column, computed when it is read
  alter({"DROP TABLE messages",
         "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp "
         "INTEGER NOT NULL, data BLOB GENERATED ALWAYS AS (zeroblob(100000000)) VIRTUAL)",
         "INSERT INTO messages(topic_id, timestamp) VALUES (9, 1), (9, 2)"});
  e = errorOf(dir);
  EXPECT_NE(e.find("table 'messages': column 'data' is a generated or hidden column"),
            std::string::npos)
      << e;
  // a topic id defined twice (no primary key)
  alter({"DROP TABLE topics",
         "CREATE TABLE topics(id INTEGER, name TEXT, type TEXT, serialization_format TEXT)",
         "INSERT INTO topics VALUES (7, '/ft', 'geometry_msgs/msg/WrenchStamped', 'cdr')",
         "INSERT INTO topics VALUES (7, '/joint_states', 'sensor_msgs/msg/JointState', 'cdr')"});
  e = errorOf(dir);
  EXPECT_NE(e.find("table topics: id 7 names topic '/ft' and topic '/joint_states'"),
            std::string::npos)
      << e;
}

TEST(Rosbag2, MetadataIsCappedStrictAndARegularFile) {
  BagSpec s;
  s.msgs = messages();
  s.msgs.resize(100);
  const fs::path dir = writeBag(tmpDir() / "metadata", s);
  const fs::path mf = dir / "metadata.yaml";
  const std::string good = exid_cli::slurp(mf);
  EXPECT_EQ(readBag(dir).size(), 50);
  // a key twice: the first used to win
  std::ofstream(mf) << good << "  storage_identifier: mcap\n";
  std::string e = errorOf(dir);
  EXPECT_NE(e.find("metadata.yaml:"), std::string::npos) << e;
  EXPECT_NE(e.find("rosbag2_bagfile_information.storage_identifier: duplicate key "
                   "'storage_identifier' (first at line 3)"),
            std::string::npos)
      << e;
  // a topic listed twice
  std::ofstream(mf) << good
                    << "  topics_with_message_count:\n"
                       "    - topic_metadata: {name: /a, type: x}\n"
                       "    - topic_metadata: {name: /a, type: y}\n";
  e = errorOf(dir);
  EXPECT_NE(e.find("duplicate key 'topics_with_message_count'"), std::string::npos) << e;
  std::string twice = good;
  const auto t = twice.find("    - topic_metadata:");
  ASSERT_NE(t, std::string::npos);
  twice.insert(t, "    - topic_metadata: {name: /ft, type: std_msgs/msg/String}\n");
  std::ofstream(mf) << twice;
  e = errorOf(dir);
  EXPECT_NE(e.find("topic '/ft' is listed twice (entries 1 and 3)"), std::string::npos) << e;
  // a document that is not a mapping, a topic entry that is not one (found by fuzz_rosbag2:
  // yaml-cpp's BadSubscript escaped, exit 3)
  std::ofstream(mf) << "just a scalar\n";
  e = errorOf(dir);
  EXPECT_NE(e.find("metadata.yaml: expected a mapping rosbag2_bagfile_information at the top"),
            std::string::npos)
      << e;
  std::string scalar = good;
  scalar.insert(scalar.find("    - topic_metadata:"), "    - just a scalar\n");
  std::ofstream(mf) << scalar;
  e = errorOf(dir);
  EXPECT_NE(e.find("topics_with_message_count: expected entries"), std::string::npos) << e;
  // above 1 MiB (here a comment): refused before it is parsed
  std::ofstream(mf) << good << "# " << std::string(rb::kMaxMetadataBytes, 'x') << "\n";
  e = errorOf(dir);
  EXPECT_NE(e.find("metadata.yaml: the bag metadata file has"), std::string::npos) << e;
  EXPECT_NE(e.find("more than the limit of 1048576 bytes"), std::string::npos) << e;
  // a directory (it exited 3 with basic_filebuf::underflow) or a FIFO (it blocked forever)
  fs::remove(mf);
  fs::create_directory(mf);
  e = errorOf(dir);
  EXPECT_NE(e.find("metadata.yaml: the bag metadata file is a directory"), std::string::npos) << e;
  fs::remove(mf);
  ASSERT_EQ(::mkfifo(mf.c_str(), 0600), 0);
  e = errorOf(dir);
  EXPECT_NE(e.find("metadata.yaml: the bag metadata file is a FIFO"), std::string::npos) << e;
  fs::remove(mf);
  std::ofstream(mf) << good;
  EXPECT_EQ(readBag(dir).size(), 50);
}

TEST(Rosbag2, AStorageFileAboveItsCapIsAnInputErrorNamingFileAndCap) {
  // A sparse MCAP file one byte above the cap (it exited 3, "unexpected error": std::bad_alloc).
  BagSpec s;
  s.storage = "mcap";
  s.msgs = messages();
  s.msgs.resize(30);
  const fs::path dir = writeBag(tmpDir() / "sparse", s);
  const fs::path f = dir / "sparse_0.mcap";
  fs::resize_file(f, rb::kMaxMcapFileBytes + 1);
  const exid_cli::CmdResult r = exid_cli::runExid("inspect puma560 " + dir.string());
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find(f.string() + ": the bag storage (MCAP) file has 4294967297 bytes, more "
                                    "than the limit of 4294967296 bytes"),
            std::string::npos)
      << r.out;
  fs::remove_all(dir);
}
