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
  read_vertices();
  AssemblyOptions ao;
  ao.tmp_dir = opt_.tmp_dir;
  ao.sort_bytes = opt_.assembly_sort_bytes;
  ao.threads = opt_.threads;
  ao.progress = [this](double f) { report(0.9 + 0.1 * f); };
  assembler_ = std::make_unique<OpAssembler>(ao);
  auto faces =
      std::make_unique<storage::ExternalSorter<FaceRecord>>(opt_.tmp_dir, opt_.face_sort_bytes);
  sort_faces(*faces);
  stats_.seconds_sort = seconds_since(t0);
  const auto t1 = Clock::now();
  simplify_leaves(*faces);
  std::unordered_set<std::uint32_t>().swap(leaf_cells_);
  stats_.temp_bytes += faces->spilled_bytes();
  faces.reset();
  const auto t_tail = Clock::now();
  for (int l = 0; l < levels_; ++l) flush(l);
  stats_.seconds_tail = seconds_since(t_tail);
  // The octree spans are done with (the root locks nothing): the assembly may use the room.
  std::vector<std::uint32_t>().swap(vmin_);
  std::vector<std::uint32_t>().swap(vmax_);
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
void BlockPmBuilder::simplify_leaves(storage::ExternalSorter<FaceRecord>& faces) {
  struct Leaf {
    std::uint32_t cell = 0;
    std::vector<std::array<std::uint32_t, 3>> faces;
    BlockState state;
    SimplifiedBlock done;
  };
  FaceRecord f;
  bool more = faces.next(f);
  const unsigned threads = thread_count(opt_.threads);
  ordered_pipeline(
      leaf_cells_.size(), threads, threads + 1,
      [&](std::size_t) {
        if (!more) throw_internal("block PM: fewer leaf blocks than cells counted");
        auto leaf = std::make_unique<Leaf>();
        leaf->cell = f.cell;
        for (; more && f.cell == leaf->cell; more = faces.next(f)) leaf->faces.push_back(f.v);
        return leaf;
      },
      [&](Leaf& leaf) {
        reject_duplicate_faces(leaf.faces);
        leaf.state = leaf_state(leaf.faces);
        leaf.done = compute(0, leaf.state);
      },
      [&](Leaf& leaf, std::size_t) {
        for (BlockTriangle& t : leaf.state.tris) t.id = next_tri_++;
        ++stats_.leaf_blocks;
        push(0, leaf.cell, commit(std::move(leaf.state), std::move(leaf.done)));
        report(0.9 * double(leaf_done_ += leaf.faces.size()) / double(stats_.triangles));
      });
  if (more) throw_internal("block PM: more leaf blocks than cells counted");
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

void BlockPmBuilder::read_vertices() {
  pos_.reserve(mesh_.vertex_count());
  mesh_.vertices([&](std::span<const Vec3> batch) {
    for (const Vec3& p : batch) {
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        throw_input("mesh '" + mesh_.name() + "': vertex " + std::to_string(pos_.size()) +
                    " has a coordinate that is not finite");
      pos_.push_back(p);
      box_.add(p);
    }
  });
  if (pos_.size() >= kNone) throw_input("mesh '" + mesh_.name() + "': too many vertices");
  stats_.vertices = pos_.size();
}

// Leaf cells: the bounding cube split 2^levels_ times per axis, about leaf_triangles each.
void BlockPmBuilder::sort_faces(storage::ExternalSorter<FaceRecord>& faces) {
  const std::uint64_t nt = mesh_.triangle_count();
  if (nt == 0) throw_input("mesh '" + mesh_.name() + "' has no triangles");
  levels_ = 0;
  while (levels_ < 20 && (std::uint64_t{1} << (3 * levels_)) * opt_.leaf_triangles < nt) ++levels_;
  const Vec3 ext = box_.hi - box_.lo;
  side_ = std::max({ext.x, ext.y, ext.z, 1e-300});
  const double cells = double(std::uint64_t{1} << levels_);
  vmin_.assign(pos_.size(), ~std::uint32_t{0});
  vmax_.assign(pos_.size(), 0);
  std::uint64_t index = 0;
  std::uint32_t last_code = 0;
  mesh_.triangles([&](std::span<const std::array<std::uint32_t, 3>> batch) {
    for (const auto& t : batch) {
      for (std::uint32_t v : t) {
        if (v >= pos_.size())
          throw_input("mesh '" + mesh_.name() + "': triangle " + std::to_string(index) +
                      " names vertex " + std::to_string(v) + ", past the last (" +
                      std::to_string(pos_.size()) + " vertices)");
      }
      const Vec3 c = (pos_[t[0]] + pos_[t[1]] + pos_[t[2]]) / 3.0;
      std::uint32_t code = 0;
      for (int a = 0; a < 3; ++a) {
        const double u = (c[a] - box_.lo[a]) / side_ * cells;
        const auto k = static_cast<std::uint64_t>(std::clamp(u, 0.0, cells - 1.0));
        code |= static_cast<std::uint32_t>(spread3(k) << a);
      }
      for (std::uint32_t v : t) {
        vmin_[v] = std::min(vmin_[v], code);
        vmax_[v] = std::max(vmax_[v], code);
      }
      faces.add({code, t});
      if (index == 0 || code != last_code) leaf_cells_.insert(code);  // runs share a cell
      last_code = code;
      ++index;
    }
  });
  stats_.triangles = index;
  stats_.levels = levels_;
  for (std::uint32_t v = 0; v < pos_.size(); ++v) {
    if (vmax_[v] >= vmin_[v]) {
      referenced_box_.add(pos_[v]);
      ++referenced_;
    }
  }
  pending_.resize(levels_ + 1);
  pending_code_.assign(levels_ + 1, 0);
}

bool BlockPmBuilder::locked_at(std::uint32_t v, int level) const {
  return level < levels_ && (vmin_[v] >> (3 * level)) != (vmax_[v] >> (3 * level));
}

// A leaf's triangles (their ids are given when the leaf is handed over) and vertex quadrics.
BlockState BlockPmBuilder::leaf_state(const std::vector<std::array<std::uint32_t, 3>>& leaf) const {
  BlockState b;
  std::unordered_map<std::uint32_t, Quadric> quads;
  for (const auto& t : leaf) {
    b.tris.push_back({t, 0.0, kNone, 0});
    const Quadric q = face_quadric(pos_[t[0]], pos_[t[1]], pos_[t[2]]);
    for (std::uint32_t v : t) quads[v] += q;
  }
  b.quads.assign(quads.begin(), quads.end());
  std::sort(b.quads.begin(), b.quads.end(),
            [](const auto& x, const auto& y) { return x.first < y.first; });
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
  BlockState merged;
  std::vector<std::pair<std::uint32_t, Quadric>> quads;
  for (BlockState& b : pending_[level]) {
    merged.tris.insert(merged.tris.end(), b.tris.begin(), b.tris.end());
    quads.insert(quads.end(), b.quads.begin(), b.quads.end());
  }
  pending_[level].clear();
  std::stable_sort(quads.begin(), quads.end(),
                   [](const auto& x, const auto& y) { return x.first < y.first; });
  for (const auto& [v, q] : quads) {
    if (!merged.quads.empty() && merged.quads.back().first == v) {
      merged.quads.back().second += q;
    } else {
      merged.quads.push_back({v, q});
    }
  }
  push(level + 1, pending_code_[level] >> 3, simplify(level + 1, std::move(merged)));
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
  const std::size_t n = in.quads.size();
  std::vector<std::uint32_t> gid(n);
  std::vector<Vec3> pos(n);
  std::vector<Quadric> quad(n);
  std::vector<std::uint8_t> locked(n), constrain(n);
  std::unordered_map<std::uint32_t, std::uint32_t> local;
  local.reserve(n * 2);
  // Local vertices in Morton order (as the in-core builder's): neighbours close in memory.
  std::vector<std::pair<std::uint64_t, std::uint32_t>> order(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    order[i] = {morton_code(pos_[in.quads[i].first], box_.lo, Vec3(side_)), i};
  }
  std::sort(order.begin(), order.end());
  for (std::uint32_t i = 0; i < n; ++i) {
    const auto& [v, q] = in.quads[order[i].second];
    gid[i] = v;
    pos[i] = pos_[v];
    quad[i] = q;
    locked[i] = locked_at(v, level) ? 1 : 0;
    constrain[i] = level == 0 || locked_at(v, level - 1) ? 1 : 0;
    local.emplace(v, i);
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
  out.rounds = simplify_block(level, *out.s);
  out.gid = std::move(gid);
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
  const CollapseLog& log = done.s->log;
  const std::vector<std::uint32_t>& gid = done.gid;
  const std::size_t n = gid.size();
  const std::uint32_t k0 = static_cast<std::uint32_t>(assembler_->removals());
  const std::size_t n_in = in.tris.size();
  std::vector<std::uint32_t> id_of(m.tris.size()), creator_of(m.tris.size());
  for (std::size_t t = 0; t < n_in; ++t) {
    id_of[t] = in.tris[t].id;
    creator_of[t] = in.tris[t].creator;
  }
  std::vector<OpAssembler::StarTriangle> star;
  std::vector<OpAssembler::MadeTriangle> made;
  for (std::uint32_t c = 0; c < log.collapses.size(); ++c) {
    const Collapse& col = log.collapses[c];
    star.clear();
    for (std::uint32_t i = col.old_begin; i < col.old_end; ++i) {
      const std::uint32_t t = log.old_tris[i];
      const Tri& x = m.tris[t];
      star.push_back({{gid[x.v[0]], gid[x.v[1]], gid[x.v[2]]}, id_of[t], creator_of[t], false});
    }
    made.clear();
    for (std::uint32_t i = col.new_begin; i < col.new_end; ++i) {
      const std::uint32_t t = log.new_tris[i];
      const Tri& x = m.tris[t];
      id_of[t] = next_tri_++;
      creator_of[t] = k0 + c;
      made.push_back({{gid[x.v[0]], gid[x.v[1]], gid[x.v[2]]}, id_of[t], false});
    }
    const std::uint32_t removed = gid[col.removed];
    assembler_->add_removal(std::span(&removed, 1), star, made, col.error);
  }
  stats_.collapses += log.collapses.size();
  stats_.rejected_intersection += done.s->stats.rejected_intersection;
  BlockState out;
  std::vector<std::uint8_t> used(n, 0);
  for (std::uint32_t t = 0; t < m.tris.size(); ++t) {
    const Tri& x = m.tris[t];
    if (x.destroyer != kNone) continue;
    out.tris.push_back({{gid[x.v[0]], gid[x.v[1]], gid[x.v[2]]}, x.e, creator_of[t], id_of[t]});
    for (std::uint32_t v : x.v) used[v] = 1;
  }
  for (std::uint32_t i = 0; i < n; ++i) {
    if (used[i]) out.quads.push_back({gid[i], m.quad[i]});
  }
  return out;
}

void BlockPmBuilder::finish(const BlockState& root, OpSink& sink) {
  CrmrInfo info;
  info.kind = ModelKind::kMesh3d;
  info.source = mesh_.name();
  info.builder = "block-pm leaf-triangles=" + std::to_string(opt_.leaf_triangles) +
                 " tolerance-fraction=" + std::to_string(opt_.tolerance_fraction) +
                 " max-normal-turn=" + std::to_string(opt_.max_normal_turn_degrees) +
                 " boundary-weight=" + std::to_string(opt_.boundary_weight);
  std::vector<std::uint8_t> used(pos_.size(), 0);
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
  for (const BlockTriangle& t : root.tris) {
    for (std::uint32_t v : t.v) used[v] = 1;
  }
  stats_.base_triangles = base.size();
  stats_.base_vertices = static_cast<std::uint64_t>(std::count(used.begin(), used.end(), 1));
  info.err_final = 0.0;
  assembler_->finish(
      info, base, [this](std::uint32_t v) { return pos_[v]; }, sink);
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
