// The self-intersection rule (collapse_crossings.h): exact triangle-triangle tests of a new star
// against the live triangles near it, and against the dead ones that a cut at one error can show
// with it (Brown 4.6.2, 5.1: a cut mixes states of the simplification).
#include "smr/builders/mesh/collapse_crossings.h"

#include <algorithm>
#include <array>
#include <limits>

namespace smr::qem {
namespace {

MeshTriangle mesh_triangle(const PmMesh& m, const std::array<std::uint32_t, 3>& v) {
  return {{m.pos[v[0]], m.pos[v[1]], m.pos[v[2]]}, v};
}

// Whether a triangle of from's star (the old star) already crosses `other`: a crossing the
// source had (or one that came from it) may be reshaped by a collapse, not made.
bool crossed_before(const PmMesh& m, std::uint32_t from, const MeshTriangle& other) {
  for (std::uint32_t id : m.star[from]) {
    if (triangles_cross(mesh_triangle(m, m.tris[id].v), other)) return true;
  }
  return false;
}

// The grid over the live triangles, made at the first test: cells of twice the mean edge
// length (a new star then spans 2-3 cells a side; at the mean length, 4: 1 % more instructions).
void build_grid(Crossings& c, const PmMesh& m) {
  Box3 bounds;
  double edges = 0.0;
  std::size_t count = 0;
  for (const Tri& t : m.tris) {
    if (t.destroyer != kNone) continue;
    for (int k = 0; k < 3; ++k) {
      bounds.add(m.pos[t.v[std::size_t(k)]]);
      edges += glm::length(m.pos[t.v[std::size_t(k)]] - m.pos[t.v[std::size_t((k + 1) % 3)]]);
      ++count;
    }
  }
  const Vec3 origin = bounds.empty() ? Vec3(0.0) : bounds.lo;
  const double cell = count ? 2.0 * edges / double(count) : 1.0;
  c.grid.reset(origin, cell);
  for (std::uint32_t id = 0; id < m.tris.size(); ++id) {
    if (m.tris[id].destroyer == kNone) c.grid.insert(id, box_of(m, m.tris[id].v), c.kNear);
  }
  c.grid_ready = true;
}

// Marks (s.collapse_marks, with the returned value) the collapses that collapsing `from` would
// depend on, directly or not, whose bounds exceed `above`.
std::uint32_t mark_dependencies(CrossingScratch& s, const PmMesh& m, const CollapseLog& log,
                                std::uint32_t from, double above) {
  if (s.collapse_marks.of.size() < log.collapses.size())
    s.collapse_marks.of.resize(log.collapses.size() * 3 / 2 + 16, 0);
  const std::uint32_t mark = s.collapse_marks.next();
  s.dependency_stack.clear();
  const auto reach = [&](std::uint32_t id) {
    const std::uint32_t c = m.tris[id].creator;
    if (c == kNone || s.collapse_marks.of[c] == mark || !(log.collapses[c].error > above)) return;
    s.collapse_marks.of[c] = mark;
    s.dependency_stack.push_back(c);
  };
  for (std::uint32_t id : m.star[from]) reach(id);
  while (!s.dependency_stack.empty()) {
    const Collapse& d = log.collapses[s.dependency_stack.back()];
    s.dependency_stack.pop_back();
    for (std::uint32_t k = d.old_begin; k < d.old_end; ++k) reach(log.old_tris[k]);
  }
  return mark;
}

// Mixed levels. A cut at one error (every op whose error exceeds it, refined) holds triangles
// of several states of the simplification: that of a split whose error exceeds the cut's and
// that of one whose error does not, whatever the order they were made in. Triangle X,
// destroyed by collapse x, and a new triangle Y of collapse c (bound b) are in one such cut
// only if x's op error exceeds c's. Op errors are at least the collapse's bound and, coalesced
// (a split joins an op whose error is at most 1/r of its bound, r = coalesce_error_ratio) and
// raised to their children's, at most 1/r of it: so only if b(x) > r b. And never if c depends
// on x (its op is an ancestor of x's): bounds do not rise along dependencies (star_bound's
// floor), so the collapses c depends on with bounds above r b are found from c's star through
// collapses with bounds above r b alone. The live triangles are tested in crosses_after; here,
// the new star against the dead triangles of the other collapses with b(x) > r b (dead_near,
// found by crosses_after's grid query). With this, no cut at one error crosses where the
// source does not (cuts of varying error are not covered: two triangles from states apart in
// the order, far apart in error, are never tested).
bool crosses_dead(CrossingScratch& s, const PmMesh& m, const CollapseLog& log, QemPmStats& stats,
                  std::uint32_t from, double above) {
  bool depends_known = false;
  std::uint32_t depends = 0;
  for (const auto& [id, box] : s.dead_near) {
    if (!depends_known) {
      depends = mark_dependencies(s, m, log, from, above);
      depends_known = true;
    }
    if (s.collapse_marks.of[m.tris[id].destroyer] == depends) continue;
    const MeshTriangle other = mesh_triangle(m, m.tris[id].v);
    for (std::size_t i = 0; i < s.made.size(); ++i) {
      if (!box.intersects(s.made_boxes[i])) continue;
      if (triangles_cross(s.made[i], other) && !crossed_before(m, from, other)) {
        ++stats.rejected_mixed_levels;
        return true;
      }
    }
  }
  return false;
}

// s.made and s.made_boxes = the new star of collapsing from -> to; returns the box of them all.
Box3 make_new_star(CrossingScratch& s, const PmMesh& m, std::uint32_t from, std::uint32_t to) {
  s.made.clear();
  for (std::uint32_t id : m.star[from]) {
    const Tri& t = m.tris[id];
    if (has(t, to)) continue;
    s.made.push_back(mesh_triangle(m, corners_after(t, from, to)));
  }
  Box3 all;
  s.made_boxes.clear();
  for (const MeshTriangle& t : s.made) {
    Box3 b;
    for (const Vec3& p : t.p) b.add(p);
    s.made_boxes.push_back(b);
    all.add(b);
  }
  return all;
}

}  // namespace

bool crosses_after(Crossings& c, const PmMesh& m, const CollapseLog& log, QemPmStats& stats,
                   std::uint32_t from, std::uint32_t to, double error) {
  if (!c.enabled) return false;
  if (!c.grid_ready) build_grid(c, m);
  CrossingScratch& s = c.scratch;
  const Box3 all = make_new_star(s, m, from, to);
  if (s.tri_marks.of.size() < m.tris.size()) s.tri_marks.of.resize(m.tris.size() * 3 / 2, 0);
  const std::uint32_t old_star = s.tri_marks.next();
  for (std::uint32_t id : m.star[from]) s.tri_marks.of[id] = old_star;
  // The triangles near the new star (one grid query for all of it), then pair by pair. The
  // grid also holds the dead triangles of the recent bands (crosses_dead), by their
  // destroyers' bounds; they take no part in this test.
  s.near.clear();
  s.dead_near.clear();
  const double above = c.ratio * error;
  const auto sort_near = [&](std::uint32_t id, const Box3& tb) {
    const std::uint32_t destroyer = m.tris[id].destroyer;
    if (destroyer == kNone) {
      if (s.tri_marks.of[id] != old_star) s.near.push_back({id, tb});
    } else if (log.collapses[destroyer].error > above) {
      s.dead_near.push_back({id, tb});
    }
  };
  // Keys: live +inf, dead their destroyers' bounds. The grid passes over keys <= least: at most
  // the largest double, so that no live triangle is passed over even for an infinite bound.
  const double least = std::min(above, std::numeric_limits<double>::max());
  c.grid.visit(all, sort_near, c.kNear, least);
  if (c.archive_largest > above) c.grid.visit(all, sort_near, c.kArchive, least);
  bool crossed = false;
  for (std::size_t i = 0; i < s.made.size() && !crossed; ++i) {
    const MeshTriangle& t = s.made[i];
    for (std::size_t j = i + 1; j < s.made.size() && !crossed; ++j) {
      crossed = triangles_cross(t, s.made[j]);
    }
    for (std::size_t j = 0; j < s.near.size() && !crossed; ++j) {
      if (!s.near[j].second.intersects(s.made_boxes[i])) continue;
      const MeshTriangle other = mesh_triangle(m, m.tris[s.near[j].first].v);
      crossed = triangles_cross(t, other) && !crossed_before(m, from, other);
    }
  }
  if (!crossed && !s.dead_near.empty()) crossed = crosses_dead(s, m, log, stats, from, above);
  if (crossed) ++stats.rejected_intersection;
  return crossed;
}

void record_collapse(Crossings& c, const PmMesh& m, const CollapseLog& log) {
  if (!c.grid_ready) return;
  const Collapse& col = log.collapses.back();
  for (std::uint32_t k = col.old_begin; k < col.old_end; ++k) {
    c.dead.push_back(log.old_tris[k]);  // stays in the grid, dead (crosses_dead)
    c.grid.set_key(log.old_tris[k], col.error);
  }
  for (std::uint32_t k = col.new_begin; k < col.new_end; ++k) {
    const std::uint32_t id = log.new_tris[k];
    c.grid.insert(id, box_of(m, m.tris[id].v), c.kNear);
  }
}

void retire_dead(Crossings& c, const PmMesh& m, const CollapseLog& log, double least) {
  if (!c.grid_ready) return;
  const double below = c.ratio * least;
  std::size_t kept = 0;
  for (const std::uint32_t id : c.dead) {
    const double b = log.collapses[m.tris[id].destroyer].error;
    if (b > below) {
      c.dead[kept++] = id;
      continue;
    }
    c.grid.insert(id, box_of(m, m.tris[id].v), c.kArchive, b);  // out of kNear
    c.archive_largest = std::max(c.archive_largest, b);
  }
  c.dead.resize(kept);
}

}  // namespace smr::qem
