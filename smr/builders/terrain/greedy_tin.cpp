// Greedy Delaunay insertion into a CRMR (Brown 7.1.1, 4.4.3.2-4.4.3.3; Garland & Heckbert,
// "Fast polygonal approximation of terrains and height fields", 1995).
//
// CGAL's Delaunay triangulation (exact predicates) is wrapped here and nowhere else. Every
// insertion is done as get_conflicts_and_boundary + star_hole, so the faces that die are exactly
// the conflict zone (PreF) and the faces that are born are exactly the new star (F).
//
// Triangles are rasterised exactly in integer grid coordinates: a sample belongs to a triangle iff
// it lies in the closed triangle, so each triangle's maximum error is computed from every sample
// it covers, and the error bound of Brown's resolution attributes is exact, not estimated.
//
// Speed and memory (benchmarks/README.md, "Profile"):
// - The sample scan is bound by DEM cache misses: the rows under a whole new star are prefetched
//   right after star_hole, before any of it is scanned, and every scan prefetches a few rows
//   ahead. Row spans come from exact integer edge steppers (no division per row); a row's maximum
//   is taken with SSE2 using the scalar code's exact operations, so errors are bit-identical.
// - The queue is an indexed max-heap over live triangles, keyed by (error, creation number), so
//   dead triangles leave it at once and ties break exactly as before (the newest first).
// - A triangle's build record is recycled as soon as the op that killed it is closed, so build
//   memory follows the live mesh, not every triangle ever made.
// - Ops are kept in fixed-size chunks and moved into an exactly sized vector at the end; each op's
//   vectors are allocated once at their final size. A triangle's build record is 48 bytes.
// - link_dag is not called: close_op fills pre_tris (from the killed triangles' records), parents
//   (their distinct creators) and the bounds (compute_op_bounds, while the op is in cache), and
//   finish sets birth_res, killer/death_res and children in one pass, then compute_rois. The
//   result is field for field what link_dag computes (bench_build --fingerprint).
#include "smr/builders/terrain/greedy_tin.h"

#include <CGAL/Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include "base/error.h"
#include "smr/builders/terrain/triangle_rows.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace smr {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_2<std::uint32_t, K>;
/// What a face tells its neighbours: its build record and, once its op is closed, its TriRef
/// (close_op reads these across fragment boundaries without touching the record).
struct FaceInfo {
  std::uint32_t id;  // index in Builder::tris_; kNone on infinite faces
  std::uint32_t op;
  std::uint32_t local;
};
using Fb = CGAL::Triangulation_face_base_with_info_2<FaceInfo, K>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
using Dt = CGAL::Delaunay_triangulation_2<K, Tds>;
using FaceHandle = Dt::Face_handle;
using Point = K::Point_2;

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
constexpr double kMixed = std::numeric_limits<double>::infinity();

struct BuildVertex {
  std::uint32_t col, row;
  float z;  // the sample's elevation, or the fill value at a no-data sample
};

/// The build record of a live triangle (or of one that died in the op being built): 48 bytes.
struct BuildTri {
  static constexpr std::uint32_t kOpBits = 30;
  FaceHandle face;
  double err = 0.0;                  // max vertical error; kMixed when it must be split
  std::array<std::uint32_t, 3> v{};  // build vertex ids, counter-clockwise
  std::uint32_t op : kOpBits = 0;    // creating op
  std::uint32_t alive : 1 = 1;
  std::uint32_t is_void : 1 = 0;
  std::uint32_t local = kNone;     // index in the op's fragment, once the op is closed
  std::uint32_t cand = kNone;      // sample to insert next (max error, or a no-data fix)
  std::uint32_t seq = 0;           // creation number: breaks ties between equal errors
  std::uint32_t heap_pos = kNone;  // index in the queue, or kNone
};
static_assert(sizeof(BuildTri) <= 48);

/// |z - plane| at column `col` of a row whose plane is a * col + zrow.
inline double sample_error(float z, double a, std::int64_t col, double zrow) {
  return std::abs(double(z) - (a * double(col) + zrow));
}

/// max(m, the errors of samples xl..xr of one row): the same arithmetic as sample_error, two
/// samples per SSE2 instruction (exact: every step is one IEEE operation, as in the scalar code).
/// NaN samples are ignored, as by `e > best`.
inline double row_max_error(const float* z, std::int64_t xl, std::int64_t xr, double a, double zrow,
                            double m) {
  std::int64_t col = xl;
#if defined(__SSE2__)
  if (xr - xl >= 3) {
    const __m128d va = _mm_set1_pd(a), vz = _mm_set1_pd(zrow), four = _mm_set1_pd(4.0);
    const __m128d sign = _mm_set1_pd(-0.0);
    __m128d c0 = _mm_set_pd(double(xl + 1), double(xl)), c1 = _mm_add_pd(c0, _mm_set1_pd(2.0));
    __m128d m0 = _mm_set1_pd(m), m1 = m0;
    for (; col + 3 <= xr; col += 4) {
      const __m128 f = _mm_loadu_ps(z + col);
      const __m128d z0 = _mm_cvtps_pd(f), z1 = _mm_cvtps_pd(_mm_movehl_ps(f, f));
      const __m128d e0 = _mm_andnot_pd(sign, _mm_sub_pd(z0, _mm_add_pd(_mm_mul_pd(va, c0), vz)));
      const __m128d e1 = _mm_andnot_pd(sign, _mm_sub_pd(z1, _mm_add_pd(_mm_mul_pd(va, c1), vz)));
      m0 = _mm_max_pd(e0, m0);  // the second operand when either is NaN
      m1 = _mm_max_pd(e1, m1);
      c0 = _mm_add_pd(c0, four);
      c1 = _mm_add_pd(c1, four);
    }
    m0 = _mm_max_pd(m0, m1);
    m = std::max(_mm_cvtsd_f64(m0), _mm_cvtsd_f64(_mm_unpackhi_pd(m0, m0)));
  }
#endif
  for (; col <= xr; ++col) {
    const double e = sample_error(z[col], a, col, zrow);
    if (e > m) m = e;
  }
  return m;
}

/// Ops in fixed-size chunks, so that growing never copies them or doubles their footprint. A chunk
/// is larger than glibc's largest dynamic mmap threshold (32 MiB), so it is mapped on its own: its
/// pages are touched only as ops fill it and go back to the system as soon as it is freed.
class OpStore {
 public:
  static constexpr std::size_t kChunk = (std::size_t(40) << 20) / sizeof(Op);
  OpStore() = default;
  OpStore(const OpStore&) = delete;
  OpStore& operator=(const OpStore&) = delete;
  ~OpStore() { clear(); }

  std::size_t size() const { return size_; }
  Op& operator[](std::size_t i) { return chunks_[i / kChunk][i % kChunk]; }
  void push_back(Op&& op) {
    if (size_ % kChunk == 0) chunks_.push_back(std::allocator<Op>().allocate(kChunk));
    new (&chunks_.back()[size_ % kChunk]) Op(std::move(op));
    ++size_;
  }
  /// Moves every op into `out` (sized exactly), freeing each chunk once it is moved.
  void move_to(std::vector<Op>& out) {
    out.clear();
    out.reserve(size_);
    for (std::size_t c = 0; c < chunks_.size(); ++c) {
      const std::size_t n = std::min(kChunk, size_ - c * kChunk);
      for (std::size_t i = 0; i < n; ++i) out.push_back(std::move(chunks_[c][i]));
      free_chunk(c, n);
    }
    chunks_.clear();
    size_ = 0;
  }

 private:
  void free_chunk(std::size_t c, std::size_t n) {
    std::destroy_n(chunks_[c], n);
    std::allocator<Op>().deallocate(chunks_[c], kChunk);
    chunks_[c] = nullptr;
  }
  void clear() {
    for (std::size_t c = 0; c < chunks_.size(); ++c) {
      if (chunks_[c] != nullptr) free_chunk(c, std::min(kChunk, size_ - c * kChunk));
    }
    chunks_.clear();
    size_ = 0;
  }

  std::vector<Op*> chunks_;
  std::size_t size_ = 0;
};

class Builder {
 public:
  /// `mesh_only`: no ops are made (run_mesh()).
  Builder(const Heightfield& dem, const GreedyTinOptions& options, bool mesh_only = false)
      : dem_(dem),
        opt_(options),
        mesh_only_(mesh_only),
        tol_(options.tolerance >= 0.0 ? options.tolerance : exact_tolerance(dem)) {
    if (dem.width < 2 || dem.height < 2) {
      throw_input(dem.source + ": a DEM needs at least 2x2 samples, got " +
                  std::to_string(dem.width) + "x" + std::to_string(dem.height));
    }
    if (static_cast<std::size_t>(dem.width) * dem.height != dem.z.size() ||
        (!dem.valid.empty() && dem.valid.size() != dem.z.size())) {
      throw_internal(dem.source + ": heightfield arrays do not match its size");
    }
    if (dem.z.size() >= kNone) {
      throw_input(dem.source + ": too many samples for the in-core builder (" +
                  std::to_string(dem.z.size()) + ")");
    }
    fill_z_ = std::numeric_limits<float>::infinity();
    std::size_t valid = 0;
    for (std::size_t i = 0; i < dem.z.size(); ++i) {
      if (dem.valid.empty() || dem.valid[i] != 0) {
        fill_z_ = std::min(fill_z_, dem.z[i]);
        ++valid;
      }
    }
    if (valid == 0 && !opt_.allow_no_data_only)
      throw_input(dem.source + ": every sample is no data");
    if (valid == 0) fill_z_ = 0.0f;
    valid_samples_ = valid;
    stop_error_ = std::max(opt_.max_error, tol_);
  }

  Crmr run() {
    const double err0 = refine();
    // The finest mesh's error: the largest error of any surviving triangle (those under the stop
    // tolerance never enter the queue, so scan them all).
    double err_final = 0.0;
    for (const BuildTri& t : tris_) {
      if (t.alive) err_final = std::max(err_final, t.err);
    }
    return finish(err0, err_final);
  }

  GreedyMesh run_mesh() {
    refine();
    GreedyMesh mesh;
    mesh.vertices.reserve(verts_.size());
    for (const BuildVertex& v : verts_) mesh.vertices.push_back({v.col, v.row, v.z});
    // By creation: ops are made in creation order and each holds its survivors in that order.
    std::vector<std::pair<std::uint32_t, std::uint32_t>> alive;  // (seq, record)
    for (std::uint32_t id = 0; id < tris_.size(); ++id) {
      if (tris_[id].alive) alive.push_back({tris_[id].seq, id});
    }
    std::sort(alive.begin(), alive.end());
    mesh.triangles.reserve(alive.size());
    for (const auto& [seq, id] : alive)
      mesh.triangles.push_back({tris_[id].v, tris_[id].is_void != 0});
    return mesh;
  }

 private:
  // The insertions: R^0 (the corners, the initial vertices, refined until holes are exact and
  // to base_vertices), then the sample of largest error until every one is within the stop
  // error. Returns R^0's error. Unless mesh_only_, each op is closed as it ends.
  double refine() {
    const std::uint32_t w = dem_.width - 1, h = dem_.height - 1;
    // R^0: the corner triangulation, refined until holes are exact (and to base_vertices).
    begin_op(kMixed);
    for (auto [c, r] : {std::pair{0u, 0u}, {w, 0u}, {w, h}, {0u, h}}) add_vertex(c, r);
    auto initial = opt_.initial_vertices;
    std::sort(initial.begin(), initial.end());
    initial.erase(std::unique(initial.begin(), initial.end()), initial.end());
    for (auto [c, r] : initial) {
      if (c > w || r > h) {
        throw_internal(dem_.source + ": an initial vertex lies outside the grid");
      }
      if ((c == 0 || c == w) && (r == 0 || r == h)) continue;  // a corner
      add_vertex(c, r);
    }
    for (std::uint32_t i = 0; i < verts_.size(); ++i) {
      Dt::Vertex_handle vh = dt_.insert(Point(verts_[i].col, verts_[i].row));
      vh->info() = i;
    }
    for (auto f = dt_.all_faces_begin(); f != dt_.all_faces_end(); ++f) {
      if (dt_.is_infinite(f)) {
        f->info().id = kNone;
      } else {
        new_tri(f);
      }
    }
    while (!heap_.empty() && (top_err() == kMixed || verts_.size() < opt_.base_vertices)) {
      insert_top();
    }
    const double err0 = heap_.empty() ? 0.0 : top_err();
    if (!mesh_only_) close_op();
    err0_ = err0;

    // R^1..R^m: one op per insertion, coalesced while the mesh error exceeds its start.
    std::size_t steps = 0;
    while (!heap_.empty() && top_err() > stop_error_) {
      if (opt_.max_vertices != 0 && verts_.size() >= opt_.max_vertices) break;
      const double e_start = top_err();
      begin_op(e_start);
      insert_top();
      while (!heap_.empty() && top_err() > e_start) insert_top();
      if (!mesh_only_) close_op();
      if (opt_.progress && (++steps & 0xfff) == 0) report_progress();
    }
    return err0;
  }

  // ---- vertices and samples ----
  std::uint32_t add_vertex(std::uint32_t col, std::uint32_t row) {
    verts_.push_back({col, row, has_data(col, row) ? dem_.at(col, row) : fill_z_});
    op_.new_vertices.push_back(static_cast<std::uint32_t>(verts_.size() - 1));
    return static_cast<std::uint32_t>(verts_.size() - 1);
  }
  Vec3 world(const BuildVertex& v) const {
    return {dem_.georef.x0 + v.col * dem_.georef.dx, dem_.georef.y0 + v.row * dem_.georef.dy,
            double(v.z)};
  }
  Vec3 world(const Point& q) const {  // the same as world(verts_[id]) for the vertex at q
    const auto col = static_cast<std::uint32_t>(q.x()), row = static_cast<std::uint32_t>(q.y());
    return world(BuildVertex{col, row, has_data(col, row) ? dem_.at(col, row) : fill_z_});
  }
  bool has_data(std::uint32_t col, std::uint32_t row) const {
    return dem_.valid.empty() || dem_.valid[dem_.index(col, row)] != 0;
  }

  // ---- the priority queue: an indexed max-heap of live triangles by (err, seq) ----
  struct HeapEntry {
    double err;
    std::uint32_t seq;
    std::uint32_t tri;
  };
  static bool above(const HeapEntry& a, const HeapEntry& b) {
    return a.err > b.err || (a.err == b.err && a.seq > b.seq);
  }
  void heap_place(std::size_t i, const HeapEntry& e) {
    heap_[i] = e;
    tris_[e.tri].heap_pos = static_cast<std::uint32_t>(i);
  }
  // Binary: a 4-ary heap measured no faster at 0.5 m (within noise).
  static constexpr std::size_t kArity = 2;
  void sift_up(std::size_t i, HeapEntry e) {
    while (i > 0) {
      const std::size_t parent = (i - 1) / kArity;
      if (!above(e, heap_[parent])) break;
      heap_place(i, heap_[parent]);
      i = parent;
    }
    heap_place(i, e);
  }
  void sift_down(std::size_t i, HeapEntry e) {
    const std::size_t n = heap_.size();
    for (;;) {
      const std::size_t first = kArity * i + 1;
      if (first >= n) break;
      std::size_t best = first;
      const std::size_t end = std::min(first + kArity, n);
      for (std::size_t c = first + 1; c < end; ++c) {
        if (above(heap_[c], heap_[best])) best = c;
      }
      if (!above(heap_[best], e)) break;
      heap_place(i, heap_[best]);
      i = best;
    }
    heap_place(i, e);
  }
  void push(std::uint32_t t) {
    const BuildTri& b = tris_[t];
    if (!(b.err > stop_error_ || b.err == kMixed)) return;
    heap_.push_back({});
    sift_up(heap_.size() - 1, {b.err, b.seq, t});
  }
  void heap_remove(std::uint32_t t) {
    const std::uint32_t pos = tris_[t].heap_pos;
    if (pos == kNone) return;
    tris_[t].heap_pos = kNone;
    const HeapEntry last = heap_.back();
    heap_.pop_back();
    if (pos == heap_.size()) return;
    if (pos > 0 && above(last, heap_[(pos - 1) / kArity])) {
      sift_up(pos, last);
    } else {
      sift_down(pos, last);
    }
  }
  double top_err() const { return heap_.front().err; }

  // ---- triangles ----
  std::uint32_t new_tri(FaceHandle f) {
    std::uint32_t id;
    if (!free_tris_.empty()) {
      id = free_tris_.back();
      free_tris_.pop_back();
    } else {
      id = static_cast<std::uint32_t>(tris_.size());
      tris_.emplace_back();
    }
    if (next_seq_ == kNone) throw_input(dem_.source + ": too many triangles for the builder");
    BuildTri& t = tris_[id];
    t = BuildTri{};
    t.face = f;
    for (int i = 0; i < 3; ++i) t.v[i] = f->vertex(i)->info();
    t.op = op_.index & ((1u << BuildTri::kOpBits) - 1);  // begin_op checks the range
    t.seq = next_seq_++;
    f->info() = {id, op_.index, kNone};
    if (!mesh_only_) op_.created.push_back(id);
    scan(t);
    push(id);
    return id;
  }

  // Computes err and cand of t from every grid sample in the closed triangle.
  void scan(BuildTri& t) {
    // The corners from the face's points (in cache after star_hole; verts_ is not), z from the
    // DEM as add_vertex takes it.
    std::int64_t x[3], y[3];
    double z[3];
    t.is_void = 0;
    for (int k = 0; k < 3; ++k) {
      const Point& q = t.face->vertex(k)->point();
      x[k] = static_cast<std::int64_t>(q.x());
      y[k] = static_cast<std::int64_t>(q.y());
      const auto col = static_cast<std::uint32_t>(x[k]), row = static_cast<std::uint32_t>(y[k]);
      const bool data = has_data(col, row);
      if (!data) t.is_void = 1;
      z[k] = data ? double(dem_.at(col, row)) : double(fill_z_);
    }
    // Plane z = a*x + b*y + c through the three vertices (in grid units).
    const double det = double((x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]));
    const double a =
        ((z[1] - z[0]) * double(y[2] - y[0]) - (z[2] - z[0]) * double(y[1] - y[0])) / det;
    const double b =
        ((z[2] - z[0]) * double(x[1] - x[0]) - (z[1] - z[0]) * double(x[2] - x[0])) / det;
    const double c = z[0] - a * double(x[0]) - b * double(y[0]);
    const double cx = double(x[0] + x[1] + x[2]) / 3.0, cy = double(y[0] + y[1] + y[2]) / 3.0;

    build::TriangleRows rows(x, y);
    const std::int64_t ymin = rows.ymin(), ymax = rows.ymax();
    if (ymin == ymax) throw_internal("greedy TIN: degenerate triangle");

    double best = 0.0;
    std::uint32_t cand = kNone;
    std::int64_t best_row = -1, best_xl = 0;
    bool mixed = false;
    double mixed_d2 = std::numeric_limits<double>::infinity();
    const bool nodata = dem_.has_nodata();
    const float* zs = dem_.z.data();
    const std::uint8_t* valid = nodata ? dem_.valid.data() : nullptr;
    const std::size_t width = static_cast<std::size_t>(dem_.width);

    for (std::int64_t row = ymin; row <= ymax; ++row) {
      std::int64_t xl, xr;
      rows.next(xl, xr);
      if (xl > xr) continue;
      const std::size_t base = static_cast<std::size_t>(row) * width;
      if (row + kLookaheadRows <= ymax) {  // the span a few rows ahead, roughly
        const float* ahead = zs + base + kLookaheadRows * width;
        for (std::int64_t col = xl; col <= xr; col += 16) __builtin_prefetch(ahead + col);
        __builtin_prefetch(ahead + xr);
      }
      const double zrow = b * double(row) + c;
      if (!nodata) {
        // The first row reaching the largest error; its column is found once, at the end.
        const double m = row_max_error(zs + base, xl, xr, a, zrow, best);
        if (m > best) {
          best = m;
          best_row = row;
          best_xl = xl;
        }
        continue;
      }
      const bool frozen_row = opt_.freeze_border && (row == 0 || row == dem_.height - 1);
      for (std::int64_t col = xl; col <= xr; ++col) {
        if (opt_.freeze_border && (frozen_row || col == 0 || col == dem_.width - 1)) continue;
        const bool v = valid[base + col] != 0;
        if (t.is_void) {
          // A void triangle may hold valid samples only at its own vertices.
          if (!v) continue;
          bool is_vertex = false;
          for (int k = 0; k < 3; ++k) is_vertex |= (x[k] == col && y[k] == row);
          if (is_vertex) continue;
        } else if (v) {
          const double e = sample_error(zs[base + col], a, col, zrow);
          if (e > best && !mixed) {
            best = e;
            cand = static_cast<std::uint32_t>(base + col);
          }
          continue;
        }
        // This sample must become a vertex for the hole boundary to be exact.
        const double d2 =
            (double(col) - cx) * (double(col) - cx) + (double(row) - cy) * (double(row) - cy);
        if (!mixed || d2 < mixed_d2) {
          mixed = true;
          mixed_d2 = d2;
          cand = static_cast<std::uint32_t>(base + col);
        }
      }
    }
    if (best_row >= 0) {
      // The first sample of that row with the error: the one a row-major scan keeps.
      const std::size_t base = static_cast<std::size_t>(best_row) * width;
      const double zrow = b * double(best_row) + c;
      std::int64_t col = best_xl;
      while (sample_error(zs[base + col], a, col, zrow) != best) ++col;
      cand = static_cast<std::uint32_t>(base + col);
    }
    if (mixed) {
      t.err = kMixed;
    } else if (t.is_void || best <= tol_) {
      t.err = 0.0;
      cand = kNone;
    } else {
      t.err = best;
    }
    t.cand = cand;
  }

  // Prefetches the DEM rows under a triangle's bounding box when it is small (every triangle also
  // prefetches a few rows ahead while it is scanned).
  void prefetch(FaceHandle f) const {
    std::int64_t x0 = std::numeric_limits<std::int64_t>::max(), x1 = -1;
    std::int64_t y0 = std::numeric_limits<std::int64_t>::max(), y1 = -1;
    for (int i = 0; i < 3; ++i) {
      const Point& q = f->vertex(i)->point();
      x0 = std::min(x0, static_cast<std::int64_t>(q.x()));
      x1 = std::max(x1, static_cast<std::int64_t>(q.x()));
      y0 = std::min(y0, static_cast<std::int64_t>(q.y()));
      y1 = std::max(y1, static_cast<std::int64_t>(q.y()));
    }
    if (y1 - y0 > kPrefetchRows || x1 - x0 > kPrefetchCols) return;
    const float* zs = dem_.z.data();
    const std::size_t width = static_cast<std::size_t>(dem_.width);
    for (std::int64_t row = y0; row <= y1; ++row) {
      const float* r = zs + static_cast<std::size_t>(row) * width;
      for (std::int64_t col = x0; col <= x1; col += 16) __builtin_prefetch(r + col);
      __builtin_prefetch(r + x1);
    }
  }

  void kill(std::uint32_t id) {
    BuildTri& t = tris_[id];
    t.alive = 0;
    heap_remove(id);
    if (mesh_only_) {
      free_tris_.push_back(id);  // no op refers to it
    } else if (t.op != op_.index) {
      op_.killed.push_back(id);
    }
  }

  void insert_top() {
    const std::uint32_t tid = heap_.front().tri;
    heap_remove(tid);
    const std::uint32_t sample = tris_[tid].cand;
    const auto col = static_cast<std::uint32_t>(sample % dem_.width);
    const auto row = static_cast<std::uint32_t>(sample / dem_.width);
    const Point p(col, row);

    scr_.conflicts.clear();
    scr_.boundary.clear();
    dt_.get_conflicts_and_boundary(p, std::back_inserter(scr_.conflicts),
                                   std::back_inserter(scr_.boundary), tris_[tid].face);
    if (scr_.conflicts.empty()) throw_internal("greedy TIN: empty conflict zone");
    for (FaceHandle f : scr_.conflicts) {
      if (f->info().id != kNone) kill(f->info().id);
    }
    const std::uint32_t vid = add_vertex(col, row);
    Dt::Vertex_handle vh = dt_.star_hole(p, scr_.boundary.begin(), scr_.boundary.end(),
                                         scr_.conflicts.begin(), scr_.conflicts.end());
    vh->info() = vid;
    // The DEM under the whole new star is fetched before any of it is scanned.
    scr_.star.clear();
    Dt::Face_circulator fc = dt_.incident_faces(vh), done = fc;
    do {
      if (dt_.is_infinite(fc)) {
        fc->info().id = kNone;
      } else {
        scr_.star.push_back(fc);
        prefetch(fc);
      }
    } while (++fc != done);
    for (FaceHandle f : scr_.star) new_tri(f);
  }

  // ---- ops ----
  void begin_op(double e_start) {
    if (ops_.size() >= (std::size_t(1) << BuildTri::kOpBits)) {
      throw_input(dem_.source + ": too many refinement operations for the builder");
    }
    op_.index = static_cast<std::uint32_t>(ops_.size());
    op_.err_start = e_start;
    op_.created.clear();
    op_.killed.clear();
    op_.new_vertices.clear();
  }

  void close_op() {
    Op op;
    op.id = OpId(op_.index);
    op.error = op_.err_start;

    scr_.frag.clear();
    for (std::uint32_t id : op_.created) {
      if (tris_[id].alive) scr_.frag.push_back(id);
    }
    for (std::uint32_t i = 0; i < scr_.frag.size(); ++i) tris_[scr_.frag[i]].local = i;

    // Vertices: V(R) first, in insertion order, then the others by id (their positions from the
    // CGAL vertices and the DEM, both in cache, rather than from verts_).
    scr_.others.clear();
    for (std::uint32_t id : scr_.frag) {
      const BuildTri& t = tris_[id];
      for (int k = 0; k < 3; ++k) scr_.others.push_back({t.v[k], t.face->vertex(k)});
    }
    std::sort(scr_.others.begin(), scr_.others.end(),
              [](const VertexRef& a, const VertexRef& b) { return a.id < b.id; });
    scr_.others.erase(
        std::unique(scr_.others.begin(), scr_.others.end(),
                    [](const VertexRef& a, const VertexRef& b) { return a.id == b.id; }),
        scr_.others.end());
    op.new_vertex_count = static_cast<std::uint32_t>(op_.new_vertices.size());
    op.vertices.reserve(scr_.others.size());
    for (std::uint32_t v : op_.new_vertices) {
      scr_.local_of[v] = static_cast<std::uint32_t>(op.vertices.size());
      op.vertices.push_back({VertexId(v), world(verts_[v])});
    }
    std::sort(op_.new_vertices.begin(), op_.new_vertices.end());
    for (const VertexRef& r : scr_.others) {
      if (std::binary_search(op_.new_vertices.begin(), op_.new_vertices.end(), r.id)) continue;
      scr_.local_of[r.id] = static_cast<std::uint32_t>(op.vertices.size());
      op.vertices.push_back({VertexId(r.id), world(r.vh->point())});
    }

    // PreF in (creator, index) order, with pre_tris (the creator's corners, same rotation, as
    // indices into this op's vertices: every PreF corner is a vertex of F), parents (the distinct
    // creators, so sorted and unique) and the edges of PreF triangles for the coarser links.
    // link_dag would derive the same from the parents' records; the builder has them at hand.
    scr_.killed.clear();
    for (std::uint32_t id : op_.killed) {
      const BuildTri& t = tris_[id];
      scr_.killed.push_back({(std::uint64_t(t.op) << 32) | t.local, id});
    }
    std::sort(scr_.killed.begin(), scr_.killed.end(),
              [](const Killed& a, const Killed& b) { return a.key < b.key; });
    scr_.pre_edges.clear();
    scr_.parents.clear();
    op.pre.reserve(scr_.killed.size());
    op.pre_tris.reserve(scr_.killed.size());
    for (const Killed& kd : scr_.killed) {
      const BuildTri& t = tris_[kd.id];
      op.pre.push_back({OpId(t.op), t.local});
      PreTriangle pt;
      for (int k = 0; k < 3; ++k) {
        pt.v[k] = scr_.local_of[t.v[k]];
        if (pt.v[k] >= op.vertices.size() || op.vertices[pt.v[k]].id.value != t.v[k]) {
          throw_internal("greedy TIN: a PreF corner is not a vertex of F");
        }
      }
      if (t.is_void) pt.flags |= FragmentTriangle::kVoid;
      op.pre_tris.push_back(pt);
      if (scr_.parents.empty() || scr_.parents.back() != t.op) {
        scr_.parents.push_back(t.op);
        ++child_count_[t.op];  // each parent gets one child entry per op: sized once at the end
      }
      for (std::uint8_t k = 0; k < 3; ++k) {
        scr_.pre_edges.push_back({edge_key(t.v[k], t.v[(k + 1) % 3]), kd.id, k});
      }
    }
    op.parents.reserve(scr_.parents.size());
    for (std::uint32_t p : scr_.parents) op.parents.push_back(OpId(p));
    child_count_.push_back(0);
    std::sort(scr_.pre_edges.begin(), scr_.pre_edges.end(),
              [](const PreEdge& a, const PreEdge& b) { return a.key < b.key; });

    scr_.coarser.clear();
    op.fragment.resize(scr_.frag.size());
    for (std::uint32_t i = 0; i < scr_.frag.size(); ++i) {
      const BuildTri& t = tris_[scr_.frag[i]];
      FragmentTriangle& ft = op.fragment[i];
      t.face->info().local = i;
      for (int k = 0; k < 3; ++k) ft.v[k] = scr_.local_of[t.v[k]];
      if (t.is_void) ft.flags |= FragmentTriangle::kVoid;
      for (std::uint8_t k = 0; k < 3; ++k) {
        // Our edge k joins v[k], v[k+1]: CGAL's edge opposite vertex k+2.
        const FaceHandle nf = t.face->neighbor((k + 2) % 3);
        const FaceInfo& n = nf->info();
        if (n.id == kNone) continue;      // infinite face: model boundary, no coarser version
        if (n.op == op_.index) continue;  // inside the fragment
        // Fragment boundary edge. Its versions are the fragments of the triangles that have had
        // it on either side; the closest coarser one is the newer of the replaced triangle inside
        // (from PreF) and the surviving triangle outside.
        const std::uint64_t key = edge_key(t.v[k], t.v[(k + 1) % 3]);
        auto it = std::lower_bound(scr_.pre_edges.begin(), scr_.pre_edges.end(), key,
                                   [](const PreEdge& e, std::uint64_t kk) { return e.key < kk; });
        if (it == scr_.pre_edges.end() || it->key != key) {
          throw_internal("greedy TIN: fragment boundary edge without a replaced triangle");
        }
        const BuildTri& inside = tris_[it->tri];
        if (n.op > inside.op) {
          // The neighbour's edge is the one opposite its vertex facing t: CGAL's edge j is our
          // edge j + 1 (vertex order is fixed at creation; faces are never flipped here).
          const auto edge = static_cast<std::uint8_t>((nf->index(t.face) + 1) % 3);
          scr_.coarser.push_back({i, k, EdgeRef{TriRef{OpId(n.op), n.local}, edge}});
        } else {
          scr_.coarser.push_back({i, k, EdgeRef{TriRef{OpId(inside.op), inside.local}, it->edge}});
        }
      }
    }
    op.coarser.assign(scr_.coarser.begin(), scr_.coarser.end());
    // The bounds from the op's own record, as link_dag computes them (and smr/db recomputes
    // them), while that record is in cache.
    compute_op_bounds(op);
    ops_.push_back(std::move(op));

    // The dead are no longer referenced: recycle their records.
    for (std::uint32_t id : op_.killed) free_tris_.push_back(id);
    for (std::uint32_t id : op_.created) {
      if (!tris_[id].alive) free_tris_.push_back(id);
    }
  }

  static std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
    return (std::uint64_t(std::min(a, b)) << 32) | std::max(a, b);
  }

  void report_progress() {
    double f = 0.0;
    if (err0_ > stop_error_ && !heap_.empty()) {
      const double e = std::max(top_err(), stop_error_);
      f = std::log(err0_ / e) / std::log(err0_ / std::max(stop_error_, err0_ * 1e-6));
    }
    if (opt_.max_vertices != 0) f = std::max(f, double(verts_.size()) / double(opt_.max_vertices));
    f = std::max(f, double(verts_.size()) / double(valid_samples_));
    opt_.progress(std::clamp(f, 0.0, 0.999));
  }

  Crmr finish(double err0, double err_final) {
    Crmr crmr;
    CrmrInfo& info = crmr.header;
    info.kind = ModelKind::kTerrain;
    info.georef = dem_.georef;
    info.grid_width = dem_.width;
    info.grid_height = dem_.height;
    info.err0 = err0;
    info.err_final = std::min(err_final, err0);
    info.source = dem_.source;
    info.builder = "greedy-delaunay max_error=" + std::to_string(opt_.max_error) +
                   " max_vertices=" + std::to_string(opt_.max_vertices) +
                   " base_vertices=" + std::to_string(opt_.base_vertices);
    info.vertex_count = verts_.size();
    for (const BuildVertex& v : verts_) info.bounds.add(world(v));
    // Free the builder's state before link_dag allocates.
    dt_.clear();
    release(tris_);
    release(heap_);
    release(verts_);
    release(free_tris_);
    release(scr_.local_of.map);
    release(scr_.pre_edges);
    release(scr_.killed);
    ops_.move_to(crmr.ops);
    crmr.ops[0].error = err0;
    for (std::size_t i = 0; i < crmr.ops.size(); ++i) crmr.ops[i].children.reserve(child_count_[i]);
    release(child_count_);
    // What link_dag would add to the ops closed above (pre_tris, parents, bounds are set): the
    // birth resolutions, each replaced triangle's killer and death_res, children (in op order,
    // so sorted) and the ROIs.
    for (Op& op : crmr.ops) {
      op.birth_res = op.id == kBaseOp ? 0.0 : resolution_of(info, op.error);
      for (const TriRef& t : op.pre) {
        FragmentTriangle& tri = crmr.ops[t.op.value].fragment[t.index];
        tri.killer = op.id;
        tri.death_res = op.birth_res;
      }
      for (OpId p : op.parents) crmr.ops[p.value].children.push_back(op.id);
    }
    compute_rois(crmr);
    if (opt_.progress) opt_.progress(1.0);
    return crmr;
  }

  template <class T>
  static void release(std::vector<T>& v) {
    std::vector<T>().swap(v);
  }

  struct PreEdge {
    std::uint64_t key;
    std::uint32_t tri;
    std::uint8_t edge;
  };

  // Prefetch limits (samples): a star's triangles whose box exceeds them are not prefetched as a
  // whole; a scan prefetches kLookaheadRows ahead (4 beat 8 and none, benchmarks/README.md).
  static constexpr std::int64_t kPrefetchRows = 128, kPrefetchCols = 128, kLookaheadRows = 4;

  const Heightfield& dem_;
  const GreedyTinOptions& opt_;
  const bool mesh_only_;
  const double tol_;
  double stop_error_ = 0.0;
  double err0_ = 0.0;
  float fill_z_ = 0.0f;
  std::size_t valid_samples_ = 0;
  Dt dt_;
  std::vector<BuildVertex> verts_;
  std::vector<BuildTri> tris_;
  std::vector<std::uint32_t> free_tris_;  // recycled slots of tris_
  std::uint32_t next_seq_ = 0;
  std::vector<HeapEntry> heap_;
  OpStore ops_;
  std::vector<std::uint32_t> child_count_;  // per op: how many later ops replace its triangles
  // The op being made (Brown 4.4.1: PreF = the triangles it kills, F = the ones it creates).
  struct CurrentOp {
    std::uint32_t index = 0;
    double err_start = 0.0;
    std::vector<std::uint32_t> created, killed, new_vertices;
  } op_;
  // Scratch, reused by every op.
  struct VertexRef {
    std::uint32_t id;
    Dt::Vertex_handle vh;
  };
  struct Killed {
    std::uint64_t key;  // (creating op, index in its fragment)
    std::uint32_t id;
  };
  struct LocalMap {
    std::vector<std::uint32_t> map;
    std::uint32_t& operator[](std::uint32_t v) {
      if (v >= map.size()) map.resize(std::max<std::size_t>(v + 1, map.size() * 2), kNone);
      return map[v];
    }
  };
  struct Scratch {
    std::vector<std::uint32_t> frag, parents;
    std::vector<Killed> killed;
    std::vector<VertexRef> others;
    std::vector<PreEdge> pre_edges;
    std::vector<CoarserLink> coarser;
    std::vector<FaceHandle> conflicts, star;
    std::vector<Dt::Edge> boundary;
    LocalMap local_of;
  } scr_;
};

}  // namespace

double exact_tolerance(const Heightfield& dem) {
  float zmax = 0.0f;
  for (float z : dem.z) zmax = std::max(zmax, std::abs(z));
  return 1e-9 * std::max(1.0, double(zmax));
}

Crmr build_greedy_tin(const Heightfield& dem, const GreedyTinOptions& options) {
  return Builder(dem, options).run();
}

GreedyMesh build_greedy_mesh(const Heightfield& dem, const GreedyTinOptions& options) {
  return Builder(dem, options, true).run_mesh();
}

}  // namespace smr
