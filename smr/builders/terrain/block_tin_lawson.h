// The block TIN builder's Delaunay repair across the leaf blocks' borders (block_tin.h, step 1).
//
// Each leaf's greedy TIN is Delaunay, but their union need not be across the border lines (each
// leaf saw only its own vertices). Lawson's flips (Lawson 1977, "Software for C1 surface
// interpolation": an edge whose opposite vertex lies in the other triangle's circumcircle is
// flipped until none is left), of edges between two data triangles so that the voids keep their
// shape, make M^m Delaunay; a flipped triangle whose exact bound exceeds the
// error gets its worst sample inserted, greedy-insertion style (Garland & Heckbert 1995, "Fast
// polygonal approximation of terrains and height fields"; Brown 7.1.1), and the triangles around
// it are legalised again. The samples on an edge that existed before are within the error (its
// interpolation is unchanged), so that sample lies inside the triangle or on a new edge between
// two data triangles. Vertex removal with Delaunay holes then keeps every mesh of the hierarchy
// Delaunay, so every fragment meets the Delaunay criterion and so does every extracted mesh
// (Brown Theorem 5.1.4).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "smr/builders/terrain/block_tin_mesh.h"
#include "smr/builders/terrain/sample_spill.h"

namespace smr::block_tin {

/// An edge to legalise: (a, b) of triangle t, if t still has it (either way round).
struct EdgeTask {
  std::uint32_t t, a, b;
};

/// Thrown by the Delaunay repair of an interleaved leaf pass when it reaches a triangle already
/// handed to a level-0 block: the build starts again without interleaving.
struct LeafConflict {};

/// A triangle the Delaunay repair of an interleaved leaf pass may no longer look at: given to
/// a level-0 block, or made or replaced by one.
inline bool handed_out(const MTri& m) {
  return m.copied || m.creator != kNone || m.destroyer != kNone;
}

/// The repair of the whole mesh, its samples read through `tiles` (it works along borders).
class LawsonRepair {
 public:
  /// `leaf_vertices`: the interleaved leaf pass's vertices per leaf block, which the inserted
  /// samples join (each a candidate of its leaf's level-0 block); null otherwise.
  LawsonRepair(const Setup& setup, Mesh& mesh, const SampleSpill& spill, SampleSpill::Cache& tiles,
               std::vector<std::vector<std::uint32_t>>* leaf_vertices, BlockTinStats& stats)
      : setup_(setup),
        mesh_(mesh),
        spill_(spill),
        tiles_(tiles),
        leaf_vertices_(leaf_vertices),
        stats_(stats) {}

  /// Every edge on a border line between two leaf blocks, legalised (the plain leaf pass).
  void make_borders_delaunay();

  /// Legalises the edges of `stack` and bounds the flipped triangles, inserting samples where
  /// they exceed the error. Triangles whose bound is to be computed go in waves sorted by place
  /// (so the tile cache reads each tile about once): a triangle changed after its turn goes to
  /// the next wave, so the last computation of each is of its final shape.
  void repair(std::vector<EdgeTask>& stack);

 private:
  void legalise(std::vector<EdgeTask>& stack, std::vector<std::uint32_t>& stale);
  void insert_sample(std::uint32_t t, int col, int row, float z, std::vector<EdgeTask>& stack,
                     std::vector<std::uint32_t>& stale);
  void set_triangle(std::uint32_t t, const std::array<std::uint32_t, 3>& v,
                    const std::array<std::uint32_t, 3>& nbr);

  const Setup& setup_;
  Mesh& mesh_;
  const SampleSpill& spill_;
  SampleSpill::Cache& tiles_;
  std::vector<std::vector<std::uint32_t>>* leaf_vertices_;
  BlockTinStats& stats_;
};

}  // namespace smr::block_tin
