// An independent oracle for self-intersections of a triangle mesh: CGAL's
// Polygon_mesh_processing::self_intersections (pairs of faces that meet anywhere but in a shared
// vertex or edge), not the builder's own test (smr/builders/mesh/exact_intersection.h).
#pragma once

#include <array>
#include <cstddef>
#include <vector>

#include "smr/core/geometry.h"

namespace smr::test {

/// Pairs of triangles that cross each other. Corners at the same position are the same vertex;
/// the triangles must form an oriented manifold surface (a source mesh or a cut of one).
std::size_t crossing_pairs(const std::vector<std::array<Vec3, 3>>& triangles);

}  // namespace smr::test
