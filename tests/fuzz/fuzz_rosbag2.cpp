// Fuzz target: the rosbag2 experiment's readers (experiments/rosbag2/bag.hpp). The first byte picks
// the reader, the rest is its input:
//   0: an MCAP file (every message of /joint_states decoded as JointState, of /ft as
//      WrenchStamped), 1: a CDR JointState, 2: a CDR WrenchStamped, 3 / 4: a zstd / LZ4 chunk
//      whose uncompressed size is the input's next 4 bytes.
// Every input must end in a result or an exid::Error: never a crash, a sanitizer report, a read
// past a buffer or an allocation the input does not justify.
#include <cstdint>
#include <string>

#include "bag.hpp"
#include "exid/error.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const std::uint8_t mode = data[0] % 5;
  const std::uint8_t* p = data + 1;
  const std::size_t n = size - 1;
  namespace rb = exid::rosbag2;
  try {
    if (mode == 0) {
      rb::BagInfo bag;
      bag.storage = "mcap";
      bag.topics = {{"/joint_states", "sensor_msgs/msg/JointState", "cdr", -1},
                    {"/ft", "geometry_msgs/msg/WrenchStamped", "cdr", -1}};
      rb::readMcapBytes(bag, "fuzz.mcap", p, n, {"/joint_states", "/ft"},
                        [](const rb::RawMessage& m) {
                          try {
                            if (*m.topic == "/ft")
                              rb::decodeWrenchStamped(m.data, m.size, m.where);
                            else
                              rb::decodeJointState(m.data, m.size, m.where);
                          } catch (const exid::Error&) {
                          }
                        });
    } else if (mode == 1) {
      rb::decodeJointState(p, n, "fuzz");
    } else if (mode == 2) {
      rb::decodeWrenchStamped(p, n, "fuzz");
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
