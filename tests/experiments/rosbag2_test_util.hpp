// Helpers of the rosbag2 experiment's tests (rosbag2_test.cpp, rosbag2_errors_test.cpp,
// rosbag2_hostile_test.cpp): a CDR writer, a bag writer (SQLite; MCAP with chunks
// uncompressed, zstd and LZ4), the simulated PUMA 560 recording as bag messages and as CSV,
// and the experiment run on a bag.
#pragma once

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

namespace rbtest {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

/// The test's folder $TMPDIR/exid_rosbag2_test_<pid>, emptied on first use.
inline fs::path tmpDir() {
  static const fs::path p = exid_cli::freshTempDir("exid_rosbag2_test", "");
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

inline Bytes jointState(std::int64_t ns, const std::vector<std::string>& names,
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

inline Bytes wrenchStamped(std::int64_t ns, const double v[6]) {
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
  // per topic: its offered_qos_profiles text in the storage (MCAP channel metadata, SQLite
  // topics row); metadata.yaml always holds "" (rosbag2 writes the list there too)
  std::map<std::string, std::string> qos;
  int files = 1;
  std::size_t chunk_msgs = 250;
  int corrupt_chunk = -1;           // MCAP: xor bytes of this chunk's stored records
  bool channels_in_chunks = false;  // MCAP: Schema and Channel records inside the first chunk
};

inline void put(Bytes& b, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
inline void putStr(Bytes& b, const std::string& s) {
  put(b, s.size(), 4);
  b.insert(b.end(), s.begin(), s.end());
}
inline void record(Bytes& out, std::uint8_t op, const Bytes& content) {
  out.push_back(op);
  put(out, content.size(), 8);
  out.insert(out.end(), content.begin(), content.end());
}

inline Bytes compress(const std::string& how, const Bytes& in) {
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

inline void writeMcap(const fs::path& file, const BagSpec& spec,
                      const std::vector<const Msg*>& msgs) {
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
    putStr(meta, spec.qos.count(topic) ? spec.qos.at(topic) : "");
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

inline void sql(sqlite3* db, const std::string& s) {
  char* err = nullptr;
  ASSERT_EQ(sqlite3_exec(db, s.c_str(), nullptr, nullptr, &err), SQLITE_OK) << err;
}

inline void writeSqlite(const fs::path& file, const BagSpec& spec,
                        const std::vector<const Msg*>& msgs) {
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
    sql(db, fmt::format("INSERT INTO topics VALUES ({}, '{}', '{}', 'cdr', '{}')", ids[topic],
                        topic, type, spec.qos.count(topic) ? spec.qos.at(topic) : ""));
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
inline fs::path writeBag(const fs::path& dir, const BagSpec& spec) {
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
inline constexpr std::int64_t kEpoch = 1700000000LL * 1000000000LL + 123456789LL;

struct Recording {
  exid::Dataset d;                 // t (s after the first stamp), q, tau, wrench
  std::vector<std::int64_t> ns;    // header stamps
  std::vector<std::string> names;  // the robot's joint names
};

inline const Recording& recording() {
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
inline std::vector<Msg> messages(const std::vector<int>& perm = {3, 0, 5, 1, 4, 2},
                                 bool wrench = true) {
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

inline fs::path csvOfRecording() {
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

inline exid::Dataset readBag(const fs::path& dir, const std::string& extra = "") {
  auto e = exid_test::create<exid::Experiment>(
      "rosbag2", "{path: " + dir.string() + (extra.empty() ? "" : ", " + extra) + "}");
  return e->run(mtest::robot("puma560"), nullptr, mtest::context());
}

inline std::string errorOf(const fs::path& dir, const std::string& extra = "") {
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
inline const Variant kVariants[] = {{"sqlite", "sqlite3", "", 1, false},
                                    {"sqlite_two_files", "sqlite3", "", 2, false},
                                    {"mcap", "mcap", "", 1, false},
                                    {"mcap_zstd", "mcap", "zstd", 1, true},
                                    {"mcap_lz4", "mcap", "lz4", 2, true}};

inline fs::path bagOf(const Variant& v) {
  BagSpec s;
  s.storage = v.storage;
  s.compression = v.compression;
  s.files = v.files;
  s.channels_in_chunks = v.channels_in_chunks;
  s.msgs = messages();
  return writeBag(tmpDir() / v.tag, s);
}

inline std::int64_t acc(const exid::Dataset& d, const char* key) {
  const exid::Json* a = d.meta.find("accounting");
  if (!a || !a->find(key)) {
    ADD_FAILURE() << "no accounting." << key;
    return -1;
  }
  return a->find(key)->asInt();
}

}  // namespace rbtest
