#include "storage/bytes.h"

#include <bit>
#include <cstring>

#include "base/error.h"

namespace smr::storage {
namespace {

template <class T>
void put_le(Bytes& out, T v) {
  for (std::size_t i = 0; i < sizeof(T); ++i) {
    out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  }
}

template <class T>
T get_le(const std::uint8_t* p) {
  T v = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) v |= static_cast<T>(static_cast<T>(p[i]) << (8 * i));
  return v;
}

}  // namespace

void ByteWriter::u16(std::uint16_t v) {
  put_le(*out_, v);
}
void ByteWriter::u32(std::uint32_t v) {
  put_le(*out_, v);
}
void ByteWriter::u64(std::uint64_t v) {
  put_le(*out_, v);
}
void ByteWriter::f32(float v) {
  u32(std::bit_cast<std::uint32_t>(v));
}
void ByteWriter::f64(double v) {
  u64(std::bit_cast<std::uint64_t>(v));
}

void ByteWriter::varint(std::uint64_t v) {
  while (v >= 0x80) {
    out_->push_back(static_cast<std::uint8_t>(v | 0x80));
    v >>= 7;
  }
  out_->push_back(static_cast<std::uint8_t>(v));
}

void ByteWriter::svarint(std::int64_t v) {
  const auto u = static_cast<std::uint64_t>(v);
  varint((u << 1) ^ (v < 0 ? ~std::uint64_t{0} : std::uint64_t{0}));
}

void ByteWriter::bytes(ByteView v) {
  out_->insert(out_->end(), v.begin(), v.end());
}

void ByteWriter::blob(ByteView v) {
  varint(v.size());
  bytes(v);
}

void ByteReader::fail(const std::string& what) const {
  throw_corrupt(context_ + ": " + what);
}

void ByteReader::expect_end() const {
  if (!at_end()) {
    fail(std::to_string(remaining()) + " unexpected trailing bytes at offset " +
         std::to_string(pos_));
  }
}

const std::uint8_t* ByteReader::take(std::size_t n, const char* what) {
  if (n > remaining()) {
    fail(std::string("truncated: ") + what + " needs " + std::to_string(n) + " bytes at offset " +
         std::to_string(pos_) + ", only " + std::to_string(remaining()) + " left");
  }
  const std::uint8_t* p = in_.data() + pos_;
  pos_ += n;
  return p;
}

std::uint16_t ByteReader::u16() {
  return get_le<std::uint16_t>(take(2, "u16"));
}
std::uint32_t ByteReader::u32() {
  return get_le<std::uint32_t>(take(4, "u32"));
}
std::uint64_t ByteReader::u64() {
  return get_le<std::uint64_t>(take(8, "u64"));
}
float ByteReader::f32() {
  return std::bit_cast<float>(u32());
}
double ByteReader::f64() {
  return std::bit_cast<double>(u64());
}

std::uint64_t ByteReader::varint_long() {
  const std::size_t start = pos_;
  std::uint64_t v = 0;
  for (int shift = 0; shift < 64; shift += 7) {
    if (at_end()) {
      fail("truncated varint at offset " + std::to_string(start));
    }
    const std::uint8_t b = in_[pos_++];
    if (shift == 63 && b > 1) {
      fail("varint overflows 64 bits at offset " + std::to_string(start));
    }
    v |= static_cast<std::uint64_t>(b & 0x7f) << shift;
    if ((b & 0x80) == 0) return v;
  }
  fail("varint longer than 10 bytes at offset " + std::to_string(start));
}

ByteView ByteReader::bytes(std::size_t n) {
  return {take(n, "byte string"), n};
}

ByteView ByteReader::blob() {
  const std::size_t start = pos_;
  const std::uint64_t n = varint();
  if (n > remaining()) {
    fail("blob at offset " + std::to_string(start) + " claims " + std::to_string(n) +
         " bytes, only " + std::to_string(remaining()) + " left");
  }
  return bytes(static_cast<std::size_t>(n));
}

Bytes key_u64(std::uint64_t key) {
  Bytes out(8);
  for (int i = 0; i < 8; ++i) out[i] = static_cast<std::uint8_t>(key >> (56 - 8 * i));
  return out;
}

std::uint64_t parse_key_u64(ByteView key, std::string_view context) {
  if (key.size() != 8) {
    throw_corrupt(std::string(context) + ": expected an 8-byte key, found " +
                  std::to_string(key.size()) + " bytes");
  }
  std::uint64_t v = 0;
  for (std::uint8_t b : key) v = (v << 8) | b;
  return v;
}

}  // namespace smr::storage
