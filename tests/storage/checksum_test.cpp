#include "storage/checksum.h"

#include <random>

#include <gtest/gtest.h>

#include "storage_test_helpers.h"

namespace smr::storage {
namespace {

using test::expect_error;

TEST(Checksum, IsXxh3SixtyFour) {
  // Reference values of XXH3_64bits (seed 0) from the xxhash test suite.
  EXPECT_EQ(checksum({}), 0x2D06800538D394C2ull);
  std::mt19937_64 rng(5);
  const Bytes a = test::random_bytes(rng, 1000);
  Bytes b = a;
  EXPECT_EQ(checksum(a), checksum(b));
  b[500] ^= 1;
  EXPECT_NE(checksum(a), checksum(b));
}

TEST(Checksum, SealAppendsLittleEndianChecksum) {
  const Bytes payload = {1, 2, 3};
  const Bytes sealed = seal(payload);
  ASSERT_EQ(sealed.size(), 11u);
  EXPECT_TRUE(std::equal(payload.begin(), payload.end(), sealed.begin()));
  std::uint64_t stored = 0;
  for (int i = 7; i >= 0; --i) stored = (stored << 8) | sealed[3 + i];
  EXPECT_EQ(stored, checksum(payload));
  const ByteView back = unseal(sealed, "pages", "42");
  EXPECT_EQ(Bytes(back.begin(), back.end()), payload);
  EXPECT_EQ(back.data(), sealed.data());  // a view, no copy
  Bytes appended = {9};
  seal_into(payload, appended);
  EXPECT_EQ(Bytes(appended.begin() + 1, appended.end()), sealed);
}

TEST(Checksum, EverySingleBitFlipIsDetected) {
  std::mt19937_64 rng(6);
  for (std::size_t size : {0u, 1u, 7u, 8u, 33u, 1000u, 4096u}) {
    const Bytes payload = test::random_bytes(rng, size);
    const Bytes sealed = seal(payload);
    ASSERT_NO_THROW(unseal(sealed, "pages", "42"));
    for (std::size_t bit = 0; bit < sealed.size() * 8; ++bit) {
      Bytes flipped = sealed;
      flipped[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
      try {
        unseal(flipped, "pages", "42");
        FAIL() << "flip of bit " << bit << " in a " << size << "-byte payload not detected";
      } catch (const Error& e) {
        ASSERT_EQ(e.kind(), ErrorKind::kCorrupt);
        ASSERT_EQ(std::string(e.what()).rfind("table 'pages', key 42: checksum mismatch (", 0), 0u)
            << e.what();
      }
    }
  }
}

TEST(Checksum, ShortValuesAreCorrupt) {
  for (std::size_t n = 0; n < 8; ++n) {
    const Bytes value(n, 0);
    expect_error([&] { unseal(value, "nodes", "7"); }, ErrorKind::kCorrupt,
                 "table 'nodes', key 7: value of " + std::to_string(n) + " bytes is too short");
  }
}

}  // namespace
}  // namespace smr::storage
