// The streamed mesh builder's share of a memory budget (smr/ingest/memory_budget.h): leaf blocks
// sized from the budget, since a block being simplified takes ~300 bytes a triangle and the
// threads' leaves and a parent of 8 leaves' worth are alive at once (issue 38).
#include <gtest/gtest.h>

#include "smr/builders/mesh/qem_pm.h"
#include "smr/ingest/memory_budget.h"

namespace smr {
namespace {

constexpr std::uint64_t MiB = std::uint64_t{1} << 20;

TEST(MeshBudget, LeafBlocksFollowTheBudget) {
  EXPECT_EQ(divide({}, IngestPath::kBlockPm).leaf_triangles, BlockPmOptions{}.leaf_triangles);
  EXPECT_EQ(divide({32 * MiB}, IngestPath::kBlockPm).leaf_triangles, 4096u);
  EXPECT_EQ(divide({64 * MiB}, IngestPath::kBlockPm).leaf_triangles, 8192u);
  EXPECT_EQ(divide({100 * MiB}, IngestPath::kBlockPm).leaf_triangles, 8192u);
  EXPECT_EQ(divide({256 * MiB}, IngestPath::kBlockPm).leaf_triangles, 32768u);
  EXPECT_EQ(divide({512 * MiB}, IngestPath::kBlockPm).leaf_triangles, 65536u);
  EXPECT_EQ(divide({64 * 1024 * MiB}, IngestPath::kBlockPm).leaf_triangles, 65536u);
  // A leaf's worth of blocks (threads' leaves and a parent of 8, ~300 bytes a triangle, two
  // threads) stays within half the budget.
  for (std::uint64_t m : {32 * MiB, 80 * MiB, 300 * MiB, 2048 * MiB}) {
    EXPECT_LE(divide({m}, IngestPath::kBlockPm).leaf_triangles * 300 * 11, m / 2) << m;
  }
  // The terrain path leaves it alone.
  EXPECT_EQ(divide({32 * MiB}, IngestPath::kBlockTin).leaf_triangles, 0u);
}

}  // namespace
}  // namespace smr
