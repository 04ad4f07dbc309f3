// Refinement operation extraction (Brown 5.1.1, Fig. 5.2; Lemma 5.2.1 for the reduced variant).
// AddToList is run with an explicit stack; the set it reaches is the same fixed point.
#include <algorithm>
#include <vector>

#include "smr/core/id_map.h"
#include "smr/extract/extract.h"

namespace smr {

namespace {

// Per op of the traversal: IsFiner / IsCompletely finer, each evaluated at most once per
// extraction, and membership of X. One flat map (smr/core/id_map.h): on a whole-database output
// X is every op.
class OpFlags {
 public:
  OpFlags(const OpSource& s, const Rcf& r) : source_(s), rcf_(r) {}
  bool finer(const Op& op) { return get(op, 0); }
  bool completely_finer(const Op& op) { return get(op, 1); }
  bool in_x(OpId id) const {
    const std::uint8_t* e = flags_.find(id.value);
    return e != nullptr && (*e & kInX) != 0;
  }
  bool add_to_x(OpId id) {  // false if already in X
    std::uint8_t& e = flags_[id.value];
    if (e & kInX) return false;
    e |= kInX;
    return true;
  }

 private:
  static constexpr std::uint8_t kInX = 0x10;
  bool get(const Op& op, int which) {
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
  const Rcf& rcf_;
  IdMap<std::uint8_t> flags_;
};

std::vector<OpId> traverse(const OpSource& source, const Rcf& rcf, bool with_ancestors) {
  OpFlags flags(source, rcf);
  // With an index, a child outside its conservative candidates (Maheshwari 4.4's query over
  // the ops' boxes) is completely finer and is not fetched; only candidates are read and tested
  // exactly. Without it, the test reads every child of every non-finer op of X: finer ops, in
  // pages the output does not use (4x the needed pages on a 268 M-sample terrain).
  IdMap<std::uint8_t> candidates;
  const auto* indexed = dynamic_cast<const RcfIndexedSource*>(&source);
  if (indexed != nullptr) {
    for (OpId id : indexed->maybe_not_completely_finer(rcf)) candidates.insert(id.value);
  }
  const auto completely_finer = [&](OpId c) {
    if (indexed != nullptr && !candidates.contains(c.value)) return true;
    return flags.completely_finer(*source.op(c));
  };
  std::vector<OpId> x, stack{kBaseOp};
  while (!stack.empty()) {
    const OpId id = stack.back();
    stack.pop_back();
    if (!flags.add_to_x(id)) continue;
    x.push_back(id);
    const OpRef op_ref = source.op(id);
    const Op& op = *op_ref;
    if (!flags.finer(op)) {
      for (OpId c : op.children) {
        if (!flags.in_x(c) && !completely_finer(c)) stack.push_back(c);
      }
    }
    if (with_ancestors) {
      for (OpId p : op.parents) {
        if (!flags.in_x(p)) stack.push_back(p);
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
