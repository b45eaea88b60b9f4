// exid — reading ROS 2 bags (rosbag2) without a ROS installation: the bag folder's
// metadata.yaml, its storage files (SQLite .db3 or MCAP, MCAP chunks uncompressed, zstd or LZ4
// frame), and the CDR encoding of sensor_msgs/msg/JointState and geometry_msgs/msg/WrenchStamped.
// Every read is bounds-checked: a truncated or corrupt file, record or message is an exid::Error
// naming the file, the record or message and what was expected.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <set>
#include <string>
#include <vector>

namespace exid::rosbag2 {

/// One topic as metadata.yaml lists it.
struct TopicInfo {
  std::string name, type, serialization_format;
  long long message_count = -1;  // -1: not given
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
                  const std::function<void(const RawMessage&)>& fn);

/// The MCAP part of readMessages on a file already in memory (`file` names it in messages);
/// exposed for the tests and fuzzers.
void readMcapBytes(const BagInfo& bag, const std::string& file, const std::uint8_t* data,
                   std::size_t size, const std::set<std::string>& wanted,
                   const std::function<void(const RawMessage&)>& fn);

/// Decompression of one MCAP chunk ("" / "zstd" / "lz4"); exposed for the tests and fuzzers.
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

/// CDR (XCDR1, little or big endian, 4-byte encapsulation header) decoding. Throw exid::Error
/// with `where` and the byte offset and field that did not fit.
JointStateMsg decodeJointState(const std::uint8_t* data, std::size_t size,
                               const std::string& where);
WrenchStampedMsg decodeWrenchStamped(const std::uint8_t* data, std::size_t size,
                                     const std::string& where);

}  // namespace exid::rosbag2
