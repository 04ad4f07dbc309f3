// Truly selective refinement of a progressive mesh (Kim & Lee 2001, papers/002): a vertex split
// or an edge collapse applies to any active vertex or edge, whatever its neighbourhood, with the
// cut vertices that play the roles of v_l and v_r found on the fly among the current neighbours
// as the active ancestors of two *fundamental cut vertices* (vertices of the source mesh), by an
// O(1) IsAncestor over a <tree-id, node-id> numbering of the vertex hierarchy (section 4.3). The
// only extra split is the paper's degenerate case (4.4): when both cut vertices are one vertex,
// that vertex is split first; those splits are counted.
//
// What it reads. A PM-built database whose ops are single vertex splits (a mesh ingested in
// memory with `--coalesce 0`, or by blocks): each op introduces one vertex u (V(R) = {u}, plus
// the vertices of any components the op spawns), F(R) is u's star just after the split and
// PreF(R) the triangles it replaced. The split vertex v is found as the corner of PreF whose fan
// over u's link is PreF (a degree-3 or -4 split is a half-edge collapse towards more than one
// corner: any of them gives the same meshes, and the first is taken), and the wings v_l, v_r as
// the third corners of F's triangles (v, u, v_l) and (u, v, v_r). Nothing is added at ingest.
// The fundamental cut vertices, which pages do not store, are derived once per database by
// replaying every split in order on an in-memory mesh (SelectiveIndex::build: one pass over every
// op through the source's cache; memory in the source's vertex and triangle count): the triangle
// (v, u, v_l) a split makes keeps its identity while later splits relabel its corners, and at the
// end of the replay its third corner is v̂_l (section 4.2). Spawned components (Brown Fig. 4.9d,
// which the in-memory builder uses for all components but one) are part of the selective base
// mesh, as in a progressive mesh, whose base holds every component.
//
// Criterion. An active vertex v, a node of the hierarchy, is *selected* when the op of its next
// split is not completely finer than the RCF (the same IsCompletelyFiner that Brown's AddToList
// asks, read from the same pages through the same cache); extraction splits selected vertices,
// coarsest op first, until no active vertex is selected (Kim & Lee's synthesis from the base mesh).
//
// Error. The ops' guaranteed Hausdorff bounds are for their own fragments, and truly selective
// splits change the neighbourhoods, so those bounds do not carry over. What holds instead: every
// output triangle is a source triangle whose corners moved to their active ancestors (the dual
// piece partition, section 3.1), so it lies within max(r(a), r(b), r(c)) of that source triangle
// and the source within the same of the output, where r(n) is the largest distance from node n's
// vertex to a source vertex of its dual piece (SelectiveIndex::Node::radius). The extraction
// reports that bound; the rest (screen-space error, flipped triangles: a triangle whose normal
// points against its source triangle's, the paper's open problem) is measured.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "smr/core/mesh.h"
#include "smr/core/op_source.h"
#include "smr/rcf/camera.h"
#include "smr/rcf/rcf.h"

namespace smr {

/// What SelectiveIndex::build makes beyond what extraction needs.
struct SelectiveIndexOptions {
  /// Also the nodes' vertex cones (SelectiveIndex::vertex_cone,
  /// NodeCriterion::vertex_normal_cones): 32 bytes a node more, half again the nodes' memory, so
  /// only when asked.
  bool vertex_cones = false;
};

/// The vertex hierarchy of a PM-built CRMR with Kim & Lee's topological details.
class SelectiveIndex {
 public:
  static constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();

  /// One vertex split: node `node` (vertex vs) becomes `child_t` (vs, keeping its id) and
  /// `child_u` (the new vertex vu), with the fundamental cut vertices cut_l, cut_r (source vertex
  /// ids; kNone on the model boundary, where a split makes one triangle).
  struct Split {
    OpId op;
    std::uint32_t vs = kNone, vu = kNone;
    std::uint32_t cut_l = kNone, cut_r = kNone;
    std::uint32_t node = kNone, child_t = kNone, child_u = kNone;
    /// Hoppe 1997's fn0..fn3 (section 3, Fig. 3): the faces across the edges (v_u, v_l),
    /// (v_l, v_s), (v_s, v_r) and (v_r, v_u) of the split's new faces, where the split is made in
    /// the PM's own sequence (face ids as source_faces(); kNone on the model boundary or for a
    /// missing side). What Hoppe's scheme requires to be active before the split.
    std::array<std::uint32_t, 4> around{kNone, kNone, kNone, kNone};
  };
  struct Node {
    std::uint32_t vertex = kNone;  // the vertex id it stands for
    std::uint32_t parent = kNone;
    std::uint32_t split = kNone;  // the split that splits it (kNone: a leaf)
    std::uint32_t tree = 0;       // tree-id: its root's number
    std::uint32_t id = 0;         // node-id: preorder number within its tree
    std::uint32_t size = 1;       // nodes in its subtree (its own included)
    float radius = 0.0f;          // r(n): max |p(vertex) - p(x)| over source vertices x below
    NormalCone cone;              // holds the normal of every source triangle at those x
  };
  struct Stats {
    std::uint64_t splits = 0, roots = 0, spawned_components = 0;
    std::uint32_t max_depth = 0;  // longest root-to-leaf path (why node-ids are intervals)
    double seconds = 0.0;
  };

  /// Reads every op of `source` once, in id order. Throws smr::Error (kInvalidInput) when the
  /// source is not a 3-D mesh or an op is not a single vertex split (a coalesced build: ingest
  /// with --coalesce 0), naming the op.
  static std::shared_ptr<const SelectiveIndex> build(const OpSource& source,
                                                     const SelectiveIndexOptions& options = {});

  /// O(1) (section 4.3): whether node a is node b or an ancestor of it. The paper numbers nodes
  /// as in a heap and compares shifted node-ids, which needs root-to-leaf paths of at most 63
  /// levels in 64 bits. A half-edge hierarchy has no such bound (a vertex that absorbs k collapses
  /// heads a chain of k levels; Stats::max_depth is 20-30 on the CGAL meshes and the terrain of
  /// benchmarks/vdpm, but nothing caps it), so node-ids are preorder numbers within the tree and a
  /// node carries its subtree's size: one comparison of ids, whatever the depth.
  bool is_ancestor(std::uint32_t a, std::uint32_t b) const {
    const Node& x = nodes_[a];
    const Node& y = nodes_[b];
    return x.tree == y.tree && x.id <= y.id && y.id - x.id < x.size;
  }

  const std::vector<Split>& splits() const { return splits_; }
  const std::vector<Node>& nodes() const { return nodes_; }
  /// Node n's vertex cone: it holds the vertex normal (the normalized sum of its triangles' unit
  /// normals) of every source vertex below n, the kind of cone OpenMesh's Analyzer gives its VDPM
  /// nodes (it centres its own on the node vertex's normal; this one is fitted). Narrower than
  /// Node::cone, and no bound on the triangles' normals. Throws smr::Error (kInvalidInput) on an
  /// index built without them (SelectiveIndexOptions::vertex_cones).
  const NormalCone& vertex_cone(std::uint32_t n) const { return vertex_cones()[n]; }
  /// Every node's vertex cone, by node; throws as vertex_cone() does.
  std::span<const NormalCone> vertex_cones() const;
  bool has_vertex_cones() const { return !vertex_cones_.empty(); }
  /// The leaf node of source vertex x.
  std::uint32_t leaf(std::uint32_t x) const { return leaf_[x]; }
  /// The selective base mesh: R^0's triangles, then every spawned component's.
  const std::vector<std::array<std::uint32_t, 3>>& base_triangles() const { return base_; }
  /// Vertices of the selective base mesh with their root nodes, and the ops holding their
  /// positions (R^0, or the op that spawns the component).
  const std::vector<std::uint32_t>& base_vertices() const { return base_vertices_; }
  const std::vector<OpId>& position_ops() const { return position_ops_; }
  /// The source triangle each selective triangle is (face ids: base triangles, then two per
  /// split, its (v, u, v_l) and (u, v, v_r)): its corners in the source mesh.
  const std::vector<std::array<std::uint32_t, 3>>& source_faces() const { return faces_; }
  std::uint32_t split_face(std::uint32_t split, int side) const {
    return static_cast<std::uint32_t>(base_.size()) + 2 * split + static_cast<std::uint32_t>(side);
  }
  /// The split that makes face f (kNone: a base triangle, always there, or f is kNone).
  std::uint32_t face_split(std::uint32_t f) const {
    const auto base = static_cast<std::uint32_t>(base_.size());
    return f < base || f == kNone ? kNone : (f - base) / 2;
  }
  std::uint32_t vertex_count() const { return static_cast<std::uint32_t>(leaf_.size()); }
  /// Source vertex positions, for measurements (flipped triangles) and checks, not for
  /// extraction, which takes positions from the ops it reads.
  const std::vector<Vec3>& source_positions() const { return pos_; }
  /// The root node above node n.
  std::uint32_t root_of(std::uint32_t n) const {
    while (nodes_[n].parent != kNone) n = nodes_[n].parent;
    return n;
  }
  const Stats& stats() const { return stats_; }

 private:
  friend struct SelectiveIndexBuilder;
  std::vector<Split> splits_;
  std::vector<Node> nodes_;
  std::vector<NormalCone> vertex_cones_;  // per node, when built with them
  std::vector<std::uint32_t> leaf_, base_vertices_;
  std::vector<OpId> position_ops_;
  std::vector<std::array<std::uint32_t, 3>> base_, faces_;
  std::vector<Vec3> pos_;
  Stats stats_;
};

/// A mesh of vertex ids under vertex splits and edge collapses that keep every triangle's
/// identity (a moved triangle is relabelled in place): the replay's and the synthesis' mesh.
class SplitMesh {
 public:
  static constexpr std::uint32_t kNone = SelectiveIndex::kNone;
  explicit SplitMesh(std::uint32_t vertex_count) : star_(vertex_count) {}

  std::uint32_t add(const std::array<std::uint32_t, 3>& t, std::uint32_t face);
  /// Splits v into v and u (new), u taking the triangles from r counter-clockwise round to l
  /// (from the fan's start to l when r is kNone; from r to its end when l is kNone), and adds
  /// (v, u, l) and (u, v, r). Returns the new triangles (kNone for a missing side). Throws
  /// smr::Error (internal) when l and r do not bound such a fan of v.
  std::array<std::uint32_t, 2> split(std::uint32_t v, std::uint32_t u, std::uint32_t l,
                                     std::uint32_t r, std::uint32_t face_l, std::uint32_t face_r);
  /// Collapses the edge (v, u) into v: removes the triangles on it, relabels u's others.
  void collapse(std::uint32_t v, std::uint32_t u);
  /// The opposite corners of edge v->u (the triangle (v, u, x)) and u->v, or kNone.
  std::array<std::uint32_t, 2> wings(std::uint32_t v, std::uint32_t u) const;
  /// v's neighbours (each once).
  std::vector<std::uint32_t> neighbours(std::uint32_t v) const;
  const std::vector<std::uint32_t>& star(std::uint32_t v) const { return star_[v]; }
  const std::array<std::uint32_t, 3>& triangle(std::uint32_t t) const { return tris_[t]; }
  std::uint32_t face(std::uint32_t t) const { return face_[t]; }
  bool alive(std::uint32_t t) const { return alive_[t] != 0; }
  std::uint32_t capacity() const { return static_cast<std::uint32_t>(tris_.size()); }
  std::uint64_t live_triangles() const { return live_; }

 private:
  void relabel(std::uint32_t t, std::uint32_t from, std::uint32_t to);
  void remove(std::uint32_t t);
  std::vector<std::array<std::uint32_t, 3>> tris_;
  std::vector<std::uint32_t> face_;
  std::vector<std::uint8_t> alive_;
  std::vector<std::vector<std::uint32_t>> star_;
  std::uint64_t live_ = 0;
};

/// Hoppe 1997's per-vertex criterion (the one Kim & Lee's experiments and OpenMesh's VDPM use),
/// over a node's dual piece: an active vertex is selected unless its sphere (its position, radius
/// r(n)) is outside the view frustum, or (backface) the normal cone of its dual piece faces away
/// from the eye, or its split op's error projects to at most pixel_error at the sphere's nearest
/// distance to the eye.
struct NodeCriterion {
  Camera camera;
  bool frustum = true, backface = true;
  double pixel_error = 1.0;
  /// Where the back-face test looks from the eye: over the whole sphere (true: conservative, the
  /// cone faces away from every point of it), or at the vertex alone, as Hoppe 1997 section 4.2
  /// and OpenMesh's VDPM make it (false: not conservative; a vertex near the silhouette can be
  /// judged facing away while part of its dual piece faces the eye).
  bool backface_over_sphere = true;
  /// Which normal cone the back-face test reads: that of every source triangle's normal below
  /// the node (false: Hoppe 1997 section 4.2's bound, Node::cone), or that of the source vertex
  /// normals below it (true: SelectiveIndex::vertex_cone, the kind OpenMesh's Analyzer computes;
  /// narrower, and not conservative: a triangle can face the eye while every vertex normal
  /// below faces away).
  bool vertex_normal_cones = false;
};

/// How a selected vertex's split gets the neighbourhood it needs: Kim & Lee's Table 2 compares
/// the two on the same hierarchy and criterion.
enum class SplitScheme {
  /// Kim & Lee 2001: any active vertex splits, its cut vertices found on the fly; only the
  /// degenerate case (section 4.4) forces a split first.
  kTrulySelective,
  /// Hoppe 1997 (its force_vsplit procedure): a split is made only when its `around` faces
  /// (fn0..fn3) are all active; the splits that make them, and the ancestors' splits that make
  /// those vertices active, are forced first, recursively. Its wings are then the cut vertices
  /// Kim & Lee's search finds (they are the vertices the fn faces meet at).
  kHoppe97,
};

struct SelectiveStats {
  std::uint64_t evaluated = 0;         // active vertices whose next split was tested
  std::uint64_t selected = 0;          // of those, splits the criterion asked for
  std::uint64_t splits = 0;            // splits made: selected + forced
  std::uint64_t degenerate_cases = 0;  // section 4.4: both cut vertices were one vertex
  std::uint64_t forced_splits = 0;     // splits made first for another: a degenerate case's,
                                       // or (SplitScheme::kHoppe97) a neighbourhood's
  std::uint64_t ops_read = 0;          // op reads through the source
  std::uint64_t vertices = 0, triangles = 0;
  std::uint64_t flipped_triangles = 0;  // normal against the source triangle's
  double displacement_bound = 0.0;      // max r over the output's vertices (the error bound above)
  double seconds = 0.0;
};

/// The state of a truly selective refinement: the mesh, its active nodes, and the operations.
class SelectiveRefinement {
 public:
  static constexpr std::uint32_t kNone = SelectiveIndex::kNone;
  /// The selective base mesh, positions read from `source` (R^0 and the spawning ops).
  SelectiveRefinement(const OpSource& source, std::shared_ptr<const SelectiveIndex> index,
                      SplitScheme scheme = SplitScheme::kTrulySelective);

  /// Refines every selected active vertex, coarsest split first, until none is selected.
  void refine(const RcfOracle& rcf);
  void refine(const NodeCriterion& criterion);
  /// vsplit_new (section 4.1): splits the active vertex v (it must have a split left), after
  /// the additional splits of a degenerate case. `forced` marks it as one of those. Whatever
  /// the scheme: refine() calls split_with_dependencies under kHoppe97; collapse() never checks
  /// Hoppe's ecol conditions.
  void split(std::uint32_t v, bool forced = false);
  /// Hoppe 1997's force_vsplit: splits active vertex v after every split its `around` faces
  /// need, and those that make them active, recursively (counted as forced). Under this scheme
  /// no degenerate case can arise (its wings are two edges of v with their faces present);
  /// one throws smr::Error (kInternal).
  void split_with_dependencies(std::uint32_t v);
  /// Whether split s's `around` faces are all in the mesh (Hoppe's condition for making it).
  bool neighbourhood_made(std::uint32_t s) const;
  /// ecol_new: collapses the active edge (v_t, v_u) of split `s` when both are active leaves of
  /// it (v_u not split since). Returns false, postponing it (section 4.4), when v_t and v_u have
  /// a common neighbour other than the edge's two opposite vertices.
  bool collapse(std::uint32_t s);
  std::uint64_t postponed_collapses() const { return postponed_; }

  /// The active node of vertex v (kNone: inactive).
  std::uint32_t node_of(std::uint32_t v) const { return node_of_[v]; }
  /// Whether the criterion selects active vertex v: it has a split left whose op is not
  /// completely finer than `rcf`.
  bool selected(std::uint32_t v, const RcfOracle& rcf) const;
  bool selected(std::uint32_t v, const NodeCriterion& criterion) const;
  const SplitMesh& mesh() const { return mesh_; }
  const SelectiveIndex& index() const { return *index_; }
  SplitScheme scheme() const { return scheme_; }
  static const char* scheme_name(SplitScheme scheme);  // "truly-selective", "hoppe97"
  /// The scheme of that name; throws smr::Error (kInvalidInput) naming `option` otherwise.
  static SplitScheme parse_scheme(const std::string& name, const std::string& option);
  /// Vertex ids of the output and the indexed mesh (positions of the active vertices).
  std::vector<std::uint32_t> active_vertices() const;
  TriangleMesh to_mesh(std::vector<std::uint32_t>* vertex_ids = nullptr) const;
  /// The statistics so far, with the output's counts, flips and displacement bound.
  SelectiveStats stats() const;
  /// Whether split s was made because the criterion selected it (not forced).
  const std::vector<std::uint8_t>& split_made() const { return made_; }  // 0, 1 selected, 2 forced

 private:
  // The criterion asked of node `node` whose next split reads `op`.
  using Select = std::function<bool(std::uint32_t node, const OpView& op)>;
  void refine_if(const Select& select);
  bool selected_if(std::uint32_t v, const Select& select) const;
  Select select_by(const NodeCriterion& c) const;
  OpRef read(OpId id) const;
  void activate(std::uint32_t node);
  std::uint32_t find_cut(std::uint32_t v, std::uint32_t fundamental) const;

  const OpSource& source_;
  std::shared_ptr<const SelectiveIndex> index_;
  SplitScheme scheme_;
  SplitMesh mesh_;
  std::vector<std::uint32_t> node_of_;
  std::vector<Vec3> pos_;
  std::vector<std::uint8_t> made_;
  std::vector<std::uint32_t> pending_;  // split ids to evaluate (a min-heap by op)
  mutable SelectiveStats stats_;
  std::uint64_t postponed_ = 0;
};

struct SelectiveExtraction {
  TriangleMesh mesh;
  std::vector<std::uint32_t> vertex_ids;  // per mesh vertex
  SelectiveStats stats;
};

/// Truly selective extraction from the base mesh: SelectiveRefinement::refine, then the mesh.
SelectiveExtraction extract_selective(const OpSource& source,
                                      std::shared_ptr<const SelectiveIndex> index,
                                      const RcfOracle& rcf,
                                      SplitScheme scheme = SplitScheme::kTrulySelective);
SelectiveExtraction extract_selective(const OpSource& source,
                                      std::shared_ptr<const SelectiveIndex> index,
                                      const NodeCriterion& criterion,
                                      SplitScheme scheme = SplitScheme::kTrulySelective);

}  // namespace smr
