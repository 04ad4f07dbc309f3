// Refinement operation extraction (Brown 5.1.1, Fig. 5.2; Lemma 5.2.1 for the reduced variant).
// AddToList is run with an explicit stack; the set it reaches is the same fixed point.
#include <algorithm>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "smr/extract/extract.h"

namespace smr {

namespace {

// Caches IsFiner / IsCompletelyFiner per op: each is evaluated at most once per extraction.
class RcfCache {
 public:
  RcfCache(const OpSource& s, const Rcf& r) : source_(s), rcf_(r) {}
  bool finer(const Op& op) { return get(op, 0); }
  bool completely_finer(const Op& op) { return get(op, 1); }

 private:
  bool get(const Op& op, int which) {
    std::uint8_t& e = cache_[op.id.value];
    const std::uint8_t known = std::uint8_t(1u << (2 * which)),
                       value = std::uint8_t(2u << (2 * which));
    if (!(e & known)) {
      const bool v =
          which == 0 ? rcf_.is_finer(op, source_) : rcf_.is_completely_finer(op, source_);
      e = std::uint8_t(e | known | (v ? value : 0));
    }
    return (e & value) != 0;
  }
  const OpSource& source_;
  const Rcf& rcf_;
  std::unordered_map<std::uint64_t, std::uint8_t> cache_;
};

std::vector<OpId> traverse(const OpSource& source, const Rcf& rcf, bool with_ancestors) {
  RcfCache cache(source, rcf);
  // With an index, a child outside its conservative candidates (Maheshwari 4.4's query over
  // the ops' boxes) is completely finer and is not fetched; only candidates are read and tested
  // exactly. Without it, the test reads every child of every non-finer op of X: finer ops, in
  // pages the output does not use (4x the needed pages on a 268 M-sample terrain).
  std::unordered_set<std::uint64_t> candidates;
  const auto* indexed = dynamic_cast<const RcfIndexedSource*>(&source);
  if (indexed != nullptr) {
    for (OpId id : indexed->maybe_not_completely_finer(rcf)) candidates.insert(id.value);
  }
  const auto completely_finer = [&](OpId c) {
    if (indexed != nullptr && candidates.count(c.value) == 0) return true;
    return cache.completely_finer(*source.op(c));
  };
  std::unordered_map<std::uint64_t, bool> in_x;
  std::vector<OpId> x, stack{kBaseOp};
  while (!stack.empty()) {
    const OpId id = stack.back();
    stack.pop_back();
    if (!in_x.emplace(id.value, true).second) continue;
    x.push_back(id);
    const OpRef op_ref = source.op(id);
    const Op& op = *op_ref;
    if (!cache.finer(op)) {
      for (OpId c : op.children) {
        if (!in_x.count(c.value) && !completely_finer(c)) stack.push_back(c);
      }
    }
    if (with_ancestors) {
      for (OpId p : op.parents) {
        if (!in_x.count(p.value)) stack.push_back(p);
      }
    }
  }
  std::sort(x.begin(), x.end(), std::greater<>());
  return x;
}

}  // namespace

std::vector<OpId> add_to_list(const OpSource& source, const Rcf& rcf) {
  return traverse(source, rcf, true);
}
std::vector<OpId> add_to_list_reduced(const OpSource& source, const Rcf& rcf) {
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
    const Op& op = *op_ref;
    if (!rcf.is_completely_finer(op, source)) x.push_back(op.id);
  }
  std::sort(x.begin(), x.end(), std::greater<>());
  return x;
}

}  // namespace smr
