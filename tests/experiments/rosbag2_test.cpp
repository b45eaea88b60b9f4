// Experiment `rosbag2`: bags written here in both storage formats (SQLite; MCAP with chunks
// uncompressed, zstd and LZ4) from a simulated PUMA 560 give exactly the dataset of the same
// samples written as CSV, and the same identification (filtered_ls, through the study path);
// damaged bags, unknown topics and joints are errors naming the place; the wrench is
// interpolated at the joint-state times and every message dropped or cut is counted.
#include <fmt/format.h>
#include <lz4frame.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>

#include "../models/model_test_util.hpp"
#include "bag.hpp"
#include "exid/config.hpp"
#include "exid/inspect.hpp"
#include "exid/io.hpp"
#include "exid/runner.hpp"
#include "exid_cli.hpp"

namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

fs::path tmpDir() {
  fs::path p = fs::temp_directory_path() / ("exid_rosbag2_test_" + std::to_string(::getpid()));
  fs::create_directories(p);
  return p;
}

// ------------------------------------------------------------------------------ CDR writer
struct CdrWriter {
  bool big = false;
  Bytes b{0x00, 0x01, 0x00, 0x00};  // CDR little endian (big endian: 00 00)
  void put(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i)
      b.push_back(static_cast<std::uint8_t>(v >> (8 * (big ? n - 1 - i : i))));
  }
  void align(std::size_t a) {
    while ((b.size() - 4) % a != 0) b.push_back(0);
  }
  void u32(std::uint32_t v) {
    align(4);
    put(v, 4);
  }
  void f64(double d) {
    align(8);
    std::uint64_t u;
    std::memcpy(&u, &d, 8);
    put(u, 8);
  }
  void str(const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size() + 1));
    b.insert(b.end(), s.begin(), s.end());
    b.push_back(0);
  }
  void doubles(const std::vector<double>& v) {
    u32(static_cast<std::uint32_t>(v.size()));
    for (double d : v) f64(d);
  }
  void stamp(std::int64_t ns) {
    u32(static_cast<std::uint32_t>(ns / 1000000000LL));
    u32(static_cast<std::uint32_t>(ns % 1000000000LL));
  }
};

Bytes jointState(std::int64_t ns, const std::vector<std::string>& names,
                 const std::vector<double>& pos, const std::vector<double>& vel,
                 const std::vector<double>& eff, const std::string& frame = "base",
                 bool big_endian = false) {
  CdrWriter w;
  w.big = big_endian;
  if (big_endian) w.b[1] = 0x00;
  w.stamp(ns);
  w.str(frame);
  w.u32(static_cast<std::uint32_t>(names.size()));
  for (const auto& s : names) w.str(s);
  w.doubles(pos);
  w.doubles(vel);
  w.doubles(eff);
  return w.b;
}

Bytes wrenchStamped(std::int64_t ns, const double v[6]) {
  CdrWriter w;
  w.stamp(ns);
  w.str("tool0_ft");
  for (int c = 0; c < 6; ++c) w.f64(v[c]);
  return w.b;
}

// ------------------------------------------------------------------------------ bag writer
struct Msg {
  std::string topic;
  std::int64_t receive_ns;
  Bytes data;
};

struct BagSpec {
  std::string storage = "sqlite3";  // sqlite3 or mcap (the files written)
  std::string compression;          // MCAP chunks: "", zstd, lz4
  std::string metadata_storage;     // storage_identifier written; empty: storage
  std::map<std::string, std::string> types = {{"/joint_states", "sensor_msgs/msg/JointState"},
                                              {"/ft", "geometry_msgs/msg/WrenchStamped"},
                                              {"/cmd", "std_msgs/msg/String"}};
  std::vector<Msg> msgs;
  int files = 1;
  std::size_t chunk_msgs = 250;
  int corrupt_chunk = -1;           // MCAP: xor bytes of this chunk's stored records
  bool channels_in_chunks = false;  // MCAP: Schema and Channel records inside the first chunk
};

void put(Bytes& b, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
void putStr(Bytes& b, const std::string& s) {
  put(b, s.size(), 4);
  b.insert(b.end(), s.begin(), s.end());
}
void record(Bytes& out, std::uint8_t op, const Bytes& content) {
  out.push_back(op);
  put(out, content.size(), 8);
  out.insert(out.end(), content.begin(), content.end());
}

Bytes compress(const std::string& how, const Bytes& in) {
  if (how.empty()) return in;
  if (how == "zstd") {
    Bytes out(ZSTD_compressBound(in.size()));
    const std::size_t n = ZSTD_compress(out.data(), out.size(), in.data(), in.size(), 3);
    EXPECT_FALSE(ZSTD_isError(n));
    out.resize(n);
    return out;
  }
  Bytes out(LZ4F_compressFrameBound(in.size(), nullptr));
  const std::size_t n = LZ4F_compressFrame(out.data(), out.size(), in.data(), in.size(), nullptr);
  EXPECT_FALSE(LZ4F_isError(n));
  out.resize(n);
  return out;
}

void writeMcap(const fs::path& file, const BagSpec& spec, const std::vector<const Msg*>& msgs) {
  Bytes out = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
  Bytes h;
  putStr(h, "ros2");
  putStr(h, "exid test writer");
  record(out, 0x01, h);
  std::map<std::string, std::uint16_t> chan;
  Bytes defs;  // Schema and Channel records
  for (const auto& [topic, type] : spec.types) {
    const std::uint16_t id = static_cast<std::uint16_t>(chan.size() + 1);
    chan[topic] = id;
    Bytes s;
    put(s, id, 2);
    putStr(s, type);
    putStr(s, "ros2msg");
    putStr(s, "# message definition");
    record(defs, 0x03, s);
    Bytes c;
    put(c, id, 2);
    put(c, id, 2);
    putStr(c, topic);
    putStr(c, "cdr");
    Bytes meta;
    putStr(meta, "offered_qos_profiles");
    putStr(meta, "");
    putStr(c, std::string(meta.begin(), meta.end()));  // a map: u32 byte length + entries
    record(defs, 0x04, c);
  }
  if (!spec.channels_in_chunks) out.insert(out.end(), defs.begin(), defs.end());
  int chunk = 0;
  for (std::size_t i = 0; i < msgs.size(); i += spec.chunk_msgs, ++chunk) {
    Bytes recs;
    if (spec.channels_in_chunks && i == 0) recs = defs;
    std::uint64_t t_lo = UINT64_MAX, t_hi = 0;
    for (std::size_t k = i; k < std::min(msgs.size(), i + spec.chunk_msgs); ++k) {
      const Msg& m = *msgs[k];
      Bytes r;
      put(r, chan.at(m.topic), 2);
      put(r, k, 4);
      put(r, static_cast<std::uint64_t>(m.receive_ns), 8);
      put(r, static_cast<std::uint64_t>(m.receive_ns), 8);
      r.insert(r.end(), m.data.begin(), m.data.end());
      record(recs, 0x05, r);
      t_lo = std::min<std::uint64_t>(t_lo, static_cast<std::uint64_t>(m.receive_ns));
      t_hi = std::max<std::uint64_t>(t_hi, static_cast<std::uint64_t>(m.receive_ns));
    }
    Bytes stored = compress(spec.compression, recs);
    if (chunk == spec.corrupt_chunk)
      for (std::size_t k = stored.size() / 3; k < stored.size() / 3 + 16 && k < stored.size(); ++k)
        stored[k] ^= 0x5A;
    Bytes c;
    put(c, t_lo, 8);
    put(c, t_hi, 8);
    put(c, recs.size(), 8);
    put(c, exid::rosbag2::crc32(recs.data(), recs.size()), 4);
    putStr(c, spec.compression);
    put(c, stored.size(), 8);
    c.insert(c.end(), stored.begin(), stored.end());
    record(out, 0x06, c);
    Bytes mi;  // an (empty) MessageIndex: a record the reader skips
    put(mi, 1, 2);
    put(mi, 0, 4);
    record(out, 0x07, mi);
  }
  Bytes de;
  put(de, 0, 4);
  record(out, 0x0F, de);
  // Summary section: a Statistics record (skipped), then the Footer and the closing magic.
  Bytes st(46, 0);
  record(out, 0x0B, st);
  Bytes f;
  put(f, 0, 8);
  put(f, 0, 8);
  put(f, 0, 4);
  record(out, 0x02, f);
  const Bytes magic = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
  out.insert(out.end(), magic.begin(), magic.end());
  std::ofstream(file, std::ios::binary)
      .write(reinterpret_cast<const char*>(out.data()), static_cast<std::streamsize>(out.size()));
}

void sql(sqlite3* db, const std::string& s) {
  char* err = nullptr;
  ASSERT_EQ(sqlite3_exec(db, s.c_str(), nullptr, nullptr, &err), SQLITE_OK) << err;
}

void writeSqlite(const fs::path& file, const BagSpec& spec, const std::vector<const Msg*>& msgs) {
  fs::remove(file);
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(file.string().c_str(), &db), SQLITE_OK);
  sql(db, "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL)");
  sql(db, "INSERT INTO schema VALUES (3, 'humble')");
  sql(db,
      "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, "
      "serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL)");
  sql(db,
      "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER "
      "NOT NULL, data BLOB NOT NULL)");
  std::map<std::string, int> ids;
  for (const auto& [topic, type] : spec.types) {
    ids[topic] = static_cast<int>(ids.size()) + 7;  // ids need not start at 1
    sql(db, fmt::format("INSERT INTO topics VALUES ({}, '{}', '{}', 'cdr', '')", ids[topic], topic,
                        type));
  }
  sql(db, "BEGIN");
  sqlite3_stmt* st = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "INSERT INTO messages(topic_id, timestamp, data) VALUES (?,?,?)",
                               -1, &st, nullptr),
            SQLITE_OK);
  for (const Msg* m : msgs) {
    sqlite3_bind_int(st, 1, ids.at(m->topic));
    sqlite3_bind_int64(st, 2, m->receive_ns);
    sqlite3_bind_blob(st, 3, m->data.data(), static_cast<int>(m->data.size()), SQLITE_TRANSIENT);
    ASSERT_EQ(sqlite3_step(st), SQLITE_DONE);
    sqlite3_reset(st);
  }
  sqlite3_finalize(st);
  sql(db, "COMMIT");
  sqlite3_close(db);
}

/// Writes the bag folder `dir`: its storage file(s) and metadata.yaml.
fs::path writeBag(const fs::path& dir, const BagSpec& spec) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string ext = spec.storage == "mcap" ? "mcap" : "db3";
  std::vector<std::string> files;
  std::map<std::string, long long> counts;
  for (const Msg& m : spec.msgs) ++counts[m.topic];
  const std::size_t per = (spec.msgs.size() + static_cast<std::size_t>(spec.files) - 1) /
                          static_cast<std::size_t>(spec.files);
  for (int f = 0; f < spec.files; ++f) {
    std::vector<const Msg*> part;
    for (std::size_t i = static_cast<std::size_t>(f) * per;
         i < std::min(spec.msgs.size(), static_cast<std::size_t>(f + 1) * per); ++i)
      part.push_back(&spec.msgs[i]);
    const std::string name = fmt::format("{}_{}.{}", dir.filename().string(), f, ext);
    files.push_back(name);
    if (spec.storage == "mcap")
      writeMcap(dir / name, spec, part);
    else
      writeSqlite(dir / name, spec, part);
  }
  std::string y = "rosbag2_bagfile_information:\n  version: 5\n";
  y += "  storage_identifier: " +
       (spec.metadata_storage.empty() ? spec.storage : spec.metadata_storage) + "\n";
  y += "  duration:\n    nanoseconds: 0\n  starting_time:\n    nanoseconds_since_epoch: 0\n";
  y += fmt::format("  message_count: {}\n  topics_with_message_count:\n", spec.msgs.size());
  for (const auto& [topic, type] : spec.types)
    y += fmt::format(
        "    - topic_metadata:\n        name: {}\n        type: {}\n        serialization_format: "
        "cdr\n        offered_qos_profiles: \"\"\n      message_count: {}\n",
        topic, type, counts[topic]);
  y += "  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n";
  for (const auto& f : files) y += "    - " + f + "\n";
  std::ofstream(dir / "metadata.yaml") << y;
  return dir;
}

// ------------------------------------------------------------------------------ the recording
constexpr std::int64_t kEpoch = 1700000000LL * 1000000000LL + 123456789LL;

struct Recording {
  exid::Dataset d;                 // t (s after the first stamp), q, tau, wrench
  std::vector<std::int64_t> ns;    // header stamps
  std::vector<std::string> names;  // the robot's joint names
};

const Recording& recording() {
  static const Recording rec = [] {
    Recording r;
    auto robot = mtest::robot("puma560");
    const exid::Dataset s = mtest::simulate(
        robot,
        "{period_s: 10, harmonics: 5, duration_s: 10, sample_period_s: 0.005, wrench: true, "
        "payload_mass_kg: 1, noise_q_rad: 1e-5, noise_tau_Nm: 0.05, output_qd_qdd: false}");
    for (const auto& b : robot->bodies) r.names.push_back(b.joint_name);
    r.d = s;
    for (int k = 0; k < s.size(); ++k) {
      r.ns.push_back(kEpoch + std::llround(s.t[k] * 1e9));
      r.d.t[k] = static_cast<double>(r.ns.back() - r.ns.front()) / 1e9;
    }
    return r;
  }();
  return rec;
}

/// The recording as bag messages: joint states in the order `perm` of the robot's joints (plus a
/// gripper joint the robot does not have), the wrench on /ft at the same stamps, and messages on
/// an unrelated topic; receive stamps 2 ms (plus a jitter of a few us) after the header stamps.
std::vector<Msg> messages(const std::vector<int>& perm = {3, 0, 5, 1, 4, 2}, bool wrench = true) {
  const Recording& r = recording();
  std::vector<Msg> out;
  for (int k = 0; k < r.d.size(); ++k) {
    std::vector<std::string> names;
    std::vector<double> pos, vel, eff;
    for (int j : perm) {
      names.push_back(r.names[static_cast<std::size_t>(j)]);
      pos.push_back(r.d.q(k, j));
      vel.push_back(100.0 + j);  // not used unless use_velocity
      eff.push_back(r.d.tau(k, j));
    }
    names.push_back("gripper_finger");
    pos.push_back(0.01);
    vel.push_back(0.0);
    eff.push_back(-1.0);
    const std::int64_t recv = r.ns[static_cast<std::size_t>(k)] + 2000000 + (k % 3) * 1000;
    out.push_back({"/joint_states", recv,
                   jointState(r.ns[static_cast<std::size_t>(k)], names, pos, vel, eff)});
    if (wrench) {
      double w[6];
      for (int c = 0; c < 6; ++c) w[c] = r.d.wrench(k, c);
      out.push_back({"/ft", recv + 500, wrenchStamped(r.ns[static_cast<std::size_t>(k)], w)});
    }
    if (k % 50 == 0) {
      CdrWriter s;
      s.str("hello");
      out.push_back({"/cmd", recv + 700, s.b});
    }
  }
  return out;
}

fs::path csvOfRecording() {
  static const fs::path f = [] {
    exid::Dataset d = recording().d;
    d.qd.resize(0, 0);
    d.qdd.resize(0, 0);
    const fs::path p = tmpDir() / "recording.csv";
    exid::writeCsvAtomic(p, exid::datasetTable(d));
    return p;
  }();
  return f;
}

exid::Dataset readBag(const fs::path& dir, const std::string& extra = "") {
  auto e = exid_test::create<exid::Experiment>(
      "rosbag2", "{path: " + dir.string() + (extra.empty() ? "" : ", " + extra) + "}");
  return e->run(mtest::robot("puma560"), nullptr, mtest::context());
}

std::string errorOf(const fs::path& dir, const std::string& extra = "") {
  try {
    readBag(dir, extra);
  } catch (const exid::Error& e) {
    return e.what();
  }
  return "(no error)";
}

struct Variant {
  const char* tag;
  const char* storage;
  const char* compression;
  int files;
  bool channels_in_chunks;
};
const Variant kVariants[] = {{"sqlite", "sqlite3", "", 1, false},
                             {"sqlite_two_files", "sqlite3", "", 2, false},
                             {"mcap", "mcap", "", 1, false},
                             {"mcap_zstd", "mcap", "zstd", 1, true},
                             {"mcap_lz4", "mcap", "lz4", 2, true}};

fs::path bagOf(const Variant& v) {
  BagSpec s;
  s.storage = v.storage;
  s.compression = v.compression;
  s.files = v.files;
  s.channels_in_chunks = v.channels_in_chunks;
  s.msgs = messages();
  return writeBag(tmpDir() / v.tag, s);
}

std::int64_t acc(const exid::Dataset& d, const char* key) {
  const exid::Json* a = d.meta.find("accounting");
  if (!a || !a->find(key)) {
    ADD_FAILURE() << "no accounting." << key;
    return -1;
  }
  return a->find(key)->asInt();
}

}  // namespace

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
  EXPECT_NE(errorOf(tmpDir() / "no_such_bag").find("not a folder"), std::string::npos);
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

// ------------------------------------------------------------------------------ issue 37:
// decoders that validate everything they decode (docs/hostile_input.md, "rosbag2 bags").
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
