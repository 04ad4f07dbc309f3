// The out-of-core mesh builder (block_pm.h; Hoppe 1998's block construction in 3-D;
// De Floriani et al.'s independent-set decimation within each block).
#include "smr/builders/mesh/block_pm.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <span>
#include <string>
#include <unordered_map>

#include "base/error.h"
#include "smr/builders/mesh/morton_order.h"
#include "smr/builders/mesh/qem_rounds.h"
#include "smr/core/clock.h"
#include "smr/core/parallel.h"

namespace smr::qem {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Both triangles with a directed edge meet in one block by the level that unlocks its ends,
// before any collapse touches them: the streamed mesh's manifold-edge and orientation check.
// Returns the block's directed edges.
IdMap<std::uint8_t> check_edges(const PmMesh& m, const std::string& what,
                                const std::vector<std::uint32_t>& ids) {
  std::uint64_t twice = kNoEdge;
  auto directed = directed_edges(m, &twice);
  if (twice != kNoEdge) {
    throw_input("mesh '" + what + "': the edge from vertex " + std::to_string(ids[twice >> 32]) +
                " to vertex " + std::to_string(ids[twice & 0xffffffffu]) +
                " is used twice in the same direction (a non-manifold edge or inconsistent "
                "orientation); ingest it in memory (without --memory) with --repair");
  }
  return directed;
}

// A block's simplification: local vertices with their (partial) quadrics and locks, triangles
// with their bounds. `constrain[v]`: v was locked one level below, so open edges of v's that
// now have an unlocked end get their boundary constraint planes here.
void load_block(Simplification& s, const QemPmOptions& options, std::vector<Vec3> pos,
                std::vector<Quadric> quad, std::vector<std::uint8_t> locked,
                const std::vector<std::uint8_t>& constrain, const std::vector<Tri>& tris,
                const std::string& what, const std::vector<std::uint32_t>& ids) {
  PmMesh& m = s.mesh;
  m.pos = std::move(pos);
  m.quad = std::move(quad);
  m.locked = std::move(locked);
  init_arrays(m, tris.size());
  init_simplification(s, options);
  for (const Tri& t : tris) add_triangle(m, t);
  const auto directed = check_edges(m, what, ids);
  // A vertex unlocked here for the first time (all of them in a leaf block: constrain is set
  // at level 0) has all its faces in this block; collapses below kept its star's fans apart or
  // together as they were, so this is the streamed mesh's non-manifold vertex check.
  for (std::uint32_t v = 0; v < m.pos.size(); ++v) {
    if (m.locked[v] || !constrain[v] || fans(m, v) <= 1) continue;
    throw_input("mesh '" + what + "': vertex " + std::to_string(ids[v]) +
                " is non-manifold: its faces form more than one fan (they share it but are "
                "not connected through edges around it); expected one fan per vertex; ingest "
                "it in memory (without --memory) with --repair, which splits it");
  }
  for (const Tri& t : m.tris) {
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = t.v[k], b = t.v[(k + 1) % 3];
      if (directed.contains(edge_key(b, a))) continue;
      m.boundary[a] = m.boundary[b] = 1;  // exact for unlocked vertices (all their faces are here)
      if ((m.locked[a] && m.locked[b]) || !(constrain[a] && constrain[b])) continue;
      add_constraint(m, t, k, options.boundary_weight);
    }
  }
  init_components(m);
}

}  // namespace

BlockPmBuilder::BlockPmBuilder(const MeshStream& mesh, const BlockPmOptions& options,
                               BlockPmStats& stats)
    : mesh_(mesh), opt_(options), stats_(stats) {
  if (!(options.tolerance_fraction > 0.0) || !std::isfinite(options.tolerance_fraction))
    throw_input("block PM: the tolerance fraction must be positive");
  if (options.leaf_triangles < 16) throw_input("block PM: leaf blocks need at least 16 triangles");
  qem_.max_normal_turn_degrees = options.max_normal_turn_degrees;
  qem_.boundary_weight = options.boundary_weight;
  qem_.allow_self_intersections = options.allow_self_intersections;
  qem_.spawn_components = false;
  qem_.threads = 1;  // leaves run on several threads, each block on one
  if (!(qem_.max_normal_turn_degrees > 0.0 && qem_.max_normal_turn_degrees <= 180.0))
    throw_input("block PM: max normal turn must be in (0, 180] degrees");
}

void BlockPmBuilder::run(OpSink& sink) {
  const auto t0 = Clock::now();
  // The three sorts of the input and the vertex cache share face_sort_bytes (two sorts and the
  // cache are alive at once).
  BlockInputOptions io;
  io.tmp_dir = opt_.tmp_dir;
  io.leaf_triangles = opt_.leaf_triangles;
  io.sort_bytes = opt_.face_sort_bytes / 2;
  io.vertex_cache_bytes = opt_.face_sort_bytes / 2;
  auto input = std::make_unique<BlockInput>(mesh_, io);
  box_ = input->box();
  side_ = input->side();
  levels_ = input->levels();
  referenced_box_ = input->referenced_box();
  referenced_ = input->referenced();
  stats_.vertices = input->vertices();
  stats_.triangles = input->triangles();
  stats_.levels = levels_;
  pending_.resize(levels_ + 1);
  pending_code_.assign(levels_ + 1, 0);
  AssemblyOptions ao;
  ao.tmp_dir = opt_.tmp_dir;
  ao.sort_bytes = opt_.assembly_sort_bytes;
  ao.table_bytes = opt_.assembly_table_bytes;
  ao.threads = opt_.threads;
  ao.progress = [this](double f) { report(0.9 + 0.1 * f); };
  assembler_ = std::make_unique<OpAssembler>(ao);
  stats_.seconds_sort = seconds_since(t0);
  const auto t1 = Clock::now();
  simplify_leaves(*input);
  stats_.temp_bytes += input->temp_bytes();
  input.reset();
  const auto t_tail = Clock::now();
  for (int l = 0; l < levels_; ++l) flush(l);
  stats_.seconds_tail = seconds_since(t_tail);
  if (pending_[levels_].size() != 1) throw_internal("block PM: the root block is missing");
  BlockState root = std::move(pending_[levels_].front());
  stats_.seconds_blocks = seconds_since(t1);
  const auto t2 = Clock::now();
  finish(root, sink);
  stats_.seconds_assemble = seconds_since(t2);
}

void BlockPmBuilder::report(double f) const {
  if (opt_.progress) opt_.progress(std::clamp(f, 0.0, 1.0));
}

// Leaf blocks are read in Morton order, simplified on the workers and handed over in order
// (parents are made as their last child is handed over, on this thread, while the workers go
// on with the next leaves): the database does not depend on the number of threads.
void BlockPmBuilder::simplify_leaves(BlockInput& input) {
  struct Leaf {
    LeafInput in;
    BlockState state;
    SimplifiedBlock done;
  };
  const unsigned threads = thread_count(opt_.threads);
  ordered_pipeline(
      input.leaf_cells(), threads, threads + 1,
      [&](std::size_t) {
        auto leaf = std::make_unique<Leaf>();
        if (!input.next_leaf(leaf->in))
          throw_internal("block PM: fewer leaf blocks than cells counted");
        return leaf;
      },
      [&](Leaf& leaf) {
        reject_duplicate_faces(leaf.in.faces);
        leaf.state = leaf_state(leaf.in);
        leaf.done = compute(0, leaf.state);
      },
      [&](Leaf& leaf, std::size_t) {
        for (BlockTriangle& t : leaf.state.tris) t.id = next_tri_++;
        ++stats_.leaf_blocks;
        const std::size_t faces = leaf.in.faces.size();
        const std::uint32_t cell = leaf.in.cell;
        leaf.in = LeafInput();
        push(0, cell, commit(std::move(leaf.state), std::move(leaf.done)));
        report(0.9 * double(leaf_done_ += faces) / double(stats_.triangles));
      });
  LeafInput rest;
  if (input.next_leaf(rest)) throw_internal("block PM: more leaf blocks than cells counted");
}

// Two faces on the same three vertices (in either orientation: a "pillow" is a closed surface
// of two triangles) are a user error, as read_mesh says in memory. They have the same
// centroid, so they meet in one leaf block.
void BlockPmBuilder::reject_duplicate_faces(
    const std::vector<std::array<std::uint32_t, 3>>& faces) const {
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

// A vertex is locked at `level` while its triangles span more than one block of the level.
bool BlockPmBuilder::locked_at(const BlockVertex& v, int level) const {
  return level < levels_ && (v.lo >> (3 * level)) != (v.hi >> (3 * level));
}

// A leaf's triangles (their ids are given when the leaf is handed over) and vertex quadrics.
BlockState BlockPmBuilder::leaf_state(const LeafInput& leaf) const {
  BlockState b;
  b.verts.resize(leaf.verts.size());
  for (std::size_t i = 0; i < leaf.verts.size(); ++i) {
    const LeafVertex& v = leaf.verts[i];
    b.verts[i] = {v.id, v.lo, v.hi, v.pos, Quadric()};
  }
  auto at = [&](std::uint32_t v) -> BlockVertex& {
    const auto it =
        std::lower_bound(b.verts.begin(), b.verts.end(), v,
                         [](const BlockVertex& x, std::uint32_t id) { return x.id < id; });
    if (it == b.verts.end() || it->id != v)
      throw_internal("block PM: a leaf triangle's vertex is not among the leaf's vertices");
    return *it;
  };
  for (const auto& t : leaf.faces) {
    b.tris.push_back({t, 0.0, kNone, 0});
    std::array<BlockVertex*, 3> c{&at(t[0]), &at(t[1]), &at(t[2])};
    const Quadric q = face_quadric(c[0]->pos, c[1]->pos, c[2]->pos);
    for (BlockVertex* v : c) v->quad += q;
  }
  return b;
}

// A block of `level` done: it waits for its siblings; a parent is made when the next block
// belongs to another parent (blocks come in Morton order).
void BlockPmBuilder::push(int level, std::uint64_t code, BlockState b) {
  if (level < levels_ && !pending_[level].empty() && (code >> 3) != pending_code_[level] >> 3) {
    flush(level);
  }
  pending_[level].push_back(std::move(b));
  pending_code_[level] = code;
}

void BlockPmBuilder::flush(int level) {
  if (pending_[level].empty()) return;
  push(level + 1, pending_code_[level] >> 3, simplify(level + 1, merge(level)));
}

// The pending blocks of `level` as one (their children's copies freed before it is simplified:
// a parent's simplification may flush the levels above it in turn).
BlockState BlockPmBuilder::merge(int level) {
  BlockState merged;
  std::vector<BlockVertex> verts;
  for (BlockState& b : pending_[level]) {
    merged.tris.insert(merged.tris.end(), b.tris.begin(), b.tris.end());
    verts.insert(verts.end(), b.verts.begin(), b.verts.end());
  }
  pending_[level].clear();
  std::stable_sort(verts.begin(), verts.end(),
                   [](const BlockVertex& x, const BlockVertex& y) { return x.id < y.id; });
  for (const BlockVertex& v : verts) {
    if (!merged.verts.empty() && merged.verts.back().id == v.id) {
      merged.verts.back().quad += v.quad;
    } else {
      merged.verts.push_back(v);
    }
  }
  return merged;
}

// Simplifies one block and hands its collapses to the assembler.
BlockState BlockPmBuilder::simplify(int level, BlockState in) {
  SimplifiedBlock done = compute(level, in);
  BlockState out = commit(std::move(in), std::move(done));
  if (level < levels_) {
    stats_.max_handed_triangles =
        std::max<std::uint64_t>(stats_.max_handed_triangles, out.tris.size());
  }
  return out;
}

// A block simplified, not yet handed over: reads only what stays fixed while blocks are made
// (positions, octree spans, options), so blocks of a level run on several threads.
SimplifiedBlock BlockPmBuilder::compute(int level, const BlockState& in) const {
  SimplifiedBlock out = load(level, in);  // its tables of the block's vertices freed
  out.rounds = simplify_block(level, *out.s);
  return out;
}

// The block's simplification, loaded (local vertices in Morton order), not run yet.
SimplifiedBlock BlockPmBuilder::load(int level, const BlockState& in) const {
  const std::size_t n = in.verts.size();
  std::vector<std::uint32_t> gid(n), src(n);
  std::vector<Vec3> pos(n);
  std::vector<Quadric> quad(n);
  std::vector<std::uint8_t> locked(n), constrain(n);
  std::unordered_map<std::uint32_t, std::uint32_t> local;
  local.reserve(n * 2);
  // Local vertices in Morton order (as the in-core builder's): neighbours close in memory.
  std::vector<std::pair<std::uint64_t, std::uint32_t>> order(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    order[i] = {morton_code(in.verts[i].pos, box_.lo, Vec3(side_)), i};
  }
  std::sort(order.begin(), order.end());
  for (std::uint32_t i = 0; i < n; ++i) {
    const BlockVertex& v = in.verts[order[i].second];
    gid[i] = v.id;
    src[i] = order[i].second;
    pos[i] = v.pos;
    quad[i] = v.quad;
    locked[i] = locked_at(v, level) ? 1 : 0;
    constrain[i] = level == 0 || locked_at(v, level - 1) ? 1 : 0;
    local.emplace(v.id, i);
  }
  std::vector<Tri> tris;
  tris.reserve(in.tris.size());
  for (const BlockTriangle& t : in.tris) {
    Tri lt;
    for (int k = 0; k < 3; ++k) lt.v[k] = local.at(t.v[k]);
    lt.e = t.e;
    tris.push_back(lt);
  }
  SimplifiedBlock out;
  out.s = std::make_unique<Simplification>();
  load_block(*out.s, qem_, std::move(pos), std::move(quad), std::move(locked), constrain, tris,
             mesh_.name(), gid);
  out.gid = std::move(gid);
  out.src = std::move(src);
  return out;
}

// Collapses up to tolerance_fraction of the block's side (the root: as far as the rules
// allow), cheapest quadric cost first within the bound, as the in-core builder orders them.
// The tolerance rises in steps of 2 from an 8th of it, so that within a block collapses with
// small bounds go first: a collapse's bound is at least those of the collapses it depends on,
// and one early large bound would raise all that come after it in its region. The root goes on
// doubling up to the model's size, then as far as the rules allow. Returns the rounds made.
std::uint64_t BlockPmBuilder::simplify_block(int level, Simplification& s) const {
  Rounds r;
  std::uint64_t rounds = 0;
  const int below = std::min(level, levels_ - 1);
  const double top =
      opt_.tolerance_fraction * side_ / double(std::uint64_t{1} << (levels_ - below));
  const double last = level == levels_ ? side_ : top;
  for (double t = top / 8.0; t <= last; t *= 2.0) rounds += simplify_rounds(s, r, t);
  if (level == levels_) rounds += simplify_rounds(s, r, kInfinity);
  // A block hands its parent at most leaf_triangles triangles (so that a block above the
  // leaves holds at most 8 times that): past `top`, the tolerance goes on doubling until it
  // does, or until the rules allow no more.
  for (double t = 2.0 * top; level < levels_ && alive_triangles(s.mesh) > opt_.leaf_triangles;
       t *= 2.0) {
    const std::uint64_t made = simplify_rounds(s, r, t);
    rounds += made;
    if (made == 0 && t > side_) break;  // the rules allow no more
  }
  return rounds;
}

// Hands a simplified block's collapses to the assembler, in order, as removals (new triangles
// get the next global ids), and returns what the block passes to its parent. In block order.
BlockState BlockPmBuilder::commit(BlockState in, SimplifiedBlock done) {
  stats_.max_block_triangles = std::max<std::uint64_t>(stats_.max_block_triangles, in.tris.size());
  stats_.rounds += done.rounds;
  const PmMesh& m = done.s->mesh;
  const std::vector<std::uint32_t>& gid = done.gid;
  const std::size_t n = gid.size();
  const std::size_t n_in = in.tris.size();
  std::vector<std::uint32_t> id_of(m.tris.size()), creator_of(m.tris.size());
  for (std::size_t t = 0; t < n_in; ++t) {
    id_of[t] = in.tris[t].id;
    creator_of[t] = in.tris[t].creator;
  }
  add_removals(*done.s, gid, id_of, creator_of);
  BlockState out;
  std::vector<std::uint8_t> used(n, 0);
  for (std::uint32_t t = 0; t < m.tris.size(); ++t) {
    const Tri& x = m.tris[t];
    if (x.destroyer != kNone) continue;
    out.tris.push_back({{gid[x.v[0]], gid[x.v[1]], gid[x.v[2]]}, x.e, creator_of[t], id_of[t]});
    for (std::uint32_t v : x.v) used[v] = 1;
  }
  std::vector<std::uint32_t> kept;  // local vertices handed over, by global id
  for (std::uint32_t i = 0; i < n; ++i) {
    if (used[i]) kept.push_back(i);
  }
  std::sort(kept.begin(), kept.end(),
            [&](std::uint32_t a, std::uint32_t b) { return gid[a] < gid[b]; });
  out.verts.reserve(kept.size());
  for (std::uint32_t i : kept) {
    out.verts.push_back(in.verts[done.src[i]]);
    out.verts.back().quad = m.quad[i];
  }
  return out;
}

// The block's collapses to the assembler, each with its star's positions (by global id).
// id_of / creator_of: per local triangle, its global id and the removal that made it.
void BlockPmBuilder::add_removals(const Simplification& s, const std::vector<std::uint32_t>& gid,
                                  std::vector<std::uint32_t>& id_of,
                                  std::vector<std::uint32_t>& creator_of) {
  const PmMesh& m = s.mesh;
  const CollapseLog& log = s.log;
  const std::uint32_t k0 = static_cast<std::uint32_t>(assembler_->removals());
  std::vector<OpAssembler::StarTriangle> star;
  std::vector<OpAssembler::MadeTriangle> made;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> corners;  // global, local
  std::vector<Vec3> positions;
  for (std::uint32_t c = 0; c < log.collapses.size(); ++c) {
    const Collapse& col = log.collapses[c];
    star.clear();
    corners.clear();
    for (std::uint32_t i = col.old_begin; i < col.old_end; ++i) {
      const std::uint32_t t = log.old_tris[i];
      const Tri& x = m.tris[t];
      star.push_back({{gid[x.v[0]], gid[x.v[1]], gid[x.v[2]]}, id_of[t], creator_of[t], false});
      for (std::uint32_t v : x.v) corners.push_back({gid[v], v});
    }
    std::sort(corners.begin(), corners.end());
    corners.erase(std::unique(corners.begin(), corners.end()), corners.end());
    positions.clear();
    for (const auto& [g, v] : corners) positions.push_back(m.pos[v]);
    made.clear();
    for (std::uint32_t i = col.new_begin; i < col.new_end; ++i) {
      const std::uint32_t t = log.new_tris[i];
      const Tri& x = m.tris[t];
      id_of[t] = next_tri_++;
      creator_of[t] = k0 + c;
      made.push_back({{gid[x.v[0]], gid[x.v[1]], gid[x.v[2]]}, id_of[t], false});
    }
    const std::uint32_t removed = gid[col.removed];
    assembler_->add_removal(std::span(&removed, 1), star, made, col.error, positions);
  }
  stats_.collapses += log.collapses.size();
  stats_.rejected_intersection += s.stats.rejected_intersection;
}

void BlockPmBuilder::finish(const BlockState& root, OpSink& sink) {
  CrmrInfo info;
  info.kind = ModelKind::kMesh3d;
  info.source = mesh_.name();
  info.builder = "block-pm leaf-triangles=" + std::to_string(opt_.leaf_triangles) +
                 " tolerance-fraction=" + std::to_string(opt_.tolerance_fraction) +
                 " max-normal-turn=" + std::to_string(opt_.max_normal_turn_degrees) +
                 " boundary-weight=" + std::to_string(opt_.boundary_weight);
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
  stats_.base_triangles = base.size();
  stats_.base_vertices = root.verts.size();  // commit() hands over the used ones only
  info.err_final = 0.0;
  // Every op's positions ride with its record; R^0's are the root's vertices.
  const auto position = [&root](std::uint32_t v) {
    const auto it =
        std::lower_bound(root.verts.begin(), root.verts.end(), v,
                         [](const BlockVertex& x, std::uint32_t id) { return x.id < id; });
    if (it == root.verts.end() || it->id != v)
      throw_internal("block PM: a vertex without a position: not in the root block");
    return it->pos;
  };
  assembler_->finish(info, base, position, sink);
  stats_.dag_height = assembler_->stats().dag_height;
  stats_.seconds_join = assembler_->stats().seconds_join;
  stats_.seconds_emit = assembler_->stats().seconds_emit;
  stats_.temp_bytes += assembler_->stats().scratch_bytes;
  report(1.0);
}

}  // namespace smr::qem

namespace smr {

void build_block_pm(const MeshStream& mesh, OpSink& sink, const BlockPmOptions& options,
                    BlockPmStats* stats) {
  BlockPmStats local;
  qem::BlockPmBuilder(mesh, options, stats != nullptr ? *stats : local).run(sink);
}

Crmr build_block_pm(const MeshStream& mesh, const BlockPmOptions& options, BlockPmStats* stats) {
  CrmrCollector collector;
  build_block_pm(mesh, collector, options, stats);
  return collector.take();
}

}  // namespace smr
