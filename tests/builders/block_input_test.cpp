// The block mesh builder's out-of-core input (smr/builders/mesh/block_input.h) on CGAL's
// armadillo: every triangle reaches exactly one leaf, in input order, with each of its vertices
// (position, lock span) in that leaf; and the memory it holds stays within its options whatever
// the input's size (issue 38: `--memory` bounds mesh ingest), measured as the growth of a child
// process's peak resident set.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <string>

#include <gtest/gtest.h>

#include "smr/builders/mesh/block_input.h"
#include "smr/core/mesh.h"
#include "smr/io/mesh_reader.h"
#include "tests/support/datasets.h"
#include "tests/support/sanitized.h"

namespace smr::qem {
namespace {

const TriangleMesh& armadillo() {
  static const TriangleMesh m = read_mesh(test::mesh_path("armadillo.off"));
  return m;
}

// kB of a /proc/self/status field ("VmRSS", "VmHWM").
long status_kib(const char* field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  const std::string key = std::string(field) + ":";
  while (std::getline(in, line)) {
    if (line.rfind(key, 0) == 0) return std::stol(line.substr(key.size()));
  }
  return -1;
}

TEST(BlockInput, EveryTriangleReachesOneLeafWithItsVertices) {
  const TriangleMesh& mesh = armadillo();
  BlockInputOptions o;
  o.leaf_triangles = 1000;
  o.sort_bytes = 64 << 10;                         // the three sorts spill
  o.vertex_cache_bytes = 4 * 2048 * sizeof(Vec3);  // the least: 4 pages
  BlockInput input(MemoryMeshStream(mesh, "armadillo"), o);
  EXPECT_EQ(input.triangles(), mesh.triangles.size());
  EXPECT_EQ(input.vertices(), mesh.positions.size());
  EXPECT_GT(input.page_reads(), 4u);
  // Each vertex's cells, from the leaves' triangles.
  std::vector<std::uint32_t> lo(mesh.positions.size(), ~0u), hi(mesh.positions.size(), 0);
  std::map<std::array<std::uint32_t, 3>, int> seen;
  std::vector<std::pair<std::uint32_t, LeafVertex>> given;  // (cell, vertex) as the leaves had them
  LeafInput leaf;
  std::uint64_t leaves = 0;
  std::int64_t last_cell = -1;
  while (input.next_leaf(leaf)) {
    ++leaves;
    EXPECT_GT(std::int64_t(leaf.cell), last_cell) << "leaves in Morton order, each once";
    last_cell = leaf.cell;
    std::vector<std::uint32_t> used;
    for (const auto& f : leaf.faces) {
      ++seen[f];
      used.insert(used.end(), f.begin(), f.end());
      for (std::uint32_t v : f)
        lo[v] = std::min(lo[v], leaf.cell), hi[v] = std::max(hi[v], leaf.cell);
    }
    std::sort(used.begin(), used.end());
    used.erase(std::unique(used.begin(), used.end()), used.end());
    ASSERT_EQ(leaf.verts.size(), used.size()) << "cell " << leaf.cell;
    for (std::size_t i = 0; i < used.size(); ++i) {
      EXPECT_EQ(leaf.verts[i].id, used[i]);
      EXPECT_EQ(leaf.verts[i].pos, mesh.positions[used[i]]);
      given.push_back({leaf.cell, leaf.verts[i]});
    }
  }
  EXPECT_EQ(leaves, input.leaf_cells());
  EXPECT_GT(leaves, 8u);
  ASSERT_EQ(seen.size(), mesh.triangles.size());
  for (const auto& t : mesh.triangles) EXPECT_EQ(seen[t], 1);
  for (const auto& [cell, v] : given) {
    EXPECT_EQ(v.lo, lo[v.id]) << "vertex " << v.id;
    EXPECT_EQ(v.hi, hi[v.id]) << "vertex " << v.id;
  }
  EXPECT_GT(input.temp_bytes(), 0u);
}

// Reads armadillo subdivided twice (832 000 triangles, 416 002 vertices: a table of 32 bytes a
// vertex, as the builder once kept, would be 12.7 MiB) through BlockInput with 256 KiB sorts in
// a child process, and returns the growth of its peak resident set (KiB) over what it held
// before, or -1 if the child failed. The mesh is made before the fork: its pages are the
// parent's, resident in the child from the start.
long input_peak_growth_kib(const TriangleMesh& mesh, std::uint64_t* triangles_read) {
  int fd[2];
  if (pipe(fd) != 0) return -1;
  const pid_t pid = fork();
  if (pid == 0) {
    close(fd[0]);
    long out[2] = {-1, 0};
    std::FILE* f = std::fopen("/proc/self/clear_refs", "w");  // 5: reset the peak to now
    const bool reset = f != nullptr && std::fputs("5", f) >= 0;
    if (f != nullptr) std::fclose(f);
    const long before = status_kib("VmRSS");
    try {
      BlockInputOptions o;
      o.leaf_triangles = 4096;
      o.sort_bytes = o.vertex_cache_bytes = 256 << 10;
      BlockInput input(MemoryMeshStream(mesh, "sub2"), o);
      LeafInput leaf;
      while (input.next_leaf(leaf)) out[1] += static_cast<long>(leaf.faces.size());
      if (reset) out[0] = status_kib("VmHWM") - before;
    } catch (...) {
    }
    const ssize_t w = write(fd[1], out, sizeof out);
    _exit(w == sizeof out ? 0 : 1);
  }
  close(fd[1]);
  long got[2] = {-1, 0};
  const ssize_t r = read(fd[0], got, sizeof got);
  close(fd[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  if (r != sizeof got) return -1;
  *triangles_read = static_cast<std::uint64_t>(got[1]);
  return got[0];
}

TEST(BlockInput, HoldsWhatItsOptionsSayWhateverTheInputSize) {
  // Under the sanitizers (3-10x slower) the code path only, on a quarter of the triangles.
  const TriangleMesh once = midpoint_subdivided(armadillo());
  const TriangleMesh mesh = test::kSanitized ? once : midpoint_subdivided(once);
  std::uint64_t read = 0;
  const long growth = input_peak_growth_kib(mesh, &read);
  ASSERT_GE(growth, 0) << "the child failed, or /proc/self/clear_refs cannot reset the peak";
  EXPECT_EQ(read, mesh.triangles.size());
  // Two sorts and the cache of 256 KiB at a time, the vertex file's 4 MiB write buffer, one
  // leaf's triangles: 6 MiB, with 2 MiB for what the allocator keeps (measured: 5.0 MiB). A table
  // of 32 bytes a vertex would be 12.7 MiB more. Under AddressSanitizer freed memory waits in
  // its quarantine and shadow memory is resident too: only the code path is checked there.
  if (!test::kSanitized) {
    EXPECT_LE(growth, 8 * 1024) << "KiB";
  }
}

}  // namespace
}  // namespace smr::qem
