#include "index/box.h"

#include <gtest/gtest.h>

#include <cmath>

namespace smr::index {
namespace {

TEST(Box, DefaultIsEmptyAndAddIsUnion) {
  Box b;
  EXPECT_TRUE(b.empty());
  b.add(Box{});
  EXPECT_TRUE(b.empty());
  b.add(Box::point(1, 2, 3));
  EXPECT_FALSE(b.empty());
  b.add(Box{{-1, 5, 0}, {0, 6, 1}});
  EXPECT_EQ(b, (Box{{-1, 2, 0}, {1, 6, 3}}));
}

TEST(Box, IntersectsIsClosedAndFalseForEmpty) {
  const Box a{{0, 0, 0}, {1, 1, 1}};
  EXPECT_TRUE(a.intersects(Box{{1, 1, 1}, {2, 2, 2}}));  // touching corner
  EXPECT_FALSE(a.intersects(Box{{1.5, 0, 0}, {2, 1, 1}}));
  EXPECT_FALSE(a.intersects(Box{}));
  EXPECT_FALSE(Box{}.intersects(a));
  const double inf = Box::kInf;
  EXPECT_TRUE(a.intersects(Box{{0.5, 0.5, -inf}, {0.6, 0.6, inf}}));  // a 2-D window
}

TEST(Box, ContainsAndNan) {
  const Box a{{0, 0, 0}, {1, 1, 1}};
  EXPECT_TRUE(a.contains(a));
  EXPECT_TRUE(a.contains(Box{}));
  EXPECT_FALSE(Box{}.contains(a));
  EXPECT_FALSE(a.contains(Box{{0, 0, 0}, {1, 1, 1.5}}));
  Box n = a;
  n.lo[1] = std::nan("");
  EXPECT_TRUE(n.empty());
}

}  // namespace
}  // namespace smr::index
