// The builder's exact triangle-triangle test (smr/build/exact_intersection.h): what two triangles
// of a mesh may share (corners and edges by vertex id) and what counts as crossing.
#include "smr/build/exact_intersection.h"

#include <gtest/gtest.h>

namespace smr {
namespace {

MeshTriangle tri(Vec3 a, Vec3 b, Vec3 c, std::uint32_t ia, std::uint32_t ib, std::uint32_t ic) {
  return {{a, b, c}, {ia, ib, ic}};
}

// A = the right triangle (0,0,0) (2,0,0) (0,2,0), vertex ids 0 1 2.
const MeshTriangle kA = tri({0, 0, 0}, {2, 0, 0}, {0, 2, 0}, 0, 1, 2);

TEST(TrianglesCross, ApartTouchingAndPiercingWithNothingShared) {
  EXPECT_FALSE(triangles_cross(kA, tri({0, 0, 1}, {2, 0, 1}, {0, 2, 1}, 3, 4, 5)));  // above
  EXPECT_TRUE(triangles_cross(kA, tri({0.5, 0.5, -1}, {0.5, 0.5, 1}, {3, 3, 0}, 3, 4, 5)));
  // A corner of B touching A's interior is a crossing: only shared vertices may meet.
  EXPECT_TRUE(triangles_cross(kA, tri({0.5, 0.5, 0}, {0.5, 0.5, 1}, {1, 1, 1}, 3, 4, 5)));
  EXPECT_FALSE(triangles_cross(kA, tri({3, 3, 0}, {4, 3, 0}, {3, 4, 0}, 3, 4, 5)));  // coplanar
}

TEST(TrianglesCross, ASharedCornerIsAllowedAnythingMoreIsNot) {
  // A fan around vertex 0: the other triangle leaves A's plane at once.
  EXPECT_FALSE(triangles_cross(kA, tri({0, 0, 0}, {0, 2, 1}, {2, 0, 1}, 0, 7, 8)));
  // Its edge opposite the shared corner pierces A at (1, 0.5, 0).
  EXPECT_TRUE(triangles_cross(kA, tri({0, 0, 0}, {1, 0.5, -1}, {1, 0.5, 1}, 0, 7, 8)));
  // Coplanar and overlapping around the shared corner (A's far edge crosses it).
  EXPECT_TRUE(triangles_cross(kA, tri({0, 0, 0}, {2, 1, 0}, {1, 2, 0}, 0, 7, 8)));
  // Coplanar across the edge they share (vertices 0 and 2).
  EXPECT_FALSE(triangles_cross(kA, tri({0, 0, 0}, {0, 2, 0}, {-2, 0, 0}, 0, 2, 9)));
  // The same corner under another id (a repeated position) is shared too.
  EXPECT_FALSE(triangles_cross(kA, tri({0, 0, 0}, {0, 2, 1}, {2, 0, 1}, 6, 7, 8)));
  EXPECT_TRUE(triangles_cross(kA, tri({0, 0, 0}, {1, 0.5, -1}, {1, 0.5, 1}, 6, 7, 8)));
  // Crossing by 1e-30 either side of A's plane: below what double arithmetic can tell, so the
  // exact predicates decide.
  EXPECT_TRUE(triangles_cross(kA, tri({0, 0, 0}, {1, 0.2, 1e-30}, {0.2, 1, -1e-30}, 0, 7, 8)));
  EXPECT_FALSE(triangles_cross(kA, tri({0, 0, 0}, {1, 0.2, 1e-30}, {0.2, 1, 1e-30}, 0, 7, 8)));
}

TEST(TrianglesCross, ASharedEdgeIsAllowedAFoldOntoEachOtherIsNot) {
  const MeshTriangle a = tri({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 0, 1, 2);
  EXPECT_FALSE(triangles_cross(a, tri({1, 0, 0}, {0, 0, 0}, {0.5, -1, 0}, 1, 0, 3)));     // flat
  EXPECT_FALSE(triangles_cross(a, tri({1, 0, 0}, {0, 0, 0}, {0.5, 0.3, 0.5}, 1, 0, 3)));  // sharp
  EXPECT_TRUE(triangles_cross(a, tri({1, 0, 0}, {0, 0, 0}, {0.5, 0.3, 0}, 1, 0, 3)));     // folded
  EXPECT_TRUE(triangles_cross(a, a));  // the same triangle twice
}

TEST(TrianglesCross, ADegenerateTriangleNeverCrosses) {
  EXPECT_FALSE(triangles_cross(kA, tri({0.5, 0.5, -1}, {0.5, 0.5, 0}, {0.5, 0.5, 1}, 3, 4, 5)));
}

}  // namespace
}  // namespace smr
