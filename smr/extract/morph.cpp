// Local morphs for geomorphing sessions (Brown ch. 6, 6.2; Hoppe 1996/1997 geomorphs): the common
// refinement of two triangulations of a changed region (2.5-D) and collapse maps derived from F(R)
// and PreF(R) (3-D). See morph.h.
//
// 2.5-D, exactly. Terrain vertices lie on an integer grid (to_grid), so every edge of either
// triangulation lies on an integer line and every vertex of the overlay is an integer point or the
// meet of two integer lines: a rational point (X/D, Y/D) whose side of an integer line is the sign
// of an __int128. A piece (a removed triangle clipped by an added one's edge lines) is built from
// such signs only, its vertices are keyed by the reduced (X, Y, D), so pieces on both sides of an
// edge share their vertices exactly, and it is split into triangles by which polygon sides its
// corners lie on (no orientation of rational points, no degenerate triangle, no corner dropped).
// The removed triangles overlapping an added one are found by a walk: from one overlapping removed
// triangle, across removed edges, to the rest (they cover the added triangle, so they are
// edge-connected), and from there into each added neighbour; linear in the pieces.
#include "smr/extract/morph.h"

#include <algorithm>
#include <cstdlib>
#include <limits>
#include <numeric>
#include <string>
#include <utility>

#include "base/error.h"
#include "smr/core/id_map.h"
#include "smr/core/invariants.h"

namespace smr {
namespace {

__extension__ typedef __int128 i128;
__extension__ typedef unsigned __int128 u128;

// Grid coordinates beyond this would overflow the predicates below (|X| < 2^90, sides < 2^120).
constexpr std::int64_t kMaxGrid = std::int64_t{1} << 28;

/// Union-find over dense indices, with path halving.
class Components {
 public:
  explicit Components(std::size_t n) : parent_(n) {
    std::iota(parent_.begin(), parent_.end(), std::uint32_t{0});
  }
  std::uint32_t find(std::uint32_t a) {
    while (parent_[a] != a) a = parent_[a] = parent_[parent_[a]];
    return a;
  }
  void join(std::uint32_t a, std::uint32_t b) {
    a = find(a);
    b = find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }
  /// Dense labels 0..count-1 in order of first appearance; returns the count.
  std::uint32_t label(std::vector<std::uint32_t>& labels) {
    labels.assign(parent_.size(), 0);
    std::vector<std::uint32_t> of_root(parent_.size(), ~std::uint32_t{0});
    std::uint32_t count = 0;
    for (std::uint32_t i = 0; i < parent_.size(); ++i) {
      std::uint32_t& r = of_root[find(i)];
      if (r == ~std::uint32_t{0}) r = count++;
      labels[i] = r;
    }
    return count;
  }

 private:
  std::vector<std::uint32_t> parent_;
};

// ---------------------------------------------------------------------------------------------
// 2.5-D

struct TerrainTri {
  GridTriangle g;
  std::array<Vec3, 3> p;
  bool is_void = false;
};

// The triangles' corners in grid and world coordinates, each op read once (in storage order).
std::vector<TerrainTri> read_terrain(const OpSource& source, std::span<const TriRef> refs) {
  const CrmrInfo& info = source.info();
  std::vector<std::pair<std::uint64_t, std::uint32_t>> order;  // (locality, triangle)
  order.reserve(refs.size());
  for (std::uint32_t i = 0; i < refs.size(); ++i) {
    const bool same = i > 0 && refs[i].op == refs[i - 1].op;
    order.push_back({same ? order.back().first : source.locality(refs[i].op), i});
  }
  std::sort(order.begin(), order.end(), [&](const auto& a, const auto& b) {
    return a.first != b.first ? a.first < b.first : refs[a.second].op < refs[b.second].op;
  });
  std::vector<TerrainTri> tris(refs.size());
  OpRef op;
  for (const auto& [place, i] : order) {
    if (op == nullptr || op->id != refs[i].op) op = source.op(refs[i].op);
    const FragmentTriangle& t = op->triangle(refs[i].index);
    TerrainTri& out = tris[i];
    out.is_void = t.is_void();
    for (int k = 0; k < 3; ++k) {
      out.p[k] = op->position(t, k);
      out.g[k] = to_grid(info, out.p[k]);
      if (std::llabs(out.g[k].x) >= kMaxGrid || std::llabs(out.g[k].y) >= kMaxGrid)
        throw_input("terrain_morph: grid coordinates beyond 2^28");
    }
  }
  return tris;
}

/// A rational point (x / d, y / d), d > 0.
struct RatPoint {
  i128 x, y, d;
};
/// The integer line through a and b (a != b), directed from a to b.
struct Line {
  GridPoint a, b;
};

// > 0 when p is strictly left of the line, 0 on it: d times the usual orientation, exactly.
i128 side(const Line& l, const RatPoint& p) {
  const i128 ux = l.b.x - l.a.x, uy = l.b.y - l.a.y;
  return ux * (p.y - i128{l.a.y} * p.d) - uy * (p.x - i128{l.a.x} * p.d);
}

int sign(i128 v) {
  return (v > 0) - (v < 0);
}

// The meet of two non-parallel integer lines.
RatPoint meet(const Line& l, const Line& m) {
  const i128 rx = l.b.x - l.a.x, ry = l.b.y - l.a.y, sx = m.b.x - m.a.x, sy = m.b.y - m.a.y;
  const i128 den = rx * sy - ry * sx;
  const i128 num = i128{m.a.x - l.a.x} * sy - i128{m.a.y - l.a.y} * sx;
  RatPoint p{i128{l.a.x} * den + num * rx, i128{l.a.y} * den + num * ry, den};
  if (den < 0) p = {-p.x, -p.y, -den};
  return p;
}

bool same_line(const Line& l, const Line& m) {
  const i128 rx = l.b.x - l.a.x, ry = l.b.y - l.a.y;
  const auto cross = [&](const GridPoint& q) { return rx * (q.y - l.a.y) - ry * (q.x - l.a.x); };
  return cross(m.a) == 0 && cross(m.b) == 0;
}

u128 gcd(u128 a, u128 b) {
  while (b != 0) {
    if (a < (u128{1} << 63) && b < (u128{1} << 63))
      return std::gcd(static_cast<std::uint64_t>(a), static_cast<std::uint64_t>(b));
    a %= b;
    std::swap(a, b);
  }
  return a;
}

/// A rational point in lowest terms: equal points have equal keys.
struct PointKey {
  i128 x = 0, y = 0, d = 0;  // d == 0: the empty marker
  friend bool operator==(const PointKey&, const PointKey&) = default;
};
struct PointKeys {
  static constexpr PointKey empty() { return {}; }
  static std::size_t hash(const PointKey& k) {
    const auto lo = [](i128 v) { return static_cast<std::uint64_t>(v); };
    return std::size_t(mix64(lo(k.x) * 0x9E3779B97F4A7C15ULL ^ mix64(lo(k.y) + lo(k.d))));
  }
};

PointKey key_of(const RatPoint& p) {
  if (p.d == 1) return {p.x, p.y, 1};
  const auto mag = [](i128 v) { return static_cast<u128>(v < 0 ? -v : v); };
  const auto g = static_cast<i128>(gcd(gcd(mag(p.x), mag(p.y)), static_cast<u128>(p.d)));
  return {p.x / g, p.y / g, p.d / g};
}

/// A convex piece: corners counter-clockwise, edge[i] the integer line from p[i] to p[i + 1].
struct Piece {
  static constexpr int kMax = 8;  // a triangle clipped by three lines has at most 6 corners
  std::array<RatPoint, kMax> p;
  std::array<Line, kMax> edge;
  int n = 0;
  void add(const RatPoint& q, const Line& e) {
    p[n] = q;
    edge[n++] = e;
  }
};

// Sutherland-Hodgman against the closed left side of `l`, with exact signs: a corner on the line
// stays (no new corner is made there), a strict crossing adds the lines' meet. Each output corner
// carries the line of the edge that leaves it.
void clip(const Piece& in, const Line& l, Piece& out) {
  out.n = 0;
  std::array<int, Piece::kMax> s{};
  for (int i = 0; i < in.n; ++i) s[i] = sign(side(l, in.p[i]));
  for (int i = 0; i < in.n; ++i) {
    const int j = (i + 1) % in.n;
    if (s[i] > 0) {
      out.add(in.p[i], in.edge[i]);
      if (s[j] < 0) out.add(meet(in.edge[i], l), l);
    } else if (s[i] == 0) {
      out.add(in.p[i], s[j] < 0 ? l : in.edge[i]);
    } else if (s[j] > 0) {
      out.add(meet(in.edge[i], l), in.edge[i]);
    }
  }
}

/// Triangles of a convex piece over all of its corners. Three corners of a convex polygon are
/// collinear exactly when they lie on one side (a maximal run of edges on one line), so each
/// corner gets the set of sides it lies on and ears are clipped where neither the ear nor the rest
/// is degenerate.
int triangulate(const Piece& piece, std::array<std::array<int, 3>, Piece::kMax>& tris) {
  const int n = piece.n;
  std::array<int, Piece::kMax> run{};  // side number of each edge
  for (int i = 1; i < n; ++i) run[i] = run[i - 1] + !same_line(piece.edge[i - 1], piece.edge[i]);
  if (n > 1 && run[n - 1] != 0 && same_line(piece.edge[n - 1], piece.edge[0])) {
    const int last = run[n - 1];  // the last side continues the first
    for (int i = n - 1; i > 0 && run[i] == last; --i) run[i] = 0;
  }
  std::array<unsigned, Piece::kMax> on{};  // bit per side, for each corner
  for (int i = 0; i < n; ++i) on[i] = (1u << run[(i + n - 1) % n]) | (1u << run[i]);
  std::array<int, Piece::kMax> left{};
  int m = n, count = 0;
  for (int i = 0; i < n; ++i) left[i] = i;
  while (m >= 3) {
    int ear = -1;  // a corner whose ear is a triangle and whose removal leaves a polygon
    for (int j = 0; j < m && ear < 0; ++j) {
      const int a = left[(j + m - 1) % m], b = left[j], c = left[(j + 1) % m];
      if ((on[a] & on[b] & on[c]) != 0) continue;  // collinear
      unsigned rest = ~0u;
      for (int q = 0; q < m; ++q) rest &= q == j ? ~0u : on[left[q]];
      if (m == 3 || rest == 0) ear = j;
    }
    if (ear < 0) {  // only a piece of no area (all corners on one line) has none
      if (count > 0) throw_internal("terrain_morph: a convex piece has no ear");
      return 0;
    }
    tris[count++] = {left[(ear + m - 1) % m], left[ear], left[(ear + 1) % m]};
    std::copy(left.begin() + ear + 1, left.begin() + m, left.begin() + ear);
    --m;
  }
  return count;
}

// The height of the plane of triangle t at the rational point p (barycentric, exact signs; the
// corners' own heights are returned exactly at the corners).
double plane_height(const TerrainTri& t, const RatPoint& p) {
  const GridTriangle& g = t.g;
  const double den = double(i128{orient(g[0], g[1], g[2])} * p.d);
  const double w0 = double(side({g[1], g[2]}, p)) / den, w1 = double(side({g[2], g[0]}, p)) / den,
               w2 = double(side({g[0], g[1]}, p)) / den;
  return w0 * t.p[0].z + w1 * t.p[1].z + w2 * t.p[2].z;
}

struct EdgeKey {
  std::uint64_t a = ~std::uint64_t{0}, b = ~std::uint64_t{0};
  friend bool operator==(const EdgeKey&, const EdgeKey&) = default;
};
struct EdgeKeys {
  static constexpr EdgeKey empty() { return {}; }
  static std::size_t hash(const EdgeKey& k) { return std::size_t(mix64(k.a ^ mix64(k.b))); }
};

std::uint64_t pack(const GridPoint& p) {
  return static_cast<std::uint64_t>(p.x + kMaxGrid) << 32 |
         static_cast<std::uint64_t>(p.y + kMaxGrid);
}

using Neighbours = std::vector<std::array<std::int32_t, 3>>;

// Across edge k (from corner k to k + 1), the triangle with the reversed edge, or -1.
Neighbours neighbours(const std::vector<TerrainTri>& tris) {
  FlatMap<EdgeKey, std::uint32_t, EdgeKeys> edges(75);
  edges.reserve(3 * tris.size());
  for (std::uint32_t i = 0; i < tris.size(); ++i) {
    for (int k = 0; k < 3; ++k) edges[{pack(tris[i].g[k]), pack(tris[i].g[(k + 1) % 3])}] = i + 1;
  }
  Neighbours nbr(tris.size());
  for (std::uint32_t i = 0; i < tris.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t* j = edges.find({pack(tris[i].g[(k + 1) % 3]), pack(tris[i].g[k])});
      nbr[i][k] = j == nullptr ? -1 : static_cast<std::int32_t>(*j - 1);
    }
  }
  return nbr;
}

class TerrainOverlay {
 public:
  TerrainOverlay(const CrmrInfo& info, std::vector<TerrainTri> out, std::vector<TerrainTri> in)
      : info_(info), out_(std::move(out)), in_(std::move(in)) {}
  MorphMesh run();

 private:
  bool overlap(std::int32_t s, std::uint32_t t) const {
    return interiors_overlap(out_[std::size_t(s)].g, in_[t].g);
  }
  std::int32_t seed_at_corners(std::uint32_t t) const;
  std::int32_t seed_by_scan(std::uint32_t t) const;
  void walk(std::uint32_t start, std::int32_t seed);
  void visit(std::uint32_t t);
  void add_piece(const TerrainTri& s, const TerrainTri& t);
  std::uint32_t vertex(const RatPoint& p, const TerrainTri& s, const TerrainTri& t);

  const CrmrInfo& info_;
  std::vector<TerrainTri> out_, in_;
  Neighbours out_nbr_, in_nbr_;
  IdMap<std::uint32_t> out_at_;       // grid vertex -> one removed triangle there
  std::vector<std::int32_t> seed_;    // per added triangle: a removed one overlapping it, or -1
  std::vector<std::uint32_t> stamp_;  // per removed triangle: the added one that last tested it
  std::vector<std::uint32_t> queue_, overlapping_, probed_;
  IdMap<std::uint32_t> grid_vertices_{75};                    // integer point -> 1 + vertex
  FlatMap<PointKey, std::uint32_t, PointKeys> vertices_{75};  // other points -> 1 + vertex
  MorphMesh mesh_;
};

// A removed triangle overlapping added triangle t, among those around t's corners that are
// removed vertices; -1 if none is.
std::int32_t TerrainOverlay::seed_at_corners(std::uint32_t t) const {
  for (int k = 0; k < 3; ++k) {
    const std::uint32_t* first = out_at_.find(pack(in_[t].g[k]));
    if (first == nullptr) continue;
    // Around the vertex counter-clockwise (across the edge entering it), then clockwise.
    for (int turn = 0; turn < 2; ++turn) {
      auto s = static_cast<std::int32_t>(*first);
      for (std::size_t steps = 0; s >= 0 && steps < out_.size(); ++steps) {
        if (overlap(s, t)) return s;
        const GridTriangle& g = out_[std::size_t(s)].g;
        const int c = g[0] == in_[t].g[k] ? 0 : g[1] == in_[t].g[k] ? 1 : 2;
        s = out_nbr_[std::size_t(s)][turn == 0 ? (c + 2) % 3 : c];
        if (s == static_cast<std::int32_t>(*first)) break;
      }
    }
  }
  return -1;
}

std::int32_t TerrainOverlay::seed_by_scan(std::uint32_t t) const {
  for (std::size_t s = 0; s < out_.size(); ++s) {
    if (overlap(static_cast<std::int32_t>(s), t)) return static_cast<std::int32_t>(s);
  }
  return -1;
}

void TerrainOverlay::walk(std::uint32_t start, std::int32_t seed) {
  seed_[start] = seed;
  queue_.assign(1, start);
  while (!queue_.empty()) {
    const std::uint32_t t = queue_.back();
    queue_.pop_back();
    visit(t);
  }
}

// The removed triangles overlapping added triangle t (a flood from its seed across removed edges),
// their pieces, and seeds for t's added neighbours (among those triangles and the ones around).
void TerrainOverlay::visit(std::uint32_t t) {
  overlapping_.clear();
  probed_.clear();
  const auto first = static_cast<std::uint32_t>(seed_[t]);
  stamp_[first] = t;
  overlapping_.push_back(first);
  for (std::size_t i = 0; i < overlapping_.size(); ++i) {
    for (std::int32_t s : out_nbr_[overlapping_[i]]) {
      if (s < 0 || stamp_[std::size_t(s)] == t) continue;
      stamp_[std::size_t(s)] = t;
      (overlap(s, t) ? overlapping_ : probed_).push_back(static_cast<std::uint32_t>(s));
    }
  }
  for (std::uint32_t s : overlapping_) add_piece(out_[s], in_[t]);
  for (std::int32_t n : in_nbr_[t]) {
    if (n < 0 || seed_[std::size_t(n)] >= 0) continue;
    const auto u = static_cast<std::uint32_t>(n);
    for (const auto* list : {&overlapping_, &probed_}) {
      for (std::uint32_t s : *list) {
        if (seed_[u] < 0 && overlap(static_cast<std::int32_t>(s), u))
          seed_[u] = static_cast<std::int32_t>(s);
      }
    }
    if (seed_[u] >= 0) queue_.push_back(u);
  }
}

std::uint32_t TerrainOverlay::vertex(const RatPoint& p, const TerrainTri& s, const TerrainTri& t) {
  const PointKey key = key_of(p);
  std::uint32_t& slot = key.d == 1
                            ? grid_vertices_[pack({std::int64_t(key.x), std::int64_t(key.y)})]
                            : vertices_[key];
  if (slot != 0) return slot - 1;
  slot = static_cast<std::uint32_t>(mesh_.start.size()) + 1;
  Vec3 a{info_.georef.x0 + double(p.x) / double(p.d) * info_.georef.dx,
         info_.georef.y0 + double(p.y) / double(p.d) * info_.georef.dy, 0.0};
  if (p.d == 1) {  // a corner keeps its stored xy
    for (const TerrainTri* tri : {&s, &t}) {
      for (int k = 0; k < 3; ++k) {
        if (tri->g[k].x == p.x && tri->g[k].y == p.y) a = tri->p[k];
      }
    }
  }
  Vec3 b = a;
  a.z = plane_height(s, p);
  b.z = plane_height(t, p);
  mesh_.start.push_back(a);
  mesh_.end.push_back(b);
  return slot - 1;
}

void TerrainOverlay::add_piece(const TerrainTri& s, const TerrainTri& t) {
  Piece a, b;
  for (int k = 0; k < 3; ++k) a.add({t.g[k].x, t.g[k].y, 1}, {t.g[k], t.g[(k + 1) % 3]});
  Piece *from = &a, *to = &b;
  for (int k = 0; k < 3 && from->n > 0; ++k) {
    clip(*from, {s.g[k], s.g[(k + 1) % 3]}, *to);
    std::swap(from, to);
  }
  const Piece& piece = *from;
  std::array<std::array<int, 3>, Piece::kMax> tris;
  const int count = triangulate(piece, tris);
  if (count == 0) return;
  std::array<std::uint32_t, Piece::kMax> id{};
  for (int i = 0; i < piece.n; ++i) id[i] = vertex(piece.p[i], s, t);
  const auto flags = static_cast<std::uint8_t>((s.is_void ? MorphMesh::kVoidStart : 0) |
                                               (t.is_void ? MorphMesh::kVoidEnd : 0));
  for (int i = 0; i < count; ++i) {
    mesh_.triangles.push_back({id[tris[i][0]], id[tris[i][1]], id[tris[i][2]]});
    mesh_.flags.push_back(flags);
  }
}

MorphMesh TerrainOverlay::run() {
  out_nbr_ = neighbours(out_);
  in_nbr_ = neighbours(in_);
  out_at_.reserve(out_.size());
  for (std::uint32_t i = 0; i < out_.size(); ++i) {
    for (const GridPoint& p : out_[i].g) out_at_[pack(p)] = i;
  }
  // About one vertex per changed triangle and three pieces per two (benchmarks: 57 k vertices
  // and 102 k pieces for 60 k changed triangles).
  grid_vertices_.reserve((out_.size() + in_.size()) / 2);
  vertices_.reserve((out_.size() + in_.size()) / 2);
  mesh_.start.reserve(out_.size() + in_.size());
  mesh_.end.reserve(out_.size() + in_.size());
  mesh_.triangles.reserve(2 * (out_.size() + in_.size()));
  mesh_.flags.reserve(2 * (out_.size() + in_.size()));
  seed_.assign(in_.size(), -1);
  stamp_.assign(out_.size(), ~std::uint32_t{0});
  // Every connected part of the region has a corner both triangulations share: walks start there.
  // A part without one (not the same region on both sides) is found by a scan.
  for (int pass = 0; pass < 2; ++pass) {
    for (std::uint32_t t = 0; t < in_.size(); ++t) {
      if (seed_[t] >= 0) continue;
      const std::int32_t s = pass == 0 ? seed_at_corners(t) : seed_by_scan(t);
      if (s >= 0) {
        walk(t, s);
      } else if (pass == 1) {
        throw_input("terrain_morph: an added triangle overlaps no removed one");
      }
    }
  }
  Components parts(mesh_.start.size());
  for (const auto& tri : mesh_.triangles) {
    parts.join(tri[0], tri[1]);
    parts.join(tri[0], tri[2]);
  }
  mesh_.groups = parts.label(mesh_.group);
  return std::move(mesh_);
}

// ---------------------------------------------------------------------------------------------
// 3-D

using LocalTri = std::array<std::uint32_t, 3>;

// Same triangle, same orientation: rotated so the smallest corner comes first.
LocalTri rotated(const LocalTri& t) {
  const int m = t[0] <= t[1] && t[0] <= t[2] ? 0 : t[1] <= t[2] ? 1 : 2;
  return {t[m], t[(m + 1) % 3], t[(m + 2) % 3]};
}

// An op's F and PreF over local vertex numbers: 0..k-1 its new vertices, then the others.
struct LocalOp {
  std::vector<VertexId> ids;  // local -> id
  std::vector<Vec3> positions;
  std::uint32_t k = 0;
  std::vector<LocalTri> f, pre;  // pre rotated()
};

LocalOp local_op(const OpView& op) {
  LocalOp l;
  l.k = op.new_vertex_count;
  IdMap<std::uint32_t> local;  // id -> 1 + local number
  const auto number = [&](const Vertex& v) {
    std::uint32_t& slot = local[v.id.value];
    if (slot == 0) {
      l.ids.push_back(v.id);
      l.positions.push_back(v.p);
      slot = static_cast<std::uint32_t>(l.ids.size());
    }
    return slot - 1;
  };
  for (std::uint32_t i = 0; i < l.k; ++i) number(op.own_vertex(i));
  for (const FragmentTriangle& t : op.fragment)
    l.f.push_back(
        {number(op.vertices[t.v[0]]), number(op.vertices[t.v[1]]), number(op.vertices[t.v[2]])});
  for (const PreTriangle& t : op.pre_tris)
    l.pre.push_back(rotated(
        {number(op.vertices[t.v[0]]), number(op.vertices[t.v[1]]), number(op.vertices[t.v[2]])}));
  return l;
}

constexpr std::uint32_t kSpawned = ~std::uint32_t{0};

/// phi: each new vertex's target (a local vertex that is not new), or kSpawned (a component
/// refinement spawns: it grows from `spawn_at`, the centroid of its vertices).
struct CollapseMap {
  std::vector<std::uint32_t> to;
  std::vector<Vec3> spawn_at;
  std::uint64_t inexact = 0;
};

// Depth-first search for phi with phi(F) = PreF (Hoppe's half-edge collapses, composed): each new
// vertex of a component that keeps old vertices is sent to an old vertex it reaches through new
// ones (a sequence of edge collapses can send it nowhere else), in order of distance from the old
// vertices; once all new corners of a triangle are sent, its image must vanish or be a PreF
// triangle not produced yet; at the end every PreF triangle must be produced.
class CollapseSearch {
 public:
  CollapseSearch(const LocalOp& op, const std::vector<std::uint8_t>& spawned);
  bool run(std::vector<std::uint32_t>& phi);

 private:
  bool place(std::size_t level);
  bool check(const std::vector<std::uint32_t>& tris);
  void release(const std::vector<std::uint32_t>& tris);

  static constexpr std::uint64_t kStepLimit = 1 << 20;
  const LocalOp& op_;
  std::vector<std::uint32_t> order_;                 // new vertices, in placing order
  std::vector<std::vector<std::uint32_t>> options_;  // per level: targets to try
  std::vector<std::vector<std::uint32_t>> decided_;  // per level + 1: triangles fixed there
  std::vector<std::uint32_t> phi_;                   // local -> local (old ones: themselves)
  std::vector<std::int32_t> made_by_;                // per PreF triangle: F triangle, or -1
  std::uint64_t steps_ = 0;
};

CollapseSearch::CollapseSearch(const LocalOp& op, const std::vector<std::uint8_t>& spawned)
    : op_(op), phi_(op.ids.size()), made_by_(op.pre.size(), -1) {
  std::iota(phi_.begin(), phi_.end(), std::uint32_t{0});
  const std::size_t n = op.ids.size();
  std::vector<std::vector<std::uint32_t>> adj(n);
  for (const LocalTri& t : op.f) {
    for (int c = 0; c < 3; ++c) adj[t[c]].push_back(t[(c + 1) % 3]);
    for (int c = 0; c < 3; ++c) adj[t[(c + 1) % 3]].push_back(t[c]);
  }
  // Distance of each new vertex from the old ones (breadth first from all of them at once).
  std::vector<std::uint32_t> dist(n, kSpawned), frontier;
  for (std::uint32_t v = op.k; v < n; ++v) {
    dist[v] = 0;
    frontier.push_back(v);
  }
  for (std::size_t i = 0; i < frontier.size(); ++i) {
    for (std::uint32_t w : adj[frontier[i]]) {
      if (dist[w] != kSpawned) continue;
      dist[w] = dist[frontier[i]] + 1;
      frontier.push_back(w);
    }
  }
  for (std::uint32_t v = 0; v < op.k; ++v) {
    if (!spawned[v]) order_.push_back(v);
  }
  std::stable_sort(order_.begin(), order_.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return dist[a] < dist[b]; });
  // Targets: the old vertices reachable from v through new ones.
  std::vector<std::uint32_t> seen(n, kSpawned);
  for (std::uint32_t v : order_) {
    std::vector<std::uint32_t> stack{v}, targets;
    seen[v] = v;
    while (!stack.empty()) {
      const std::uint32_t u = stack.back();
      stack.pop_back();
      for (std::uint32_t w : adj[u]) {
        if (seen[w] == v) continue;
        seen[w] = v;
        (w >= op.k ? targets : stack).push_back(w);
      }
    }
    options_.push_back(std::move(targets));
  }
  // The level at which each triangle of the searched part is fixed (0: before any choice).
  std::vector<std::uint32_t> level_of(n, 0);
  for (std::uint32_t i = 0; i < order_.size(); ++i) level_of[order_[i]] = i + 1;
  decided_.resize(order_.size() + 1);
  for (std::uint32_t i = 0; i < op.f.size(); ++i) {
    const LocalTri& t = op.f[i];
    if (t[0] < op.k && spawned[t[0]]) continue;
    decided_[std::max({level_of[t[0]], level_of[t[1]], level_of[t[2]]})].push_back(i);
  }
}

bool CollapseSearch::check(const std::vector<std::uint32_t>& tris) {
  for (std::uint32_t i : tris) {
    const LocalTri& t = op_.f[i];
    const LocalTri image{phi_[t[0]], phi_[t[1]], phi_[t[2]]};
    if (image[0] == image[1] || image[1] == image[2] || image[2] == image[0]) continue;
    const auto it = std::find(op_.pre.begin(), op_.pre.end(), rotated(image));
    const auto p = static_cast<std::size_t>(it - op_.pre.begin());
    if (it == op_.pre.end() || made_by_[p] >= 0) {
      release(tris);
      return false;
    }
    made_by_[p] = static_cast<std::int32_t>(i);
  }
  return true;
}

void CollapseSearch::release(const std::vector<std::uint32_t>& tris) {
  for (std::int32_t& m : made_by_) {
    if (m >= 0 && std::find(tris.begin(), tris.end(), std::uint32_t(m)) != tris.end()) m = -1;
  }
}

bool CollapseSearch::place(std::size_t level) {
  if (level == order_.size()) return std::count(made_by_.begin(), made_by_.end(), -1) == 0;
  for (std::uint32_t target : options_[level]) {
    if (++steps_ > kStepLimit) return false;
    phi_[order_[level]] = target;
    if (!check(decided_[level + 1])) continue;
    if (place(level + 1)) return true;
    release(decided_[level + 1]);
  }
  return false;
}

bool CollapseSearch::run(std::vector<std::uint32_t>& phi) {
  if (!check(decided_[0]) || !place(0)) return false;
  for (std::uint32_t v : order_) phi[v] = phi_[v];
  return true;
}

CollapseMap collapse_map(const LocalOp& op) {
  const std::size_t n = op.ids.size();
  Components parts(n);
  for (const LocalTri& t : op.f) {
    parts.join(t[0], t[1]);
    parts.join(t[0], t[2]);
  }
  // Components of F with no old vertex are spawned (Brown 4.4.1, Fig. 4.9d).
  std::vector<std::uint8_t> keeps_old(n, 0), spawned(op.k, 0);
  for (std::size_t v = op.k; v < n; ++v) keeps_old[parts.find(std::uint32_t(v))] = 1;
  std::vector<Vec3> sum(n, Vec3{0.0});
  std::vector<std::uint32_t> count(n, 0);
  for (std::uint32_t v = 0; v < op.k; ++v) {
    const std::uint32_t r = parts.find(v);
    spawned[v] = keeps_old[r] == 0;
    sum[r] += op.positions[v];
    ++count[r];
  }
  CollapseMap c;
  c.to.assign(op.k, kSpawned);
  c.spawn_at.assign(op.k, Vec3{0.0});
  for (std::uint32_t v = 0; v < op.k; ++v) {
    const std::uint32_t r = parts.find(v);
    if (spawned[v]) c.spawn_at[v] = sum[r] / double(count[r]);
  }
  if (CollapseSearch(op, spawned).run(c.to)) return c;
  // No map: each vertex starts at the nearest vertex of PreF (of F if PreF has none).
  std::vector<std::uint8_t> in_pre(n, 0);
  for (const LocalTri& t : op.pre) in_pre[t[0]] = in_pre[t[1]] = in_pre[t[2]] = 1;
  const bool any_pre = !op.pre.empty();
  for (std::uint32_t v = 0; v < op.k; ++v) {
    if (spawned[v]) continue;
    ++c.inexact;
    double best = std::numeric_limits<double>::infinity();
    for (std::uint32_t w = op.k; w < n; ++w) {
      const double d = glm::length(op.positions[w] - op.positions[v]);
      if ((in_pre[w] || !any_pre) && d < best) best = d, c.to[v] = w;
    }
    if (c.to[v] == kSpawned) c.spawn_at[v] = op.positions[v];
  }
  return c;
}

/// Where each vertex of the changed region's ops comes from: its own position, and for new
/// vertices of added (side 0) or removed (side 1) ops, the collapse that hides them on that side.
class Origins {
 public:
  void add_op(const LocalOp& op, const CollapseMap& c, int side) {
    for (std::uint32_t v = 0; v < op.ids.size(); ++v) {
      std::uint32_t& slot = own_[op.ids[v].value];
      if (slot == 0) {
        positions_.push_back(op.positions[v]);
        slot = static_cast<std::uint32_t>(positions_.size());
      }
    }
    for (std::uint32_t v = 0; v < op.k; ++v) {
      hidden_[op.ids[v].value] = static_cast<std::uint32_t>(hides_.size()) + 1;
      hides_.push_back({side, c.to[v] == kSpawned ? VertexId{} : op.ids[c.to[v]], c.spawn_at[v]});
    }
  }
  /// The position of vertex v on `side` (0: X_prev at t = 0, 1: X_new at t = 1).
  Vec3 at(VertexId v, int side) const {
    for (std::size_t steps = 0; steps <= hides_.size(); ++steps) {
      const std::uint32_t* h = hidden_.find(v.value);
      if (h == nullptr || hides_[*h - 1].side != side) break;
      const Hide& hide = hides_[*h - 1];
      if (!hide.to.valid()) return hide.at;
      v = hide.to;
    }
    const std::uint32_t* own = own_.find(v.value);
    if (own == nullptr) throw_internal("mesh_morph: a vertex of no changed op");
    return positions_[*own - 1];
  }

 private:
  struct Hide {
    int side;
    VertexId to;  // invalid: a spawned vertex, at `at`
    Vec3 at;
  };
  IdMap<std::uint32_t> own_, hidden_;  // vertex id -> 1 + index
  std::vector<Vec3> positions_;
  std::vector<Hide> hides_;
};

}  // namespace

MorphMesh terrain_morph(const OpSource& source, std::span<const TriRef> out,
                        std::span<const TriRef> in) {
  if (source.info().kind != ModelKind::kTerrain) throw_input("terrain_morph needs a terrain");
  TerrainOverlay overlay(source.info(), read_terrain(source, out), read_terrain(source, in));
  return overlay.run();
}

MorphMesh mesh_morph(const OpSource& source, const std::function<bool(OpId)>& in_union,
                     std::span<const OpId> added, std::span<const OpId> removed) {
  MorphMesh mesh;
  Origins origins;
  IdMap<std::uint32_t> index_of;  // vertex id -> 1 + morph vertex
  std::vector<VertexId> ids;
  for (int side = 0; side < 2; ++side) {
    for (OpId id : side == 0 ? added : removed) {
      const OpRef ref = source.op(id);
      const OpView& op = *ref;
      const LocalOp local = local_op(op);
      const CollapseMap c = collapse_map(local);
      mesh.inexact_vertices += c.inexact;
      origins.add_op(local, c, side);
      for (std::size_t i = 0; i < op.fragment.size(); ++i) {
        const FragmentTriangle& t = op.fragment[i];
        if (t.killer.valid() && in_union(t.killer)) continue;
        std::array<std::uint32_t, 3> tri{};
        for (int k = 0; k < 3; ++k) {
          const VertexId v = local.ids[local.f[i][k]];
          std::uint32_t& slot = index_of[v.value];
          if (slot == 0) {
            ids.push_back(v);
            slot = static_cast<std::uint32_t>(ids.size());
          }
          tri[k] = slot - 1;
        }
        mesh.triangles.push_back(tri);
        mesh.flags.push_back(static_cast<std::uint8_t>(
            t.is_void() ? MorphMesh::kVoidStart | MorphMesh::kVoidEnd : 0));
      }
    }
  }
  for (VertexId v : ids) {
    mesh.start.push_back(origins.at(v, 0));
    mesh.end.push_back(origins.at(v, 1));
  }
  Components parts(ids.size());
  for (const auto& tri : mesh.triangles) {
    parts.join(tri[0], tri[1]);
    parts.join(tri[0], tri[2]);
  }
  mesh.groups = parts.label(mesh.group);
  return mesh;
}

}  // namespace smr
