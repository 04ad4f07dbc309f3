// Refinement operation extraction (Brown 5.1.1, Fig. 5.2; Lemma 5.2.1 for the reduced variant).
// AddToList is run with an explicit stack; the set it reaches is the same fixed point.
#include <algorithm>
#include <set>
#include <vector>

#include "smr/core/id_map.h"
#include "smr/extract/extract.h"

namespace smr {

namespace {

// Per op of the traversal: IsFiner / IsCompletely finer, each evaluated at most once per
// extraction, and membership of X. One byte per op (IdTable: an array for all but huge sources);
// on a whole-database output X is every op.
class OpFlags {
 public:
  OpFlags(const OpSource& s, const RcfOracle& r) : source_(s), rcf_(r), flags_(s.op_count()) {}
  bool finer(const OpView& op) { return get(op, 0); }
  bool completely_finer(const OpView& op) { return get(op, 1); }
  bool in_x(OpId id) const { return (flags_.get(id.value) & kInX) != 0; }
  void add_to_x(OpId id) { flags_[id.value] |= kInX; }
  void mark_candidate(OpId id) { flags_[id.value] |= kCandidate; }
  bool candidate(OpId id) const { return (flags_.get(id.value) & kCandidate) != 0; }
  /// X in decreasing id order, `x` being its members in any order.
  void sort_descending(std::vector<OpId>& x) const {
    const std::uint64_t n = flags_.size();
    if (!flags_.dense() || x.size() * 16 < n) {  // a sort, or a scan of every op when cheaper
      std::sort(x.begin(), x.end(), std::greater<>());
      return;
    }
    x.clear();
    for (std::uint64_t id = n; id-- > 0;) {
      if (flags_.get(id) & kInX) x.push_back(OpId{id});
    }
  }

 private:
  static constexpr std::uint8_t kInX = 0x10, kCandidate = 0x20;
  bool get(const OpView& op, int which) {
    std::uint8_t& e = flags_[op.id.value];
    const std::uint8_t known = std::uint8_t(1u << (2 * which)),
                       value = std::uint8_t(2u << (2 * which));
    if (!(e & known)) {
      const bool v =
          which == 0 ? rcf_.is_finer(op, source_) : rcf_.is_completely_finer(op, source_);
      e = std::uint8_t(e | known | (v ? value : 0));  // the RCF does not touch flags_
    }
    return (e & value) != 0;
  }
  const OpSource& source_;
  const RcfOracle& rcf_;
  IdTable<std::uint8_t> flags_;
};

// Hints every place the index leaves candidates on, so that the source reads them on its own
// thread while the traversal runs; true if the hint took them all. The traversal sweeps upwards
// from R^0's place, and the hint lists the rest from the top down: the two meet in the middle
// rather than queueing on the same places. (Hinting only the places waiting ahead of the sweep
// kept the reader waiting for the prefetcher 2.9 ms of a 15.6 ms 1 px view of the 16385^2
// database; this way 0.1 ms, and the view took 11.9 ms.)
bool hint_places(const OpSource& source, std::vector<std::uint64_t> places) {
  const std::uint64_t first = source.place_of(kBaseOp).place;
  std::sort(places.begin(), places.end(), std::greater<>());  // each once (CandidateOps)
  places.erase(std::remove(places.begin(), places.end(), first), places.end());
  places.insert(places.begin(), first);  // the reader's own first place (OpSource::prefetch)
  return source.prefetch(places) == places.size();
}

std::vector<OpId> traverse(const OpSource& source, const RcfOracle& rcf, bool with_ancestors) {
  // With an index, a child outside its conservative candidates (Maheshwari 4.4's query over
  // the ops' boxes) is completely finer and is not fetched; only candidates are read and tested
  // exactly. Without it, the test reads every child of every non-finer op of X: finer ops, in
  // pages the output does not use (4x the needed pages on a 268 M-sample terrain).
  const auto* indexed_source = dynamic_cast<const RcfIndexedSource*>(&source);
  CandidateOps candidates;
  bool hinted_all = false;  // the source reads every candidate place ahead: no hints per place
  if (indexed_source != nullptr) {
    candidates = indexed_source->maybe_not_completely_finer(rcf, true);
    hinted_all = hint_places(source, candidates.places);
  }
  OpFlags flags(source, rcf);
  for (OpId id : candidates.ids) flags.mark_candidate(id);
  const auto ruled_out = [&](OpId c) {  // completely finer by the index alone
    return indexed_source != nullptr && !flags.candidate(c);
  };
  // X is a closure, the same whatever order ops are visited in; they are visited page by page
  // (OpSource::locality), sweeping upwards through the pages and wrapping around, and a child is
  // tested (IsCompletelyFiner) when its own page is visited, not when its parent is: a page is
  // then fetched about once per sweep. Visiting depth first and testing children from the parent
  // fetched 18 000 pages of 3 515 for a whole-database output under a 64 MiB cache.
  struct Pending {
    OpId id;
    std::uint32_t index;  // in its place's batch (OpPlace)
    bool test;            // reached as a child: joins X only if not completely finer
  };
  // Ops waiting, by locality: a bucket per place (found by hash), and the places with a non-empty
  // bucket in order (for the sweep), which change far less often than ops are pushed.
  IdMap<std::uint32_t> bucket_of;  // locality -> 1 + index in buckets
  std::vector<std::vector<Pending>> buckets;
  std::set<std::uint64_t> waiting;  // localities whose bucket is not empty
  const auto push = [&](OpId id, bool test) {
    if (flags.in_x(id)) return;
    const OpPlace at = source.place_of(id);
    std::uint32_t& b = bucket_of[at.place];
    if (b == 0) {
      buckets.emplace_back();
      b = static_cast<std::uint32_t>(buckets.size());
    }
    if (buckets[b - 1].empty()) waiting.insert(at.place);
    buckets[b - 1].push_back({id, at.index, test});
  };
  std::vector<OpId> x;
  OpReader reader(source);  // the place's ops, read once for its bucket
  push(kBaseOp, false);
  std::uint64_t cursor = 0;
  constexpr std::size_t kAhead = PlaceLookahead::kAhead;
  std::vector<std::uint64_t> ahead;
  while (!waiting.empty()) {
    auto next = waiting.lower_bound(cursor);
    if (next == waiting.end()) next = waiting.begin();
    const std::uint64_t here = *next;
    const std::uint32_t b = *bucket_of.find(here) - 1;
    if (!hinted_all) {  // the places the sweep visits next, for the source to read meanwhile
      ahead.clear();
      for (auto it = std::next(next); it != waiting.end() && ahead.size() < kAhead; ++it)
        ahead.push_back(*it);
      source.prefetch(ahead);
    }
    // Ops pushed into this bucket while it is processed join it (buckets may grow: re-indexed).
    while (!buckets[b].empty()) {
      const Pending p = buckets[b].back();
      buckets[b].pop_back();
      if (flags.in_x(p.id)) continue;
      const OpView& op = reader.read({{here, p.index}, p.id});
      if (p.test && flags.completely_finer(op)) continue;
      flags.add_to_x(p.id);
      x.push_back(p.id);
      if (!flags.finer(op)) {
        for (OpId c : op.children) {
          if (!ruled_out(c)) push(c, true);
        }
      }
      if (with_ancestors) {
        for (OpId q : op.parents) push(q, false);
      }
    }
    waiting.erase(here);
    cursor = here + 1;
  }
  flags.sort_descending(x);
  return x;
}

}  // namespace

std::vector<OpId> add_to_list(const OpSource& source, const RcfOracle& rcf) {
  return traverse(source, rcf, true);
}
std::vector<OpId> add_to_list_reduced(const OpSource& source, const RcfOracle& rcf) {
  // Lemma 5.2.1's form of Eq. 5.5: R^0 and every op not completely finer. The two agree when the
  // RCF bisects the Hypermesh (Brown 5.2); with screen-space tolerances the traversal of Eq. 5.5
  // can miss such an op behind a completely-finer-but-not-finer parent, and the output would then
  // break Theorem 5.2.2. This is also exactly what the R-tree's RCF query returns.
  std::vector<OpId> x{kBaseOp};
  if (const auto* indexed = dynamic_cast<const RcfIndexedSource*>(&source)) {
    for (OpId id : indexed->not_completely_finer(rcf)) {
      if (id != kBaseOp) x.push_back(id);
    }
    std::sort(x.begin(), x.end(), std::greater<>());
    x.erase(std::unique(x.begin(), x.end()), x.end());
    return x;
  }
  for (std::uint64_t i = 1; i < source.op_count(); ++i) {
    const OpRef op_ref = source.op(OpId{i});
    const OpView& op = *op_ref;
    if (!rcf.is_completely_finer(op, source)) x.push_back(op.id);
  }
  std::sort(x.begin(), x.end(), std::greater<>());
  return x;
}

}  // namespace smr
