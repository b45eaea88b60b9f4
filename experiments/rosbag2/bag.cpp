// exid — rosbag2 storage (metadata.yaml, SQLite, MCAP) and CDR decoding. See bag.hpp.
//
// Formats, as read here:
// - metadata.yaml: rosbag2_bagfile_information {version, storage_identifier, relative_file_paths,
//   topics_with_message_count: [{topic_metadata: {name, type, serialization_format},
//   message_count}], compression_format, compression_mode}.
// - SQLite (.db3): tables topics(id, name, type, serialization_format, ...) and
//   messages(id, topic_id, timestamp, data).
// - MCAP: magic \x89MCAP0\r\n, then records <opcode u8><length u64><content>, little endian;
//   strings are u32 length + bytes; Schema(0x03) {id u16, name, encoding, data u32+bytes},
//   Channel(0x04) {id u16, schema_id u16, topic, message_encoding, metadata}, Message(0x05)
//   {channel_id u16, sequence u32, log_time u64, publish_time u64, data}, Chunk(0x06)
//   {start u64, end u64, uncompressed_size u64, uncompressed_crc u32, compression, records
//   u64+bytes}, DataEnd(0x0F) ends the data section, Footer(0x02) the file; other records are
//   skipped. The data section is read sequentially: no summary section is needed.
// - CDR: 4-byte encapsulation header (0x00 0x01: little endian, 0x00 0x00: big endian), then
//   the fields, each aligned to its size relative to the end of that header.
#include "bag.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <lz4frame.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <map>
#include <memory>
#include <new>

#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/yaml_strict.hpp"

namespace exid::rosbag2 {

namespace fs = std::filesystem;

namespace {

/// A read-only byte range (C++17 has no std::span).
struct Span {
  const std::uint8_t* p;
  std::size_t n;
  std::size_t size() const { return n; }
  const std::uint8_t* data() const { return p; }
  const std::uint8_t* begin() const { return p; }
  std::uint8_t operator[](std::size_t i) const { return p[i]; }
};

constexpr std::array<std::uint8_t, 8> kMcapMagic = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

/// Bounds-checked little-endian reader of a byte range (MCAP records).
class Bytes {
 public:
  Bytes(const std::uint8_t* p, std::size_t n, std::string where)
      : p_(p), n_(n), where_(std::move(where)) {}
  std::size_t pos() const { return pos_; }
  std::size_t left() const { return n_ - pos_; }
  void need(std::size_t k, const char* what) const {
    if (k > left())
      throw Error(fmt::format("{}: truncated: {} needs {} bytes at byte {}, {} left", where_, what,
                              k, pos_, left()));
  }
  std::uint64_t uint(int bytes, const char* what) {
    need(static_cast<std::size_t>(bytes), what);
    std::uint64_t v = 0;
    for (int i = bytes - 1; i >= 0; --i) v = (v << 8) | p_[pos_ + static_cast<std::size_t>(i)];
    pos_ += static_cast<std::size_t>(bytes);
    return v;
  }
  std::uint16_t u16(const char* what) { return static_cast<std::uint16_t>(uint(2, what)); }
  std::uint32_t u32(const char* what) { return static_cast<std::uint32_t>(uint(4, what)); }
  std::uint64_t u64(const char* what) { return uint(8, what); }
  std::string str(const char* what) {
    const std::uint32_t len = u32(what);
    need(len, what);
    std::string s(reinterpret_cast<const char*>(p_ + pos_), len);
    pos_ += len;
    return s;
  }
  /// A u32- or u64-length-prefixed byte range: its start and size.
  std::pair<const std::uint8_t*, std::size_t> block(int len_bytes, const char* what) {
    const std::uint64_t len = uint(len_bytes, what);
    if (len > left())
      throw Error(fmt::format("{}: truncated: {} has length {} at byte {}, {} bytes left", where_,
                              what, len, pos_, left()));
    const std::uint8_t* at = p_ + pos_;
    pos_ += static_cast<std::size_t>(len);
    return {at, static_cast<std::size_t>(len)};
  }
  std::pair<const std::uint8_t*, std::size_t> rest() {
    const std::uint8_t* at = p_ + pos_;
    const std::size_t k = left();
    pos_ = n_;
    return {at, k};
  }

 private:
  const std::uint8_t* p_;
  std::size_t n_, pos_ = 0;
  std::string where_;
};

// ------------------------------------------------------------------------------ CDR
class Cdr {
 public:
  Cdr(const std::uint8_t* p, std::size_t n, const std::string& where) : where_(where) {
    if (n < 4)
      throw Error(
          fmt::format("{}: truncated message: {} bytes, expected at least the 4-byte CDR "
                      "encapsulation header",
                      where, n));
    if (p[0] != 0x00 || (p[1] != 0x00 && p[1] != 0x01))
      throw Error(
          fmt::format("{}: CDR encapsulation {:02x} {:02x}: expected 00 01 (CDR little "
                      "endian) or 00 00 (CDR big endian)",
                      where, p[0], p[1]));
    big_ = p[1] == 0x00;
    p_ = p + 4;
    n_ = n - 4;
  }
  void align(std::size_t a, const char* what) {
    const std::size_t to = (pos_ + a - 1) / a * a;
    if (to > n_) fail(to - pos_, what);
    pos_ = to;
  }
  void need(std::size_t k, const char* what) const {
    if (k > n_ - pos_) fail(k, what);
  }
  std::uint64_t raw(std::size_t size, const char* what) {
    align(size, what);
    need(size, what);
    std::uint64_t v = 0;
    for (std::size_t i = 0; i < size; ++i) {
      const std::size_t b = big_ ? i : size - 1 - i;
      v = (v << 8) | p_[pos_ + b];
    }
    pos_ += size;
    return v;
  }
  std::uint32_t u32(const char* what) { return static_cast<std::uint32_t>(raw(4, what)); }
  std::int32_t i32(const char* what) {
    const std::uint32_t u = u32(what);
    std::int32_t v;
    std::memcpy(&v, &u, 4);
    return v;
  }
  double f64(const char* what) {
    const std::uint64_t u = raw(8, what);
    double v;
    std::memcpy(&v, &u, 8);
    return v;
  }
  std::string str(const char* what) {
    const std::uint32_t len = u32(what);
    need(len, what);
    // The length counts the terminating NUL; an empty string may be written with length 0.
    if (len > 0 && p_[pos_ + len - 1] != 0)
      throw Error(
          fmt::format("{}: {}: the string of {} bytes at byte {} of the CDR data does not "
                      "end with its terminating NUL byte (a corrupt message, or not of "
                      "this type)",
                      where_, what, len, pos_ + 4));
    const std::size_t k = len > 0 ? len - 1 : 0;
    const void* nul = std::memchr(p_ + pos_, 0, k);
    if (nul)
      throw Error(fmt::format(
          "{}: {}: a NUL byte inside the string at byte {} of the CDR data (its {} bytes end at "
          "byte {}); a name or frame holds no NUL",
          where_, what, static_cast<const std::uint8_t*>(nul) - p_ + 4, len, pos_ + 4 + len));
    std::string s(reinterpret_cast<const char*>(p_ + pos_), k);
    pos_ += len;
    return s;
  }
  /// The message must end here: at most 3 zero bytes of padding may follow (a serializer may pad
  /// the data to a multiple of 4); anything else is left over, the message is not of `type`.
  void finish(const char* type) const {
    const std::size_t left = n_ - pos_;
    bool padding = left <= 3;
    for (std::size_t i = pos_; padding && i < n_; ++i) padding = p_[i] == 0;
    if (!padding)
      throw Error(fmt::format(
          "{}: {} bytes left after the {} message, which ends at byte {} of the {} bytes of "
          "CDR data: not a {} (a message of another type on this topic, or a corrupt one); a "
          "message must be consumed exactly",
          where_, left, type, pos_ + 4, n_ + 4, type));
  }
  /// Length of a sequence whose elements take at least min_elem bytes each (never more elements
  /// than the bytes left can hold: a corrupt length allocates nothing).
  std::size_t count(std::size_t min_elem, const char* what) {
    const std::uint32_t c = u32(what);
    if (static_cast<std::uint64_t>(c) * min_elem > n_ - pos_)
      throw Error(fmt::format(
          "{}: corrupt or truncated message: {} has {} elements, which need "
          "at least {} bytes at byte {}; {} left",
          where_, what, c, static_cast<std::uint64_t>(c) * min_elem, pos_ + 4, n_ - pos_));
    return c;
  }
  std::vector<double> doubles(const char* what) {
    const std::size_t c = count(8, what);
    std::vector<double> v(c);
    if (c > 0) align(8, what);  // an empty sequence writes no padding (Fast-CDR)
    for (std::size_t i = 0; i < c; ++i) v[i] = f64(what);
    return v;
  }
  Stamp stamp() {
    Stamp s;
    s.sec = i32("header.stamp.sec");
    s.nanosec = u32("header.stamp.nanosec");
    if (s.nanosec >= 1000000000u)
      throw Error(
          fmt::format("{}: header.stamp.nanosec = {}: expected below 1e9", where_, s.nanosec));
    return s;
  }

 private:
  [[noreturn]] void fail(std::size_t k, const char* what) const {
    throw Error(
        fmt::format("{}: truncated message: {} needs {} bytes at byte {} of the CDR data, "
                    "{} left",
                    where_, what, k, pos_ + 4, n_ - pos_));
  }
  const std::uint8_t* p_ = nullptr;
  std::size_t n_ = 0, pos_ = 0;
  bool big_ = false;
  const std::string& where_;
};

// ------------------------------------------------------------------------------ files
/// A storage file read whole: a regular file (checked before it is opened) of at most max_bytes.
std::vector<std::uint8_t> readWhole(const fs::path& p, const char* what, std::uint64_t max_bytes) {
  struct stat st {};
  const int fd = openInputFile(p, what, max_bytes, &st);
  std::vector<std::uint8_t> buf;
  try {
    buf.resize(static_cast<std::size_t>(st.st_size));
  } catch (const std::bad_alloc&) {
    ::close(fd);
    throw Error(fmt::format("{}: the {} file has {} bytes: not enough memory to read it whole",
                            p.string(), what, st.st_size));
  }
  std::size_t got = 0;
  while (got < buf.size()) {
    const ssize_t n = ::read(fd, buf.data() + got, buf.size() - got);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = errno;
      ::close(fd);
      throw Error(fmt::format("{}: cannot read the {} file ({})", p.string(), what,
                              n < 0 ? std::strerror(err) : "it ended early: it shrank"));
    }
    got += static_cast<std::size_t>(n);
  }
  ::close(fd);
  return buf;
}

std::string scalarText(const YAML::Node& n) {
  if (!n) return "(missing)";
  if (n.IsScalar()) return n.Scalar();
  if (n.IsSequence()) return "(a list)";
  if (n.IsMap()) return "(a mapping)";
  return "(null)";
}

// ------------------------------------------------------------------------------ SQLite
struct Db {
  sqlite3* db = nullptr;
  ~Db() {
    if (db) sqlite3_close(db);
  }
};
struct Stmt {
  sqlite3_stmt* s = nullptr;
  ~Stmt() {
    if (s) sqlite3_finalize(s);
  }
};

/// The work budget of one .db3 file (sqlite3_progress_handler, called every kSqliteTick steps).
constexpr int kSqliteTick = 10000;
struct SqliteWork {
  std::uint64_t ticks = 0, max_ticks = 0;
};
int sqliteProgress(void* p) {
  auto* w = static_cast<SqliteWork*>(p);
  return ++w->ticks > w->max_ticks ? 1 : 0;  // non-zero: interrupt the statement
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

}  // namespace

void readSqliteFile(const BagInfo& bag, const fs::path& file, const std::set<std::string>& wanted,
                    const std::function<void(const RawMessage&)>& fn) {
  const std::string name = file.string();
  // A regular file (a FIFO would block the open), checked before SQLite opens it.
  struct stat fst {};
  ::close(openInputFile(file, "bag storage (SQLite)", UINTMAX_MAX, &fst));
  Db db;
  if (sqlite3_open_v2(name.c_str(), &db.db, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX, nullptr) !=
      SQLITE_OK)
    throw Error(fmt::format("{}: cannot open as SQLite: {}", name,
                            db.db ? sqlite3_errmsg(db.db) : "out of memory"));
  // Defensive: no view or trigger can run, the schema is not trusted with functions that have
  // side effects, sizes are bounded, temporary data stays in memory (no temporary files), and
  // the work is bounded by the file's size.
  sqlite3_db_config(db.db, SQLITE_DBCONFIG_DEFENSIVE, 1, nullptr);
  sqlite3_db_config(db.db, SQLITE_DBCONFIG_TRUSTED_SCHEMA, 0, nullptr);
  sqlite3_db_config(db.db, SQLITE_DBCONFIG_ENABLE_VIEW, 0, nullptr);
  sqlite3_db_config(db.db, SQLITE_DBCONFIG_ENABLE_TRIGGER, 0, nullptr);
  sqlite3_limit(db.db, SQLITE_LIMIT_LENGTH, static_cast<int>(kMaxChunkBytes));
  sqlite3_limit(db.db, SQLITE_LIMIT_SQL_LENGTH, 1 << 20);
  sqlite3_limit(db.db, SQLITE_LIMIT_EXPR_DEPTH, 100);
  sqlite3_limit(db.db, SQLITE_LIMIT_COMPOUND_SELECT, 10);
  sqlite3_limit(db.db, SQLITE_LIMIT_ATTACHED, 0);
  sqlite3_limit(db.db, SQLITE_LIMIT_TRIGGER_DEPTH, 1);
  SqliteWork work;
  const std::uint64_t max_steps =
      kSqliteBaseSteps + kSqliteStepsPerByte * static_cast<std::uint64_t>(fst.st_size);
  work.max_ticks = max_steps / kSqliteTick;
  sqlite3_progress_handler(db.db, kSqliteTick, &sqliteProgress, &work);
  sqlite3_exec(db.db, "PRAGMA temp_store = MEMORY", nullptr, nullptr, nullptr);
  auto failure = [&](const char* what) {
    if (work.ticks > work.max_ticks)
      return Error(fmt::format(
          "{}: {}: stopped after {} steps of SQLite's work, the limit for a file of {} bytes "
          "({} + {} per byte): a hostile or corrupt database",
          name, what, max_steps, fst.st_size, kSqliteBaseSteps, kSqliteStepsPerByte));
    return Error(fmt::format("{}: {}: {}", name, what, sqlite3_errmsg(db.db)));
  };
  auto prepare = [&](const std::string& sql, Stmt* st, const char* what) {
    if (sqlite3_prepare_v2(db.db, sql.c_str(), -1, &st->s, nullptr) != SQLITE_OK)
      throw Error(
          fmt::format("{}: not a rosbag2 SQLite file ({}: {}; expected tables "
                      "topics(id, name, type, serialization_format) and messages(id, "
                      "topic_id, timestamp, data), storage_identifier sqlite3 in {})",
                      name, what, sqlite3_errmsg(db.db), bag.metadata_file.string()));
  };
  // One snapshot for every query below.
  if (sqlite3_exec(db.db, "BEGIN", nullptr, nullptr, nullptr) != SQLITE_OK) throw failure("BEGIN");
  // The schema: topics and messages plain tables; no view, no trigger anywhere.
  {
    Stmt st;
    prepare("SELECT type, name, sql FROM sqlite_master", &st, "the schema (sqlite_master)");
    std::set<std::string> tables;
    int rc;
    while ((rc = sqlite3_step(st.s)) == SQLITE_ROW) {
      auto text = [&](int c) {
        const unsigned char* t = sqlite3_column_text(st.s, c);
        return t ? std::string(reinterpret_cast<const char*>(t)) : std::string();
      };
      const std::string type = text(0), obj = text(1), sql = lower(text(2));
      if (type == "view" || type == "trigger")
        throw Error(fmt::format(
            "{}: the database holds a {} '{}': a rosbag2 file has plain tables only (topics, "
            "messages, and their indexes); views and triggers are refused",
            name, type, obj));
      if (type == "table" && (obj == "topics" || obj == "messages")) {
        if (sql.rfind("create virtual table", 0) == 0)
          throw Error(
              fmt::format("{}: table '{}' is a virtual table: a rosbag2 file has plain tables only",
                          name, obj));
        if (sql.find("without rowid") != std::string::npos)
          throw Error(fmt::format(
              "{}: table '{}' is a WITHOUT ROWID table: a rosbag2 file has plain tables only", name,
              obj));
        tables.insert(obj);
      }
    }
    if (rc != SQLITE_DONE) throw failure("reading the schema (sqlite_master)");
    for (const char* t : {"topics", "messages"})
      if (!tables.count(t))
        throw Error(
            fmt::format("{}: not a rosbag2 SQLite file (no table '{}'; expected tables "
                        "topics(id, name, type, serialization_format) and messages(id, "
                        "topic_id, timestamp, data), storage_identifier sqlite3 in {})",
                        name, t, bag.metadata_file.string()));
    // Stored columns only: a generated column is computed when it is read (zeroblob(2e8) per row).
    for (const char* t : {"topics", "messages"}) {
      Stmt cols;
      prepare(fmt::format("SELECT name, hidden FROM pragma_table_xinfo('{}')", t), &cols,
              "the columns of the tables (pragma table_xinfo)");
      int crc;
      while ((crc = sqlite3_step(cols.s)) == SQLITE_ROW)
        if (sqlite3_column_int(cols.s, 1) != 0) {
          const unsigned char* c = sqlite3_column_text(cols.s, 0);
          throw Error(fmt::format(
              "{}: table '{}': column '{}' is a generated or hidden column: a rosbag2 file has "
              "plain tables only, of stored columns",
              name, t, c ? reinterpret_cast<const char*>(c) : ""));
        }
      if (crc != SQLITE_DONE) throw failure("reading the columns of the tables");
    }
  }
  // Topics of this file: id -> name, with their types checked against metadata.yaml; one row
  // per id.
  std::map<std::int64_t, const std::string*> ids;
  {
    Stmt st;
    prepare("SELECT id, name, type, serialization_format FROM topics", &st, "table topics");
    std::map<std::int64_t, std::string> seen;
    int rc;
    while ((rc = sqlite3_step(st.s)) == SQLITE_ROW) {
      auto text = [&](int c) {
        const unsigned char* t = sqlite3_column_text(st.s, c);
        return t ? std::string(reinterpret_cast<const char*>(t)) : std::string();
      };
      const std::int64_t id = sqlite3_column_int64(st.s, 0);
      const std::string topic = text(1), type = text(2), ser = text(3);
      if (const auto [at, fresh] = seen.emplace(id, topic); !fresh)
        throw Error(fmt::format(
            "{}: table topics: id {} names topic '{}' and topic '{}': one definition per id", name,
            id, at->second, topic));
      const auto it = wanted.find(topic);
      if (it == wanted.end()) continue;
      const TopicInfo* info = bag.topic(topic);
      if (info && info->type != type)
        throw Error(fmt::format("{}: topic '{}' has type '{}' in table topics, '{}' in {}", name,
                                topic, type, info->type, bag.metadata_file.string()));
      if (ser != "cdr")
        throw Error(fmt::format("{}: topic '{}': serialization_format '{}', expected cdr", name,
                                topic, ser));
      ids[id] = &*it;
    }
    if (rc != SQLITE_DONE) throw failure("reading table topics");
  }
  if (ids.empty()) return;
  std::string in;
  for (const auto& [id, t] : ids) in += (in.empty() ? "" : ", ") + std::to_string(id);
  // The wanted messages' keys in the table's own order (a scan, no sort, no temporary data),
  // then ordered here by time stamp and id; their data are read one by one in that order.
  struct Key {
    std::int64_t ts, id, rowid;
    const std::string* topic;
  };
  std::vector<Key> keys;
  {
    Stmt st;
    prepare("SELECT rowid, id, topic_id, timestamp FROM messages NOT INDEXED WHERE topic_id IN (" +
                in + ") ORDER BY rowid",
            &st, "table messages");
    int rc;
    while ((rc = sqlite3_step(st.s)) == SQLITE_ROW) {
      Key k;
      k.rowid = sqlite3_column_int64(st.s, 0);
      k.id = sqlite3_column_int64(st.s, 1);
      k.topic = ids.at(sqlite3_column_int64(st.s, 2));
      k.ts = sqlite3_column_int64(st.s, 3);
      // Nanoseconds since the epoch; a negative one is corrupt (and differences of two
      // arbitrary int64 stamps could overflow).
      if (k.ts < 0)
        throw Error(
            fmt::format("{}: messages row id {}: timestamp {}: expected nanoseconds since "
                        "the epoch (>= 0)",
                        name, k.id, k.ts));
      keys.push_back(k);
    }
    if (rc != SQLITE_DONE) throw failure("reading table messages");
  }
  auto before = [](const Key& a, const Key& b) { return a.ts != b.ts ? a.ts < b.ts : a.id < b.id; };
  const bool in_order = std::is_sorted(keys.begin(), keys.end(), before);
  if (!in_order) std::stable_sort(keys.begin(), keys.end(), before);
  auto deliver = [&](const Key& k, sqlite3_stmt* s, int col) {
    RawMessage m;
    m.topic = k.topic;
    m.receive_ns = k.ts;
    m.data = static_cast<const std::uint8_t*>(sqlite3_column_blob(s, col));
    const int bytes = sqlite3_column_bytes(s, col);
    m.size = bytes > 0 && m.data ? static_cast<std::size_t>(bytes) : 0;
    m.where = fmt::format("{}: messages row id {}", name, k.id);
    fn(m);
  };
  Stmt st;
  if (in_order) {  // recorded in time order (the usual case): one more scan
    prepare("SELECT rowid, data FROM messages NOT INDEXED WHERE topic_id IN (" + in +
                ") ORDER BY rowid",
            &st, "table messages");
    std::size_t i = 0;
    int rc;
    while ((rc = sqlite3_step(st.s)) == SQLITE_ROW) {
      if (i >= keys.size() || sqlite3_column_int64(st.s, 0) != keys[i].rowid)
        throw Error(fmt::format("{}: table messages changed while it was read", name));
      deliver(keys[i++], st.s, 1);
    }
    if (rc != SQLITE_DONE) throw failure("reading table messages");
    if (i != keys.size())
      throw Error(fmt::format("{}: table messages changed while it was read", name));
  } else {  // each row by its rowid
    prepare("SELECT data FROM messages WHERE rowid = ?", &st, "table messages");
    for (const Key& k : keys) {
      sqlite3_reset(st.s);
      sqlite3_bind_int64(st.s, 1, k.rowid);
      const int rc = sqlite3_step(st.s);
      if (rc == SQLITE_DONE)
        throw Error(fmt::format("{}: table messages changed while it was read", name));
      if (rc != SQLITE_ROW) throw failure("reading table messages");
      deliver(k, st.s, 0);
    }
  }
}

namespace {

// ------------------------------------------------------------------------------ MCAP
/// A chunk's declared uncompressed size against the caps (before anything is decompressed).
void checkChunkSize(const std::string& compression, std::size_t size,
                    std::uint64_t uncompressed_size, const std::string& where) {
  if (uncompressed_size > kMaxChunkBytes)
    throw Error(
        fmt::format("{}: chunk uncompressed_size {} bytes is above the limit of {} bytes "
                    "(a corrupt size, or chunks far larger than rosbag2 writes)",
                    where, uncompressed_size, kMaxChunkBytes));
  if (uncompressed_size > kMaxChunkRatio * static_cast<std::uint64_t>(size) + kChunkAllowanceBytes)
    throw Error(fmt::format(
        "{}: chunk uncompressed_size {} bytes from {} compressed bytes ({}): above the limit "
        "of {} times the compressed size plus {} bytes (a decompression bomb, or a corrupt "
        "size)",
        where, uncompressed_size, size, compression.empty() ? "none" : compression, kMaxChunkRatio,
        kChunkAllowanceBytes));
}

struct McapState {
  struct Schema {
    std::string name, encoding;
    std::uint32_t data_crc = 0;
    std::size_t data_size = 0;
    std::string where;  // the record that defined it first
    bool operator==(const Schema& o) const {
      return name == o.name && encoding == o.encoding && data_crc == o.data_crc &&
             data_size == o.data_size;
    }
  };
  struct Channel {
    std::string topic, encoding;
    std::uint16_t schema = 0;
    const std::string* wanted = nullptr;  // the wanted topic, or null
    std::string where;                    // the record that defined it first
  };
  std::map<std::uint16_t, Schema> schemas;
  std::map<std::uint16_t, Channel> channels;
  std::map<std::string, std::uint16_t> topic_channel;  // a topic's first channel
  std::uint64_t decompressed = 0;                      // bytes of chunks so far (declared)
};

/// The name of a schema for messages ("0 (none)", "3 'sensor_msgs/msg/JointState'").
std::string schemaText(const McapState& st, std::uint16_t id) {
  if (id == 0) return "0 (none)";
  const auto s = st.schemas.find(id);
  return s == st.schemas.end() ? std::to_string(id) : fmt::format("{} '{}'", id, s->second.name);
}

/// Handles one Schema, Channel or Message record (top level or inside a chunk). Returns false
/// for other opcodes (the caller decides).
bool mcapRecord(const BagInfo& bag, const std::string& file, std::uint8_t op, Bytes& r,
                const std::string& where, McapState& st, const std::set<std::string>& wanted,
                const std::function<void(const RawMessage&)>& fn) {
  if (op == 0x03) {
    const std::uint16_t id = r.u16("Schema.id");
    McapState::Schema s;
    s.name = r.str("Schema.name");
    s.encoding = r.str("Schema.encoding");
    const auto data = r.block(4, "Schema.data");
    s.data_crc = crc32(data.first, data.second);
    s.data_size = data.second;
    s.where = where;
    if (id == 0)
      throw Error(fmt::format("{}: Schema.id 0: expected 1 or more (0 means no schema)", where));
    // One definition per schema id: a channel's type was checked against the first.
    const auto [it, fresh] = st.schemas.emplace(id, s);
    if (!fresh && !(it->second == s))
      throw Error(fmt::format(
          "{}: schema {} redefined as '{}' (encoding '{}', {} bytes of definition); it was "
          "defined as '{}' (encoding '{}', {} bytes) by {}: one definition per schema id",
          where, id, s.name, s.encoding, s.data_size, it->second.name, it->second.encoding,
          it->second.data_size, it->second.where));
    return true;
  }
  if (op == 0x04) {
    const std::uint16_t id = r.u16("Channel.id");
    McapState::Channel c;
    c.schema = r.u16("Channel.schema_id");
    c.topic = r.str("Channel.topic");
    c.encoding = r.str("Channel.message_encoding");
    r.block(4, "Channel.metadata");
    c.where = where;
    // One definition per channel id (the same record may repeat): a channel redefined to
    // another topic, schema or encoding would send its later messages elsewhere.
    if (const auto old = st.channels.find(id); old != st.channels.end()) {
      const McapState::Channel& o = old->second;
      if (o.topic != c.topic || o.schema != c.schema || o.encoding != c.encoding)
        throw Error(fmt::format(
            "{}: channel {} redefined as topic '{}' (schema {}, encoding '{}'); it was defined "
            "as topic '{}' (schema {}, encoding '{}') by {}: one definition per channel id",
            where, id, c.topic, schemaText(st, c.schema), c.encoding, o.topic,
            schemaText(st, o.schema), o.encoding, o.where));
      return true;
    }
    // One definition per topic: a second channel of a topic must say the same of it.
    if (const auto t = st.topic_channel.find(c.topic); t != st.topic_channel.end()) {
      const McapState::Channel& o = st.channels.at(t->second);
      auto schemaName = [&](std::uint16_t sid) {
        const auto f = st.schemas.find(sid);
        return f == st.schemas.end() ? "#" + std::to_string(sid) : f->second.name;
      };
      const bool same_schema =
          o.schema == c.schema ||
          (o.schema != 0 && c.schema != 0 && schemaName(o.schema) == schemaName(c.schema));
      if (!same_schema || o.encoding != c.encoding)
        throw Error(fmt::format(
            "{}: topic '{}' defined again by channel {} with schema {} and encoding '{}'; "
            "channel {} defined it with schema {} and encoding '{}' ({}): one definition per "
            "topic",
            where, c.topic, id, schemaText(st, c.schema), c.encoding, t->second,
            schemaText(st, o.schema), o.encoding, o.where));
    } else {
      st.topic_channel.emplace(c.topic, id);
    }
    const auto it = wanted.find(c.topic);
    if (it != wanted.end()) {
      c.wanted = &*it;
      if (c.encoding != "cdr")
        throw Error(fmt::format("{}: channel {} of topic '{}': message_encoding '{}', expected cdr",
                                where, id, c.topic, c.encoding));
      const TopicInfo* info = bag.topic(c.topic);
      if (c.schema != 0) {
        const auto s = st.schemas.find(c.schema);
        if (s == st.schemas.end())
          throw Error(
              fmt::format("{}: channel {} of topic '{}' refers to schema {}, not defined "
                          "before it",
                          where, id, c.topic, c.schema));
        if (info && s->second.name != info->type)
          throw Error(fmt::format("{}: topic '{}' has schema '{}' in {}, type '{}' in {}", where,
                                  c.topic, s->second.name, file, info->type,
                                  bag.metadata_file.string()));
      }
    }
    st.channels[id] = c;
    return true;
  }
  if (op == 0x05) {
    const std::uint16_t ch = r.u16("Message.channel_id");
    r.u32("Message.sequence");
    const std::uint64_t log_time = r.u64("Message.log_time");
    r.u64("Message.publish_time");
    const auto c = st.channels.find(ch);
    if (c == st.channels.end())
      throw Error(fmt::format(
          "{}: message on channel {}, which no Channel record defined before it", where, ch));
    if (!c->second.wanted) return true;
    RawMessage m;
    m.topic = c->second.wanted;
    if (log_time > static_cast<std::uint64_t>(INT64_MAX))
      throw Error(fmt::format("{}: Message.log_time {} ns is out of range", where, log_time));
    m.receive_ns = static_cast<std::int64_t>(log_time);
    const auto d = r.rest();
    m.data = d.first;
    m.size = d.second;
    m.where = where;
    fn(m);
    return true;
  }
  return false;
}

}  // namespace

void readMcapBytes(const BagInfo& bag, const std::string& file, const std::uint8_t* data,
                   std::size_t size, const std::set<std::string>& wanted,
                   const std::function<void(const RawMessage&)>& fn) {
  const Span buf{data, size};
  if (buf.size() < kMcapMagic.size() ||
      !std::equal(kMcapMagic.begin(), kMcapMagic.end(), buf.begin()))
    throw Error(
        fmt::format("{}: not an MCAP file: expected the magic bytes 89 4d 43 41 50 30 0d "
                    "0a at its start (storage_identifier mcap in {})",
                    file, bag.metadata_file.string()));
  McapState st;
  std::size_t pos = kMcapMagic.size();
  long long index = 0;
  bool ended = false;
  while (!ended) {
    ++index;
    if (buf.size() - pos < 9)
      throw Error(
          fmt::format("{}: truncated: record {} at byte {} needs a 9-byte opcode and "
                      "length, {} bytes left (the file ends before its DataEnd and Footer "
                      "records)",
                      file, index, pos, buf.size() - pos));
    const std::uint8_t op = buf[pos];
    std::uint64_t len = 0;
    for (int i = 8; i >= 1; --i) len = (len << 8) | buf[pos + static_cast<std::size_t>(i)];
    const std::size_t start = pos + 9;
    if (len > buf.size() - start)
      throw Error(
          fmt::format("{}: truncated: record {} (opcode 0x{:02x}) at byte {} has length "
                      "{}, {} bytes left in the file",
                      file, index, op, pos, len, buf.size() - start));
    const std::string where =
        fmt::format("{}: record {} (opcode 0x{:02x}) at byte {}", file, index, op, pos);
    Bytes r(buf.data() + start, static_cast<std::size_t>(len), where);
    pos = start + static_cast<std::size_t>(len);
    if (mcapRecord(bag, file, op, r, where, st, wanted, fn)) continue;
    if (op == 0x06) {  // Chunk
      r.u64("Chunk.message_start_time");
      r.u64("Chunk.message_end_time");
      const std::uint64_t usize = r.u64("Chunk.uncompressed_size");
      const std::uint32_t crc = r.u32("Chunk.uncompressed_crc");
      const std::string comp = r.str("Chunk.compression");
      const auto stored = r.block(8, "Chunk.records");
      // The chunk's and the file's decompression budgets, from the sizes the chunks declare,
      // before any work.
      checkChunkSize(comp, stored.second, usize, where);
      const std::uint64_t budget = std::min<std::uint64_t>(
          kMaxFileDecompressedBytes,
          kMaxChunkRatio * static_cast<std::uint64_t>(buf.size()) + kFileAllowanceBytes);
      if (usize > budget - std::min(budget, st.decompressed))
        throw Error(fmt::format(
            "{}: chunk uncompressed_size {} bytes would bring the file's decompressed chunks to "
            "{} bytes, above its limit of {} bytes ({} times the file's {} bytes plus {}, at most "
            "{}): a decompression bomb, or a corrupt size",
            where, usize, st.decompressed + usize, budget, kMaxChunkRatio, buf.size(),
            kFileAllowanceBytes, kMaxFileDecompressedBytes));
      st.decompressed += usize;
      const std::vector<std::uint8_t> recs =
          decompressChunk(comp, stored.first, stored.second, usize, where);
      if (crc != 0 && crc32(recs.data(), recs.size()) != crc)
        throw Error(
            fmt::format("{}: corrupt chunk: CRC-32 of its {} uncompressed bytes is "
                        "{:08x}, the chunk says {:08x}",
                        where, recs.size(), crc32(recs.data(), recs.size()), crc));
      std::size_t q = 0;
      long long inner = 0;
      while (q < recs.size()) {
        ++inner;
        if (recs.size() - q < 9)
          throw Error(
              fmt::format("{}: corrupt chunk: its record {} at byte {} needs a 9-byte "
                          "opcode and length, {} bytes left",
                          where, inner, q, recs.size() - q));
        const std::uint8_t iop = recs[q];
        std::uint64_t ilen = 0;
        for (int i = 8; i >= 1; --i) ilen = (ilen << 8) | recs[q + static_cast<std::size_t>(i)];
        if (ilen > recs.size() - q - 9)
          throw Error(
              fmt::format("{}: corrupt chunk: its record {} (opcode 0x{:02x}) at byte {} "
                          "has length {}, {} bytes left in the chunk",
                          where, inner, iop, q, ilen, recs.size() - q - 9));
        const std::string iwhere =
            fmt::format("{}, chunk record {} (opcode 0x{:02x})", where, inner, iop);
        Bytes ir(recs.data() + q + 9, static_cast<std::size_t>(ilen), iwhere);
        q += 9 + static_cast<std::size_t>(ilen);
        mcapRecord(bag, file, iop, ir, iwhere, st, wanted, fn);  // others: skipped
      }
      continue;
    }
    if (op == 0x0F || op == 0x02) ended = true;  // DataEnd (the summary follows) or Footer
    // Header, MessageIndex, ChunkIndex, Attachment, Metadata, Statistics, ...: skipped.
  }
}

namespace {

void readMcap(const BagInfo& bag, const fs::path& path, const std::set<std::string>& wanted,
              const std::function<void(const RawMessage&)>& fn) {
  const std::vector<std::uint8_t> buf = readWhole(path, "bag storage (MCAP)", kMaxMcapFileBytes);
  readMcapBytes(bag, path.string(), buf.data(), buf.size(), wanted, fn);
}

}  // namespace

// ------------------------------------------------------------------------------ public
const TopicInfo* BagInfo::topic(const std::string& name) const {
  for (const TopicInfo& t : topics)
    if (t.name == name) return &t;
  return nullptr;
}

std::uint32_t crc32(const std::uint8_t* data, std::size_t size, std::uint32_t crc) {
  static const std::array<std::uint32_t, 256> table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  crc = ~crc;
  for (std::size_t i = 0; i < size; ++i) crc = table[(crc ^ data[i]) & 0xFFu] ^ (crc >> 8);
  return ~crc;
}

std::vector<std::uint8_t> decompressChunk(const std::string& compression, const std::uint8_t* src,
                                          std::size_t size, std::uint64_t uncompressed_size,
                                          const std::string& where) {
  checkChunkSize(compression, size, uncompressed_size, where);
  std::vector<std::uint8_t> out;
  if (compression.empty()) {
    if (size != uncompressed_size)
      throw Error(
          fmt::format("{}: corrupt chunk: uncompressed, {} bytes of records, but "
                      "uncompressed_size says {}",
                      where, size, uncompressed_size));
    out.assign(src, src + size);
    return out;
  }
  if (compression != "zstd" && compression != "lz4")
    throw Error(fmt::format("{}: chunk compression '{}': expected \"\" (none), zstd or lz4", where,
                            compression));
  // Streaming decompression into a buffer that grows with the output (never beyond
  // uncompressed_size): a corrupt size field allocates nothing the data do not fill. When the
  // buffer is full, one scratch byte of room shows whether the stream would give more.
  const std::size_t usize = static_cast<std::size_t>(uncompressed_size);
  out.resize(std::min<std::size_t>(usize, std::size_t{1} << 20));
  std::size_t in_pos = 0, out_pos = 0;
  std::uint8_t scratch = 0;
  auto room = [&]() -> std::pair<std::uint8_t*, std::size_t> {
    if (out_pos == out.size() && out.size() < usize)
      out.resize(std::min(usize, std::max<std::size_t>(2 * out.size(), 4096)));
    if (out_pos == out.size()) return {&scratch, 1};
    return {out.data() + out_pos, out.size() - out_pos};
  };
  auto tooMuch = [&] {
    return Error(fmt::format("{}: corrupt chunk: {} gives more than uncompressed_size = {} bytes",
                             where, compression, uncompressed_size));
  };
  auto early = [&] {
    return Error(
        fmt::format("{}: corrupt chunk: the {} stream ends early ({} of {} bytes "
                    "decompressed, all {} compressed bytes read)",
                    where, compression, out_pos, uncompressed_size, size));
  };
  if (compression == "zstd") {
    std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> ctx(ZSTD_createDCtx(), &ZSTD_freeDCtx);
    if (!ctx) throw Error(fmt::format("{}: zstd: cannot create a decompression context", where));
    ZSTD_inBuffer in{src, size, 0};
    for (;;) {
      const auto [dst, cap] = room();
      ZSTD_outBuffer o{dst, cap, 0};
      const std::size_t r = ZSTD_decompressStream(ctx.get(), &o, &in);
      if (ZSTD_isError(r))
        throw Error(fmt::format("{}: corrupt chunk: zstd: {} ({} compressed bytes)", where,
                                ZSTD_getErrorName(r), size));
      if (dst == &scratch && o.pos > 0) throw tooMuch();
      if (dst != &scratch) out_pos += o.pos;
      if (in.pos == in.size) {
        if (r == 0) break;                  // the last frame is complete
        if (o.pos < o.size) throw early();  // room left, input used up, frame unfinished
      }
    }
  } else {
    LZ4F_dctx* raw = nullptr;
    if (LZ4F_isError(LZ4F_createDecompressionContext(&raw, LZ4F_VERSION)))
      throw Error(fmt::format("{}: lz4: cannot create a decompression context", where));
    std::unique_ptr<LZ4F_dctx, decltype(&LZ4F_freeDecompressionContext)> ctx(
        raw, &LZ4F_freeDecompressionContext);
    for (;;) {
      const auto [dst, cap] = room();
      std::size_t in_n = size - in_pos, out_n = cap;
      const std::size_t r = LZ4F_decompress(ctx.get(), dst, &out_n, src + in_pos, &in_n, nullptr);
      if (LZ4F_isError(r))
        throw Error(fmt::format("{}: corrupt chunk: lz4: {} ({} compressed bytes)", where,
                                LZ4F_getErrorName(r), size));
      if (dst == &scratch && out_n > 0) throw tooMuch();
      if (dst != &scratch) out_pos += out_n;
      in_pos += in_n;
      if (r == 0) {  // a frame is complete
        if (in_pos == size) break;
        continue;  // another frame follows
      }
      if (in_pos == size && out_n < cap) throw early();
    }
  }
  if (out_pos != usize)
    throw Error(fmt::format("{}: corrupt chunk: {} gave {} bytes, uncompressed_size says {}", where,
                            compression, out_pos, uncompressed_size));
  out.resize(out_pos);
  return out;
}

namespace {

/// The contents of metadata.yaml (readMetadata); YAML exceptions are the caller's.
void metadataOf(const YAML::Node& root, BagInfo* out) {
  BagInfo& bag = *out;
  const fs::path& dir = bag.dir;
  const std::string mf = bag.metadata_file.string();
  const YAML::Node info =
      root.IsMap() ? root["rosbag2_bagfile_information"] : YAML::Node(YAML::NodeType::Undefined);
  if (!info || !info.IsMap())
    throw Error(fmt::format("{}: expected a mapping rosbag2_bagfile_information at the top", mf));
  auto line = [](const YAML::Node& n) { return n.Mark().line + 1; };
  if (const YAML::Node v = info["version"]) {
    try {
      bag.version = v.as<int>();
    } catch (const YAML::Exception&) {
      throw Error(fmt::format("{}:{}: version: expected an integer, found '{}'", mf, line(v),
                              scalarText(v)));
    }
  }
  const YAML::Node sid = info["storage_identifier"];
  if (!sid || !sid.IsScalar())
    throw Error(fmt::format("{}: storage_identifier: missing (expected sqlite3 or mcap)", mf));
  bag.storage = sid.Scalar();
  if (bag.storage != "sqlite3" && bag.storage != "mcap")
    throw Error(fmt::format("{}:{}: storage_identifier '{}': expected sqlite3 or mcap", mf,
                            line(sid), bag.storage));
  const YAML::Node cf = info["compression_format"];
  if (cf && cf.IsScalar() && !cf.Scalar().empty())
    throw Error(
        fmt::format("{}:{}: compression_format '{}' (compression_mode '{}'): bags "
                    "compressed by rosbag2 as a whole are not read; decompress it (ros2 "
                    "bag convert) or record with the storage's own chunk compression "
                    "(MCAP zstd or lz4)",
                    mf, line(cf), cf.Scalar(), scalarText(info["compression_mode"])));
  const YAML::Node files = info["relative_file_paths"];
  if (!files || !files.IsSequence() || files.size() == 0)
    throw Error(
        fmt::format("{}: relative_file_paths: expected a list of the bag's storage files", mf));
  for (const YAML::Node& f : files) {
    if (!f.IsScalar())
      throw Error(fmt::format("{}:{}: relative_file_paths: expected file names, found '{}'", mf,
                              line(f), scalarText(f)));
    // Paths are relative to the bag folder; early versions wrote them relative to its parent.
    const fs::path rel = f.Scalar();
    std::vector<fs::path> tries = {dir / rel, dir.parent_path() / rel, dir / rel.filename()};
    fs::path found;
    for (const fs::path& p : tries) {
      std::error_code ec;  // (a name too long, say: not found, never an exception)
      if (fs::is_regular_file(p, ec)) {
        found = p;
        break;
      }
    }
    if (found.empty()) {
      std::vector<std::string> looked;
      for (const fs::path& p : tries) looked.push_back(p.string());
      throw Error(fmt::format("{}:{}: relative_file_paths: file '{}' not found (looked for {})", mf,
                              line(f), f.Scalar(), fmt::join(looked, ", ")));
    }
    bag.files.push_back(found);
  }
  const YAML::Node topics = info["topics_with_message_count"];
  if (topics && !topics.IsSequence())
    throw Error(fmt::format("{}:{}: topics_with_message_count: expected a list", mf, line(topics)));
  std::map<std::string, std::size_t> entries;  // topic -> its entry (1-based)
  if (topics)
    for (const YAML::Node& t : topics) {
      const YAML::Node md = t.IsMap() ? t["topic_metadata"] : YAML::Node(YAML::NodeType::Undefined);
      if (!md || !md.IsMap() || !md["name"] || !md["type"])
        throw Error(
            fmt::format("{}:{}: topics_with_message_count: expected entries "
                        "{{topic_metadata: {{name, type, serialization_format}}, "
                        "message_count}}",
                        mf, line(t)));
      TopicInfo ti;
      ti.name = scalarText(md["name"]);
      ti.type = scalarText(md["type"]);
      ti.serialization_format =
          md["serialization_format"] ? scalarText(md["serialization_format"]) : "cdr";
      if (const YAML::Node c = t["message_count"]) {
        try {
          ti.message_count = c.as<long long>();
        } catch (const YAML::Exception&) {
          throw Error(fmt::format("{}:{}: message_count: expected an integer, found '{}'", mf,
                                  line(c), scalarText(c)));
        }
      }
      if (const auto [at, fresh] = entries.emplace(ti.name, bag.topics.size() + 1); !fresh)
        throw Error(fmt::format(
            "{}:{}: topics_with_message_count: topic '{}' is listed twice (entries {} and {}); "
            "one entry per topic",
            mf, line(t), ti.name, at->second, bag.topics.size() + 1));
      bag.topics.push_back(ti);
    }
}

}  // namespace

BagInfo readMetadata(const fs::path& dir) {
  BagInfo bag;
  bag.dir = dir;
  bag.metadata_file = dir / "metadata.yaml";
  const std::string mf = bag.metadata_file.string();
  std::error_code dir_ec;  // (an error of the path itself, a name too long: not a folder)
  if (!fs::is_directory(dir, dir_ec))
    throw Error(
        fmt::format("{}: not a folder (a rosbag2 bag is a folder holding metadata.yaml and "
                    "its storage files)",
                    dir.string()));
  if (std::error_code ec; !fs::exists(bag.metadata_file, ec))
    throw Error(fmt::format("{}: no metadata.yaml in the bag folder {}", mf, dir.string()));
  // A regular file of at most kMaxMetadataBytes (checked before it is read), strict YAML: a key
  // repeated in a mapping is an error naming both lines.
  const std::string text = readInputFile(bag.metadata_file, "bag metadata", kMaxMetadataBytes);
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw Error(fmt::format("{}:{}: malformed YAML: {}", mf, e.mark.line + 1, e.msg));
  }
  {
    std::vector<std::string> problems;
    duplicateKeys(root, mf, "", &problems);
    if (!problems.empty()) throw Error(problems.front());
  }
  try {
    metadataOf(root, &bag);
  } catch (const YAML::Exception& x) {  // (a scalar where a mapping is expected, ...)
    throw Error(fmt::format("{}:{}: unexpected structure: {}", mf, x.mark.line + 1, x.msg));
  }
  return bag;
}

void readMessages(const BagInfo& bag, const std::set<std::string>& wanted,
                  const std::function<void(const RawMessage&)>& fn) {
  for (const fs::path& f : bag.files) {
    if (bag.storage == "sqlite3")
      readSqliteFile(bag, f, wanted, fn);
    else
      readMcap(bag, f, wanted, fn);
  }
}

JointStateMsg decodeJointState(const std::uint8_t* data, std::size_t size,
                               const std::string& where) {
  Cdr c(data, size, where);
  JointStateMsg m;
  m.stamp = c.stamp();
  m.frame_id = c.str("header.frame_id");
  const std::size_t nn = c.count(4, "name");
  m.name.reserve(nn);
  for (std::size_t i = 0; i < nn; ++i) m.name.push_back(c.str("name"));
  m.position = c.doubles("position");
  m.velocity = c.doubles("velocity");
  m.effort = c.doubles("effort");
  c.finish("sensor_msgs/msg/JointState");
  // Names unique: a joint named twice has two values, and which one is meant is unknowable.
  if (nn > 1) {
    std::vector<std::size_t> order(nn);
    for (std::size_t i = 0; i < nn; ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return m.name[a] != m.name[b] ? m.name[a] < m.name[b] : a < b;
    });
    for (std::size_t i = 1; i < nn; ++i)
      if (m.name[order[i]] == m.name[order[i - 1]])
        throw Error(fmt::format(
            "{}: name: joint '{}' is named twice (names {} and {} of {}); each joint may "
            "appear once in a JointState message",
            where, m.name[order[i]], order[i - 1] + 1, order[i] + 1, nn));
  }
  return m;
}

WrenchStampedMsg decodeWrenchStamped(const std::uint8_t* data, std::size_t size,
                                     const std::string& where) {
  Cdr c(data, size, where);
  WrenchStampedMsg m;
  m.stamp = c.stamp();
  m.frame_id = c.str("header.frame_id");
  for (double& v : m.force) v = c.f64("wrench.force");
  for (double& v : m.torque) v = c.f64("wrench.torque");
  c.finish("geometry_msgs/msg/WrenchStamped");
  return m;
}

}  // namespace exid::rosbag2
