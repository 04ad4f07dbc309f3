// Surface expansion (Brown 5.1.2: Fig. 5.6 Infill, Fig. 5.10 PerformExpansion; 5.2.1.2 and
// Fig. 5.14 for reduced extraction). An advancing front of directed edges, each belonging to one
// fragment's version of the edge, with the expanded mesh on its left. Ops are visited finest
// first; a fragment is expanded completely when it is a starting point (no front edge on it and
// no child encountered, plus, for reduced extraction, a domain disjoint from the expanded mesh);
// otherwise only its triangles beyond the front are. A front edge with nothing beyond it in its
// fragment moves to the edge's closest coarser version (the Hypermesh link).
//
// Per op, front edges wait on a stack; the edge that continues the current triangle fan is pushed
// last so it is expanded next (Brown 5.1.2.1), and fans are counted as expanded.
#include "smr/extract/expansion.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <unordered_map>
#include <utility>

#include "base/error.h"
#include "smr/core/crmr.h"
#include "smr/core/id_map.h"
#include "smr/core/invariants.h"

namespace smr {

namespace {

struct FrontKey {
  std::uint64_t op, u, v;
  friend bool operator==(const FrontKey&, const FrontKey&) = default;
};
struct FrontKeys {  // FlatMap's key traits
  static constexpr FrontKey empty() { return {~std::uint64_t{0}, 0, 0}; }
  static std::size_t hash(const FrontKey& k) {
    return mix64(k.op * 0x9E3779B97F4A7C15ULL ^ mix64(k.u * 0xC2B2AE3D27D4EB4FULL ^ k.v));
  }
};
struct FrontEntry {
  std::uint32_t tri;  // a triangle of the op's fragment having the edge
  std::uint8_t edge;
};

// Expanded triangles' xy-domains, for reduced extraction's starting-point domain test.
class DomainIndex {
 public:
  explicit DomainIndex(const CrmrInfo& info)
      : span_{std::max<std::int64_t>(1, info.grid_width - 1),
              std::max<std::int64_t>(1, info.grid_height - 1)} {}
  void add(const std::array<GridPoint, 3>& t) {
    const std::size_t id = tris_.size();
    tris_.push_back(t);
    for_cells(t, [&](std::size_t cell) {
      cells_[cell].push_back(id);
      return false;
    });
  }
  bool overlaps(const std::array<GridPoint, 3>& t) const {
    return for_cells(t, [&](std::size_t cell) {
      auto it = cells_.find(cell);
      if (it == cells_.end()) return false;
      for (std::size_t id : it->second) {
        if (interiors_overlap(tris_[id], t)) return true;
      }
      return false;
    });
  }

 private:
  template <class F>
  bool for_cells(const std::array<GridPoint, 3>& t, F&& f) const {
    std::int64_t x0 = t[0].x, x1 = t[0].x, y0 = t[0].y, y1 = t[0].y;
    for (const GridPoint& p : t) {
      x0 = std::min(x0, p.x), x1 = std::max(x1, p.x), y0 = std::min(y0, p.y),
      y1 = std::max(y1, p.y);
    }
    const std::int64_t c0 = cell_of(x0, span_.x), c1 = cell_of(x1, span_.x);
    const std::int64_t r0 = cell_of(y0, span_.y), r1 = cell_of(y1, span_.y);
    for (std::int64_t r = r0; r <= r1; ++r) {
      for (std::int64_t c = c0; c <= c1; ++c) {
        if (f(std::size_t(r * kCells + c))) return true;
      }
    }
    return false;
  }
  static std::int64_t cell_of(std::int64_t v, std::int64_t span) {
    return std::clamp<std::int64_t>(v * kCells / span, 0, kCells - 1);
  }
  static constexpr std::int64_t kCells = 128;
  GridPoint span_;
  std::vector<std::array<GridPoint, 3>> tris_;
  std::unordered_map<std::size_t, std::vector<std::size_t>> cells_;
};

// A vector grown in fixed chunks, then moved into one exactly sized vector chunk by chunk: a
// doubling vector holds 1.5x its final size while it reallocates (50 MiB for a 1.2 M-triangle
// output), this at most the final size plus one chunk.
template <class T>
class ChunkedVector {
 public:
  std::size_t size() const { return size_; }
  void push_back(const T& v) {
    if (chunks_.empty() || chunks_.back().size() == kChunk) chunks_.emplace_back().reserve(kChunk);
    chunks_.back().push_back(v);
    ++size_;
  }
  void move_to(std::vector<T>& out) {
    out.clear();
    out.reserve(size_);
    for (std::vector<T>& c : chunks_) {
      out.insert(out.end(), c.begin(), c.end());
      std::vector<T>().swap(c);
    }
    chunks_.clear();
    size_ = 0;
  }

 private:
  static constexpr std::size_t kChunk = 1 << 14;
  std::vector<std::vector<T>> chunks_;
  std::size_t size_ = 0;
};

// The ops of X, read a page at a time and held until infilled. The expansion visits X finest
// first (descending ids); op ids follow the error, and data pages group ops by resolution band
// and place (index/rtree.h), so within a band that order crosses the band's pages in no spatial
// order. Through an LRU page cache smaller than the band, a page was decoded again for nearly
// every op it held (a 3.3 M-triangle mesh, one oblique view: 190 492 page reads for 4 486 pages
// touched). Here the first op of a page that the expansion asks for brings in every op of X on
// that page (OpSource::locality), and each op leaves when infilled, so a page is read about once.
// A held op holds its decoded page (OpRef), which is charged (OpSource::locality_bytes) until the
// page's last held op leaves. Beyond `max_bytes`, further pages are not brought in whole: their
// ops come through the source's cache as before.
class HeldOps {
 public:
  HeldOps(const OpSource& source, std::span<const std::uint64_t> x, std::uint64_t max_bytes)
      : source_(source), max_bytes_(max_bytes) {
    members_.reserve(x.size());
    for (std::uint64_t id : x) members_.push_back({source.place_of(OpId{id}), OpId{id}});
    sort_for_reading(members_);
    group_of_.reserve(x.size());
    for (std::size_t i = 0; i < members_.size(); ++i) {
      if (i == 0 || members_[i].at.place != members_[i - 1].at.place) starts_.push_back(i);
      group_of_[members_[i].id.value] = static_cast<std::uint32_t>(starts_.size() - 1);
    }
    starts_.push_back(members_.size());
    groups_.assign(starts_.size() - 1, Group{});
  }

  // Op `id`, no longer held afterwards (each op of X is infilled once).
  OpRef take(OpId id) {
    if (auto* held = held_.find(id.value)) {
      OpRef out = std::move(held->first);
      Group& g = groups_[held->second];
      held_.erase(id.value);
      if (--g.held == 0) bytes_ -= g.bytes;
      return out;
    }
    const std::uint32_t* group = group_of_.find(id.value);
    if (group == nullptr || groups_[*group].loaded || bytes_ > max_bytes_) return source_.op(id);
    Group& g = groups_[*group];
    g.loaded = true;
    const std::uint64_t place = members_[starts_[*group]].at.place;
    OpBatch batch;  // the page's ops, one lookup for the group (sources with places)
    OpRef wanted;
    for (std::size_t i = starts_[*group]; i < starts_[*group + 1]; ++i) {
      const PlacedOp& m = members_[i];
      OpRef op;
      if (m.at.index == OpPlace::kNoIndex) {
        op = source_.op(m.id);
      } else {
        if (batch.keep == nullptr) batch = source_.batch(place);
        op = OpRef(batch.keep, &batch_op(batch, m.at.index, m.id));
      }
      if (m.id == id) {
        wanted = std::move(op);
        continue;
      }
      held_[m.id.value] = {std::move(op), *group};
      ++g.held;
    }
    if (g.held > 0) {
      g.bytes = source_.locality_bytes(place);
      bytes_ += g.bytes;
    }
    peak_bytes_ = std::max(peak_bytes_, bytes_);
    peak_ops_ = std::max<std::uint64_t>(peak_ops_, held_.size());
    return wanted;
  }
  std::uint64_t peak_bytes() const { return peak_bytes_; }
  std::uint64_t peak_ops() const { return peak_ops_; }

 private:
  struct Group {
    bool loaded = false;
    std::uint32_t held = 0;   // its ops held now
    std::uint64_t bytes = 0;  // charged while held > 0
  };
  const OpSource& source_;
  const std::uint64_t max_bytes_;
  std::vector<PlacedOp> members_;    // X grouped by place
  std::vector<std::size_t> starts_;  // group g is members_[starts_[g], starts_[g + 1])
  std::vector<Group> groups_;
  IdMap<std::uint32_t> group_of_;
  IdMap<std::pair<OpRef, std::uint32_t>> held_;  // op, its group
  std::uint64_t bytes_ = 0, peak_bytes_ = 0, peak_ops_ = 0;
};

class Expander {
 public:
  Expander(const OpSource& source, bool reduced, const ExpansionOptions& options)
      : source_(source), reduced_(reduced), options_(options) {
    if (reduced_) domain_ = std::make_unique<DomainIndex>(source.info());
  }

  Extraction run(std::span<const OpId> x) {
    for (OpId id : x) {
      if (in_x_.insert(id.value)) queue_.push_back(id.value);
    }
    held_ = std::make_unique<HeldOps>(source_, queue_, options_.max_held_bytes);
    std::make_heap(queue_.begin(), queue_.end());
    out_.stats.x = in_x_.size();
    while (!queue_.empty() && !budget_reached()) {
      std::pop_heap(queue_.begin(), queue_.end());
      const OpId id{queue_.back()};
      queue_.pop_back();
      infill(id);
      ++out_.stats.ops_visited;
    }
    const bool stopped = budget_reached();
    out_.stats.held_ops_peak = held_->peak_ops();
    out_.stats.held_bytes_peak = held_->peak_bytes();
    held_.reset();
    triangles_.move_to(out_.triangles);
    out_.stats.x_plus = in_x_.size();
    out_.x.reserve(in_x_.size());
    in_x_.for_each([&](std::uint64_t v, std::uint8_t) { out_.x.push_back(OpId{v}); });
    std::sort(out_.x.begin(), out_.x.end(), std::greater<>());
    if (!stopped && !front_.empty()) {
      throw_internal("surface expansion ended with " + std::to_string(front_.size()) +
                     " edges left on the active front");
    }
    if (anomalies_ != 0) {
      throw_internal("surface expansion met " + std::to_string(anomalies_) +
                     " inconsistent front edges (the CRMR violates Brown 4.4.1)");
    }
    return std::move(out_);
  }

 private:
  bool budget_reached() const {
    return options_.max_triangles != 0 && triangles_.size() >= options_.max_triangles;
  }

  // Infill (Fig. 5.6).
  void infill(OpId id) {
    const OpRef op_ref = held_->take(id);
    const OpView& op = *op_ref;
    std::vector<FrontKey> stack;
    if (auto* waiting = stacks_.find(id.value)) {
      stack = std::move(*waiting);
      stacks_.erase(id.value);
    }
    expanded_.assign(op.fragment.size(), 0);
    fragment_neighbours(op.fragment, nbr_);  // fragments do not keep them
    bool on_front = false;
    for (const FrontKey& k : stack) on_front |= front_.contains(k);
    bool starting = !on_front;
    if (starting) {
      for (OpId c : op.children) {
        if (in_x_.contains(c.value)) {
          starting = false;
          break;
        }
      }
    }
    if (starting && reduced_) {
      ++out_.stats.domain_tests;
      for (const FragmentTriangle& t : op.fragment) {
        if (domain_->overlaps(grid_triangle(op, t))) {
          starting = false;
          break;
        }
      }
    }
    if (starting) {
      ++out_.stats.starting_points;
      for (std::uint32_t i = 0; i < op.fragment.size() && !budget_reached(); ++i) {
        if (expanded_[i]) continue;
        emit(op, i, -1, stack);
        drain(op, stack);
      }
    } else {
      drain(op, stack);
      // Parts of F that no op of X replaces and the front never reached: other connected
      // components of the model (a 3-D mesh of several pieces in one fragment, Brown's spawned
      // meshes, Fig. 4.9d). Front edges reach an op only from finer ops, all visited before it,
      // so nothing else will expand them; each is a starting point of its own. (Minimal surface
      // only: reduced extraction decides overlaps with its domain test.)
      for (std::uint32_t i = 0; !reduced_ && i < op.fragment.size() && !budget_reached(); ++i) {
        const FragmentTriangle& t = op.fragment[i];
        if (expanded_[i] || (t.killer.valid() && in_x_.contains(t.killer.value))) continue;
        ++out_.stats.starting_points;
        emit(op, i, -1, stack);
        drain(op, stack);
      }
    }
  }

  void drain(const OpView& op, std::vector<FrontKey>& stack) {
    while (!stack.empty() && !budget_reached()) {
      const FrontKey key = stack.back();
      stack.pop_back();
      const FrontEntry* found = front_.find(key);
      if (found == nullptr) continue;  // merged away earlier
      const FrontEntry entry = *found;
      front_.erase(key);
      if (front_.erase(FrontKey{key.op, key.v, key.u})) continue;  // both sides expanded: merge
      perform_expansion(op, key, entry, stack);
    }
  }

  // PerformExpansion (Fig. 5.10 / 5.14) on the region to the right of front edge u->v.
  void perform_expansion(const OpView& op, const FrontKey& key, const FrontEntry& entry,
                         std::vector<FrontKey>& stack) {
    const FragmentTriangle& t = op.fragment[entry.tri];
    const std::uint64_t a = op.vertex_id(t, entry.edge).value;
    const std::uint64_t b = op.vertex_id(t, (entry.edge + 1) % 3).value;
    std::int64_t beyond = -1;  // the triangle of F with counter-clockwise edge v->u
    int beyond_edge = 0;
    std::uint32_t left = entry.tri;  // the triangle of F with counter-clockwise edge u->v
    std::uint8_t left_edge = entry.edge;
    if (a == key.v && b == key.u) {
      beyond = entry.tri;
      beyond_edge = entry.edge;
    } else if (nbr_[entry.tri][entry.edge] >= 0) {
      beyond = nbr_[entry.tri][entry.edge];
      beyond_edge = edge_of(op, op.fragment[beyond], key.v, key.u);
    }
    if (beyond >= 0) {
      if (expanded_[beyond]) {
        ++anomalies_;
        return;
      }
      emit(op, static_cast<std::uint32_t>(beyond), beyond_edge, stack);
      return;
    }
    // Nothing beyond in this fragment: hand the edge to its closest coarser version.
    const CoarserLink* link = op.coarser_link(left, left_edge);
    if (link == nullptr) return;  // model boundary
    EdgeRef target = link->coarser;
    if (!reduced_) {
      while (!in_x_.contains(target.tri.op.value)) {
        const OpRef q_ref = source_.op(target.tri.op);
        const OpView& q = *q_ref;
        const CoarserLink* next = q.coarser_link(target.tri.index, target.edge);
        if (next == nullptr) {
          ++anomalies_;
          return;
        }
        target = next->coarser;
      }
    } else if (in_x_.insert(target.tri.op.value)) {
      queue_.push_back(target.tri.op.value);
      std::push_heap(queue_.begin(), queue_.end());
    }
    const FrontKey moved{target.tri.op.value, key.u, key.v};
    if (!add_to_front(moved, FrontEntry{target.tri.index, target.edge})) {
      ++anomalies_;
      return;
    }
    stacks_[moved.op].push_back(moved);
  }

  bool add_to_front(const FrontKey& key, const FrontEntry& entry) {  // false if there already
    const std::size_t before = front_.size();
    FrontEntry& slot = front_[key];
    if (front_.size() == before) return false;
    slot = entry;
    return true;
  }

  static int edge_of(const OpView& op, const FragmentTriangle& t, std::uint64_t u,
                     std::uint64_t v) {
    for (int k = 0; k < 3; ++k) {
      if (op.vertex_id(t, k).value == u && op.vertex_id(t, (k + 1) % 3).value == v) return k;
    }
    throw_internal("surface expansion: neighbour link without a shared edge in op " +
                   std::to_string(op.id.value));
  }

  // Adds triangle i of F(op) to the mesh and its other edges to the front. entry_edge is the edge
  // it was entered through (-1 for a starting point, which puts all three edges on the front).
  void emit(const OpView& op, std::uint32_t i, int entry_edge, std::vector<FrontKey>& stack) {
    const FragmentTriangle& t = op.fragment[i];
    expanded_[i] = 1;
    triangles_.push_back({op.id, i});
    if (t.is_void()) ++out_.stats.void_triangles;
    track_fan(op, i, entry_edge);
    if (reduced_) domain_->add(grid_triangle(op, t));
    // Lprev first, Lnext last: Lnext is popped next and continues the fan.
    std::array<int, 3> ks{0, 1, 2};
    int count = 3;
    if (entry_edge >= 0) {
      ks = {(entry_edge + 2) % 3, (entry_edge + 1) % 3, 0};
      count = 2;
    }
    for (int n = 0; n < count; ++n) {
      const int k = ks[n];
      const FrontKey key{op.id.value, op.vertex_id(t, k).value, op.vertex_id(t, (k + 1) % 3).value};
      if (!add_to_front(key, FrontEntry{i, static_cast<std::uint8_t>(k)})) {
        ++anomalies_;
        continue;
      }
      stack.push_back(key);
    }
  }

  void track_fan(const OpView& op, std::uint32_t i, int entry_edge) {
    const FragmentTriangle& t = op.fragment[i];
    bool continues = false;
    if (entry_edge >= 0 && fan_.op == op.id &&
        nbr_[i][entry_edge] == static_cast<std::int32_t>(fan_.last)) {
      const std::uint64_t u = op.vertex_id(t, entry_edge).value;
      const std::uint64_t v = op.vertex_id(t, (entry_edge + 1) % 3).value;
      if (fan_.len == 1) {
        fan_.apex = {u, v};
        fan_.apex_n = 2;
        continues = true;
      } else {
        std::array<std::uint64_t, 2> keep{};
        int n = 0;
        for (int j = 0; j < fan_.apex_n; ++j) {
          if (fan_.apex[j] == u || fan_.apex[j] == v) keep[n++] = fan_.apex[j];
        }
        if (n > 0) {
          fan_.apex = keep;
          fan_.apex_n = n;
          continues = true;
        }
      }
    }
    if (continues) {
      ++fan_.len;
    } else {
      out_.fan_starts.push_back(static_cast<std::uint32_t>(triangles_.size() - 1));
      ++out_.stats.fans;
      fan_.len = 1;
      fan_.apex_n = 0;
    }
    fan_.op = op.id;
    fan_.last = i;
  }

  std::array<GridPoint, 3> grid_triangle(const OpView& op, const FragmentTriangle& t) const {
    return {to_grid(source_.info(), op.position(t, 0)), to_grid(source_.info(), op.position(t, 1)),
            to_grid(source_.info(), op.position(t, 2))};
  }

  const OpSource& source_;
  const bool reduced_;
  const ExpansionOptions options_;
  Extraction out_;
  ChunkedVector<TriRef> triangles_;   // out_.triangles while expanding
  IdMap<std::uint8_t> in_x_;          // X, then X+ (a set: the values are unused)
  std::vector<std::uint64_t> queue_;  // max-heap of op ids: finest first
  // Filled to 75 %: a whole-model front holds ~10^5 edges, and the output's memory bound counts.
  FlatMap<FrontKey, FrontEntry, FrontKeys> front_{75};
  IdMap<std::vector<FrontKey>> stacks_{75};
  std::vector<std::uint8_t> expanded_;
  std::vector<std::array<std::int32_t, 3>> nbr_;  // the infilled op's fragment neighbours
  std::unique_ptr<DomainIndex> domain_;
  std::unique_ptr<HeldOps> held_;
  std::uint64_t anomalies_ = 0;
  // The triangle fan being grown (Brown 5.1.2: the front emits fans): its op, last triangle,
  // length and the one or two vertices every triangle of it shares so far.
  struct Fan {
    OpId op;
    std::uint32_t last = 0;
    std::uint64_t len = 0;
    std::array<std::uint64_t, 2> apex{};
    int apex_n = 0;
  } fan_;
};

}  // namespace

Extraction run_expansion(const OpSource& source, std::span<const OpId> x, bool reduced,
                         const ExpansionOptions& options) {
  source.need_links();  // the fans walk the Hypermesh (Op::coarser)
  Extraction out;
  {
    Expander e(source, reduced, options);  // its front and maps are freed before the shrink
    out = e.run(x);
  }
  // The result outlives the extraction: drop the fan list's doubling slack.
  out.fan_starts.shrink_to_fit();
  out.stats.triangles = out.triangles.size();
  return out;
}

}  // namespace smr
