// exid — rosbag2: CDR decoding of the messages read (sensor_msgs/msg/JointState,
// geometry_msgs/msg/WrenchStamped). See bag.hpp.
//
// - CDR: 4-byte encapsulation header (0x00 0x01: little endian, 0x00 0x00: big endian), then
//   the fields, each aligned to its size relative to the end of that header.
#include <fmt/format.h>

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "bag.hpp"
#include "exid/error.hpp"

namespace exid::rosbag2 {

namespace {

// ------------------------------------------------------------------------------ CDR
class Cdr {
 public:
  Cdr(const std::uint8_t* p, std::size_t n, const std::string& where) : where_(where) {
    if (n < 4)
      throw Error(
          fmt::format("{}: truncated message: {} bytes, expected at least the 4-byte CDR "
                      "encapsulation header",
                      where, n));
    if (p[0] != 0x00 || (p[1] != 0x00 && p[1] != 0x01))
      throw Error(
          fmt::format("{}: CDR encapsulation {:02x} {:02x}: expected 00 01 (CDR little "
                      "endian) or 00 00 (CDR big endian)",
                      where, p[0], p[1]));
    big_ = p[1] == 0x00;
    p_ = p + 4;
    n_ = n - 4;
  }
  void align(std::size_t a, const char* what) {
    const std::size_t to = (pos_ + a - 1) / a * a;
    if (to > n_) fail(to - pos_, what);
    pos_ = to;
  }
  void need(std::size_t k, const char* what) const {
    if (k > n_ - pos_) fail(k, what);
  }
  std::uint64_t raw(std::size_t size, const char* what) {
    align(size, what);
    need(size, what);
    std::uint64_t v = 0;
    for (std::size_t i = 0; i < size; ++i) {
      const std::size_t b = big_ ? i : size - 1 - i;
      v = (v << 8) | p_[pos_ + b];
    }
    pos_ += size;
    return v;
  }
  std::uint32_t u32(const char* what) { return static_cast<std::uint32_t>(raw(4, what)); }
  std::int32_t i32(const char* what) {
    const std::uint32_t u = u32(what);
    std::int32_t v;
    std::memcpy(&v, &u, 4);
    return v;
  }
  double f64(const char* what) {
    const std::uint64_t u = raw(8, what);
    double v;
    std::memcpy(&v, &u, 8);
    return v;
  }
  std::string str(const char* what) {
    const std::uint32_t len = u32(what);
    need(len, what);
    // The length counts the terminating NUL; an empty string may be written with length 0.
    if (len > 0 && p_[pos_ + len - 1] != 0)
      throw Error(
          fmt::format("{}: {}: the string of {} bytes at byte {} of the CDR data does not "
                      "end with its terminating NUL byte (a corrupt message, or not of "
                      "this type)",
                      where_, what, len, pos_ + 4));
    const std::size_t k = len > 0 ? len - 1 : 0;
    const void* nul = std::memchr(p_ + pos_, 0, k);
    if (nul)
      throw Error(fmt::format(
          "{}: {}: a NUL byte inside the string at byte {} of the CDR data (its {} bytes end at "
          "byte {}); a name or frame holds no NUL",
          where_, what, static_cast<const std::uint8_t*>(nul) - p_ + 4, len, pos_ + 4 + len));
    std::string s(reinterpret_cast<const char*>(p_ + pos_), k);
    pos_ += len;
    return s;
  }
  /// The message must end here: at most 3 zero bytes of padding may follow (a serializer may pad
  /// the data to a multiple of 4); anything else is left over, the message is not of `type`.
  void finish(const char* type) const {
    const std::size_t left = n_ - pos_;
    bool padding = left <= 3;
    for (std::size_t i = pos_; padding && i < n_; ++i) padding = p_[i] == 0;
    if (!padding)
      throw Error(fmt::format(
          "{}: {} bytes left after the {} message, which ends at byte {} of the {} bytes of "
          "CDR data: not a {} (a message of another type on this topic, or a corrupt one); a "
          "message must be consumed exactly",
          where_, left, type, pos_ + 4, n_ + 4, type));
  }
  /// Length of a sequence whose elements take at least min_elem bytes each (never more elements
  /// than the bytes left can hold: a corrupt length allocates nothing).
  std::size_t count(std::size_t min_elem, const char* what) {
    const std::uint32_t c = u32(what);
    if (static_cast<std::uint64_t>(c) * min_elem > n_ - pos_)
      throw Error(fmt::format(
          "{}: corrupt or truncated message: {} has {} elements, which need "
          "at least {} bytes at byte {}; {} left",
          where_, what, c, static_cast<std::uint64_t>(c) * min_elem, pos_ + 4, n_ - pos_));
    return c;
  }
  std::vector<double> doubles(const char* what) {
    const std::size_t c = count(8, what);
    std::vector<double> v(c);
    if (c > 0) align(8, what);  // an empty sequence writes no padding (Fast-CDR)
    for (std::size_t i = 0; i < c; ++i) v[i] = f64(what);
    return v;
  }
  Stamp stamp() {
    Stamp s;
    s.sec = i32("header.stamp.sec");
    s.nanosec = u32("header.stamp.nanosec");
    if (s.nanosec >= 1000000000u)
      throw Error(
          fmt::format("{}: header.stamp.nanosec = {}: expected below 1e9", where_, s.nanosec));
    return s;
  }

 private:
  [[noreturn]] void fail(std::size_t k, const char* what) const {
    throw Error(
        fmt::format("{}: truncated message: {} needs {} bytes at byte {} of the CDR data, "
                    "{} left",
                    where_, what, k, pos_ + 4, n_ - pos_));
  }
  const std::uint8_t* p_ = nullptr;
  std::size_t n_ = 0, pos_ = 0;
  bool big_ = false;
  const std::string& where_;
};

}  // namespace

JointStateMsg decodeJointState(const std::uint8_t* data, std::size_t size,
                               const std::string& where) {
  Cdr c(data, size, where);
  JointStateMsg m;
  m.stamp = c.stamp();
  m.frame_id = c.str("header.frame_id");
  const std::size_t nn = c.count(4, "name");
  m.name.reserve(nn);
  for (std::size_t i = 0; i < nn; ++i) m.name.push_back(c.str("name"));
  m.position = c.doubles("position");
  m.velocity = c.doubles("velocity");
  m.effort = c.doubles("effort");
  c.finish("sensor_msgs/msg/JointState");
  // Names unique: a joint named twice has two values, and which one is meant is unknowable.
  if (nn > 1) {
    std::vector<std::size_t> order(nn);
    for (std::size_t i = 0; i < nn; ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return m.name[a] != m.name[b] ? m.name[a] < m.name[b] : a < b;
    });
    for (std::size_t i = 1; i < nn; ++i)
      if (m.name[order[i]] == m.name[order[i - 1]])
        throw Error(fmt::format(
            "{}: name: joint '{}' is named twice (names {} and {} of {}); each joint may "
            "appear once in a JointState message",
            where, m.name[order[i]], order[i - 1] + 1, order[i] + 1, nn));
  }
  return m;
}

WrenchStampedMsg decodeWrenchStamped(const std::uint8_t* data, std::size_t size,
                                     const std::string& where) {
  Cdr c(data, size, where);
  WrenchStampedMsg m;
  m.stamp = c.stamp();
  m.frame_id = c.str("header.frame_id");
  for (double& v : m.force) v = c.f64("wrench.force");
  for (double& v : m.torque) v = c.f64("wrench.torque");
  c.finish("geometry_msgs/msg/WrenchStamped");
  return m;
}

ImuMsg decodeImu(const std::uint8_t* data, std::size_t size, const std::string& where) {
  Cdr c(data, size, where);
  ImuMsg m;
  m.stamp = c.stamp();
  m.frame_id = c.str("header.frame_id");
  for (int i = 0; i < 4; ++i) (void)c.f64("orientation");
  for (int i = 0; i < 9; ++i) (void)c.f64("orientation_covariance");
  for (double& v : m.angular_velocity) v = c.f64("angular_velocity");
  for (int i = 0; i < 9; ++i) (void)c.f64("angular_velocity_covariance");
  for (double& v : m.linear_acceleration) v = c.f64("linear_acceleration");
  for (int i = 0; i < 9; ++i) (void)c.f64("linear_acceleration_covariance");
  c.finish("sensor_msgs/msg/Imu");
  return m;
}

}  // namespace exid::rosbag2
