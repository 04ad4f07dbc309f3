// The invariant checker (smr/core/invariants.h, docs/design.md section 8) notices what it is meant
// to: a CRMR damaged on purpose fails the check.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <random>
#include <utility>
#include <vector>

#include "smr/core/invariants.h"
#include "tests/support/datasets.h"
#include "tests/support/sanitized.h"

namespace smr {
namespace {

TEST(Checker, NoticesPreFCornersThatDisagreeWithTheCreator) {
  // A dataset the sanitizer run builds anyway (it has no jacksboro).
  Crmr m = test::dataset(test::kSanitized ? "topobathy" : "jacksboro").crmr;
  Op& op = m.ops.at(m.ops.size() / 2);
  ASSERT_FALSE(op.pre_tris.empty());
  std::swap(op.pre_tris[0].v[0], op.pre_tris[0].v[1]);  // the same corners, other orientation
  EXPECT_FALSE(check_crmr(m).ok());
  std::swap(op.pre_tris[0].v[0], op.pre_tris[0].v[1]);
  op.pre_tris.pop_back();
  EXPECT_FALSE(check_crmr(m).ok());
}

// Fragments keep no neighbours (FragmentTriangle): fragment_neighbours derives them, by a scan up
// to 64 triangles and through a hash map beyond. Both agree with a brute-force search on strips of
// quads, their triangles shuffled: every diagonal and every inner rung joins two triangles.
TEST(FragmentNeighbours, AgreeWithBruteForceOnSmallAndLargeFragments) {
  for (const std::uint32_t quads : {5u, 30u, 200u}) {
    SCOPED_TRACE(std::to_string(2 * quads) + " triangles");
    std::vector<FragmentTriangle> f;
    for (std::uint32_t q = 0; q < quads; ++q) {  // vertices 2q (bottom), 2q + 1 (top)
      const std::uint32_t a = 2 * q, b = 2 * q + 2, c = 2 * q + 3, d = 2 * q + 1;
      for (const std::array<std::uint32_t, 3>& v :
           {std::array<std::uint32_t, 3>{a, b, c}, std::array<std::uint32_t, 3>{a, c, d}}) {
        FragmentTriangle t;
        t.v = v;
        f.push_back(t);
      }
    }
    std::shuffle(f.begin(), f.end(), std::mt19937(quads));
    std::vector<std::array<std::int32_t, 3>> nbr;
    fragment_neighbours(f, nbr);
    ASSERT_EQ(nbr.size(), f.size());
    std::size_t joined = 0;
    for (std::size_t i = 0; i < f.size(); ++i) {
      for (int k = 0; k < 3; ++k) {
        std::int32_t want = FragmentTriangle::kNoNeighbour;
        for (std::size_t j = 0; j < f.size() && want < 0; ++j) {
          for (int l = 0; l < 3; ++l) {
            if (f[j].v[l] == f[i].v[(k + 1) % 3] && f[j].v[(l + 1) % 3] == f[i].v[k])
              want = std::int32_t(j);
          }
        }
        EXPECT_EQ(nbr[i][k], want) << "triangle " << i << " edge " << k;
        joined += want >= 0;
      }
    }
    EXPECT_EQ(joined, 2 * (2 * quads - 1));  // quads diagonals and quads - 1 rungs, both sides
  }
}

}  // namespace
}  // namespace smr
