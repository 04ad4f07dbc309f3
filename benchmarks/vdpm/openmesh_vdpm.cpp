#include "benchmarks/vdpm/openmesh_vdpm.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <unordered_map>

#include <glm/geometric.hpp>

#include "base/error.h"
#include "benchmarks/bench_common.h"

namespace smr::bench::vdpm {

namespace VDPM = OpenMesh::VDPM;
using VdpmMesh = Vdpm::VdpmMesh;
using VDPM::VHierarchyNodeHandle;
using VDPM::VHierarchyNodeIndex;

nlohmann::json AdaptStats::to_json() const {
  return {{"passes", passes},   {"converged", converged},
          {"vsplits", vsplits}, {"forced_vsplits", forced_vsplits},
          {"ecols", ecols},     {"unresolved_dependencies", unresolved_dependencies},
          {"seconds", seconds}};
}

Vdpm::Vdpm(const std::string& bytes) {
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

double Vdpm::set_view(const smr::Camera& cam, double tau_px, bool cull) {
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
  vp_.set_fovy(float(cam.fov_y_deg * M_PI / 180.0 + 2.0 * M_PI));  // see openmesh_vdpm.h
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

AdaptStats Vdpm::adapt(int max_passes) {
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

std::vector<Triangle3> Vdpm::triangles() const {
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

bool Vdpm::qrefine(VHierarchyNodeHandle nh) {
  VDPM::VHierarchyNode& node = vhierarchy_.node(nh);
  const OpenMesh::Vec3f p = mesh_.point(node.vertex_handle());
  const OpenMesh::Vec3f eye_dir = p - vp_.eye_pos();
  const float distance2 = eye_dir.sqrnorm();
  const float product = OpenMesh::dot(eye_dir, node.normal());
  if (cull_) {
    for (int i = 0; i < 4; ++i)  // outside_view_frustum
      if (planes_[i].signed_distance(p) < -node.radius()) return false;
    if (backface_ && product > 0.0f &&
        product * product > distance2 * node.sin_square())  // oriented_away
      return false;
  }
  // screen_space_error: refine when mu or the normal-direction term projects above tolerance.
  return node.mue_square() >= kappa_square_ * distance2 ||
         node.sigma_square() * (distance2 - product * product) >=
             kappa_square_ * distance2 * distance2;
}

void Vdpm::force_vsplit(VHierarchyNodeHandle nh, AdaptStats& s) {
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

void Vdpm::attach(VdpmMesh::VertexHandle v, VHierarchyNodeHandle node) {
  mesh_.data(v).set_vhierarchy_node_handle(node);
  mesh_.status(v).set_deleted(false);
}

void Vdpm::vsplit(VHierarchyNodeHandle nh, VdpmMesh::VertexHandle vl, VdpmMesh::VertexHandle vr) {
  const VHierarchyNodeHandle lc = vhierarchy_.lchild_handle(nh), rc = vhierarchy_.rchild_handle(nh);
  const auto v0 = vhierarchy_.vertex_handle(lc), v1 = vhierarchy_.vertex_handle(rc);
  mesh_.vertex_split(v0, v1, vl, vr);
  mesh_.set_normal(v0, vhierarchy_.normal(lc));
  mesh_.set_normal(v1, vhierarchy_.normal(rc));
  attach(v0, lc);
  attach(v1, rc);
  vfront_.remove(nh);
  vfront_.add(lc);
  vfront_.add(rc);
}

void Vdpm::ecol(VHierarchyNodeHandle nh, VdpmMesh::HalfedgeHandle v0v1) {
  const VHierarchyNodeHandle lc = vhierarchy_.lchild_handle(nh), rc = vhierarchy_.rchild_handle(nh);
  const auto v0 = vhierarchy_.vertex_handle(lc), v1 = vhierarchy_.vertex_handle(rc);
  mesh_.collapse(v0v1);
  mesh_.set_normal(v1, vhierarchy_.normal(nh));
  attach(v0, lc);
  attach(v1, nh);
  vfront_.add(nh);
  vfront_.remove(lc);
  vfront_.remove(rc);
}

bool Vdpm::ecol_legal(VHierarchyNodeHandle parent, VdpmMesh::HalfedgeHandle& v0v1) {
  const VHierarchyNodeHandle lc = vhierarchy_.lchild_handle(parent),
                             rc = vhierarchy_.rchild_handle(parent);
  if (!vfront_.is_active(lc) || !vfront_.is_active(rc)) return false;
  v0v1 = mesh_.find_halfedge(vhierarchy_.vertex_handle(lc), vhierarchy_.vertex_handle(rc));
  return v0v1.is_valid() && mesh_.is_collapse_ok(v0v1);
}

// The active neighbours of the node's vertex that descend from its fundamental cut vertices.
void Vdpm::active_cuts(VHierarchyNodeHandle nh, VdpmMesh::VertexHandle& vl,
                       VdpmMesh::VertexHandle& vr) {
  const VHierarchyNodeIndex lcut = vhierarchy_.fund_lcut_index(nh),
                            rcut = vhierarchy_.fund_rcut_index(nh);
  vl = VdpmMesh::InvalidVertexHandle;
  vr = VdpmMesh::InvalidVertexHandle;
  for (auto it = mesh_.vv_iter(vhierarchy_.vertex_handle(nh)); it.is_valid(); ++it) {
    const VHierarchyNodeIndex ni = vhierarchy_.node_index(mesh_.data(*it).vhierarchy_node_handle());
    if (!vl.is_valid() && vhierarchy_.is_ancestor(ni, lcut)) vl = *it;
    if (!vr.is_valid() && vhierarchy_.is_ancestor(ni, rcut)) vr = *it;
    if (vl.is_valid() && vr.is_valid()) break;
  }
}

}  // namespace smr::bench::vdpm
