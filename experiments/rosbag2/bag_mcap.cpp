// exid — rosbag2 storage: MCAP, its chunks (uncompressed, zstd or LZ4 frame) and their CRC-32.
// See bag.hpp.
//
// - MCAP: magic \x89MCAP0\r\n, then records <opcode u8><length u64><content>, little endian;
//   strings are u32 length + bytes; Schema(0x03) {id u16, name, encoding, data u32+bytes},
//   Channel(0x04) {id u16, schema_id u16, topic, message_encoding, metadata}, Message(0x05)
//   {channel_id u16, sequence u32, log_time u64, publish_time u64, data}, Chunk(0x06)
//   {start u64, end u64, uncompressed_size u64, uncompressed_crc u32, compression, records
//   u64+bytes}, DataEnd(0x0F) ends the data section, Footer(0x02) the file; other records are
//   skipped. The data section is read sequentially: no summary section is needed.
#include <fmt/format.h>
#include <lz4frame.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <map>
#include <memory>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include "bag.hpp"
#include "bag_internal.hpp"
#include "exid/error.hpp"
#include "exid/input_file.hpp"

namespace exid::rosbag2 {

namespace fs = std::filesystem;

namespace {

/// A read-only byte range (C++17 has no std::span).
struct Span {
  const std::uint8_t* p;
  std::size_t n;
  std::size_t size() const { return n; }
  const std::uint8_t* data() const { return p; }
  const std::uint8_t* begin() const { return p; }
  std::uint8_t operator[](std::size_t i) const { return p[i]; }
};

constexpr std::array<std::uint8_t, 8> kMcapMagic = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

/// Bounds-checked little-endian reader of a byte range (MCAP records).
class Bytes {
 public:
  Bytes(const std::uint8_t* p, std::size_t n, std::string where)
      : p_(p), n_(n), where_(std::move(where)) {}
  std::size_t pos() const { return pos_; }
  std::size_t left() const { return n_ - pos_; }
  void need(std::size_t k, const char* what) const {
    if (k > left())
      throw Error(fmt::format("{}: truncated: {} needs {} bytes at byte {}, {} left", where_, what,
                              k, pos_, left()));
  }
  std::uint64_t uint(int bytes, const char* what) {
    need(static_cast<std::size_t>(bytes), what);
    std::uint64_t v = 0;
    for (int i = bytes - 1; i >= 0; --i) v = (v << 8) | p_[pos_ + static_cast<std::size_t>(i)];
    pos_ += static_cast<std::size_t>(bytes);
    return v;
  }
  std::uint16_t u16(const char* what) { return static_cast<std::uint16_t>(uint(2, what)); }
  std::uint32_t u32(const char* what) { return static_cast<std::uint32_t>(uint(4, what)); }
  std::uint64_t u64(const char* what) { return uint(8, what); }
  std::string str(const char* what) {
    const std::uint32_t len = u32(what);
    need(len, what);
    std::string s(reinterpret_cast<const char*>(p_ + pos_), len);
    pos_ += len;
    return s;
  }
  /// A u32- or u64-length-prefixed byte range: its start and size.
  std::pair<const std::uint8_t*, std::size_t> block(int len_bytes, const char* what) {
    const std::uint64_t len = uint(len_bytes, what);
    if (len > left())
      throw Error(fmt::format("{}: truncated: {} has length {} at byte {}, {} bytes left", where_,
                              what, len, pos_, left()));
    const std::uint8_t* at = p_ + pos_;
    pos_ += static_cast<std::size_t>(len);
    return {at, static_cast<std::size_t>(len)};
  }
  std::pair<const std::uint8_t*, std::size_t> rest() {
    const std::uint8_t* at = p_ + pos_;
    const std::size_t k = left();
    pos_ = n_;
    return {at, k};
  }

 private:
  const std::uint8_t* p_;
  std::size_t n_, pos_ = 0;
  std::string where_;
};

// ------------------------------------------------------------------------------ files
/// A storage file read whole: a regular file (checked before it is opened) of at most max_bytes.
std::vector<std::uint8_t> readWhole(const fs::path& p, const char* what, std::uint64_t max_bytes) {
  struct stat st {};
  const int fd = openInputFile(p, what, max_bytes, &st);
  std::vector<std::uint8_t> buf;
  try {
    buf.resize(static_cast<std::size_t>(st.st_size));
  } catch (const std::bad_alloc&) {
    ::close(fd);
    throw Error(fmt::format("{}: the {} file has {} bytes: not enough memory to read it whole",
                            p.string(), what, st.st_size));
  }
  std::size_t got = 0;
  while (got < buf.size()) {
    const ssize_t n = ::read(fd, buf.data() + got, buf.size() - got);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = errno;
      ::close(fd);
      throw Error(fmt::format("{}: cannot read the {} file ({})", p.string(), what,
                              n < 0 ? std::strerror(err) : "it ended early: it shrank"));
    }
    got += static_cast<std::size_t>(n);
  }
  ::close(fd);
  return buf;
}

// ------------------------------------------------------------------------------ MCAP
/// A chunk's declared uncompressed size against the caps (before anything is decompressed).
void checkChunkSize(const std::string& compression, std::size_t size,
                    std::uint64_t uncompressed_size, const std::string& where) {
  if (uncompressed_size > kMaxChunkBytes)
    throw Error(
        fmt::format("{}: chunk uncompressed_size {} bytes is above the limit of {} bytes "
                    "(a corrupt size, or chunks far larger than rosbag2 writes)",
                    where, uncompressed_size, kMaxChunkBytes));
  if (uncompressed_size > kMaxChunkRatio * static_cast<std::uint64_t>(size) + kChunkAllowanceBytes)
    throw Error(fmt::format(
        "{}: chunk uncompressed_size {} bytes from {} compressed bytes ({}): above the limit "
        "of {} times the compressed size plus {} bytes (a decompression bomb, or a corrupt "
        "size)",
        where, uncompressed_size, size, compression.empty() ? "none" : compression, kMaxChunkRatio,
        kChunkAllowanceBytes));
}

struct McapState {
  struct Schema {
    std::string name, encoding;
    std::uint32_t data_crc = 0;
    std::size_t data_size = 0;
    std::string where;  // the record that defined it first
    bool operator==(const Schema& o) const {
      return name == o.name && encoding == o.encoding && data_crc == o.data_crc &&
             data_size == o.data_size;
    }
  };
  struct Channel {
    std::string topic, encoding;
    std::uint16_t schema = 0;
    int publishers = -1;                  // its metadata's offered_qos_profiles entries
    const std::string* wanted = nullptr;  // the wanted topic, or null
    std::string where;                    // the record that defined it first
  };
  std::map<std::uint16_t, Schema> schemas;
  std::map<std::uint16_t, Channel> channels;
  std::map<std::string, std::uint16_t> topic_channel;  // a topic's first channel
  std::uint64_t decompressed = 0;                      // bytes of chunks so far (declared)
  Census* census = nullptr;                            // set: every topic counted
};

/// The name of a schema for messages ("0 (none)", "3 'sensor_msgs/msg/JointState'").
std::string schemaText(const McapState& st, std::uint16_t id) {
  if (id == 0) return "0 (none)";
  const auto s = st.schemas.find(id);
  return s == st.schemas.end() ? std::to_string(id) : fmt::format("{} '{}'", id, s->second.name);
}

/// The publishers a channel's metadata (a map of strings) names: the entries of its
/// offered_qos_profiles, as rosbag2's MCAP storage writes them; -1 when it has none. A
/// malformed map is an error, as any truncated record.
int channelPublishers(std::pair<const std::uint8_t*, std::size_t> metadata,
                      const std::string& where) {
  Bytes m(metadata.first, metadata.second, where + " (Channel.metadata)");
  int n = -1;
  while (m.left() > 0) {
    const std::string key = m.str("Channel.metadata key");
    const std::string value = m.str("Channel.metadata value");
    if (key == "offered_qos_profiles") n = qosProfileCount(value);
  }
  return n;
}

/// A channel's topic in the census: its type (the schema's name), serialization and publishers.
void censusChannel(McapState& st, const McapState::Channel& c) {
  TopicCensus& tc = (*st.census)[c.topic];
  tc.publishers = std::max(tc.publishers, c.publishers);
  if (const auto sc = st.schemas.find(c.schema); tc.type.empty() && sc != st.schemas.end())
    tc.type = sc->second.name;
  if (tc.serialization_format.empty()) tc.serialization_format = c.encoding;
}

/// A message in the census: counted, its log time in the topic's span.
void censusMessage(McapState& st, const std::string& topic, std::uint64_t log_time) {
  TopicCensus& tc = (*st.census)[topic];
  const auto t = static_cast<std::int64_t>(std::min<std::uint64_t>(log_time, INT64_MAX));
  if (tc.messages == 0 || t < tc.first_ns) tc.first_ns = t;
  if (tc.messages == 0 || t > tc.last_ns) tc.last_ns = t;
  ++tc.messages;
}

/// Handles one Schema, Channel or Message record (top level or inside a chunk). Returns false
/// for other opcodes (the caller decides).
bool mcapRecord(const BagInfo& bag, const std::string& file, std::uint8_t op, Bytes& r,
                const std::string& where, McapState& st, const std::set<std::string>& wanted,
                const std::function<void(const RawMessage&)>& fn) {
  if (op == 0x03) {
    const std::uint16_t id = r.u16("Schema.id");
    McapState::Schema s;
    s.name = r.str("Schema.name");
    s.encoding = r.str("Schema.encoding");
    const auto data = r.block(4, "Schema.data");
    s.data_crc = crc32(data.first, data.second);
    s.data_size = data.second;
    s.where = where;
    if (id == 0)
      throw Error(fmt::format("{}: Schema.id 0: expected 1 or more (0 means no schema)", where));
    // One definition per schema id: a channel's type was checked against the first.
    const auto [it, fresh] = st.schemas.emplace(id, s);
    if (!fresh && !(it->second == s))
      throw Error(fmt::format(
          "{}: schema {} redefined as '{}' (encoding '{}', {} bytes of definition); it was "
          "defined as '{}' (encoding '{}', {} bytes) by {}: one definition per schema id",
          where, id, s.name, s.encoding, s.data_size, it->second.name, it->second.encoding,
          it->second.data_size, it->second.where));
    return true;
  }
  if (op == 0x04) {
    const std::uint16_t id = r.u16("Channel.id");
    McapState::Channel c;
    c.schema = r.u16("Channel.schema_id");
    c.topic = r.str("Channel.topic");
    c.encoding = r.str("Channel.message_encoding");
    c.publishers = channelPublishers(r.block(4, "Channel.metadata"), where);
    c.where = where;
    // One definition per channel id (the same record may repeat): a channel redefined to
    // another topic, schema or encoding would send its later messages elsewhere.
    if (const auto old = st.channels.find(id); old != st.channels.end()) {
      const McapState::Channel& o = old->second;
      if (o.topic != c.topic || o.schema != c.schema || o.encoding != c.encoding)
        throw Error(fmt::format(
            "{}: channel {} redefined as topic '{}' (schema {}, encoding '{}'); it was defined "
            "as topic '{}' (schema {}, encoding '{}') by {}: one definition per channel id",
            where, id, c.topic, schemaText(st, c.schema), c.encoding, o.topic,
            schemaText(st, o.schema), o.encoding, o.where));
      return true;
    }
    // One definition per topic: a second channel of a topic must say the same of it.
    if (const auto t = st.topic_channel.find(c.topic); t != st.topic_channel.end()) {
      const McapState::Channel& o = st.channels.at(t->second);
      auto schemaName = [&](std::uint16_t sid) {
        const auto f = st.schemas.find(sid);
        return f == st.schemas.end() ? "#" + std::to_string(sid) : f->second.name;
      };
      const bool same_schema =
          o.schema == c.schema ||
          (o.schema != 0 && c.schema != 0 && schemaName(o.schema) == schemaName(c.schema));
      if (!same_schema || o.encoding != c.encoding)
        throw Error(fmt::format(
            "{}: topic '{}' defined again by channel {} with schema {} and encoding '{}'; "
            "channel {} defined it with schema {} and encoding '{}' ({}): one definition per "
            "topic",
            where, c.topic, id, schemaText(st, c.schema), c.encoding, t->second,
            schemaText(st, o.schema), o.encoding, o.where));
    } else {
      st.topic_channel.emplace(c.topic, id);
    }
    const auto it = wanted.find(c.topic);
    if (it != wanted.end()) {
      c.wanted = &*it;
      if (c.encoding != "cdr")
        throw Error(fmt::format("{}: channel {} of topic '{}': message_encoding '{}', expected cdr",
                                where, id, c.topic, c.encoding));
      const TopicInfo* info = bag.topic(c.topic);
      if (c.schema != 0) {
        const auto s = st.schemas.find(c.schema);
        if (s == st.schemas.end())
          throw Error(
              fmt::format("{}: channel {} of topic '{}' refers to schema {}, not defined "
                          "before it",
                          where, id, c.topic, c.schema));
        if (info && s->second.name != info->type)
          throw Error(fmt::format("{}: topic '{}' has schema '{}' in {}, type '{}' in {}", where,
                                  c.topic, s->second.name, file, info->type,
                                  bag.metadata_file.string()));
      }
    }
    st.channels[id] = c;
    if (st.census) censusChannel(st, c);
    return true;
  }
  if (op == 0x05) {
    const std::uint16_t ch = r.u16("Message.channel_id");
    r.u32("Message.sequence");
    const std::uint64_t log_time = r.u64("Message.log_time");
    r.u64("Message.publish_time");
    const auto c = st.channels.find(ch);
    if (c == st.channels.end())
      throw Error(fmt::format(
          "{}: message on channel {}, which no Channel record defined before it", where, ch));
    if (st.census) censusMessage(st, c->second.topic, log_time);
    if (!c->second.wanted) return true;
    RawMessage m;
    m.topic = c->second.wanted;
    if (log_time > static_cast<std::uint64_t>(INT64_MAX))
      throw Error(fmt::format("{}: Message.log_time {} ns is out of range", where, log_time));
    m.receive_ns = static_cast<std::int64_t>(log_time);
    const auto d = r.rest();
    m.data = d.first;
    m.size = d.second;
    m.where = where;
    fn(m);
    return true;
  }
  return false;
}

}  // namespace

void readMcapBytes(const BagInfo& bag, const std::string& file, const std::uint8_t* data,
                   std::size_t size, const std::set<std::string>& wanted,
                   const std::function<void(const RawMessage&)>& fn, Census* census) {
  const Span buf{data, size};
  if (buf.size() < kMcapMagic.size() ||
      !std::equal(kMcapMagic.begin(), kMcapMagic.end(), buf.begin()))
    throw Error(
        fmt::format("{}: not an MCAP file: expected the magic bytes 89 4d 43 41 50 30 0d "
                    "0a at its start (storage_identifier mcap in {})",
                    file, bag.metadata_file.string()));
  McapState st;
  st.census = census;
  std::size_t pos = kMcapMagic.size();
  long long index = 0;
  bool ended = false;
  while (!ended) {
    ++index;
    if (buf.size() - pos < 9)
      throw Error(
          fmt::format("{}: truncated: record {} at byte {} needs a 9-byte opcode and "
                      "length, {} bytes left (the file ends before its DataEnd and Footer "
                      "records)",
                      file, index, pos, buf.size() - pos));
    const std::uint8_t op = buf[pos];
    std::uint64_t len = 0;
    for (int i = 8; i >= 1; --i) len = (len << 8) | buf[pos + static_cast<std::size_t>(i)];
    const std::size_t start = pos + 9;
    if (len > buf.size() - start)
      throw Error(
          fmt::format("{}: truncated: record {} (opcode 0x{:02x}) at byte {} has length "
                      "{}, {} bytes left in the file",
                      file, index, op, pos, len, buf.size() - start));
    const std::string where =
        fmt::format("{}: record {} (opcode 0x{:02x}) at byte {}", file, index, op, pos);
    Bytes r(buf.data() + start, static_cast<std::size_t>(len), where);
    pos = start + static_cast<std::size_t>(len);
    if (mcapRecord(bag, file, op, r, where, st, wanted, fn)) continue;
    if (op == 0x06) {  // Chunk
      r.u64("Chunk.message_start_time");
      r.u64("Chunk.message_end_time");
      const std::uint64_t usize = r.u64("Chunk.uncompressed_size");
      const std::uint32_t crc = r.u32("Chunk.uncompressed_crc");
      const std::string comp = r.str("Chunk.compression");
      const auto stored = r.block(8, "Chunk.records");
      // The chunk's and the file's decompression budgets, from the sizes the chunks declare,
      // before any work.
      checkChunkSize(comp, stored.second, usize, where);
      const std::uint64_t budget = std::min<std::uint64_t>(
          kMaxFileDecompressedBytes,
          kMaxChunkRatio * static_cast<std::uint64_t>(buf.size()) + kFileAllowanceBytes);
      if (usize > budget - std::min(budget, st.decompressed))
        throw Error(fmt::format(
            "{}: chunk uncompressed_size {} bytes would bring the file's decompressed chunks to "
            "{} bytes, above its limit of {} bytes ({} times the file's {} bytes plus {}, at most "
            "{}): a decompression bomb, or a corrupt size",
            where, usize, st.decompressed + usize, budget, kMaxChunkRatio, buf.size(),
            kFileAllowanceBytes, kMaxFileDecompressedBytes));
      st.decompressed += usize;
      const std::vector<std::uint8_t> recs =
          decompressChunk(comp, stored.first, stored.second, usize, where);
      if (crc != 0 && crc32(recs.data(), recs.size()) != crc)
        throw Error(
            fmt::format("{}: corrupt chunk: CRC-32 of its {} uncompressed bytes is "
                        "{:08x}, the chunk says {:08x}",
                        where, recs.size(), crc32(recs.data(), recs.size()), crc));
      std::size_t q = 0;
      long long inner = 0;
      while (q < recs.size()) {
        ++inner;
        if (recs.size() - q < 9)
          throw Error(
              fmt::format("{}: corrupt chunk: its record {} at byte {} needs a 9-byte "
                          "opcode and length, {} bytes left",
                          where, inner, q, recs.size() - q));
        const std::uint8_t iop = recs[q];
        std::uint64_t ilen = 0;
        for (int i = 8; i >= 1; --i) ilen = (ilen << 8) | recs[q + static_cast<std::size_t>(i)];
        if (ilen > recs.size() - q - 9)
          throw Error(
              fmt::format("{}: corrupt chunk: its record {} (opcode 0x{:02x}) at byte {} "
                          "has length {}, {} bytes left in the chunk",
                          where, inner, iop, q, ilen, recs.size() - q - 9));
        const std::string iwhere =
            fmt::format("{}, chunk record {} (opcode 0x{:02x})", where, inner, iop);
        Bytes ir(recs.data() + q + 9, static_cast<std::size_t>(ilen), iwhere);
        q += 9 + static_cast<std::size_t>(ilen);
        mcapRecord(bag, file, iop, ir, iwhere, st, wanted, fn);  // others: skipped
      }
      continue;
    }
    if (op == 0x0F || op == 0x02) ended = true;  // DataEnd (the summary follows) or Footer
    // Header, MessageIndex, ChunkIndex, Attachment, Metadata, Statistics, ...: skipped.
  }
}

std::uint32_t crc32(const std::uint8_t* data, std::size_t size, std::uint32_t crc) {
  static const std::array<std::uint32_t, 256> table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  crc = ~crc;
  for (std::size_t i = 0; i < size; ++i) crc = table[(crc ^ data[i]) & 0xFFu] ^ (crc >> 8);
  return ~crc;
}

std::vector<std::uint8_t> decompressChunk(const std::string& compression, const std::uint8_t* src,
                                          std::size_t size, std::uint64_t uncompressed_size,
                                          const std::string& where) {
  checkChunkSize(compression, size, uncompressed_size, where);
  std::vector<std::uint8_t> out;
  if (compression.empty()) {
    if (size != uncompressed_size)
      throw Error(
          fmt::format("{}: corrupt chunk: uncompressed, {} bytes of records, but "
                      "uncompressed_size says {}",
                      where, size, uncompressed_size));
    out.assign(src, src + size);
    return out;
  }
  if (compression != "zstd" && compression != "lz4")
    throw Error(fmt::format("{}: chunk compression '{}': expected \"\" (none), zstd or lz4", where,
                            compression));
  // Streaming decompression into a buffer that grows with the output (never beyond
  // uncompressed_size): a corrupt size field allocates nothing the data do not fill. When the
  // buffer is full, one scratch byte of room shows whether the stream would give more.
  const std::size_t usize = static_cast<std::size_t>(uncompressed_size);
  out.resize(std::min<std::size_t>(usize, std::size_t{1} << 20));
  std::size_t in_pos = 0, out_pos = 0;
  std::uint8_t scratch = 0;
  auto room = [&]() -> std::pair<std::uint8_t*, std::size_t> {
    if (out_pos == out.size() && out.size() < usize)
      out.resize(std::min(usize, std::max<std::size_t>(2 * out.size(), 4096)));
    if (out_pos == out.size()) return {&scratch, 1};
    return {out.data() + out_pos, out.size() - out_pos};
  };
  auto tooMuch = [&] {
    return Error(fmt::format("{}: corrupt chunk: {} gives more than uncompressed_size = {} bytes",
                             where, compression, uncompressed_size));
  };
  auto early = [&] {
    return Error(
        fmt::format("{}: corrupt chunk: the {} stream ends early ({} of {} bytes "
                    "decompressed, all {} compressed bytes read)",
                    where, compression, out_pos, uncompressed_size, size));
  };
  if (compression == "zstd") {
    std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> ctx(ZSTD_createDCtx(), &ZSTD_freeDCtx);
    if (!ctx) throw Error(fmt::format("{}: zstd: cannot create a decompression context", where));
    ZSTD_inBuffer in{src, size, 0};
    for (;;) {
      const auto [dst, cap] = room();
      ZSTD_outBuffer o{dst, cap, 0};
      const std::size_t r = ZSTD_decompressStream(ctx.get(), &o, &in);
      if (ZSTD_isError(r))
        throw Error(fmt::format("{}: corrupt chunk: zstd: {} ({} compressed bytes)", where,
                                ZSTD_getErrorName(r), size));
      if (dst == &scratch && o.pos > 0) throw tooMuch();
      if (dst != &scratch) out_pos += o.pos;
      if (in.pos == in.size) {
        if (r == 0) break;                  // the last frame is complete
        if (o.pos < o.size) throw early();  // room left, input used up, frame unfinished
      }
    }
  } else {
    LZ4F_dctx* raw = nullptr;
    if (LZ4F_isError(LZ4F_createDecompressionContext(&raw, LZ4F_VERSION)))
      throw Error(fmt::format("{}: lz4: cannot create a decompression context", where));
    std::unique_ptr<LZ4F_dctx, decltype(&LZ4F_freeDecompressionContext)> ctx(
        raw, &LZ4F_freeDecompressionContext);
    for (;;) {
      const auto [dst, cap] = room();
      std::size_t in_n = size - in_pos, out_n = cap;
      const std::size_t r = LZ4F_decompress(ctx.get(), dst, &out_n, src + in_pos, &in_n, nullptr);
      if (LZ4F_isError(r))
        throw Error(fmt::format("{}: corrupt chunk: lz4: {} ({} compressed bytes)", where,
                                LZ4F_getErrorName(r), size));
      if (dst == &scratch && out_n > 0) throw tooMuch();
      if (dst != &scratch) out_pos += out_n;
      in_pos += in_n;
      if (r == 0) {  // a frame is complete
        if (in_pos == size) break;
        continue;  // another frame follows
      }
      if (in_pos == size && out_n < cap) throw early();
    }
  }
  if (out_pos != usize)
    throw Error(fmt::format("{}: corrupt chunk: {} gave {} bytes, uncompressed_size says {}", where,
                            compression, out_pos, uncompressed_size));
  out.resize(out_pos);
  return out;
}

namespace detail {

/// The MCAP part of readMessages: the storage file read whole, at most kMaxMcapFileBytes.
void readMcap(const BagInfo& bag, const fs::path& path, const std::set<std::string>& wanted,
              const std::function<void(const RawMessage&)>& fn, Census* census) {
  const std::vector<std::uint8_t> buf = readWhole(path, "bag storage (MCAP)", kMaxMcapFileBytes);
  readMcapBytes(bag, path.string(), buf.data(), buf.size(), wanted, fn, census);
}

}  // namespace detail

}  // namespace exid::rosbag2
