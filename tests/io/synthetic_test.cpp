// Tests of make_fbm (smr/io/synthetic.h): determinism (including a golden hash, so a change of
// compiler, library or thread count that alters the terrain is caught), exact range, parameters.
#include "smr/io/synthetic.h"

#include <algorithm>

#include <gtest/gtest.h>

#include "tests/io/io_test_helpers.h"

namespace smr {
namespace {

using test::expect_error;

std::uint64_t hash_of(const Heightfield& h) {
  return test::fnv1a(h.z.data(), h.z.size() * sizeof(float));
}

TEST(Fbm, DeterministicAndSeedDependent) {
  const Heightfield a = make_fbm(257, 129, 42);
  const Heightfield b = make_fbm(257, 129, 42);
  const Heightfield c = make_fbm(257, 129, 43);
  EXPECT_EQ(hash_of(a), hash_of(b));
  EXPECT_EQ(a.z, b.z);
  EXPECT_NE(hash_of(a), hash_of(c));
  // Different parameters give different terrain.
  EXPECT_NE(hash_of(make_fbm(257, 129, 42, 1600.0, 3)), hash_of(a));
  EXPECT_NE(hash_of(make_fbm(257, 129, 42, 1600.0, 0, 0.6)), hash_of(a));
}

TEST(Fbm, GoldenHash) {
  // Pinned output: if this changes, every benchmark and test built on make_fbm changes too.
  EXPECT_EQ(hash_of(make_fbm(65, 33, 7)), 4795394003913088376u);
  EXPECT_EQ(hash_of(make_fbm(300, 17, 123456789, 250.0, 5, 0.45, 10.0)), 8832067955952198833u);
}

TEST(Fbm, RangeIsExactAndGeorefIsUnitOrSpacing) {
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    const Heightfield h = make_fbm(100, 80, seed);
    ASSERT_EQ(h.z.size(), 8000u);
    const auto [lo, hi] = std::minmax_element(h.z.begin(), h.z.end());
    EXPECT_EQ(*lo, 0.0f);
    EXPECT_EQ(*hi, 1600.0f);
    EXPECT_TRUE(h.valid.empty());
    EXPECT_EQ(h.georef, Georef{});
  }
  const Heightfield s = make_fbm(10, 12, 9, 37.5, 2, 0.5, 10.0);
  const auto [lo, hi] = std::minmax_element(s.z.begin(), s.z.end());
  EXPECT_EQ(*lo, 0.0f);
  EXPECT_EQ(*hi, 37.5f);
  EXPECT_EQ(s.width, 10);
  EXPECT_EQ(s.height, 12);
  EXPECT_EQ(s.georef.dx, 10.0);
  EXPECT_EQ(s.georef.dy, 10.0);
  EXPECT_EQ(s.source,
            "fbm(width=10, height=12, seed=9, range=37.5, octaves=2, persistence=0.5, spacing=10)");
}

TEST(Fbm, IsNotDegenerate) {
  // Neighbouring samples differ (fine octaves are present) but the field is spatially coherent.
  const Heightfield h = make_fbm(129, 129, 5);
  double sum_step = 0.0, sum_far = 0.0;
  int n = 0;
  for (int r = 0; r < 129; ++r) {
    for (int c = 0; c + 64 < 129; ++c) {
      sum_step += std::abs(h.at(c + 1, r) - h.at(c, r));
      sum_far += std::abs(h.at(c + 64, r) - h.at(c, r));
      ++n;
    }
  }
  EXPECT_GT(sum_step / n, 0.5);
  EXPECT_GT(sum_far, 3 * sum_step);
}

TEST(Fbm, BadParametersAreInvalidInput) {
  expect_error([] { (void)make_fbm(1, 10, 0); }, ErrorKind::kInvalidInput, {"2..65536"});
  expect_error([] { (void)make_fbm(10, 70000, 0); }, ErrorKind::kInvalidInput, {"2..65536"});
  expect_error([] { (void)make_fbm(10, 10, 0, 0.0); }, ErrorKind::kInvalidInput, {"height_range"});
  expect_error([] { (void)make_fbm(10, 10, 0, 100.0, 31); }, ErrorKind::kInvalidInput, {"octaves"});
  expect_error([] { (void)make_fbm(10, 10, 0, 100.0, 0, 0.0); }, ErrorKind::kInvalidInput,
               {"persistence"});
  expect_error([] { (void)make_fbm(10, 10, 0, 100.0, 0, 0.5, -1.0); }, ErrorKind::kInvalidInput,
               {"spacing"});
}

}  // namespace
}  // namespace smr
