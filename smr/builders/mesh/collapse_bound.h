// A collapse's guaranteed two-sided Hausdorff bound (qem_pm.h, "Error"): each new triangle's
// bound e(T) to the source surface, from the old star's bounds and the distances between the
// two stars (star_distance.h). These bounds are the geometric error the splits are ordered by
// (Brown 4.4.3.3) and that the object-space criterion compares (Brown 4.6.2).
#pragma once

#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "smr/builders/mesh/pm_mesh.h"
#include "smr/builders/mesh/star_distance.h"

namespace smr::qem {

// What a collapse's bound depends on, copied out of the mesh so that it can be computed on
// another thread while the mesh changes: the old star (the removed vertex's triangles), each
// with its corners, which of them is the removed vertex, its bound, the bound of the collapse
// that made it and whether it has the kept vertex; the two vertices' positions.
struct StarSnapshot {
  struct OldTriangle {
    std::array<Vec3, 3> p;
    std::array<bool, 3> is_from{};
    double e = 0.0, creator_error = 0.0;
    bool has_to = false;
  };
  std::vector<OldTriangle> star;
  Vec3 from{0.0}, to{0.0};
};

// A collapse's bound's snapshot and buffers (star_bound): one per thread computing bounds.
struct BoundScratch {
  StarSnapshot snap;
  std::vector<StarDistance::Target> old_targets, new_targets;
  StarDistance to_new, to_old;          // the forward and backward bounds
  std::vector<std::uint32_t> image;     // old star index -> its new triangle
  std::vector<std::uint32_t> preimage;  // new triangle -> its old star index
  std::vector<std::pair<double, std::size_t>> order;
  std::vector<double> new_e;   // new triangle -> its bound
  std::uint64_t computed = 0;  // bounds computed (QemPmStats::bounds_computed)
};

/// What the bound of collapsing `from` onto `to` depends on, copied out of the mesh.
void snapshot(const PmMesh& m, const CollapseLog& log, std::uint32_t from, std::uint32_t to,
              StarSnapshot& snap);

/// The bound of s.snap's collapse (second: true; s.new_e then holds its new triangles'), or a
/// lower bound of it once one exceeds `tolerance` (second: false), found without computing it:
/// the bound of a collapse it depends on, or the largest bound of an old triangle plus the
/// removed vertex's distance to the new star (the removed vertex is a corner of every old
/// triangle, so the cell holding it is charged at least that triangle's bound plus that
/// distance, free or not: StarDistance::charge). Unless `finish`, a bound found part way to
/// exceed `tolerance` is not finished either: over a third of the bounds the banded
/// simplification computes do, and that collapse waits all the same. Infinite when the collapse
/// has no new star. Reads nothing but `s`, so it runs on any thread.
std::pair<double, bool> star_bound(double tolerance, bool finish, BoundScratch& s);

/// snapshot() then star_bound().
std::pair<double, bool> bound_within(const PmMesh& m, const CollapseLog& log, std::uint32_t from,
                                     std::uint32_t to, double tolerance, bool finish,
                                     BoundScratch& s);

}  // namespace smr::qem
