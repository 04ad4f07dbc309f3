// Mesh validation and repair (validate_mesh, smr/io/mesh_reader.h), as named steps over flat
// arrays with one short driver (validate_faces at the end):
//   check sizes, finite coordinates and indices; weld; drop degenerate faces; bucket the edges;
//   drop duplicate faces; glue faces along edges; split fans; orient; write the output.
// Everything is O(V + F) (plus tiny per-vertex sorts): face edges are bucketed by their lower
// vertex (a counting sort), which groups every undirected edge's faces together; the faces around
// each vertex are split into fans with a union-find over face corners (two corners at the same
// vertex are joined when their faces are glued along an edge through it); orientation is a
// breadth-first traversal over glued edges (the classic half-edge consistency check, Botsch et
// al., "Polygon Mesh Processing", 2010, section 2.5).
//
// Numbering: face t has corners 3t + k (at vertex T[t][k]) and edge slots 3t + k (the edge from
// T[t][k] to T[t][k + 1]).
#include <algorithm>
#include <array>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

#include "smr/io/mesh/source.h"
#include "smr/io/mesh/text.h"

namespace smr::mesh_io {

namespace {

using Tris = std::vector<std::array<std::uint32_t, 3>>;

std::string prefix(const Source& src) {
  return "'" + src.what + "': ";
}

std::uint32_t slot_from(const Tris& T, std::uint32_t s) {
  return T[s / 3][s % 3];
}
std::uint32_t slot_to(const Tris& T, std::uint32_t s) {
  return T[s / 3][(s % 3 + 1) % 3];
}
std::uint32_t slot_lo(const Tris& T, std::uint32_t s) {
  return std::min(slot_from(T, s), slot_to(T, s));
}
std::uint32_t slot_hi(const Tris& T, std::uint32_t s) {
  return std::max(slot_from(T, s), slot_to(T, s));
}
// The slot after s in its face (the edge leaving s's end vertex).
std::uint32_t slot_next(std::uint32_t s) {
  return 3 * (s / 3) + (s % 3 + 1) % 3;
}

// Union-find over face corners with path halving.
std::uint32_t find_root(std::vector<std::uint32_t>& parent, std::uint32_t x) {
  while (parent[x] != x) {
    parent[x] = parent[parent[x]];
    x = parent[x];
  }
  return x;
}

void unite(std::vector<std::uint32_t>& parent, std::uint32_t a, std::uint32_t b) {
  a = find_root(parent, a);
  b = find_root(parent, b);
  if (a == b) return;
  if (a < b) std::swap(a, b);
  parent[a] = b;  // the lower corner is the root
}

// ---------------------------------------------------------------------------------------------
// 1-2. Sizes, finite coordinates, indices in range (never repairable)

void check_sizes(const TriangleMesh& mesh, const Source& src) {
  const std::size_t values = mesh.triangle_values.size(), m = mesh.triangles.size();
  if (values != 0 && values != m) {
    throw_input(prefix(src) + "it has " + num(std::uint64_t{values}) + " triangle values for " +
                num(std::uint64_t{m}) + " triangles; expected one per triangle or none");
  }
  if (m > kMaxTriangles) {
    throw_input(prefix(src) + "more than " + num(std::uint64_t{kMaxTriangles}) +
                " triangles are not supported");
  }
  if (mesh.positions.size() > kMaxVertices) throw_input(prefix(src) + "too many vertices");
}

void check_finite(const std::vector<Vec3>& P, const Source& src) {
  for (std::uint32_t v = 0; v < P.size(); ++v) {
    if (!finite3(P[v])) {
      non_finite(src.what, src.vertex_base < 0 ? "a vertex" : "vertex " + vertex_number(src, v),
                 P[v], "");
    }
  }
}

void check_indices(const Tris& T, std::uint32_t n, const Source& src) {
  for (std::size_t t = 0; t < T.size(); ++t) {
    for (std::uint32_t v : T[t]) {
      if (v >= n) {
        throw_input(prefix(src) + face_label(src, t) + " references vertex " +
                    vertex_number(src, v) + ", which is out of range: the mesh has " +
                    num(std::uint64_t{n}) + " vertices");
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// 3. Weld: faces are renumbered to the first vertex of each position. Returns the map (vertex ->
// the vertex it was welded to), empty when not asked.

std::vector<std::uint32_t> weld(const std::vector<Vec3>& P, Tris& T, MeshReport& rep) {
  const auto n = static_cast<std::uint32_t>(P.size());
  std::vector<std::uint32_t> welded_to(n);
  std::vector<Vec3> firsts;
  firsts.reserve(n);
  std::vector<std::uint32_t> first_id;
  first_id.reserve(n);
  PositionWelder welder(firsts, n);
  for (std::uint32_t v = 0; v < n; ++v) {
    const std::uint32_t k = welder.add(P[v]);
    if (k == first_id.size()) first_id.push_back(v);
    welded_to[v] = first_id[k];
    if (welded_to[v] != v) ++rep.welded_vertices;
  }
  if (rep.welded_vertices > 0) {
    for (auto& tri : T) {
      for (std::uint32_t& v : tri) v = welded_to[v];
    }
  }
  return welded_to;
}

// ---------------------------------------------------------------------------------------------
// 4. Degenerate faces (a repeated vertex) are dropped or an error; zero-area ones are counted.

struct LiveFaces {
  std::vector<std::uint8_t> dead;  // per face: dropped
  std::size_t live = 0;            // faces not dropped
};

LiveFaces drop_degenerate(const Tris& T, const std::vector<Vec3>& P, const Source& src,
                          const MeshRepair& repair, MeshReport& rep) {
  const std::size_t m = T.size();
  LiveFaces faces{std::vector<std::uint8_t>(m, 0), m};
  for (std::size_t t = 0; t < m; ++t) {
    const auto& f = T[t];
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) {
      if (!repair.drop_degenerate) {
        const std::uint32_t twice = f[0] == f[1] || f[0] == f[2] ? f[0] : f[1];
        throw_input(prefix(src) + face_label(src, t) + " is degenerate: it uses " +
                    vertex_label(src, P, twice) + " twice" +
                    (rep.welded_vertices > 0 ? " (after welding)" : "") +
                    "; expected three distinct vertices (repairable: --repair drops degenerate "
                    "faces)");
      }
      faces.dead[t] = 1;
      --faces.live;
      ++rep.degenerate_faces_dropped;
      continue;
    }
    const Vec3 u = P[f[1]] - P[f[0]], w = P[f[2]] - P[f[0]];
    if (u.y * w.z - u.z * w.y == 0.0 && u.z * w.x - u.x * w.z == 0.0 &&
        u.x * w.y - u.y * w.x == 0.0) {
      ++rep.zero_area_faces;
    }
  }
  if (faces.live == 0) {
    if (m == 0) throw_input("'" + src.what + "' has no faces; expected at least one triangle");
    throw_input("'" + src.what + "' has no faces left after dropping " + num(std::uint64_t{m}) +
                " degenerate ones");
  }
  return faces;
}

// ---------------------------------------------------------------------------------------------
// Edge buckets: the live faces' edge slots bucketed by their lower vertex (a counting sort), then
// sorted by the upper one within each bucket, so the slots of one undirected edge are adjacent.

struct EdgeBuckets {
  std::vector<std::uint32_t> start;  // bucket v is slots[start[v] .. start[v + 1])
  std::vector<std::uint32_t> slots;
};

void sort_bucket(const Tris& T, std::vector<std::uint32_t>::iterator b,
                 std::vector<std::uint32_t>::iterator e) {
  if (e - b < 2) return;
  const auto less = [&](std::uint32_t a, std::uint32_t c) {
    const std::uint32_t ha = slot_hi(T, a), hc = slot_hi(T, c);
    return ha != hc ? ha < hc : a < c;
  };
  if (e - b <= 16) {  // insertion sort: buckets hold about three edges
    for (auto i = b + 1; i < e; ++i) {
      const std::uint32_t x = *i;
      auto j = i;
      for (; j > b && less(x, *(j - 1)); --j) *j = *(j - 1);
      *j = x;
    }
  } else {
    std::sort(b, e, less);
  }
}

EdgeBuckets bucket_edges(const Tris& T, const LiveFaces& faces, std::uint32_t n) {
  const std::size_t m = T.size();
  EdgeBuckets eb{std::vector<std::uint32_t>(std::size_t{n} + 1, 0),
                 std::vector<std::uint32_t>(3 * faces.live)};
  std::vector<std::uint32_t>& start = eb.start;
  for (std::size_t t = 0; t < m; ++t) {
    if (faces.dead[t]) continue;
    for (std::uint32_t k = 0; k < 3; ++k)
      ++start[slot_lo(T, static_cast<std::uint32_t>(3 * t + k))];
  }
  for (std::uint32_t v = 1; v <= n; ++v) start[v] += start[v - 1];  // start[v] = end of bucket v
  for (std::size_t t = m; t-- > 0;) {
    if (faces.dead[t]) continue;
    for (std::uint32_t k = 3; k-- > 0;) {
      const auto s = static_cast<std::uint32_t>(3 * t + k);
      eb.slots[--start[slot_lo(T, s)]] = s;
    }
  }
  start[n] = static_cast<std::uint32_t>(eb.slots.size());
  for (std::uint32_t v = 0; v < n; ++v) {
    sort_bucket(T, eb.slots.begin() + start[v], eb.slots.begin() + start[v + 1]);
  }
  return eb;
}

// Calls fn(begin, end) for every group slots[begin .. end) sharing an undirected edge.
template <class Fn>
void for_each_edge(const EdgeBuckets& eb, const Tris& T, Fn&& fn) {
  const std::size_t buckets = eb.start.size() - 1;
  for (std::size_t v = 0; v < buckets; ++v) {
    std::uint32_t i = eb.start[v];
    const std::uint32_t e = eb.start[v + 1];
    while (i < e) {
      std::uint32_t j = i + 1;
      const std::uint32_t h = slot_hi(T, eb.slots[i]);
      while (j < e && slot_hi(T, eb.slots[j]) == h) ++j;
      fn(i, j);
      i = j;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// 5. Duplicate faces: two faces with the same vertex set share the edge between their two lower
// vertices and have the same third (highest) vertex; each face is considered at that edge only.

void drop_duplicates(const EdgeBuckets& eb, const Tris& T, const Source& src,
                     const MeshRepair& repair, LiveFaces& faces, MeshReport& rep) {
  std::vector<std::pair<std::uint32_t, std::uint32_t>> canon;  // (third vertex, face)
  std::size_t first_dup = kNone, first_orig = kNone;
  for_each_edge(eb, T, [&](std::uint32_t b, std::uint32_t e) {
    if (e - b < 2) return;
    canon.clear();
    for (std::uint32_t i = b; i < e; ++i) {
      const std::uint32_t s = eb.slots[i];
      const std::uint32_t third = T[s / 3][(s % 3 + 2) % 3];
      if (third > slot_hi(T, s)) canon.emplace_back(third, s / 3);
    }
    if (canon.size() < 2) return;
    std::sort(canon.begin(), canon.end());
    for (std::size_t i = 1; i < canon.size(); ++i) {
      if (canon[i].first != canon[i - 1].first) continue;
      std::size_t k = i - 1;  // the first face of this run
      while (k > 0 && canon[k - 1].first == canon[i].first) --k;
      const std::uint32_t dup = canon[i].second, orig = canon[k].second;
      if (repair.drop_duplicates) {
        faces.dead[dup] = 1;
        --faces.live;
        ++rep.duplicate_faces_dropped;
      } else if (dup < first_dup) {
        first_dup = dup;
        first_orig = orig;
      }
    }
  });
  if (first_dup != kNone) {
    const auto& f = T[first_dup];
    throw_input(prefix(src) + face_label(src, first_dup) + " is a duplicate of " +
                face_label(src, first_orig) + ": both use vertices " + vertex_number(src, f[0]) +
                ", " + vertex_number(src, f[1]) + " and " + vertex_number(src, f[2]) +
                "; expected no duplicate faces (repairable: --repair drops duplicate faces)");
  }
}

// ---------------------------------------------------------------------------------------------
// 6. Glue faces along edges: twin[s] is the slot of the other face on s's edge, or kNone. An edge
// with more than two faces is an error, or (split_nonmanifold) keeps one pair glued (preferring
// two that traverse it in opposite directions, else the first two) and detaches the others.

struct Glue {
  std::vector<std::uint32_t> twin;      // per slot
  std::vector<std::uint32_t> nm_slots;  // the slots of each non-manifold edge, edge after edge:
  std::vector<std::uint32_t> nm_begin;  // edge i's are nm_slots[nm_begin[i] .. nm_begin[i + 1])
};

[[noreturn]] void nonmanifold_edge(const std::vector<std::uint32_t>& g, const Tris& T,
                                   const std::vector<Vec3>& P, const Source& src) {
  std::string faces;
  for (std::size_t i = 0; i < g.size() && i < 4; ++i) {
    faces += (i == 0 ? "" : ", ") + face_label(src, g[i] / 3);
  }
  if (g.size() > 4) faces += ", ...";
  throw_input(prefix(src) + "the edge between " + vertex_label(src, P, slot_lo(T, g[0])) + " and " +
              vertex_label(src, P, slot_hi(T, g[0])) + " is non-manifold: it has " +
              num(std::uint64_t{g.size()}) + " faces (" + faces +
              "); expected at most 2 (repairable: --repair detaches the extra faces)");
}

Glue glue_edges(const EdgeBuckets& eb, const Tris& T, const std::vector<Vec3>& P,
                const LiveFaces& faces, const Source& src, const MeshRepair& repair,
                MeshReport& rep) {
  Glue glue{std::vector<std::uint32_t>(3 * T.size(), kNone), {}, {}};
  std::vector<std::uint32_t>& twin = glue.twin;
  std::vector<std::uint32_t> g;
  for_each_edge(eb, T, [&](std::uint32_t b, std::uint32_t e) {
    g.clear();
    for (std::uint32_t i = b; i < e; ++i) {
      if (!faces.dead[eb.slots[i] / 3]) g.push_back(eb.slots[i]);
    }
    if (g.size() == 2) {
      twin[g[0]] = g[1];
      twin[g[1]] = g[0];
    } else if (g.size() > 2) {
      if (!repair.split_nonmanifold) nonmanifold_edge(g, T, P, src);
      ++rep.nonmanifold_edges_cut;
      const std::uint32_t lo = slot_lo(T, g[0]);
      std::uint32_t a = kNone, c = kNone;  // the first slot in each direction
      for (std::uint32_t s : g) {
        if (slot_from(T, s) == lo) {
          if (a == kNone) a = s;
        } else if (c == kNone) {
          c = s;
        }
      }
      if (a == kNone || c == kNone) {
        a = g[0];
        c = g[1];
      }
      twin[a] = c;
      twin[c] = a;
      glue.nm_begin.push_back(static_cast<std::uint32_t>(glue.nm_slots.size()));
      glue.nm_slots.insert(glue.nm_slots.end(), g.begin(), g.end());
    }
  });
  glue.nm_begin.push_back(static_cast<std::uint32_t>(glue.nm_slots.size()));
  return glue;
}

// ---------------------------------------------------------------------------------------------
// 7. Fans: corners joined across glued edges; each class of corners becomes one output vertex
// (the first class of a vertex keeps its number, the others get copies appended after the input
// vertices).

struct Fans {
  std::vector<std::uint32_t> out;     // corner -> output vertex
  std::vector<std::uint32_t> origin;  // copy n + i is a copy of vertex origin[i]
};

// The first live face (in file order) that uses vertex v, for a message.
std::size_t first_face_at(const Tris& T, const LiveFaces& faces, std::uint32_t v) {
  for (std::size_t q = 0; q < T.size(); ++q) {
    if (faces.dead[q]) continue;
    for (std::uint32_t x : T[q]) {
      if (x == v) return q;
    }
  }
  return 0;
}

[[noreturn]] void nonmanifold_vertex(const Tris& T, const std::vector<Vec3>& P,
                                     const LiveFaces& faces, std::uint32_t v, std::size_t t,
                                     const Source& src) {
  throw_input(prefix(src) + vertex_label(src, P, v) +
              " is non-manifold: its faces form more than one fan (" +
              face_label(src, first_face_at(T, faces, v)) + " and " + face_label(src, t) +
              " share it but are not connected through edges around it); expected one fan per "
              "vertex (repairable: --repair splits it into one copy per fan)");
}

// Unites the corners across glued edges and numbers the classes (fans.out, fans.origin).
void assign_vertices(const Tris& T, const std::vector<Vec3>& P, const LiveFaces& faces,
                     const std::vector<std::uint32_t>& twin, const Source& src,
                     const MeshRepair& repair, Fans& fans) {
  const std::size_t m = T.size();
  const auto n = static_cast<std::uint32_t>(P.size());
  std::vector<std::uint32_t> parent(3 * m);
  std::iota(parent.begin(), parent.end(), std::uint32_t{0});
  for (std::size_t t = 0; t < m; ++t) {
    if (faces.dead[t]) continue;
    for (std::uint32_t k = 0; k < 3; ++k) {
      const auto s = static_cast<std::uint32_t>(3 * t + k);
      const std::uint32_t u = twin[s];
      if (u == kNone || u < s) continue;
      if (slot_from(T, u) == slot_from(T, s)) {  // same direction
        unite(parent, s, u);
        unite(parent, slot_next(s), slot_next(u));
      } else {
        unite(parent, s, slot_next(u));
        unite(parent, slot_next(s), u);
      }
    }
  }
  fans.out.assign(3 * m, kNone);
  fans.origin.clear();
  std::vector<std::uint8_t> taken(n, 0);
  for (std::size_t t = 0; t < m; ++t) {
    if (faces.dead[t]) continue;
    for (std::uint32_t k = 0; k < 3; ++k) {
      const auto c = static_cast<std::uint32_t>(3 * t + k);
      const std::uint32_t r = find_root(parent, c);
      if (fans.out[r] == kNone) {
        const std::uint32_t v = T[t][k];
        if (!taken[v]) {
          taken[v] = 1;
          fans.out[r] = v;
        } else {
          if (!repair.split_nonmanifold) nonmanifold_vertex(T, P, faces, v, t, src);
          if (std::size_t{n} + fans.origin.size() >= kMaxVertices) {
            throw_input(prefix(src) + "too many vertices after splitting non-manifold ones");
          }
          fans.out[r] = n + static_cast<std::uint32_t>(fans.origin.size());
          fans.origin.push_back(v);
        }
      }
      fans.out[c] = fans.out[r];
    }
  }
}

// The slots of non-manifold edge gi keyed by their output vertices (lower << 32 | upper), sorted.
void edge_keys(const Glue& glue, const Fans& fans, std::size_t gi,
               std::vector<std::pair<std::uint64_t, std::uint32_t>>& keys) {
  keys.clear();
  for (std::uint32_t i = glue.nm_begin[gi]; i < glue.nm_begin[gi + 1]; ++i) {
    const std::uint32_t s = glue.nm_slots[i];
    const std::uint32_t a = fans.out[s], b = fans.out[slot_next(s)];
    keys.emplace_back(std::uint64_t{std::min(a, b)} << 32 | std::max(a, b), s);
  }
  std::sort(keys.begin(), keys.end());
}

// Detached faces that still share both output vertices of a non-manifold edge with other faces
// (their fans close up around the edge's ends) are detached completely: all their slots
// unglued. True when any was.
bool isolate_closed_fans(const Fans& fans, Glue& glue) {
  std::vector<std::uint32_t>& twin = glue.twin;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> keys;
  bool isolated = false;
  for (std::size_t gi = 0; gi + 1 < glue.nm_begin.size(); ++gi) {
    edge_keys(glue, fans, gi, keys);
    for (std::size_t i = 0; i < keys.size();) {
      std::size_t j = i + 1;
      while (j < keys.size() && keys[j].first == keys[i].first) ++j;
      if (j - i >= 2) {
        for (std::size_t q = i; q < j; ++q) {
          const std::uint32_t s = keys[q].second;
          if (twin[s] != kNone) continue;  // the kept pair
          const std::uint32_t t = s / 3;
          for (std::uint32_t k = 0; k < 3; ++k) {
            const std::uint32_t x = 3 * t + k;
            if (twin[x] != kNone) {
              twin[twin[x]] = kNone;
              twin[x] = kNone;
            }
          }
          isolated = true;
        }
      }
      i = j;
    }
  }
  return isolated;
}

Fans split_fans(const Tris& T, const std::vector<Vec3>& P, const LiveFaces& faces, Glue& glue,
                const Source& src, const MeshRepair& repair, MeshReport& rep) {
  Fans fans;
  assign_vertices(T, P, faces, glue.twin, src, repair, fans);
  if (rep.nonmanifold_edges_cut > 0 && isolate_closed_fans(fans, glue)) {
    assign_vertices(T, P, faces, glue.twin, src, repair, fans);
    std::vector<std::pair<std::uint64_t, std::uint32_t>> keys;
    for (std::size_t gi = 0; gi + 1 < glue.nm_begin.size(); ++gi) {
      edge_keys(glue, fans, gi, keys);
      for (std::size_t i = 0; i + 1 < keys.size(); ++i) {
        if (keys[i].first == keys[i + 1].first && glue.twin[keys[i].second] != keys[i + 1].second) {
          throw_internal(prefix(src) + "detaching faces at a non-manifold edge failed");
        }
      }
    }
  }
  rep.vertices_split = fans.origin.size();
  return fans;
}

// ---------------------------------------------------------------------------------------------
// 8. Orientation: breadth-first over glued edges; a face's flip bit makes it agree with the first
// face of its component, and a component flips the fewer faces. A contradiction means the
// component is not orientable.

struct Orientation {
  std::vector<std::uint8_t> state;  // per face: bit 0 visited, bit 1 flip
  std::size_t components = 0;
};

Orientation orient_faces(const Tris& T, const std::vector<Vec3>& P, const LiveFaces& faces,
                         const std::vector<std::uint32_t>& twin, const Source& src,
                         const MeshRepair& repair, MeshReport& rep) {
  const std::size_t m = T.size();
  Orientation o{std::vector<std::uint8_t>(m, 0), 0};
  std::vector<std::uint8_t>& state = o.state;
  std::vector<std::uint32_t> order;
  order.reserve(faces.live);
  std::uint32_t same_a = kNone, same_b = kNone, same_s = kNone;  // the first disagreement
  std::size_t flips = 0;
  for (std::size_t t0 = 0; t0 < m; ++t0) {
    if (faces.dead[t0] || state[t0]) continue;
    ++o.components;
    const std::size_t begin = order.size();
    state[t0] = 1;
    order.push_back(static_cast<std::uint32_t>(t0));
    for (std::size_t head = begin; head < order.size(); ++head) {
      const std::uint32_t t = order[head];
      const std::uint8_t ft = state[t] >> 1;
      for (std::uint32_t k = 0; k < 3; ++k) {
        const std::uint32_t s = 3 * t + k;
        const std::uint32_t u = twin[s];
        if (u == kNone) continue;
        const std::uint32_t t2 = u / 3;
        const bool same = slot_from(T, u) == slot_from(T, s);
        const auto want = static_cast<std::uint8_t>(ft ^ (same ? 1 : 0));
        if (same && same_s == kNone) {
          same_a = t;
          same_b = t2;
          same_s = s;
        }
        if (!state[t2]) {
          state[t2] = static_cast<std::uint8_t>(1 | (want << 1));
          order.push_back(t2);
        } else if ((state[t2] >> 1) != want) {
          throw_input(prefix(src) + "the part of the mesh containing " + face_label(src, t0) +
                      " is not orientable (like a Moebius strip): " + face_label(src, t) + " and " +
                      face_label(src, t2) +
                      " cannot agree on the direction of their shared edge whichever way the "
                      "faces around it are flipped (not repairable)");
        }
      }
    }
    std::size_t flipped = 0;
    for (std::size_t i = begin; i < order.size(); ++i) flipped += state[order[i]] >> 1;
    const std::size_t size = order.size() - begin;
    if (2 * flipped > size) {
      for (std::size_t i = begin; i < order.size(); ++i) state[order[i]] ^= 2;
      flipped = size - flipped;
    }
    flips += flipped;
  }
  if (flips > 0 && !repair.orient) {
    throw_input(prefix(src) + face_label(src, same_a) + " and " + face_label(src, same_b) +
                " both go from " + vertex_label(src, P, slot_from(T, same_s)) + " to " +
                vertex_label(src, P, slot_to(T, same_s)) +
                ", so their orientations disagree; expected faces sharing an edge to traverse it "
                "in opposite directions (inconsistent orientation; repairable: --repair flips "
                "faces)");
  }
  rep.faces_flipped = flips;
  return o;
}

std::size_t count_boundary(const LiveFaces& faces, const std::vector<std::uint32_t>& twin) {
  std::size_t boundary = 0;
  for (std::size_t t = 0; t < faces.dead.size(); ++t) {
    if (faces.dead[t]) continue;
    for (std::uint32_t k = 0; k < 3; ++k) boundary += twin[3 * t + k] == kNone ? 1 : 0;
  }
  return boundary;
}

// ---------------------------------------------------------------------------------------------
// 9. Output: faces in order (flipped ones as (a, c, b)), referenced vertices in order (vertices no
// face references are dropped and counted, welded ones excepted).

void write_output(TriangleMesh& mesh, const LiveFaces& faces, const Fans& fans,
                  const std::vector<std::uint8_t>& state,
                  const std::vector<std::uint32_t>& welded_to, MeshReport& rep) {
  std::vector<Vec3>& P = mesh.positions;
  Tris& T = mesh.triangles;
  const bool has_values = !mesh.triangle_values.empty();
  const auto n = static_cast<std::uint32_t>(P.size());
  const std::size_t m = T.size();
  const std::size_t total = std::size_t{n} + fans.origin.size();
  std::vector<std::uint32_t> renum(total, kNone);
  for (std::size_t t = 0; t < m; ++t) {
    if (faces.dead[t]) continue;
    for (std::uint32_t k = 0; k < 3; ++k) renum[fans.out[3 * t + k]] = 0;
  }
  std::uint32_t next = 0;
  for (std::size_t v = 0; v < total; ++v) {
    if (renum[v] == kNone) {
      if (v < n && (welded_to.empty() || welded_to[v] == v)) ++rep.unused_vertices_dropped;
      continue;
    }
    renum[v] = next++;
  }
  std::vector<Vec3> positions(next);
  for (std::size_t v = 0; v < total; ++v) {
    if (renum[v] != kNone) positions[renum[v]] = P[v < n ? v : fans.origin[v - n]];
  }
  std::size_t w = 0;
  for (std::size_t t = 0; t < m; ++t) {
    if (faces.dead[t]) continue;
    std::array<std::uint32_t, 3> f = {renum[fans.out[3 * t]], renum[fans.out[3 * t + 1]],
                                      renum[fans.out[3 * t + 2]]};
    if (state[t] & 2) std::swap(f[1], f[2]);
    T[w] = f;
    if (has_values) mesh.triangle_values[w] = mesh.triangle_values[t];
    ++w;
  }
  T.resize(w);
  if (has_values) mesh.triangle_values.resize(w);
  P = std::move(positions);
}

}  // namespace

void validate_faces(TriangleMesh& mesh, const Source& src, const MeshRepair& repair,
                    MeshReport& rep) {
  check_sizes(mesh, src);
  const std::vector<Vec3>& P = mesh.positions;
  Tris& T = mesh.triangles;
  const auto n = static_cast<std::uint32_t>(P.size());
  check_finite(P, src);
  check_indices(T, n, src);
  std::vector<std::uint32_t> welded_to;  // empty: no weld
  if (repair.weld && n > 0) welded_to = weld(P, T, rep);
  LiveFaces faces = drop_degenerate(T, P, src, repair, rep);
  Glue glue;
  {
    const EdgeBuckets edges = bucket_edges(T, faces, n);
    drop_duplicates(edges, T, src, repair, faces, rep);
    glue = glue_edges(edges, T, P, faces, src, repair, rep);
  }
  const Fans fans = split_fans(T, P, faces, glue, src, repair, rep);
  const Orientation orientation = orient_faces(T, P, faces, glue.twin, src, repair, rep);
  const std::size_t boundary = count_boundary(faces, glue.twin);
  glue = {};
  write_output(mesh, faces, fans, orientation.state, welded_to, rep);
  rep.vertices = mesh.positions.size();
  rep.faces = mesh.triangles.size();
  rep.components = orientation.components;
  rep.boundary_edges = boundary;
  rep.closed = boundary == 0;
}

}  // namespace smr::mesh_io
