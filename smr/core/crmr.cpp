#include "smr/core/crmr.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <unordered_map>

#include "base/error.h"
#include "smr/core/fragment_edges.h"

namespace smr {

namespace {

const CoarserLink* find_link(std::span<const CoarserLink> links, std::uint32_t tri,
                             std::uint8_t edge) {
  for (const CoarserLink& l : links) {
    if (l.tri == tri && l.edge == edge) return &l;
  }
  return nullptr;
}

}  // namespace

const CoarserLink* Op::coarser_link(std::uint32_t tri, std::uint8_t edge) const {
  return find_link(coarser, tri, edge);
}

OpView::OpView(const Op& op)
    : id(op.id),
      birth_res(op.birth_res),
      error(op.error),
      vertices(op.vertices),
      new_vertex_count(op.new_vertex_count),
      fragment(op.fragment),
      pre(op.pre),
      pre_tris(op.pre_tris),
      coarser(op.coarser),
      parents(op.parents),
      children(op.children),
      box(op.box),
      sphere(op.sphere),
      roi(op.roi),
      subtree_cone(op.subtree_cone) {}

void OpView::require_links() const {
  if (!links)
    throw_internal("op " + std::to_string(id.value) +
                   ": its page was decoded without Hypermesh links (the reader did not call "
                   "OpSource::need_links first)");
}

const CoarserLink* OpView::coarser_link(std::uint32_t tri, std::uint8_t edge) const {
  require_links();
  return find_link(coarser, tri, edge);
}

const FragmentTriangle& OpView::triangle(std::uint32_t i) const {
  if (i >= fragment.size())
    throw_input("op " + std::to_string(id.value) + " has no triangle " + std::to_string(i));
  return fragment[i];
}

Op to_op(const OpView& view) {
  view.require_links();
  Op op;
  op.id = view.id;
  op.birth_res = view.birth_res;
  op.error = view.error;
  op.new_vertex_count = view.new_vertex_count;
  const std::size_t n = view.own_vertex_count();
  op.vertices.reserve(n);
  std::unordered_map<std::uint32_t, std::uint32_t> local;  // index in view.vertices -> in op's
  for (std::size_t i = 0; i < n; ++i) {
    op.vertices.push_back(view.own_vertex(i));
    local.emplace(view.vertex_list.empty() ? std::uint32_t(i) : view.vertex_list[i],
                  std::uint32_t(i));
  }
  const auto renumber = [&](std::array<std::uint32_t, 3> v) {
    for (std::uint32_t& c : v) c = local.at(c);
    return v;
  };
  op.fragment.assign(view.fragment.begin(), view.fragment.end());
  for (FragmentTriangle& t : op.fragment) t.v = renumber(t.v);
  op.pre.assign(view.pre.begin(), view.pre.end());
  op.pre_tris.assign(view.pre_tris.begin(), view.pre_tris.end());
  for (PreTriangle& t : op.pre_tris) t.v = renumber(t.v);
  op.coarser.assign(view.coarser.begin(), view.coarser.end());
  op.parents.assign(view.parents.begin(), view.parents.end());
  op.children.assign(view.children.begin(), view.children.end());
  op.box = view.box;
  op.sphere = view.sphere;
  op.cone = op_bounds(view).cone;  // nor their own normal cone
  op.roi = view.roi;
  op.subtree_cone = view.subtree_cone;
  return op;
}

OpRef Crmr::op(OpId id) const {
  return std::make_shared<const OpView>(ops.at(id.value));
}

std::uint64_t Crmr::triangle_count() const {
  std::uint64_t n = 0;
  for (const Op& op : ops) n += op.fragment.size();
  return n;
}

void OpSink::encode(Op& /*op*/, std::vector<std::uint8_t>& /*out*/) const {
  throw_internal("op sink: encode() on a sink that takes ops whole (encodes() is false)");
}
void OpSink::add_encoded(std::span<const std::uint8_t> /*op*/) {
  throw_internal("op sink: add_encoded() on a sink that takes ops whole (encodes() is false)");
}

void CrmrCollector::add(Op&& op) {
  if (op.id.value != crmr_.ops.size())
    throw_internal("op sink: op " + std::to_string(op.id.value) + " arrived out of id order");
  crmr_.ops.push_back(std::move(op));
}

Crmr CrmrCollector::take() {
  compute_rois(crmr_);
  return std::move(crmr_);
}

// In-fragment neighbours: the triangle across each edge that has the reversed edge. Fragments
// are small (a few triangles), so a quadratic scan beats a hash map (and a sort); R^0 may be
// large and is hashed.
void fragment_neighbours(std::span<const FragmentTriangle> fragment,
                         std::vector<std::array<std::int32_t, 3>>& nbr) {
  nbr.resize(fragment.size());
  for_each_neighbour(fragment, [&](std::size_t i, int k, std::int32_t j) { nbr[i][k] = j; });
}

void compute_op_bounds(Op& op) {
  const OpBounds b = op_bounds(op);
  op.box = b.box;
  op.sphere = b.sphere;
  op.cone = b.cone;
}

OpBounds op_bounds(const OpView& op) {
  // bounding_sphere and normal_cone over the corners and normals of F then PreF, computed in
  // place (the same operations in the same order, so the same values): pages decode it per op.
  thread_local std::vector<Vec3> normals;  // the thread's scratch, kept
  normals.clear();
  OpBounds b;
  Vec3 sum{0.0};
  const auto first = [&](const Vec3& p0, const Vec3& p1, const Vec3& p2) {
    b.box.add(p0);
    b.box.add(p1);
    b.box.add(p2);
    normals.push_back(triangle_normal(p0, p1, p2));
    sum += normals.back();
  };
  for (const FragmentTriangle& t : op.fragment)
    first(op.position(t, 0), op.position(t, 1), op.position(t, 2));
  for (const PreTriangle& t : op.pre_tris)
    first(op.position(t, 0), op.position(t, 1), op.position(t, 2));
  if (!b.box.empty()) {
    b.sphere.center = b.box.center();
    double r2 = 0.0;
    const auto far = [&](const Vec3& p) {
      r2 = std::max(r2, glm::dot(p - b.sphere.center, p - b.sphere.center));
    };
    for (const FragmentTriangle& t : op.fragment)
      for (int k = 0; k < 3; ++k) far(op.position(t, k));
    for (const PreTriangle& t : op.pre_tris)
      for (int k = 0; k < 3; ++k) far(op.position(t, k));
    b.sphere.radius = std::sqrt(r2);
  }
  b.cone = normal_cone_of(normals, sum);
  return b;
}

void link_dag(Crmr& crmr) {
  const std::uint64_t m = crmr.ops.size();
  auto ref_error = [&](const Op& op, const std::string& what) {
    throw_internal("CRMR op " + std::to_string(op.id.value) + ": " + what);
  };
  for (Op& op : crmr.ops) {
    op.parents.clear();
    op.children.clear();
  }
  std::vector<std::pair<std::uint64_t, std::uint32_t>> local;  // (vertex id, index in op.vertices)
  for (Op& op : crmr.ops) {
    local.clear();
    for (std::uint32_t i = 0; i < op.vertices.size(); ++i)
      local.push_back({op.vertices[i].id.value, i});
    std::sort(local.begin(), local.end());
    op.pre_tris.clear();
    op.pre_tris.reserve(op.pre.size());
    for (const TriRef& t : op.pre) {
      if (t.op.value >= m || t.op >= op.id) ref_error(op, "PreF names a triangle of a later op");
      Op& parent = crmr.ops[t.op.value];
      if (t.index >= parent.fragment.size()) ref_error(op, "PreF names a missing triangle");
      FragmentTriangle& tri = parent.fragment[t.index];
      if (tri.killer.valid() && tri.killer != op.id) ref_error(op, "a triangle is replaced twice");
      tri.killer = op.id;
      tri.death_res = op.birth_res;
      op.parents.push_back(t.op);
      PreTriangle pt;
      pt.flags = tri.flags;
      for (int k = 0; k < 3; ++k) {
        const std::uint64_t vid = parent.vertex_id(tri, k).value;
        auto it = std::lower_bound(local.begin(), local.end(), std::pair(vid, std::uint32_t{0}));
        if (it == local.end() || it->first != vid)
          ref_error(op, "a PreF corner is not a vertex of F");
        pt.v[k] = it->second;
      }
      op.pre_tris.push_back(pt);
    }
    compute_op_bounds(op);
    std::sort(op.parents.begin(), op.parents.end());
    op.parents.erase(std::unique(op.parents.begin(), op.parents.end()), op.parents.end());
    for (OpId p : op.parents) crmr.ops[p.value].children.push_back(op.id);
  }
  compute_rois(crmr);
}

void compute_rois(Crmr& crmr) {
  // Children have larger ids, so going backwards finishes every child before its parents.
  for (std::uint64_t i = crmr.ops.size(); i-- > 0;) {
    Op& op = crmr.ops[i];
    op.roi = op.box;
    NormalCone cone = op.cone;
    for (OpId c : op.children) {
      const Op& child = crmr.ops.at(c.value);
      op.roi.add(child.roi);
      cone = cone_union(cone, child.subtree_cone);
    }
    op.subtree_cone = canonical_cone(cone);
  }
}

}  // namespace smr
