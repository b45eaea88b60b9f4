// exid — rosbag2: the bag folder's metadata.yaml, and the messages of a bag read file by file
// from its storage (bag_sqlite.cpp, bag_mcap.cpp; the CDR messages decoded in bag_cdr.cpp).
// See bag.hpp.
//
// Format, as read here:
// - metadata.yaml: rosbag2_bagfile_information {version, storage_identifier, relative_file_paths,
//   topics_with_message_count: [{topic_metadata: {name, type, serialization_format},
//   message_count}], compression_format, compression_mode}.
#include "bag.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "bag_internal.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"
#include "exid/yaml_strict.hpp"

namespace exid::rosbag2 {

namespace fs = std::filesystem;

namespace {

std::string scalarText(const YAML::Node& n) {
  if (!n) return "(missing)";
  if (n.IsScalar()) return n.Scalar();
  if (n.IsSequence()) return "(a list)";
  if (n.IsMap()) return "(a mapping)";
  return "(null)";
}

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
      // offered_qos_profiles: one entry per publisher (a YAML list, or a string holding one)
      if (const YAML::Node q = md["offered_qos_profiles"]) {
        if (q.IsScalar())
          ti.publishers = qosProfileCount(q.Scalar());
        else if (q.IsSequence())
          ti.publishers = static_cast<int>(q.size());
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

int qosProfileCount(const std::string& yaml) {
  if (yaml.empty()) return -1;
  try {
    const YAML::Node list = YAML::Load(yaml);
    return list.IsSequence() ? static_cast<int>(list.size()) : -1;
  } catch (const YAML::Exception&) {  // (not read: the count stays unknown)
    return -1;
  }
}

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

const TopicInfo* BagInfo::topic(const std::string& name) const {
  for (const TopicInfo& t : topics)
    if (t.name == name) return &t;
  return nullptr;
}

void readMessages(const BagInfo& bag, const std::set<std::string>& wanted,
                  const std::function<void(const RawMessage&)>& fn, Census* census) {
  for (const fs::path& f : bag.files) {
    if (bag.storage == "sqlite3")
      readSqliteFile(bag, f, wanted, fn, census);
    else
      detail::readMcap(bag, f, wanted, fn, census);
  }
}

Census censusOf(const BagInfo& bag) {
  Census c;
  readMessages(
      bag, {}, [](const RawMessage&) {}, &c);
  return c;
}

namespace {
std::string storageOf(const fs::path& p) { return exid::bagStorageOf(p); }

// A bag without metadata.yaml: its storage files, their topics from a census.
BagInfo bareBag(const fs::path& dir, std::vector<fs::path> files, const std::string& storage) {
  BagInfo bag;
  bag.dir = dir;
  bag.metadata_file = files.front();  // (names the storage in messages)
  bag.storage = storage;
  bag.files = std::move(files);
  for (const auto& [name, tc] : censusOf(bag)) {
    TopicInfo t;
    t.name = name;
    t.type = tc.type;
    t.serialization_format = tc.serialization_format;
    t.message_count = tc.messages;
    bag.topics.push_back(t);
  }
  return bag;
}
}  // namespace

bool isBagStorageFile(const fs::path& path) {
  std::error_code ec;
  return fs::is_regular_file(path, ec) && !storageOf(path).empty();
}

BagInfo openBag(const fs::path& path, std::string* how) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    if (fs::exists(path / "metadata.yaml", ec)) {
      *how = "bag folder with metadata.yaml";
      return readMetadata(path);
    }
    std::vector<fs::path> mcap, db3;
    for (const auto& e : fs::directory_iterator(path, ec)) {
      const std::string ext = e.path().extension().string();
      if (ext == ".mcap") mcap.push_back(fs::absolute(e.path()));
      if (ext == ".db3") db3.push_back(fs::absolute(e.path()));
    }
    if (mcap.empty() == db3.empty())
      throw Error(fmt::format(
          "{}: a folder without metadata.yaml holding {} .mcap and {} .db3 files: expected a "
          "rosbag2 bag folder (metadata.yaml and its storage files), or storage files of one "
          "kind",
          path.string(), mcap.size(), db3.size()));
    std::vector<fs::path>& files = mcap.empty() ? db3 : mcap;
    std::sort(files.begin(), files.end());
    const std::string storage = mcap.empty() ? "sqlite3" : "mcap";
    for (const fs::path& f : files)
      if (storageOf(f) != storage)
        throw Error(fmt::format("{}: not a{} file (its first bytes)", f.string(),
                                storage == "mcap" ? "n MCAP" : " SQLite"));
    *how = fmt::format(
        "folder without metadata.yaml: {} {} file(s) in name order, topics from "
        "the storage",
        files.size(), storage);
    return bareBag(path, files, storage);
  }
  if (!fs::exists(path, ec))
    throw Error(
        fmt::format("{}: not found (expected a rosbag2 bag folder, an .mcap file or a "
                    ".db3 file)",
                    path.string()));
  const std::string storage = storageOf(path);
  if (storage.empty())
    throw Error(
        fmt::format("{}: not a rosbag2 bag: expected a bag folder (metadata.yaml and its "
                    "storage files), an .mcap file or a .db3 file",
                    path.string()));
  const fs::path file = fs::absolute(path);
  const fs::path dir = file.parent_path();
  if (fs::exists(dir / "metadata.yaml", ec)) {
    BagInfo bag = readMetadata(dir);
    for (const fs::path& f : bag.files)
      if (fs::equivalent(f, file, ec)) {
        *how = fmt::format("storage file {} of the bag in {} (the whole bag is read: {} file(s))",
                           file.filename().string(), dir.string(), bag.files.size());
        return bag;
      }
  }
  *how = fmt::format("{} file alone, topics from the storage", storage);
  return bareBag(dir, {file}, storage);
}

}  // namespace exid::rosbag2
