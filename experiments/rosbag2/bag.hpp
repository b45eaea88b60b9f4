// exid — reading ROS 2 bags (rosbag2) without a ROS installation: the bag folder's
// metadata.yaml, its storage files (SQLite .db3 or MCAP, MCAP chunks uncompressed, zstd or LZ4
// frame), and the CDR encoding of sensor_msgs/msg/JointState and geometry_msgs/msg/WrenchStamped.
// Every read is bounds-checked: a truncated or corrupt file, record or message is an exid::Error
// naming the file, the record or message and what was expected. Everything decoded is validated:
// each CDR message is consumed exactly, names are unique, an MCAP channel or schema id has one
// definition, decompression is bounded per chunk and per file, a SQLite file is read through its
// plain tables `topics` and `messages` only (views, triggers and virtual tables refused, the work
// bounded), and metadata.yaml is capped in size and refuses duplicate keys (docs/hostile_input.md,
// "rosbag2 bags").
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace exid::rosbag2 {

// ------------------------------------------------------------------------------ limits
/// metadata.yaml: at most this many bytes (as a study file; a bag of 1000 topics writes ~1 MB).
inline constexpr std::uint64_t kMaxMetadataBytes = std::uint64_t{1} << 20;
/// An MCAP storage file is read whole into memory: at most this many bytes (rosbag2 splits a
/// recording into files with --max-bag-size; `ros2 bag convert` keeps only the topics needed).
inline constexpr std::uint64_t kMaxMcapFileBytes = std::uint64_t{4} << 30;
/// One MCAP chunk, uncompressed: at most this many bytes (rosbag2 writes chunks of about 1 MB).
inline constexpr std::uint64_t kMaxChunkBytes = std::uint64_t{256} << 20;
/// Decompression ratio: a chunk's uncompressed size may be at most kMaxChunkRatio times its
/// compressed size plus kChunkAllowanceBytes; all chunks of one file together at most
/// kMaxChunkRatio times the file's size plus kFileAllowanceBytes, and never more than
/// kMaxFileDecompressedBytes. Declared sizes are checked before anything is decompressed, and a
/// stream is never decompressed beyond its declared size.
inline constexpr std::uint64_t kMaxChunkRatio = 64;
inline constexpr std::uint64_t kChunkAllowanceBytes = std::uint64_t{1} << 20;
inline constexpr std::uint64_t kFileAllowanceBytes = std::uint64_t{16} << 20;
inline constexpr std::uint64_t kMaxFileDecompressedBytes = std::uint64_t{16} << 30;
/// SQLite: the work of all statements on one .db3 file, in SQLite's virtual machine steps, is at
/// most kSqliteBaseSteps + kSqliteStepsPerByte times the file's size (a plain rosbag2 file
/// needs a few steps per byte); beyond it the reading is interrupted, an error.
inline constexpr std::uint64_t kSqliteBaseSteps = 20000000;
inline constexpr std::uint64_t kSqliteStepsPerByte = 100;

/// One topic as metadata.yaml lists it.
struct TopicInfo {
  std::string name, type, serialization_format;
  long long message_count = -1;  // -1: not given
  int publishers = -1;           // offered_qos_profiles' entries (one per publisher); -1: not given
};

/// The bag folder's metadata.yaml (rosbag2_bagfile_information).
struct BagInfo {
  std::filesystem::path dir;
  std::filesystem::path metadata_file;
  int version = 0;
  std::string storage;                       // sqlite3 or mcap
  std::vector<std::filesystem::path> files;  // absolute, in the order listed
  std::vector<TopicInfo> topics;
  const TopicInfo* topic(const std::string& name) const;
};

/// Reads and checks dir/metadata.yaml. Throws exid::Error naming the file and the key.
BagInfo readMetadata(const std::filesystem::path& dir);

/// What a bag holds per topic, from its storage: type, serialization, message count and the
/// span of the storage's time stamps (a scan of the records; no message is decoded).
struct TopicCensus {
  std::string type, serialization_format;
  long long messages = 0;
  std::int64_t first_ns = 0, last_ns = 0;
  int publishers = -1;  // the storage's offered_qos_profiles entries; -1: not stored
};
/// The entries of an offered_qos_profiles text (a YAML list, one entry per publisher, as
/// metadata.yaml, an MCAP channel's metadata and a SQLite topics row hold it); -1 when it is
/// empty or not a list.
int qosProfileCount(const std::string& yaml);
using Census = std::map<std::string, TopicCensus>;
Census censusOf(const BagInfo& bag);

/// A bag named by `path`, as a user names it: a bag folder with metadata.yaml; a folder of
/// storage files without it (every *.mcap, or every *.db3, in name order); a storage file itself
/// (the bag of its folder when that folder's metadata.yaml lists it, else the file alone: an
/// MCAP or SQLite file recognised by its first bytes). Without metadata.yaml the topics come from
/// the storage (censusOf). *how says which it was, for the dataset's meta.
BagInfo openBag(const std::filesystem::path& path, std::string* how);
/// Whether a path is a storage file of a bag by its first bytes (MCAP magic, SQLite header).
bool isBagStorageFile(const std::filesystem::path& path);

/// One serialized message of a wanted topic.
struct RawMessage {
  const std::string* topic = nullptr;
  std::int64_t receive_ns = 0;  // the storage's time stamp (rosbag2: receive time)
  const std::uint8_t* data = nullptr;
  std::size_t size = 0;
  std::string where;  // its place in the storage, for messages ("bag_0.db3: messages row 17")
};

/// Calls fn for every message of the topics in `wanted`, file by file in the order listed, in the
/// order of each file (SQLite: by time stamp then row id; MCAP: the order of the records).
/// Checks that each wanted topic's type in the storage matches metadata.yaml.
void readMessages(const BagInfo& bag, const std::set<std::string>& wanted,
                  const std::function<void(const RawMessage&)>& fn, Census* census = nullptr);

/// The SQLite part of readMessages (one .db3 file); exposed for the tests and fuzzers.
void readSqliteFile(const BagInfo& bag, const std::filesystem::path& file,
                    const std::set<std::string>& wanted,
                    const std::function<void(const RawMessage&)>& fn, Census* census = nullptr);

/// The MCAP part of readMessages on a file already in memory (`file` names it in messages);
/// exposed for the tests and fuzzers.
/// census: when set, every topic's census of the file is added to it.
void readMcapBytes(const BagInfo& bag, const std::string& file, const std::uint8_t* data,
                   std::size_t size, const std::set<std::string>& wanted,
                   const std::function<void(const RawMessage&)>& fn, Census* census = nullptr);

/// Decompression of one MCAP chunk ("" / "zstd" / "lz4"); exposed for the tests and fuzzers.
/// uncompressed_size is checked against kMaxChunkBytes and the ratio cap before anything is
/// decompressed; the output never exceeds it.
std::vector<std::uint8_t> decompressChunk(const std::string& compression, const std::uint8_t* src,
                                          std::size_t size, std::uint64_t uncompressed_size,
                                          const std::string& where);
/// CRC-32 (ISO-HDLC, as zlib and MCAP use it).
std::uint32_t crc32(const std::uint8_t* data, std::size_t size, std::uint32_t crc = 0);

// ------------------------------------------------------------------------------ CDR messages
struct Stamp {
  std::int32_t sec = 0;
  std::uint32_t nanosec = 0;
  std::int64_t ns() const { return static_cast<std::int64_t>(sec) * 1000000000LL + nanosec; }
};

struct JointStateMsg {
  Stamp stamp;
  std::string frame_id;
  std::vector<std::string> name;
  std::vector<double> position, velocity, effort;
};

struct WrenchStampedMsg {
  Stamp stamp;
  std::string frame_id;
  double force[3] = {0, 0, 0}, torque[3] = {0, 0, 0};
};

/// sensor_msgs/msg/Imu: what exid reads of it (the orientation and the covariances are decoded
/// and checked for their length, not kept).
struct ImuMsg {
  Stamp stamp;
  std::string frame_id;
  double angular_velocity[3] = {0, 0, 0}, linear_acceleration[3] = {0, 0, 0};
};

/// CDR (XCDR1, little or big endian, 4-byte encapsulation header) decoding. Throw exid::Error
/// with `where` and the byte offset and field that did not fit; bytes left after the message
/// (beyond at most 3 zero bytes of padding) are an error, so is a JointState naming a joint twice
/// and a string with a NUL byte inside or without its terminating NUL.
JointStateMsg decodeJointState(const std::uint8_t* data, std::size_t size,
                               const std::string& where);
WrenchStampedMsg decodeWrenchStamped(const std::uint8_t* data, std::size_t size,
                                     const std::string& where);
ImuMsg decodeImu(const std::uint8_t* data, std::size_t size, const std::string& where);

}  // namespace exid::rosbag2
