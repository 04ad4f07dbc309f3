// The block TIN builder's leaf pass; block_tin_leaves.h describes it.
#include "smr/builders/terrain/block_tin_leaves.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <string>
#include <tuple>
#include <utility>

#include "base/error.h"
#include "smr/builders/terrain/block_tin_bounds.h"
#include "smr/builders/terrain/greedy_tin.h"

namespace smr::block_tin {
namespace {

/// Items between a level-0 block's copy and its merge in the interleaved leaf pass (and the most
/// the pass holds in flight).
constexpr std::size_t kLevel0Lag = 8;

/// The vertices of 1-D line samples z[0..n) kept so that linear interpolation between kept
/// neighbours is within `tol` of every sample (Douglas-Peucker with vertical error), plus every
/// sample with valid[i] == 0 (no data on or next to it) and its neighbours. Deterministic in the
/// samples alone, so the two blocks that share a border line keep the same vertices.
std::vector<int> simplify_line(const std::vector<float>& z, const std::vector<std::uint8_t>& valid,
                               double tol) {
  const int n = static_cast<int>(z.size());
  std::vector<std::uint8_t> keep(n, 0);
  keep[0] = keep[n - 1] = 1;
  if (!valid.empty()) {
    for (int i = 0; i < n; ++i) {
      if (valid[i] != 0) continue;
      for (int j = std::max(0, i - 1); j <= std::min(n - 1, i + 1); ++j) keep[j] = 1;
    }
  }
  std::vector<std::pair<int, int>> pending;
  int prev = 0;
  for (int i = 1; i < n; ++i) {
    if (keep[i]) {
      if (i - prev > 1) pending.push_back({prev, i});
      prev = i;
    }
  }
  while (!pending.empty()) {
    auto [lo, hi] = pending.back();
    pending.pop_back();
    double worst = tol;
    int at = -1;
    for (int i = lo + 1; i < hi; ++i) {
      const double t = double(i - lo) / double(hi - lo);
      const double e = std::abs(double(z[i]) - (double(z[lo]) + t * (double(z[hi]) - z[lo])));
      if (e > worst) {
        worst = e;
        at = i;
      }
    }
    if (at < 0) continue;
    keep[at] = 1;
    if (at - lo > 1) pending.push_back({lo, at});
    if (hi - at > 1) pending.push_back({at, hi});
  }
  std::vector<int> out;
  for (int i = 0; i < n; ++i) {
    if (keep[i]) out.push_back(i);
  }
  return out;
}

/// f(t) for every live triangle having vertex v (each once).
template <class F>
void for_each_incident(const Mesh& mesh, std::uint32_t v, F&& f) {
  const std::uint32_t start = mesh.verts[v].tri;
  auto at = [&](std::uint32_t t) {
    const int i = index_of(mesh.tris[t], v);
    if (i < 0) throw_internal("block TIN: a vertex's fan is broken");
    return i;
  };
  std::uint32_t t = start;
  for (;;) {  // counter-clockwise, across (b, v), until back or open
    f(t);
    t = mesh.tris[t].nbr[(at(t) + 2) % 3];
    if (t == start) return;
    if (t == kNone) break;
  }
  for (t = start;;) {  // then clockwise from the start, across (v, a)
    t = mesh.tris[t].nbr[at(t)];
    if (t == kNone) return;
    f(t);
  }
}

/// The id of vertex (col, row) in `mesh`, made if new: a vertex on a block border line is made
/// once (`shared`: grid index -> id + 1), so the blocks that share it share its id.
std::uint32_t global_vertex(Mesh& mesh, IdMap<std::uint32_t>& shared, const Grid& grid, int col,
                            int row, float z) {
  const int W = grid.W, H = grid.H, B = grid.B;
  const std::uint64_t key = std::uint64_t(row) * std::uint64_t(W) + std::uint64_t(col);
  const bool on_block_border = (col % B == 0) || (row % B == 0) || col == W - 1 || row == H - 1;
  if (on_block_border) {
    std::uint32_t& id = shared[key];  // stored + 1: 0 = new
    if (id != 0) return id - 1;
    id = static_cast<std::uint32_t>(mesh.verts.size()) + 1;
  }
  MVert v;
  v.col = col;
  v.row = row;
  v.z = z;
  mesh.verts.push_back(v);
  return static_cast<std::uint32_t>(mesh.verts.size() - 1);
}

/// The greedy TIN's options for leaf `in`: max_error, and its border lines' vertices given.
GreedyTinOptions leaf_options(const Setup& setup, const LeafPass::LeafInput& in) {
  const Heightfield& halo = in.halo;
  const Heightfield& w = in.w;
  const int c0 = setup.grid.block_col0(in.bx), r0 = setup.grid.block_row0(in.by);
  const int hc0 = std::max(0, c0 - 1), hr0 = std::max(0, r0 - 1);
  const int ww = w.width, wh = w.height;
  const double line_tol = setup.stop_error * 0.999;  // below the 2-D test, whatever its rounding
  GreedyTinOptions g;
  g.max_error = setup.opt.max_error;
  g.tolerance = in.tol;
  g.allow_no_data_only = true;
  g.freeze_border = true;
  // A border line's vertices: its 1-D simplification, plus every sample of it next to a no-data
  // sample (on the line or either side of it), so that the holes' edges need no other border
  // vertex.
  auto no_data_near = [&](int c, int r) {  // grid coordinates
    if (!halo.has_nodata()) return false;
    for (int dr = -1; dr <= 1; ++dr) {
      for (int dc = -1; dc <= 1; ++dc) {
        const int hc = c + dc - hc0, hr = r + dr - hr0;
        if (hc < 0 || hr < 0 || hc >= halo.width || hr >= halo.height) continue;
        if (!halo.has_data(hc, hr)) return true;
      }
    }
    return false;
  };
  auto border = [&](bool horizontal, int fixed) {
    const int n = horizontal ? ww : wh;
    std::vector<float> z(n);
    std::vector<std::uint8_t> valid;
    if (halo.has_nodata()) valid.resize(n);
    for (int i = 0; i < n; ++i) {
      const int c = horizontal ? i : fixed, r = horizontal ? fixed : i;
      z[i] = w.at(c, r);
      if (halo.has_nodata()) valid[i] = no_data_near(c0 + c, r0 + r) ? 0 : 1;
    }
    for (int i : simplify_line(z, valid, line_tol)) {
      g.initial_vertices.push_back(horizontal ? std::pair(std::uint32_t(i), std::uint32_t(fixed))
                                              : std::pair(std::uint32_t(fixed), std::uint32_t(i)));
    }
  };
  border(true, 0);
  border(true, wh - 1);
  border(false, 0);
  border(false, ww - 1);
  return g;
}

/// Builds read leaf block `in` into `leaf` (empty): its greedy TIN from the shared border
/// vertices and their exact bounds. Runs on a worker thread; LeafPass::merge_leaf then appends
/// the records to the whole mesh's.
void build_leaf(const Setup& setup, const LeafPass::LeafInput& in, Mesh& leaf,
                BlockTinStats& stats) {
  Clock::time_point clock = Clock::now();
  leaf.tol = in.tol;
  const int bx = in.bx, by = in.by;
  const Heightfield& w = in.w;
  const int c0 = setup.grid.block_col0(bx), r0 = setup.grid.block_row0(by);
  const int ww = w.width, wh = w.height;
  const GreedyTinOptions g = leaf_options(setup, in);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> prescribed = g.initial_vertices;
  std::sort(prescribed.begin(), prescribed.end());
  prescribed.erase(std::unique(prescribed.begin(), prescribed.end()), prescribed.end());

  const GreedyMesh tin = build_greedy_mesh(w, g);
  stats.seconds_greedy += since(clock);

  // The final triangles, into the global mesh.
  IdMap<std::uint32_t> shared;  // the leaf's own border vertices
  const std::uint32_t first_tri = static_cast<std::uint32_t>(leaf.tris.size());
  std::vector<std::uint32_t> local(tin.vertices.size(), kNone);  // greedy vertex id -> ours
  for (const GreedyMesh::Triangle& t : tin.triangles) {
    MTri m;
    for (int k = 0; k < 3; ++k) {
      const GreedyMesh::Vertex& gv = tin.vertices.at(t.v[k]);
      std::uint32_t& ours = local[t.v[k]];
      if (ours == kNone) {
        const int col = static_cast<int>(gv.col), row = static_cast<int>(gv.row);
        const bool on_border = col == 0 || row == 0 || col == ww - 1 || row == wh - 1;
        if (on_border && !std::binary_search(prescribed.begin(), prescribed.end(),
                                             std::pair(std::uint32_t(col), std::uint32_t(row)))) {
          throw_internal(setup.dem.source() + ": block (" + std::to_string(bx) + ", " +
                         std::to_string(by) + ") put a vertex on its border at (" +
                         std::to_string(c0 + col) + ", " + std::to_string(r0 + row) +
                         ") that its neighbour does not have");
        }
        ours = global_vertex(leaf, shared, setup.grid, c0 + col, r0 + row, gv.z);
      }
      m.v[k] = ours;
    }
    m.is_void = t.is_void;
    leaf.tris.push_back(m);
  }
  // Adjacency: within the block, and across its borders to earlier blocks.
  for (std::uint32_t t = first_tri; t < leaf.tris.size(); ++t) {
    MTri& m = leaf.tris[t];
    for (int k = 0; k < 3; ++k) {
      leaf.verts[m.v[k]].tri = t;
      if (m.is_void) leaf.verts[m.v[k]].sticky = true;
      const std::uint64_t back = edge_key(m.v[(k + 1) % 3], m.v[k]);
      if (const std::uint32_t* o = leaf.open_edges.find(back); o != nullptr) {
        const std::uint32_t other = *o >> 2, oe = *o & 3;
        m.nbr[k] = other;
        leaf.tris[other].nbr[oe] = t;
        leaf.open_edges.erase(back);
      } else if (!setup.grid.boundary_edge(leaf.verts[m.v[k]], leaf.verts[m.v[(k + 1) % 3]])) {
        leaf.open_edges[edge_key(m.v[k], m.v[(k + 1) % 3])] = (t << 2) | std::uint32_t(k);
      }
    }
  }
  // Exact errors of M^m from the window's samples.
  for (std::uint32_t t = first_tri; t < leaf.tris.size(); ++t) {
    if (leaf.tris[t].is_void) continue;
    TriBound& b = leaf.tris[t].bound;
    b = exact_bound(leaf, leaf.tris[t].v, w, c0, r0, false);
    if (b.err() > setup.stop_error + leaf.tol) {
      throw_internal(setup.dem.source() +
                     ": a greedy TIN triangle exceeds the error it was built to");
    }
    b.up = std::min(b.up, setup.stop_error);  // within float rounding of the greedy's own test
    b.down = std::min(b.down, setup.stop_error);
    leaf.err_final = std::max(leaf.err_final, b.err());
  }
  leaf.finest_triangles += leaf.tris.size() - first_tri;
  stats.seconds_greedy += since(clock);
  // Edges on the block's outer border wait for the neighbour.
}

}  // namespace

LeafPass::LeafInput LeafPass::read_leaf(std::size_t k) {
  return read_turns_.run(k, [&] { return read_leaf_now(k); });
}
/// Reads leaf k = (bx, by), copies it to the scratch file, counts its samples. The workers
/// read the leaves one at a time in block order (read_turns_: the reader is not shared between
/// threads and the tolerance is a running maximum), so the calling thread, which merges the
/// leaves in order, is left the merges.
LeafPass::LeafInput LeafPass::read_leaf_now(std::size_t k) {
  const Grid& grid = setup_.grid;
  const int bx = int(k % std::size_t(grid.bw)), by = int(k / std::size_t(grid.bw));
  const Clock::time_point t0 = Clock::now();
  LeafInput in;
  in.halo = spare_window();
  in.w = spare_window();
  in.bx = bx;
  in.by = by;
  // The block's window and a halo of one sample around it, which the border rule below reads:
  // both blocks that share a border line see the same samples on either side of it.
  const int c0 = grid.block_col0(bx), r0 = grid.block_row0(by);
  const int hc0 = std::max(0, c0 - 1), hr0 = std::max(0, r0 - 1);
  const int hc1 = std::min(grid.W - 1, grid.block_col1(bx) + 1),
            hr1 = std::min(grid.H - 1, grid.block_row1(by) + 1);
  setup_.dem.read_into(in.halo, hc0, hr0, hc1 - hc0 + 1, hr1 - hr0 + 1);
  HeightfieldWindows(in.halo).read_into(in.w, c0 - hc0, r0 - hr0, grid.block_col1(bx) - c0 + 1,
                                        grid.block_row1(by) - r0 + 1);
  const Heightfield& w = in.w;
  // Not stats_.max_block_samples: this thread merges level-0 blocks into it meanwhile.
  read_max_samples_ = std::max<std::uint64_t>(read_max_samples_, in.halo.z.size());
  spill_.put(bx, by, w, c0, r0);
  for (std::size_t i = 0; i < w.z.size(); ++i) {
    if (!w.valid.empty() && w.valid[i] == 0) continue;
    ++valid_samples_;
    if (setup_.opt.max_error != 0.0)
      read_tol_ = std::max(read_tol_, 1e-9 * std::abs(double(w.z[i])));
  }
  if (setup_.opt.max_error != 0.0) read_tol_ = std::max(read_tol_, 1e-9);
  in.tol = read_tol_;
  leaf_tol_[k] = read_tol_;
  ++stats_.leaf_blocks;
  stats_.samples += w.z.size();
  stats_.seconds_read += seconds_since(t0);
  return in;
}

/// A window whose buffers a worker handed back (or a new one): the leaf pass's windows reuse
/// pages already faulted in instead of fresh ones. They are taken on the calling thread and
/// handed back by the workers, so at most the pipeline's items' windows are ever out.
Heightfield LeafPass::spare_window() {
  std::lock_guard lock(spare_mu_);
  if (spare_windows_.empty()) return {};
  Heightfield w = std::move(spare_windows_.back());
  spare_windows_.pop_back();
  return w;
}
void LeafPass::give_back(Heightfield&& w) {
  std::lock_guard lock(spare_mu_);
  spare_windows_.push_back(std::move(w));
}

/// Appends a leaf's records (built by build_leaf) to the whole mesh's, renumbered: vertices
/// through global_vertex in the leaf's own order (so border vertices are shared and the ids
/// are those a single pass would give), triangles after the whole mesh's, and the leaf's open
/// border edges glued to the earlier blocks' or left open for later ones.
/// With `glued`, the edges glued to earlier leaves are listed there and the leaf's vertices
/// kept as leaf_vertices_[leaf_index] (the interleaved pass).
void LeafPass::merge_leaf(Mesh& leaf, const BlockTinStats& leaf_stats, std::vector<EdgeTask>* glued,
                          std::size_t leaf_index) {
  const std::uint32_t tri_base = static_cast<std::uint32_t>(whole_.tris.size());
  auto tri = [&](std::uint32_t t) { return t == kNone ? kNone : t + tri_base; };
  std::vector<std::uint32_t> vmap(leaf.verts.size());
  for (std::size_t v = 0; v < leaf.verts.size(); ++v) {
    const MVert& lv = leaf.verts[v];
    const std::uint32_t g = global_vertex(whole_, shared_, setup_.grid, lv.col, lv.row, lv.z);
    vmap[v] = g;
    whole_.verts[g].tri = tri(lv.tri);  // the leaf wrote it last, as a single pass would
    whole_.verts[g].sticky = whole_.verts[g].sticky || lv.sticky;
  }
  if (glued != nullptr) leaf_vertices_[leaf_index] = vmap;
  leaf.tris.drain([&](std::size_t, const MTri& lt) {
    MTri m = lt;
    for (int k = 0; k < 3; ++k) {
      m.v[k] = vmap[lt.v[k]];
      m.nbr[k] = tri(lt.nbr[k]);
    }
    whole_.tris.push_back(m);
  });
  leaf.open_edges.for_each([&](std::uint64_t key, std::uint32_t value) {
    const std::uint32_t a = vmap[key >> 32], b = vmap[key & 0xffffffffu];
    const std::uint32_t t = (value >> 2) + tri_base, e = value & 3;
    const std::uint64_t back = edge_key(b, a);
    if (const std::uint32_t* o = whole_.open_edges.find(back); o != nullptr) {
      const std::uint32_t other = *o >> 2, oe = *o & 3;
      whole_.tris[t].nbr[e] = other;
      whole_.tris[other].nbr[oe] = t;
      whole_.open_edges.erase(back);
      if (glued != nullptr) glued->push_back({t, a, b});
    } else {
      whole_.open_edges[edge_key(a, b)] = (t << 2) | e;
    }
  });
  if (glued != nullptr)  // last first: repair pops them in triangle order
    std::sort(glued->begin(), glued->end(), [](const EdgeTask& x, const EdgeTask& y) {
      return std::tie(x.t, x.a, x.b) > std::tie(y.t, y.a, y.b);
    });
  whole_.err_final = std::max(whole_.err_final, leaf.err_final);
  whole_.finest_triangles += leaf.finest_triangles;
  whole_.scanned += leaf.scanned;
  stats_.seconds_greedy += leaf_stats.seconds_greedy;
}

bool LeafPass::run(const std::function<void()>& merged) {
  const Grid& grid = setup_.grid;
  const std::size_t n = std::size_t(grid.bw) * std::size_t(grid.bh);
  struct Item {
    std::size_t k = 0;
    LeafInput in;
    BlockTinStats stats;                // the leaf's
    std::unique_ptr<Mesh> leaf;         // the leaf's TIN
    std::unique_ptr<UpperBlock> block;  // a level-0 block
  };
  const unsigned threads = thread_count(setup_.opt.threads);
  const bool interleave = setup_.opt.interleave_level0 && grid.levels > 0;
  // Item k + kLevel0Lag carries the block copied when leaf k was merged, so the pipeline holds
  // at most kLevel0Lag items (whatever the thread count) and item k + kLevel0Lag is made after
  // merge k.
  const std::size_t in_flight = std::min<std::size_t>(2 * std::size_t(threads), kLevel0Lag);
  const std::size_t items = interleave ? n + std::size_t(grid.bw) + 1 + kLevel0Lag : n;
  std::deque<std::unique_ptr<UpperBlock>> ready;  // copied at merges, waiting for their item
  if (interleave) leaf_vertices_.assign(n, {});
  leaf_tol_.assign(n, 0.0);
  read_turns_.reset();
  read_tol_ = whole_.tol;
  ordered_pipeline(
      items, threads, in_flight,
      [&](std::size_t k) {
        auto item = std::make_unique<Item>();
        item->k = k;
        if (k < n) item->leaf = std::make_unique<Mesh>();
        if (interleave && k >= kLevel0Lag) {
          item->block = std::move(ready.front());
          ready.pop_front();
        }
        return item;
      },
      [this](Item& item) {
        if (item.leaf) {
          item.in = read_leaf(item.k);
          build_leaf(setup_, item.in, *item.leaf, item.stats);
          give_back(std::move(item.in.halo));  // the halo is done with: its buffers serve the
        }                                      // next leaves (the window's, after the merge)
        if (item.block) {
          decimate_block(setup_, spill_, *item.block);
          if (item.block->samples.width != 0) give_back(std::move(item.block->samples));
        }
      },
      [&](Item& item, std::size_t k) {
        if (item.leaf) {
          // The repair's tiles get the leaf's window, which is at hand, in merge order.
          spill_.warm(tiles_, item.in.bx, item.in.by, item.in.w, grid.block_col0(item.in.bx),
                      grid.block_row0(item.in.by));
          give_back(std::move(item.in.w));
          std::vector<EdgeTask> glued;
          merge_leaf(*item.leaf, item.stats, interleave ? &glued : nullptr, k);
          if (interleave)
            LawsonRepair(setup_, whole_, spill_, tiles_, &leaf_vertices_, stats_).repair(glued);
        }
        if (item.block) {
          merge_block(whole_, *item.block, stats_);
          merged();
        }
        if (interleave) {
          // Leaf k - bw - 1's last neighbour is merged: its block goes out (none before).
          const std::size_t j = k - std::size_t(grid.bw) - 1;
          ready.push_back(k >= std::size_t(grid.bw) + 1 && j < n ? level0_block(j) : nullptr);
        }
        report(setup_.opt, 0.7 * double(std::min(k + 1, n)) / double(n));
      });
  whole_.tol = read_tol_;
  stats_.max_block_samples = std::max(stats_.max_block_samples, read_max_samples_);
  leaf_vertices_ = {};
  spare_windows_ = {};
  window_buffer() = Heightfield{};
  stats_.level0_interleaved = interleave;
  return interleave;
}

/// Leaf j's level-0 block, copied out (the interleaved leaf pass): the live triangles around
/// its vertices whose centroid is in it and that no other block has, its unlocked vertices.
std::unique_ptr<UpperBlock> LeafPass::level0_block(std::size_t j) {
  const Grid& grid = setup_.grid;
  const int bx = int(j % std::size_t(grid.bw)), by = int(j / std::size_t(grid.bw));
  const int c0 = grid.block_col0(bx), r0 = grid.block_row0(by);
  const int c1 = grid.block_col1(bx), r1 = grid.block_row1(by);
  auto in_leaf = [&](double col, double row) {
    return std::min(int(col) / grid.B, grid.bw - 1) == bx &&
           std::min(int(row) / grid.B, grid.bh - 1) == by;
  };
  std::vector<std::uint32_t> tris, cand;
  for (std::uint32_t v : leaf_vertices_[j]) {
    const MVert& m = whole_.verts[v];
    if (m.tri == kNone || m.col < c0 || m.col > c1 || m.row < r0 || m.row > r1) continue;
    if (in_leaf(m.col, m.row) && !grid.locked(m, 0)) cand.push_back(v);
    for_each_incident(whole_, v, [&](std::uint32_t t) {
      const MTri& tm = whole_.tris[t];
      if (handed_out(tm)) return;
      const MVert &a = whole_.verts[tm.v[0]], &b = whole_.verts[tm.v[1]],
                  &c = whole_.verts[tm.v[2]];
      if (in_leaf((a.col + b.col + c.col) / 3.0, (a.row + b.row + c.row) / 3.0)) tris.push_back(t);
    });
  }
  std::vector<std::uint32_t>().swap(leaf_vertices_[j]);
  if (cand.empty()) return nullptr;
  std::sort(tris.begin(), tris.end());
  tris.erase(std::unique(tris.begin(), tris.end()), tris.end());
  std::sort(cand.begin(), cand.end());
  cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
  for (std::uint32_t t : tris) whole_.tris[t].copied = true;
  auto block = setup_block(setup_, whole_, stats_, 0, c0, r0, grid.B, std::move(tris), cand);
  // The running tolerance as of the leaf whose merge copies this block (not of however many
  // leaves the reader is ahead by): it covers this block's samples, and does not depend on
  // the thread count.
  block->mesh.tol = leaf_tol_[std::min(j + std::size_t(grid.bw) + 1, leaf_tol_.size() - 1)];
  // Its window is leaf j's, most likely still among the repair's tiles: a copy, not a read.
  Heightfield w = spare_window();
  if (spill_.read_cached(tiles_, bx, by, setup_.dem, w)) {
    block->samples = std::move(w);
  } else {
    give_back(std::move(w));
  }
  return block;
}

}  // namespace smr::block_tin
