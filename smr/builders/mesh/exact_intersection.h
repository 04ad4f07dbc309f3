// Exact triangle-triangle intersection for the mesh builders (CGAL's filtered exact predicates,
// wrapped here so that no other file of the QEM builder includes CGAL).
#pragma once

#include <array>
#include <cstdint>

#include "smr/core/geometry.h"

namespace smr {

/// A triangle of a mesh: its corners and their vertex ids. Corners with equal ids or equal
/// positions are the same vertex (a mesh may repeat a position under two ids).
struct MeshTriangle {
  std::array<Vec3, 3> p;
  std::array<std::uint32_t, 3> id;
};

/// Whether two triangles of a mesh meet anywhere but in the vertices they share: a shared
/// corner or a shared edge is allowed; crossing, touching elsewhere or folding onto each other
/// across the shared edge is not. Exact (no tolerance). A degenerate triangle (collinear
/// corners) is never reported: it has no interior to cross.
bool triangles_cross(const MeshTriangle& a, const MeshTriangle& b);

}  // namespace smr
