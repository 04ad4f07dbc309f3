// Local morphs for geomorphing sessions (Brown ch. 6, 6.2): the geometry that takes the triangles
// a session update removes (at t = 0) to the triangles it adds (at t = 1), for any builder.
//
// Brown morphs op by op with routines each builder supplies (MorphCoarsen / MorphRefine: for
// Delaunay insertion, originators and edge-swap points recorded at build time). We keep his
// ordering (the session coarsens then refines, smr/extract/session.h) but morph the whole changed
// region at once, with geometry derived from the ops alone, so no builder records anything:
//
// - 2.5-D (terrain_morph): the common refinement of the two triangulations of the changed region
//   in the plane. Each piece (a removed triangle intersected with an added one, a convex polygon)
//   is triangulated; every vertex keeps its xy and moves vertically from the removed surface's
//   height to the added surface's. At t = 0 the surface IS the removed triangles', at t = 1 the
//   added ones' (exactly, up to float rounding of the heights); xy never moves, so at every t the
//   pieces tile the region with no overlap, gap, T-junction or flip.
// - 3-D (mesh_morph): the mesh of X_prev union X_new (a refinement of both meshes), restricted to
//   the changed region. A vertex introduced by an op that only one side has is collapsed, on the
//   side that lacks it, to its originator: the vertex its op's half-edge collapse moved it to
//   (Hoppe 1996/1997 geomorphs), found from F(R) and PreF(R) (the collapse map taking F onto
//   PreF), recursively (an originator may itself be collapsed). Components that refinement spawns
//   (Brown 4.4.1, Fig. 4.9d; no PreF) grow from their centroid.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "smr/core/geometry.h"
#include "smr/core/op_source.h"

namespace smr {

struct MorphMesh {
  static constexpr std::uint8_t kVoidStart = 1;  // the piece lies in a void triangle at t = 0
  static constexpr std::uint8_t kVoidEnd = 2;    // ... at t = 1

  std::vector<Vec3> start, end;      // per vertex: its position at t = 0 and at t = 1
  std::vector<std::uint32_t> group;  // per vertex: its morph group (one connected changed region)
  std::vector<std::array<std::uint32_t, 3>> triangles;  // counter-clockwise (from +z / outside)
  std::vector<std::uint8_t> flags;                      // per triangle
  std::uint32_t groups = 0;
  /// Vertices whose start or end could not be derived exactly (3-D: no collapse map found; they
  /// start at the nearest vertex of their op's PreF instead).
  std::uint64_t inexact_vertices = 0;

  /// Vertex v at time t in [0, 1]: exactly `start` at t = 0 and exactly `end` at t = 1.
  Vec3 at(std::size_t v, double t) const { return (1.0 - t) * start[v] + t * end[v]; }
};

/// 2.5-D: the morph from the surface of `out` (t = 0) to that of `in` (t = 1). Both must cover the
/// same region of the domain (a session update's triangles out and in); each is conforming.
/// Vertices are shared (one per point of the plane, corners keep their stored xy); triangles are
/// the pieces' (an out triangle meets an in one), each with positive area. Linear in the pieces.
/// Throws smr::Error (kInvalidInput) when an in triangle overlaps no out triangle or a grid
/// coordinate reaches 2^28.
MorphMesh terrain_morph(const OpSource& source, std::span<const TriRef> out,
                        std::span<const TriRef> in);

/// 3-D: the morph between the meshes of X_prev and X_new, given `in_union` (membership of
/// X_prev union X_new), `added` (X_new \ X_prev) and `removed` (X_prev \ X_new). Triangles: those
/// of F(R), R added or removed, whose killer is not in the union; one vertex per vertex id. At
/// t = 0 the non-degenerate ones are the changed part of X_prev's mesh, at t = 1 of X_new's.
/// Linear interpolation can fold a triangle whose corners head for different originators.
MorphMesh mesh_morph(const OpSource& source, const std::function<bool(OpId)>& in_union,
                     std::span<const OpId> added, std::span<const OpId> removed);

}  // namespace smr
