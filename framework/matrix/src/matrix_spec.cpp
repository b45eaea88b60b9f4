// exid — the matrix file (loadMatrix): its keys, the base study, the axes or listed cells, each
// cell's study with its overrides, and the cell's key (the hash its result is found by). The
// cells' supervision is in matrix_run.cpp, the results database in matrix_db.cpp.
#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/io.hpp"
#include "exid/matrix.hpp"
#include "exid/registry.hpp"
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
        c = hashHex(xxh3File(f));
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

}  // namespace exid
