// Refinement operations and their fragments: the CRMR's unit of storage (Brown 4.4.1, 4.5).
//
// An Op is self-contained: it names other ops only by OpId and other triangles only by TriRef,
// and carries the positions of every vertex its fragment uses, so one op can be serialised and
// paged in on its own (docs/design.md section 3).
//
// Builders make Ops (each a set of vectors). Readers see OpViews: the same fields as spans, over
// an Op or over a decoded data page (smr/db/page.h), where every array of every op of the page
// lies in one block and corners index the page's shared vertex table.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "smr/core/geometry.h"
#include "smr/core/ids.h"

namespace smr {

struct Vertex {
  VertexId id;
  Vec3 p{0.0};
  friend bool operator==(const Vertex&, const Vertex&) = default;
};

/// The coarser version of a fragment boundary edge (Brown 4.5.1, Hypermesh): the same geometric
/// edge in the closest coarser fragment that contains it. `tri`/`edge` name one triangle of that
/// fragment having the edge (on either side of it). Absent on the model boundary.
struct EdgeRef {
  TriRef tri;
  std::uint8_t edge = 0;  // edge k of a triangle joins v[k] and v[(k + 1) % 3]
  friend bool operator==(const EdgeRef&, const EdgeRef&) = default;
};

struct CoarserLink {
  std::uint32_t tri = 0;  // triangle of this fragment
  std::uint8_t edge = 0;  // its boundary edge
  EdgeRef coarser;        // the edge's closest coarser version
  friend bool operator==(const CoarserLink&, const CoarserLink&) = default;
};

/// A triangle of a fragment F(R): 32 bytes (a decoded page holds thousands). Its neighbours in F
/// are not kept: fragment_neighbours (crmr.h) derives them for the readers that need them.
struct FragmentTriangle {
  static constexpr std::int32_t kNoNeighbour = -1;  // fragment_neighbours: no triangle across
  static constexpr std::uint8_t kVoid = 1;          // covers only "no data": never output

  std::array<std::uint32_t, 3> v{};  // indices into Op::vertices, counter-clockwise
  std::uint8_t flags = 0;
  double death_res = 1.0;  // resolution at which it is replaced (1 if never)
  OpId killer;             // op whose PreF contains it; invalid if never replaced

  bool is_void() const { return (flags & kVoid) != 0; }
  friend bool operator==(const FragmentTriangle&, const FragmentTriangle&) = default;
};
static_assert(sizeof(FragmentTriangle) == 32);

/// A triangle of PreF(R) as R sees it: its corners as indices into R's own `vertices` (no vertex
/// disappears in a refinement, so every corner of PreF is a vertex of F) and its flags. With it an
/// op answers IsCompletelyFiner from its own record: smr/db pages an op in without its parents.
struct PreTriangle {
  std::array<std::uint32_t, 3> v{};  // same corners, same rotation as in the creator's fragment
  std::uint8_t flags = 0;
  bool is_void() const { return (flags & FragmentTriangle::kVoid) != 0; }
  friend bool operator==(const PreTriangle&, const PreTriangle&) = default;
};

struct Op {
  OpId id;
  double birth_res = 0.0;  // resolution of M^{i-1} just before this op (Brown 4.4.2)
  double error = 0.0;      // the error, in data units, that birth_res stands for

  /// Every vertex used by the fragment. The first `new_vertex_count` are V(R^i), the vertices this
  /// op introduces; the rest are positions copied from ancestors so the op is self-contained.
  std::vector<Vertex> vertices;
  std::uint32_t new_vertex_count = 0;

  std::vector<FragmentTriangle> fragment;  // F(R^i)
  std::vector<TriRef> pre;                 // PreF(R^i): triangles of parents' fragments it replaces
  std::vector<PreTriangle> pre_tris;       // parallel to `pre` (filled by link_dag)
  std::vector<CoarserLink> coarser;        // one per boundary edge of F that is not model boundary

  std::vector<OpId> parents;   // sorted: ops whose fragments meet PreF (Brown 4.5.2)
  std::vector<OpId> children;  // sorted: ops whose PreF meets this fragment

  // Geometry for the RCF and the index. `box`, `sphere` and `cone` cover F(R^i) AND PreF(R^i), so
  // one culling verdict serves both IsFiner and IsCompletelyFiner. `sphere` is centred at
  // box.center(). `roi` = box united with the children's ROIs: it contains every descendant.
  // `subtree_cone` holds `cone` and the children's subtree cones, in the stored (canonical_cone)
  // form: every normal of every descendant, which back-face culling needs (Hoppe 1997 section
  // 4.2: a coarse triangle facing away can refine into triangles that face the eye).
  Box3 box;
  Sphere sphere;
  NormalCone cone;
  Box3 roi;
  NormalCone subtree_cone;

  const Vec3& position(const FragmentTriangle& t, int k) const { return vertices[t.v[k]].p; }
  const Vec3& position(const PreTriangle& t, int k) const { return vertices[t.v[k]].p; }
  VertexId vertex_id(const FragmentTriangle& t, int k) const { return vertices[t.v[k]].id; }
  /// The link of boundary edge `edge` of triangle `tri`, or nullptr (model boundary).
  const CoarserLink* coarser_link(std::uint32_t tri, std::uint8_t edge) const;

  friend bool operator==(const Op&, const Op&) = default;
};

/// An op as extraction and the checks read it: Op's fields as spans into storage someone else
/// owns (an Op, or a decoded page), so reading an op copies no array. Corners of `fragment` and
/// `pre_tris` index `vertices`, which is the op's own vertex list for an Op and the page's vertex
/// table for a paged op; `vertex_list` then names the op's own vertices in that table (the first
/// `new_vertex_count` are V(R^i)).
struct OpView {
  OpId id;
  double birth_res = 0.0;
  double error = 0.0;
  std::span<const Vertex> vertices;            // what corners index
  std::span<const std::uint32_t> vertex_list;  // the op's vertices in `vertices`; empty: all
  std::uint32_t new_vertex_count = 0;
  /// False when the op's page was decoded without its Hypermesh links (`coarser` is then empty):
  /// only the advancing front reads them, so a database decodes them once a reader asks
  /// (OpSource::need_links). coarser_link() and to_op() throw on such a view.
  bool links = true;
  std::span<const FragmentTriangle> fragment;
  std::span<const TriRef> pre;
  std::span<const PreTriangle> pre_tris;
  std::span<const CoarserLink> coarser;  // sorted by (tri, edge); see `links`
  std::span<const OpId> parents;
  std::span<const OpId> children;
  Box3 box;
  Sphere sphere;
  Box3 roi;
  NormalCone subtree_cone;
  // Not here, though Op has it, since pages derive it only on demand: the op's own normal cone
  // (op_bounds(view).cone).

  OpView() = default;
  OpView(const Op& op);  // NOLINT(google-explicit-constructor): an Op reads as its view

  const Vec3& position(const FragmentTriangle& t, int k) const { return vertices[t.v[k]].p; }
  const Vec3& position(const PreTriangle& t, int k) const { return vertices[t.v[k]].p; }
  VertexId vertex_id(const FragmentTriangle& t, int k) const { return vertices[t.v[k]].id; }
  /// The op's own vertices, in its order (new ones first).
  std::size_t own_vertex_count() const {
    return vertex_list.empty() ? vertices.size() : vertex_list.size();
  }
  const Vertex& own_vertex(std::size_t i) const {
    return vertex_list.empty() ? vertices[i] : vertices[vertex_list[i]];
  }
  /// The link of boundary edge `edge` of triangle `tri`, or nullptr (model boundary). Throws
  /// smr::Error (kInternal) if the view has no links (`links`).
  const CoarserLink* coarser_link(std::uint32_t tri, std::uint8_t edge) const;
  void require_links() const;  // throws as coarser_link() does
  /// Fragment triangle i; throws smr::Error (kInvalidInput) if there is none.
  const FragmentTriangle& triangle(std::uint32_t i) const;
};

/// An Op with the view's contents (corners renumbered to the op's own vertex list, the normal cone
/// derived): equal to the Op the view was written from. Throws smr::Error
/// (kInternal) on a view without its links (OpView::links).
Op to_op(const OpView& view);

}  // namespace smr
