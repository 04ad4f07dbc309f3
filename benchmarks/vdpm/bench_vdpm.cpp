// bench_vdpm: view-dependent output size against OpenMesh's VDPM (Kim & Lee, "Truly selective
// refinement of progressive meshes", GI 2001, with Hoppe 1997's refinement criteria), issue 4.
//
// For one mesh and the .spm vertex hierarchy that OpenMesh-mkbalancedpm + OpenMesh-Analyzer built
// from the same file, and for every camera x tolerance tau (pixels):
//   ours  smr::read_mesh -> smr::build_qem_pm -> smr::extract_minimal_surface with
//         RcfSpec{camera, pixel_error = tau} (frustum and back-face culling on; also counted off)
//   VDPM  the .spm loaded into OpenMesh's VDPM classes (VHierarchy, VFront, ViewingParameters) and
//         refined exactly the way OpenMesh's Synthesizer (Apps/VDProgMesh/Synthesizer,
//         adaptive_refinement) does, pass after pass until a pass changes nothing: per active node,
//         force_vsplit when qrefine(node), else ecol when legal and !qrefine(parent). qrefine is
//         false when the node's sphere is outside the frustum, its normal cone faces away, or
//         mu^2 < kappa^2 d^2 and sigma^2 (d^2 - (n.(v-e))^2) < kappa^2 d^4 (Hoppe 97's screen-space
//         test), with kappa^2 = 4 tan^2(fovy/2) tolerance_square.
// Both outputs are measured the same way (measure_output_to_source / measure_source_to_output).
//
// Conventions worked out from OpenMesh 9.0's sources (the Debian package ships the library, not
// the apps' sources):
//  - tolerance_square is (tau / viewport_h)^2: mu * focal_px / d < tau <=> mu / d < 2 tan(fovy/2)
//    tau / viewport_h = kappa, i.e. the same "error x focal / distance" bound as smr/rcf/rcf.cpp
//    (which takes the distance to the op's box, VDPM the distance to the node's vertex).
//  - ViewingParameters::update_viewing_configurations computes the frustum normals with
//    sin/cos(fovy / 2) and fovy in radians, but its bottom and top normals carry the wrong sign for
//    0 < fovy < pi (they point out of the frustum). The Qt viewer passes fovy = 45 (degrees),
//    where sin(22.5 rad) < 0 happens to flip them back, giving a vertical half-angle of 29.4 deg
//    instead of 22.5 and tan(22.5 rad) = 0.56 instead of tan(22.5 deg) = 0.41 in kappa. We pass
//    fovy = fov + 2 pi (radians): half-angle + pi flips sin and cos, so all four planes and
//    tan(fovy / 2) come out exactly right. The planes are checked against smr::Camera::planes()
//    and the largest deviation is reported (frustum_plane_check).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <numeric>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include <CLI/CLI.hpp>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/VDPM/MeshTraits.hh>
#include <OpenMesh/Tools/VDPM/VFront.hh>
#include <OpenMesh/Tools/VDPM/VHierarchy.hh>
#include <OpenMesh/Tools/VDPM/ViewingParameters.hh>
#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "benchmarks/bench_common.h"
#include "smr/builders/mesh/qem_pm.h"
#include "smr/extract/extract.h"
#include "smr/io/mesh_reader.h"
#include "smr/rcf/spec.h"

namespace {

using nlohmann::json;
using smr::Triangle3;
using smr::Vec3;
using smr::bench::median;
using smr::bench::now_ns;
using smr::bench::seconds_since;

// ---- exact point-to-triangle-soup distance ------------------------------------------------------

// Closest point of the closed triangle abc to p (Ericson, Real-Time Collision Detection 5.1.5:
// Voronoi regions of the vertices, then of the edges, else the face).
Vec3 closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Vec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + ab * (d1 / (d1 - d3));
  const Vec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0)
    return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = va + vb + vc;
  if (!(std::abs(denom) > 0.0)) {  // zero-area triangle: the nearest of its three edges
    auto seg = [&](const Vec3& s, const Vec3& t) {
      const Vec3 st = t - s;
      const double l2 = glm::dot(st, st);
      const double u = l2 > 0.0 ? std::clamp(glm::dot(p - s, st) / l2, 0.0, 1.0) : 0.0;
      return s + st * u;
    };
    const std::array<Vec3, 3> q{seg(a, b), seg(b, c), seg(c, a)};
    return *std::min_element(q.begin(), q.end(), [&](const Vec3& x, const Vec3& y) {
      return glm::dot(x - p, x - p) < glm::dot(y - p, y - p);
    });
  }
  const double v = vb / denom, w = vc / denom;
  return a + ab * v + ac * w;
}

// Uniform grid of buckets over a triangle soup: each triangle is listed in every bucket its box
// meets. A query visits shells of buckets around the query's bucket and stops once no unvisited
// bucket can hold a nearer triangle, so the answer is the minimum over all triangles.
class SoupDistance {
 public:
  explicit SoupDistance(std::vector<Triangle3> tris) : tris_(std::move(tris)) {
    for (const Triangle3& t : tris_)
      for (const Vec3& p : t) box_.add(p);
    if (tris_.empty()) return;
    const Vec3 ext = glm::max(box_.hi - box_.lo, Vec3(1e-12));
    const double diag = glm::length(ext);
    box_.lo -= Vec3(1e-9 * diag);
    box_.hi += Vec3(1e-9 * diag);
    const Vec3 e = box_.hi - box_.lo;
    // About one bucket per triangle, never thinner than 1/256 of the diagonal.
    const double volume =
        std::max(e.x, diag / 256) * std::max(e.y, diag / 256) * std::max(e.z, diag / 256);
    cell_ = std::max(std::cbrt(volume / double(tris_.size())), diag / 256);
    for (int i = 0; i < 3; ++i)
      dims_[i] = std::clamp<std::int64_t>(std::int64_t(std::ceil(e[i] / cell_)), 1, 512);
    const std::size_t n = std::size_t(dims_[0] * dims_[1] * dims_[2]);
    std::vector<std::uint32_t> count(n + 1, 0);
    auto for_cells = [&](const Triangle3& t, auto&& f) {
      smr::Box3 b;
      for (const Vec3& p : t) b.add(p);
      const auto lo = cell_of(b.lo), hi = cell_of(b.hi);
      for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
        for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
          for (std::int64_t x = lo[0]; x <= hi[0]; ++x) f(index(x, y, z));
    };
    for (const Triangle3& t : tris_) for_cells(t, [&](std::size_t c) { ++count[c + 1]; });
    std::partial_sum(count.begin(), count.end(), count.begin());
    start_ = count;
    items_.resize(count.back());
    for (std::uint32_t i = 0; i < tris_.size(); ++i)
      for_cells(tris_[i], [&](std::size_t c) { items_[count[c]++] = i; });
    stamp_.assign(tris_.size(), 0);
  }

  bool empty() const { return tris_.empty(); }

  /// min over triangles of the distance from p to the closed triangle.
  double distance(const Vec3& p) const {
    if (tris_.empty()) return std::numeric_limits<double>::infinity();
    ++query_;
    const auto c = cell_of(p);
    double best2 = std::numeric_limits<double>::infinity();
    for (std::int64_t k = 0;; ++k) {
      // The shell of buckets at Chebyshev distance exactly k from c.
      for (std::int64_t dz = -k; dz <= k; ++dz) {
        const std::int64_t z = c[2] + dz;
        if (z < 0 || z >= dims_[2]) continue;
        for (std::int64_t dy = -k; dy <= k; ++dy) {
          const std::int64_t y = c[1] + dy;
          if (y < 0 || y >= dims_[1]) continue;
          const bool face = std::abs(dz) == k || std::abs(dy) == k;
          for (std::int64_t dx = -k; dx <= k; dx += face ? 1 : std::max<std::int64_t>(2 * k, 1)) {
            const std::int64_t x = c[0] + dx;
            if (x < 0 || x >= dims_[0]) continue;
            const std::size_t b = index(x, y, z);
            for (std::uint32_t j = start_[b]; j < start_[b + 1]; ++j) {
              const std::uint32_t i = items_[j];
              if (stamp_[i] == query_) continue;
              stamp_[i] = query_;
              const Triangle3& t = tris_[i];
              const Vec3 q = closest_point_on_triangle(p, t[0], t[1], t[2]);
              best2 = std::min(best2, glm::dot(q - p, q - p));
            }
          }
        }
      }
      // Triangles not seen yet lie outside the block of buckets within k of c (inside the grid),
      // so at least as far from p as the nearest face of that block that is not a grid face.
      double bound = std::numeric_limits<double>::infinity();
      for (int a = 0; a < 3; ++a) {
        if (c[a] - k > 0) bound = std::min(bound, p[a] - (box_.lo[a] + double(c[a] - k) * cell_));
        if (c[a] + k + 1 < dims_[a])
          bound = std::min(bound, (box_.lo[a] + double(c[a] + k + 1) * cell_) - p[a]);
      }
      if (bound == std::numeric_limits<double>::infinity()) break;  // the block is the grid
      if (bound > 0.0 && best2 <= bound * bound) break;
    }
    return std::sqrt(best2);
  }

 private:
  std::array<std::int64_t, 3> cell_of(const Vec3& p) const {
    std::array<std::int64_t, 3> c{};
    for (int i = 0; i < 3; ++i)
      c[i] = std::clamp<std::int64_t>(std::int64_t(std::floor((p[i] - box_.lo[i]) / cell_)), 0,
                                      dims_[i] - 1);
    return c;
  }
  std::size_t index(std::int64_t x, std::int64_t y, std::int64_t z) const {
    return std::size_t((z * dims_[1] + y) * dims_[0] + x);
  }

  std::vector<Triangle3> tris_;
  smr::Box3 box_;
  double cell_ = 1.0;
  std::array<std::int64_t, 3> dims_{1, 1, 1};
  std::vector<std::uint32_t> start_, items_;
  mutable std::vector<std::uint64_t> stamp_;
  mutable std::uint64_t query_ = 0;
};

// ---- the measured screen-space error
// -------------------------------------------------------------

bool inside_frustum(const smr::Camera& cam, const std::array<smr::Plane, 6>& planes,
                    const Vec3& p) {
  if (glm::dot(p - cam.eye, cam.forward()) <= 0.0) return false;
  for (int i = 0; i < 4; ++i)
    if (planes[i].signed_distance(p) < 0.0) return false;
  return true;
}

// A triangle is measured when it is front-facing and not wholly outside one frustum plane; of its
// samples, those inside the frustum count.
bool visible_triangle(const smr::Camera& cam, const std::array<smr::Plane, 6>& planes,
                      const Triangle3& t) {
  const Vec3 n = glm::cross(t[1] - t[0], t[2] - t[0]);
  if (!(glm::dot(n, cam.eye - t[0]) > 0.0)) return false;
  for (int i = 0; i < 5; ++i) {
    if (planes[i].signed_distance(t[0]) < 0 && planes[i].signed_distance(t[1]) < 0 &&
        planes[i].signed_distance(t[2]) < 0)
      return false;
  }
  return true;
}

// Vertices, edge midpoints, centroid and three interior points (barycentric 2/3, 1/6, 1/6).
std::array<Vec3, 10> samples(const Triangle3& t) {
  const Vec3 g = (t[0] + t[1] + t[2]) / 3.0;
  auto in = [&](int i) { return (4.0 * t[i] + t[(i + 1) % 3] + t[(i + 2) % 3]) / 6.0; };
  return {t[0],  t[1],  t[2], 0.5 * (t[0] + t[1]), 0.5 * (t[1] + t[2]), 0.5 * (t[2] + t[0]), g,
          in(0), in(1), in(2)};
}

struct ErrorStats {
  std::uint64_t triangles_measured = 0;
  std::uint64_t samples = 0;
  double max_px = 0.0, p99_px = 0.0, mean_px = 0.0;
  double max_distance = 0.0;  // object space, model units
  json to_json() const {
    return {{"triangles_measured", triangles_measured},
            {"samples", samples},
            {"max_px", max_px},
            {"p99_px", p99_px},
            {"mean_px", mean_px},
            {"max_distance", max_distance}};
  }
};

// Distance in pixels of each sample of each visible triangle of `from` to the surface `to`:
// d x focal_px / depth, depth along the view direction.
ErrorStats measure(const std::vector<Triangle3>& from, const SoupDistance& to,
                   const smr::Camera& cam) {
  ErrorStats s;
  const auto planes = cam.planes();
  const double focal = cam.focal_px();
  const Vec3 fwd = cam.forward();
  std::vector<double> px;
  double sum = 0.0;
  for (const Triangle3& t : from) {
    if (!visible_triangle(cam, planes, t)) continue;
    ++s.triangles_measured;
    for (const Vec3& p : samples(t)) {
      if (!inside_frustum(cam, planes, p)) continue;
      const double d = to.distance(p);
      const double e = d * focal / glm::dot(p - cam.eye, fwd);
      px.push_back(e);
      sum += e;
      s.max_distance = std::max(s.max_distance, d);
    }
  }
  s.samples = px.size();
  if (!px.empty()) {
    const std::size_t k = std::size_t(0.99 * double(px.size() - 1));
    std::nth_element(px.begin(), px.begin() + std::ptrdiff_t(k), px.end());
    s.p99_px = px[k];
    s.max_px = *std::max_element(px.begin(), px.end());
    s.mean_px = sum / double(px.size());
  }
  return s;
}

struct TwoSided {
  ErrorStats to_source;    // output samples -> source surface
  ErrorStats from_source;  // source samples -> output surface
  double max_px() const { return std::max(to_source.max_px, from_source.max_px); }
  double p99_px() const { return std::max(to_source.p99_px, from_source.p99_px); }
  json to_json() const {
    return {{"max_px", max_px()},
            {"p99_px", p99_px()},
            {"output_to_source", to_source.to_json()},
            {"source_to_output", from_source.to_json()}};
  }
};

TwoSided measure_both(const std::vector<Triangle3>& output, const std::vector<Triangle3>& source,
                      const SoupDistance& source_distance, const smr::Camera& cam) {
  TwoSided r;
  r.to_source = measure(output, source_distance, cam);
  const SoupDistance output_distance(output);
  r.from_source = measure(source, output_distance, cam);
  return r;
}

// ---- OpenMesh VDPM, driven the way its Synthesizer does
// ------------------------------------------

namespace VDPM = OpenMesh::VDPM;
using VdpmMesh = OpenMesh::TriMesh_ArrayKernelT<VDPM::MeshTraits>;
using VDPM::VHierarchyNodeHandle;
using VDPM::VHierarchyNodeIndex;

struct AdaptStats {
  int passes = 0;
  bool converged = false;
  std::uint64_t vsplits = 0, forced_vsplits = 0, ecols = 0;
  std::uint64_t unresolved_dependencies = 0;  // force_vsplit found no cut vertex (never expected)
  double seconds = 0.0;
  json to_json() const {
    return {{"passes", passes},   {"converged", converged},
            {"vsplits", vsplits}, {"forced_vsplits", forced_vsplits},
            {"ecols", ecols},     {"unresolved_dependencies", unresolved_dependencies},
            {"seconds", seconds}};
  }
};

class Vdpm {
 public:
  /// Parses an .spm (OpenMesh-Analyzer's "VDProgMesh" format, little-endian) as the Synthesizer's
  /// open_vd_prog_mesh does: base mesh, then per detail the new vertex, the node index of the
  /// split vertex, its fundamental cut indices and the view-dependent parameters (radius, normal,
  /// sin^2 of the normal cone, mu^2, sigma^2) of both children.
  explicit Vdpm(const std::string& bytes) {
    std::size_t at = 0;
    auto need = [&](std::size_t n) {
      if (at + n > bytes.size()) smr::throw_input("truncated .spm file");
    };
    auto u32 = [&] {
      need(4);
      std::uint32_t v;
      std::memcpy(&v, bytes.data() + at, 4);
      at += 4;
      return v;
    };
    auto f32 = [&] {
      need(4);
      float v;
      std::memcpy(&v, bytes.data() + at, 4);
      at += 4;
      return v;
    };
    auto vec = [&] {
      const float x = f32(), y = f32(), z = f32();
      return OpenMesh::Vec3f(x, y, z);
    };
    need(10);
    if (bytes.compare(0, 10, "VDProgMesh") != 0) smr::throw_input("not a VDProgMesh (.spm) file");
    at = 10;
    n_base_vertices_ = u32();
    n_base_faces_ = u32();
    n_details_ = u32();
    vhierarchy_.set_num_roots(n_base_vertices_);
    std::unordered_map<std::uint32_t, VHierarchyNodeHandle> by_index;
    by_index.reserve(n_base_vertices_ + 2 * std::size_t(n_details_));
    VDPM::VHierarchyNodeHandleContainer roots;
    auto set_params = [&](VDPM::VHierarchyNode& node) {
      node.set_radius(f32());
      node.set_normal(vec());
      node.set_sin_square(f32());
      node.set_mue_square(f32());
      node.set_sigma_square(f32());
    };
    for (std::uint32_t i = 0; i < n_base_vertices_; ++i) {
      const OpenMesh::Vec3f p = vec();
      const auto vh = mesh_.add_vertex(p);
      const VHierarchyNodeHandle nh = vhierarchy_.add_node();
      VDPM::VHierarchyNode& node = vhierarchy_.node(nh);
      node.set_index(vhierarchy_.generate_node_index(i, 1));
      node.set_vertex_handle(vh);
      set_params(node);
      mesh_.data(vh).set_vhierarchy_node_handle(nh);
      mesh_.set_normal(vh, node.normal());
      by_index[node.node_index().value()] = nh;
      roots.push_back(nh);
    }
    vfront_.init(roots, n_details_);
    for (std::uint32_t i = 0; i < n_base_faces_; ++i) {
      const std::uint32_t a = u32(), b = u32(), c = u32();
      if (a >= n_base_vertices_ || b >= n_base_vertices_ || c >= n_base_vertices_)
        smr::throw_input(".spm base face refers to a missing vertex");
      if (!mesh_.add_face(mesh_.vertex_handle(a), mesh_.vertex_handle(b), mesh_.vertex_handle(c))
               .is_valid())
        smr::throw_input(".spm base mesh is not manifold");
    }
    for (std::uint32_t i = 0; i < n_details_; ++i) {
      const OpenMesh::Vec3f p = vec();
      const std::uint32_t index = u32();
      const VHierarchyNodeIndex lcut(u32()), rcut(u32());
      const auto it = by_index.find(index);
      if (it == by_index.end()) smr::throw_input(".spm detail refers to an unknown node");
      VHierarchyNodeHandle nh = it->second;
      vhierarchy_.make_children(nh);
      VDPM::VHierarchyNode& node = vhierarchy_.node(nh);
      node.set_fund_lcut(lcut);
      node.set_fund_rcut(rcut);
      VDPM::VHierarchyNode& l = vhierarchy_.node(node.lchild_handle());
      VDPM::VHierarchyNode& r = vhierarchy_.node(node.rchild_handle());
      l.set_vertex_handle(mesh_.add_vertex(p));   // v0, the vertex the split introduces
      r.set_vertex_handle(node.vertex_handle());  // v1 keeps its position (half-edge collapse)
      by_index[l.node_index().value()] = node.lchild_handle();
      by_index[r.node_index().value()] = node.rchild_handle();
      set_params(l);
      set_params(r);
    }
    if (at != bytes.size()) smr::throw_input(".spm has trailing bytes");
    mesh_.update_face_normals();
  }

  std::uint32_t base_vertices() const { return n_base_vertices_; }
  std::uint32_t base_faces() const { return n_base_faces_; }
  std::uint32_t details() const { return n_details_; }

  /// The camera as OpenMesh's ViewingParameters (an OpenGL column-major modelview matrix, fovy,
  /// aspect, tolerance_square), then kappa^2 as the Synthesizer computes it. Returns the largest
  /// difference between OpenMesh's four frustum planes and smr::Camera's (normals and offsets).
  double set_view(const smr::Camera& cam, double tau_px, bool cull) {
    cull_ = cull;
    const Vec3 r = cam.right(), u = cam.true_up(), f = cam.forward();
    const std::array<Vec3, 3> rows{r, u, -f};
    double m[16] = {};
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 3; ++col) m[col * 4 + row] = rows[row][col];
      m[12 + row] = -glm::dot(rows[row], cam.eye);
    }
    m[15] = 1.0;
    vp_.set_modelview_matrix(m);
    vp_.set_aspect(float(double(cam.viewport_w) / double(cam.viewport_h)));
    vp_.set_fovy(float(cam.fov_y_deg * M_PI / 180.0 + 2.0 * M_PI));  // see the file comment
    const double tol = tau_px / double(cam.viewport_h);
    vp_.set_tolerance_square(float(tol * tol));
    vp_.update_viewing_configurations();
    const float t = std::tan(vp_.fovy() / 2.0f);
    kappa_square_ = 4.0f * t * t * vp_.tolerance_square();
    vp_.frustum_planes(planes_);
    // OpenMesh's order: left, bottom, right, top; ours: left, right, bottom, top.
    const auto ours = cam.planes();
    const std::array<int, 4> match{0, 2, 1, 3};
    const double scale = std::max(1.0, glm::length(cam.eye));
    double dev = 0.0;
    for (int i = 0; i < 4; ++i) {
      const smr::Plane& o = ours[std::size_t(match[std::size_t(i)])];
      const Vec3 n(planes_[i].n_[0], planes_[i].n_[1], planes_[i].n_[2]);
      dev = std::max({dev, glm::length(n - o.n), std::abs(double(planes_[i].d_) - o.d) / scale});
    }
    return dev;
  }

  /// The Synthesizer's adaptive_refinement, repeated until a pass makes no split and no collapse
  /// (each pass ends with the Synthesizer's garbage collection of edges and faces).
  AdaptStats adapt(int max_passes) {
    AdaptStats s;
    const std::uint64_t t0 = now_ns();
    for (s.passes = 1; s.passes <= max_passes; ++s.passes) {
      const std::uint64_t before = s.vsplits + s.ecols;
      VdpmMesh::HalfedgeHandle v0v1;
      for (vfront_.begin(); !vfront_.end();) {
        const VHierarchyNodeHandle nh = vfront_.node_handle();
        const VHierarchyNodeHandle parent = vhierarchy_.parent_handle(nh);
        if (!vhierarchy_.is_leaf_node(nh) && qrefine(nh)) {
          force_vsplit(nh, s);
        } else if (!vhierarchy_.is_root_node(nh) && ecol_legal(parent, v0v1) && !qrefine(parent)) {
          ecol(parent, v0v1);
          ++s.ecols;
        } else {
          vfront_.next();
        }
      }
      mesh_.garbage_collection(false, true, true);
      if (s.vsplits + s.ecols == before) {
        s.converged = true;
        break;
      }
    }
    s.passes = std::min(s.passes, max_passes);
    s.seconds = seconds_since(t0);
    return s;
  }

  std::size_t face_count() const { return mesh_.n_faces(); }

  std::vector<Triangle3> triangles() const {
    std::vector<Triangle3> out;
    out.reserve(mesh_.n_faces());
    for (const auto fh : mesh_.faces()) {
      if (mesh_.status(fh).deleted()) continue;
      Triangle3 t;
      int i = 0;
      for (const auto vh : mesh_.fv_range(fh)) {
        const auto& p = mesh_.point(vh);
        if (i < 3) t[std::size_t(i)] = Vec3(p[0], p[1], p[2]);
        ++i;
      }
      if (i == 3) out.push_back(t);
    }
    return out;
  }

 private:
  bool qrefine(VHierarchyNodeHandle nh) {
    VDPM::VHierarchyNode& node = vhierarchy_.node(nh);
    const OpenMesh::Vec3f p = mesh_.point(node.vertex_handle());
    const OpenMesh::Vec3f eye_dir = p - vp_.eye_pos();
    const float distance2 = eye_dir.sqrnorm();
    const float product = OpenMesh::dot(eye_dir, node.normal());
    if (cull_) {
      for (int i = 0; i < 4; ++i)  // outside_view_frustum
        if (planes_[i].signed_distance(p) < -node.radius()) return false;
      if (product > 0.0f && product * product > distance2 * node.sin_square())  // oriented_away
        return false;
    }
    // screen_space_error: refine when mu or the normal-direction term projects above tolerance.
    return node.mue_square() >= kappa_square_ * distance2 ||
           node.sigma_square() * (distance2 - product * product) >=
               kappa_square_ * distance2 * distance2;
  }

  void force_vsplit(VHierarchyNodeHandle nh, AdaptStats& s) {
    VdpmMesh::VertexHandle vl, vr;
    active_cuts(nh, vl, vr);
    while (vl == vr) {
      if (!vl.is_valid()) {  // no active neighbour descends from either cut: cannot split
        ++s.unresolved_dependencies;
        vfront_.next();
        return;
      }
      force_vsplit(mesh_.data(vl).vhierarchy_node_handle(), s);
      ++s.forced_vsplits;
      active_cuts(nh, vl, vr);
    }
    vsplit(nh, vl, vr);
    ++s.vsplits;
  }

  void vsplit(VHierarchyNodeHandle nh, VdpmMesh::VertexHandle vl, VdpmMesh::VertexHandle vr) {
    const VHierarchyNodeHandle lc = vhierarchy_.lchild_handle(nh),
                               rc = vhierarchy_.rchild_handle(nh);
    const auto v0 = vhierarchy_.vertex_handle(lc), v1 = vhierarchy_.vertex_handle(rc);
    mesh_.vertex_split(v0, v1, vl, vr);
    mesh_.set_normal(v0, vhierarchy_.normal(lc));
    mesh_.set_normal(v1, vhierarchy_.normal(rc));
    mesh_.data(v0).set_vhierarchy_node_handle(lc);
    mesh_.data(v1).set_vhierarchy_node_handle(rc);
    mesh_.status(v0).set_deleted(false);
    mesh_.status(v1).set_deleted(false);
    vfront_.remove(nh);
    vfront_.add(lc);
    vfront_.add(rc);
  }

  void ecol(VHierarchyNodeHandle nh, VdpmMesh::HalfedgeHandle v0v1) {
    const VHierarchyNodeHandle lc = vhierarchy_.lchild_handle(nh),
                               rc = vhierarchy_.rchild_handle(nh);
    const auto v0 = vhierarchy_.vertex_handle(lc), v1 = vhierarchy_.vertex_handle(rc);
    mesh_.collapse(v0v1);
    mesh_.set_normal(v1, vhierarchy_.normal(nh));
    mesh_.data(v0).set_vhierarchy_node_handle(lc);
    mesh_.data(v1).set_vhierarchy_node_handle(nh);
    mesh_.status(v0).set_deleted(false);
    mesh_.status(v1).set_deleted(false);
    vfront_.add(nh);
    vfront_.remove(lc);
    vfront_.remove(rc);
  }

  bool ecol_legal(VHierarchyNodeHandle parent, VdpmMesh::HalfedgeHandle& v0v1) {
    const VHierarchyNodeHandle lc = vhierarchy_.lchild_handle(parent),
                               rc = vhierarchy_.rchild_handle(parent);
    if (!vfront_.is_active(lc) || !vfront_.is_active(rc)) return false;
    v0v1 = mesh_.find_halfedge(vhierarchy_.vertex_handle(lc), vhierarchy_.vertex_handle(rc));
    return v0v1.is_valid() && mesh_.is_collapse_ok(v0v1);
  }

  // The active neighbours of the node's vertex that descend from its fundamental cut vertices.
  void active_cuts(VHierarchyNodeHandle nh, VdpmMesh::VertexHandle& vl,
                   VdpmMesh::VertexHandle& vr) {
    const VHierarchyNodeIndex lcut = vhierarchy_.fund_lcut_index(nh),
                              rcut = vhierarchy_.fund_rcut_index(nh);
    vl = VdpmMesh::InvalidVertexHandle;
    vr = VdpmMesh::InvalidVertexHandle;
    for (auto it = mesh_.vv_iter(vhierarchy_.vertex_handle(nh)); it.is_valid(); ++it) {
      const VHierarchyNodeIndex ni =
          vhierarchy_.node_index(mesh_.data(*it).vhierarchy_node_handle());
      if (!vl.is_valid() && vhierarchy_.is_ancestor(ni, lcut)) vl = *it;
      if (!vr.is_valid() && vhierarchy_.is_ancestor(ni, rcut)) vr = *it;
      if (vl.is_valid() && vr.is_valid()) break;
    }
  }

  VdpmMesh mesh_;
  VDPM::VHierarchy vhierarchy_;
  VDPM::VFront vfront_;
  VDPM::ViewingParameters vp_;
  VDPM::Plane3d planes_[4];
  float kappa_square_ = 0.0f;
  bool cull_ = true;
  std::uint32_t n_base_vertices_ = 0, n_base_faces_ = 0, n_details_ = 0;
};

// ---- ours ---------------------------------------------------------------------------------------

std::vector<Triangle3> triangles_of(const smr::TriangleMesh& m) {
  std::vector<Triangle3> out;
  out.reserve(m.triangles.size());
  for (const auto& t : m.triangles)
    out.push_back({m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]});
  return out;
}

struct OurCut {
  std::vector<Triangle3> triangles;
  std::vector<double> assigned_error;  // per triangle: the error its death_res stands for
  std::uint64_t x = 0;
  double extract_seconds = 0.0, expand_seconds = 0.0, total_seconds = 0.0;
};

OurCut extract_ours(const smr::Crmr& crmr, const smr::Camera& cam, double tau, bool cull) {
  smr::RcfSpec spec;
  spec.camera = cam;
  spec.cull = cull;
  spec.pixel_error = tau;
  const smr::Rcf rcf = smr::make_rcf(spec, smr::ModelKind::kMesh3d, nullptr);
  const std::uint64_t t0 = now_ns();
  const smr::Extraction e = smr::extract_minimal_surface(crmr, rcf);
  OurCut c;
  c.total_seconds = seconds_since(t0);
  c.extract_seconds = e.stats.extract_seconds;
  c.expand_seconds = e.stats.expand_seconds;
  c.x = e.stats.x;
  const smr::TriangleMesh m = smr::to_mesh(crmr, e.triangles);
  c.triangles = triangles_of(m);
  for (const float res : m.triangle_values) c.assigned_error.push_back(crmr.error_at(res));
  return c;
}

// How tight our per-triangle errors are: for each visible output triangle with a non-zero
// assigned error (error_at(death_res): the op error the screen-space criterion projects), the
// largest distance of its samples to the source surface divided by that error.
json tightness(const OurCut& cut, const SoupDistance& source, const smr::Camera& cam) {
  const auto planes = cam.planes();
  std::vector<double> ratio;
  for (std::size_t i = 0; i < cut.triangles.size(); ++i) {
    const Triangle3& t = cut.triangles[i];
    if (i >= cut.assigned_error.size() || !(cut.assigned_error[i] > 0.0)) continue;
    if (!visible_triangle(cam, planes, t)) continue;
    double d = 0.0;
    for (const Vec3& p : samples(t)) d = std::max(d, source.distance(p));
    ratio.push_back(d / cut.assigned_error[i]);
  }
  if (ratio.empty()) return {{"triangles", 0}};
  std::sort(ratio.begin(), ratio.end());
  auto q = [&](double f) { return ratio[std::size_t(f * double(ratio.size() - 1))]; };
  return {{"triangles", ratio.size()}, {"median", q(0.5)}, {"p90", q(0.9)}, {"max", ratio.back()}};
}

// Diagnostic for the builder: the same CRMR with each op's error replaced by a local one, the
// largest measured distance to the source of the samples of the triangles it replaces (PreF),
// made monotone over the DAG (an op's error is at least its children's: children have larger
// ids). Sampled, so a lower estimate rather than a guaranteed bound: its cuts show how much of
// our cut size comes from op.error being the largest bound over the whole mesh at the op's time.
smr::Crmr local_error_crmr(const smr::Crmr& crmr, const SoupDistance& source, json& stats) {
  smr::Crmr c = crmr;
  std::vector<double> local(c.ops.size(), 0.0), sat(c.ops.size(), 0.0);
  for (std::size_t i = c.ops.size(); i-- > 1;) {
    const smr::Op& op = c.ops[i];
    for (const smr::PreTriangle& t : op.pre_tris) {
      if (t.is_void()) continue;
      const Triangle3 v = smr::corners(op, t);
      for (const Vec3& p : samples(v)) local[i] = std::max(local[i], source.distance(p));
    }
    sat[i] = local[i];
    for (const smr::OpId ch : op.children) sat[i] = std::max(sat[i], sat[ch.value]);
  }
  std::vector<double> ratio_local, ratio_sat;
  for (std::size_t i = 1; i < c.ops.size(); ++i) {
    smr::Op& op = c.ops[i];
    if (op.error > 0.0) {
      ratio_local.push_back(local[i] / op.error);
      ratio_sat.push_back(sat[i] / op.error);
    }
    op.error = sat[i];
    op.birth_res = smr::resolution_of(c.header, sat[i]);
  }
  for (smr::Op& op : c.ops)
    for (smr::FragmentTriangle& t : op.fragment)
      if (t.killer.valid()) t.death_res = c.ops[t.killer.value].birth_res;
  auto q = [](std::vector<double> v, double f) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[std::size_t(f * double(v.size() - 1))];
  };
  stats = {{"ops", ratio_sat.size()},
           {"local_over_op_error_median", q(ratio_local, 0.5)},
           {"local_over_op_error_p90", q(ratio_local, 0.9)},
           {"monotone_local_over_op_error_median", q(ratio_sat, 0.5)},
           {"monotone_local_over_op_error_p10", q(ratio_sat, 0.1)},
           {"monotone_local_over_op_error_p90", q(ratio_sat, 0.9)}};
  return c;
}

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) smr::throw_input("cannot open " + path);
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

std::vector<double> parse_list(const std::string& s) {
  std::vector<double> v;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');) v.push_back(std::stod(item));
  return v;
}

json vec_json(const Vec3& v) {
  return json::array({v.x, v.y, v.z});
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"View-dependent output size and measured screen-space error: ours vs OpenMesh VDPM"};
  std::string mesh_path, spm_path, taus_arg = "1,2,4", distances_arg = "1.5,3";
  int repeat = 3, max_passes = 200, viewport_w = 1024, viewport_h = 768;
  double fov = 60.0;
  double match_max_factor = 16.0;
  bool match = true;
  smr::QemPmOptions build_options;
  app.add_option("--mesh", mesh_path, "source mesh (.off/.ply/.obj/.stl)")->required();
  app.add_option("--spm", spm_path, "OpenMesh-Analyzer output for the same mesh")->required();
  app.add_option("--taus", taus_arg, "screen-space tolerances in pixels, comma-separated");
  app.add_option("--distances", distances_arg, "eye distances in model radii, comma-separated");
  app.add_option("--repeat", repeat, "timed runs per cut (median)")->check(CLI::PositiveNumber);
  app.add_option("--max-passes", max_passes, "VDPM refinement passes before giving up");
  app.add_option("--fov", fov, "vertical field of view, degrees");
  app.add_option("--viewport-w", viewport_w);
  app.add_option("--viewport-h", viewport_h);
  app.add_option("--match-max-factor", match_max_factor,
                 "equal-error search: largest tau multiple tried for ours");
  app.add_flag("!--no-match", match, "skip the equal-error search");
  app.add_option("--max-fragment-triangles", build_options.max_fragment_triangles,
                 "our builder's coalescing bound (QemPmOptions; 0 = one op per split)");
  CLI11_PARSE(app, argc, argv);

  try {
    const std::vector<double> taus = parse_list(taus_arg), distances = parse_list(distances_arg);
    json out;
    out["benchmark"] = "vdpm";
    out["machine"] = smr::bench::machine_json();

    // Source mesh and our CRMR.
    std::uint64_t t0 = now_ns();
    smr::MeshReport report;
    const smr::TriangleMesh source = smr::read_mesh(mesh_path, {}, &report);
    const double read_seconds = seconds_since(t0);
    t0 = now_ns();
    smr::QemPmStats qstats;
    const smr::Crmr crmr = smr::build_qem_pm(source, mesh_path, build_options, &qstats);
    const double build_seconds = seconds_since(t0);
    const std::vector<Triangle3> source_tris = triangles_of(source);
    const SoupDistance source_distance(source_tris);
    json local_stats;
    t0 = now_ns();
    const smr::Crmr local_crmr = local_error_crmr(crmr, source_distance, local_stats);
    local_stats["seconds"] = seconds_since(t0);
    const smr::Box3 bounds = crmr.info().bounds;
    const Vec3 centre = bounds.center();
    const double radius = 0.5 * glm::length(bounds.hi - bounds.lo);
    out["mesh"] = {{"path", mesh_path},
                   {"vertices", source.positions.size()},
                   {"triangles", source.triangles.size()},
                   {"summary", report.summary()},
                   {"read_seconds", read_seconds},
                   {"centre", vec_json(centre)},
                   {"radius", radius}};
    out["ours_build"] = {{"builder", "smr::build_qem_pm (default options)"},
                         {"builder_header", crmr.info().builder},
                         {"seconds", build_seconds},
                         {"ops", crmr.op_count()},
                         {"collapses", qstats.collapses},
                         {"base_vertices", qstats.base_vertices},
                         {"base_triangles", qstats.base_triangles},
                         {"err0", crmr.info().err0},
                         {"err_final", crmr.info().err_final},
                         {"what_if_local_op_errors", local_stats}};

    // VDPM hierarchy.
    const std::string spm = read_bytes(spm_path);
    t0 = now_ns();
    auto previous = std::make_unique<Vdpm>(spm);
    const double load_seconds = seconds_since(t0);
    out["vdpm_hierarchy"] = {{"path", spm_path},
                             {"bytes", spm.size()},
                             {"base_vertices", previous->base_vertices()},
                             {"base_faces", previous->base_faces()},
                             {"details", previous->details()},
                             {"load_seconds", load_seconds}};
    if (previous->base_vertices() + previous->details() != source.positions.size())
      std::cerr << "warning: the .spm has " << previous->base_vertices() + previous->details()
                << " vertices, the mesh " << source.positions.size() << "\n";

    // Cameras as in tests/support/meshes.cpp: three directions around the bounds' centre.
    const std::array<Vec3, 3> dirs{Vec3{1, 0.3, 0.2}, Vec3{-0.4, 1, -0.5}, Vec3{0.2, -0.6, 1}};
    json cuts = json::array();
    for (std::size_t d = 0; d < dirs.size(); ++d) {
      for (const double dist : distances) {
        smr::Camera cam;
        cam.eye = centre + glm::normalize(dirs[d]) * (dist * radius);
        cam.target = centre;
        cam.up = std::abs(glm::normalize(dirs[d]).z) > 0.9 ? Vec3{0, 1, 0} : Vec3{0, 0, 1};
        cam.fov_y_deg = fov;
        cam.viewport_w = viewport_w;
        cam.viewport_h = viewport_h;
        cam.validate();
        for (const double tau : taus) {
          json cut = {{"direction", d},
                      {"distance_radii", dist},
                      {"tau_px", tau},
                      {"camera",
                       {{"eye", vec_json(cam.eye)},
                        {"target", vec_json(cam.target)},
                        {"up", vec_json(cam.up)},
                        {"fov_y_deg", fov},
                        {"viewport", {viewport_w, viewport_h}},
                        {"focal_px", cam.focal_px()}}}};
          std::cerr << mesh_path << ": dir " << d << ", " << dist << " radii, tau " << tau
                    << " px\n";

          // Ours.
          std::vector<double> times, totals;
          OurCut ours;
          for (int r = 0; r < repeat; ++r) {
            ours = extract_ours(crmr, cam, tau, true);
            times.push_back(ours.extract_seconds + ours.expand_seconds);
            totals.push_back(ours.total_seconds);
          }
          const OurCut ours_nocull = extract_ours(crmr, cam, tau, false);
          const TwoSided ours_err = measure_both(ours.triangles, source_tris, source_distance, cam);
          const TwoSided ours_nocull_err =
              measure_both(ours_nocull.triangles, source_tris, source_distance, cam);
          const OurCut ours_local = extract_ours(local_crmr, cam, tau, true);
          const TwoSided ours_local_err =
              measure_both(ours_local.triangles, source_tris, source_distance, cam);

          // VDPM from its base mesh (a fresh load each run; the load is not timed).
          std::vector<double> vtimes;
          AdaptStats vstats;
          double plane_dev = 0.0;
          std::unique_ptr<Vdpm> fresh;
          for (int r = 0; r < repeat; ++r) {
            fresh = std::make_unique<Vdpm>(spm);
            plane_dev = fresh->set_view(cam, tau, true);
            vstats = fresh->adapt(max_passes);
            vtimes.push_back(vstats.seconds);
          }
          const std::vector<Triangle3> vdpm_tris = fresh->triangles();
          const TwoSided vdpm_err = measure_both(vdpm_tris, source_tris, source_distance, cam);
          Vdpm nocull(spm);
          nocull.set_view(cam, tau, false);
          const AdaptStats nocull_stats = nocull.adapt(max_passes);
          const TwoSided nocull_err =
              measure_both(nocull.triangles(), source_tris, source_distance, cam);
          // VDPM from the previous cut of this run (the order of the cuts in the output).
          previous->set_view(cam, tau, true);
          const AdaptStats prev_stats = previous->adapt(max_passes);

          cut["ours"] = {
              {"triangles", ours.triangles.size()},
              {"triangles_no_culling", ours_nocull.triangles.size()},
              {"error_no_culling", ours_nocull_err.to_json()},
              {"measured_over_assigned_error", tightness(ours, source_distance, cam)},
              {"what_if_local_op_errors",
               {{"triangles", ours_local.triangles.size()},
                {"extract_seconds", ours_local.extract_seconds + ours_local.expand_seconds},
                {"error", ours_local_err.to_json()}}},
              {"x", ours.x},
              {"extract_seconds", median(times)},
              {"extract_seconds_all", times},
              {"wall_seconds_incl_setup", median(totals)},
              {"error", ours_err.to_json()}};
          cut["vdpm"] = {{"triangles", vdpm_tris.size()},
                         {"triangles_no_culling", nocull.face_count()},
                         {"from_base", vstats.to_json()},
                         {"from_base_seconds", median(vtimes)},
                         {"from_base_seconds_all", vtimes},
                         {"from_previous", prev_stats.to_json()},
                         {"from_previous_triangles", previous->face_count()},
                         {"no_culling", nocull_stats.to_json()},
                         {"error_no_culling", nocull_err.to_json()},
                         {"frustum_plane_check", plane_dev},
                         {"error", vdpm_err.to_json()}};
          const bool fewer = ours.triangles.size() <= vdpm_tris.size();
          const bool lower_max = ours_err.max_px() <= vdpm_err.max_px();
          const bool lower_p99 = ours_err.p99_px() <= vdpm_err.p99_px();
          cut["target"] = {
              {"ours_le_vdpm_triangles", fewer},
              {"ours_le_vdpm_max_px", lower_max},
              {"ours_le_vdpm_p99_px", lower_p99},
              {"holds", fewer && lower_max},
              {"triangle_ratio",
               double(ours.triangles.size()) / double(std::max<std::size_t>(1, vdpm_tris.size()))}};

          // Equal measured error: our triangle count at the largest tolerance tau' = tau * 2^(k/4)
          // (-8 <= k <= 4 log2(match_max_factor)) whose measured two-sided error is still <=
          // VDPM's at tau, once for the max and once for the p99. From k = 0 each search goes up
          // while our error stays <= VDPM's, or down until it is.
          if (match) {
            std::map<int, std::pair<std::size_t, TwoSided>> ladder;  // k -> (triangles, error)
            ladder[0] = {ours.triangles.size(), ours_err};
            auto at = [&](int k) -> const std::pair<std::size_t, TwoSided>& {
              auto it = ladder.find(k);
              if (it == ladder.end()) {
                const OurCut c = extract_ours(crmr, cam, tau * std::pow(2.0, k / 4.0), true);
                it = ladder
                         .emplace(k, std::make_pair(c.triangles.size(),
                                                    measure_both(c.triangles, source_tris,
                                                                 source_distance, cam)))
                         .first;
              }
              return it->second;
            };
            const int k_max = int(std::floor(4.0 * std::log2(match_max_factor) + 1e-9));
            auto search = [&](auto&& metric) {
              const double limit = metric(vdpm_err);
              auto ok = [&](int k) { return metric(at(k).second) <= limit; };
              int best = std::numeric_limits<int>::min();
              if (ok(0)) {
                best = 0;
                while (best < k_max && ok(best + 1)) ++best;
              } else {
                for (int k = -1; k >= -8; --k) {
                  if (ok(k)) {
                    best = k;
                    break;
                  }
                }
              }
              if (best == std::numeric_limits<int>::min()) return json{{"found", false}};
              const auto& [tris, err] = at(best);
              return json{{"found", true},
                          {"tau_px", tau * std::pow(2.0, best / 4.0)},
                          {"at_ladder_limit", best == k_max},
                          {"triangles", tris},
                          {"max_px", err.max_px()},
                          {"p99_px", err.p99_px()},
                          {"triangle_ratio_vs_vdpm",
                           double(tris) / double(std::max<std::size_t>(1, vdpm_tris.size()))}};
            };
            json matched = {{"max", search([](const TwoSided& e) { return e.max_px(); })},
                            {"p99", search([](const TwoSided& e) { return e.p99_px(); })}};
            json steps = json::array();
            for (const auto& [k, v] : ladder)
              steps.push_back({{"tau_px", tau * std::pow(2.0, k / 4.0)},
                               {"triangles", v.first},
                               {"max_px", v.second.max_px()},
                               {"p99_px", v.second.p99_px()}});
            matched["ladder"] = steps;
            cut["ours_at_vdpm_error"] = matched;
          }
          cuts.push_back(cut);
        }
      }
    }
    out["cuts"] = cuts;
    out["peak_rss_mb"] = smr::bench::peak_rss_mb();
    std::cout << out.dump(2) << "\n";
  } catch (const std::exception& e) {
    std::cerr << "bench_vdpm: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
