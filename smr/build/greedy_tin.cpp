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
#include "smr/build/greedy_tin.h"

#include <CGAL/Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>
#include <string>
#include <vector>

#include <glm/geometric.hpp>

#include "storage/error.h"

namespace smr {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_2<std::uint32_t, K>;
using Fb = CGAL::Triangulation_face_base_with_info_2<std::uint32_t, K>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
using Dt = CGAL::Delaunay_triangulation_2<K, Tds>;
using FaceHandle = Dt::Face_handle;
using Point = K::Point_2;

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
constexpr double kMixed = std::numeric_limits<double>::infinity();

struct BuildVertex {
  std::uint32_t col, row;
  Vec3 world;
};

struct BuildTri {
  FaceHandle face;
  std::array<std::uint32_t, 3> v{};  // build vertex ids, counter-clockwise
  std::uint32_t op = 0;              // creating op
  std::uint32_t local = kNone;       // index in the op's fragment, once the op is closed
  std::uint32_t cand = kNone;        // sample to insert next (max error, or a no-data fix)
  double err = 0.0;                  // max vertical error; kMixed when it must be split
  bool alive = true;
  bool is_void = false;
};

std::int64_t floor_div(std::int64_t n, std::int64_t d) {  // d > 0
  std::int64_t q = n / d;
  if ((n % d != 0) && (n < 0)) --q;
  return q;
}
std::int64_t ceil_div(std::int64_t n, std::int64_t d) {
  return -floor_div(-n, d);
}

class Builder {
 public:
  Builder(const Heightfield& dem, const GreedyTinOptions& options)
      : dem_(dem), opt_(options), tol_(exact_tolerance(dem)) {
    if (dem.width < 2 || dem.height < 2) {
      throw_input(dem.source + ": a DEM needs at least 2x2 samples, got " +
                  std::to_string(dem.width) + "x" + std::to_string(dem.height));
    }
    if (static_cast<std::size_t>(dem.width) * dem.height != dem.z.size() ||
        (!dem.valid.empty() && dem.valid.size() != dem.z.size())) {
      throw_internal(dem.source + ": heightfield arrays do not match its size");
    }
    fill_z_ = std::numeric_limits<float>::infinity();
    std::size_t valid = 0;
    for (std::size_t i = 0; i < dem.z.size(); ++i) {
      if (dem.valid.empty() || dem.valid[i] != 0) {
        fill_z_ = std::min(fill_z_, dem.z[i]);
        ++valid;
      }
    }
    if (valid == 0) throw_input(dem.source + ": every sample is no data");
    valid_samples_ = valid;
    stop_error_ = std::max(opt_.max_error, tol_);
  }

  Crmr run() {
    const std::uint32_t w = dem_.width - 1, h = dem_.height - 1;
    // R^0: the corner triangulation, refined until holes are exact (and to base_vertices).
    begin_op(kMixed);
    for (auto [c, r] : {std::pair{0u, 0u}, {w, 0u}, {w, h}, {0u, h}}) add_vertex(c, r);
    for (std::uint32_t i = 0; i < 4; ++i) {
      Dt::Vertex_handle vh = dt_.insert(Point(verts_[i].col, verts_[i].row));
      vh->info() = i;
    }
    for (auto f = dt_.all_faces_begin(); f != dt_.all_faces_end(); ++f) {
      if (dt_.is_infinite(f)) {
        f->info() = kNone;
      } else {
        new_tri(f);
      }
    }
    while (!heap_empty() && (top_err() == kMixed || verts_.size() < opt_.base_vertices)) {
      insert_top();
    }
    const double err0 = heap_empty() ? 0.0 : top_err();
    close_op();
    err0_ = err0;

    // R^1..R^m: one op per insertion, coalesced while the mesh error exceeds its start.
    std::size_t steps = 0;
    while (!heap_empty() && top_err() > stop_error_) {
      if (opt_.max_vertices != 0 && verts_.size() >= opt_.max_vertices) break;
      const double e_start = top_err();
      begin_op(e_start);
      insert_top();
      while (!heap_empty() && top_err() > e_start) insert_top();
      close_op();
      if (opt_.progress && (++steps & 0xfff) == 0) report_progress();
    }
    // The finest mesh's error: the largest error of any surviving triangle (those under the stop
    // tolerance never enter the queue, so scan them all).
    double err_final = 0.0;
    for (const BuildTri& t : tris_) {
      if (t.alive) err_final = std::max(err_final, t.err);
    }
    return finish(err0, err_final);
  }

 private:
  // ---- vertices and samples ----
  std::uint32_t add_vertex(std::uint32_t col, std::uint32_t row) {
    Vec3 p{dem_.georef.x0 + col * dem_.georef.dx, dem_.georef.y0 + row * dem_.georef.dy,
           has_data(col, row) ? double(dem_.at(col, row)) : double(fill_z_)};
    verts_.push_back({col, row, p});
    op_new_vertices_.push_back(static_cast<std::uint32_t>(verts_.size() - 1));
    return static_cast<std::uint32_t>(verts_.size() - 1);
  }
  bool has_data(std::uint32_t col, std::uint32_t row) const {
    return dem_.valid.empty() || dem_.valid[dem_.index(col, row)] != 0;
  }

  // ---- the priority queue of triangles by error (lazy deletion) ----
  void push(std::uint32_t t) {
    if (tris_[t].err > stop_error_ || (tris_[t].err == kMixed)) heap_.push({tris_[t].err, t});
  }
  void pop_dead() {
    while (!heap_.empty() && !tris_[heap_.top().second].alive) heap_.pop();
  }
  bool heap_empty() {
    pop_dead();
    return heap_.empty();
  }
  double top_err() {
    pop_dead();
    return heap_.top().first;
  }

  // ---- triangles ----
  void new_tri(FaceHandle f) {
    BuildTri t;
    t.face = f;
    for (int i = 0; i < 3; ++i) t.v[i] = f->vertex(i)->info();
    t.op = current_op_;
    const auto id = static_cast<std::uint32_t>(tris_.size());
    f->info() = id;
    tris_.push_back(t);
    op_created_.push_back(id);
    scan(tris_.back());
    push(id);
  }

  // Computes err and cand of t from every grid sample in the closed triangle.
  void scan(BuildTri& t) {
    const BuildVertex* p[3] = {&verts_[t.v[0]], &verts_[t.v[1]], &verts_[t.v[2]]};
    t.is_void = !(has_data(p[0]->col, p[0]->row) && has_data(p[1]->col, p[1]->row) &&
                  has_data(p[2]->col, p[2]->row));
    const std::int64_t x[3] = {p[0]->col, p[1]->col, p[2]->col};
    const std::int64_t y[3] = {p[0]->row, p[1]->row, p[2]->row};
    const double z[3] = {p[0]->world.z, p[1]->world.z, p[2]->world.z};
    // Plane z = a*x + b*y + c through the three vertices (in grid units).
    const double det = double((x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]));
    const double a =
        ((z[1] - z[0]) * double(y[2] - y[0]) - (z[2] - z[0]) * double(y[1] - y[0])) / det;
    const double b =
        ((z[2] - z[0]) * double(x[1] - x[0]) - (z[1] - z[0]) * double(x[2] - x[0])) / det;
    const double c = z[0] - a * double(x[0]) - b * double(y[0]);
    const double cx = double(x[0] + x[1] + x[2]) / 3.0, cy = double(y[0] + y[1] + y[2]) / 3.0;

    const std::int64_t ymin = std::min({y[0], y[1], y[2]}), ymax = std::max({y[0], y[1], y[2]});
    double best = 0.0;
    std::uint32_t cand = kNone;
    bool mixed = false;
    double mixed_d2 = std::numeric_limits<double>::infinity();
    const bool nodata = dem_.has_nodata();
    const float* zs = dem_.z.data();
    const std::uint8_t* valid = nodata ? dem_.valid.data() : nullptr;
    for (std::int64_t row = ymin; row <= ymax; ++row) {
      std::int64_t xl = std::numeric_limits<std::int64_t>::max();
      std::int64_t xr = std::numeric_limits<std::int64_t>::min();
      for (int e = 0; e < 3; ++e) {
        const int f = (e + 1) % 3;
        const std::int64_t ya = y[e], yb = y[f];
        if (ya == yb) {
          if (ya == row) {
            xl = std::min({xl, x[e], x[f]});
            xr = std::max({xr, x[e], x[f]});
          }
          continue;
        }
        if (row < std::min(ya, yb) || row > std::max(ya, yb)) continue;
        // x(row) = x[e] + (row - ya) * (x[f] - x[e]) / (yb - ya), exactly as a rational.
        std::int64_t num = x[e] * (yb - ya) + (row - ya) * (x[f] - x[e]);
        std::int64_t den = yb - ya;
        if (den < 0) {
          num = -num;
          den = -den;
        }
        xl = std::min(xl, ceil_div(num, den));
        xr = std::max(xr, floor_div(num, den));
      }
      if (xl > xr) continue;
      const std::size_t base = static_cast<std::size_t>(row) * dem_.width;
      const double zrow = b * double(row) + c;
      if (!nodata) {
        for (std::int64_t col = xl; col <= xr; ++col) {
          const double e = std::abs(double(zs[base + col]) - (a * double(col) + zrow));
          if (e > best) {
            best = e;
            cand = static_cast<std::uint32_t>(base + col);
          }
        }
        continue;
      }
      for (std::int64_t col = xl; col <= xr; ++col) {
        const bool v = valid[base + col] != 0;
        if (t.is_void) {
          // A void triangle may hold valid samples only at its own vertices.
          if (!v) continue;
          bool is_vertex = false;
          for (int k = 0; k < 3; ++k) is_vertex |= (x[k] == col && y[k] == row);
          if (is_vertex) continue;
        } else if (v) {
          const double e = std::abs(double(zs[base + col]) - (a * double(col) + zrow));
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

  void kill(std::uint32_t id) {
    BuildTri& t = tris_[id];
    t.alive = false;
    if (t.op != current_op_) op_killed_.push_back(id);
  }

  void insert_top() {
    pop_dead();
    const std::uint32_t tid = heap_.top().second;
    heap_.pop();
    const std::uint32_t sample = tris_[tid].cand;
    const auto col = static_cast<std::uint32_t>(sample % dem_.width);
    const auto row = static_cast<std::uint32_t>(sample / dem_.width);
    const Point p(col, row);

    conflicts_.clear();
    boundary_.clear();
    dt_.get_conflicts_and_boundary(p, std::back_inserter(conflicts_), std::back_inserter(boundary_),
                                   tris_[tid].face);
    if (conflicts_.empty()) throw_internal("greedy TIN: empty conflict zone");
    for (FaceHandle f : conflicts_) {
      if (f->info() != kNone) kill(f->info());
    }
    const std::uint32_t vid = add_vertex(col, row);
    Dt::Vertex_handle vh =
        dt_.star_hole(p, boundary_.begin(), boundary_.end(), conflicts_.begin(), conflicts_.end());
    vh->info() = vid;
    Dt::Face_circulator fc = dt_.incident_faces(vh), done = fc;
    do {
      if (dt_.is_infinite(fc)) {
        fc->info() = kNone;
      } else {
        new_tri(fc);
      }
    } while (++fc != done);
  }

  // ---- ops ----
  void begin_op(double e_start) {
    current_op_ = static_cast<std::uint32_t>(crmr_.ops.size());
    op_err_start_ = e_start;
    op_created_.clear();
    op_killed_.clear();
    op_new_vertices_.clear();
  }

  void close_op() {
    Op op;
    op.id = OpId(current_op_);
    op.error = op_err_start_;

    std::vector<std::uint32_t> frag;
    for (std::uint32_t id : op_created_) {
      if (tris_[id].alive) frag.push_back(id);
    }
    for (std::uint32_t i = 0; i < frag.size(); ++i) tris_[frag[i]].local = i;

    // Vertices: V(R) first, in insertion order, then the others by id.
    std::vector<std::uint32_t> others;
    for (std::uint32_t id : frag) {
      for (std::uint32_t v : tris_[id].v) others.push_back(v);
    }
    std::sort(others.begin(), others.end());
    others.erase(std::unique(others.begin(), others.end()), others.end());
    std::vector<std::uint32_t> order = op_new_vertices_;
    std::sort(op_new_vertices_.begin(), op_new_vertices_.end());
    for (std::uint32_t v : others) {
      if (!std::binary_search(op_new_vertices_.begin(), op_new_vertices_.end(), v))
        order.push_back(v);
    }
    op.new_vertex_count = static_cast<std::uint32_t>(op_new_vertices_.size());
    for (std::uint32_t v : order) {
      local_of_[v] = static_cast<std::uint32_t>(op.vertices.size());
      op.vertices.push_back({VertexId(v), verts_[v].world});
    }

    // PreF, and the edges of PreF triangles for the coarser links.
    std::sort(op_killed_.begin(), op_killed_.end(), [&](std::uint32_t a, std::uint32_t b) {
      return std::pair(tris_[a].op, tris_[a].local) < std::pair(tris_[b].op, tris_[b].local);
    });
    pre_edges_.clear();
    for (std::uint32_t id : op_killed_) {
      const BuildTri& t = tris_[id];
      op.pre.push_back({OpId(t.op), t.local});
      for (std::uint8_t k = 0; k < 3; ++k) {
        pre_edges_.push_back({edge_key(t.v[k], t.v[(k + 1) % 3]), id, k});
      }
    }
    std::sort(pre_edges_.begin(), pre_edges_.end(),
              [](const PreEdge& a, const PreEdge& b) { return a.key < b.key; });

    std::vector<Vec3> points, normals;
    for (std::uint32_t i = 0; i < frag.size(); ++i) {
      const BuildTri& t = tris_[frag[i]];
      FragmentTriangle ft;
      for (int k = 0; k < 3; ++k) ft.v[k] = local_of_[t.v[k]];
      if (t.is_void) ft.flags |= FragmentTriangle::kVoid;
      for (std::uint8_t k = 0; k < 3; ++k) {
        // Our edge k joins v[k], v[k+1]: CGAL's edge opposite vertex k+2.
        FaceHandle nf = t.face->neighbor((k + 2) % 3);
        if (dt_.is_infinite(nf)) continue;  // model boundary: no coarser version
        const BuildTri& n = tris_[nf->info()];
        if (n.op == current_op_) {
          ft.nbr[k] = static_cast<std::int32_t>(n.local);
          continue;
        }
        // Fragment boundary edge. Its versions are the fragments of the triangles that have had
        // it on either side; the closest coarser one is the newer of the replaced triangle inside
        // (from PreF) and the surviving triangle outside.
        const std::uint64_t key = edge_key(t.v[k], t.v[(k + 1) % 3]);
        auto it = std::lower_bound(pre_edges_.begin(), pre_edges_.end(), key,
                                   [](const PreEdge& e, std::uint64_t kk) { return e.key < kk; });
        if (it == pre_edges_.end() || it->key != key) {
          throw_internal("greedy TIN: fragment boundary edge without a replaced triangle");
        }
        const BuildTri& inside = tris_[it->tri];
        const bool use_outside = n.op > inside.op;
        const BuildTri& target = use_outside ? n : inside;
        const std::uint8_t target_edge =
            use_outside ? edge_index(n, t.v[k], t.v[(k + 1) % 3]) : it->edge;
        op.coarser.push_back({i, k, EdgeRef{TriRef{OpId(target.op), target.local}, target_edge}});
      }
      op.fragment.push_back(ft);
      add_geometry(t, points, normals);
    }
    for (std::uint32_t id : op_killed_) add_geometry(tris_[id], points, normals);
    op.sphere = bounding_sphere(points);
    op.box = Box3{};
    for (const Vec3& p : points) op.box.add(p);
    op.cone = normal_cone(normals);
    crmr_.ops.push_back(std::move(op));
  }

  void add_geometry(const BuildTri& t, std::vector<Vec3>& points,
                    std::vector<Vec3>& normals) const {
    const Vec3& a = verts_[t.v[0]].world;
    const Vec3& b = verts_[t.v[1]].world;
    const Vec3& c = verts_[t.v[2]].world;
    points.insert(points.end(), {a, b, c});
    normals.push_back(triangle_normal(a, b, c));
  }

  static std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
    return (std::uint64_t(std::min(a, b)) << 32) | std::max(a, b);
  }
  static std::uint8_t edge_index(const BuildTri& t, std::uint32_t a, std::uint32_t b) {
    for (std::uint8_t k = 0; k < 3; ++k) {
      const std::uint32_t p = t.v[k], q = t.v[(k + 1) % 3];
      if ((p == a && q == b) || (p == b && q == a)) return k;
    }
    throw_internal("greedy TIN: neighbour does not share the edge");
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
    CrmrInfo& info = crmr_.header;
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
    for (const BuildVertex& v : verts_) info.bounds.add(v.world);
    for (Op& op : crmr_.ops) op.birth_res = op.id == kBaseOp ? 0.0 : resolution_of(info, op.error);
    crmr_.ops[0].error = err0;
    link_dag(crmr_);
    if (opt_.progress) opt_.progress(1.0);
    return std::move(crmr_);
  }

  struct PreEdge {
    std::uint64_t key;
    std::uint32_t tri;
    std::uint8_t edge;
  };

  const Heightfield& dem_;
  const GreedyTinOptions& opt_;
  const double tol_;
  double stop_error_ = 0.0;
  double err0_ = 0.0;
  float fill_z_ = 0.0f;
  std::size_t valid_samples_ = 0;
  Dt dt_;
  std::vector<BuildVertex> verts_;
  std::vector<BuildTri> tris_;
  std::priority_queue<std::pair<double, std::uint32_t>> heap_;
  Crmr crmr_;
  std::uint32_t current_op_ = 0;
  double op_err_start_ = 0.0;
  std::vector<std::uint32_t> op_created_, op_killed_, op_new_vertices_;
  std::vector<PreEdge> pre_edges_;
  std::vector<FaceHandle> conflicts_;
  std::vector<Dt::Edge> boundary_;
  struct LocalMap {
    std::vector<std::uint32_t> map;
    std::uint32_t& operator[](std::uint32_t v) {
      if (v >= map.size()) map.resize(std::max<std::size_t>(v + 1, map.size() * 2), kNone);
      return map[v];
    }
  } local_of_;
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

}  // namespace smr
