// The constant-level cut (level_cut.h).
#include "smr/query/level_cut.h"

#include <algorithm>
#include <atomic>
#include <exception>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "index/rtree.h"
#include "smr/core/id_map.h"
#include "smr/core/parallel.h"
#include "smr/db/page.h"
#include "smr/db/tables.h"
#include "smr/query/indexed_source.h"
#include "smr/rcf/rcf.h"

namespace smr {

namespace {

// The leaves (= data pages) holding an op whose birth_res is below `below`, through the R-tree's
// least birth_res per subtree.
class BelowVisitor final : public index::Visitor {
 public:
  explicit BelowVisitor(double below) : below_(below) {}
  bool enter(const index::Summary& s) override { return s.min_res < below_; }
  bool accept(const index::Entry& e) override { return e.res < below_; }

 private:
  double below_;
};

// Vertex ids hashed by runs of 8: a page's vertices lie close together (a terrain's ids are
// row * width + column, a mesh's follow its builder's spatial order), so that the ids of a row of
// a page share a cache line of the map's instead of each missing the caches.
struct RunKeys {
  static constexpr std::uint64_t empty() { return ~std::uint64_t{0}; }
  static std::size_t hash(std::uint64_t id) { return std::size_t(mix64(id >> 3) << 3 | (id & 7)); }
};

}  // namespace

std::optional<double> constant_level(const RcfSpec& spec) {
  const bool alone = !spec.camera && !spec.pixel_error && !spec.screen_aoi && spec.aois.empty() &&
                     spec.discs.empty() && spec.volumes.empty() && !spec.frustum_level &&
                     !spec.centre_cone && !spec.critical_level;
  return alone ? spec.floor : std::nullopt;
}

std::optional<TriangleMesh> extract_level_cut(const Database& db, double level,
                                              const LevelCutOptions& options,
                                              LevelCutStats* stats) {
  const unsigned threads = options.threads;
  // An op is in X iff it is R^0 or its birth_res does not meet the level (meets_level).
  const double below = meets_level(1.0, level) ? level : std::numeric_limits<double>::infinity();
  std::vector<std::uint64_t> pages;
  if (below > 1.0) {  // every op
    pages.resize(db.page_count());
    for (std::uint64_t p = 0; p < pages.size(); ++p) pages[p] = p;
  } else {
    BelowVisitor visitor(below);
    for (const index::Hit& h : db.rtree_query(visitor)) {
      if (!pages.empty() && pages.back() == h.leaf) continue;  // mostly grouped by leaf
      pages.push_back(h.leaf);
    }
    pages.push_back(db.place_of(kBaseOp).place);  // R^0 is in X whatever its resolution
    std::sort(pages.begin(), pages.end());
    pages.erase(std::unique(pages.begin(), pages.end()), pages.end());
  }
  db.will_need(pages);  // a cold file is then read many pages at once, not one after another
  // Each thread cuts a few pages at a time, then merges them in their turn (Turnstile: page
  // order) while the other cuts the next: two threads on two cores, the merge never waiting on a
  // third. An item's arrays are kept for a later one.
  constexpr std::size_t kPagesPerItem = 8;
  using Item = std::vector<PageCut>;
  std::mutex spare_mu;
  std::vector<std::unique_ptr<Item>> spare;
  TriangleMesh mesh;
  FlatMap<std::uint64_t, std::uint32_t, RunKeys> index_of(85);  // vertex id -> 1 + mesh index
  if (below > 1.0) {  // every vertex is used: sized once (a surface has ~2 triangles a vertex)
    const std::uint64_t v = db.info().vertex_count;
    index_of.reserve(v);
    mesh.positions.reserve(v);
    mesh.triangles.reserve(2 * v + 64);
    mesh.triangle_values.reserve(2 * v + 64);
  }
  std::vector<std::uint32_t> local;  // a page's vertices: their mesh indices
  std::atomic<bool> go{true};  // no void triangle met, the mesh within max_triangles, no error
  bool voids = false;          // set in a turn
  LevelCutStats s;
  const auto merge = [&](const PageCut& c) {
    local.resize(c.vertex_ids.size());
    constexpr std::size_t kAhead = 8;  // the map is far larger than the caches
    for (std::size_t v = 0; v < c.vertex_ids.size(); ++v) {
      if (v + kAhead < c.vertex_ids.size()) index_of.prefetch(c.vertex_ids[v + kAhead]);
      std::uint32_t& at = index_of[c.vertex_ids[v]];
      if (at == 0) {
        mesh.positions.push_back(c.positions[v]);
        at = static_cast<std::uint32_t>(mesh.positions.size());
      }
      local[v] = at - 1;
    }
    for (const auto& t : c.triangles)
      mesh.triangles.push_back({local[t[0]], local[t[1]], local[t[2]]});
    mesh.triangle_values.insert(mesh.triangle_values.end(), c.values.begin(), c.values.end());
    s.x += c.ops_in_x;
    ++s.pages;
  };
  const std::string table = db.path() + ": " + std::string(table_name(Table::kPages)) + "/";
  Turnstile turns;
  parallel_for((pages.size() + kPagesPerItem - 1) / kPagesPerItem, threads, [&](std::size_t k) {
    std::unique_ptr<Item> item;
    std::size_t cut = 0;       // pages of the item cut
    bool item_voids = false;   // the cut stopped at a page with a void triangle
    std::exception_ptr error;  // thrown in its turn: every turn must come (Turnstile)
    try {
      {
        std::lock_guard lock(spare_mu);
        if (!spare.empty()) {
          item = std::move(spare.back());
          spare.pop_back();
        }
      }
      if (!item) item = std::make_unique<Item>();
      const std::size_t first = k * kPagesPerItem;
      item->resize(std::min(kPagesPerItem, pages.size() - first));
      for (; cut < item->size() && go; ++cut) {
        const std::uint64_t page = pages[first + cut];
        db.with_page_bytes(page, [&](storage::ByteView bytes) {
          item_voids =
              !cut_page(bytes, db.grid(), below, (*item)[cut], table + std::to_string(page));
        });
        if (item_voids) break;
      }
    } catch (...) {
      error = std::current_exception();
    }
    // In page order: what stops the cut (a void triangle, the budget, an error) is the first
    // one in page order, whatever the threads.
    turns.run(k, [&] {
      if (!go) return;  // an earlier item stopped the cut: this one is not needed
      if (error) std::rethrow_exception(error);
      if (item_voids) {
        voids = true;
        go = false;  // the caller takes the general path
        return;
      }
      for (std::size_t i = 0; i < cut && go; ++i) {
        merge((*item)[i]);
        if (options.max_triangles != 0 && mesh.triangles.size() > options.max_triangles) go = false;
      }
    });
    if (!item) return;
    std::lock_guard lock(spare_mu);
    spare.push_back(std::move(item));
  });
  s.voids = voids;
  s.over_budget = !go && !voids;
  s.triangles = mesh.triangles.size();
  if (stats != nullptr) *stats = s;
  if (!go) return std::nullopt;
  return mesh;
}

std::string check_level_cut(const Database& db, const Rcf& rcf, const TriangleMesh& mesh,
                            const LevelCutStats& stats, Extraction* general) {
  const IndexedSource source(db);
  Extraction e = extract_minimal_surface(source, rcf, {.fronts = false});
  std::string differs;
  if (e.x.size() != stats.x) {
    differs = "the level cut's |X| is " + std::to_string(stats.x) + ", the minimal surface's " +
              std::to_string(e.x.size());
  } else if (!same_triangles(mesh, to_mesh(db, e.triangles))) {
    differs = "the level cut's triangles differ from the minimal surface's set formula";
  }
  if (general != nullptr) *general = std::move(e);
  return differs;
}

}  // namespace smr
