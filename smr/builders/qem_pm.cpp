// Quadric edge collapse into a CRMR (see qem_pm.h). Two passes:
//  1. simplify: half-edge collapses from a lazy priority queue (one best candidate per vertex,
//     re-validated when popped; refused when its new triangles would cross the mesh),
//     recording for each collapse the triangles it removed and made;
//  2. emit: order the reversed collapses (vertex splits) topologically, largest error first,
//     and replay them from the base mesh to assign triangles to ops, find each fragment boundary
//     edge's closest coarser version (Brown 4.5.1) and the mesh error before each split.
#include "smr/builders/qem_pm.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <exception>
#include <functional>
#include <limits>
#include <mutex>
#include <numeric>
#include <queue>
#include <span>
#include <thread>
#include <unordered_map>
#include <unordered_set>

#include <glm/geometric.hpp>

#include "base/error.h"
#include "smr/builders/exact_intersection.h"
#include "smr/builders/op_assembly.h"
#include "smr/builders/star_distance.h"
#include "smr/core/geometry.h"
#include "smr/core/id_map.h"
#include "smr/core/parallel.h"
#include "storage/external_sort.h"

namespace smr {

namespace {

constexpr std::uint32_t kNone = ~std::uint32_t{0};

// Incremental bookkeeping recomputed in full and compared (CMake SMRDB_SELF_CHECKS: the
// sanitizer preset's tests).
#ifdef SMRDB_SELF_CHECKS
constexpr bool kSelfChecks = true;
#else
constexpr bool kSelfChecks = false;
#endif

// Garland & Heckbert's fundamental error quadric: the sum of w (n.p + d)^2 over planes.
struct Quadric {
  std::array<double, 10> q{};  // aa ab ac ad bb bc bd cc cd dd
  void add_plane(const Vec3& n, double d, double w) {
    const double a = n.x, b = n.y, c = n.z;
    const std::array<double, 10> t{a * a, a * b, a * c, a * d, b * b,
                                   b * c, b * d, c * c, c * d, d * d};
    for (int i = 0; i < 10; ++i) q[i] += w * t[i];
  }
  Quadric& operator+=(const Quadric& o) {
    for (int i = 0; i < 10; ++i) q[i] += o.q[i];
    return *this;
  }
  double eval(const Vec3& p) const {
    const double x = p.x, y = p.y, z = p.z;
    return q[0] * x * x + 2 * q[1] * x * y + 2 * q[2] * x * z + 2 * q[3] * x + q[4] * y * y +
           2 * q[5] * y * z + 2 * q[6] * y + q[7] * z * z + 2 * q[8] * z + q[9];
  }
};

// The plane of triangle (a, b, c) weighted by its area; empty for a degenerate triangle.
Quadric face_quadric(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = glm::cross(b - a, c - a);
  const double len = glm::length(n);
  Quadric q;
  if (len > 0.0) q.add_plane(n / len, -glm::dot(n / len, a), 0.5 * len);
  return q;
}

// Spreads the low 21 bits of x to every third bit (Morton order).
std::uint64_t spread3(std::uint64_t x) {
  x &= 0x1fffff;
  x = (x | x << 32) & 0x1f00000000ffffULL;
  x = (x | x << 16) & 0x1f0000ff0000ffULL;
  x = (x | x << 8) & 0x100f00f00f00f00fULL;
  x = (x | x << 4) & 0x10c30c30c30c30c3ULL;
  x = (x | x << 2) & 0x1249249249249249ULL;
  return x;
}

// The Morton code of p in the box lo + [0, extent] (21 bits per axis; a flat axis is 0).
std::uint64_t morton_code(const Vec3& p, const Vec3& lo, const Vec3& extent) {
  std::uint64_t code = 0;
  for (int a = 0; a < 3; ++a) {
    const double u = extent[a] > 0.0 ? (p[a] - lo[a]) / extent[a] : 0.0;
    code |= spread3(static_cast<std::uint64_t>(std::clamp(u, 0.0, 1.0) * 2097151.0)) << a;
  }
  return code;
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
  std::uint32_t old_begin = 0, old_end = 0;  // into old_tris_: the star of `removed` before
  std::uint32_t new_begin = 0, new_end = 0;  // into new_tris_: the triangles that replaced it
  double error = 0.0;  // the largest bound of its new triangles, at least its creators' errors
};

struct Candidate {
  double cost;
  std::uint32_t from, to, stamp;
  // The in-core builder's post_ahead() is done with it for its band: handed over, or never
  // current again (not part of the order).
  bool looked = false;
  // std::priority_queue is a max-heap: the "largest" is the cheapest, ties by vertex ids.
  bool operator<(const Candidate& o) const {
    if (cost != o.cost) return cost > o.cost;
    if (from != o.from) return from > o.from;
    return to > o.to;
  }
};

std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
  return (std::uint64_t(a) << 32) | b;
}

// Live triangles by their bounding boxes, for the self-intersection test: a hierarchy of uniform
// grids (cell sizes cell * 2^level, cells in open-addressing tables: std::unordered_map's node
// chains made the lookups most of the test's time on large meshes), each triangle in the one
// cell of the level whose cells are at least its box's extent that holds its box's centre. At a
// level of cell size s, a box then meets only triangles of the cells holding its own box grown
// by s / 2; where that range has more cells than the level holds, the level's cells are scanned
// instead. A cell keeps its triangles' boxes, so the boxes that miss the query are dropped
// without touching the mesh.
class TriangleGrid {
 public:
  void reset(const Vec3& origin, double cell) {
    origin_ = origin;
    cell_ = cell > 0.0 ? cell : 1.0;
    levels_.assign(kLevels, {});
    where_.clear();
  }
  void insert(std::uint32_t id, const Box3& b) {
    const Vec3 e = b.hi - b.lo;
    const double extent = std::max({e.x, e.y, e.z});
    int level = 0;
    double size = cell_;
    while (size < extent && level + 1 < kLevels) size *= 2.0, ++level;
    Level& l = levels_[std::size_t(level)];
    const std::uint64_t key = key_of(index_of(0.5 * (b.lo + b.hi), size));
    std::uint32_t& slot = l.index[key];  // the cell's index + 1; 0: a new cell
    if (slot == 0) {
      l.keys.push_back(key);
      l.ids.emplace_back();
      slot = static_cast<std::uint32_t>(l.keys.size());
    }
    const std::uint32_t cell = slot - 1;
    if (l.ids[cell].empty()) ++l.occupied;
    l.ids[cell].push_back(Entry::of(id, b));
    if (where_.size() <= id) where_.resize(std::size_t(id) + 1, {kNoLevel, 0});
    where_[id] = {level, cell};
  }
  void erase(std::uint32_t id) {
    if (id >= where_.size() || where_[id].first == kNoLevel) return;
    Level& l = levels_[std::size_t(where_[id].first)];
    std::vector<Entry>& ids = l.ids[where_[id].second];
    *std::find_if(ids.begin(), ids.end(), [&](const Entry& e) { return e.id == id; }) = ids.back();
    ids.pop_back();
    if (ids.empty()) --l.occupied;
    where_[id].first = kNoLevel;
  }
  // f(id, box) for every triangle whose box meets b (box: its box, rounded outwards to floats).
  template <class F>
  void visit(const Box3& b, F&& f) const {
    double size = cell_;
    for (int level = 0; level < kLevels; ++level, size *= 2.0) {
      const Level& l = levels_[std::size_t(level)];
      if (l.occupied == 0) continue;
      const Vec3 half(0.5 * size);
      const std::array<std::int64_t, 3> lo = index_of(b.lo - half, size),
                                        hi = index_of(b.hi + half, size);
      double range = 1.0;
      for (int k = 0; k < 3; ++k) range *= double(hi[std::size_t(k)] - lo[std::size_t(k)] + 1);
      const auto inside = [&](std::uint64_t key) {
        for (int k = 0; k < 3; ++k) {
          const auto i = std::int64_t((key >> (21 * k)) & kMask) - kOffset;
          if (i < lo[std::size_t(k)] || i > hi[std::size_t(k)]) return false;
        }
        return true;
      };
      if (range > double(l.keys.size())) {  // fewer cells than the range: all of them
        for (std::size_t c = 0; c < l.keys.size(); ++c) {
          if (l.ids[c].empty() || !inside(l.keys[c])) continue;
          for (const Entry& e : l.ids[c]) e.visit(b, f);
        }
        continue;
      }
      for (std::int64_t x = lo[0]; x <= hi[0]; ++x) {
        for (std::int64_t y = lo[1]; y <= hi[1]; ++y) {
          for (std::int64_t z = lo[2]; z <= hi[2]; ++z) {
            const std::uint32_t* slot = l.index.find(key_of({x, y, z}));
            if (slot == nullptr) continue;
            for (const Entry& e : l.ids[*slot - 1]) e.visit(b, f);
          }
        }
      }
    }
  }

 private:
  static constexpr int kLevels = 40;
  static constexpr int kNoLevel = -1;
  static constexpr std::int64_t kOffset = std::int64_t{1} << 20;
  static constexpr std::uint64_t kMask = (std::uint64_t{1} << 21) - 1;
  // A triangle and its box in floats, rounded outwards: the box test runs on the cell's own
  // memory (looking up each triangle's corners missed the cache on most visits).
  struct Entry {
    std::uint32_t id;
    std::array<float, 3> lo, hi;
    static Entry of(std::uint32_t id, const Box3& b) {
      Entry e{id, {}, {}};
      for (int k = 0; k < 3; ++k) {
        e.lo[std::size_t(k)] = below(b.lo[k]);
        e.hi[std::size_t(k)] = above(b.hi[k]);
      }
      return e;
    }
    static float below(double x) {
      const auto f = static_cast<float>(x);
      return double(f) <= x ? f : std::nextafter(f, -std::numeric_limits<float>::infinity());
    }
    static float above(double x) {
      const auto f = static_cast<float>(x);
      return double(f) >= x ? f : std::nextafter(f, std::numeric_limits<float>::infinity());
    }
    template <class F>
    void visit(const Box3& b, F& f) const {
      for (int k = 0; k < 3; ++k) {
        if (double(lo[std::size_t(k)]) > b.hi[k] || double(hi[std::size_t(k)]) < b.lo[k]) return;
      }
      Box3 box;
      box.lo = Vec3(lo[0], lo[1], lo[2]);
      box.hi = Vec3(hi[0], hi[1], hi[2]);
      f(id, box);
    }
  };
  // One grid: its cells in a flat hash table (cells emptied stay, to be filled again).
  struct Level {
    IdMap<std::uint32_t> index;           // cell key -> its index + 1
    std::vector<std::uint64_t> keys;      // per cell
    std::vector<std::vector<Entry>> ids;  // per cell: its triangles
    std::size_t occupied = 0;             // cells holding a triangle
  };
  std::array<std::int64_t, 3> index_of(const Vec3& p, double size) const {
    std::array<std::int64_t, 3> i{};
    for (int k = 0; k < 3; ++k) {
      const double c = std::floor((p[k] - origin_[k]) / size);
      i[std::size_t(k)] = std::int64_t(std::clamp(c, -double(kOffset), double(kOffset - 1)));
    }
    return i;
  }
  // 3 x 21 bits: never IdMap's empty key.
  static std::uint64_t key_of(const std::array<std::int64_t, 3>& i) {
    std::uint64_t key = 0;
    for (int k = 0; k < 3; ++k) key |= std::uint64_t(i[std::size_t(k)] + kOffset) << (21 * k);
    return key;
  }
  Vec3 origin_{0.0};
  double cell_ = 1.0;
  std::vector<Level> levels_;
  std::vector<std::pair<int, std::uint32_t>> where_;  // triangle -> (level, cell); kNoLevel: none
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

class Builder {
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

 public:
  // The vertices are renumbered in Morton order of their positions and the triangles sorted by
  // their first corner, so that neighbours lie close in every per-vertex and per-triangle array
  // (a source's own order may scatter them: the 832k-triangle midpoint-subdivided armadillo built
  // 17 % faster in this order); ops name the source's vertex ids (source_id_).
  Builder(const TriangleMesh& mesh, const QemPmOptions& options) : options_(options) {
    const std::size_t n = mesh.positions.size();
    for (const auto& t : mesh.triangles) {
      for (std::uint32_t v : t) {
        if (v >= n) throw_input("mesh: a triangle references a vertex out of range");
      }
    }
    Box3 box;
    for (const Vec3& p : mesh.positions) box.add(p);
    std::vector<std::pair<std::uint64_t, std::uint32_t>> codes(n);
    for (std::uint32_t v = 0; v < n; ++v) {
      codes[v] = {morton_code(mesh.positions[v], box.lo, box.hi - box.lo), v};
    }
    std::sort(codes.begin(), codes.end());
    std::vector<std::uint32_t> renumbered(n);
    source_id_.resize(n);
    pos_.resize(n);
    for (std::uint32_t i = 0; i < n; ++i) {
      source_id_[i] = codes[i].second;
      renumbered[codes[i].second] = i;
      pos_[i] = mesh.positions[codes[i].second];
    }
    std::vector<std::pair<std::uint32_t, std::uint32_t>> first;  // (first corner, triangle)
    first.reserve(mesh.triangles.size());
    for (std::uint32_t i = 0; i < mesh.triangles.size(); ++i) {
      const auto& t = mesh.triangles[i];
      first.push_back({std::min({renumbered[t[0]], renumbered[t[1]], renumbered[t[2]]}), i});
    }
    std::sort(first.begin(), first.end());
    quad_.resize(n);
    init_arrays(first.size());
    for (const auto& [corner, i] : first) {
      const auto& t = mesh.triangles[i];
      add_triangle(Tri{{renumbered[t[0]], renumbered[t[1]], renumbered[t[2]]}, 0.0, kNone, kNone});
    }
    init_quadrics_and_boundary();
    init_components();
  }

  /// A block of the out-of-core builder: local vertices with their (partial) quadrics and
  /// locks, triangles with their bounds. `constrain[v]`: v was locked one level below, so open
  /// edges of v's that now have an unlocked end get their boundary constraint planes here.
  Builder(const QemPmOptions& options, std::vector<Vec3> pos, std::vector<Quadric> quad,
          std::vector<std::uint8_t> locked, const std::vector<std::uint8_t>& constrain,
          const std::vector<Tri>& tris, const std::string& what,
          const std::vector<std::uint32_t>& ids)
      : options_(options) {
    pos_ = std::move(pos);
    quad_ = std::move(quad);
    locked_ = std::move(locked);
    init_arrays(tris.size());
    for (const Tri& t : tris) add_triangle(t);
    // Both triangles with a directed edge meet in one block by the level that unlocks its ends,
    // before any collapse touches them: the streamed mesh's manifold-edge and orientation check.
    std::uint64_t twice = kNoEdge;
    const auto directed = directed_edges(&twice);
    if (twice != kNoEdge) {
      throw_input("mesh '" + what + "': the edge from vertex " + std::to_string(ids[twice >> 32]) +
                  " to vertex " + std::to_string(ids[twice & 0xffffffffu]) +
                  " is used twice in the same direction (a non-manifold edge or inconsistent "
                  "orientation); ingest it in memory (without --memory) with --repair");
    }
    // A vertex unlocked here for the first time (all of them in a leaf block: constrain is set
    // at level 0) has all its faces in this block; collapses below kept its star's fans apart or
    // together as they were, so this is the streamed mesh's non-manifold vertex check.
    for (std::uint32_t v = 0; v < pos_.size(); ++v) {
      if (locked_[v] || !constrain[v] || fans(v) <= 1) continue;
      throw_input("mesh '" + what + "': vertex " + std::to_string(ids[v]) +
                  " is non-manifold: its faces form more than one fan (they share it but are "
                  "not connected through edges around it); expected one fan per vertex; ingest "
                  "it in memory (without --memory) with --repair, which splits it");
    }
    for (const Tri& t : tris_) {
      for (int k = 0; k < 3; ++k) {
        const std::uint32_t a = t.v[k], b = t.v[(k + 1) % 3];
        if (directed.contains(edge_key(b, a))) continue;
        boundary_[a] = boundary_[b] = 1;  // exact for unlocked vertices (all their faces are here)
        if ((locked_[a] && locked_[b]) || !(constrain[a] && constrain[b])) continue;
        add_constraint(t, k);
      }
    }
    init_components();
  }

  Crmr run(const std::string& name, QemPmStats* stats) {
    simplify();
    if (options_.spawn_components && exhausted_) remove_components();
    Crmr crmr = emit(name);
    if (stats != nullptr) {
      stats_.collapses = collapses_.size() - stats_.spawned_components;
      stats_.bounds_computed = scratch_.computed;
      stats_.base_triangles = crmr.ops[0].fragment.size();
      stats_.base_vertices = crmr.ops[0].vertices.size();
      *stats = stats_;
    }
    return crmr;
  }

 private:
  // ---- mesh state ---------------------------------------------------------------------------

  std::uint32_t add_triangle(const Tri& t) {
    const auto id = static_cast<std::uint32_t>(tris_.size());
    tris_.push_back(t);
    for (std::uint32_t v : t.v) {
      star_[v].push_back(id);
      ++star_version_[v];
    }
    if (grid_ready_) grid_.insert(id, box_of(t.v));
    return id;
  }
  Box3 box_of(const std::array<std::uint32_t, 3>& v) const {
    Box3 b;
    for (std::uint32_t w : v) b.add(pos_[w]);
    return b;
  }
  void unlink_triangle(std::uint32_t id, std::uint32_t except) {
    for (std::uint32_t v : tris_[id].v) {
      if (v == except) continue;
      auto& s = star_[v];
      s.erase(std::find(s.begin(), s.end(), id));
      ++star_version_[v];
    }
  }
  // Connected pieces of v's star, triangles joined through the edges around v.
  std::size_t fans(std::uint32_t v) const {
    const std::vector<std::uint32_t>& star = star_[v];
    std::vector<std::pair<std::uint32_t, std::uint32_t>> rim;  // (other corner, star index)
    rim.reserve(2 * star.size());
    for (std::uint32_t i = 0; i < star.size(); ++i) {
      for (std::uint32_t w : tris_[star[i]].v) {
        if (w != v) rim.push_back({w, i});
      }
    }
    std::sort(rim.begin(), rim.end());
    std::vector<std::uint32_t> parent(star.size());
    std::iota(parent.begin(), parent.end(), 0u);
    const auto root = [&](std::uint32_t i) {
      while (parent[i] != i) i = parent[i] = parent[parent[i]];
      return i;
    };
    std::size_t pieces = star.size();
    for (std::size_t j = 1; j < rim.size(); ++j) {
      if (rim[j].first != rim[j - 1].first) continue;
      const std::uint32_t a = root(rim[j].second), b = root(rim[j - 1].second);
      if (a == b) continue;
      parent[a] = b;
      --pieces;
    }
    return pieces;
  }
  static bool has(const Tri& t, std::uint32_t v) {
    return t.v[0] == v || t.v[1] == v || t.v[2] == v;
  }
  Vec3 normal(const std::array<std::uint32_t, 3>& v) const {
    return glm::cross(pos_[v[1]] - pos_[v[0]], pos_[v[2]] - pos_[v[0]]);
  }

  // The per-vertex arrays for pos_.size() vertices, room for the triangles and their
  // replacements, and the normal-turn threshold.
  void init_arrays(std::size_t triangles) {
    const std::size_t n = pos_.size();
    star_.resize(n);
    star_version_.assign(n, 0);
    removed_.assign(n, 0);
    boundary_.assign(n, 0);
    stamp_.assign(n, 0);
    marks_.of.assign(n, 0);
    blocked_.assign(n, {});
    cheapest_.assign(n, kUnknown);
    tris_.reserve(triangles * 2);
    cos_max_turn_ = std::cos(options_.max_normal_turn_degrees * 3.14159265358979323846 / 180.0);
  }

  static constexpr std::uint64_t kNoEdge = ~std::uint64_t{0};
  // The triangles' directed edges; `twice`, if given, gets an edge two triangles have.
  IdMap<std::uint8_t> directed_edges(std::uint64_t* twice) const {
    IdMap<std::uint8_t> directed;
    directed.reserve(tris_.size() * 3);
    for (const Tri& t : tris_) {
      for (int k = 0; k < 3; ++k) {
        const std::uint64_t key = edge_key(t.v[k], t.v[(k + 1) % 3]);
        if (!directed.insert(key) && twice != nullptr && *twice == kNoEdge) *twice = key;
      }
    }
    return directed;
  }

  void init_quadrics_and_boundary() {
    // Face planes weighted by area; each boundary edge adds a constraint plane through it,
    // perpendicular to its face (Garland & Heckbert 1997, section 6.1).
    const auto directed = directed_edges(nullptr);
    for (const Tri& t : tris_) {
      if (!(glm::length(normal(t.v)) > 0.0)) continue;
      const Quadric q = face_quadric(pos_[t.v[0]], pos_[t.v[1]], pos_[t.v[2]]);
      for (std::uint32_t v : t.v) quad_[v] += q;
      for (int k = 0; k < 3; ++k) {
        const std::uint32_t a = t.v[k], b = t.v[(k + 1) % 3];
        if (directed.contains(edge_key(b, a))) continue;
        boundary_[a] = boundary_[b] = 1;
        add_constraint(t, k);
      }
    }
  }

  // The constraint plane of boundary edge k of t: through the edge, perpendicular to t.
  void add_constraint(const Tri& t, int k) {
    const std::uint32_t a = t.v[k], b = t.v[(k + 1) % 3];
    const Vec3 c = normal(t.v);
    const double len = glm::length(c);
    if (!(len > 0.0)) return;
    const Vec3 e = pos_[b] - pos_[a];
    Vec3 m = glm::cross(e, c / len);
    const double ml = glm::length(m);
    if (!(ml > 0.0)) return;
    m /= ml;
    Quadric bq;
    bq.add_plane(m, -glm::dot(m, pos_[a]), options_.boundary_weight * glm::dot(e, e));
    quad_[a] += bq;
    quad_[b] += bq;
  }

  void init_components() {
    const std::size_t n = pos_.size();
    std::vector<std::uint32_t> parent(n);
    std::iota(parent.begin(), parent.end(), 0u);
    auto find = [&](std::uint32_t x) {
      while (parent[x] != x) x = parent[x] = parent[parent[x]];
      return x;
    };
    for (const Tri& t : tris_) {
      for (int k = 1; k < 3; ++k) parent[find(t.v[k])] = find(t.v[0]);
    }
    comp_.resize(n);
    std::unordered_map<std::uint32_t, std::uint32_t> ids;
    for (std::uint32_t v = 0; v < n; ++v) {
      if (star_[v].empty()) {
        comp_[v] = kNone;
        removed_[v] = 1;  // unreferenced: never part of the model
        continue;
      }
      auto [it, fresh] = ids.emplace(find(v), std::uint32_t(comp_vertices_.size()));
      if (fresh) {
        comp_vertices_.push_back(0);
        comp_open_.push_back(0);
      }
      comp_[v] = it->second;
      ++comp_vertices_[it->second];
      if (boundary_[v]) comp_open_[it->second] = 1;
    }
  }

  std::uint64_t alive_triangles() const {
    return static_cast<std::uint64_t>(std::count_if(
        tris_.begin(), tris_.end(), [](const Tri& t) { return t.destroyer == kNone; }));
  }
  std::uint64_t alive_vertices() const {
    return std::accumulate(comp_vertices_.begin(), comp_vertices_.end(), std::uint64_t{0});
  }

  // ---- candidates ---------------------------------------------------------------------------

  // Neighbours of v (sorted, unique) from its star.
  // The vertices sharing a triangle with v, each once, in the order the star meets them (every
  // user is indifferent to the order: candidates are ranked by (cost, id), the heap orders by
  // (cost, from, to), dirty lists are sorted).
  void neighbours(std::uint32_t v, std::vector<std::uint32_t>& out) const {
    out.clear();
    const std::uint32_t seen = marks_.next();
    for (std::uint32_t id : star_[v]) {
      for (std::uint32_t w : tris_[id].v) {
        if (w == v || marks_.of[w] == seen) continue;
        marks_.of[w] = seen;
        out.push_back(w);
      }
    }
  }

  // Whether collapsing from -> to keeps the mesh a manifold of the same topology with no
  // flipped or degenerate triangle (counts the reason when not).
  bool valid(std::uint32_t from, std::uint32_t to) {
    neighbours(from, nf_);
    return valid(from, to, nf_);
  }
  // With nf = neighbours(from).
  bool valid(std::uint32_t from, std::uint32_t to, const std::vector<std::uint32_t>& nf) {
    // A block's locked vertices stay, and a collapse needs its target's whole star (the link
    // condition), which a locked vertex has only partly in the block.
    if (is_locked(from) || is_locked(to)) return false;
    std::uint32_t shared = 0;
    std::array<std::uint32_t, 2> opposite{kNone, kNone};
    std::uint32_t replaced = 0;
    for (std::uint32_t id : star_[from]) {
      const Tri& t = tris_[id];
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
    if (boundary_[from] && !boundary_edge) {
      ++stats_.rejected_boundary;
      return false;
    }
    const std::uint32_t comp = comp_[from];
    if (comp_vertices_[comp] <= (comp_open_[comp] ? 3u : 4u)) return false;
    // Link condition: the common neighbours of from and to are exactly the edge's opposite
    // vertices (with a virtual vertex joined to the boundary, Dey et al.).
    const std::uint32_t in_nf = marks_.next();
    for (std::uint32_t w : nf) marks_.of[w] = in_nf;
    const std::uint32_t counted = marks_.next();
    std::uint32_t common = 0;
    for (std::uint32_t id : star_[to]) {
      for (std::uint32_t w : tris_[id].v) {
        if (w == to || marks_.of[w] != in_nf) continue;
        marks_.of[w] = counted;
        if (w != opposite[0] && w != opposite[1]) {
          ++stats_.rejected_link;
          return false;
        }
        ++common;
      }
    }
    if (common != shared) {
      ++stats_.rejected_link;
      return false;
    }
    // No triangle may flip, turn too far or degenerate.
    for (std::uint32_t id : star_[from]) {
      const Tri& t = tris_[id];
      if (has(t, to)) continue;
      std::array<std::uint32_t, 3> nv = t.v;
      for (std::uint32_t& w : nv) {
        if (w == from) w = to;
      }
      const Vec3 before = normal(t.v), after = normal(nv);
      const double lb = glm::length(before), la = glm::length(after);
      if (!(la > 1e-12 * (lb + 1e-300)) || !(la > 0.0)) {
        ++stats_.rejected_flip;
        return false;
      }
      if (lb > 0.0 && glm::dot(before, after) < cos_max_turn_ * lb * la) {
        ++stats_.rejected_flip;
        return false;
      }
    }
    return true;
  }

  double cost(std::uint32_t from, std::uint32_t to) const {
    Quadric q = quad_[from];
    q += quad_[to];
    return std::max(0.0, q.eval(pos_[to]));
  }

  // ranked_ = (cost, target) for the neighbours of `from` (cand_) that the self-intersection test
  // has not refused since its neighbourhood last changed; false when `from` cannot collapse.
  bool rank_targets(std::uint32_t from) {
    if (removed_[from] || is_locked(from)) return false;
    neighbours(from, cand_);
    ranked_.clear();
    const std::vector<std::uint32_t>& blocked = blocked_[from];
    for (std::uint32_t to : cand_) {
      if (std::find(blocked.begin(), blocked.end(), to) == blocked.end())
        ranked_.push_back({cost(from, to), to});
    }
    return true;
  }

  // The cheapest valid target of `from` and its cost (ties: the smaller id; kNone if none):
  // validity, the costly test, is checked in order of cost until one passes.
  // `failed`: a target just found not valid, not tested again.
  std::pair<double, std::uint32_t> cheapest_valid(std::uint32_t from,
                                                  std::uint32_t failed = kNone) {
    if (!rank_targets(from)) return {0.0, kNone};
    std::sort(ranked_.begin(), ranked_.end());
    for (const auto& [c, to] : ranked_) {
      if (to != failed && valid(from, to, cand_)) return {c, to};
    }
    return {0.0, kNone};
  }

  void push_best(std::uint32_t from, std::uint32_t failed = kNone) {
    ++stamp_[from];
    const auto [c, to] = cheapest_valid(from, failed);
    if (to != kNone) heap_.push({c, from, to, stamp_[from]});
  }

  // The cheapest target of `from` by cost alone: validity, the costly test, waits until the
  // candidate comes up (simplify() checks it then and, if it fails, pushes the cheapest valid
  // target instead). Most candidates are replaced before they come up.
  void push_cheapest(std::uint32_t from) { push_cheapest(from, cheapest_target(from)); }
  void push_cheapest(std::uint32_t from, std::pair<double, std::uint32_t> target) {
    ++stamp_[from];
    if (target.second != kNone) heap_.push({target.first, from, target.second, stamp_[from]});
  }

  // A target the self-intersection test refused `from`, until its neighbourhood changes.
  void refuse(std::uint32_t from, std::uint32_t to) {
    blocked_[from].push_back(to);
    cheapest_[from] = kUnknown;
  }

  // The cheapest target of `from` by cost (ties: the smaller id; kNone if none), kept in
  // cheapest_ (locked targets never pass valid(): skipped).
  std::pair<double, std::uint32_t> cheapest_target(std::uint32_t from) {
    std::pair<double, std::uint32_t> first = kUnknown;
    if (rank_targets(from)) {
      for (const auto& r : ranked_) {
        if (!is_locked(r.second) && (first.second == kNone || r < first)) first = r;
      }
    }
    return cheapest_[from] = first;
  }
  // The same for w, a vertex of the ring around `kept` after the collapse removed -> kept. Its
  // targets are those it had less `removed`, with `kept`, and only the cost to `kept` changed
  // (its quadric grew): a cheapest target that was neither stays cheapest unless `kept` is now
  // cheaper (same ties). 70 % of these are found so on the 832 k armadillo (blocks), 78 % on the
  // bunny (in core).
  std::pair<double, std::uint32_t> cheapest_after(std::uint32_t w, std::uint32_t removed,
                                                  std::uint32_t kept) {
    std::pair<double, std::uint32_t>& last = cheapest_[w];
    const std::vector<std::uint32_t>& refused = blocked_[w];
    if (last.second == kNone || last.second == removed || last.second == kept ||
        std::find(refused.begin(), refused.end(), kept) != refused.end()) {
      return cheapest_target(w);
    }
    last = std::min(last, {cost(w, kept), kept});
    if (kSelfChecks) {
      const std::pair<double, std::uint32_t> found = last;
      if (cheapest_target(w) != found)
        throw_internal("QEM PM: vertex " + std::to_string(w) +
                       "'s cheapest target after a collapse beside it is not the one in full");
    }
    return last;
  }

  // ---- error bound --------------------------------------------------------------------------

  // The bound of the collapse that made triangle id (a source triangle's own).
  double creator_error(std::uint32_t id) const {
    const Tri& t = tris_[id];
    return t.creator == kNone ? t.e : collapses_[t.creator].error;
  }

  // The collapse's bound (exact = true; s.new_e then holds its new triangles'), or a lower bound
  // of it once one exceeds `tolerance` (star_bound).
  std::pair<double, bool> bound_within(std::uint32_t from, std::uint32_t to, double tolerance,
                                       bool finish, BoundScratch& s) const {
    snapshot(from, to, s.snap);
    return star_bound(tolerance, finish, s);
  }

  // What the bound of collapsing `from` onto `to` depends on, copied out of the mesh.
  void snapshot(std::uint32_t from, std::uint32_t to, StarSnapshot& snap) const {
    snap.from = pos_[from];
    snap.to = pos_[to];
    snap.star.clear();
    for (std::uint32_t id : star_[from]) {
      const Tri& t = tris_[id];
      StarSnapshot::OldTriangle& o = snap.star.emplace_back();
      for (int k = 0; k < 3; ++k) {
        o.p[k] = pos_[t.v[k]];
        o.is_from[k] = t.v[k] == from;
      }
      o.e = t.e;
      o.creator_error = creator_error(id);
      o.has_to = has(t, to);
    }
  }

  // The bound of s.snap's collapse, or a lower bound of it once one exceeds `tolerance`, found
  // without computing it: the bound of a collapse it depends on (collapse_error's floor), or the
  // largest bound of an old triangle plus the removed vertex's distance to the new star (the
  // removed vertex is a corner of every old triangle, so the cell holding it is charged at least
  // that triangle's bound plus that distance, free or not: StarDistance::charge). Unless
  // `finish`, a bound found part way to exceed `tolerance` is not finished either
  // (collapse_error's stop_above): over a third of the bounds simplify() computes do, and that
  // collapse waits all the same. Reads nothing but `s`, so it runs on any thread.
  static std::pair<double, bool> star_bound(double tolerance, bool finish, BoundScratch& s) {
    // At least the bound of every collapse this one depends on, so that the splits' order
    // (largest error first) keeps their errors monotone: collapse_error's floor.
    double floor = 0.0, own = 0.0;
    for (const StarSnapshot::OldTriangle& t : s.snap.star) {
      floor = std::max(floor, t.creator_error);
      own = std::max(own, t.e);
    }
    if (floor > tolerance) return {floor, false};
    new_star(s);
    // No new star: the collapse is not valid (valid()), a helper may still be handed it.
    if (s.new_targets.empty()) return {std::numeric_limits<double>::infinity(), false};
    double d2 = std::numeric_limits<double>::infinity();
    for (const StarDistance::Target& t : s.new_targets)
      d2 = std::min(d2, t.distance.squared(s.snap.from));
    const double lower = std::max(floor, own + std::sqrt(d2));
    if (lower > tolerance) return {lower, false};
    const double stop = finish ? std::numeric_limits<double>::infinity() : tolerance;
    const double e = collapse_error(floor, stop, s);
    return {e, e <= stop};
  }

  // s.new_targets = the triangles the old star becomes when `from` collapses onto `to`, and
  // s.preimage = the old star's index of each.
  static void new_star(BoundScratch& s) {
    s.new_targets.clear();
    s.preimage.clear();
    for (std::uint32_t i = 0; i < s.snap.star.size(); ++i) {
      const StarSnapshot::OldTriangle& t = s.snap.star[i];
      if (t.has_to) continue;
      s.preimage.push_back(i);
      std::array<Vec3, 3> p = t.p;
      for (int k = 0; k < 3; ++k) {
        if (t.is_from[k]) p[k] = s.snap.to;
      }
      s.new_targets.push_back({p[0], p[1], p[2], 0.0});
    }
  }

  // The collapse's bound, with new_star() made and `floor` its creators' largest error; or, once
  // that exceeds `stop_above`, a lower bound of it above stop_above (the bound only rises as the
  // old triangles are charged to the new ones and the new ones to the old).
  static double collapse_error(double floor, double stop_above, BoundScratch& s) {
    ++s.computed;
    s.old_targets.clear();
    s.image.clear();
    std::uint32_t made = 0;
    for (const StarSnapshot::OldTriangle& t : s.snap.star) {
      s.old_targets.push_back({t.p[0], t.p[1], t.p[2], t.e});
      // The two triangles on the edge vanish; their nearest new one is a guess (the first).
      s.image.push_back(t.has_to ? 0u : made++);
    }
    // Forward: the source points assigned to each old triangle (within its e) go to their
    // nearest new triangles, whose bounds rise to hold them (StarDistance::charge). The largest
    // old bounds first, so the new ones rise early and more cells are free. (Ordering by a
    // depth-0 bound of each old triangle instead did that work twice and gave larger bounds.)
    s.to_new.reset(s.new_targets, s.snap.to);
    const StarDistance& to_new = s.to_new;
    s.order.clear();
    for (std::size_t i = 0; i < s.old_targets.size(); ++i) {
      s.order.push_back({s.old_targets[i].offset, i});
    }
    std::sort(s.order.begin(), s.order.end(), std::greater<>());
    s.new_e.assign(s.new_targets.size(), 0.0);
    double e = floor;  // every old triangle's points are charged at least its own bound
    for (const auto& [estimate, i] : s.order) {
      const StarDistance::Target& t = s.old_targets[i];
      to_new.charge(t.a, t.b, t.c, t.offset, kStarBoundDepth, s.image[i], s.new_e, e);
      if (e > stop_above) return e;
    }
    // Backward, per new triangle: its points to the old star, plus the old bounds. Pieces are
    // refined only while they could raise the collapse's bound so far (e), as charge() does: one
    // that could not leaves the collapse's bound as it is, and only loosens its new triangle's own
    // bound (at most to e, which the collapses that later destroy it reach anyway: err is
    // monotone). The ops' errors stay those of refining down to new_e[j]; the later collapses'
    // bounds hardly change (VDPM's 72 cuts: total triangles within 0.2 %), and the block build of
    // the 832 k-triangle armadillo takes 13 % less CPU.
    s.to_old.reset(s.old_targets, s.snap.from);
    const StarDistance& to_old = s.to_old;
    for (std::size_t j = 0; j < s.new_targets.size(); ++j) {
      const StarDistance::Target& t = s.new_targets[j];
      s.new_e[j] =
          std::max(s.new_e[j], to_old.bound(t.a, t.b, t.c, e, kStarBoundDepth, s.preimage[j]));
      e = std::max(e, s.new_e[j]);
      if (e > stop_above) return e;
    }
    return e;
  }

  // ---- self-intersections ------------------------------------------------------------------

  // Whether collapsing from -> to would make a new triangle cross another triangle of the mesh
  // (one that stays, or another new one) anywhere but in the corners and edges they share
  // (exact_intersection.h), unless a triangle of the old star crossed it already. Such a
  // collapse is refused (QemPmOptions::allow_self_intersections): a source that does not cross
  // itself gives no level that does, and one that does can still simplify around its crossings
  // (refusing every collapse near them stalled the repaired pig at 258 base triangles).
  bool crosses_after(std::uint32_t from, std::uint32_t to, double error) {
    if (options_.allow_self_intersections) return false;
    if (!grid_ready_) build_grid();
    made_.clear();
    for (std::uint32_t id : star_[from]) {
      const Tri& t = tris_[id];
      if (has(t, to)) continue;
      std::array<std::uint32_t, 3> v = t.v;
      for (std::uint32_t& w : v) {
        if (w == from) w = to;
      }
      made_.push_back(mesh_triangle(v));
    }
    if (tri_marks_.of.size() < tris_.size()) tri_marks_.of.resize(tris_.size() * 3 / 2, 0);
    const std::uint32_t old_star = tri_marks_.next();
    for (std::uint32_t id : star_[from]) tri_marks_.of[id] = old_star;
    // The triangles near the new star (one grid query for all of it), then pair by pair.
    Box3 all;
    made_boxes_.clear();
    for (const MeshTriangle& m : made_) {
      Box3 b;
      for (const Vec3& p : m.p) b.add(p);
      made_boxes_.push_back(b);
      all.add(b);
    }
    // The grid also holds the dead triangles of the recent bands (crosses_dead), by their
    // destroyers' bounds; they take no part in this test.
    near_.clear();
    dead_near_.clear();
    const double above = options_.coalesce_error_ratio * error;
    const auto sort_near = [&](std::uint32_t id, const Box3& tb) {
      const std::uint32_t destroyer = tris_[id].destroyer;
      if (destroyer == kNone) {
        if (tri_marks_.of[id] != old_star) near_.push_back({id, tb});
      } else if (collapses_[destroyer].error > above) {
        dead_near_.push_back({id, tb});
      }
    };
    grid_.visit(all, sort_near);
    if (archive_largest_ > above) archive_.visit(all, sort_near);
    bool crossed = false;
    for (std::size_t i = 0; i < made_.size() && !crossed; ++i) {
      const MeshTriangle& m = made_[i];
      for (std::size_t j = i + 1; j < made_.size() && !crossed; ++j) {
        crossed = triangles_cross(m, made_[j]);
      }
      for (std::size_t j = 0; j < near_.size() && !crossed; ++j) {
        if (!near_[j].second.intersects(made_boxes_[i])) continue;
        const MeshTriangle other = mesh_triangle(tris_[near_[j].first].v);
        crossed = triangles_cross(m, other) && !crossed_before(from, other);
      }
    }
    if (!crossed && !dead_near_.empty()) crossed = crosses_dead(from, above);
    if (crossed) ++stats_.rejected_intersection;
    return crossed;
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
  // collapses with bounds above r b alone. The live triangles are tested above; here, the
  // new star against the dead triangles of the other collapses with b(x) > r b (dead_near_,
  // found by crosses_after's grid query). With this, no cut at one error crosses where the
  // source does not (cuts of varying error are not covered: two triangles from states apart in
  // the order, far apart in error, are never tested).
  bool crosses_dead(std::uint32_t from, double above) {
    bool depends_known = false;
    std::uint32_t depends = 0;
    for (const auto& [id, box] : dead_near_) {
      if (!depends_known) {
        depends = mark_dependencies(from, above);
        depends_known = true;
      }
      if (collapse_marks_.of[tris_[id].destroyer] == depends) continue;
      const MeshTriangle other = mesh_triangle(tris_[id].v);
      for (std::size_t i = 0; i < made_.size(); ++i) {
        if (!box.intersects(made_boxes_[i])) continue;
        if (triangles_cross(made_[i], other) && !crossed_before(from, other)) {
          ++stats_.rejected_mixed_levels;
          return true;
        }
      }
    }
    return false;
  }

  // Marks (collapse_marks_, with the returned value) the collapses that collapsing `from` would
  // depend on, directly or not, whose bounds exceed `above`.
  std::uint32_t mark_dependencies(std::uint32_t from, double above) {
    if (collapse_marks_.of.size() < collapses_.size())
      collapse_marks_.of.resize(collapses_.size() * 3 / 2 + 16, 0);
    const std::uint32_t mark = collapse_marks_.next();
    dependency_stack_.clear();
    const auto reach = [&](std::uint32_t id) {
      const std::uint32_t c = tris_[id].creator;
      if (c == kNone || collapse_marks_.of[c] == mark || !(collapses_[c].error > above)) return;
      collapse_marks_.of[c] = mark;
      dependency_stack_.push_back(c);
    };
    for (std::uint32_t id : star_[from]) reach(id);
    while (!dependency_stack_.empty()) {
      const Collapse& d = collapses_[dependency_stack_.back()];
      dependency_stack_.pop_back();
      for (std::uint32_t k = d.old_begin; k < d.old_end; ++k) reach(old_tris_[k]);
    }
    return mark;
  }

  // Whether a triangle of from's star (the old star) already crosses `other`: a crossing the
  // source had (or one that came from it) may be reshaped by a collapse, not made.
  bool crossed_before(std::uint32_t from, const MeshTriangle& other) const {
    for (std::uint32_t id : star_[from]) {
      if (triangles_cross(mesh_triangle(tris_[id].v), other)) return true;
    }
    return false;
  }

  MeshTriangle mesh_triangle(const std::array<std::uint32_t, 3>& v) const {
    return {{pos_[v[0]], pos_[v[1]], pos_[v[2]]}, v};
  }

  // The grid over the live triangles, made at the first test: cells of twice the mean edge
  // length (a new star then spans 2-3 cells a side; at the mean length, 4: 1 % more instructions).
  void build_grid() {
    Box3 bounds;
    double edges = 0.0;
    std::size_t count = 0;
    for (const Tri& t : tris_) {
      if (t.destroyer != kNone) continue;
      for (int k = 0; k < 3; ++k) {
        bounds.add(pos_[t.v[std::size_t(k)]]);
        edges += glm::length(pos_[t.v[std::size_t(k)]] - pos_[t.v[std::size_t((k + 1) % 3)]]);
        ++count;
      }
    }
    const Vec3 origin = bounds.empty() ? Vec3(0.0) : bounds.lo;
    const double cell = count ? 2.0 * edges / double(count) : 1.0;
    grid_.reset(origin, cell);
    archive_.reset(origin, cell);
    for (std::uint32_t id = 0; id < tris_.size(); ++id) {
      if (tris_[id].destroyer == kNone) grid_.insert(id, box_of(tris_[id].v));
    }
    grid_ready_ = true;
  }

  // Dead triangles stay in the grid while a collapse can still need them (crosses_dead): with
  // bounds b >= `least` to come, one whose destroyer's bound is at most r `least` moves to the
  // archive, which only a collapse of a smaller bound (rare: bounds rise band by band) visits.
  void retire_dead(double least) {
    const double below = options_.coalesce_error_ratio * least;
    std::size_t kept = 0;
    for (const std::uint32_t id : dead_) {
      const double b = collapses_[tris_[id].destroyer].error;
      if (b > below) {
        dead_[kept++] = id;
        continue;
      }
      grid_.erase(id);
      archive_.insert(id, box_of(tris_[id].v));
      archive_largest_ = std::max(archive_largest_, b);
    }
    dead_.resize(kept);
  }

  // ---- simplification -----------------------------------------------------------------------

  // `new_e`: the bounds of the new triangles, in star order (collapse_error's BoundScratch::new_e).
  void apply(std::uint32_t from, std::uint32_t to, double error, const std::vector<double>& new_e) {
    const auto c = static_cast<std::uint32_t>(collapses_.size());
    Collapse col;
    col.removed = from;
    col.kept = to;
    col.error = error;
    col.old_begin = static_cast<std::uint32_t>(old_tris_.size());
    const std::vector<std::uint32_t> old = star_[from];
    for (std::uint32_t id : old) {
      old_tris_.push_back(id);
      tris_[id].destroyer = c;
      unlink_triangle(id, from);
      if (grid_ready_) {
        if (track_dead_) {
          dead_.push_back(id);  // stays in the grid, dead (crosses_dead)
        } else {
          grid_.erase(id);
        }
      }
      for (std::uint32_t w : tris_[id].v) {  // their neighbourhoods change
        if (!blocked_[w].empty()) {
          blocked_[w].clear();
          cheapest_[w] = kUnknown;  // the targets given back were not among those ranked
        }
      }
    }
    col.old_end = static_cast<std::uint32_t>(old_tris_.size());
    star_[from].clear();
    ++star_version_[from];
    col.new_begin = static_cast<std::uint32_t>(new_tris_.size());
    std::size_t made = 0;
    for (std::uint32_t id : old) {
      if (has(tris_[id], to)) continue;
      Tri t;
      t.v = tris_[id].v;
      for (std::uint32_t& w : t.v) {
        if (w == from) w = to;
      }
      t.e = new_e[made++];
      t.creator = c;
      new_tris_.push_back(add_triangle(t));
    }
    col.new_end = static_cast<std::uint32_t>(new_tris_.size());
    collapses_.push_back(col);
    removed_[from] = 1;
    --comp_vertices_[comp_[from]];
    const Quadric qf = quad_[from];
    quad_[to] += qf;
  }

  // Per vertex, the bound its candidate last waited with: exact while its star and target are
  // unchanged (stamp, to); after a change, a prediction that keeps it waiting without a new bound
  // until the band reaches it (bounds only grow as a region coarsens; a wrong guess only delays
  // the collapse, whose bound is computed before it is made).
  struct Waited {
    std::uint32_t stamp = 0, to = kNone;
    double error = 0.0;
  };

  // Bounds computed ahead (QemPmOptions::threads > 1). A collapse's bound depends only on the
  // star of its removed vertex, the positions and the bounds of the collapses that made that
  // star (StarSnapshot), none of which changes while the vertex's stamp stays. So the calling
  // thread hands the helper threads snapshots of candidates that come up soon (those whose bound
  // it would compute when they come up: current, not waiting; validity is left to the calling
  // thread when they come up, as testing it here too cost that thread 4 % of the bunny's build
  // and a helper computing a bound no one uses costs it nothing), kAhead at a time whenever
  // fewer than kAhead / 2 wait, and goes on simplifying; a result is used if its candidate comes
  // up with the same stamp and band; a bound not handed over, the calling thread computes itself,
  // and one handed over but not started yet too. The simplification, and so the database, is the
  // same whatever the number of threads.
  class AheadThreads {
   public:
    // A candidate's bound: its snapshot, filled by the calling thread, and its result.
    struct Job {
      Candidate c{};
      double tolerance = 0.0;
      StarSnapshot snap;
      double error_bound = 0.0;
      bool counted = false;  // collapse_error ran (BoundScratch::computed)
      std::vector<double> new_e;
      std::exception_ptr error;  // what the computation threw, if it did
      enum State : int { kQueued, kRunning, kDone };
      std::atomic<int> state{kQueued};
    };

    explicit AheadThreads(unsigned helpers) {
      try {
        for (unsigned t = 0; t < helpers; ++t) threads_.emplace_back([this] { serve(); });
      } catch (...) {
        stop();  // the threads started so far
        throw;
      }
    }
    ~AheadThreads() { stop(); }
    AheadThreads(const AheadThreads&) = delete;
    AheadThreads& operator=(const AheadThreads&) = delete;

    // The calling thread's: a job to fill (from the free ones), queueing it, and giving it back
    // once done with it (not while a helper may hold it: wait() first).
    Job& make() {
      if (free_.empty()) {
        free_.push_back(&pool_.emplace_back());
      }
      Job& job = *free_.back();
      free_.pop_back();
      job.state.store(Job::kQueued, std::memory_order_relaxed);
      return job;
    }
    void post(std::span<Job* const> jobs) {
      {
        std::lock_guard lock(mu_);
        queue_.insert(queue_.end(), jobs.begin(), jobs.end());
        queued_.store(queue_.size(), std::memory_order_relaxed);
      }
      work_cv_.notify_all();
    }
    void release(Job& job) { free_.push_back(&job); }
    std::size_t queued() const { return queued_.load(std::memory_order_relaxed); }
    // Makes sure the job is done: run here if no helper has started it, else waited for.
    void wait(Job& job, BoundScratch& s) {
      {
        std::unique_lock lock(mu_);
        if (job.state.load(std::memory_order_relaxed) == Job::kQueued) {
          queue_.erase(std::find(queue_.begin(), queue_.end(), &job));
          queued_.store(queue_.size(), std::memory_order_relaxed);
          job.state.store(Job::kRunning, std::memory_order_relaxed);
        } else {
          waiting_ = true;
          done_cv_.wait(lock, [&] { return job.state.load() == Job::kDone; });
          waiting_ = false;
          return;
        }
      }
      try {
        run(job, s);
      } catch (...) {
        job.error = std::current_exception();  // rethrown by its user, as a helper's
      }
      job.state.store(Job::kDone);
    }
    bool done(const Job& job) const { return job.state.load() == Job::kDone; }

   private:
    void stop() {
      {
        std::lock_guard lock(mu_);
        quit_ = true;
      }
      work_cv_.notify_all();
      for (std::thread& t : threads_) t.join();
    }
    static void run(Job& job, BoundScratch& s) {
      std::swap(s.snap, job.snap);
      const std::uint64_t computed = s.computed;
      job.error_bound = star_bound(job.tolerance, false, s).first;
      job.counted = s.computed != computed;
      s.computed = computed;  // counted when used (bound_ahead)
      job.new_e.assign(s.new_e.begin(), s.new_e.end());
      std::swap(s.snap, job.snap);
    }
    void serve() {
      BoundScratch s;
      for (;;) {
        Job* job = nullptr;
        // A short spin first: sleeping and being woken for every few jobs cost more than them.
        for (int spin = 0; spin < 4000 && queued_.load(std::memory_order_relaxed) == 0; ++spin) {
          std::this_thread::yield();
        }
        {
          std::unique_lock lock(mu_);
          work_cv_.wait(lock, [&] { return quit_ || !queue_.empty(); });
          if (quit_) return;
          job = queue_.front();
          queue_.pop_front();
          queued_.store(queue_.size(), std::memory_order_relaxed);
          job->state.store(Job::kRunning, std::memory_order_relaxed);
        }
        try {
          run(*job, s);
        } catch (...) {
          job->error = std::current_exception();
        }
        std::lock_guard lock(mu_);
        job->state.store(Job::kDone);
        if (waiting_) done_cv_.notify_all();
      }
    }

    std::vector<std::thread> threads_;
    std::mutex mu_;
    std::condition_variable work_cv_, done_cv_;
    std::deque<Job*> queue_;  // jobs posted, not started
    bool quit_ = false;
    bool waiting_ = false;                // the calling thread waits for a job (wait())
    std::atomic<std::size_t> queued_{0};  // queue_.size(), read without the lock
    std::deque<Job> pool_;                // the calling thread's (stable addresses)
    std::vector<Job*> free_;              // the calling thread's
  };
  static constexpr std::size_t kAhead = 16;  // candidates handed over at a time
  static constexpr std::size_t kAheadHeld = std::size_t{1} << 14;  // jobs kept, about

  // bound_within(top, tolerance, finish = false).first, with BoundScratch::new_e in scratch_.
  double bound_ahead(const Candidate& top, double tolerance, const std::vector<Waited>& waited) {
    AheadThreads::Job* job = ahead_[top.from];
    if (job == nullptr || job->c.to != top.to || job->c.stamp != top.stamp ||
        job->tolerance != tolerance) {
      post_ahead(tolerance, waited, top.from);  // the helpers start meanwhile
      return bound_within(top.from, top.to, tolerance, false, scratch_).first;
    }
    if (!ahead_threads_->done(*job)) ahead_threads_->wait(*job, scratch_);
    if (job->error) std::rethrow_exception(job->error);
    if (job->counted) ++scratch_.computed;
    scratch_.new_e.assign(job->new_e.begin(), job->new_e.end());
    const double error = job->error_bound;
    // Used: given back (the candidate is out of the queue; if it comes back, in a later band,
    // it may be handed over again).
    ahead_threads_->release(*job);
    ahead_[top.from] = nullptr;
    ahead_seen_[top.from] = 0;
    ++stats_.bounds_ahead_used;
    post_ahead(tolerance, waited, top.from);
    return error;
  }

  // Hands the helpers candidates that come up soon (not `skip`, nor those looked at already):
  // from the front of the queue's heap order (not sorted: any order is right, this one is
  // cheap), when fewer than kAhead / 2 wait for them. Items it is done with are flagged in the
  // heap (Candidate::looked): a scan passed over about 127 items to post 1.5, each looked up in
  // five per-vertex arrays (13 M look-ups on the bunny, half of this function's time).
  void post_ahead(double tolerance, const std::vector<Waited>& waited, std::uint32_t skip) {
    if (ahead_threads_->queued() >= kAhead / 2) return;
    // Jobs whose candidates changed are given back now and then: when twice as many are held
    // as after the last time; past kAheadHeld, those finished are given back whatever their
    // candidates (a result dropped is only computed again), so the jobs' memory stays small.
    if (ahead_held_.size() > std::max<std::size_t>(16 * kAhead, 2 * ahead_kept_)) {
      const bool all = ahead_held_.size() > kAheadHeld;
      std::erase_if(ahead_held_, [&](std::uint32_t v) {
        AheadThreads::Job* job = ahead_[v];
        if (job == nullptr) {  // used (bound_ahead)
          ahead_listed_[v] = 0;
          return true;
        }
        if (!ahead_threads_->done(*job)) return false;
        if (!all && !removed_[v] && job->c.stamp == stamp_[v]) return false;
        ahead_threads_->release(*job);
        ahead_[v] = nullptr;
        ahead_seen_[v] = 0;
        ahead_listed_[v] = 0;
        return true;
      });
      ahead_kept_ = ahead_held_.size();
    }
    posting_.clear();
    std::vector<Candidate>& items = heap_.items();
    for (std::size_t i = 0; i < items.size() && i < 8 * kAhead && posting_.size() < kAhead; ++i) {
      Candidate& c = items[i];
      if (c.looked || c.from == skip) continue;
      if (removed_[c.from] || c.stamp != stamp_[c.from] || removed_[c.to]) {
        c.looked = true;  // stale for good
        continue;
      }
      if (waited[c.from].error > tolerance) continue;
      AheadThreads::Job*& held = ahead_[c.from];
      if (ahead_seen_[c.from] == c.stamp + 1 &&
          (held == nullptr || held->c.stamp != c.stamp || held->tolerance == tolerance)) {
        c.looked = true;  // handed over in this band
        continue;
      }
      if (held != nullptr && !ahead_threads_->done(*held)) continue;  // a helper holds it
      c.looked = true;
      ahead_seen_[c.from] = c.stamp + 1;
      if (held != nullptr) ahead_threads_->release(*held);
      if (!ahead_listed_[c.from]) {
        ahead_listed_[c.from] = 1;
        ahead_held_.push_back(c.from);
      }
      AheadThreads::Job& job = ahead_threads_->make();
      job.error = nullptr;
      job.c = c;
      job.tolerance = tolerance;
      snapshot(c.from, c.to, job.snap);
      held = &job;
      posting_.push_back(&job);
    }
    ahead_threads_->post(posting_);
    stats_.bounds_ahead += posting_.size();
  }

  // Cheapest quadric cost first, in bands of the bound: a collapse whose bound exceeds the
  // band's tolerance waits for the next band (twice the least bound that waited). A collapse's
  // bound is at least those of the collapses it depends on, so one early large bound would
  // raise every later one in its region; in bands, small bounds go first (the block builder's
  // rising tolerances do the same).
  void simplify() {
    const std::size_t n = pos_.size();
    for (std::uint32_t v = 0; v < n; ++v) push_cheapest(v);
    const std::uint64_t start = alive_vertices();
    std::uint64_t alive = start;
    const std::uint64_t floor_vertices = options_.base_vertices;
    std::uint64_t next_report = 0;
    double tolerance = options_.bound_band > 0.0 ? 0.0 : std::numeric_limits<double>::infinity();
    struct Waiting {
      Candidate c;
      double error;
    };
    std::vector<Waiting> waiting;
    std::vector<Waited> waited(n);
    if (thread_count(options_.threads) > 1 && n > kAhead) {
      ahead_threads_ = std::make_unique<AheadThreads>(thread_count(options_.threads) - 1);
      ahead_.assign(n, nullptr);
      ahead_seen_.assign(n, 0);
      ahead_listed_.assign(n, 0);
    }
    const auto current = [&](const Candidate& c) {
      return !removed_[c.from] && c.stamp == stamp_[c.from];
    };
    track_dead_ = !options_.allow_self_intersections;
    while (alive > floor_vertices) {
      if (heap_.empty()) {
        double least = std::numeric_limits<double>::infinity();
        for (const Waiting& w : waiting) {
          if (current(w.c)) least = std::min(least, w.error);
        }
        if (least == std::numeric_limits<double>::infinity()) {
          waiting.clear();  // only stale entries: nothing is left to collapse
          break;
        }
        if (track_dead_ && grid_ready_) retire_dead(tolerance);  // the band that ended
        tolerance = options_.bound_band * least;
        // Those still above it would only come up to wait again.
        std::size_t kept = 0;
        for (const Waiting& w : waiting) {
          if (!current(w.c)) continue;
          if (w.error > tolerance) {
            waiting[kept++] = w;
          } else {
            Candidate c = w.c;
            c.looked = false;  // a new band
            heap_.push(c);
          }
        }
        waiting.resize(kept);
        continue;
      }
      const Candidate top = heap_.top();
      heap_.pop();
      if (!current(top)) continue;
      if (removed_[top.to]) {
        push_best(top.from, top.to);
        continue;
      }
      // The bound, or a lower bound of it when that already exceeds the band (bound_within).
      Waited& w = waited[top.from];
      double error = w.error;
      bool known = w.to == top.to && w.stamp == top.stamp;
      if (error <= tolerance) {
        known = true;
        error = ahead_threads_ ? bound_ahead(top, tolerance, waited)
                               : bound_within(top.from, top.to, tolerance, false, scratch_).first;
      }
      // Validity is tested only once the collapse is to be made or `from` given up: 80 % of the
      // candidates that come up wait here for a later band instead (the bunny: 163 k of 206 k),
      // and their stars change meanwhile. An infinite bound (no new star) is never valid.
      const bool never = error == std::numeric_limits<double>::infinity();
      if (never || (known && options_.max_base_error > 0.0 && error > options_.max_base_error)) {
        if (never || !valid(top.from, top.to)) {
          push_best(top.from, top.to);
        } else {
          ++stamp_[top.from];  // given up; retried only when its neighbourhood changes
        }
        continue;
      }
      if (error > tolerance) {
        if (known) w = {top.stamp, top.to, error};
        waiting.push_back({top, error});
        continue;
      }
      if (!valid(top.from, top.to)) {
        push_best(top.from, top.to);
        continue;
      }
      if (crosses_after(top.from, top.to, error)) {
        refuse(top.from, top.to);
        push_best(top.from);
        continue;
      }
      apply(top.from, top.to, error, scratch_.new_e);
      --alive;
      neighbours(top.to, ring_);
      const std::vector<std::uint32_t> ring = ring_;
      push_cheapest(top.to);
      for (std::uint32_t r : ring) push_cheapest(r, cheapest_after(r, top.from, top.to));
      if (options_.progress && start - alive >= next_report) {
        options_.progress(0.8 * double(start - alive) / double(start));
        next_report += std::max<std::uint64_t>(1, start / 200);
      }
    }
    exhausted_ = heap_.empty() && waiting.empty() && options_.max_base_error == 0.0;
    ahead_threads_.reset();
    std::vector<AheadThreads::Job*>().swap(ahead_);
    std::vector<std::uint32_t>().swap(ahead_seen_);
    std::vector<std::uint32_t>().swap(ahead_held_);
    std::vector<std::uint8_t>().swap(ahead_listed_);
  }

  // ---- spawned components -------------------------------------------------------------------

  // After simplification every component is at its smallest. All but one are then removed, each
  // as one more "collapse" with no replacement; reversed, its op spawns the component (Brown
  // 4.4.1, Fig. 4.9d). The bound: a source point assigned to a triangle T of the component is
  // within e(T) of a point q of T, and q within (distance from a corner of T to the rest of the
  // mesh) + (T's longest edge) of the rest. The component with the largest bound stays.
  void remove_components() {
    if (collapses_.empty()) return;  // a spawn needs an op to hold it
    std::vector<std::vector<std::uint32_t>> tris_of(comp_vertices_.size());
    for (std::uint32_t id = 0; id < tris_.size(); ++id) {
      if (tris_[id].destroyer == kNone) tris_of[comp_[tris_[id].v[0]]].push_back(id);
    }
    struct Removal {
      double error;
      std::uint32_t comp;
    };
    std::vector<Removal> removals;
    for (std::uint32_t comp = 0; comp < tris_of.size(); ++comp) {
      if (tris_of[comp].empty()) continue;
      double e = 0.0;
      for (std::uint32_t id : tris_of[comp]) {
        const Tri& t = tris_[id];
        double nearest = 0.0, longest = 0.0;
        for (int k = 0; k < 3; ++k) {
          nearest = std::max(nearest, distance_to_others(pos_[t.v[k]], comp, tris_of));
          longest = std::max(longest, glm::length(pos_[t.v[k]] - pos_[t.v[(k + 1) % 3]]));
        }
        e = std::max(e, t.e + nearest + longest);
      }
      removals.push_back({e, comp});
    }
    if (removals.size() < 2) return;
    std::sort(removals.begin(), removals.end(), [](const Removal& a, const Removal& b) {
      return a.error != b.error ? a.error < b.error : a.comp < b.comp;
    });
    removals.pop_back();  // the coarsest mesh keeps one component
    for (const Removal& r : removals) {
      Collapse col;
      col.removed = kNone;
      col.kept = kNone;
      col.error = r.error;
      col.old_begin = static_cast<std::uint32_t>(old_tris_.size());
      const auto c = static_cast<std::uint32_t>(collapses_.size());
      for (std::uint32_t id : tris_of[r.comp]) {
        old_tris_.push_back(id);
        tris_[id].destroyer = c;
        for (std::uint32_t v : tris_[id].v) col.spawn_vertices.push_back(v);
      }
      std::sort(col.spawn_vertices.begin(), col.spawn_vertices.end());
      col.spawn_vertices.erase(std::unique(col.spawn_vertices.begin(), col.spawn_vertices.end()),
                               col.spawn_vertices.end());
      col.old_end = static_cast<std::uint32_t>(old_tris_.size());
      col.new_begin = col.new_end = static_cast<std::uint32_t>(new_tris_.size());
      collapses_.push_back(std::move(col));
      ++stats_.spawned_components;
    }
  }

  // Distance from p to the alive triangles of every component but `comp`.
  double distance_to_others(const Vec3& p, std::uint32_t comp,
                            const std::vector<std::vector<std::uint32_t>>& tris_of) const {
    double best = std::numeric_limits<double>::infinity();
    for (std::uint32_t other = 0; other < tris_of.size(); ++other) {
      if (other == comp) continue;
      for (std::uint32_t id : tris_of[other]) {
        const Tri& t = tris_[id];
        best =
            std::min(best, point_triangle_distance3d(p, pos_[t.v[0]], pos_[t.v[1]], pos_[t.v[2]]));
      }
    }
    return best;
  }

  // ---- emission -----------------------------------------------------------------------------

  // Splits in a topological order of their dependencies, largest error first.
  std::vector<std::uint32_t> split_order() const {
    const std::size_t m = collapses_.size();
    std::vector<std::uint32_t> indegree(m, 0);
    std::vector<std::uint32_t> tmp;
    for (std::uint32_t c = 0; c < m; ++c) {
      tmp.clear();
      for (std::uint32_t i = collapses_[c].new_begin; i < collapses_[c].new_end; ++i) {
        const std::uint32_t d = tris_[new_tris_[i]].destroyer;
        if (d != kNone) tmp.push_back(d);
      }
      std::sort(tmp.begin(), tmp.end());
      indegree[c] = static_cast<std::uint32_t>(std::unique(tmp.begin(), tmp.end()) - tmp.begin());
    }
    using Entry = std::pair<double, std::uint32_t>;  // (error, collapse): largest, then latest
    std::priority_queue<Entry> ready;
    for (std::uint32_t c = 0; c < m; ++c) {
      if (indegree[c] == 0) ready.push({collapses_[c].error, c});
    }
    std::vector<std::uint32_t> order;
    order.reserve(m);
    while (!ready.empty()) {
      const std::uint32_t c = ready.top().second;
      ready.pop();
      order.push_back(c);
      tmp.clear();
      for (std::uint32_t i = collapses_[c].old_begin; i < collapses_[c].old_end; ++i) {
        const std::uint32_t k = tris_[old_tris_[i]].creator;
        if (k != kNone) tmp.push_back(k);
      }
      std::sort(tmp.begin(), tmp.end());
      tmp.erase(std::unique(tmp.begin(), tmp.end()), tmp.end());
      for (std::uint32_t k : tmp) {
        if (--indegree[k] == 0) ready.push({collapses_[k].error, k});
      }
    }
    if (order.size() != m) throw_internal("QEM PM: the split dependencies have a cycle");
    return order;
  }

  // Coalescing (Brown 4.4.3.3, Fig. 4.12b: a finer op merged into the coarser one it overlaps):
  // walking the splits in order, a split joins the latest group holding one of its parents when
  // the group's fragment stays within the size bound and the split's error is at least the given
  // fraction of the group's. The group then stands where its first split stood: the split's
  // other parents are in earlier groups (or R^0), and everything that depends on a member comes
  // after it, so the groups keep a topological order.
  std::vector<std::vector<std::uint32_t>> coalesce(const std::vector<std::uint32_t>& order) {
    std::vector<std::vector<std::uint32_t>> groups;
    std::vector<std::uint32_t> group_of(collapses_.size(), kNone);
    std::vector<std::uint32_t> size, parents, pending_spawns;
    std::vector<double> first_error;
    std::uint32_t last = kNone;  // the group that took the previous split
    for (std::uint32_t c : order) {
      const Collapse& col = collapses_[c];
      if (col.kept == kNone) {
        // A spawn replaces nothing, so it cannot be an op of its own (nothing would lead
        // AddToList to it): it joins the op before it, or the first op when it comes first.
        if (last == kNone) {
          pending_spawns.push_back(c);
        } else {
          groups[last].push_back(c);
          group_of[c] = last;
        }
        continue;
      }
      parents.clear();
      for (std::uint32_t i = col.new_begin; i < col.new_end; ++i) {
        const std::uint32_t d = tris_[new_tris_[i]].destroyer;
        if (d != kNone) parents.push_back(group_of[d]);
      }
      const std::uint32_t own = col.old_end - col.old_begin;
      if (!parents.empty() && options_.max_fragment_triangles != 0) {
        const std::uint32_t g = *std::max_element(parents.begin(), parents.end());
        // Joining g, the fragment loses the split's PreF triangles g made and gains its star.
        const auto from_g =
            static_cast<std::uint32_t>(std::count(parents.begin(), parents.end(), g));
        const std::uint32_t grown = own - from_g;
        if (g != kNone && size[g] + grown <= options_.max_fragment_triangles &&
            col.error >= options_.coalesce_error_ratio * first_error[g]) {
          groups[g].push_back(c);
          size[g] += grown;
          group_of[c] = last = g;
          continue;
        }
      }
      group_of[c] = last = static_cast<std::uint32_t>(groups.size());
      groups.push_back({c});
      size.push_back(own);
      first_error.push_back(col.error);
      for (std::uint32_t p : pending_spawns) {
        groups[last].push_back(p);
        group_of[p] = last;
      }
      pending_spawns.clear();
    }
    if (!pending_spawns.empty())
      throw_internal("QEM PM: spawned components with no op to hold them");
    return groups;
  }

  // fill_fragment()'s buffers: one per thread making ops.
  struct FragmentScratch {
    std::vector<std::uint32_t> local;
    std::vector<std::pair<std::uint64_t, std::uint32_t>> edges;
  };
  // Fills an op's vertices (the new ones first, then every other corner of `frag`) and its
  // fragment triangles with in-fragment neighbours. Reads the mesh only: runs on any thread.
  void fill_fragment(Op& op, std::span<const std::uint32_t> frag,
                     const std::vector<std::uint32_t>& new_vertices, FragmentScratch& s) const {
    std::vector<std::uint32_t>& local = s.local;
    std::vector<std::pair<std::uint64_t, std::uint32_t>>& edges = s.edges;
    local.clear();
    for (std::uint32_t v : new_vertices) local.push_back(v);
    for (std::uint32_t id : frag) {
      for (std::uint32_t v : tris_[id].v) local.push_back(v);
    }
    std::sort(local.begin() + std::ptrdiff_t(new_vertices.size()), local.end());
    local.erase(std::unique(local.begin() + std::ptrdiff_t(new_vertices.size()), local.end()),
                local.end());
    local.erase(std::remove_if(local.begin() + std::ptrdiff_t(new_vertices.size()), local.end(),
                               [&](std::uint32_t v) {
                                 return std::find(new_vertices.begin(), new_vertices.end(), v) !=
                                        new_vertices.end();
                               }),
                local.end());
    op.new_vertex_count = static_cast<std::uint32_t>(new_vertices.size());
    op.vertices.clear();
    op.vertices.reserve(local.size());
    for (std::uint32_t v : local) {
      op.vertices.push_back({VertexId(source_id_.empty() ? v : source_id_[v]), pos_[v]});
    }
    const auto index_of = [&](std::uint32_t v) {
      const auto first = local.begin() + std::ptrdiff_t(new_vertices.size());
      for (auto it = local.begin(); it != first; ++it) {
        if (*it == v) return static_cast<std::uint32_t>(it - local.begin());
      }
      return static_cast<std::uint32_t>(std::lower_bound(first, local.end(), v) - local.begin());
    };
    op.fragment.assign(frag.size(), FragmentTriangle{});
    // Neighbours across directed edges: (edge, triangle) sorted by edge, the first holder of an
    // edge being the one found.
    edges.clear();
    for (std::uint32_t i = 0; i < frag.size(); ++i) {
      const Tri& t = tris_[frag[i]];
      for (int k = 0; k < 3; ++k) {
        op.fragment[i].v[k] = index_of(t.v[k]);
        edges.push_back({edge_key(t.v[k], t.v[(k + 1) % 3]), i});
      }
    }
    std::sort(edges.begin(), edges.end());
    for (std::uint32_t i = 0; i < frag.size(); ++i) {
      const Tri& t = tris_[frag[i]];
      for (int k = 0; k < 3; ++k) {
        const std::uint64_t key = edge_key(t.v[(k + 1) % 3], t.v[k]);
        const auto it = std::lower_bound(edges.begin(), edges.end(), std::pair{key, 0u});
        if (it != edges.end() && it->first == key)
          op.fragment[i].nbr[k] = static_cast<std::int32_t>(it->second);
      }
    }
  }

  // Whether collapse c (kNone: none) is a member of the group (a few splits: a linear search).
  static bool in_group(const std::vector<std::uint32_t>& group, std::uint32_t c) {
    return c != kNone && std::find(group.begin(), group.end(), c) != group.end();
  }
  // A group's op, less its links to the mesh before it (emit): its own bound (its members',
  // and spawned components'), its fragment F (the members' stars) and vertices; its PreF (the
  // members' replacements) appended to chunk.pre. F and PreF leave out the triangles one member
  // makes and another removes (inside the group they never appear). Reads the mesh only: runs
  // on any thread.
  template <class Chunk>
  void make_op(const std::vector<std::uint32_t>& group, OpId id, Op& op, Chunk& chunk) const {
    std::vector<std::uint32_t>& removed = chunk.removed;
    removed.clear();
    op.id = id;
    op.error = 0.0;
    const std::size_t first = chunk.frag.size();
    for (std::uint32_t c : group) {
      const Collapse& col = collapses_[c];
      if (col.kept == kNone) {
        removed.insert(removed.end(), col.spawn_vertices.begin(), col.spawn_vertices.end());
      } else {
        removed.push_back(col.removed);
      }
      op.error = std::max(op.error, col.error);
      for (std::uint32_t k = col.old_begin; k < col.old_end; ++k) {
        if (!in_group(group, tris_[old_tris_[k]].creator)) chunk.frag.push_back(old_tris_[k]);
      }
      for (std::uint32_t k = col.new_begin; k < col.new_end; ++k) {
        if (!in_group(group, tris_[new_tris_[k]].destroyer)) chunk.pre.push_back(new_tris_[k]);
      }
    }
    std::sort(chunk.frag.begin() + std::ptrdiff_t(first), chunk.frag.end());
    chunk.frag_end.push_back(static_cast<std::uint32_t>(chunk.frag.size()));
    chunk.pre_end.push_back(static_cast<std::uint32_t>(chunk.pre.size()));
    fill_fragment(op, std::span<const std::uint32_t>(chunk.frag).subspan(first), removed,
                  chunk.scratch);
  }

  static std::uint8_t edge_index(const Tri& t, std::uint32_t a, std::uint32_t b) {
    for (std::uint8_t k = 0; k < 3; ++k) {
      if (t.v[k] == a && t.v[(k + 1) % 3] == b) return k;
    }
    throw_internal("QEM PM: a triangle lacks the edge it was found by");
  }

  Crmr emit(const std::string& name) {
    Crmr crmr;
    CrmrInfo& h = crmr.header;
    h.kind = ModelKind::kMesh3d;
    h.source = name;
    h.err_final = 0.0;
    for (std::uint32_t v = 0; v < pos_.size(); ++v) {
      if (comp_[v] != kNone) {
        h.bounds.add(pos_[v]);
        ++h.vertex_count;
      }
    }
    h.builder = "qem-pm max-normal-turn=" + std::to_string(options_.max_normal_turn_degrees) +
                " coalesce=" + std::to_string(options_.max_fragment_triangles) +
                " coalesce-ratio=" + std::to_string(options_.coalesce_error_ratio) +
                " boundary-weight=" + std::to_string(options_.boundary_weight) +
                " base-vertices=" + std::to_string(options_.base_vertices) +
                " max-base-error=" + std::to_string(options_.max_base_error) +
                " bound-band=" + std::to_string(options_.bound_band) +
                " no-self-intersections=" + (options_.allow_self_intersections ? "no" : "yes");

    const std::vector<std::vector<std::uint32_t>> groups = coalesce(split_order());
    const std::size_t nt = tris_.size();
    tri_op_.assign(nt, kNone);
    tri_local_.assign(nt, kNone);

    // R^0: the triangles never removed, and every vertex they use.
    std::vector<std::uint32_t> base;
    for (std::uint32_t id = 0; id < nt; ++id) {
      if (tris_[id].destroyer == kNone) base.push_back(id);
    }
    std::vector<std::uint32_t> base_vertices;
    for (std::uint32_t id : base) {
      for (std::uint32_t v : tris_[id].v) base_vertices.push_back(v);
    }
    std::sort(base_vertices.begin(), base_vertices.end());
    base_vertices.erase(std::unique(base_vertices.begin(), base_vertices.end()),
                        base_vertices.end());
    crmr.ops.resize(groups.size() + 1);
    Op& r0 = crmr.ops[0];
    r0.id = kBaseOp;
    FragmentScratch scratch;
    fill_fragment(r0, base, base_vertices, scratch);

    IdMap<std::uint32_t> edges;  // directed edge -> current triangle
    edges.reserve(nt);
    std::vector<std::uint8_t> current(nt, 0);
    const auto enter = [&](std::uint32_t id) {
      const Tri& t = tris_[id];
      for (int k = 0; k < 3; ++k) edges[edge_key(t.v[k], t.v[(k + 1) % 3])] = id;
      current[id] = 1;
    };
    // R^0's error, the top of the resolution scale: its triangles' bounds and the removed
    // components' (they count in the mesh error until their ops spawn them), and no less than
    // any op's error (a collapse's error can exceed its new triangles' own bounds: it is at least
    // its creators'), so that no op's resolution is clamped to 0 below its error.
    h.err0 = 0.0;
    for (std::uint32_t i = 0; i < base.size(); ++i) {
      tri_op_[base[i]] = 0;
      tri_local_[base[i]] = i;
      enter(base[i]);
      h.err0 = std::max(h.err0, tris_[base[i]].e);
    }
    for (const Collapse& col : collapses_) h.err0 = std::max(h.err0, col.error);
    r0.error = h.err0;
    r0.birth_res = 0.0;

    // The ops in chunks of groups: made on worker threads (make_op: fragments, vertices, PreF),
    // then linked to the mesh before them on this thread, in order (PreF references, coarser
    // links). All on one thread, the bunny's emit took 0.29 s, a fifth of its build.
    struct Chunk {
      std::size_t first = 0, end = 0;        // groups [first, end)
      std::vector<std::uint32_t> frag, pre;  // per group, one after another
      std::vector<std::uint32_t> frag_end, pre_end;
      std::vector<std::uint32_t> removed;  // make_op's buffers
      FragmentScratch scratch;
    };
    constexpr std::size_t kGroupsPerChunk = 256;
    const std::size_t chunks = (groups.size() + kGroupsPerChunk - 1) / kGroupsPerChunk;
    const unsigned threads = thread_count(options_.threads);
    ordered_pipeline(
        chunks, threads, 4 * std::size_t(threads),
        [&](std::size_t k) {
          auto chunk = std::make_unique<Chunk>();
          chunk->first = k * kGroupsPerChunk;
          chunk->end = std::min(groups.size(), chunk->first + kGroupsPerChunk);
          return chunk;
        },
        [&](Chunk& chunk) {
          for (std::size_t i = chunk.first; i < chunk.end; ++i) {
            make_op(groups[i], OpId(static_cast<std::uint32_t>(i + 1)), crmr.ops[i + 1], chunk);
          }
        },
        [&](Chunk& chunk, std::size_t) {
          std::size_t f = 0, p = 0;
          for (std::size_t i = chunk.first; i < chunk.end; ++i) {
            const std::size_t j = i - chunk.first;
            const std::span<const std::uint32_t> frag(chunk.frag.data() + f, chunk.frag_end[j] - f);
            const std::span<const std::uint32_t> pre(chunk.pre.data() + p, chunk.pre_end[j] - p);
            f = chunk.frag_end[j];
            p = chunk.pre_end[j];
            const std::vector<std::uint32_t>& group = groups[i];
            const auto op_id = static_cast<std::uint32_t>(i + 1);
            Op& op = crmr.ops[op_id];
            for (std::uint32_t k = 0; k < frag.size(); ++k) {
              tri_op_[frag[k]] = op_id;
              tri_local_[frag[k]] = k;
            }
            op.pre.clear();
            for (std::uint32_t id : pre) {
              if (!current[id]) throw_internal("QEM PM: a split's PreF is not in the mesh");
              op.pre.push_back({OpId(tri_op_[id]), tri_local_[id]});
            }
            std::sort(op.pre.begin(), op.pre.end());
            // Coarser links of the fragment's boundary edges: the newer of the replaced
            // triangle inside and the surviving one outside (both hold the edge just before
            // the split).
            op.coarser.clear();
            for (std::uint32_t k = 0; k < frag.size(); ++k) {
              const Tri& t = tris_[frag[k]];
              for (std::uint8_t e = 0; e < 3; ++e) {
                if (op.fragment[k].nbr[e] != FragmentTriangle::kNoNeighbour) continue;
                const std::uint32_t a = t.v[e], b = t.v[(e + 1) % 3];
                const std::uint32_t* out = edges.find(edge_key(b, a));
                if (out == nullptr) continue;  // model boundary
                const std::uint32_t* in = edges.find(edge_key(a, b));
                if (in == nullptr || !in_group(group, tris_[*in].creator)) {
                  throw_internal("QEM PM: a fragment boundary edge has no replaced triangle");
                }
                const std::uint32_t inside = *in, outside = *out;
                const bool outer = tri_op_[outside] > tri_op_[inside];
                const std::uint32_t tri = outer ? outside : inside;
                const std::uint8_t edge =
                    outer ? edge_index(tris_[tri], b, a) : edge_index(tris_[tri], a, b);
                op.coarser.push_back(
                    {k, e, EdgeRef{TriRef{OpId(tri_op_[tri]), tri_local_[tri]}, edge}});
              }
            }
            for (std::uint32_t id : pre) {
              const Tri& t = tris_[id];
              for (int k = 0; k < 3; ++k) edges.erase(edge_key(t.v[k], t.v[(k + 1) % 3]));
              current[id] = 0;
            }
            for (std::uint32_t id : frag) enter(id);
            if (options_.progress && (i % std::max<std::size_t>(1, groups.size() / 50)) == 0) {
              options_.progress(0.8 + 0.15 * double(i) / double(groups.size()));
            }
          }
        });
    link_dag(crmr);
    // An op's error: its own bound, or a descendant's when larger (children first: they have
    // larger ids), so resolutions never fall from parent to child and a triangle's death_res
    // stands for at least its own bound. Much tighter than the mesh-wide error before each op,
    // which let one rough region refine every op that came after it in the order.
    for (std::size_t i = crmr.ops.size(); i-- > 1;) {
      Op& op = crmr.ops[i];
      for (OpId c : op.children) op.error = std::max(op.error, crmr.ops[c.value].error);
      op.birth_res = resolution_of(h, op.error);
    }
    for (Op& op : crmr.ops) {
      for (FragmentTriangle& t : op.fragment) {
        if (t.killer.valid()) t.death_res = crmr.ops[t.killer.value].birth_res;
      }
    }
    if (options_.progress) options_.progress(1.0);
    return crmr;
  }

  bool is_locked(std::uint32_t v) const { return !locked_.empty() && locked_[v] != 0; }

  // ---- independent-set rounds (the block builder) ------------------------------------------

  // Rounds of collapses whose bound is at most `tolerance`, cheapest quadric cost first; in a
  // round no two collapses touch (each takes its two vertices and their neighbours), so none
  // depends on another of its round and the DAG height is at most the number of rounds. Each
  // vertex keeps its cheapest target and that collapse's bound between calls; both are
  // recomputed only when its neighbourhood changes. The target is the cheapest by cost alone
  // until the vertex comes up in a round: only then is the collapse tested (valid()), and when
  // it fails the vertex takes its cheapest valid target from the next round on. A star changes
  // about ten times before its vertex comes up (4.3 M refreshes for 416 k collapses on the 832 k
  // armadillo), and testing each time cost 6 M valid() calls: 10 % of the CPU, saved; the
  // cuts' triangle counts move by under 1.2 % either way. Returns the rounds that made a collapse.
  std::uint64_t simplify_rounds(double tolerance) {
    const std::size_t n = pos_.size();
    track_dead_ = !options_.allow_self_intersections;
    if (grid_ready_) retire_dead(last_tolerance_);  // the rounds of the last call
    last_tolerance_ = tolerance;
    if (best_.size() != n) {
      best_.assign(n, Best{});
      for (std::uint32_t v = 0; v < n; ++v) dirty_list_.push_back(v);
      taken_.assign(n, 0);
    }
    std::uint64_t rounds = 0;
    std::vector<std::pair<double, std::uint32_t>> cands;
    for (;;) {
      for (const Moved& m : moved_) update_best(m);
      moved_.clear();
      for (std::uint32_t v : dirty_list_) refresh_best(v);  // after update_best: it may undo one
      dirty_list_.clear();
      cands.clear();
      for (std::uint32_t v = 0; v < n; ++v) {
        const Best& b = best_[v];
        if (b.to == kNone || removed_[v] || (b.have_error ? b.error : b.lower) > tolerance)
          continue;
        cands.push_back({b.cost, v});
      }
      std::sort(cands.begin(), cands.end());
      ++taken_stamp_;
      std::uint64_t made = 0, reranked = 0;
      // A collapse v -> to takes v, to and their rings (the new ring of `to`); a candidate may not
      // touch a taken vertex's star, so it is refused when it or its target is in the new 2-ring
      // of a collapse made in this round. That set is marked once per collapse (stars of taken
      // vertices do not change in the round: no later collapse is beside one).
      auto near_taken = [&](std::uint32_t x) { return taken_[x] == taken_stamp_; };
      for (const auto& [c, v] : cands) {
        Best& b = best_[v];
        if (removed_[v] || near_taken(v) || near_taken(b.to)) continue;
        neighbours(v, ring_);
        if (!still_valid(v, b) && !valid(v, b.to, ring_)) {
          if (b.validated) {
            dirty_list_.push_back(v);
          } else {  // its cheapest target fails: its cheapest valid one, from the next round
            const auto [cheapest, to] = cheapest_valid(v, b.to);
            set_best(v, cheapest, to, true);
            ++reranked;
          }
          continue;
        }
        b.validated = true;
        if (!b.have_error) {
          const auto [error, exact] = bound_within(v, b.to, tolerance, true, scratch_);
          if (!exact) {  // a lower bound is already too large: it waits while its star stays
            b.lower = error;
            continue;
          }
          b.error = error;
          b.new_e = scratch_.new_e;
          b.have_error = true;
        }
        if (b.error > tolerance) continue;
        if (crosses_after(v, b.to, b.error)) {
          refuse(v, b.to);
          dirty_list_.push_back(v);
          continue;
        }
        const std::uint32_t to = b.to;
        apply(v, to, b.error, b.new_e);
        b = Best{};
        dirty_list_.push_back(to);
        neighbours(to, ring_);
        for (std::uint32_t w : ring_) moved_.push_back({w, v, to});
        taken_[v] = taken_[to] = taken_stamp_;
        for (std::uint32_t w : ring_) {
          for (std::uint32_t id : star_[w]) {
            for (std::uint32_t u : tris_[id].v) taken_[u] = taken_stamp_;
          }
        }
        ++made;
      }
      std::sort(dirty_list_.begin(), dirty_list_.end());
      dirty_list_.erase(std::unique(dirty_list_.begin(), dirty_list_.end()), dirty_list_.end());
      if (made == 0 && dirty_list_.empty() && reranked == 0) return rounds;
      if (made != 0) ++rounds;
    }
  }

  struct Best {
    double cost = 0.0, error = 0.0;
    double lower = 0.0;         // a lower bound of the error once one exceeded the tolerance
    std::vector<double> new_e;  // collapse_error's bounds of the new triangles
    std::uint32_t to = kNone;
    std::array<std::uint32_t, 2> versions{};  // star_version_ of v and `to` when chosen
    bool have_error = false;
    bool validated = false;  // valid() passed for `to` (at `versions`)
  };
  // A vertex of the ring around `kept` after the collapse removed -> kept.
  struct Moved {
    std::uint32_t w, removed, kept;
  };
  // v's target, the cheapest by cost, not tested yet (update_best: after a collapse beside it).
  void refresh_best(std::uint32_t v) {
    const auto [c, to] = cheapest_target(v);
    set_best(v, c, to, false);
  }
  void update_best(const Moved& m) {
    const auto [c, to] = cheapest_after(m.w, m.removed, m.kept);
    set_best(m.w, c, to, false);
  }
  void set_best(std::uint32_t v, double c, std::uint32_t to, bool validated) {
    Best& b = best_[v];
    b = Best{};
    b.cost = c;
    b.to = to;
    b.validated = validated;
    if (to != kNone) b.versions = {star_version_[v], star_version_[to]};
  }
  // Whether b's collapse of v is known valid without testing it again: valid() read the stars of
  // v and its target (positions, locks and boundary flags do not change), neither has changed
  // since it passed, and v's component still has more vertices than the test's limit. A vertex
  // whose star changes gets a new target before the next round (refresh_best, update_best), so
  // the test is repeated only where the target's star changed (a collapse beside the target, not
  // beside v: that cannot break v's link condition, and on the subdivided dragon the 12 564
  // repeats all pass). The rounds' choices are the same as with the test (databases
  // byte-identical); 2 % less CPU.
  bool still_valid(std::uint32_t v, const Best& b) const {
    const std::uint32_t comp = comp_[v];
    return b.validated && b.versions[0] == star_version_[v] &&
           b.versions[1] == star_version_[b.to] &&
           comp_vertices_[comp] > (comp_open_[comp] ? 3u : 4u);
  }

  std::vector<Best> best_;
  std::vector<std::uint32_t> dirty_list_, taken_;
  std::vector<Moved> moved_;
  std::uint32_t taken_stamp_ = 0;

  friend class BlockPmBuilder;
  QemPmOptions options_;
  QemPmStats stats_;
  bool exhausted_ = false;  // simplification went as far as the rules allow
  double cos_max_turn_ = 0.0;
  std::vector<Vec3> pos_;
  std::vector<std::uint32_t> source_id_;  // vertex -> the source's id (empty: the same)
  std::vector<Tri> tris_;
  std::vector<std::vector<std::uint32_t>> star_;
  std::vector<std::uint32_t> star_version_;  // per vertex: changes of its star (still_valid)
  std::vector<Quadric> quad_;
  std::vector<std::uint8_t> removed_, boundary_;
  std::vector<std::uint8_t> locked_;  // block builder: vertices that stay (empty: none)
  std::vector<std::uint32_t> stamp_, comp_, comp_vertices_;
  std::vector<std::uint8_t> comp_open_;
  // The queue; its items in heap order (those in front come up soon) for post_ahead().
  struct CandidateHeap : std::priority_queue<Candidate> {
    std::vector<Candidate>& items() { return c; }  // Candidate::looked may change, not the order
  };
  CandidateHeap heap_;
  std::vector<Collapse> collapses_;
  std::vector<std::uint32_t> old_tris_, new_tris_;
  BoundScratch scratch_;  // the calling thread's
  // Bounds computed ahead (simplify(); none: one thread), by removed vertex.
  std::unique_ptr<AheadThreads> ahead_threads_;
  std::vector<AheadThreads::Job*> ahead_;   // per vertex: its job, if it holds one
  std::vector<std::uint32_t> ahead_seen_;   // per vertex: 1 + the stamp post_ahead() last saw
  std::vector<std::uint32_t> ahead_held_;   // the vertices that hold a job (or held one, used)
  std::vector<std::uint8_t> ahead_listed_;  // per vertex: in ahead_held_
  std::size_t ahead_kept_ = 0;              // their number after post_ahead() last gave jobs back
  std::vector<AheadThreads::Job*> posting_;
  std::vector<std::uint32_t> nf_, cand_, ring_;
  mutable Marks marks_;  // per vertex (neighbours, the link condition)
  // Self-intersections: the live triangles by box, per vertex the targets refused since its
  // neighbourhood last changed, per triangle marks (the old star), the new star under test.
  TriangleGrid grid_;
  bool grid_ready_ = false;
  // Mixed levels (crosses_dead): dead triangles stay in grid_ while a collapse may still need
  // them (dead_), then move to archive_ (retire_dead).
  bool track_dead_ = false;
  std::vector<std::uint32_t> dead_;  // the dead triangles still in grid_
  TriangleGrid archive_;             // the others (retire_dead)
  double archive_largest_ = 0.0;     // the largest bound of their destroyers
  double last_tolerance_ = 0.0;      // simplify_rounds: the last call's
  std::vector<std::pair<std::uint32_t, Box3>> dead_near_;
  Marks collapse_marks_;
  std::vector<std::uint32_t> dependency_stack_;
  std::vector<std::vector<std::uint32_t>> blocked_;
  Marks tri_marks_;
  std::vector<MeshTriangle> made_;
  std::vector<Box3> made_boxes_;
  std::vector<std::pair<std::uint32_t, Box3>> near_;
  std::vector<std::pair<double, std::uint32_t>> ranked_;
  // Per vertex: its cheapest target by cost (cheapest_target()), or kUnknown.
  static constexpr std::pair<double, std::uint32_t> kUnknown{0.0, kNone};
  std::vector<std::pair<double, std::uint32_t>> cheapest_;
  std::vector<std::uint32_t> tri_op_, tri_local_;
};

// ---- out of core: octree blocks with locked borders (qem_pm.h, build_block_pm) -------------

struct FaceRecord {  // a source triangle and its leaf cell (Morton code)
  std::uint32_t cell = 0;
  std::array<std::uint32_t, 3> v{};
  bool operator<(const FaceRecord& o) const { return cell < o.cell; }
};

// What a block hands to its parent: its triangles (global vertex and triangle ids, bounds, the
// collapse that made each) and the quadrics of their vertices.
struct BlockTriangle {
  std::array<std::uint32_t, 3> v{};
  double e = 0.0;
  std::uint32_t creator = kNone;  // global removal
  std::uint32_t id = 0;
};
struct BlockState {
  std::vector<BlockTriangle> tris;
  std::vector<std::pair<std::uint32_t, Quadric>> quads;  // by vertex id
};

class BlockPmBuilder {
 public:
  BlockPmBuilder(const MeshStream& mesh, const BlockPmOptions& options, BlockPmStats& stats)
      : mesh_(mesh), opt_(options), stats_(stats) {
    if (!(options.tolerance_fraction > 0.0) || !std::isfinite(options.tolerance_fraction))
      throw_input("block PM: the tolerance fraction must be positive");
    if (options.leaf_triangles < 16)
      throw_input("block PM: leaf blocks need at least 16 triangles");
    qem_.max_normal_turn_degrees = options.max_normal_turn_degrees;
    qem_.boundary_weight = options.boundary_weight;
    qem_.allow_self_intersections = options.allow_self_intersections;
    qem_.spawn_components = false;
    qem_.threads = 1;  // leaves run on several threads, each block on one
    if (!(qem_.max_normal_turn_degrees > 0.0 && qem_.max_normal_turn_degrees <= 180.0))
      throw_input("block PM: max normal turn must be in (0, 180] degrees");
  }

  void run(OpSink& sink) {
    using Clock = std::chrono::steady_clock;
    const auto t0 = Clock::now();
    auto since = [](Clock::time_point t) {
      return std::chrono::duration<double>(Clock::now() - t).count();
    };
    read_vertices();
    AssemblyOptions ao;
    ao.tmp_dir = opt_.tmp_dir;
    ao.sort_bytes = opt_.assembly_sort_bytes;
    ao.threads = opt_.threads;
    ao.progress = [this](double f) { report(0.9 + 0.1 * f); };
    assembler_ = std::make_unique<OpAssembler>(ao);
    auto faces =
        std::make_unique<storage::ExternalSorter<FaceRecord>>(opt_.tmp_dir, opt_.face_sort_bytes);
    sort_faces(*faces);
    stats_.seconds_sort = since(t0);
    const auto t1 = Clock::now();
    // Leaf blocks are read in Morton order, simplified on the workers and handed over in order
    // (parents are made as their last child is handed over, on this thread, while the workers go
    // on with the next leaves): the database does not depend on the number of threads.
    struct Leaf {
      std::uint32_t cell = 0;
      std::vector<std::array<std::uint32_t, 3>> faces;
      BlockState state;
      Simplified done;
    };
    FaceRecord f;
    bool more = faces->next(f);
    const unsigned threads = thread_count(opt_.threads);
    ordered_pipeline(
        leaf_cells_.size(), threads, threads + 1,
        [&](std::size_t) {
          if (!more) throw_internal("block PM: fewer leaf blocks than cells counted");
          auto leaf = std::make_unique<Leaf>();
          leaf->cell = f.cell;
          for (; more && f.cell == leaf->cell; more = faces->next(f)) leaf->faces.push_back(f.v);
          return leaf;
        },
        [&](Leaf& leaf) {
          reject_duplicate_faces(leaf.faces);
          leaf.state = leaf_state(leaf.faces);
          leaf.done = compute(0, leaf.state);
        },
        [&](Leaf& leaf, std::size_t) {
          for (BlockTriangle& t : leaf.state.tris) t.id = next_tri_++;
          ++stats_.leaf_blocks;
          push(0, leaf.cell, commit(std::move(leaf.state), std::move(leaf.done)));
          report(0.9 * double(leaf_done_ += leaf.faces.size()) / double(stats_.triangles));
        });
    if (more) throw_internal("block PM: more leaf blocks than cells counted");
    std::unordered_set<std::uint32_t>().swap(leaf_cells_);
    stats_.temp_bytes += faces->spilled_bytes();
    faces.reset();
    const auto t_tail = Clock::now();
    for (int l = 0; l < levels_; ++l) flush(l);
    stats_.seconds_tail = since(t_tail);
    // The octree spans are done with (the root locks nothing): the assembly may use the room.
    std::vector<std::uint32_t>().swap(vmin_);
    std::vector<std::uint32_t>().swap(vmax_);
    if (pending_[levels_].size() != 1) throw_internal("block PM: the root block is missing");
    BlockState root = std::move(pending_[levels_].front());
    stats_.seconds_blocks = since(t1);
    const auto t2 = Clock::now();
    finish(root, sink);
    stats_.seconds_assemble = since(t2);
  }

 private:
  void report(double f) const {
    if (opt_.progress) opt_.progress(std::clamp(f, 0.0, 1.0));
  }

  // Two faces on the same three vertices (in either orientation: a "pillow" is a closed surface
  // of two triangles) are a user error, as read_mesh says in memory. They have the same
  // centroid, so they meet in one leaf block.
  void reject_duplicate_faces(const std::vector<std::array<std::uint32_t, 3>>& faces) const {
    std::vector<std::array<std::uint32_t, 3>> sorted(faces);
    for (auto& f : sorted) std::sort(f.begin(), f.end());
    std::sort(sorted.begin(), sorted.end());
    const auto twice = std::adjacent_find(sorted.begin(), sorted.end());
    if (twice == sorted.end()) return;
    throw_input("mesh '" + mesh_.name() + "': two faces use the same vertices " +
                std::to_string((*twice)[0]) + ", " + std::to_string((*twice)[1]) + " and " +
                std::to_string((*twice)[2]) +
                " (a duplicate face); expected each face once; ingest it in memory (without "
                "--memory) with --repair, which drops duplicates");
  }

  void read_vertices() {
    pos_.reserve(mesh_.vertex_count());
    mesh_.vertices([&](std::span<const Vec3> batch) {
      for (const Vec3& p : batch) {
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
          throw_input("mesh '" + mesh_.name() + "': vertex " + std::to_string(pos_.size()) +
                      " has a coordinate that is not finite");
        pos_.push_back(p);
        box_.add(p);
      }
    });
    if (pos_.size() >= kNone) throw_input("mesh '" + mesh_.name() + "': too many vertices");
    stats_.vertices = pos_.size();
  }

  // Leaf cells: the bounding cube split 2^levels_ times per axis, about leaf_triangles each.
  void sort_faces(storage::ExternalSorter<FaceRecord>& faces) {
    const std::uint64_t nt = mesh_.triangle_count();
    if (nt == 0) throw_input("mesh '" + mesh_.name() + "' has no triangles");
    levels_ = 0;
    while (levels_ < 20 && (std::uint64_t{1} << (3 * levels_)) * opt_.leaf_triangles < nt)
      ++levels_;
    const Vec3 ext = box_.hi - box_.lo;
    side_ = std::max({ext.x, ext.y, ext.z, 1e-300});
    const double cells = double(std::uint64_t{1} << levels_);
    vmin_.assign(pos_.size(), ~std::uint32_t{0});
    vmax_.assign(pos_.size(), 0);
    std::uint64_t index = 0;
    std::uint32_t last_code = 0;
    mesh_.triangles([&](std::span<const std::array<std::uint32_t, 3>> batch) {
      for (const auto& t : batch) {
        for (std::uint32_t v : t) {
          if (v >= pos_.size())
            throw_input("mesh '" + mesh_.name() + "': triangle " + std::to_string(index) +
                        " names vertex " + std::to_string(v) + ", past the last (" +
                        std::to_string(pos_.size()) + " vertices)");
        }
        const Vec3 c = (pos_[t[0]] + pos_[t[1]] + pos_[t[2]]) / 3.0;
        std::uint32_t code = 0;
        for (int a = 0; a < 3; ++a) {
          const double u = (c[a] - box_.lo[a]) / side_ * cells;
          const auto k = static_cast<std::uint64_t>(std::clamp(u, 0.0, cells - 1.0));
          code |= static_cast<std::uint32_t>(spread3(k) << a);
        }
        for (std::uint32_t v : t) {
          vmin_[v] = std::min(vmin_[v], code);
          vmax_[v] = std::max(vmax_[v], code);
        }
        faces.add({code, t});
        if (index == 0 || code != last_code) leaf_cells_.insert(code);  // runs share a cell
        last_code = code;
        ++index;
      }
    });
    stats_.triangles = index;
    stats_.levels = levels_;
    for (std::uint32_t v = 0; v < pos_.size(); ++v) {
      if (vmax_[v] >= vmin_[v]) {
        referenced_box_.add(pos_[v]);
        ++referenced_;
      }
    }
    pending_.resize(levels_ + 1);
    pending_code_.assign(levels_ + 1, 0);
  }

  bool locked_at(std::uint32_t v, int level) const {
    return level < levels_ && (vmin_[v] >> (3 * level)) != (vmax_[v] >> (3 * level));
  }

  // A leaf's triangles (their ids are given when the leaf is handed over) and vertex quadrics.
  BlockState leaf_state(const std::vector<std::array<std::uint32_t, 3>>& leaf) const {
    BlockState b;
    std::unordered_map<std::uint32_t, Quadric> quads;
    for (const auto& t : leaf) {
      b.tris.push_back({t, 0.0, kNone, 0});
      const Quadric q = face_quadric(pos_[t[0]], pos_[t[1]], pos_[t[2]]);
      for (std::uint32_t v : t) quads[v] += q;
    }
    b.quads.assign(quads.begin(), quads.end());
    std::sort(b.quads.begin(), b.quads.end(),
              [](const auto& x, const auto& y) { return x.first < y.first; });
    return b;
  }

  // A block of `level` done: it waits for its siblings; a parent is made when the next block
  // belongs to another parent (blocks come in Morton order).
  void push(int level, std::uint64_t code, BlockState b) {
    if (level < levels_ && !pending_[level].empty() && (code >> 3) != pending_code_[level] >> 3) {
      flush(level);
    }
    pending_[level].push_back(std::move(b));
    pending_code_[level] = code;
  }

  void flush(int level) {
    if (pending_[level].empty()) return;
    BlockState merged;
    std::vector<std::pair<std::uint32_t, Quadric>> quads;
    for (BlockState& b : pending_[level]) {
      merged.tris.insert(merged.tris.end(), b.tris.begin(), b.tris.end());
      quads.insert(quads.end(), b.quads.begin(), b.quads.end());
    }
    pending_[level].clear();
    std::stable_sort(quads.begin(), quads.end(),
                     [](const auto& x, const auto& y) { return x.first < y.first; });
    for (const auto& [v, q] : quads) {
      if (!merged.quads.empty() && merged.quads.back().first == v) {
        merged.quads.back().second += q;
      } else {
        merged.quads.push_back({v, q});
      }
    }
    push(level + 1, pending_code_[level] >> 3, simplify(level + 1, std::move(merged)));
  }

  // Simplifies one block and hands its collapses to the assembler.
  BlockState simplify(int level, BlockState in) {
    Simplified done = compute(level, in);
    BlockState out = commit(std::move(in), std::move(done));
    if (level < levels_) {
      stats_.max_handed_triangles =
          std::max<std::uint64_t>(stats_.max_handed_triangles, out.tris.size());
    }
    return out;
  }

  // A block simplified, not yet handed over: reads only what stays fixed while blocks are made
  // (positions, octree spans, options), so blocks of a level run on several threads.
  struct Simplified {
    std::unique_ptr<Builder> b;
    std::vector<std::uint32_t> gid;  // local vertex -> global
    std::uint64_t rounds = 0;
  };
  Simplified compute(int level, const BlockState& in) const {
    const std::size_t n = in.quads.size();
    std::vector<std::uint32_t> gid(n);
    std::vector<Vec3> pos(n);
    std::vector<Quadric> quad(n);
    std::vector<std::uint8_t> locked(n), constrain(n);
    std::unordered_map<std::uint32_t, std::uint32_t> local;
    local.reserve(n * 2);
    // Local vertices in Morton order (as the in-core builder's): neighbours close in memory.
    std::vector<std::pair<std::uint64_t, std::uint32_t>> order(n);
    for (std::uint32_t i = 0; i < n; ++i) {
      order[i] = {morton_code(pos_[in.quads[i].first], box_.lo, Vec3(side_)), i};
    }
    std::sort(order.begin(), order.end());
    for (std::uint32_t i = 0; i < n; ++i) {
      const auto& [v, q] = in.quads[order[i].second];
      gid[i] = v;
      pos[i] = pos_[v];
      quad[i] = q;
      locked[i] = locked_at(v, level) ? 1 : 0;
      constrain[i] = level == 0 || locked_at(v, level - 1) ? 1 : 0;
      local.emplace(v, i);
    }
    std::vector<Tri> tris;
    tris.reserve(in.tris.size());
    for (const BlockTriangle& t : in.tris) {
      Tri lt;
      for (int k = 0; k < 3; ++k) lt.v[k] = local.at(t.v[k]);
      lt.e = t.e;
      tris.push_back(lt);
    }
    Simplified out;
    out.b = std::make_unique<Builder>(qem_, std::move(pos), std::move(quad), std::move(locked),
                                      constrain, tris, mesh_.name(), gid);
    // Collapses up to tolerance_fraction of the block's side (the root: as far as the rules
    // allow), cheapest quadric cost first within the bound, as the in-core builder orders them.
    // The tolerance rises in steps of 2 from an 8th of it, so that within a block collapses
    // with small bounds go first: a collapse's bound is at least those of the collapses it
    // depends on, and one early large bound would raise all that come after it in its region.
    // The root goes on doubling up to the model's size, then as far as the rules allow.
    const int below = std::min(level, levels_ - 1);
    const double top =
        opt_.tolerance_fraction * side_ / double(std::uint64_t{1} << (levels_ - below));
    const double last = level == levels_ ? side_ : top;
    for (double t = top / 8.0; t <= last; t *= 2.0) out.rounds += out.b->simplify_rounds(t);
    if (level == levels_) out.rounds += out.b->simplify_rounds(kInfinity);
    // A block hands its parent at most leaf_triangles triangles (so that a block above the
    // leaves holds at most 8 times that): past `top`, the tolerance goes on doubling until it
    // does, or until the rules allow no more.
    for (double t = 2.0 * top; level < levels_ && out.b->alive_triangles() > opt_.leaf_triangles;
         t *= 2.0) {
      const std::uint64_t rounds = out.b->simplify_rounds(t);
      out.rounds += rounds;
      if (rounds == 0 && t > side_) break;  // the rules allow no more
    }
    out.gid = std::move(gid);
    return out;
  }

  // Hands a simplified block's collapses to the assembler, in order, as removals (new triangles
  // get the next global ids), and returns what the block passes to its parent. In block order.
  BlockState commit(BlockState in, Simplified done) {
    stats_.max_block_triangles =
        std::max<std::uint64_t>(stats_.max_block_triangles, in.tris.size());
    stats_.rounds += done.rounds;
    const Builder& b = *done.b;
    const std::vector<std::uint32_t>& gid = done.gid;
    const std::size_t n = gid.size();
    const std::uint32_t k0 = static_cast<std::uint32_t>(assembler_->removals());
    const std::size_t n_in = in.tris.size();
    std::vector<std::uint32_t> id_of(b.tris_.size()), creator_of(b.tris_.size());
    for (std::size_t t = 0; t < n_in; ++t) {
      id_of[t] = in.tris[t].id;
      creator_of[t] = in.tris[t].creator;
    }
    std::vector<OpAssembler::StarTriangle> star;
    std::vector<OpAssembler::MadeTriangle> made;
    for (std::uint32_t c = 0; c < b.collapses_.size(); ++c) {
      const Collapse& col = b.collapses_[c];
      star.clear();
      for (std::uint32_t i = col.old_begin; i < col.old_end; ++i) {
        const std::uint32_t t = b.old_tris_[i];
        const Tri& x = b.tris_[t];
        star.push_back({{gid[x.v[0]], gid[x.v[1]], gid[x.v[2]]}, id_of[t], creator_of[t], false});
      }
      made.clear();
      for (std::uint32_t i = col.new_begin; i < col.new_end; ++i) {
        const std::uint32_t t = b.new_tris_[i];
        const Tri& x = b.tris_[t];
        id_of[t] = next_tri_++;
        creator_of[t] = k0 + c;
        made.push_back({{gid[x.v[0]], gid[x.v[1]], gid[x.v[2]]}, id_of[t], false});
      }
      const std::uint32_t removed = gid[col.removed];
      assembler_->add_removal(std::span(&removed, 1), star, made, col.error);
    }
    stats_.collapses += b.collapses_.size();
    stats_.rejected_intersection += b.stats_.rejected_intersection;
    BlockState out;
    std::vector<std::uint8_t> used(n, 0);
    for (std::uint32_t t = 0; t < b.tris_.size(); ++t) {
      const Tri& x = b.tris_[t];
      if (x.destroyer != kNone) continue;
      out.tris.push_back({{gid[x.v[0]], gid[x.v[1]], gid[x.v[2]]}, x.e, creator_of[t], id_of[t]});
      for (std::uint32_t v : x.v) used[v] = 1;
    }
    for (std::uint32_t i = 0; i < n; ++i) {
      if (used[i]) out.quads.push_back({gid[i], b.quad_[i]});
    }
    return out;
  }

  void finish(const BlockState& root, OpSink& sink) {
    CrmrInfo info;
    info.kind = ModelKind::kMesh3d;
    info.source = mesh_.name();
    info.builder = "block-pm leaf-triangles=" + std::to_string(opt_.leaf_triangles) +
                   " tolerance-fraction=" + std::to_string(opt_.tolerance_fraction) +
                   " max-normal-turn=" + std::to_string(opt_.max_normal_turn_degrees) +
                   " boundary-weight=" + std::to_string(opt_.boundary_weight);
    std::vector<std::uint8_t> used(pos_.size(), 0);
    std::vector<OpAssembler::StarTriangle> base;
    for (const BlockTriangle& t : root.tris) {
      base.push_back({t.v, t.id, t.creator, false});
      info.err0 = std::max(info.err0, t.e);
    }
    // No op's error above R^0's (their resolutions would be clamped to 0 below their error).
    for (std::uint64_t k = 0; k < assembler_->removals(); ++k) {
      info.err0 = std::max(info.err0, assembler_->error(static_cast<std::uint32_t>(k)));
    }
    info.bounds = referenced_box_;
    info.vertex_count = referenced_;
    for (const BlockTriangle& t : root.tris) {
      for (std::uint32_t v : t.v) used[v] = 1;
    }
    stats_.base_triangles = base.size();
    stats_.base_vertices = static_cast<std::uint64_t>(std::count(used.begin(), used.end(), 1));
    info.err_final = 0.0;
    assembler_->finish(
        info, base, [this](std::uint32_t v) { return pos_[v]; }, sink);
    stats_.dag_height = assembler_->stats().dag_height;
    stats_.seconds_join = assembler_->stats().seconds_join;
    stats_.seconds_emit = assembler_->stats().seconds_emit;
    stats_.temp_bytes += assembler_->stats().scratch_bytes;
    report(1.0);
  }

  static constexpr double kInfinity = std::numeric_limits<double>::infinity();
  const MeshStream& mesh_;
  const BlockPmOptions& opt_;
  BlockPmStats& stats_;
  QemPmOptions qem_;
  std::vector<Vec3> pos_;
  Box3 box_;
  double side_ = 1.0;
  int levels_ = 0;
  std::vector<std::uint32_t> vmin_, vmax_;  // leaf cells of each vertex's triangles (Morton)
  Box3 referenced_box_;                     // of the vertices some triangle uses
  std::uint64_t referenced_ = 0;
  std::vector<std::vector<BlockState>> pending_;  // per level: blocks waiting for siblings
  std::vector<std::uint64_t> pending_code_;
  std::uint32_t next_tri_ = 0;
  std::uint64_t leaf_done_ = 0;
  std::unordered_set<std::uint32_t> leaf_cells_;  // non-empty leaf cells (sort_faces)
  std::unique_ptr<OpAssembler> assembler_;
};

}  // namespace

Crmr build_qem_pm(const TriangleMesh& mesh, const std::string& name, const QemPmOptions& options,
                  QemPmStats* stats) {
  if (mesh.triangles.empty()) throw_input("mesh '" + name + "' has no triangles");
  if (!(options.max_normal_turn_degrees > 0.0 && options.max_normal_turn_degrees <= 180.0)) {
    throw_input("QEM PM: max normal turn must be in (0, 180] degrees");
  }
  if (!(options.coalesce_error_ratio >= 0.0 && options.coalesce_error_ratio <= 1.0)) {
    throw_input("QEM PM: the coalescing error ratio must be in [0, 1]");
  }
  if (!(options.bound_band == 0.0 ||
        (options.bound_band >= 1.0 && std::isfinite(options.bound_band)))) {
    throw_input("QEM PM: the bound band must be 0 (none) or a finite factor of at least 1");
  }
  Builder b(mesh, options);
  return b.run(name, stats);
}

}  // namespace smr

namespace smr {

void build_block_pm(const MeshStream& mesh, OpSink& sink, const BlockPmOptions& options,
                    BlockPmStats* stats) {
  BlockPmStats local;
  BlockPmBuilder(mesh, options, stats != nullptr ? *stats : local).run(sink);
}

Crmr build_block_pm(const MeshStream& mesh, const BlockPmOptions& options, BlockPmStats* stats) {
  CrmrCollector collector;
  build_block_pm(mesh, collector, options, stats);
  return collector.take();
}

}  // namespace smr
