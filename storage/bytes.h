// Byte buffers, little-endian fixed-width values and LEB128 varints: the encoding every record,
// page and key of the store is built from. ByteReader validates every read: running past the end
// or meeting a malformed varint throws smr::Error (kCorrupt) naming the record being decoded.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace smr::storage {

using Bytes = std::vector<std::uint8_t>;
using ByteView = std::span<const std::uint8_t>;

inline ByteView as_bytes(std::string_view s) {
  return {reinterpret_cast<const std::uint8_t*>(s.data()), s.size()};
}

// Appends to a caller-owned buffer; never clears it.
class ByteWriter {
 public:
  explicit ByteWriter(Bytes& out) : out_(&out) {}

  void u8(std::uint8_t v) { out_->push_back(v); }
  void u16(std::uint16_t v);
  void u32(std::uint32_t v);
  void u64(std::uint64_t v);
  void f32(float v);             // bit-exact (IEEE-754 bits, little-endian)
  void f64(double v);            // bit-exact
  void varint(std::uint64_t v);  // unsigned LEB128, 1..10 bytes
  void svarint(std::int64_t v);  // zigzag, then LEB128
  void bytes(ByteView v);        // raw, no length
  void blob(ByteView v);         // varint length, then the bytes

  std::size_t size() const { return out_->size(); }

 private:
  Bytes* out_;
};

// Reads from a view that must outlive the reader (returned views point into it).
class ByteReader {
 public:
  // `context` names what is being decoded ("<table>/<key>", say) and prefixes every error message.
  ByteReader(ByteView in, std::string context) : in_(in), context_(std::move(context)) {}

  std::uint8_t u8() {
    if (pos_ < in_.size()) return in_[pos_++];
    return *take(1, "u8");  // throws
  }
  std::uint16_t u16();
  std::uint32_t u32();
  std::uint64_t u64();
  float f32();
  double f64();
  // Rejects overlong (> 10 bytes) and overflowing encodings. Inline for the one-byte case, which
  // is most of a page's records.
  std::uint64_t varint() {
    if (pos_ < in_.size() && in_[pos_] < 0x80) return in_[pos_++];
    if (pos_ + 1 < in_.size() && in_[pos_ + 1] < 0x80) {  // two bytes, the next most common
      const std::uint64_t v = (in_[pos_] & 0x7fu) | std::uint64_t{in_[pos_ + 1]} << 7;
      pos_ += 2;
      return v;
    }
    return varint_long();
  }
  std::int64_t svarint() {
    const std::uint64_t u = varint();
    return static_cast<std::int64_t>((u >> 1) ^ (~(u & 1) + 1));
  }
  ByteView bytes(std::size_t n);
  ByteView blob();

  bool at_end() const { return pos_ == in_.size(); }
  std::size_t remaining() const { return in_.size() - pos_; }
  std::size_t position() const { return pos_; }
  const std::string& context() const { return context_; }
  // Throws kCorrupt "<context>: <what>".
  [[noreturn]] void fail(const std::string& what) const;
  // Throws kCorrupt unless every byte was consumed (trailing garbage is corruption too).
  void expect_end() const;

 private:
  const std::uint8_t* take(std::size_t n, const char* what);
  std::uint64_t varint_long();

  ByteView in_;
  std::size_t pos_ = 0;
  std::string context_;
};

// 8-byte big-endian key: lexicographic byte order == numeric order (LMDB's default comparator).
Bytes key_u64(std::uint64_t key);
// Inverse of key_u64; throws kCorrupt naming `context` unless `key` is exactly 8 bytes.
std::uint64_t parse_key_u64(ByteView key, std::string_view context);

}  // namespace smr::storage
