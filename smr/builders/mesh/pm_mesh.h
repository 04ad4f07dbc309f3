// The mesh under half-edge collapse (Hoppe 1996, "Progressive meshes", section 3's ecol, in
// its half-edge form: v' -> v, v keeps its position): per-vertex stars, quadrics, boundary
// flags and components, and the log of every collapse (the star it removed, the triangles it
// made) that emit (pm_emit.h) reverses into vertex-split ops (Brown 4.4.1).
// Internal to the QEM builders (qem_pm.h, block_pm.h).
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include <glm/geometric.hpp>

#include "smr/builders/mesh/quadric.h"
#include "smr/core/geometry.h"
#include "smr/core/id_map.h"
#include "smr/core/mesh.h"

namespace smr::qem {

inline constexpr std::uint32_t kNone = ~std::uint32_t{0};
inline constexpr std::uint64_t kNoEdge = ~std::uint64_t{0};

inline std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
  return (std::uint64_t(a) << 32) | b;
}

struct Tri {
  std::array<std::uint32_t, 3> v{};
  double e = 0.0;                   // two-sided Hausdorff bound to the source (qem_pm.h)
  std::uint32_t creator = kNone;    // collapse that made it (kNone: a source triangle)
  std::uint32_t destroyer = kNone;  // collapse that removed it (kNone: in the base mesh)
};

struct Collapse {
  // A component removal (its refinement spawns the component, Brown Fig. 4.9d) has kept == kNone,
  // no new triangles, and removes every vertex in spawn_vertices.
  std::uint32_t removed = 0, kept = 0;
  std::vector<std::uint32_t> spawn_vertices;
  std::uint32_t old_begin = 0, old_end = 0;  // into old_tris: the star of `removed` before
  std::uint32_t new_begin = 0, new_end = 0;  // into new_tris: the triangles that replaced it
  double error = 0.0;  // the largest bound of its new triangles, at least its creators' errors
};

// Set membership by stamps, without sorting or clearing: an element is in the current set when
// its stamp is the value next() last returned.
struct Marks {
  std::vector<std::uint32_t> of;
  std::uint32_t value = 0;
  std::uint32_t next() {
    if (++value == 0) {
      std::fill(of.begin(), of.end(), 0u);
      value = 1;
    }
    return value;
  }
};

// The mesh being simplified. Every triangle ever made stays in `tris` (the dead ones name their
// destroyer); a vertex's star holds its live triangles.
struct PmMesh {
  std::vector<Vec3> pos;
  std::vector<Tri> tris;
  std::vector<std::vector<std::uint32_t>> star;  // per vertex: its live triangles
  std::vector<std::uint32_t> star_version;       // per vertex: changes of its star
  std::vector<Quadric> quad;                     // per vertex (Garland & Heckbert)
  std::vector<std::uint8_t> removed, boundary;   // per vertex
  std::vector<std::uint8_t> locked;              // block builder: vertices that stay (empty: none)
  // Connected components: per vertex its component (kNone: unreferenced), per component its
  // live vertices and whether it has a boundary.
  std::vector<std::uint32_t> comp, comp_vertices;
  std::vector<std::uint8_t> comp_open;
};

// The collapses made, in order; old_tris and new_tris hold their stars' triangle ids.
struct CollapseLog {
  std::vector<Collapse> collapses;
  std::vector<std::uint32_t> old_tris, new_tris;
};

inline bool has(const Tri& t, std::uint32_t v) {
  return t.v[0] == v || t.v[1] == v || t.v[2] == v;
}
// t's corners once `from` has collapsed onto `to`.
inline std::array<std::uint32_t, 3> corners_after(const Tri& t, std::uint32_t from,
                                                  std::uint32_t to) {
  std::array<std::uint32_t, 3> v = t.v;
  for (std::uint32_t& w : v) {
    if (w == from) w = to;
  }
  return v;
}
inline Vec3 normal(const PmMesh& m, const std::array<std::uint32_t, 3>& v) {
  return glm::cross(m.pos[v[1]] - m.pos[v[0]], m.pos[v[2]] - m.pos[v[0]]);
}
inline Box3 box_of(const PmMesh& m, const std::array<std::uint32_t, 3>& v) {
  Box3 b;
  for (std::uint32_t w : v) b.add(m.pos[w]);
  return b;
}
inline bool is_locked(const PmMesh& m, std::uint32_t v) {
  return !m.locked.empty() && m.locked[v] != 0;
}
// Whether v's component may lose a vertex: no component shrinks below a tetrahedron (closed)
// or a triangle (open).
inline bool component_can_shrink(const PmMesh& m, std::uint32_t v) {
  const std::uint32_t c = m.comp[v];
  return m.comp_vertices[c] > (m.comp_open[c] ? 3u : 4u);
}
// The bound of the collapse that made triangle id (a source triangle's own).
inline double creator_error(const PmMesh& m, const CollapseLog& log, std::uint32_t id) {
  const Tri& t = m.tris[id];
  return t.creator == kNone ? t.e : log.collapses[t.creator].error;
}

/// The per-vertex arrays for m.pos.size() vertices and room for `triangles` triangles and their
/// replacements (pos, quad and locked are the caller's).
void init_arrays(PmMesh& m, std::size_t triangles);
/// Appends t (linked into its corners' stars); returns its id.
std::uint32_t add_triangle(PmMesh& m, const Tri& t);
/// Unlinks triangle id from the stars of its corners but `except`.
void unlink_triangle(PmMesh& m, std::uint32_t id, std::uint32_t except);
/// Connected pieces of v's star, triangles joined through the edges around v.
std::size_t fans(const PmMesh& m, std::uint32_t v);
/// The live and dead triangles' directed edges; `twice`, if given, gets an edge two triangles
/// have (kNoEdge: none).
IdMap<std::uint8_t> directed_edges(const PmMesh& m, std::uint64_t* twice);
/// Adds the constraint quadric of boundary edge k of t to its two ends (Garland & Heckbert 6.1).
void add_constraint(PmMesh& m, const Tri& t, int k, double boundary_weight);
/// Face quadrics weighted by area, boundary flags and constraint planes of a whole source mesh.
void init_quadrics_and_boundary(PmMesh& m, double boundary_weight);
/// Components from the triangles; unreferenced vertices are marked removed (never in the model).
void init_components(PmMesh& m);
/// The source mesh, its vertices renumbered in Morton order of their positions and its
/// triangles sorted by their first corner, so that neighbours lie close in every per-vertex and
/// per-triangle array (a source's own order may scatter them: the 832k-triangle
/// midpoint-subdivided armadillo built 17 % faster in this order). Returns vertex -> the
/// source's id (ops name those).
std::vector<std::uint32_t> load_source(PmMesh& m, const TriangleMesh& mesh, double boundary_weight);

std::uint64_t alive_triangles(const PmMesh& m);
std::uint64_t alive_vertices(const PmMesh& m);

/// The vertices sharing a triangle with v, each once, in the order the star meets them (every
/// user is indifferent to the order: candidates are ranked by (cost, id), the heap orders by
/// (cost, from, to), dirty lists are sorted). `marks` is per vertex.
void neighbours(const PmMesh& m, Marks& marks, std::uint32_t v, std::vector<std::uint32_t>& out);

/// The mesh's part of collapsing from -> to: from's star dies (destroyer: the new collapse), its
/// triangles without `to` come back with `to` for `from` and the bounds `new_e` (in star order),
/// the collapse is logged with bound `error` and to's quadric takes from's. The old and new
/// triangles are then log.collapses.back()'s ranges.
void collapse_mesh(PmMesh& m, CollapseLog& log, std::uint32_t from, std::uint32_t to, double error,
                   const std::vector<double>& new_e);

}  // namespace smr::qem
