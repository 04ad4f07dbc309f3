// The block TIN builder's level decimation; block_tin_levels.h describes it.
#include "smr/builders/terrain/block_tin_levels.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "base/error.h"
#include "smr/core/parallel.h"

namespace smr::block_tin {
namespace {

/// One level's decimation of a mesh: stages of growing error tolerance, each of rounds that
/// remove an independent set of candidates, cheapest first.
class LevelDecimation {
 public:
  LevelDecimation(const Setup& setup, Mesh& mesh, DecimationScratch& scratch, BlockTinStats& stats,
                  int level, const BlockWindow& window)
      : setup_(setup), mesh_(mesh), s_(scratch), stats_(stats), level_(level), window_(window) {}

  void run(const std::vector<std::uint32_t>* only) {
    take_candidates(only);
    const bool root = level_ >= setup_.grid.levels;
    const double eps0 = setup_.eps0;
    const double top = eps0 * std::ldexp(1.0, 2 * (level_ + 1));
    double eps = level_ == 0 ? eps0 : eps0 * std::ldexp(1.0, 2 * level_);
    for (;;) {
      eps = root ? eps * std::sqrt(2.0) : std::min(top, eps * std::sqrt(2.0));
      const std::uint64_t removed_in_stage = stage(eps);
      cand_.erase(std::remove_if(cand_.begin(), cand_.end(),
                                 [&](std::uint32_t v) { return mesh_.verts[v].tri == kNone; }),
                  cand_.end());
      double cheapest_left = kInfeasible;
      if (root && removed_in_stage == 0) {
        for (std::uint32_t v : cand_) {
          if (s_.dirty[v] == 1) estimate(v);
          cheapest_left = std::min(cheapest_left, s_.cost[v]);
        }
      }
      if (!root && eps >= top) break;
      if (root && removed_in_stage == 0) {
        if (cheapest_left == kInfeasible) break;
        eps = std::max(eps, cheapest_left / std::sqrt(2.0));
      }
    }
  }

 private:
  /// The level's candidates: the live vertices of `only` (a block's), or of the whole mesh, that
  /// are not locked; marked, and their costs to be estimated.
  void take_candidates(const std::vector<std::uint32_t>* only) {
    const std::vector<MVert>& verts = mesh_.verts;
    if (only != nullptr) {
      for (std::uint32_t v : *only) {
        if (verts[v].tri != kNone && !setup_.grid.locked(verts[v], level_)) cand_.push_back(v);
      }
    } else {
      for (std::uint32_t v = 0; v < verts.size(); ++v) {
        if (verts[v].tri != kNone && !setup_.grid.locked(verts[v], level_)) cand_.push_back(v);
      }
    }
    std::sort(cand_.begin(), cand_.end());
    s_.cost.resize(verts.size());
    s_.dirty.resize(verts.size());
    s_.stamp.resize(verts.size(), 0);
    for (std::uint32_t v : cand_) s_.dirty[v] = 1;
    ++s_.cand_stamp;
    s_.cand_mark.resize(verts.size(), 0);
    s_.seen.resize(verts.size(), 0);
    for (std::uint32_t v : cand_) s_.cand_mark[v] = s_.cand_stamp;
  }

  /// v's cost estimated (its star changed).
  void estimate(std::uint32_t v) {
    plan_removal(setup_, mesh_, s_.removal.clip, v, p_, window_, true);
    s_.cost[v] = p_.err;
    s_.dirty[v] = p_.lower_bound ? 2 : 0;
  }

  /// The rounds of the stage of tolerance eps, until no vertex is within it; how many vertices
  /// they removed.
  std::uint64_t stage(double eps) {
    std::uint64_t removed = 0;
    // A round looks only at vertices that may be removed: those within eps or whose star
    // changed in the last round; the others cannot change until a neighbour goes.
    active_.clear();
    for (std::uint32_t v : cand_) {
      if (mesh_.verts[v].tri != kNone) active_.push_back(v);
    }
    for (;;) {
      order_.clear();
      for (std::uint32_t v : active_) {
        if (mesh_.verts[v].tri == kNone) continue;
        if (s_.dirty[v] == 1) estimate(v);
        if (s_.cost[v] <= eps) order_.push_back({s_.cost[v], v});
      }
      if (order_.empty()) break;
      const std::size_t n = round(eps);
      if (n == 0) continue;
      removed += n;
      ++stats_.rounds;
    }
    return removed;
  }

  /// One round over order_ (the active vertices within eps): removes an independent set and
  /// makes the vertices the next round looks at active_; how many it removed.
  std::size_t round(double eps) {
    std::sort(order_.begin(), order_.end());
    ++s_.round_stamp;
    // An independent set, cheapest first: no two removed vertices are adjacent, so each
    // star is untouched by the others' removals and its plan stays valid.
    std::size_t n = 0;
    for (const auto& [c, v] : order_) {
      if (s_.stamp[v] == s_.round_stamp) continue;
      if (n == chosen_.size()) chosen_.emplace_back();
      Plan& q = chosen_[n].second;
      plan_removal(setup_, mesh_, s_.removal.clip, v, q, window_, false, eps);
      s_.cost[v] = q.err;
      s_.dirty[v] = q.lower_bound ? 2 : 0;
      if (q.err > eps) continue;
      chosen_[n++].first = v;
      s_.stamp[v] = s_.round_stamp;
      for (std::uint32_t u : q.poly) s_.stamp[u] = s_.round_stamp;
    }
    ++s_.seen_stamp;
    next_.clear();
    for (std::size_t i = 0; i < n; ++i) {
      const Plan& q = chosen_[i].second;
      apply_removal(setup_.grid, mesh_, s_.removal, chosen_[i].first, q, stats_);
      for (std::uint32_t u : q.poly) {
        s_.dirty[u] = 1;
        if (s_.cand_mark[u] == s_.cand_stamp && s_.seen[u] != s_.seen_stamp) {
          s_.seen[u] = s_.seen_stamp;
          next_.push_back(u);
        }
      }
    }
    for (const auto& [c, v] : order_) {
      if (mesh_.verts[v].tri != kNone && s_.cost[v] <= eps && s_.seen[v] != s_.seen_stamp) {
        s_.seen[v] = s_.seen_stamp;
        next_.push_back(v);
      }
    }
    std::sort(next_.begin(), next_.end());
    active_.swap(next_);
    return n;
  }

  const Setup& setup_;
  Mesh& mesh_;
  DecimationScratch& s_;
  BlockTinStats& stats_;
  const int level_;
  const BlockWindow window_;
  Plan p_;  // estimates'
  std::vector<std::pair<double, std::uint32_t>> order_;
  std::vector<std::pair<std::uint32_t, Plan>> chosen_;
  std::vector<std::uint32_t> active_, next_, cand_;
};

std::unique_ptr<UpperBlock> copy_block(const Mesh& whole, int level,
                                       std::vector<std::uint32_t>&& tris,
                                       const std::vector<std::uint32_t>& cand) {
  auto block = std::make_unique<UpperBlock>();
  UpperBlock& u = *block;
  u.level = level;
  Mesh& b = u.mesh;
  b.tol = whole.tol;
  u.gtris = std::move(tris);
  for (std::uint32_t t : u.gtris)
    u.gverts.insert(u.gverts.end(), whole.tris[t].v.begin(), whole.tris[t].v.end());
  std::sort(u.gverts.begin(), u.gverts.end());
  u.gverts.erase(std::unique(u.gverts.begin(), u.gverts.end()), u.gverts.end());
  auto local_of = [](const std::vector<std::uint32_t>& ids, std::uint32_t g) {
    const auto it = std::lower_bound(ids.begin(), ids.end(), g);
    return it != ids.end() && *it == g ? std::uint32_t(it - ids.begin()) : kNone;
  };
  b.verts.reserve(u.gverts.size());
  u.first_tri.reserve(u.gverts.size());
  for (std::uint32_t g : u.gverts) {
    MVert v = whole.verts[g];
    v.tri = v.tri == kNone ? kNone : local_of(u.gtris, v.tri);
    u.first_tri.push_back(v.tri);
    b.verts.push_back(v);
  }
  for (std::uint32_t t : u.gtris) {
    const MTri& g = whole.tris[t];
    MTri m;
    for (int k = 0; k < 3; ++k) {
      m.v[k] = local_of(u.gverts, g.v[k]);
      m.nbr[k] = g.nbr[k] == kNone ? kNone : local_of(u.gtris, g.nbr[k]);
      if (g.nbr[k] != kNone && m.nbr[k] == kNone) {
        u.border_owner[edge_key(g.v[k], g.v[(k + 1) % 3])] = t;
      }
    }
    m.bound = g.bound;
    m.is_void = g.is_void;
    b.tris.push_back(m);
  }
  u.cand.reserve(cand.size());
  for (std::uint32_t g : cand) {
    const std::uint32_t l = local_of(u.gverts, g);
    if (l != kNone) u.cand.push_back(l);  // none of its triangles is in this copy
  }
  return block;
}

}  // namespace

void decimate_level(const Setup& setup, Mesh& mesh, DecimationScratch& scratch,
                    BlockTinStats& stats, int level, const BlockWindow& window,
                    const std::vector<std::uint32_t>* only) {
  LevelDecimation(setup, mesh, scratch, stats, level, window).run(only);
}

std::unique_ptr<UpperBlock> setup_block(const Setup& setup, const Mesh& whole, BlockTinStats& stats,
                                        int level, int c0, int r0, int span,
                                        std::vector<std::uint32_t>&& tris,
                                        const std::vector<std::uint32_t>& cand) {
  auto block = copy_block(whole, level, std::move(tris), cand);
  const int W = setup.grid.W, H = setup.grid.H;
  block->c0 = c0;
  block->r0 = r0;
  block->w = std::min(c0 + span, W - 1) - c0 + 1;
  block->h = std::min(r0 + span, H - 1) - r0 + 1;
  stats.max_block_samples =
      std::max<std::uint64_t>(stats.max_block_samples, std::uint64_t(block->w) * block->h);
  if (level > 0) stats.samples_rescanned += std::uint64_t(block->w) * std::uint64_t(block->h);
  return block;
}

void decimate_block(const Setup& setup, const SampleSpill& spill, UpperBlock& block) {
  DecimationScratch scratch;
  if (block.samples.width != 0) {
    decimate_level(setup, block.mesh, scratch, block.stats, block.level,
                   BlockWindow{&block.samples, block.c0, block.r0}, &block.cand);
    return;
  }
  Heightfield& w = window_buffer();
  spill.read_into(w, block.c0, block.r0, block.w, block.h, setup.dem);
  decimate_level(setup, block.mesh, scratch, block.stats, block.level,
                 BlockWindow{&w, block.c0, block.r0}, &block.cand);
}

void merge_block(Mesh& whole, UpperBlock& u, BlockTinStats& stats) {
  Mesh& b = u.mesh;
  const auto ncopy = static_cast<std::uint32_t>(u.gtris.size());
  const auto tri_base = static_cast<std::uint32_t>(whole.tris.size());
  const auto rem_base = static_cast<std::uint32_t>(whole.removals.size());
  const auto star_base = static_cast<std::uint32_t>(whole.star_ids.size());
  auto tri = [&](std::uint32_t t) {
    return t == kNone ? kNone : t < ncopy ? u.gtris[t] : tri_base + (t - ncopy);
  };
  auto rem = [&](std::uint32_t r) { return r == kNone ? kNone : r + rem_base; };
  for (std::uint32_t t = 0; t < ncopy; ++t) {
    const MTri& l = b.tris[t];
    MTri& g = whole.tris[u.gtris[t]];
    if (l.destroyer != kNone) {
      g.destroyer = rem(l.destroyer);
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      if (l.nbr[k] != kNone) g.nbr[k] = tri(l.nbr[k]);
    }
  }
  for (std::uint32_t t = ncopy; t < b.tris.size(); ++t) {
    MTri m = b.tris[t];
    for (int k = 0; k < 3; ++k) {
      m.v[k] = u.gverts[m.v[k]];
      m.nbr[k] = tri(m.nbr[k]);
    }
    m.creator = rem(m.creator);
    m.destroyer = rem(m.destroyer);
    whole.tris.push_back(m);
  }
  for (Removal r : b.removals) {
    r.vertex = u.gverts[r.vertex];
    r.star_begin += star_base;
    r.star_end += star_base;
    r.new_begin = tri(r.new_begin);
    r.new_end = tri_base + (r.new_end - ncopy);
    whole.removals.push_back(r);
  }
  for (std::size_t i = 0; i < b.star_ids.size(); ++i) whole.star_ids.push_back(tri(b.star_ids[i]));
  b.open_edges.for_each([&](std::uint64_t key, std::uint32_t value) {
    const std::uint32_t a = u.gverts[key >> 32], c = u.gverts[key & 0xffffffffu];
    const std::uint32_t t = tri(value >> 2), e = value & 3;
    const std::uint32_t* owner = u.border_owner.find(edge_key(a, c));
    if (owner == nullptr) throw_internal("block TIN: a block's new border edge had no owner");
    const MTri& s = whole.tris[*owner];
    const std::uint32_t o = s.nbr[index_of(s, a)];
    whole.tris[t].nbr[e] = o;
    relink(whole, o, c, a, t);
  });
  for (std::size_t v = 0; v < b.verts.size(); ++v) {
    if (b.verts[v].tri != u.first_tri[v]) whole.verts[u.gverts[v]].tri = tri(b.verts[v].tri);
  }
  whole.scanned += b.scanned;
  whole.plans += b.plans;
  stats.rounds += u.stats.rounds;
  stats.non_delaunay_holes += u.stats.non_delaunay_holes;
}

void decimate_blocks(const Setup& setup, Mesh& whole, DecimationScratch& scratch,
                     const SampleSpill& spill, BlockTinStats& stats, int level,
                     const std::function<void()>& merged) {
  const int W = setup.grid.W, H = setup.grid.H;
  const int span = setup.grid.B << level;
  const int nx = (W - 2) / span + 1, ny = (H - 2) / span + 1;
  const std::uint64_t window =
      std::uint64_t(std::min(span, W - 1) + 1) * std::uint64_t(std::min(span, H - 1) + 1);
  if (level > 0 && window > setup.exact_window_samples) {
    decimate_level(setup, whole, scratch, stats, level, BlockWindow{}, nullptr);
    return;
  }
  if (level > 0) ++stats.exact_levels;
  // Blocks are independent: each is copied out for a worker, decimated there with exact bounds
  // from its window, and merged back in block order, so the records are the ones a single pass
  // over the blocks makes. A triangle goes to the block of its centroid; a vertex is removed
  // only where its whole star and hole lie in its block's copy and window (a Delaunay edge may
  // cross a border line), and the border lines' vertices are locked, so no triangle is changed
  // by two blocks.
  const std::size_t blocks = std::size_t(nx) * std::size_t(ny);
  auto block_of = [&](double col, double row) {
    const int bx = std::min(int(col) / span, nx - 1), by = std::min(int(row) / span, ny - 1);
    return std::size_t(by) * std::size_t(nx) + std::size_t(bx);
  };
  std::vector<std::vector<std::uint32_t>> cand(blocks), tris(blocks);
  for (std::uint32_t v = 0; v < whole.verts.size(); ++v) {
    const MVert& m = whole.verts[v];
    if (m.tri == kNone || setup.grid.locked(m, level)) continue;
    cand[block_of(m.col, m.row)].push_back(v);
  }
  for (std::uint32_t t = 0; t < whole.tris.size(); ++t) {
    const MTri& m = whole.tris[t];
    if (m.destroyer != kNone) continue;
    const MVert &a = whole.verts[m.v[0]], &b = whole.verts[m.v[1]], &c = whole.verts[m.v[2]];
    tris[block_of((a.col + b.col + c.col) / 3.0, (a.row + b.row + c.row) / 3.0)].push_back(t);
  }
  std::vector<std::size_t> with_candidates;
  for (std::size_t k = 0; k < blocks; ++k) {
    if (!cand[k].empty()) with_candidates.push_back(k);
  }
  const unsigned threads = thread_count(setup.opt.threads);
  // Several blocks per worker in flight: the copies are small (the live mesh shrinks level by
  // level; windows are the workers' own), and the workers go on while this thread copies and
  // merges, and past a slow block (one in flight per worker left them idle for a tenth of the
  // upper levels on the 8193² terrain).
  ordered_pipeline(
      with_candidates.size(), threads, 4 * std::size_t(threads),
      [&](std::size_t i) {
        const std::size_t k = with_candidates[i];
        const int c0 = int(k % std::size_t(nx)) * span, r0 = int(k / std::size_t(nx)) * span;
        auto block =
            setup_block(setup, whole, stats, level, c0, r0, span, std::move(tris[k]), cand[k]);
        std::vector<std::uint32_t>().swap(cand[k]);
        return block;
      },
      [&](UpperBlock& block) { decimate_block(setup, spill, block); },
      [&](UpperBlock& block, std::size_t) {
        merge_block(whole, block, stats);
        merged();
      });
  window_buffer() = Heightfield{};
}

Heightfield& window_buffer() {
  thread_local Heightfield w;
  return w;
}

}  // namespace smr::block_tin
