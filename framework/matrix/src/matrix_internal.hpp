// exid — what the matrix's sources share (private to the matrix layer): the results database
// (Db, its tables; matrix_db.cpp) as the cells' supervision (matrix_run.cpp) writes to it.
#pragma once

#include <fmt/format.h>
#include <sqlite3.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "exid/error.hpp"
#include "exid/json.hpp"
#include "exid/matrix.hpp"

namespace exid::matrix_detail {

namespace fs = std::filesystem;

// The time now, UTC, ISO 8601 (2026-01-31T12:00:00Z).
std::string isoNow();

// One connection to the results database, its tables made when missing (WAL; schema in
// docs/matrix.md); Stmt: one prepared statement.
class Db {
 public:
  explicit Db(const fs::path& path) : path_(path.string()) {
    if (sqlite3_open(path_.c_str(), &db_) != SQLITE_OK) {
      std::string m = db_ ? sqlite3_errmsg(db_) : "out of memory";
      sqlite3_close(db_);
      throw Error(fmt::format("{}: cannot open the database: {}", path_, m));
    }
    // A failure below (a file that is not a database) throws from the constructor, where the
    // destructor does not run: close the connection first (LeakSanitizer found the leak).
    try {
      init();
    } catch (...) {
      sqlite3_close(db_);
      db_ = nullptr;
      throw;
    }
  }
  void init() {
    sqlite3_busy_timeout(db_, 10000);
    exec("PRAGMA journal_mode=WAL");
    exec("PRAGMA synchronous=NORMAL");
    exec(R"(CREATE TABLE IF NOT EXISTS matrices(
              id INTEGER PRIMARY KEY, name TEXT, file TEXT, started TEXT, exid_version TEXT, axes TEXT);
            CREATE TABLE IF NOT EXISTS configs(hash TEXT PRIMARY KEY, yaml TEXT, json TEXT);
            CREATE TABLE IF NOT EXISTS runs(
              id INTEGER PRIMARY KEY, matrix TEXT, cell INTEGER, hash TEXT UNIQUE, label TEXT,
              status TEXT, message TEXT, wall_s REAL, started TEXT, finished TEXT, summary TEXT);
            CREATE TABLE IF NOT EXISTS axes(run_id INTEGER, axis TEXT, value TEXT);
            CREATE TABLE IF NOT EXISTS metrics(run_id INTEGER, name TEXT, type TEXT, real REAL, text TEXT);
            CREATE TABLE IF NOT EXISTS progress(run_id INTEGER, series TEXT, t REAL, value REAL);
            CREATE INDEX IF NOT EXISTS metrics_by_name ON metrics(name);
            CREATE INDEX IF NOT EXISTS axes_by_run ON axes(run_id);)");
  }
  ~Db() { sqlite3_close(db_); }
  Db(const Db&) = delete;
  Db& operator=(const Db&) = delete;

  void exec(const std::string& sql) {
    char* err = nullptr;
    if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
      std::string m = err ? err : "?";
      sqlite3_free(err);
      throw Error(fmt::format("{}: {}", path_, m));
    }
  }

  struct Stmt {
    sqlite3_stmt* s = nullptr;
    Db* db;
    Stmt(Db* d, const std::string& sql) : db(d) {
      if (sqlite3_prepare_v2(d->db_, sql.c_str(), -1, &s, nullptr) != SQLITE_OK)
        throw Error(fmt::format("{}: {}", d->path_, sqlite3_errmsg(d->db_)));
    }
    ~Stmt() { sqlite3_finalize(s); }
    Stmt& bind(int i, const std::string& v) {
      sqlite3_bind_text(s, i, v.c_str(), -1, SQLITE_TRANSIENT);
      return *this;
    }
    Stmt& bind(int i, double v) {
      if (std::isfinite(v))
        sqlite3_bind_double(s, i, v);
      else
        sqlite3_bind_null(s, i);
      return *this;
    }
    Stmt& bind(int i, long long v) {
      sqlite3_bind_int64(s, i, v);
      return *this;
    }
    Stmt& bindNull(int i) {
      sqlite3_bind_null(s, i);
      return *this;
    }
    bool step() {
      int rc = sqlite3_step(s);
      if (rc == SQLITE_ROW) return true;
      if (rc == SQLITE_DONE) return false;
      throw Error(fmt::format("{}: {}", db->path_, sqlite3_errmsg(db->db_)));
    }
    void reset() {
      sqlite3_reset(s);
      sqlite3_clear_bindings(s);
    }
    std::string text(int c) const {
      auto* t = sqlite3_column_text(s, c);
      return t ? reinterpret_cast<const char*>(t) : "";
    }
    double real(int c) const {
      return sqlite3_column_type(s, c) == SQLITE_NULL ? NAN : sqlite3_column_double(s, c);
    }
    long long integer(int c) const { return sqlite3_column_int64(s, c); }
  };

  long long lastId() const { return sqlite3_last_insert_rowid(db_); }
  sqlite3* raw() { return db_; }

 private:
  std::string path_;
  sqlite3* db_ = nullptr;
};

// One finished cell's rows (its run, configuration, axes, metrics and progress), replacing an
// earlier result of the same cell; one transaction.
void recordRun(Db& db, const MatrixSpec& spec, const MatrixCell& cell, const std::string& status,
               const std::string& message, double wall_s, const std::string& started,
               const Json& summary);

// The matrix's row in the database (one per run of the matrix, resumed or not).
void recordMatrixStart(Db& db, const MatrixSpec& spec);

}  // namespace exid::matrix_detail
