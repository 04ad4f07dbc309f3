// The legal half-edge collapses (Hoppe et al. 1993; Dey et al. 1999's link condition; Garland &
// Heckbert 1997, 6.1 boundaries and 6.2 mesh inversion): collapse_rules.h.
#include "smr/builders/mesh/collapse_rules.h"

#include <array>
#include <cmath>

namespace smr::qem {
namespace {

// Link condition: the common neighbours of from and to are exactly the edge's opposite vertices
// (`shared` of them; with a virtual vertex joined to the boundary, Dey et al.).
bool link_condition(const PmMesh& m, Marks& marks, std::uint32_t to,
                    const std::vector<std::uint32_t>& nf, std::array<std::uint32_t, 2> opposite,
                    std::uint32_t shared) {
  const std::uint32_t in_nf = marks.next();
  for (std::uint32_t w : nf) marks.of[w] = in_nf;
  const std::uint32_t counted = marks.next();
  std::uint32_t common = 0;
  for (std::uint32_t id : m.star[to]) {
    for (std::uint32_t w : m.tris[id].v) {
      if (w == to || marks.of[w] != in_nf) continue;
      marks.of[w] = counted;
      if (w != opposite[0] && w != opposite[1]) return false;
      ++common;
    }
  }
  return common == shared;
}

// No triangle of from's star may flip, turn too far or degenerate when `from` moves onto `to`.
bool no_flip(const PmMesh& m, double cos_max_turn, std::uint32_t from, std::uint32_t to) {
  for (std::uint32_t id : m.star[from]) {
    const Tri& t = m.tris[id];
    if (has(t, to)) continue;
    const Vec3 before = normal(m, t.v), after = normal(m, corners_after(t, from, to));
    const double lb = glm::length(before), la = glm::length(after);
    if (!(la > 1e-12 * (lb + 1e-300)) || !(la > 0.0)) return false;
    if (lb > 0.0 && glm::dot(before, after) < cos_max_turn * lb * la) return false;
  }
  return true;
}

}  // namespace

double max_turn_cosine(double degrees) {
  return std::cos(degrees * 3.14159265358979323846 / 180.0);
}

bool collapse_allowed(const PmMesh& m, Marks& marks, double cos_max_turn, std::uint32_t from,
                      std::uint32_t to, const std::vector<std::uint32_t>& nf, QemPmStats& stats) {
  // A block's locked vertices stay, and a collapse needs its target's whole star (the link
  // condition), which a locked vertex has only partly in the block.
  if (is_locked(m, from) || is_locked(m, to)) return false;
  std::uint32_t shared = 0;
  std::array<std::uint32_t, 2> opposite{kNone, kNone};
  std::uint32_t replaced = 0;
  for (std::uint32_t id : m.star[from]) {
    const Tri& t = m.tris[id];
    if (has(t, to)) {
      if (shared < 2) {
        for (std::uint32_t w : t.v) {
          if (w != from && w != to) opposite[shared] = w;
        }
      }
      ++shared;
    } else {
      ++replaced;
    }
  }
  if (shared == 0 || shared > 2 || replaced == 0) return false;
  const bool boundary_edge = shared == 1;
  if (m.boundary[from] && !boundary_edge) {
    ++stats.rejected_boundary;
    return false;
  }
  if (!component_can_shrink(m, from)) return false;
  if (!link_condition(m, marks, to, nf, opposite, shared)) {
    ++stats.rejected_link;
    return false;
  }
  if (!no_flip(m, cos_max_turn, from, to)) {
    ++stats.rejected_flip;
    return false;
  }
  return true;
}

}  // namespace smr::qem
