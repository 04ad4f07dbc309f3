// Geomorphing sessions (session.h; Brown 6.3, 6.4).
#include "smr/extract/session.h"

#include <algorithm>
#include <functional>
#include <queue>
#include <string>
#include <system_error>
#include <tuple>
#include <utility>

#include "base/error.h"
#include "smr/core/clock.h"
#include "smr/extract/extract.h"

namespace smr {

// Net changes of one update: +1 per insertion, -1 per removal (an op removed by the coarsening
// can come back as an ancestor in the refining; a triangle can go out and in again).
struct Session::Changes {
  FlatMap<TriRef, int, TriKeys> triangles;
  IdMap<int> ops;
};

namespace {

struct Candidate {
  double res;
  std::uint64_t id;
  bool test;  // reached as a child: joins X only if not completely finer
};
struct LowestFirst {
  bool operator()(const Candidate& a, const Candidate& b) const {
    return std::tie(a.res, a.id) > std::tie(b.res, b.id);
  }
};
struct HighestFirst {
  bool operator()(const Candidate& a, const Candidate& b) const {
    return std::tie(a.res, a.id) < std::tie(b.res, b.id);
  }
};

double ms_since(Clock::time_point t0) {
  return 1000.0 * seconds_since(t0);
}

}  // namespace

Session::Session(const OpSource& source, SessionOptions options)
    : source_(source), options_(options), indexed_(dynamic_cast<const RcfIndexedSource*>(&source)) {
  const OpRef base = source_.op(kBaseOp);
  x_[kBaseOp.value] = {base->birth_res, 0};
  Changes ignored;
  for (std::uint32_t i = 0; i < base->fragment.size(); ++i) insert_triangle({kBaseOp, i}, ignored);
}

void Session::insert_triangle(const TriRef& t, Changes& changes) {
  std::uint32_t& slot = slot_[t];
  if (slot != 0)
    throw_internal("session: triangle " + std::to_string(t.op.value) + "/" +
                   std::to_string(t.index) + " is in the mesh twice");
  triangles_.push_back(t);
  slot = static_cast<std::uint32_t>(triangles_.size());
  ++changes.triangles[t];
}

void Session::erase_triangle(const TriRef& t, Changes& changes) {
  std::uint32_t* slot = slot_.find(t);
  if (slot == nullptr)
    throw_internal("session: triangle " + std::to_string(t.op.value) + "/" +
                   std::to_string(t.index) + " is not in the mesh");
  const std::uint32_t i = *slot - 1;
  slot_.erase(t);
  if (i + 1 != triangles_.size()) {
    triangles_[i] = triangles_.back();
    *slot_.find(triangles_[i]) = i + 1;
  }
  triangles_.pop_back();
  --changes.triangles[t];
}

// Brown 5.1.1: R joins X after its parents; none of its children is in X yet (X stays
// ancestor-closed), so its whole fragment enters the mesh in place of its PreF.
void Session::add_op(const OpView& op, Changes& changes) {
  for (OpId p : op.parents) {
    XEntry* parent = x_.find(p.value);
    if (parent == nullptr)
      throw_internal("session: op " + std::to_string(op.id.value) + " added before its parent " +
                     std::to_string(p.value));
    ++parent->children;
  }
  x_[op.id.value] = {op.birth_res, 0};
  for (const TriRef& t : op.pre) erase_triangle(t, changes);
  for (std::uint32_t i = 0; i < op.fragment.size(); ++i) insert_triangle({op.id, i}, changes);
  ++changes.ops[op.id.value];
}

// R is in C (no child in X): its fragment, all in the mesh, gives way to its PreF again.
void Session::remove_op(const OpView& op, Changes& changes) {
  for (OpId p : op.parents) --x_.find(p.value)->children;
  x_.erase(op.id.value);
  for (std::uint32_t i = 0; i < op.fragment.size(); ++i) erase_triangle({op.id, i}, changes);
  for (const TriRef& t : op.pre) insert_triangle(t, changes);
  --changes.ops[op.id.value];
}

// Brown 6.3, step 1: C in order of decreasing resolution; an op completely finer than the new
// RCF leaves X, and a parent left with no child in X joins C.
void Session::coarsen(const RcfOracle& rcf, double deadline_ms, Changes& changes,
                      FrameStats& stats) {
  const auto t0 = Clock::now();
  std::priority_queue<Candidate, std::vector<Candidate>, HighestFirst> c;
  x_.for_each([&](std::uint64_t id, const XEntry& e) {
    if (e.children == 0 && id != kBaseOp.value) c.push({e.birth_res, id, true});
  });
  while (!c.empty()) {
    const Candidate top = c.top();
    const XEntry* e = x_.find(top.id);
    if (e == nullptr || e->children != 0) {
      c.pop();
      continue;
    }
    if (deadline_ms > 0.0 && ms_since(t0) >= deadline_ms) {
      stats.pending_coarsenings = c.size();
      stats.complete = false;
      break;
    }
    c.pop();
    const OpRef op = source_.op(OpId{top.id});
    ++stats.ops_tested;
    if (!rcf.is_completely_finer(*op, source_)) continue;
    remove_op(*op, changes);
    for (OpId p : op->parents) {
      const XEntry* parent = x_.find(p.value);
      if (p != kBaseOp && parent->children == 0) c.push({parent->birth_res, p.value, true});
    }
  }
  stats.coarsen_seconds = seconds_since(t0);
}

// Brown 6.3, step 2: AddToList (5.1.1) for the new RCF, lowest birth_res first, from R^0 over
// the DAG: ops already in X are traversed (their children offered) without changing the mesh; the
// others (Brown's set Y) are added with their missing ancestors. The traversal reaches exactly
// the new minimal-surface X. Brown's coarsening can keep ops the new X lacks (an op of X_old that
// is not completely finer but no longer reachable: Theorem 6.4.1 assumes otherwise), so when the
// traversal completes, the ops of X it did not reach are removed too, finest first (each is then
// a leaf: a child in the new X would make it an ancestor, reached).
class Session::Refiner {
 public:
  /// by_page: with no budget the order does not matter (the traversal reaches the same X), so
  /// candidates are taken page by page, sweeping upwards through the pages and wrapping around as
  /// add_to_list does (a page is then decoded about once per sweep; in order of resolution the
  /// same traversal decodes pages many times over when the cache cannot hold X's pages).
  Refiner(Session& s, const RcfOracle& rcf, Changes& changes, FrameStats& stats, bool by_page)
      : s_(s), rcf_(rcf), changes_(changes), stats_(stats), by_page_(by_page) {
    // As in add_to_list: with an index, a child outside its conservative candidates is
    // completely finer and is not read (reading them all decodes pages the mesh never uses).
    if (const auto* indexed = dynamic_cast<const RcfIndexedSource*>(&s_.source_)) {
      indexed_ = true;
      for (OpId id : indexed->maybe_not_completely_finer(rcf_, false).ids)
        marks_.set(id.value, kCandidate);
    }
  }

  /// Runs until Y is added or `stop` (given the triangles the next group would add) says no;
  /// returns the resolution it stopped at (1: done).
  double run(const std::function<bool(std::int64_t)>& stop) {
    reach(*s_.source_.op(kBaseOp));
    for (std::uint64_t pops = 0; !queue_.empty(); ++pops) {
      const Candidate top = queue_.top();
      // The walk over ops already in X takes time too: the period bounds it (Brown 6.3).
      if (pops % 64 == 63 && stop(0)) return stopped(top.res);
      if (marks_.any(top.id, kReached | kRejected)) {
        queue_.pop();
        continue;
      }
      if (by_page_) {
        round_ = std::uint64_t(top.res) >> kRoundShift;
        cursor_ = std::uint64_t(top.res) & ((std::uint64_t{1} << kRoundShift) - 1);
      }
      const OpRef op = s_.source_.op(OpId{top.id});
      ++stats_.ops_tested;
      if (rcf_.is_completely_finer(*op, s_.source_)) {
        marks_.set(top.id, kRejected);
        queue_.pop();
        continue;
      }
      std::vector<OpRef> group{op};  // the op and its ancestors not reached yet
      marks_.set(top.id, kSeen);
      collect_ancestors(*op, group);
      std::int64_t delta = 0;
      for (const OpRef& a : group) {
        if (!s_.x_.contains(a->id.value))
          delta += std::int64_t(a->fragment.size()) - std::int64_t(a->pre.size());
      }
      if (stop(delta)) return stopped(top.res);
      queue_.pop();
      std::sort(group.begin(), group.end(),
                [](const OpRef& a, const OpRef& b) { return a->id < b->id; });  // parents first
      for (const OpRef& a : group) {
        if (!s_.x_.contains(a->id.value)) s_.add_op(*a, changes_);
        reach(*a);
      }
    }
    return 1.0;
  }

  /// After a complete run: removes the ops of X that the new X lacks.
  void remove_unreached() {
    std::vector<OpId> extra;
    s_.x_.for_each([&](std::uint64_t id, const XEntry&) {
      if (!marks_.any(id, kReached)) extra.push_back(OpId{id});
    });
    std::sort(extra.begin(), extra.end(), std::greater<>());
    for (OpId id : extra) s_.remove_op(*s_.source_.op(id), changes_);
    stats_.unreached_coarsenings = extra.size();
  }

 private:
  void reach(const OpView& op) {
    marks_.set(op.id.value, kReached);
    ++stats_.ops_tested;
    if (rcf_.is_finer(op, s_.source_)) return;
    for (const FragmentTriangle& t : op.fragment) {
      if (!t.killer.valid() || marks_.any(t.killer.value, kReached)) continue;
      if (indexed_ && !marks_.any(t.killer.value, kCandidate)) continue;  // completely finer
      if (marks_.set(t.killer.value, kQueued))
        queue_.push({key(t.killer, t.death_res), t.killer.value, true});
    }
  }
  void collect_ancestors(const OpView& op, std::vector<OpRef>& group) {
    for (OpId p : op.parents) {
      if (marks_.any(p.value, kReached) || !marks_.set(p.value, kSeen)) continue;
      group.push_back(s_.source_.op(p));
      collect_ancestors(*group.back(), group);
    }
  }
  // The queue's order: resolution, or (sweep round, page) packed exactly into a double.
  static constexpr int kRoundShift = 40;
  double key(OpId id, double res) const {
    if (!by_page_) return res;
    const std::uint64_t place = s_.source_.locality(id) & ((std::uint64_t{1} << kRoundShift) - 1);
    const std::uint64_t round = round_ + (place < cursor_ ? 1 : 0);
    return double((round << kRoundShift) | place);
  }
  double stopped(double res) {
    IdMap<std::uint8_t> waiting;
    while (!queue_.empty()) {
      const std::uint64_t id = queue_.top().id;
      queue_.pop();
      if (!marks_.any(id, kReached | kRejected) && !s_.x_.contains(id)) waiting.insert(id);
    }
    stats_.pending_refinings = waiting.size();
    stats_.complete = false;
    return res;
  }

  Session& s_;
  const RcfOracle& rcf_;
  Changes& changes_;
  FrameStats& stats_;
  std::priority_queue<Candidate, std::vector<Candidate>, LowestFirst> queue_;
  // Per op, what the traversal knows of it (one byte per op: IdTable).
  static constexpr std::uint8_t kQueued = 1, kRejected = 2, kSeen = 4, kReached = 8,
                                kCandidate = 16;
  class Marks {
   public:
    explicit Marks(std::uint64_t n) : table_(n) {}
    bool any(std::uint64_t id, std::uint8_t bits) const { return (table_.get(id) & bits) != 0; }
    bool set(std::uint64_t id, std::uint8_t bit) {  // false if it was set already
      std::uint8_t& m = table_[id];
      const bool fresh = (m & bit) == 0;
      m |= bit;
      return fresh;
    }

   private:
    IdTable<std::uint8_t> table_;
  };
  Marks marks_{s_.source_.op_count()};
  bool by_page_, indexed_ = false;
  std::uint64_t round_ = 0, cursor_ = 0;
};

void Session::refine(const RcfOracle& rcf, const SessionBudget& budget, double start_ms,
                     Changes& changes, FrameStats& stats) {
  const auto t0 = Clock::now();
  const auto out_of_time = [&] {
    return budget.max_period_ms > 0.0 && start_ms + ms_since(t0) >= budget.max_period_ms;
  };
  if (out_of_time()) {
    // Brown 6.3: no refining once the period is over; X stays the coarsening's.
    stats.complete = false;
    stats.stop_resolution = 0.0;
  } else {
    Refiner refiner(*this, rcf, changes, stats,
                    budget.max_period_ms <= 0.0 && budget.max_triangles == 0);
    stats.stop_resolution = refiner.run([&](std::int64_t delta) {
      return out_of_time() ||
             (budget.max_triangles != 0 && delta > 0 &&
              std::int64_t(triangles_.size()) + delta > std::int64_t(budget.max_triangles));
    });
    if (stats.complete) refiner.remove_unreached();
  }
  stats.refine_seconds = seconds_since(t0);
}

// The index's candidates (RcfIndexedSource::maybe_not_completely_finer) for every camera within
// a margin of one pose, found again when the camera leaves it. The margin is 2 updates of the
// last one's motion, within [scale / 256, scale / 16] (a wide one reads pages no view needs).
// Once the camera has used half of it, the next set is sought on another thread from the pose of
// then (when the source allows it and the RCF can be copied), so that the update that leaves the
// current set finds the next one ready instead of querying the index itself (4-5 ms on the
// 32769^2 database at 1920x1080).
double Session::candidate_margin() const {
  const RcfPose& now = memo_.pose();
  const double scale = now.scale > 0.0 ? now.scale : 1.0;
  return std::clamp(2.0 * memo_.last_motion(), std::ldexp(scale, -8), std::ldexp(scale, -4));
}

namespace {

std::shared_ptr<const IdMap<std::uint8_t>> candidate_ids(const RcfIndexedSource& indexed,
                                                         const RcfOracle& rcf, const RcfPose& pose,
                                                         double margin) {
  const double scale = pose.scale > 0.0 ? pose.scale : 1.0;
  auto ids = std::make_shared<IdMap<std::uint8_t>>();
  for (OpId o :
       indexed.maybe_not_completely_finer(MovedIndexRcf(rcf, Motion{margin, margin / scale}), false)
           .ids)
    ids->insert(o.value);
  return ids;
}

}  // namespace

Session::Refresh Session::refresh_candidates(const RcfOracle& rcf) {
  IndexCandidates& c = candidates_;
  const RcfPose& now = memo_.pose();
  const auto install = [&](CandidateSet&& set) {
    static_cast<CandidateSet&>(c) = std::move(set);
    c.valid = true;
    if (++c.tag >= OpMemo::kRuledOut - 1) c.tag = 1;  // marks of 2^31 sets ago are long gone
  };
  if (c.valid && c.covers(now)) {
    const auto* copyable = dynamic_cast<const Rcf*>(&rcf);
    if (!next_candidates_.valid() && copyable != nullptr && indexed_->concurrent_queries() &&
        c.pose.needed_to(now) > 0.5 * c.margin) {
      try {
        next_candidates_ =
            std::async(std::launch::async, [indexed = indexed_, rcf_copy = *copyable, pose = now,
                                            margin = candidate_margin(), current = c.ids] {
              CandidateSet next{pose, margin, candidate_ids(*indexed, rcf_copy, pose, margin), {}};
              next.ids->for_each([&](std::uint64_t id, std::uint8_t) {
                if (!current->contains(id)) next.entering.insert(id);
              });
              return next;
            });
      } catch (const std::system_error&) {
        // No thread to be had: the set is found when it is needed, on this one.
      }
    }
    return Refresh::kSame;
  }
  if (next_candidates_.valid()) {
    CandidateSet next = next_candidates_.get();  // waits if it is still running
    if (next.covers(now)) {
      install(std::move(next));
      return Refresh::kNext;
    }
  }
  const double margin = candidate_margin();
  install(CandidateSet{now, margin, candidate_ids(*indexed_, rcf, now, margin), {}});
  return Refresh::kNew;
}

// Memo entries of X leaving it, finest first: each is then a leaf of X (a child still in X would
// make it reachable), so its fragment gives way to its PreF.
void Session::remove_finest_first(std::vector<std::uint32_t>& entries, Changes& changes) {
  std::sort(entries.begin(), entries.end(),
            [&](std::uint32_t a, std::uint32_t b) { return memo_.id(a) > memo_.id(b); });
  for (std::uint32_t e : entries) {
    remove_op(*source_.op(memo_.id(e)), changes);
    memo_[e].in_x = false;
  }
}

// Child i of entry e as the refining meets it: its entry, or kNone when the index rules it out
// (completely finer for every camera the candidates hold for); a child not met before is read
// only if the index cannot rule it out (as Refiner does).
std::uint32_t Session::child_entry(std::uint32_t e, std::uint32_t i) {
  if (indexed_ != nullptr && memo_.child_ruled_out(e, i, candidates_.tag)) return OpMemo::kNone;
  const std::uint32_t child = memo_.child_if_known(e, i);
  if (child != OpMemo::kNone) return child;
  if (indexed_ != nullptr && !candidates_.ids->contains(memo_.child_id(e, i).value)) {
    memo_.rule_out_child(e, i, candidates_.tag);
    return OpMemo::kNone;
  }
  return memo_.child(source_, e, i);
}

// The refining of an unbudgeted update over the memo (op_memo.h): the closure Refiner reaches
// (AddToList from R^0: an op of X that is not finer offers its children that are not completely
// finer, with their ancestors), found on the kept DAG links and verdicts, in any order (the
// closure does not depend on it); then the ops of X it did not reach are removed, finest first.
void Session::refine_kept(Changes& changes, FrameStats& stats) {
  const auto t0 = Clock::now();
  const std::uint64_t judged = memo_.judged(), kept = memo_.kept();
  const std::uint32_t now = updates_;
  constexpr std::uint8_t kQueued = 1, kRejected = 2, kSeen = 4, kReached = 8;
  OpMemo& memo = memo_;
  const auto marks = [&memo](std::uint32_t e) -> std::uint8_t& { return memo.marks(e); };
  std::vector<std::uint32_t> stack, group, reached;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> up;  // (entry, next parent)
  reached.reserve(x_.size() + 64);
  const auto reach = [&](std::uint32_t e) {
    marks(e) |= kReached;
    reached.push_back(e);
    if (memo.verdict(source_, e, OpMemo::kFiner)) return;
    const std::uint32_t n = memo[e].children;
    for (std::uint32_t i = 0; i < n; ++i) {
      const std::uint32_t child = child_entry(e, i);
      if (child == OpMemo::kNone) continue;
      std::uint8_t& m = marks(child);
      // (A child gathered as an ancestor, kSeen, keeps that level: its CompletelyFiner verdict
      // is not judged, so e's offer is no witness.)
      if (m & (kReached | kQueued | kSeen)) continue;
      m |= kQueued;
      memo[child].level = memo[e].level + 1;  // its witness: e offers it
      stack.push_back(child);
    }
  };
  if (!memo_synced_) {
    // X came from another kind of update (or this is the first): each op of X gets its entry and
    // its mark; from here on the kept updates keep them.
    memo.for_each_entry([&](std::uint32_t e) { memo[e].in_x = false; });
    x_.for_each(
        [&](std::uint64_t id, const XEntry&) { memo[memo.get(source_, OpId{id})].in_x = true; });
    memo_synced_ = true;
  }
  const std::uint32_t base = memo.get(source_, kBaseOp);
  memo[base].level = 0;
  reach(base);
  while (!stack.empty()) {
    const std::uint32_t c = stack.back();
    stack.pop_back();
    if (marks(c) & (kReached | kRejected)) continue;
    if (memo.verdict(source_, c, OpMemo::kCompletelyFiner)) {
      marks(c) |= kRejected;
      continue;
    }
    marks(c) |= kSeen;
    // c and its ancestors not reached yet.
    memo.gather(
        source_, c, kSeen, [&](std::uint32_t p) { return (marks(p) & kReached) != 0; }, group, up);
    for (std::uint32_t a : group) {
      if (!memo[a].in_x) {
        add_op(*source_.op(memo.id(a)), changes);
        memo[a].in_x = true;
      }
      reach(a);
    }
  }
  // X now holds every op reached; the others are those of the X before it that it did not reach
  // (all have entries: the last update reached them, or the resync above made them).
  std::vector<std::uint32_t> extra;
  if (reached.size() != x_.size()) {
    const auto unreached = [&](std::uint32_t e) {
      if (memo[e].in_x && (memo[e].marked != now || !(memo[e].marks & kReached)))
        extra.push_back(e);
    };
    if (reached_update_ + 1 == now) {
      for (std::uint32_t e : reached_) unreached(e);
    } else {
      memo.for_each_entry(unreached);
    }
  }
  reached_.swap(reached);
  reached_update_ = now;
  remove_finest_first(extra, changes);
  stats.unreached_coarsenings = extra.size();
  stats.ops_tested = memo.judged() - judged;
  stats.verdicts_kept = memo.kept() - kept;
  if (now >= forgotten_at_ + kIdle) {
    memo.forget_idle(kIdle);
    forgotten_at_ = now;
  }
  stats.refine_seconds = seconds_since(t0);
}

// An unbudgeted update without a traversal of X (after a traversal, refine_kept, or another of
// these, for the same signature and candidate set). X is the set of ops reachable from R^0 in a
// graph whose edges are the offers (an op of X that is not finer offers each child that is not
// completely finer) and the ancestor links (an op of X brings in its parents), so X changes only
// where a verdict did, and the verdicts that lapse are known without looking at the others
// (OpMemo::collect_lapsed). Each op of X keeps a level with a witness: a predecessor in X whose
// level is lower (walking witnesses down reaches R^0). The update then
//   1. judges again the lapsed verdicts that matter (IsFiner of an op of X; IsCompletelyFiner of
//      an op of X or of a child some op of X offers to) and notes the ones that changed;
//   2. shrinks (delete and rederive): an op that lost an edge from a lower level, and then
//      anything whose every witness is gone, is held out (U); the ops of U still reachable from
//      outside it get levels again, shortest first; the rest leave X, finest first;
//   3. grows from the new edges as the traversal would: children newly offered, with their
//      missing ancestors, and what they offer in turn.
// The result is the reachable set, the X a traversal finds (Session tests compare each update
// with a fresh extraction). Returns false, having changed nothing, when so many verdicts lapsed
// that a traversal costs no more.
bool Session::refine_incremental(Changes& changes, FrameStats& stats,
                                 const IdMap<std::uint8_t>* entering) {
  const auto t0 = Clock::now();
  OpMemo& memo = memo_;
  const std::uint64_t judged = memo.judged();
  std::vector<OpMemo::Lapse> lapsed;
  memo.collect_lapsed(lapsed);
  if (lapsed.size() > x_.size() / 4 + 64) return false;  // the lapsed ones are judged there
  constexpr std::uint8_t kInU = 1, kSeen = 2;
  const auto marks = [&memo](std::uint32_t e) -> std::uint8_t& { return memo.marks(e); };
  const auto finer = [&](std::uint32_t e) { return memo.verdict(source_, e, OpMemo::kFiner); };
  const auto completely_finer = [&](std::uint32_t e) {
    return memo.verdict(source_, e, OpMemo::kCompletelyFiner);
  };
  // 1. IsFiner first: a child's IsCompletelyFiner matters if an op of X offers to it.
  std::vector<std::uint32_t> suspects, offering, offered;
  std::stable_partition(lapsed.begin(), lapsed.end(),
                        [](const OpMemo::Lapse& l) { return l.which == OpMemo::kFiner; });
  for (const OpMemo::Lapse& l : lapsed) {
    const std::uint32_t e = l.entry;
    if (l.which == OpMemo::kFiner) {
      if (!memo[e].in_x) continue;  // judged when it joins X
      const bool before = memo.stored(e, OpMemo::kFiner);
      if (finer(e) == before) continue;
      if (before) {
        offering.push_back(e);  // now offers its children
      } else {
        for (std::uint32_t i = 0; i < memo[e].children; ++i) {  // its offers are gone
          const std::uint32_t c = memo.child_if_known(e, i);
          if (c != OpMemo::kNone && memo[c].in_x && memo[c].level > memo[e].level)
            suspects.push_back(c);
        }
      }
      continue;
    }
    bool matters = memo[e].in_x;
    for (std::uint32_t i = 0; !matters && i < memo[e].parents; ++i) {
      const std::uint32_t p = memo.parent(source_, e, i);
      matters = memo[p].in_x && !finer(p);
    }
    if (!matters) continue;
    const bool before = memo.stored(e, OpMemo::kCompletelyFiner);
    if (completely_finer(e) == before) continue;
    if (!before) {
      if (memo[e].in_x) suspects.push_back(e);  // no op offers it any more
    } else if (!memo[e].in_x) {
      offered.push_back(e);
    }
  }

  // 2. Delete and rederive.
  // Whether v (in X) has a predecessor in X outside U, of a level below `below` (offers need v
  // not completely finer and a parent that is not finer; every child of v in X brings v in).
  const auto predecessor = [&](std::uint32_t v, std::uint32_t below) {
    std::uint32_t best = ~std::uint32_t{0};
    for (std::uint32_t i = 0; i < memo[v].children; ++i) {
      const std::uint32_t c = memo.child_if_known(v, i);
      if (c != OpMemo::kNone && memo[c].in_x && !(marks(c) & kInU) && memo[c].level < below)
        best = std::min(best, memo[c].level);
    }
    if (best == ~std::uint32_t{0} && !completely_finer(v)) {
      for (std::uint32_t i = 0; i < memo[v].parents; ++i) {
        const std::uint32_t p = memo.parent(source_, v, i);
        if (!(marks(p) & kInU) && memo[p].level < below && memo[p].level < best && !finer(p))
          best = memo[p].level;
      }
    }
    return best;  // ~0: none
  };
  const std::uint32_t base = memo.find(kBaseOp);
  std::vector<std::uint32_t> held_out;  // U
  while (!suspects.empty()) {
    const std::uint32_t v = suspects.back();
    suspects.pop_back();
    if (v == base || !memo[v].in_x || (marks(v) & kInU)) continue;
    if (predecessor(v, memo[v].level) != ~std::uint32_t{0}) continue;
    marks(v) |= kInU;
    held_out.push_back(v);
    // Its successors may have had it as their only witness.
    for (std::uint32_t i = 0; i < memo[v].children; ++i) {
      const std::uint32_t c = memo.child_if_known(v, i);
      if (c != OpMemo::kNone && memo[c].in_x && memo[c].level > memo[v].level)
        suspects.push_back(c);
    }
    for (std::uint32_t i = 0; i < memo[v].parents; ++i) {
      const std::uint32_t p = memo.parent(source_, v, i);
      if (memo[p].level > memo[v].level) suspects.push_back(p);
    }
  }
  if (!held_out.empty()) {
    using Item = std::pair<std::uint32_t, std::uint32_t>;  // (level, entry)
    std::priority_queue<Item, std::vector<Item>, std::greater<>> ready;
    for (std::uint32_t v : held_out) {
      const std::uint32_t p = predecessor(v, ~std::uint32_t{0});
      if (p != ~std::uint32_t{0}) ready.push({p + 1, v});
    }
    while (!ready.empty()) {
      const auto [level, v] = ready.top();
      ready.pop();
      if (!(marks(v) & kInU)) continue;
      marks(v) &= std::uint8_t(~kInU);
      memo[v].level = level;
      const bool offers = !finer(v);
      for (std::uint32_t i = 0; i < memo[v].children; ++i) {
        const std::uint32_t c = memo.child_if_known(v, i);
        if (c != OpMemo::kNone && (marks(c) & kInU) && offers && !completely_finer(c))
          ready.push({level + 1, c});
      }
      for (std::uint32_t i = 0; i < memo[v].parents; ++i) {
        const std::uint32_t p = memo.parent(source_, v, i);
        if (marks(p) & kInU) ready.push({level + 1, p});
      }
    }
    std::vector<std::uint32_t> gone;
    for (std::uint32_t v : held_out) {
      if (marks(v) & kInU) gone.push_back(v);
    }
    remove_finest_first(gone, changes);
    stats.unreached_coarsenings = gone.size();
  }

  // 3. Grow: what the traversal would add from the new edges.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> up;  // (entry, next parent)
  std::vector<std::uint32_t> group;
  const auto join = [&](std::uint32_t c, std::uint32_t level) {  // c and its missing ancestors
    memo[c].level = level;
    marks(c) |= kSeen;
    memo.gather(
        source_, c, kSeen, [&](std::uint32_t p) { return memo[p].in_x; }, group, up);
    for (std::uint32_t a : group) {  // parents first
      add_op(*source_.op(memo.id(a)), changes);
      memo[a].in_x = true;
      offering.push_back(a);
    }
  };
  for (std::uint32_t c : offered) {
    if (memo[c].in_x) continue;
    for (std::uint32_t i = 0; i < memo[c].parents; ++i) {
      const std::uint32_t p = memo.parent(source_, c, i);
      if (memo[p].in_x && !finer(p)) {
        join(c, memo[p].level + 1);
        break;
      }
    }
  }
  if (entering != nullptr && !entering->empty()) {
    // A new set of the index's candidates: an op of X may now offer a child the last set ruled
    // out.
    memo.for_each_entry([&](std::uint32_t e) {
      if (!memo[e].in_x || memo.stored(e, OpMemo::kFiner)) return;
      for (std::uint32_t i = 0; i < memo[e].children; ++i) {
        if (entering->contains(memo.child_id(e, i).value)) {
          offering.push_back(e);
          return;
        }
      }
    });
  }
  while (!offering.empty()) {
    const std::uint32_t e = offering.back();
    offering.pop_back();
    if (!memo[e].in_x || finer(e)) continue;
    for (std::uint32_t i = 0; i < memo[e].children; ++i) {
      const std::uint32_t c = child_entry(e, i);
      if (c == OpMemo::kNone || memo[c].in_x || completely_finer(c)) continue;
      join(c, memo[e].level + 1);
    }
  }
  stats.traversed = false;
  stats.ops_tested = memo.judged() - judged;
  stats.verdicts_kept = memo.held() > stats.ops_tested ? memo.held() - stats.ops_tested : 0;
  stats.refine_seconds = seconds_since(t0);
  return true;
}

Frame Session::update(const RcfOracle& rcf, const SessionBudget& budget) {
  const auto t0 = Clock::now();
  Frame frame;
  Changes changes;
  // Brown's coarsening first only where order matters: under a budget (it decides what a period
  // or triangle cap leaves pending) and when asked for alone. Unbudgeted, the refining's traversal
  // reaches exactly the new X and removes, finest first, the ops of X it does not reach, the
  // coarsenings among them: X, the mesh and the frame (net changes) are the same, and the ops of C
  // are not each read and tested a second time.
  const bool budgeted =
      budget.max_period_ms > 0.0 || budget.max_triangles != 0 || budget.coarsen_only;
  ++updates_;
  // Unbudgeted updates run over the memo (it reads through the index what it lacks, so a cold
  // start decodes only the pages it needs).
  const bool kept = !budgeted && memo_.begin(rcf, updates_);
  if (budgeted) {
    coarsen(rcf, budget.max_period_ms, changes, frame.stats);
    memo_synced_ = false;
  }
  if (kept) {
    // The index's candidates hold for a region of poses. A set found ahead comes with the ids it
    // no longer rules out (the children to look at again); after any other new set the update
    // checks every child again (a traversal).
    const Refresh refresh = indexed_ != nullptr ? refresh_candidates(rcf) : Refresh::kSame;
    if (refresh == Refresh::kNew || !memo_synced_ || !memo_.continuous() ||
        updates_ % kTraverseEvery == 0 ||
        !refine_incremental(changes, frame.stats,
                            refresh == Refresh::kNext ? &candidates_.entering : nullptr)) {
      refine_kept(changes, frame.stats);
    }
  } else if (!budget.coarsen_only) {
    memo_synced_ = false;  // X changes without the memo's marks
    refine(rcf, budget, ms_since(t0), changes, frame.stats);
  }
  const auto t1 = Clock::now();
  changes.ops.for_each([&](std::uint64_t id, int d) {
    if (d > 0) frame.ops_added.push_back(OpId{id});
    if (d < 0) frame.ops_removed.push_back(OpId{id});
  });
  changes.triangles.for_each([&](const TriRef& t, int d) {
    if (d > 0) frame.triangles_in.push_back(t);
    if (d < 0) frame.triangles_out.push_back(t);
  });
  std::sort(frame.ops_added.begin(), frame.ops_added.end());
  std::sort(frame.ops_removed.begin(), frame.ops_removed.end());
  std::sort(frame.triangles_in.begin(), frame.triangles_in.end());
  std::sort(frame.triangles_out.begin(), frame.triangles_out.end());
  if (options_.morph && !frame.triangles_in.empty()) {
    if (source_.info().kind == ModelKind::kTerrain) {
      frame.morph = terrain_morph(source_, frame.triangles_out, frame.triangles_in);
    } else {
      IdMap<std::uint8_t> removed;
      for (OpId id : frame.ops_removed) removed.insert(id.value);
      const auto in_union = [&](OpId id) {
        return x_.contains(id.value) || removed.contains(id.value);
      };
      frame.morph = mesh_morph(source_, in_union, frame.ops_added, frame.ops_removed);
    }
  }
  FrameStats& s = frame.stats;
  s.morph_seconds = seconds_since(t1);
  s.coarsenings = frame.ops_removed.size();
  s.refinings = frame.ops_added.size();
  s.x = x_.size();
  s.triangles = triangles_.size();
  s.triangles_in = frame.triangles_in.size();
  s.triangles_out = frame.triangles_out.size();
  s.morph_triangles = frame.morph.triangles.size();
  s.morph_vertices = frame.morph.start.size();
  s.morph_groups = frame.morph.groups;
  s.seconds = seconds_since(t0);
  return frame;
}

std::vector<OpId> Session::x() const {
  std::vector<OpId> x;
  x.reserve(x_.size());
  x_.for_each([&](std::uint64_t id, const XEntry&) { x.push_back(OpId{id}); });
  std::sort(x.begin(), x.end(), std::greater<>());
  return x;
}

TriangleMesh Session::mesh() const {
  return to_mesh(source_, triangles_);
}

std::uint64_t Session::memory_bytes() const {
  return x_.memory_bytes() + slot_.memory_bytes() + triangles_.capacity() * sizeof(TriRef) +
         memo_.memory_bytes();
}

std::vector<OpId> add_to_list_budgeted(const OpSource& source, const RcfOracle& rcf,
                                       const SessionBudget& budget, FrameStats* frame_stats) {
  Session session(source, SessionOptions{.morph = false});
  const Frame frame = session.update(rcf, budget);
  if (frame_stats != nullptr) *frame_stats = frame.stats;
  return session.x();
}

Extraction extract_budgeted(const OpSource& source, const RcfOracle& rcf,
                            const SessionBudget& budget, const ExpansionOptions& options,
                            FrameStats* frame_stats) {
  if (options.runs_front()) source.need_links();  // before the session reads the pages
  const auto t0 = Clock::now();
  const std::vector<OpId> x = add_to_list_budgeted(source, rcf, budget, frame_stats);
  return expand_minimal(source, x, options, seconds_since(t0));
}

}  // namespace smr
