// exid — rosbag2 storage: SQLite (.db3), read through its plain tables only. See bag.hpp.
//
// - SQLite (.db3): tables topics(id, name, type, serialization_format, ...) and
//   messages(id, topic_id, timestamp, data).
#include <fmt/format.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "bag.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"

namespace exid::rosbag2 {

namespace fs = std::filesystem;

namespace {

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

/// Column c of the current row as text (NULL: "").
std::string columnText(sqlite3_stmt* s, int c) {
  const unsigned char* t = sqlite3_column_text(s, c);
  return t ? std::string(reinterpret_cast<const char*>(t)) : std::string();
}

/// A wanted message: its storage time stamp, id and rowid, and its topic.
struct Key {
  std::int64_t ts, id, rowid;
  const std::string* topic;
};

/// One .db3 file opened read-only and defensively, and the work budget of all the statements on
/// it (readSqliteFile's queries, in one snapshot).
class SqliteFile {
 public:
  SqliteFile(const BagInfo& bag, const fs::path& file);
  SqliteFile(const SqliteFile&) = delete;
  SqliteFile& operator=(const SqliteFile&) = delete;

  /// The error of a statement that failed: the work budget used up, or SQLite's message.
  Error failure(const char* what) const {
    if (work_.ticks > work_.max_ticks)
      return Error(fmt::format(
          "{}: {}: stopped after {} steps of SQLite's work, the limit for a file of {} bytes "
          "({} + {} per byte): a hostile or corrupt database",
          name_, what, max_steps_, fst_.st_size, kSqliteBaseSteps, kSqliteStepsPerByte));
    return Error(fmt::format("{}: {}: {}", name_, what, sqlite3_errmsg(db_.db)));
  }
  void prepare(const std::string& sql, Stmt* st, const char* what) const {
    if (sqlite3_prepare_v2(db_.db, sql.c_str(), -1, &st->s, nullptr) != SQLITE_OK)
      throw Error(
          fmt::format("{}: not a rosbag2 SQLite file ({}: {}; expected tables "
                      "topics(id, name, type, serialization_format) and messages(id, "
                      "topic_id, timestamp, data), storage_identifier sqlite3 in {})",
                      name_, what, sqlite3_errmsg(db_.db), bag_.metadata_file.string()));
  }
  /// One snapshot for every query that follows.
  void begin() const {
    if (sqlite3_exec(db_.db, "BEGIN", nullptr, nullptr, nullptr) != SQLITE_OK)
      throw failure("BEGIN");
  }
  void checkSchema() const;
  void census(Census* out) const;
  std::map<std::int64_t, const std::string*> topicIds(const std::set<std::string>& wanted) const;
  std::vector<Key> messageKeys(const std::map<std::int64_t, const std::string*>& ids,
                               const std::string& in) const;
  void deliverInRowidOrder(const std::vector<Key>& keys, const std::string& in,
                           const std::function<void(const RawMessage&)>& fn) const;
  void deliverByRowid(const std::vector<Key>& keys,
                      const std::function<void(const RawMessage&)>& fn) const;

 private:
  void deliver(const Key& k, sqlite3_stmt* s, int col,
               const std::function<void(const RawMessage&)>& fn) const;

  const BagInfo& bag_;
  std::string name_;
  struct stat fst_ {};
  SqliteWork work_;
  std::uint64_t max_steps_ = 0;
  Db db_;  // (closed first: the progress handler's work_ outlives it)
};

SqliteFile::SqliteFile(const BagInfo& bag, const fs::path& file) : bag_(bag), name_(file.string()) {
  // A regular file (a FIFO would block the open), checked before SQLite opens it.
  ::close(openInputFile(file, "bag storage (SQLite)", UINTMAX_MAX, &fst_));
  if (sqlite3_open_v2(name_.c_str(), &db_.db, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX,
                      nullptr) != SQLITE_OK)
    throw Error(fmt::format("{}: cannot open as SQLite: {}", name_,
                            db_.db ? sqlite3_errmsg(db_.db) : "out of memory"));
  // Defensive: no view or trigger can run, the schema is not trusted with functions that have
  // side effects, sizes are bounded, temporary data stays in memory (no temporary files), and
  // the work is bounded by the file's size.
  sqlite3_db_config(db_.db, SQLITE_DBCONFIG_DEFENSIVE, 1, nullptr);
  sqlite3_db_config(db_.db, SQLITE_DBCONFIG_TRUSTED_SCHEMA, 0, nullptr);
  sqlite3_db_config(db_.db, SQLITE_DBCONFIG_ENABLE_VIEW, 0, nullptr);
  sqlite3_db_config(db_.db, SQLITE_DBCONFIG_ENABLE_TRIGGER, 0, nullptr);
  sqlite3_limit(db_.db, SQLITE_LIMIT_LENGTH, static_cast<int>(kMaxChunkBytes));
  sqlite3_limit(db_.db, SQLITE_LIMIT_SQL_LENGTH, 1 << 20);
  sqlite3_limit(db_.db, SQLITE_LIMIT_EXPR_DEPTH, 100);
  sqlite3_limit(db_.db, SQLITE_LIMIT_COMPOUND_SELECT, 10);
  sqlite3_limit(db_.db, SQLITE_LIMIT_ATTACHED, 0);
  sqlite3_limit(db_.db, SQLITE_LIMIT_TRIGGER_DEPTH, 1);
  max_steps_ = kSqliteBaseSteps + kSqliteStepsPerByte * static_cast<std::uint64_t>(fst_.st_size);
  work_.max_ticks = max_steps_ / kSqliteTick;
  sqlite3_progress_handler(db_.db, kSqliteTick, &sqliteProgress, &work_);
  sqlite3_exec(db_.db, "PRAGMA temp_store = MEMORY", nullptr, nullptr, nullptr);
}

/// The schema: topics and messages plain tables; no view, no trigger anywhere.
void SqliteFile::checkSchema() const {
  const std::string& name = name_;
  Stmt st;
  prepare("SELECT type, name, sql FROM sqlite_master", &st, "the schema (sqlite_master)");
  std::set<std::string> tables;
  int rc;
  while ((rc = sqlite3_step(st.s)) == SQLITE_ROW) {
    const std::string type = columnText(st.s, 0), obj = columnText(st.s, 1),
                      sql = lower(columnText(st.s, 2));
    if (type == "view" || type == "trigger")
      throw Error(fmt::format(
          "{}: the database holds a {} '{}': a rosbag2 file has plain tables only (topics, "
          "messages, and their indexes); views and triggers are refused",
          name, type, obj));
    if (type == "table" && (obj == "topics" || obj == "messages")) {
      if (sql.rfind("create virtual table", 0) == 0)
        throw Error(fmt::format(
            "{}: table '{}' is a virtual table: a rosbag2 file has plain tables only", name, obj));
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
                      name, t, bag_.metadata_file.string()));
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

/// Every topic of this file with its type, serialization, message count and time span.
void SqliteFile::census(Census* out) const {
  // (offered_qos_profiles: a column of table topics since Foxy; older files lack it)
  bool qos = false;
  {
    Stmt cols;
    prepare("SELECT name FROM pragma_table_xinfo('topics')", &cols, "the columns of table topics");
    while (sqlite3_step(cols.s) == SQLITE_ROW)
      qos = qos || columnText(cols.s, 0) == "offered_qos_profiles";
  }
  Stmt st;
  prepare(fmt::format("SELECT t.name, t.type, t.serialization_format, COUNT(m.topic_id), "
                      "MIN(m.timestamp), MAX(m.timestamp), {} FROM topics t LEFT JOIN messages "
                      "m ON m.topic_id = t.id GROUP BY t.id",
                      qos ? "t.offered_qos_profiles" : "''"),
          &st, "tables topics and messages");
  int rc;
  while ((rc = sqlite3_step(st.s)) == SQLITE_ROW) {
    TopicCensus& tc = (*out)[columnText(st.s, 0)];
    tc.publishers = std::max(tc.publishers, qosProfileCount(columnText(st.s, 6)));
    if (tc.type.empty()) tc.type = columnText(st.s, 1);
    if (tc.serialization_format.empty()) tc.serialization_format = columnText(st.s, 2);
    const long long count = sqlite3_column_int64(st.s, 3);
    if (count == 0) continue;
    const std::int64_t first = sqlite3_column_int64(st.s, 4), last = sqlite3_column_int64(st.s, 5);
    if (tc.messages == 0 || first < tc.first_ns) tc.first_ns = first;
    if (tc.messages == 0 || last > tc.last_ns) tc.last_ns = last;
    tc.messages += count;
  }
  if (rc != SQLITE_DONE) throw failure("counting the messages per topic");
}

/// Topics of this file: id -> name, with their types checked against metadata.yaml; one row
/// per id.
std::map<std::int64_t, const std::string*> SqliteFile::topicIds(
    const std::set<std::string>& wanted) const {
  const std::string& name = name_;
  std::map<std::int64_t, const std::string*> ids;
  Stmt st;
  prepare("SELECT id, name, type, serialization_format FROM topics", &st, "table topics");
  std::map<std::int64_t, std::string> seen;
  int rc;
  while ((rc = sqlite3_step(st.s)) == SQLITE_ROW) {
    const std::int64_t id = sqlite3_column_int64(st.s, 0);
    const std::string topic = columnText(st.s, 1), type = columnText(st.s, 2),
                      ser = columnText(st.s, 3);
    if (const auto [at, fresh] = seen.emplace(id, topic); !fresh)
      throw Error(fmt::format(
          "{}: table topics: id {} names topic '{}' and topic '{}': one definition per id", name,
          id, at->second, topic));
    const auto it = wanted.find(topic);
    if (it == wanted.end()) continue;
    const TopicInfo* info = bag_.topic(topic);
    if (info && info->type != type)
      throw Error(fmt::format("{}: topic '{}' has type '{}' in table topics, '{}' in {}", name,
                              topic, type, info->type, bag_.metadata_file.string()));
    if (ser != "cdr")
      throw Error(
          fmt::format("{}: topic '{}': serialization_format '{}', expected cdr", name, topic, ser));
    ids[id] = &*it;
  }
  if (rc != SQLITE_DONE) throw failure("reading table topics");
  return ids;
}

/// The wanted messages' keys in the table's own order (a scan, no sort, no temporary data);
/// in: the wanted topics' ids, a list for SQL.
std::vector<Key> SqliteFile::messageKeys(const std::map<std::int64_t, const std::string*>& ids,
                                         const std::string& in) const {
  const std::string& name = name_;
  std::vector<Key> keys;
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
  return keys;
}

void SqliteFile::deliver(const Key& k, sqlite3_stmt* s, int col,
                         const std::function<void(const RawMessage&)>& fn) const {
  const std::string& name = name_;
  RawMessage m;
  m.topic = k.topic;
  m.receive_ns = k.ts;
  m.data = static_cast<const std::uint8_t*>(sqlite3_column_blob(s, col));
  const int bytes = sqlite3_column_bytes(s, col);
  m.size = bytes > 0 && m.data ? static_cast<std::size_t>(bytes) : 0;
  m.where = fmt::format("{}: messages row id {}", name, k.id);
  fn(m);
}

/// Recorded in time order (the usual case): one more scan, in rowid order.
void SqliteFile::deliverInRowidOrder(const std::vector<Key>& keys, const std::string& in,
                                     const std::function<void(const RawMessage&)>& fn) const {
  const std::string& name = name_;
  Stmt st;
  prepare(
      "SELECT rowid, data FROM messages NOT INDEXED WHERE topic_id IN (" + in + ") ORDER BY rowid",
      &st, "table messages");
  std::size_t i = 0;
  int rc;
  while ((rc = sqlite3_step(st.s)) == SQLITE_ROW) {
    if (i >= keys.size() || sqlite3_column_int64(st.s, 0) != keys[i].rowid)
      throw Error(fmt::format("{}: table messages changed while it was read", name));
    deliver(keys[i++], st.s, 1, fn);
  }
  if (rc != SQLITE_DONE) throw failure("reading table messages");
  if (i != keys.size())
    throw Error(fmt::format("{}: table messages changed while it was read", name));
}

/// Each row by its rowid, in the order of keys.
void SqliteFile::deliverByRowid(const std::vector<Key>& keys,
                                const std::function<void(const RawMessage&)>& fn) const {
  const std::string& name = name_;
  Stmt st;
  prepare("SELECT data FROM messages WHERE rowid = ?", &st, "table messages");
  for (const Key& k : keys) {
    sqlite3_reset(st.s);
    sqlite3_bind_int64(st.s, 1, k.rowid);
    const int rc = sqlite3_step(st.s);
    if (rc == SQLITE_DONE)
      throw Error(fmt::format("{}: table messages changed while it was read", name));
    if (rc != SQLITE_ROW) throw failure("reading table messages");
    deliver(k, st.s, 0, fn);
  }
}

}  // namespace

void readSqliteFile(const BagInfo& bag, const fs::path& file, const std::set<std::string>& wanted,
                    const std::function<void(const RawMessage&)>& fn, Census* census) {
  SqliteFile db(bag, file);
  // One snapshot for every query below.
  db.begin();
  db.checkSchema();
  if (census) db.census(census);
  const std::map<std::int64_t, const std::string*> ids = db.topicIds(wanted);
  if (ids.empty()) return;
  std::string in;
  for (const auto& [id, t] : ids) in += (in.empty() ? "" : ", ") + std::to_string(id);
  // The wanted messages' keys in the table's own order (a scan, no sort, no temporary data),
  // then ordered here by time stamp and id; their data are read one by one in that order.
  std::vector<Key> keys = db.messageKeys(ids, in);
  auto before = [](const Key& a, const Key& b) { return a.ts != b.ts ? a.ts < b.ts : a.id < b.id; };
  const bool in_order = std::is_sorted(keys.begin(), keys.end(), before);
  if (!in_order) std::stable_sort(keys.begin(), keys.end(), before);
  if (in_order)
    db.deliverInRowidOrder(keys, in, fn);
  else
    db.deliverByRowid(keys, fn);
}

}  // namespace exid::rosbag2
