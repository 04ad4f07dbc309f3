// The rules a half-edge collapse must pass (Hoppe et al. 1993, "Mesh optimization", its legal
// edge collapse; Garland & Heckbert 1997, sections 6.1 and 6.2): the link condition (Dey,
// Edelsbrunner, Guha & Nekhayev 1999, with a virtual vertex joined to the boundary), no
// flipped, over-turned or degenerate triangle, a boundary vertex only moves along its boundary,
// locked vertices stay and no component shrinks below a tetrahedron (closed) or a triangle
// (open). The self-intersection rule is collapse_crossings.h.
#pragma once

#include <cstdint>
#include <vector>

#include "smr/builders/mesh/pm_mesh.h"
#include "smr/builders/mesh/qem_pm.h"

namespace smr::qem {

/// cos(degrees): the least cosine of a triangle normal's turn that collapse_allowed() accepts.
double max_turn_cosine(double degrees);

/// Whether collapsing from -> to keeps the mesh a manifold of the same topology with no flipped
/// or degenerate triangle (counts the reason in `stats` when not). `nf` = neighbours(from);
/// `marks` is per vertex.
bool collapse_allowed(const PmMesh& m, Marks& marks, double cos_max_turn, std::uint32_t from,
                      std::uint32_t to, const std::vector<std::uint32_t>& nf, QemPmStats& stats);

}  // namespace smr::qem
