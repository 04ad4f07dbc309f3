// The block mesh builder's input (block_pm.h), out of core: a streamed mesh's triangles and
// vertices regrouped by octree leaf cell on disk, so that memory holds the sorts' buffers and a
// cache of vertex pages, never a table the size of the input.
//
//  1. The vertices go to a scratch file as they are read (their bounding box on the way).
//  2. Each triangle's corners are read back through an LRU cache of that file's pages (meshes
//     list nearby triangles' vertices near each other, so a page read serves many corners; any
//     order is correct, a scattered one is only slower), its centroid gives its leaf cell (a
//     Morton code), and the triangle goes to an external sort by cell, each corner (vertex, cell)
//     to one by vertex.
//  3. The corners, merged with the vertex file in vertex order, give each vertex its span of
//     cells (the first and last leaf cell of its triangles: what locks it, level by level) and
//     one record per distinct cell, with its position, to an external sort by (cell, vertex).
//  4. The leaves are read in cell order from the two sorts side by side: a leaf's triangles (in
//     input order) and their vertices (by id).
// Internal to smr/builders.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "smr/core/geometry.h"
#include "smr/core/mesh.h"
#include "storage/external_sort.h"
#include "storage/record_file.h"

namespace smr::qem {

struct FaceRecord {  // a source triangle and its leaf cell (Morton code)
  std::uint32_t cell = 0;
  std::array<std::uint32_t, 3> v{};
  bool operator<(const FaceRecord& o) const { return cell < o.cell; }
};

// A vertex as a leaf cell gets it: its position and the span of leaf cells of its triangles.
struct LeafVertex {
  std::uint32_t cell = 0;  // the leaf cell this copy goes to
  std::uint32_t id = 0;
  Vec3 pos;
  std::uint32_t lo = 0, hi = 0;  // first and last leaf cell (Morton) of its triangles
  bool operator<(const LeafVertex& o) const {
    return cell < o.cell || (cell == o.cell && id < o.id);
  }
};

// One leaf cell's input.
struct LeafInput {
  std::uint32_t cell = 0;
  std::vector<std::array<std::uint32_t, 3>> faces;  // in input order
  std::vector<LeafVertex> verts;                    // by id
};

struct BlockInputOptions {
  std::string tmp_dir;
  std::uint64_t leaf_triangles = 1 << 16;
  /// Memory of each of the three external sorts (faces, corners, leaf vertices).
  std::uint64_t sort_bytes = std::uint64_t{128} << 20;
  /// Memory of the cache of vertex pages read while the triangles' cells are found.
  std::uint64_t vertex_cache_bytes = std::uint64_t{16} << 20;
};

class BlockInput {
 public:
  /// Reads `mesh` (two passes) into the sorts. Throws smr::Error (input) on an empty mesh, a
  /// coordinate that is not finite, a corner index out of range.
  BlockInput(const MeshStream& mesh, const BlockInputOptions& options);
  ~BlockInput();

  /// The next leaf cell's input, in Morton order; false after the last.
  bool next_leaf(LeafInput& out);

  const Box3& box() const { return box_; }
  double side() const { return side_; }   // of the bounding cube
  int levels() const { return levels_; }  // octree levels above the leaves
  std::uint64_t vertices() const { return vertices_; }
  std::uint64_t triangles() const { return triangles_; }
  std::uint64_t leaf_cells() const { return leaf_cells_; }  // non-empty ones
  std::uint64_t referenced() const { return referenced_; }  // vertices some triangle uses
  const Box3& referenced_box() const { return referenced_box_; }
  /// Bytes written to scratch files so far.
  std::uint64_t temp_bytes() const;
  /// Vertex pages read (cache misses) while the cells were found.
  std::uint64_t page_reads() const { return page_reads_; }

 private:
  struct Corner {  // a triangle's corner: its vertex and the triangle's cell
    std::uint32_t v = 0, cell = 0;
    bool operator<(const Corner& o) const { return v < o.v || (v == o.v && cell < o.cell); }
  };
  using CornerSorter = storage::ExternalSorter<Corner, std::less<Corner>, storage::Ties::kAny>;
  using VertexSorter =
      storage::ExternalSorter<LeafVertex, std::less<LeafVertex>, storage::Ties::kAny>;

  void read_vertices();
  void sort_faces(CornerSorter& corners);
  void distribute(CornerSorter& corners);

  const MeshStream& mesh_;
  const BlockInputOptions options_;
  std::string dir_;
  std::unique_ptr<storage::RecordFile<Vec3>> positions_;
  std::unique_ptr<storage::ExternalSorter<FaceRecord>> faces_;
  std::unique_ptr<VertexSorter> verts_;
  Box3 box_, referenced_box_;
  double side_ = 1.0;
  int levels_ = 0;
  std::uint64_t vertices_ = 0, triangles_ = 0, leaf_cells_ = 0, referenced_ = 0;
  std::uint64_t page_reads_ = 0, spilled_ = 0;
  FaceRecord face_{};
  LeafVertex vert_{};
  bool more_faces_ = false, more_verts_ = false;
};

}  // namespace smr::qem
