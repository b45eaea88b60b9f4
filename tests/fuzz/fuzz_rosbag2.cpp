// Fuzz target: the rosbag2 experiment's readers (experiments/rosbag2/bag.hpp). The first byte picks
// the reader, the rest is its input:
//   0: an MCAP file (every message of /joint_states decoded as JointState, of /ft as
//      WrenchStamped), 1: a CDR JointState, 2: a CDR WrenchStamped, 3 / 4: a zstd / LZ4 chunk
//      whose uncompressed size is the input's next 4 bytes, 5: a SQLite .db3 file (its messages
//      decoded as in 0), 6: a bag's metadata.yaml, 7: a CDR Imu.
// Modes 5 and 6 write the input to a file of this process's own temporary folder (SQLite and the
// metadata reader read files). Every input must end in a result or an exid::Error: never a
// crash, a sanitizer report, a read past a buffer or an allocation the input does not justify.
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "bag.hpp"
#include "exid/error.hpp"

namespace {

namespace fs = std::filesystem;
namespace rb = exid::rosbag2;

/// This process's temporary folder (removed at exit).
const fs::path& scratch() {
  static const struct Dir {
    fs::path p = fs::temp_directory_path() / ("exid_fuzz_rosbag2_" + std::to_string(::getpid()));
    Dir() { fs::create_directories(p); }
    ~Dir() {
      std::error_code ec;
      fs::remove_all(p, ec);
    }
  } dir;
  return dir.p;
}

fs::path writeScratch(const char* name, const std::uint8_t* p, std::size_t n) {
  const fs::path f = scratch() / name;
  std::ofstream(f, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(p), static_cast<std::streamsize>(n));
  return f;
}

rb::BagInfo bagOf(const char* storage) {
  rb::BagInfo bag;
  bag.storage = storage;
  bag.dir = scratch();
  bag.metadata_file = scratch() / "metadata.yaml";
  bag.topics = {{"/joint_states", "sensor_msgs/msg/JointState", "cdr", -1},
                {"/ft", "geometry_msgs/msg/WrenchStamped", "cdr", -1}};
  return bag;
}

void decode(const rb::RawMessage& m) {
  try {
    if (*m.topic == "/ft")
      rb::decodeWrenchStamped(m.data, m.size, m.where);
    else
      rb::decodeJointState(m.data, m.size, m.where);
  } catch (const exid::Error&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const std::uint8_t mode = data[0] % 8;
  const std::uint8_t* p = data + 1;
  const std::size_t n = size - 1;
  try {
    if (mode == 0) {
      rb::readMcapBytes(bagOf("mcap"), "fuzz.mcap", p, n, {"/joint_states", "/ft"}, decode);
    } else if (mode == 1) {
      rb::decodeJointState(p, n, "fuzz");
    } else if (mode == 2) {
      rb::decodeWrenchStamped(p, n, "fuzz");
    } else if (mode == 7) {
      rb::decodeImu(p, n, "fuzz");
    } else if (mode == 5) {
      const fs::path f = writeScratch("fuzz.db3", p, n);
      rb::readSqliteFile(bagOf("sqlite3"), f, {"/joint_states", "/ft"}, decode);
    } else if (mode == 6) {
      writeScratch("metadata.yaml", p, n);
      rb::readMetadata(scratch());
    } else if (n >= 4) {
      const std::uint32_t usize =
          static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
          static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
      rb::decompressChunk(mode == 3 ? "zstd" : "lz4", p + 4, n - 4, usize, "fuzz");
    }
  } catch (const exid::Error&) {
  }
  return 0;
}
