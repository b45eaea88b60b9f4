#include "exid/matrix.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <poll.h>
#include <signal.h>
#include <sqlite3.h>
#include <sys/file.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <fstream>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <system_error>

#include "exid/context.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/io.hpp"
#include "exid/registry.hpp"
#include "exid/runner.hpp"
#include "exid/yaml_strict.hpp"

namespace exid {

namespace fs = std::filesystem;

// ------------------------------------------------------------------ parsing

namespace {

std::string flowText(const YAML::Node& n) {
  YAML::Emitter e;
  e << YAML::Flow << n;
  return e.c_str();
}

std::string valueLabel(const YAML::Node& n) {
  if (n.IsScalar()) return n.Scalar();
  if (n.IsMap() && n["type"] && n["type"].IsScalar()) {
    if (n["params"] && n["params"].IsMap() && n["params"].size() > 0)
      return n["type"].Scalar() + flowText(n["params"]);
    return n["type"].Scalar();
  }
  return flowText(n);
}

void setPath(YAML::Node root, const std::string& path, const YAML::Node& value) {
  std::vector<std::string> keys;
  std::stringstream ss(path);
  std::string k;
  while (std::getline(ss, k, '.')) keys.push_back(k);
  if (keys.empty()) throw Error("empty axis name");
  YAML::Node cur = root;
  for (std::size_t i = 0; i + 1 < keys.size(); ++i) {
    if (!cur[keys[i]] || cur[keys[i]].IsNull()) cur[keys[i]] = YAML::Node(YAML::NodeType::Map);
    YAML::Node next = cur[keys[i]];
    if (!next.IsMap())
      throw Error(fmt::format("'{}': '{}' is not a mapping in the base study", path, keys[i]));
    cur.reset(next);
  }
  cur[keys.back()] = YAML::Clone(value);
}

std::string isoNow() {
  std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return buf;
}

MatrixSpec loadMatrixUnchecked(const fs::path& file, const Registry& reg);

// Cells of one matrix at most: the product of the axes is checked before any cell is built.
constexpr double kMaxMatrixCells = 100000;

// Parses a YAML file read with the input-file checks; duplicate keys are errors.
YAML::Node loadStrictYaml(const fs::path& file, const std::string& what) {
  const std::string text = readInputFile(file, what, kMaxStudyFileBytes);
  checkYamlAliases(text, file.string());  // before any node is built
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw Error(fmt::format("{}:{}: malformed YAML: {}", file.string(), e.mark.line + 1, e.msg));
  }
  std::vector<std::string> dups;
  duplicateKeys(root, file.string(), "", &dups);
  if (!dups.empty()) {
    std::string msg = fmt::format("{}: {} problem{} in the {} file:", file.string(), dups.size(),
                                  dups.size() == 1 ? "" : "s", what);
    for (std::size_t i = 0; i < dups.size() && i < 20; ++i) msg += "\n  " + dups[i];
    throw Error(msg);
  }
  return root;
}

std::string keyText(const YAML::Node& key, const fs::path& file) {
  if (!key.IsScalar())
    throw Error(
        fmt::format("{}:{}: a key must be a plain name", file.string(), key.Mark().line + 1));
  return key.Scalar();
}

// The cell's key: configuration hash, exid version, and the contents of every file it reads.
// `contents` caches the hash of each file's contents (cells of a matrix share their files).
std::string cellKey(const StudyConfig& cfg, const std::string& config_hash, const Registry& reg,
                    std::map<std::string, std::string>* contents) {
  std::uint64_t h = fnv1a64(config_hash);
  h = fnv1a64(std::string("\nexid ") + EXID_VERSION_STRING, h);
  for (const auto& f : studyInputFiles(cfg, reg)) {
    h = fnv1a64("\n" + f.string() + "\n", h);
    auto it = contents->find(f.string());
    if (it == contents->end()) {
      std::string c;
      try {
        c = hashHex(fnv1a64File(f));
      } catch (const Error&) {
        // unreadable (the cell will fail and say why), or a folder (a bag: what the cell read
        // in it is in its manifest, checked before the cell is skipped: cellsToRun)
        c = "(not a readable file)";
      }
      it = contents->emplace(f.string(), c).first;
    }
    h = fnv1a64(it->second, h);
  }
  return hashHex(h);
}

}  // namespace

MatrixSpec loadMatrix(const fs::path& file, const Registry& reg) {
  try {
    return loadMatrixUnchecked(file, reg);
  } catch (const YAML::Exception& e) {  // a conversion not checked: still the input's fault
    throw Error(e.mark.line >= 0 ? fmt::format("{}:{}: {}", file.string(), e.mark.line + 1, e.msg)
                                 : fmt::format("{}: {}", file.string(), e.msg));
  }
}

namespace {

// The keys a matrix file may hold; any other is an error naming the closest.
void checkMatrixKeys(const YAML::Node& root, const fs::path& file) {
  const std::vector<std::string> allowed = {
      "name", "base", "study", "axes", "cells", "cell_budget_s", "cell_memory_mb", "description"};
  for (const auto& kv : root) {
    const std::string key = keyText(kv.first, file);
    if (std::find(allowed.begin(), allowed.end(), key) == allowed.end()) {
      std::string close = closestMatch(key, allowed);
      throw Error(fmt::format("{}:{}: unknown key '{}'; allowed: {}{}", file.string(),
                              kv.first.Mark().line + 1, key, fmt::join(allowed, ", "),
                              close.empty() ? "" : "; did you mean '" + close + "'?"));
    }
  }
}

// The smallest cell_memory_mb accepted (besides 0, none): below it a cell cannot start the
// threads of a run (each reserves an 8 MB stack), and failed with "Resource temporarily
// unavailable", naming nothing.
constexpr double kMinCellMemoryMb = 32;

// root[key]: a number in [0, max]; 0 means none (also when absent).
double matrixLimit(const YAML::Node& root, const fs::path& file, const char* key, double max,
                   const char* unit) {
  YAML::Node v = root[key];
  if (!v) return 0.0;
  double x = NAN;
  if (v.IsScalar()) {
    try {
      std::size_t pos = 0;
      x = std::stod(v.Scalar(), &pos);
      if (pos != v.Scalar().size()) x = NAN;
    } catch (...) {
      x = NAN;
    }
  }
  if (!(x >= 0 && x <= max))
    throw Error(fmt::format("{}:{}: {} = {}: must be a number in [0, {:g}] {} (0: none)",
                            file.string(), v.Mark().line + 1, key,
                            v.IsScalar() ? v.Scalar() : std::string("(not a number)"), max, unit));
  return x;
}

// The study every cell starts from: a file (base) or inline (study).
struct BaseStudy {
  YAML::Node study;
  fs::path dir;      // relative paths in the study: from here
  std::string name;  // for messages
};

BaseStudy loadBaseStudy(const YAML::Node& root, const fs::path& file, const fs::path& abs_file) {
  BaseStudy b;
  b.dir = abs_file.parent_path();
  if (root["base"] && root["study"])
    throw Error(
        fmt::format("{}: give either base (a file) or study (inline), not both", file.string()));
  if (root["base"]) {
    fs::path bp = root["base"].as<std::string>();
    if (bp.is_relative()) bp = b.dir / bp;
    try {
      b.study = loadStrictYaml(bp, "base study");
    } catch (const Error& e) {
      throw Error(fmt::format("{}: base study: {}", file.string(), e.what()));
    }
    b.dir = fs::absolute(bp).parent_path();
    b.name = bp.string();
  } else if (root["study"]) {
    b.study = YAML::Clone(root["study"]);
    b.name = file.string() + ":study";
  } else {
    throw Error(fmt::format("{}: missing 'base' (a study file) or 'study' (an inline study)",
                            file.string()));
  }
  if (!b.study.IsMap()) throw Error(fmt::format("{}: the base study is not a mapping", b.name));
  return b;
}

// The cells of `axes`: every combination of the axes' values, one map {axis: value} each.
std::vector<YAML::Node> axesOverrides(const YAML::Node& axes, const fs::path& file,
                                      std::vector<std::string>* axis_names) {
  if (!axes.IsMap() || axes.size() == 0)
    throw Error(fmt::format("{}: axes: expected a mapping axis -> list of values", file.string()));
  double product = 1;
  for (const auto& kv : axes) {
    product *= kv.second.IsSequence() ? static_cast<double>(kv.second.size()) : 1.0;
    if (product > kMaxMatrixCells)
      throw Error(
          fmt::format("{}:{}: axes: the product of the axes has more than {:g} cells "
                      "(at axis '{}'); split the matrix",
                      file.string(), kv.first.Mark().line + 1, kMaxMatrixCells,
                      kv.first.IsScalar() ? kv.first.Scalar() : "?"));
  }
  std::vector<YAML::Node> overrides;
  overrides.push_back(YAML::Node(YAML::NodeType::Map));
  for (const auto& kv : axes) {
    const std::string axis = keyText(kv.first, file);
    if (!kv.second.IsSequence() || kv.second.size() == 0)
      throw Error(fmt::format("{}:{}: axes.{}: expected a non-empty list of values", file.string(),
                              kv.second.Mark().line + 1, axis));
    axis_names->push_back(axis);
    std::vector<YAML::Node> next;
    for (const auto& o : overrides)
      for (const auto& v : kv.second) {
        YAML::Node c = YAML::Clone(o);
        c[axis] = YAML::Clone(v);
        next.push_back(c);
      }
    overrides = std::move(next);
  }
  return overrides;
}

// The cells listed in `cells`, one map {axis: value} each.
std::vector<YAML::Node> listedOverrides(const YAML::Node& cells, const fs::path& file,
                                        std::vector<std::string>* axis_names) {
  if (!cells.IsSequence())
    throw Error(fmt::format("{}: cells: expected a list of overrides", file.string()));
  if (static_cast<double>(cells.size()) > kMaxMatrixCells)
    throw Error(fmt::format("{}: cells: {} cells, more than {:g}; split the matrix", file.string(),
                            cells.size(), kMaxMatrixCells));
  std::vector<YAML::Node> overrides;
  for (const auto& c : cells) {
    if (!c.IsMap())
      throw Error(fmt::format("{}:{}: a cell must be a mapping axis -> value", file.string(),
                              c.Mark().line + 1));
    for (const auto& kv : c) {
      const std::string axis = keyText(kv.first, file);
      if (std::find(axis_names->begin(), axis_names->end(), axis) == axis_names->end())
        axis_names->push_back(axis);
    }
    overrides.push_back(YAML::Clone(c));
  }
  return overrides;
}

// One map {axis: value} per cell: from axes, from cells, or the base study alone.
std::vector<YAML::Node> cellOverrides(const YAML::Node& root, const fs::path& file,
                                      std::vector<std::string>* axis_names) {
  if (root["axes"] && root["cells"])
    throw Error(fmt::format("{}: give either axes or cells, not both", file.string()));
  if (root["axes"]) return axesOverrides(root["axes"], file, axis_names);
  if (root["cells"]) return listedOverrides(root["cells"], file, axis_names);
  return {YAML::Node(YAML::NodeType::Map)};  // the base study alone
}

// Applies one cell's overrides to its study and records its coordinates; problems: each
// override that cannot be applied.
void applyOverrides(const YAML::Node& overrides, std::size_t i, YAML::Node study, MatrixCell* cell,
                    std::vector<std::string>* problems) {
  for (const auto& kv : overrides) {
    const std::string axis = kv.first.as<std::string>();
    try {
      if (!axis.empty() && axis[0] == '@') {
        // A composite axis: each value is a mapping of overrides, with an optional label.
        if (!kv.second.IsMap())
          throw Error(fmt::format(
              "axis '{}': each value must be a mapping {{label: ..., path: value, ...}}", axis));
        std::string label;
        for (const auto& o : kv.second) {
          const std::string path = o.first.as<std::string>();
          if (path == "label")
            label = o.second.as<std::string>();
          else
            setPath(study, path, o.second);
        }
        cell->coords.emplace_back(axis.substr(1), label.empty() ? flowText(kv.second) : label);
        continue;
      }
      setPath(study, axis, kv.second);
    } catch (const Error& e) {
      problems->push_back(fmt::format("cell {}: {}", i, e.what()));
    }
    cell->coords.emplace_back(axis, valueLabel(kv.second));
  }
}

MatrixSpec loadMatrixUnchecked(const fs::path& file, const Registry& reg) {
  YAML::Node root = loadStrictYaml(file, "matrix");
  if (!root.IsMap())
    throw Error(
        fmt::format("{}: expected a mapping (name, base or study, axes or cells)", file.string()));
  checkMatrixKeys(root, file);
  MatrixSpec spec;
  spec.file = fs::absolute(file);
  spec.name = root["name"] ? root["name"].as<std::string>() : file.stem().string();
  if (spec.name.empty()) spec.name = file.stem().string();
  if (const std::string why = studyNameProblem(spec.name); !why.empty())
    throw Error(fmt::format("{}{}: name = '{}': {}", file.string(),
                            root["name"] ? ":" + std::to_string(root["name"].Mark().line + 1) : "",
                            spec.name, why));
  spec.cell_budget_s = matrixLimit(root, file, "cell_budget_s", 1e7, "s");
  spec.cell_memory_mb = matrixLimit(root, file, "cell_memory_mb", 1e8, "MB");
  if (spec.cell_memory_mb > 0 && spec.cell_memory_mb < kMinCellMemoryMb)
    throw Error(fmt::format(
        "{}:{}: cell_memory_mb = {}: too small; a cell needs at least {:g} MB beyond what it "
        "inherits (its threads' stacks, the plugins it loads, its data) to run at all (0: none)",
        file.string(), root["cell_memory_mb"].Mark().line + 1, root["cell_memory_mb"].Scalar(),
        kMinCellMemoryMb));
  const BaseStudy base = loadBaseStudy(root, file, spec.file);
  const std::vector<YAML::Node> overrides = cellOverrides(root, file, &spec.axes);

  std::vector<std::string> problems;
  std::set<std::string> hashes;
  std::map<std::string, std::string> file_hashes;
  for (std::size_t i = 0; i < overrides.size(); ++i) {
    MatrixCell cell;
    cell.index = static_cast<int>(i);
    YAML::Node study = YAML::Clone(base.study);
    applyOverrides(overrides[i], i, study, &cell, &problems);
    for (const auto& [a, v] : cell.coords)
      cell.label += (cell.label.empty() ? "" : " ") + a + "=" + v;
    if (cell.label.empty()) cell.label = "base";
    study["name"] = fmt::format("{}_{}", spec.name, i);
    YAML::Emitter e;
    e << study;
    cell.yaml = std::string(e.c_str()) + "\n";
    try {
      cell.config = parseStudy(
          cell.yaml, fmt::format("{} cell {} ({})", file.string(), i, cell.label), base.dir, reg);
      cell.config_hash = cell.config.hash();
      cell.hash = cellKey(cell.config, cell.config_hash, reg, &file_hashes);
      if (!hashes.insert(cell.config_hash).second)
        problems.push_back(
            fmt::format("cell {} ({}): same configuration as an earlier cell", i, cell.label));
    } catch (const Error& err) {
      problems.push_back(err.what());
    }
    spec.cells.push_back(std::move(cell));
  }
  if (!problems.empty()) {
    std::string msg = fmt::format("{}: {} problem{} in the matrix:", file.string(), problems.size(),
                                  problems.size() == 1 ? "" : "s");
    for (const auto& p : problems) msg += "\n  " + p;
    throw Error(msg);
  }
  return spec;
}

}  // namespace

// ------------------------------------------------------------------ database

namespace {

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

void flatten(const Json& j, const std::string& prefix,
             std::vector<std::pair<std::string, const Json*>>& out) {
  if (j.isObject()) {
    for (const auto& [k, v] : j.items()) flatten(v, prefix.empty() ? k : prefix + "." + k, out);
  } else if (!j.isArray()) {
    out.emplace_back(prefix, &j);
  }
}

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
    {
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
    db.exec("COMMIT");
  } catch (const std::exception& e) {
    // The cause (e.g. "database or disk is full") is what matters; a failed ROLLBACK (SQLite
    // may have rolled back itself) must not replace it. The cell is not recorded: it runs again
    // on resume.
    sqlite3_exec(db.raw(), "ROLLBACK", nullptr, nullptr, nullptr);
    throw Error(fmt::format("recording cell {} ({}): {}", cell.index, cell.label, e.what()));
  }
}

/// The output folder belongs to one writer: an exclusive flock on DIR/.lock (released by the
/// kernel when the process ends), holding "pid host" for the message of a second writer.
class FolderLock {
 public:
  FolderLock(const fs::path& dir, const std::string& name) {
    const fs::path file = dir / name;
    fd_ = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0)
      throw Error(
          fmt::format("{}: cannot create the lock file: {}", file.string(), std::strerror(errno)));
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      char buf[256] = {0};
      const ssize_t n = ::pread(fd_, buf, sizeof buf - 1, 0);
      std::string who = n > 0 ? std::string(buf, static_cast<std::size_t>(n)) : "unknown";
      while (!who.empty() && (who.back() == '\n' || who.back() == ' ')) who.pop_back();
      ::close(fd_);
      throw Error(fmt::format(
          "{}: the matrix folder is in use by another exid (pid {}); wait for it to finish or "
          "use another --out",
          dir.string(), who));
    }
    char host[256] = {0};
    ::gethostname(host, sizeof host - 1);
    const std::string me = fmt::format("{} on host {}\n", ::getpid(), host);
    if (::ftruncate(fd_, 0) == 0) {
      const ssize_t w = ::pwrite(fd_, me.data(), me.size(), 0);
      (void)w;
    }
  }
  ~FolderLock() {
    if (fd_ >= 0) ::close(fd_);
  }
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;

 private:
  int fd_ = -1;
};

struct Child {
  pid_t pid = -1;
  int fd = -1;
  const MatrixCell* cell = nullptr;
  std::string output;
  std::chrono::steady_clock::time_point start;
  std::string started;
  bool killed_for_time = false;
};

// A cell gets this long past its budget to stop by itself before it is killed.
constexpr double kCellGraceS = 5.0;

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

// Why a finished cell's inputs are no longer what it read: the first entry of its input
// manifest (summary.json `inputs`, as the cell's run recorded it) whose file is gone or whose
// size or content hash differs now; "" when every entry still holds. `now` caches the hashes
// (cells share their files).
std::string changedInput(const std::string& inputs_json, std::map<std::string, std::string>* now) {
  if (inputs_json.empty()) return "";
  Json inputs;
  try {
    inputs = Json::parse(inputs_json);
  } catch (const std::exception&) {
    return "its input manifest cannot be read";
  }
  if (!inputs.isArray()) return "its input manifest cannot be read";
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    const Json& e = inputs.at(i);
    const Json* path = e.find("path");
    const Json* hash = e.find("fnv1a64");
    const Json* size = e.find("size_bytes");
    if (!path || !hash || !size) return "its input manifest cannot be read";
    const std::string& p = path->asString();
    auto it = now->find(p);
    if (it == now->end()) {
      std::string h;
      try {
        h = hashHex(fnv1a64File(p));
      } catch (const Error&) {
        h = "(not a readable file)";
      }
      it = now->emplace(p, h).first;
    }
    if (it->second != hash->asString())
      return fmt::format("{} changed since the cell ran ({}: content hash {} then, {} now)", p,
                         e.find("kind") ? e.find("kind")->asString() : "input", hash->asString(),
                         it->second);
  }
  return "";
}

// The cells of this shard not finished yet (sum: total and skipped counted). A finished cell
// whose inputs changed since it ran (a file of its manifest: inside a bag folder, a mesh, a
// data file) runs again.
std::vector<const MatrixCell*> cellsToRun(Db& db, const MatrixSpec& spec, const MatrixOptions& opt,
                                          MatrixRunSummary* sum) {
  struct Done {
    std::string status, inputs;
  };
  std::map<std::string, Done> done;  // hash -> status and input manifest
  {
    Db::Stmt s(&db,
               "SELECT hash, status, CASE WHEN json_valid(summary) THEN "
               "json_extract(summary, '$.inputs') END FROM runs");
    while (s.step()) done[s.text(0)] = Done{s.text(1), s.text(2)};
  }
  std::map<std::string, std::string> hashes_now;
  std::vector<const MatrixCell*> todo;
  for (const auto& c : spec.cells) {
    if (c.index % opt.shard_count != opt.shard_index) continue;
    ++sum->total;
    auto it = done.find(c.hash);
    // "incomplete": stopped by the machine (disk full), never a result: always run again.
    if (!opt.force && it != done.end() && it->second.status != "incomplete" &&
        (it->second.status == "ok" || !opt.retry_failed)) {
      const std::string changed = changedInput(it->second.inputs, &hashes_now);
      if (changed.empty()) {
        ++sum->skipped;
        continue;
      }
      logInfo(fmt::format("cell {} ({}): finished before, but {}: run again", c.index, c.label,
                          changed));
    }
    todo.push_back(&c);
  }
  return todo;
}

// The cell's status, message and summary from how its process ended and what it wrote.
void cellOutcome(const MatrixSpec& spec, const Child& ch, int status, double wall, std::string* st,
                 std::string* msg, Json* summary) {
  if (ch.killed_for_time) {
    *st = "timeout";
    *msg = fmt::format("over the cell budget of {} s (killed after {:.1f} s)", spec.cell_budget_s,
                       wall);
  } else if (WIFSIGNALED(status)) {
    *st = "failed";
    *msg = fmt::format("the cell's process died with signal {} ({})", WTERMSIG(status),
                       strsignal(WTERMSIG(status)));
  } else {
    try {
      *summary = Json::parse(ch.output);
      *st = summary->find("status") ? summary->find("status")->asString() : "failed";
      *msg = summary->find("message") ? summary->find("message")->asString() : "";
      const Json* to = summary->find("timed_out");
      if (*st != "ok" && to && to->asBool()) *st = "timeout";
      const Json* full = summary->find("out_of_space");
      if (*st != "ok" && full && full->asBool()) {
        *st = "incomplete";  // run again on resume
        *msg = "no space left on device (or over the file size limit): " + *msg;
      }
      const Json* oom = summary->find("out_of_memory");
      if (*st != "ok" && oom && oom->asBool() && spec.cell_memory_mb > 0)
        *msg += fmt::format(
            " (over the cell memory cap cell_memory_mb = {} MB: too small for this cell; raise "
            "it or make the cell smaller)",
            spec.cell_memory_mb);
    } catch (const std::exception& e) {
      *st = "failed";
      *msg = fmt::format("the cell's process gave no summary (exit {}): {}",
                         WIFEXITED(status) ? WEXITSTATUS(status) : -1, e.what());
    }
  }
}

// A cell's process has ended: its outcome recorded, counted and logged.
void finishCell(Db& db, const MatrixSpec& spec, Child& ch, int status, MatrixRunSummary* sum) {
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - ch.start).count();
  std::string st, msg;
  Json summary = Json::object();
  cellOutcome(spec, ch, status, wall, &st, &msg, &summary);
  recordRun(db, spec, *ch.cell, st, msg, wall, ch.started, summary);
  if (st == "incomplete") ++sum->incomplete;
  if (st == "ok")
    ++sum->ok;
  else if (st == "timeout")
    ++sum->timeout;
  else
    ++sum->failed;
  logInfo(fmt::format("cell {:>3} {:<8} {:6.2f} s  {}{}", ch.cell->index, st, wall, ch.cell->label,
                      st == "ok" ? "" : "  (" + msg + ")"));
}

// A std::system_error saying that memory (or a thread's stack) could not be had.
bool outOfMemory(const std::exception& e) {
  const auto* se = dynamic_cast<const std::system_error*>(&e);
  return se && (se->code() == std::errc::resource_unavailable_try_again ||
                se->code() == std::errc::not_enough_memory);
}

// In the cell's process: caps what the cell adds to the address space it inherits (the
// program, its libraries and plugins are already mapped when it is forked).
void capCellMemory(double cell_memory_mb) {
  double inherited = 0;
  if (std::FILE* f = std::fopen("/proc/self/statm", "r")) {
    unsigned long pages = 0;
    if (std::fscanf(f, "%lu", &pages) == 1)
      inherited = static_cast<double>(pages) * static_cast<double>(::sysconf(_SC_PAGESIZE));
    std::fclose(f);
  }
  const rlim_t bytes = static_cast<rlim_t>(inherited + cell_memory_mb * 1048576.0);
  struct rlimit rl {
    bytes, bytes
  };
  ::setrlimit(RLIMIT_AS, &rl);
}

// The forked cell's process: runs the cell's study and writes its summary (or the failure) to
// fds[1]; never returns.
[[noreturn]] void runCellProcess(const MatrixSpec& spec, const Registry& reg,
                                 const MatrixOptions& opt, const MatrixCell* cell, int fds[2],
                                 pid_t parent) {
  ::close(fds[0]);
  // The cell dies with its parent (no orphans when the parent is killed, even by SIGKILL);
  // the parent may have died before the request took effect.
  ::prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (::getppid() != parent) ::_exit(1);
  if (spec.cell_memory_mb > 0) capCellMemory(spec.cell_memory_mb);
  ::signal(SIGINT, SIG_IGN);  // the parent decides
  ::signal(SIGTERM, SIG_DFL);
  setLogLevel(LogLevel::Quiet);
  std::string text;
  try {
    StudyConfig cfg = cell->config;
    cfg.budget_s = spec.cell_budget_s;
    cfg.report.plots = false;  // a cell's plots would dominate the matrix's overhead
    RunOptions ro;
    if (opt.write_cell_files) ro.out_dir = opt.out_dir / "cells" / cell->hash;
    ro.clean_stale = false;  // done once for all cells (a scan of cells/ per cell is O(n^2))
    StudyResult r = runStudy(cfg, reg, ro);
    text = r.summary.dump(-1);
  } catch (const std::exception& e) {
    Json j = Json::object();
    j["status"] = "failed";
    j["message"] = e.what();
    // (a thread or a mapping the cap refused: std::system_error, EAGAIN or ENOMEM)
    if (dynamic_cast<const std::bad_alloc*>(&e) || outOfMemory(e)) j["out_of_memory"] = true;
    text = j.dump(-1);
  }
  std::size_t off = 0;
  while (off < text.size()) {
    ssize_t n = ::write(fds[1], text.data() + off, text.size() - off);
    if (n <= 0) break;
    off += static_cast<std::size_t>(n);
  }
  ::_exit(0);
}

// Forks the cell's process; the parent reads its summary from the returned child's fd.
Child startCell(const MatrixSpec& spec, const Registry& reg, const MatrixOptions& opt,
                const MatrixCell* cell) {
  int fds[2];
  if (::pipe(fds) != 0) throw Error("matrix: cannot create a pipe");
  Child ch;
  ch.cell = cell;
  ch.start = std::chrono::steady_clock::now();
  ch.started = isoNow();
  std::fflush(nullptr);
  const pid_t parent = ::getpid();
  pid_t pid = ::fork();
  if (pid < 0) throw Error("matrix: fork failed");
  if (pid == 0) runCellProcess(spec, reg, opt, cell, fds, parent);
  ::close(fds[1]);
  ::fcntl(fds[0], F_SETFL, O_NONBLOCK);
  ch.pid = pid;
  ch.fd = fds[0];
  return ch;
}

// Appends what the cell's pipe holds now to its output (the pipe does not block).
void readCellOutput(Child& ch) {
  char buf[65536];
  while (true) {
    ssize_t n = ::read(ch.fd, buf, sizeof buf);
    if (n > 0)
      ch.output.append(buf, static_cast<std::size_t>(n));
    else
      break;
  }
}

// Interrupted: the running cells are stopped and waited for, the rest counted as not run.
void stopRunningCells(const MatrixSpec& spec, std::size_t not_started, std::vector<Child>* running,
                      MatrixRunSummary* sum) {
  for (auto& ch : *running) ::kill(ch.pid, SIGTERM);
  for (auto& ch : *running) {
    ::waitpid(ch.pid, nullptr, 0);
    ::close(ch.fd);
  }
  sum->not_run = static_cast<int>(not_started + running->size());
  running->clear();
  logWarn(fmt::format("matrix '{}': interrupted; {} cells not run (finished cells are saved)",
                      spec.name, sum->not_run));
}

// One round over the running cells: their output read, those over budget killed, those ended
// recorded and removed. A cell that cannot be recorded stops every other one, then throws.
void serviceRunningCells(Db& db, const MatrixSpec& spec, std::vector<Child>* running,
                         MatrixRunSummary* sum) {
  for (std::size_t i = 0; i < running->size();) {
    Child& ch = (*running)[i];
    readCellOutput(ch);
    const double age =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - ch.start).count();
    if (spec.cell_budget_s > 0 && !ch.killed_for_time && age > spec.cell_budget_s + kCellGraceS) {
      ch.killed_for_time = true;
      ::kill(ch.pid, SIGKILL);
    }
    int status = 0;
    pid_t w = ::waitpid(ch.pid, &status, WNOHANG);
    if (w == ch.pid) {
      readCellOutput(ch);
      ::close(ch.fd);
      try {
        finishCell(db, spec, ch, status, sum);
      } catch (...) {  // e.g. the database cannot be written: stop, leave no cell running
        for (auto& other : *running)
          if (other.pid != ch.pid) {
            ::kill(other.pid, SIGKILL);
            ::waitpid(other.pid, nullptr, 0);
            ::close(other.fd);
          }
        throw;
      }
      running->erase(running->begin() + static_cast<std::ptrdiff_t>(i));
      continue;
    }
    ++i;
  }
}

}  // namespace

MatrixRunSummary runMatrix(const MatrixSpec& spec, const Registry& reg, const MatrixOptions& opt) {
  const auto t0 = std::chrono::steady_clock::now();
  check(opt.shard_count >= 1 && opt.shard_index >= 0 && opt.shard_index < opt.shard_count,
        fmt::format("--shard {}/{}: expected 0 <= i < N", opt.shard_index, opt.shard_count));
  check(opt.jobs >= 1 && opt.jobs <= 1024,
        fmt::format("-j {}: expected 1 to 1024 cells at a time", opt.jobs));
  fs::create_directories(opt.out_dir);
  // Before anything in the folder is touched. MPI ranks share the folder, one database each:
  // each locks its own.
  FolderLock lock(opt.out_dir,
                  opt.database == "results.sqlite" ? ".lock" : "." + opt.database + ".lock");
  cleanStaleTemporaries(opt.out_dir);
  cleanStaleTemporaries(opt.out_dir / "cells");
  Db db(opt.out_dir / opt.database);
  recordMatrixStart(db, spec);
  MatrixRunSummary sum;
  const std::vector<const MatrixCell*> todo = cellsToRun(db, spec, opt, &sum);
  logInfo(fmt::format(
      "matrix '{}': {} cells in this shard, {} already finished, {} to run on {} job{}", spec.name,
      sum.total, sum.skipped, todo.size(), opt.jobs, opt.jobs == 1 ? "" : "s"));

  std::vector<Child> running;
  std::size_t next = 0;
  while ((next < todo.size() || !running.empty())) {
    const bool stop = opt.cancelled && opt.cancelled();
    while (!stop && next < todo.size() && static_cast<int>(running.size()) < std::max(1, opt.jobs))
      running.push_back(startCell(spec, reg, opt, todo[next++]));
    if (stop) {
      stopRunningCells(spec, todo.size() - next, &running, &sum);
      break;
    }
    std::vector<pollfd> pfds;
    for (auto& ch : running) pfds.push_back({ch.fd, POLLIN, 0});
    ::poll(pfds.data(), pfds.size(), 50);
    serviceRunningCells(db, spec, &running, &sum);
  }
  sum.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return sum;
}

// ------------------------------------------------------------------ tables and merging

std::vector<std::string> matrixMetrics(const fs::path& path) {
  check(fs::exists(path), fmt::format("{}: no such database", path.string()));
  Db db(path);
  std::vector<std::string> out;
  Db::Stmt s(&db, "SELECT DISTINCT name FROM metrics ORDER BY name");
  while (s.step()) out.push_back(s.text(0));
  return out;
}

MatrixTable matrixTable(const fs::path& path, const std::vector<std::string>& rows,
                        const std::vector<std::string>& cols, const std::string& metric) {
  check(fs::exists(path),
        fmt::format("{}: no such database (run exid matrix first)", path.string()));
  Db db(path);
  // Resolve the metric name.
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
