#include "index/hilbert.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <map>

namespace smr::index {
namespace {

// The first 8^k (3-D) or 4^k (2-D) positions of the curve fill the block of side 2^k at the
// origin, each step moving to a face-adjacent cell.
void check_block(int dims, std::uint32_t side) {
  std::map<std::uint64_t, std::array<std::uint32_t, 3>> by_index;
  const std::uint32_t zs = dims == 3 ? side : 1;
  for (std::uint32_t x = 0; x < side; ++x) {
    for (std::uint32_t y = 0; y < side; ++y) {
      for (std::uint32_t z = 0; z < zs; ++z) {
        by_index[hilbert_index({x, y, z}, dims)] = {x, y, z};
      }
    }
  }
  ASSERT_EQ(by_index.size(), static_cast<std::size_t>(side) * side * zs);
  EXPECT_EQ(by_index.rbegin()->first, by_index.size() - 1);  // exactly 0 .. n-1
  const std::array<std::uint32_t, 3>* prev = nullptr;
  for (const auto& [index, cell] : by_index) {
    if (prev != nullptr) {
      int moved = 0;
      for (int a = 0; a < 3; ++a) {
        moved += std::abs(static_cast<int>(cell[a]) - static_cast<int>((*prev)[a]));
      }
      EXPECT_EQ(moved, 1) << "at index " << index;
    }
    prev = &cell;
  }
}

TEST(Hilbert, TwoDimensionalBlockIsAContinuousCurve) {
  check_block(2, 16);
}
TEST(Hilbert, ThreeDimensionalBlockIsAContinuousCurve) {
  check_block(3, 8);
}

TEST(Hilbert, CornersSpanTheWholeIndexRange) {
  for (int dims : {2, 3}) {
    const std::uint32_t top = (1u << hilbert_bits(dims)) - 1;
    const int bits = hilbert_bits(dims) * dims;
    std::uint64_t highest = 0;
    for (std::uint32_t c = 0; c < (1u << dims); ++c) {
      const std::uint64_t h =
          hilbert_index({c & 1 ? top : 0, c & 2 ? top : 0, c & 4 ? top : 0}, dims);
      EXPECT_LT(h, std::uint64_t{1} << bits);
      highest = std::max(highest, h);
    }
    // One corner lies in the last quadrant / octant of the curve.
    const std::uint64_t last = ((std::uint64_t{1} << dims) - 1) << (bits - dims);
    EXPECT_GE(highest, last) << dims;
  }
}

}  // namespace
}  // namespace smr::index
