// OpenMesh's VDPM (Kim & Lee, "Truly selective refinement of progressive meshes", GI 2001, with
// Hoppe 1997's refinement criteria), driven the way its Synthesizer (Apps/VDProgMesh/Synthesizer,
// adaptive_refinement) does: the .spm loaded into OpenMesh's VDPM classes (VHierarchy, VFront,
// ViewingParameters) and refined pass after pass until a pass changes nothing: per active node,
// force_vsplit when qrefine(node), else ecol when legal and !qrefine(parent). qrefine is false
// when the node's sphere is outside the frustum, its normal cone faces away, or
// mu^2 < kappa^2 d^2 and sigma^2 (d^2 - (n.(v-e))^2) < kappa^2 d^4 (Hoppe 97's screen-space test),
// with kappa^2 = 4 tan^2(fovy/2) tolerance_square.
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
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/VDPM/MeshTraits.hh>
#include <OpenMesh/Tools/VDPM/VFront.hh>
#include <OpenMesh/Tools/VDPM/VHierarchy.hh>
#include <OpenMesh/Tools/VDPM/ViewingParameters.hh>
#include <nlohmann/json.hpp>

#include "smr/core/geometry.h"
#include "smr/rcf/camera.h"

namespace smr::bench::vdpm {

struct AdaptStats {
  int passes = 0;
  bool converged = false;
  std::uint64_t vsplits = 0, forced_vsplits = 0, ecols = 0;
  std::uint64_t unresolved_dependencies = 0;  // force_vsplit found no cut vertex (never expected)
  double seconds = 0.0;
  nlohmann::json to_json() const;
};

class Vdpm {
 public:
  using VdpmMesh = OpenMesh::TriMesh_ArrayKernelT<OpenMesh::VDPM::MeshTraits>;
  using VHierarchyNodeHandle = OpenMesh::VDPM::VHierarchyNodeHandle;
  using VHierarchyNodeIndex = OpenMesh::VDPM::VHierarchyNodeIndex;

  /// Parses an .spm (OpenMesh-Analyzer's "VDProgMesh" format, little-endian) as the Synthesizer's
  /// open_vd_prog_mesh does: base mesh, then per detail the new vertex, the node index of the
  /// split vertex, its fundamental cut indices and the view-dependent parameters (radius, normal,
  /// sin^2 of the normal cone, mu^2, sigma^2) of both children.
  explicit Vdpm(const std::string& bytes);

  std::uint32_t base_vertices() const { return n_base_vertices_; }
  std::uint32_t base_faces() const { return n_base_faces_; }
  std::uint32_t details() const { return n_details_; }

  /// The camera as OpenMesh's ViewingParameters (an OpenGL column-major modelview matrix, fovy,
  /// aspect, tolerance_square), then kappa^2 as the Synthesizer computes it. Returns the largest
  /// difference between OpenMesh's four frustum planes and smr::Camera's (normals and offsets).
  double set_view(const Camera& cam, double tau_px, bool cull);
  /// With culling on, whether the back-face (normal cone) test is made too (default: yes); off,
  /// only the view frustum culls (Kim & Lee's Table 2 "V.F." rows).
  void set_backface(bool on) { backface_ = on; }

  /// The Synthesizer's adaptive_refinement, repeated until a pass makes no split and no collapse
  /// (each pass ends with the Synthesizer's garbage collection of edges and faces).
  AdaptStats adapt(int max_passes);

  std::size_t face_count() const { return mesh_.n_faces(); }

  /// The current mesh's faces.
  std::vector<Triangle3> triangles() const;

 private:
  bool qrefine(VHierarchyNodeHandle nh);
  void force_vsplit(VHierarchyNodeHandle nh, AdaptStats& s);
  // `v` now stands for `node`, and is live (the Synthesizer undeletes both vertices of a vsplit
  // and of an ecol).
  void attach(VdpmMesh::VertexHandle v, VHierarchyNodeHandle node);
  void vsplit(VHierarchyNodeHandle nh, VdpmMesh::VertexHandle vl, VdpmMesh::VertexHandle vr);
  void ecol(VHierarchyNodeHandle nh, VdpmMesh::HalfedgeHandle v0v1);
  bool ecol_legal(VHierarchyNodeHandle parent, VdpmMesh::HalfedgeHandle& v0v1);
  void active_cuts(VHierarchyNodeHandle nh, VdpmMesh::VertexHandle& vl, VdpmMesh::VertexHandle& vr);

  VdpmMesh mesh_;
  OpenMesh::VDPM::VHierarchy vhierarchy_;
  OpenMesh::VDPM::VFront vfront_;
  OpenMesh::VDPM::ViewingParameters vp_;
  OpenMesh::VDPM::Plane3d planes_[4];
  float kappa_square_ = 0.0f;
  bool cull_ = true;
  bool backface_ = true;
  std::uint32_t n_base_vertices_ = 0, n_base_faces_ = 0, n_details_ = 0;
};

}  // namespace smr::bench::vdpm
