#include "storage/bytes.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "storage_test_helpers.h"

namespace smr::storage {
namespace {

using test::expect_error;

struct Sample {
  std::uint8_t a;
  std::uint16_t b;
  std::uint32_t c;
  std::uint64_t d;
  float e;
  double f;
  std::uint64_t g;
  std::int64_t h;
  Bytes blob;
  Bytes raw;
};

Bytes encode(const Sample& s) {
  Bytes out;
  ByteWriter w(out);
  w.u8(s.a);
  w.u16(s.b);
  w.u32(s.c);
  w.u64(s.d);
  w.f32(s.e);
  w.f64(s.f);
  w.varint(s.g);
  w.svarint(s.h);
  w.blob(s.blob);
  w.bytes(s.raw);
  return out;
}

Sample decode(ByteView in, std::size_t raw_size) {
  ByteReader r(in, "pages/42");
  Sample s;
  s.a = r.u8();
  s.b = r.u16();
  s.c = r.u32();
  s.d = r.u64();
  s.e = r.f32();
  s.f = r.f64();
  s.g = r.varint();
  s.h = r.svarint();
  const ByteView blob = r.blob();
  s.blob.assign(blob.begin(), blob.end());
  const ByteView raw = r.bytes(raw_size);
  s.raw.assign(raw.begin(), raw.end());
  r.expect_end();
  return s;
}

TEST(Bytes, RoundTripsEveryTypeBitExactly) {
  std::mt19937_64 rng(1);
  const std::uint64_t varints[] = {0,
                                   1,
                                   127,
                                   128,
                                   16383,
                                   16384,
                                   std::uint64_t{1} << 63,
                                   std::numeric_limits<std::uint64_t>::max()};
  const std::int64_t svarints[] = {0,
                                   1,
                                   -1,
                                   63,
                                   -64,
                                   64,
                                   -65,
                                   std::numeric_limits<std::int64_t>::max(),
                                   std::numeric_limits<std::int64_t>::min()};
  const float floats[] = {0.0f,
                          -0.0f,
                          1.5f,
                          std::numeric_limits<float>::denorm_min(),
                          std::numeric_limits<float>::infinity(),
                          std::bit_cast<float>(0x7fc00123u)};  // NaN with payload
  int cases = 0;
  for (std::uint64_t g : varints) {
    for (std::int64_t h : svarints) {
      for (float e : floats) {
        Sample s{static_cast<std::uint8_t>(rng()),
                 static_cast<std::uint16_t>(rng()),
                 static_cast<std::uint32_t>(rng()),
                 rng(),
                 e,
                 std::bit_cast<double>(rng()),
                 g,
                 h,
                 test::random_bytes(rng, rng() % 300),
                 test::random_bytes(rng, rng() % 5)};
        const Bytes bytes = encode(s);
        const Sample t = decode(bytes, s.raw.size());
        EXPECT_EQ(s.a, t.a);
        EXPECT_EQ(s.b, t.b);
        EXPECT_EQ(s.c, t.c);
        EXPECT_EQ(s.d, t.d);
        EXPECT_EQ(std::bit_cast<std::uint32_t>(s.e), std::bit_cast<std::uint32_t>(t.e));
        EXPECT_EQ(std::bit_cast<std::uint64_t>(s.f), std::bit_cast<std::uint64_t>(t.f));
        EXPECT_EQ(s.g, t.g);
        EXPECT_EQ(s.h, t.h);
        EXPECT_EQ(s.blob, t.blob);
        EXPECT_EQ(s.raw, t.raw);
        ++cases;
      }
    }
  }
  EXPECT_EQ(cases, 8 * 9 * 6);
}

TEST(Bytes, FixedWidthIsLittleEndianAndVarintIsLeb128) {
  Bytes out;
  ByteWriter w(out);
  w.u32(0x04030201u);
  w.varint(300);  // 0xac 0x02
  w.svarint(-1);  // zigzag 1
  w.svarint(1);   // zigzag 2
  w.varint(std::numeric_limits<std::uint64_t>::max());
  const Bytes expected = {1,    2,    3,    4,    0xac, 0x02, 0x01, 0x02, 0xff,
                          0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01};
  EXPECT_EQ(out, expected);
}

TEST(Bytes, EveryTruncationThrowsNamingTheContext) {
  std::mt19937_64 rng(2);
  Sample s{200,
           65000,
           0xdeadbeef,
           rng(),
           3.5f,
           -2.25,
           std::uint64_t{1} << 40,
           -123456789,
           test::random_bytes(rng, 40),
           test::random_bytes(rng, 3)};
  const Bytes bytes = encode(s);
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    const ByteView prefix(bytes.data(), n);
    expect_error([&] { decode(prefix, s.raw.size()); }, ErrorKind::kCorrupt, "pages/42: ");
  }
  // Trailing bytes are corruption too.
  Bytes longer = bytes;
  longer.push_back(0);
  expect_error([&] { decode(longer, s.raw.size()); }, ErrorKind::kCorrupt,
               "pages/42: 1 unexpected trailing bytes");
}

TEST(Bytes, BadVarintsThrow) {
  {
    const Bytes eleven(11, 0x80);
    ByteReader r(eleven, "nodes/7");
    expect_error([&] { r.varint(); }, ErrorKind::kCorrupt, "nodes/7: varint");
  }
  {
    Bytes overflow(9, 0xff);
    overflow.push_back(0x02);  // bit 64 set
    ByteReader r(overflow, "nodes/8");
    expect_error([&] { r.varint(); }, ErrorKind::kCorrupt, "nodes/8: varint overflows");
  }
  {
    const Bytes unterminated = {0x80, 0x80};
    ByteReader r(unterminated, "nodes/9");
    expect_error([&] { r.svarint(); }, ErrorKind::kCorrupt, "nodes/9: truncated varint");
  }
  {
    Bytes max(9, 0xff);
    max.push_back(0x01);  // exactly 2^64 - 1: valid
    ByteReader r(max, "nodes/10");
    EXPECT_EQ(r.varint(), std::numeric_limits<std::uint64_t>::max());
    EXPECT_TRUE(r.at_end());
  }
}

TEST(Bytes, BlobLongerThanInputThrows) {
  Bytes out;
  ByteWriter w(out);
  w.varint(1000);
  w.bytes(Bytes(10, 7));
  ByteReader r(out, "rtree/3");
  expect_error([&] { r.blob(); }, ErrorKind::kCorrupt, "rtree/3: blob at offset 0 claims 1000");
  ByteReader r2(out, "rtree/4");
  r2.u8();
  r2.u8();
  EXPECT_EQ(r2.remaining(), 10u);
  expect_error([&] { r2.bytes(11); }, ErrorKind::kCorrupt, "rtree/4: truncated");
  EXPECT_EQ(r2.remaining(), 10u);  // a failed read consumes nothing
  EXPECT_EQ(r2.context(), "rtree/4");
  expect_error([&] { r2.fail("custom"); }, ErrorKind::kCorrupt, "rtree/4: custom");
}

TEST(Bytes, KeyOrderIsNumericOrder) {
  std::mt19937_64 rng(3);
  std::vector<std::uint64_t> keys = {
      0, 1, 255, 256, 65535, 65536, std::numeric_limits<std::uint64_t>::max()};
  for (int i = 0; i < 500; ++i) keys.push_back(rng() >> (rng() % 64));
  std::vector<Bytes> encoded;
  for (std::uint64_t k : keys) {
    encoded.push_back(key_u64(k));
    ASSERT_EQ(encoded.back().size(), 8u);
    EXPECT_EQ(parse_key_u64(encoded.back(), "k"), k);
  }
  for (std::size_t i = 0; i < keys.size(); ++i) {
    for (std::size_t j = 0; j < keys.size(); j += 7) {
      EXPECT_EQ(keys[i] < keys[j], encoded[i] < encoded[j]) << keys[i] << " vs " << keys[j];
    }
  }
  EXPECT_EQ(key_u64(0x0102030405060708u), (Bytes{1, 2, 3, 4, 5, 6, 7, 8}));
  expect_error([] { parse_key_u64(Bytes(7, 0), "table 'nodes'"); }, ErrorKind::kCorrupt,
               "table 'nodes': expected an 8-byte key, found 7 bytes");
}

}  // namespace
}  // namespace smr::storage
