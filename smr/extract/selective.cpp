// Truly selective refinement (Kim & Lee 2001): the split mesh, vsplit_new and ecol_new with cut
// vertices found on the fly, and the synthesis from the base mesh (selective.h).
#include "smr/extract/selective.h"

#include <algorithm>
#include <functional>
#include <string>
#include <utility>

#include <glm/geometric.hpp>

#include "base/error.h"
#include "smr/core/clock.h"

namespace smr {

namespace {

void erase_one(std::vector<std::uint32_t>& list, std::uint32_t x) {
  const auto it = std::find(list.begin(), list.end(), x);
  if (it == list.end()) throw_internal("selective: a star lost a triangle");
  *it = list.back();
  list.pop_back();
}

// The corner index of v in t.
int corner_of(const std::array<std::uint32_t, 3>& t, std::uint32_t v) {
  for (int k = 0; k < 3; ++k) {
    if (t[static_cast<std::size_t>(k)] == v) return k;
  }
  throw_internal("selective: a star holds a triangle without its vertex");
}

std::string vertex_name(std::uint32_t v) {
  return "vertex " + std::to_string(v);
}

}  // namespace

// ---- SplitMesh

std::uint32_t SplitMesh::add(const std::array<std::uint32_t, 3>& t, std::uint32_t face) {
  const auto id = static_cast<std::uint32_t>(tris_.size());
  tris_.push_back(t);
  face_.push_back(face);
  alive_.push_back(1);
  for (std::uint32_t v : t) star_[v].push_back(id);
  ++live_;
  return id;
}

void SplitMesh::relabel(std::uint32_t t, std::uint32_t from, std::uint32_t to) {
  tris_[t][static_cast<std::size_t>(corner_of(tris_[t], from))] = to;
  erase_one(star_[from], t);
  star_[to].push_back(t);
}

void SplitMesh::remove(std::uint32_t t) {
  for (std::uint32_t v : tris_[t]) erase_one(star_[v], t);
  alive_[t] = 0;
  --live_;
}

std::array<std::uint32_t, 2> SplitMesh::split(std::uint32_t v, std::uint32_t u, std::uint32_t l,
                                              std::uint32_t r, std::uint32_t face_l,
                                              std::uint32_t face_r) {
  if (l == kNone && r == kNone)
    throw_internal("selective: a split of " + vertex_name(v) + " has no side");
  // v's fan: per triangle (v, a, b), a -> the triangle; b marks a's successor.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> next;
  std::vector<std::uint32_t> succ;
  for (std::uint32_t t : star_[v]) {
    const auto k = static_cast<std::size_t>(corner_of(tris_[t], v));
    next.push_back({tris_[t][(k + 1) % 3], t});
    succ.push_back(tris_[t][(k + 2) % 3]);
  }
  std::sort(next.begin(), next.end());
  std::sort(succ.begin(), succ.end());
  const auto find = [&](std::uint32_t a) {
    const auto it = std::lower_bound(next.begin(), next.end(), std::pair{a, 0u});
    return it != next.end() && it->first == a ? it->second : kNone;
  };
  std::uint32_t a = r;
  if (r == kNone) {  // u takes the fan from its start: the a that follows nothing
    std::size_t starts = 0;
    for (const auto& [x, t] : next) {
      if (!std::binary_search(succ.begin(), succ.end(), x)) {
        a = x;
        ++starts;
      }
    }
    if (starts != 1) throw_internal("selective: " + vertex_name(v) + " has no single fan start");
  }
  std::vector<std::uint32_t> moved;
  while (a != l) {
    const std::uint32_t t = find(a);
    if (t == kNone) {
      if (l == kNone) break;  // the fan's end
      throw_internal("selective: the fan of " + vertex_name(v) + " ends before its cut vertex");
    }
    if (moved.size() == next.size()) {
      throw_internal("selective: the fan of " + vertex_name(v) + " never meets its cut vertex");
    }
    moved.push_back(t);
    const auto k = static_cast<std::size_t>(corner_of(tris_[t], v));
    a = tris_[t][(k + 2) % 3];
  }
  for (std::uint32_t t : moved) relabel(t, v, u);
  return {l == kNone ? kNone : add({v, u, l}, face_l), r == kNone ? kNone : add({u, v, r}, face_r)};
}

std::array<std::uint32_t, 2> SplitMesh::wings(std::uint32_t v, std::uint32_t u) const {
  std::array<std::uint32_t, 2> w{kNone, kNone};
  for (std::uint32_t t : star_[v]) {
    const auto k = static_cast<std::size_t>(corner_of(tris_[t], v));
    if (tris_[t][(k + 1) % 3] == u) w[0] = tris_[t][(k + 2) % 3];
    if (tris_[t][(k + 2) % 3] == u) w[1] = tris_[t][(k + 1) % 3];
  }
  return w;
}

void SplitMesh::collapse(std::uint32_t v, std::uint32_t u) {
  const std::vector<std::uint32_t> around = star_[u];
  for (std::uint32_t t : around) {
    if (std::find(tris_[t].begin(), tris_[t].end(), v) != tris_[t].end()) {
      remove(t);
    } else {
      relabel(t, u, v);
    }
  }
}

std::vector<std::uint32_t> SplitMesh::neighbours(std::uint32_t v) const {
  std::vector<std::uint32_t> out;
  for (std::uint32_t t : star_[v]) {
    for (std::uint32_t x : tris_[t]) {
      if (x != v) out.push_back(x);
    }
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

// ---- SelectiveRefinement

SelectiveRefinement::SelectiveRefinement(const OpSource& source,
                                         std::shared_ptr<const SelectiveIndex> index,
                                         SplitScheme scheme)
    : source_(source),
      index_(std::move(index)),
      scheme_(scheme),
      mesh_(index_->vertex_count()),
      node_of_(index_->vertex_count(), kNone),
      pos_(index_->vertex_count()),
      made_(index_->splits().size(), 0) {
  const SelectiveIndex& ix = *index_;
  for (std::uint32_t v : ix.base_vertices()) node_of_[v] = ix.root_of(ix.leaf(v));
  std::vector<OpId> ops = ix.position_ops();
  ops.erase(std::unique(ops.begin(), ops.end()), ops.end());
  for (OpId id : ops) {
    const OpRef op = read(id);
    for (std::size_t i = 0; i < op->own_vertex_count(); ++i) {
      const Vertex& x = op->own_vertex(i);
      if (x.id.value < node_of_.size() && node_of_[x.id.value] != kNone &&
          ix.nodes()[node_of_[x.id.value]].parent == kNone) {
        pos_[x.id.value] = x.p;
      }
    }
  }
  for (std::uint32_t f = 0; f < ix.base_triangles().size(); ++f)
    mesh_.add(ix.base_triangles()[f], f);
  for (std::uint32_t v : ix.base_vertices()) activate(node_of_[v]);
}

OpRef SelectiveRefinement::read(OpId id) const {
  ++stats_.ops_read;
  return source_.op(id);
}

// Queues the node's split, if it has one, for evaluation (coarsest op first).
void SelectiveRefinement::activate(std::uint32_t node) {
  const std::uint32_t s = index_->nodes()[node].split;
  if (s == kNone) return;
  pending_.push_back(s);
  std::push_heap(pending_.begin(), pending_.end(), std::greater<>());
}

bool SelectiveRefinement::selected_if(std::uint32_t v, const Select& select) const {
  if (node_of_[v] == kNone) return false;
  const std::uint32_t s = index_->nodes()[node_of_[v]].split;
  if (s == kNone) return false;
  return select(node_of_[v], *read(index_->splits()[s].op));
}

void SelectiveRefinement::refine_if(const Select& select) {
  const auto t0 = Clock::now();
  while (!pending_.empty()) {
    std::pop_heap(pending_.begin(), pending_.end(), std::greater<>());
    const std::uint32_t s = pending_.back();
    pending_.pop_back();
    const SelectiveIndex::Split& sp = index_->splits()[s];
    if (node_of_[sp.vs] != sp.node) continue;  // split already (a degenerate case forced it)
    ++stats_.evaluated;
    if (!select(sp.node, *read(sp.op))) continue;
    ++stats_.selected;
    if (scheme_ == SplitScheme::kHoppe97) {
      split_with_dependencies(sp.vs);
    } else {
      split(sp.vs);
    }
  }
  stats_.seconds += seconds_since(t0);
}

SelectiveRefinement::Select SelectiveRefinement::select_by(const NodeCriterion& c) const {
  // The vertex cones, asked for (and checked) once, not per vertex.
  const std::span<const NormalCone> vertex_cones =
      c.vertex_normal_cones ? index_->vertex_cones() : std::span<const NormalCone>{};
  return [this, &c, vertex_cones](std::uint32_t node, const OpView& op) {
    const SelectiveIndex::Node& n = index_->nodes()[node];
    const Sphere sphere{pos_[n.vertex], double(n.radius)};
    if (c.frustum && sphere_outside(c.camera, sphere)) return false;
    if (c.backface &&
        backfacing(c.camera, c.backface_over_sphere ? sphere : Sphere{sphere.center, 0.0},
                   c.vertex_normal_cones ? vertex_cones[node] : n.cone))
      return false;
    const double d = std::max(glm::length(sphere.center - c.camera.eye) - sphere.radius, 1e-12);
    return op.error * c.camera.focal_px() / d > c.pixel_error;
  };
}

bool SelectiveRefinement::selected(std::uint32_t v, const RcfOracle& rcf) const {
  return selected_if(
      v, [&](std::uint32_t, const OpView& op) { return !rcf.is_completely_finer(op, source_); });
}

bool SelectiveRefinement::selected(std::uint32_t v, const NodeCriterion& criterion) const {
  return selected_if(v, select_by(criterion));
}

void SelectiveRefinement::refine(const RcfOracle& rcf) {
  refine_if([&](std::uint32_t, const OpView& op) { return !rcf.is_completely_finer(op, source_); });
}

void SelectiveRefinement::refine(const NodeCriterion& criterion) {
  refine_if(select_by(criterion));
}

std::uint32_t SelectiveRefinement::find_cut(std::uint32_t v, std::uint32_t fundamental) const {
  const std::uint32_t leaf = index_->leaf(fundamental);
  for (std::uint32_t w : mesh_.neighbours(v)) {
    if (index_->is_ancestor(node_of_[w], leaf)) return w;
  }
  throw_internal("selective: no neighbour of " + vertex_name(v) + " is an ancestor of its cut " +
                 vertex_name(fundamental));
}

void SelectiveRefinement::split(std::uint32_t v, bool forced) {
  if (v >= node_of_.size() || node_of_[v] == kNone) throw_input(vertex_name(v) + " is not active");
  const std::uint32_t s = index_->nodes()[node_of_[v]].split;
  if (s == kNone) throw_input(vertex_name(v) + " has no split left (it is a source vertex)");
  const SelectiveIndex::Split& sp = index_->splits()[s];
  std::uint32_t l = kNone, r = kNone;
  for (;;) {
    l = sp.cut_l == kNone ? kNone : find_cut(v, sp.cut_l);
    r = sp.cut_r == kNone ? kNone : find_cut(v, sp.cut_r);
    if (l == kNone || l != r) break;
    // Section 4.4: one vertex holds both cut vertices; splitting it first keeps the mesh simply
    // connected (until they part, which they do: they are distinct source vertices).
    if (scheme_ == SplitScheme::kHoppe97)
      throw_internal("selective: a degenerate case under Hoppe 1997's scheme, at " +
                     vertex_name(v));
    ++stats_.degenerate_cases;
    split(l, true);
  }
  const OpRef op = read(sp.op);
  mesh_.split(sp.vs, sp.vu, l, r, index_->split_face(s, 0), index_->split_face(s, 1));
  node_of_[sp.vs] = sp.child_t;
  node_of_[sp.vu] = sp.child_u;
  pos_[sp.vu] = op->own_vertex(0).p;
  made_[s] = forced ? 2 : 1;
  ++stats_.splits;
  if (forced) ++stats_.forced_splits;
  activate(sp.child_t);
  activate(sp.child_u);
}

void SelectiveRefinement::split_with_dependencies(std::uint32_t v) {
  if (v >= node_of_.size() || node_of_[v] == kNone) throw_input(vertex_name(v) + " is not active");
  const SelectiveIndex& ix = *index_;
  const std::uint32_t first = ix.nodes()[node_of_[v]].split;
  if (first == kNone) throw_input(vertex_name(v) + " has no split left (it is a source vertex)");
  // Every split pushed comes earlier in the PM's sequence than the one that pushed it (a parent's
  // split, or the maker of a face there when it was made), so the stack empties.
  std::vector<std::uint32_t> stack{first};
  while (!stack.empty()) {
    const std::uint32_t s = stack.back();
    const SelectiveIndex::Split& sp = ix.splits()[s];
    if (made_[s] != 0) {
      stack.pop_back();
      continue;
    }
    if (node_of_[sp.vs] != sp.node) {  // an ancestor is active: its splits first
      const std::uint32_t parent = ix.nodes()[sp.node].parent;
      if (parent == kNone)
        throw_internal("selective: an inactive root, split " + std::to_string(s));
      stack.push_back(ix.nodes()[parent].split);
      continue;
    }
    const std::size_t waiting = stack.size();  // the makers of its fn faces not made yet first
    for (std::uint32_t f : sp.around) {
      const std::uint32_t maker = ix.face_split(f);
      if (maker != kNone && made_[maker] == 0) stack.push_back(maker);
    }
    if (stack.size() != waiting) continue;
    stack.pop_back();
    split(sp.vs, s != first);
  }
}

bool SelectiveRefinement::neighbourhood_made(std::uint32_t s) const {
  for (std::uint32_t f : index_->splits().at(s).around) {
    const std::uint32_t maker = index_->face_split(f);
    if (maker != kNone && made_[maker] == 0) return false;
  }
  return true;
}

const char* SelectiveRefinement::scheme_name(SplitScheme scheme) {
  return scheme == SplitScheme::kHoppe97 ? "hoppe97" : "truly-selective";
}

SplitScheme SelectiveRefinement::parse_scheme(const std::string& name, const std::string& option) {
  for (SplitScheme s : {SplitScheme::kTrulySelective, SplitScheme::kHoppe97}) {
    if (name == scheme_name(s)) return s;
  }
  throw_input(option + " must be 'truly-selective' or 'hoppe97', got '" + name + "'");
}

bool SelectiveRefinement::collapse(std::uint32_t s) {
  const SelectiveIndex::Split& sp = index_->splits().at(s);
  if (node_of_[sp.vs] != sp.child_t || node_of_[sp.vu] != sp.child_u) {
    throw_input("split " + std::to_string(s) +
                " cannot be collapsed: its two vertices are not both active");
  }
  // The opposite vertices of the edge are the cut vertices (section 4.3); any other common
  // neighbour would pinch the mesh: postponed until splits remove it.
  const auto w = mesh_.wings(sp.vs, sp.vu);
  const std::vector<std::uint32_t> a = mesh_.neighbours(sp.vs), b = mesh_.neighbours(sp.vu);
  std::vector<std::uint32_t> common;
  std::set_intersection(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(common));
  for (std::uint32_t x : common) {
    if (x != w[0] && x != w[1]) {
      ++postponed_;
      return false;
    }
  }
  mesh_.collapse(sp.vs, sp.vu);
  node_of_[sp.vs] = sp.node;
  node_of_[sp.vu] = kNone;
  made_[s] = 0;
  return true;
}

std::vector<std::uint32_t> SelectiveRefinement::active_vertices() const {
  std::vector<std::uint32_t> out;
  for (std::uint32_t v = 0; v < node_of_.size(); ++v) {
    if (node_of_[v] != kNone) out.push_back(v);
  }
  return out;
}

TriangleMesh SelectiveRefinement::to_mesh(std::vector<std::uint32_t>* vertex_ids) const {
  TriangleMesh m;
  const std::vector<std::uint32_t> active = active_vertices();
  std::vector<std::uint32_t> index(node_of_.size(), kNone);
  for (std::uint32_t v : active) {
    index[v] = static_cast<std::uint32_t>(m.positions.size());
    m.positions.push_back(pos_[v]);
  }
  for (std::uint32_t t = 0; t < mesh_.capacity(); ++t) {
    if (!mesh_.alive(t)) continue;
    const auto& c = mesh_.triangle(t);
    m.triangles.push_back({index[c[0]], index[c[1]], index[c[2]]});
  }
  if (vertex_ids != nullptr) *vertex_ids = active;
  return m;
}

SelectiveStats SelectiveRefinement::stats() const {
  SelectiveStats s = stats_;
  const SelectiveIndex& ix = *index_;
  s.vertices = 0;
  s.displacement_bound = 0.0;
  for (std::uint32_t v = 0; v < node_of_.size(); ++v) {
    if (node_of_[v] == kNone) continue;
    ++s.vertices;
    s.displacement_bound = std::max(s.displacement_bound, double(ix.nodes()[node_of_[v]].radius));
  }
  s.triangles = mesh_.live_triangles();
  s.flipped_triangles = 0;
  const auto& src = ix.source_positions();
  for (std::uint32_t t = 0; t < mesh_.capacity(); ++t) {
    if (!mesh_.alive(t)) continue;
    const auto& c = mesh_.triangle(t);
    const auto& f = ix.source_faces()[mesh_.face(t)];
    const Vec3 n = glm::cross(pos_[c[1]] - pos_[c[0]], pos_[c[2]] - pos_[c[0]]);
    const Vec3 m = glm::cross(src[f[1]] - src[f[0]], src[f[2]] - src[f[0]]);
    if (glm::dot(n, m) < 0.0) ++s.flipped_triangles;
  }
  return s;
}

namespace {

template <class Criterion>
SelectiveExtraction extract_with(const OpSource& source,
                                 std::shared_ptr<const SelectiveIndex> index,
                                 const Criterion& criterion, SplitScheme scheme) {
  const auto t0 = Clock::now();
  SelectiveRefinement r(source, std::move(index), scheme);
  r.refine(criterion);
  SelectiveExtraction out;
  out.mesh = r.to_mesh(&out.vertex_ids);
  out.stats = r.stats();
  out.stats.seconds = seconds_since(t0);
  return out;
}

}  // namespace

SelectiveExtraction extract_selective(const OpSource& source,
                                      std::shared_ptr<const SelectiveIndex> index,
                                      const RcfOracle& rcf, SplitScheme scheme) {
  return extract_with(source, std::move(index), rcf, scheme);
}

SelectiveExtraction extract_selective(const OpSource& source,
                                      std::shared_ptr<const SelectiveIndex> index,
                                      const NodeCriterion& criterion, SplitScheme scheme) {
  return extract_with(source, std::move(index), criterion, scheme);
}

}  // namespace smr
