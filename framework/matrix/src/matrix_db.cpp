// exid — the matrix's results database (SQLite; schema in docs/matrix.md): a cell's rows, the
// tables of a metric over the axes, and the merge of the shards' databases.
#include <fmt/format.h>
#include <sqlite3.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <map>
#include <memory>
#include <set>

#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/io.hpp"
#include "exid/matrix.hpp"
#include "exid/registry.hpp"
#include "matrix_internal.hpp"

namespace exid {

namespace fs = std::filesystem;

// ------------------------------------------------------------------ database

namespace matrix_detail {

std::string isoNow() {
  std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return buf;
}

namespace {

void flatten(const Json& j, const std::string& prefix,
             std::vector<std::pair<std::string, const Json*>>& out) {
  if (j.isObject()) {
    for (const auto& [k, v] : j.items()) flatten(v, prefix.empty() ? k : prefix + "." + k, out);
  } else if (!j.isArray()) {
    out.emplace_back(prefix, &j);
  }
}

// The summary's metrics of run `run`: every number, text and truth value of the summary by its
// dotted path, and short aliases of the most used.
void insertMetrics(Db& db, long long run, const Json& summary) {
  std::vector<std::pair<std::string, const Json*>> flat;
  flatten(summary, "", flat);
  Db::Stmt m(&db, "INSERT INTO metrics(run_id, name, type, real, text) VALUES(?,?,?,?,?)");
  for (const auto& [name, v] : flat) {
    m.bind(1, run).bind(2, name);
    if (v->isNumber())
      m.bind(3, std::string(v->type() == Json::Type::Int ? "int" : "real"))
          .bind(4, v->asDouble())
          .bindNull(5);
    else if (v->isString())
      m.bind(3, std::string("text")).bindNull(4).bind(5, v->asString());
    else if (v->type() == Json::Type::Bool)
      m.bind(3, std::string("bool")).bind(4, v->asBool() ? 1.0 : 0.0).bindNull(5);
    else {
      m.reset();
      continue;
    }
    m.step();
    m.reset();
  }
  // Short aliases of the most used metrics.
  auto alias = [&](const char* name, const char* path) {
    for (const auto& [n, v] : flat)
      if (n == path && v->isNumber()) {
        m.bind(1, run)
            .bind(2, std::string(name))
            .bind(3, std::string("real"))
            .bind(4, v->asDouble())
            .bindNull(5)
            .step();
        m.reset();
      }
  };
  alias("param_rel_err", "identification.param_rel_err");
  alias("cond_W", "identification.cond_W");
  alias("residual_rms", "identification.residual_rms");
  alias("validation_rel_err", "validation.relative_error");
  alias("criterion_final", "excitation.criterion_final");
  alias("cond_W_final", "excitation.cond_W_final");
}

// The excitation optimizer's progress of run `run` (the criterion over time), when it has one.
void insertProgress(Db& db, long long run, const Json& summary) {
  if (const Json* x = summary.find("excitation")) {
    const Json* h = x->find("history");
    if (h && h->find("t_s") && h->find("value")) {
      Db::Stmt p(&db, "INSERT INTO progress(run_id, series, t, value) VALUES(?,?,?,?)");
      const Json& ts = *h->find("t_s");
      const Json& vs = *h->find("value");
      for (std::size_t i = 0; i < std::min(ts.size(), vs.size()); ++i) {
        p.bind(1, run)
            .bind(2, std::string("criterion"))
            .bind(3, ts.at(i).asDouble())
            .bind(4, vs.at(i).asDouble())
            .step();
        p.reset();
      }
    }
  }
}

}  // namespace

void recordRun(Db& db, const MatrixSpec& spec, const MatrixCell& cell, const std::string& status,
               const std::string& message, double wall_s, const std::string& started,
               const Json& summary) {
  db.exec("BEGIN IMMEDIATE");
  try {
    Db::Stmt(&db, "INSERT OR REPLACE INTO configs(hash, yaml, json) VALUES(?,?,?)")
        .bind(1, cell.hash)
        .bind(2, cell.config.resolvedYaml())
        .bind(3, cell.config.resolvedJson().dump(-1))
        .step();
    Db::Stmt(&db, "DELETE FROM metrics WHERE run_id IN (SELECT id FROM runs WHERE hash = ?)")
        .bind(1, cell.hash)
        .step();
    Db::Stmt(&db, "DELETE FROM axes WHERE run_id IN (SELECT id FROM runs WHERE hash = ?)")
        .bind(1, cell.hash)
        .step();
    Db::Stmt(&db, "DELETE FROM progress WHERE run_id IN (SELECT id FROM runs WHERE hash = ?)")
        .bind(1, cell.hash)
        .step();
    Db::Stmt(&db, "DELETE FROM runs WHERE hash = ?").bind(1, cell.hash).step();
    Db::Stmt(&db,
             "INSERT INTO runs(matrix, cell, hash, label, status, message, wall_s, started, "
             "finished, summary) "
             "VALUES(?,?,?,?,?,?,?,?,?,?)")
        .bind(1, spec.name)
        .bind(2, static_cast<long long>(cell.index))
        .bind(3, cell.hash)
        .bind(4, cell.label)
        .bind(5, status)
        .bind(6, message)
        .bind(7, wall_s)
        .bind(8, started)
        .bind(9, isoNow())
        .bind(10, summary.dump(-1))
        .step();
    const long long run = db.lastId();
    {
      Db::Stmt ax(&db, "INSERT INTO axes(run_id, axis, value) VALUES(?,?,?)");
      for (const auto& [a, v] : cell.coords) {
        ax.bind(1, run).bind(2, a).bind(3, v).step();
        ax.reset();
      }
    }
    insertMetrics(db, run, summary);
    insertProgress(db, run, summary);
    db.exec("COMMIT");
  } catch (const std::exception& e) {
    // The cause (e.g. "database or disk is full") is what matters; a failed ROLLBACK (SQLite
    // may have rolled back itself) must not replace it. The cell is not recorded: it runs again
    // on resume.
    sqlite3_exec(db.raw(), "ROLLBACK", nullptr, nullptr, nullptr);
    throw Error(fmt::format("recording cell {} ({}): {}", cell.index, cell.label, e.what()));
  }
}

// The matrix's row in the database (one per run of the matrix, resumed or not).
void recordMatrixStart(Db& db, const MatrixSpec& spec) {
  Db::Stmt(&db, "INSERT INTO matrices(name, file, started, exid_version, axes) VALUES(?,?,?,?,?)")
      .bind(1, spec.name)
      .bind(2, spec.file.string())
      .bind(3, isoNow())
      .bind(4, std::string(EXID_VERSION_STRING))
      .bind(5, fmt::format("{}", fmt::join(spec.axes, ",")))
      .step();
}

}  // namespace matrix_detail

using matrix_detail::Db;

// ------------------------------------------------------------------ tables and merging

std::vector<std::string> matrixMetrics(const fs::path& path) {
  check(fs::exists(path), fmt::format("{}: no such database", path.string()));
  Db db(path);
  std::vector<std::string> out;
  Db::Stmt s(&db, "SELECT DISTINCT name FROM metrics ORDER BY name");
  while (s.step()) out.push_back(s.text(0));
  return out;
}

namespace {

// The metric's full name in the database: `metric` itself, or the first name ending in
// `.metric`; an unknown metric is an error naming the closest.
std::string resolveMetricName(Db& db, const std::string& metric) {
  std::vector<std::string> names;
  {
    Db::Stmt s(&db, "SELECT DISTINCT name FROM metrics");
    while (s.step()) names.push_back(s.text(0));
  }
  std::string name;
  for (const auto& n : names)
    if (n == metric) name = n;
  if (name.empty())
    for (const auto& n : names) {
      auto dot = n.rfind('.');
      if (dot != std::string::npos && n.substr(dot + 1) == metric) {
        name = n;
        break;
      }
    }
  if (name.empty()) {
    std::string close = closestMatch(metric, names);
    throw Error(fmt::format("unknown metric '{}'{}; available: {}", metric,
                            close.empty() ? "" : "; did you mean '" + close + "'?",
                            fmt::join(names, ", ")));
  }
  return name;
}

// Every axis in `rows` and `cols` is an axis of the matrix in the database.
void checkTableAxes(Db& db, const std::vector<std::string>& rows,
                    const std::vector<std::string>& cols) {
  std::set<std::string> axes;
  {
    Db::Stmt s(&db, "SELECT DISTINCT axis FROM axes");
    while (s.step()) axes.insert(s.text(0));
  }
  for (const auto& a : rows)
    check(axes.count(a) > 0,
          fmt::format("--rows {}: not an axis of this matrix; axes: {}", a, fmt::join(axes, ", ")));
  for (const auto& a : cols)
    check(axes.count(a) > 0,
          fmt::format("--cols {}: not an axis of this matrix; axes: {}", a, fmt::join(axes, ", ")));
}

}  // namespace

MatrixTable matrixTable(const fs::path& path, const std::vector<std::string>& rows,
                        const std::vector<std::string>& cols, const std::string& metric) {
  check(fs::exists(path),
        fmt::format("{}: no such database (run exid matrix first)", path.string()));
  Db db(path);
  const std::string name = resolveMetricName(db, metric);
  checkTableAxes(db, rows, cols);
  struct Cell {
    double sum = 0;
    int n = 0;
    int bad = 0;
  };
  std::map<std::string, std::map<std::string, Cell>> table;
  std::vector<std::string> row_keys, col_keys;
  Db::Stmt runs(&db, "SELECT id, status FROM runs ORDER BY cell");
  Db::Stmt ax(&db, "SELECT axis, value FROM axes WHERE run_id = ?");
  Db::Stmt mv(&db, "SELECT real FROM metrics WHERE run_id = ? AND name = ?");
  while (runs.step()) {
    const long long id = runs.integer(0);
    const std::string status = runs.text(1);
    std::map<std::string, std::string> coord;
    ax.bind(1, id);
    while (ax.step()) coord[ax.text(0)] = ax.text(1);
    ax.reset();
    auto key = [&](const std::vector<std::string>& keys) {
      std::string k;
      for (const auto& a : keys) k += (k.empty() ? "" : ", ") + coord[a];
      return k.empty() ? std::string("all") : k;
    };
    const std::string rk = key(rows), ck = key(cols);
    if (std::find(row_keys.begin(), row_keys.end(), rk) == row_keys.end()) row_keys.push_back(rk);
    if (std::find(col_keys.begin(), col_keys.end(), ck) == col_keys.end()) col_keys.push_back(ck);
    Cell& c = table[rk][ck];
    double v = NAN;
    mv.bind(1, id).bind(2, name);
    if (mv.step()) v = mv.real(0);
    mv.reset();
    if (status == "ok" && std::isfinite(v)) {
      c.sum += v;
      ++c.n;
    } else {
      ++c.bad;
    }
  }
  MatrixTable out;
  const std::string corner =
      rows.empty() ? std::string("") : fmt::format("{}", fmt::join(rows, ", "));
  out.markdown =
      fmt::format("{} (mean over cells; `n/a`: failed or missing)\n\n| {} \\ {} |", name, corner,
                  cols.empty() ? std::string("") : fmt::format("{}", fmt::join(cols, ", ")));
  out.csv = "\"" + corner + "\"";
  for (const auto& ck : col_keys) {
    out.markdown += " " + ck + " |";
    out.csv += ",\"" + ck + "\"";
  }
  out.markdown += "\n|---|";
  for (std::size_t i = 0; i < col_keys.size(); ++i) out.markdown += "---|";
  out.markdown += "\n";
  out.csv += "\n";
  for (const auto& rk : row_keys) {
    out.markdown += "| " + rk + " |";
    out.csv += "\"" + rk + "\"";
    for (const auto& ck : col_keys) {
      auto it = table[rk].find(ck);
      std::string cell = "";
      std::string csv = "";
      if (it != table[rk].end()) {
        const Cell& c = it->second;
        if (c.n > 0) {
          cell = fmt::format("{:.4g}", c.sum / c.n);
          csv = fmt::format("{}", c.sum / c.n);
          if (c.n > 1) cell += fmt::format(" (n={})", c.n);
          if (c.bad > 0) cell += fmt::format(" [{} failed]", c.bad);
        } else {
          cell = "n/a";
        }
      }
      out.markdown += " " + cell + " |";
      out.csv += "," + csv;
    }
    out.markdown += "\n";
    out.csv += "\n";
  }
  return out;
}

int mergeMatrixDatabases(const fs::path& dest, const std::vector<fs::path>& sources) {
  // Atomic: every source is opened and read before anything is written, and the whole merge
  // is one transaction (a failure part-way leaves dest exactly as it was).
  std::vector<std::unique_ptr<Db>> ins;
  for (const auto& src : sources) {
    checkInputFile(src, "matrix database", std::uintmax_t{1} << 40);
    auto in = std::make_unique<Db>(src);
    Db::Stmt probe(in.get(), "SELECT count(*) FROM runs");
    probe.step();
    ins.push_back(std::move(in));
  }
  if (dest.has_parent_path()) fs::create_directories(dest.parent_path());
  Db db(dest);
  int copied = 0;
  db.exec("BEGIN IMMEDIATE");
  try {
    for (auto& inp : ins) {
      Db& in = *inp;
      Db::Stmt runs(&in,
                    "SELECT id, matrix, cell, hash, label, status, message, wall_s, started, "
                    "finished, summary FROM runs");
      while (runs.step()) {
        const std::string hash = runs.text(3);
        {
          Db::Stmt exists(&db, "SELECT 1 FROM runs WHERE hash = ?");
          exists.bind(1, hash);
          if (exists.step()) continue;
        }
        {
          Db::Stmt(&db,
                   "INSERT INTO runs(matrix, cell, hash, label, status, message, wall_s, started, "
                   "finished, summary) "
                   "VALUES(?,?,?,?,?,?,?,?,?,?)")
              .bind(1, runs.text(1))
              .bind(2, runs.integer(2))
              .bind(3, hash)
              .bind(4, runs.text(4))
              .bind(5, runs.text(5))
              .bind(6, runs.text(6))
              .bind(7, runs.real(7))
              .bind(8, runs.text(8))
              .bind(9, runs.text(9))
              .bind(10, runs.text(10))
              .step();
          const long long id = db.lastId();
          const long long old = runs.integer(0);
          Db::Stmt ax(&in, "SELECT axis, value FROM axes WHERE run_id = ?");
          ax.bind(1, old);
          while (ax.step())
            Db::Stmt(&db, "INSERT INTO axes VALUES(?,?,?)")
                .bind(1, id)
                .bind(2, ax.text(0))
                .bind(3, ax.text(1))
                .step();
          Db::Stmt mt(&in, "SELECT name, type, real, text FROM metrics WHERE run_id = ?");
          mt.bind(1, old);
          while (mt.step()) {
            Db::Stmt insert(&db, "INSERT INTO metrics VALUES(?,?,?,?,?)");
            insert.bind(1, id).bind(2, mt.text(0)).bind(3, mt.text(1));
            if (std::isfinite(mt.real(2)))
              insert.bind(4, mt.real(2));
            else
              insert.bindNull(4);
            insert.bind(5, mt.text(3)).step();
          }
          Db::Stmt pr(&in, "SELECT series, t, value FROM progress WHERE run_id = ?");
          pr.bind(1, old);
          while (pr.step())
            Db::Stmt(&db, "INSERT INTO progress VALUES(?,?,?,?)")
                .bind(1, id)
                .bind(2, pr.text(0))
                .bind(3, pr.real(1))
                .bind(4, pr.real(2))
                .step();
          Db::Stmt cf(&in, "SELECT yaml, json FROM configs WHERE hash = ?");
          cf.bind(1, hash);
          if (cf.step())
            Db::Stmt(&db, "INSERT OR IGNORE INTO configs VALUES(?,?,?)")
                .bind(1, hash)
                .bind(2, cf.text(0))
                .bind(3, cf.text(1))
                .step();
          ++copied;
        }
      }
    }
    db.exec("COMMIT");
  } catch (const std::exception& e) {
    sqlite3_exec(db.raw(), "ROLLBACK", nullptr, nullptr, nullptr);
    throw Error(fmt::format("{}: merge failed, nothing was merged: {}", dest.string(), e.what()));
  }
  return copied;
}

}  // namespace exid
