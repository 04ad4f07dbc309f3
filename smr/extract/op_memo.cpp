// Verdicts kept across a session's updates (op_memo.h).
#include "smr/extract/op_memo.h"

#include <algorithm>
#include <cmath>

namespace smr {

bool OpMemo::begin(const RcfOracle& rcf, std::uint32_t update) {
  update_ = update;
  rcf_ = &rcf;
  std::optional<RcfPose> pose = rcf.pose();
  if (!pose) {
    valid_from_ = update + 1;  // nothing judged before survives a gap
    held_ = 0;
    return false;
  }
  if (pose->signature != signature_) {
    signature_ = pose->signature;
    valid_from_ = update;
    held_ = 0;
  }
  for (Epoch& e : ring_) {
    if (e.update == 0 || e.update < valid_from_) continue;
    e.needed = e.pose.needed_to(*pose);
  }
  // The verdicts judged kRing updates ago lapse now, their bucket making room for this update's.
  expired_.clear();
  auto& bucket = lapses_[update % kRing];
  const std::uint32_t old = ring_[update % kRing].update;
  for (std::size_t i = cursor_[update % kRing]; i < bucket.size(); ++i) {
    if (old != 0 && entries_.size() > bucket[i].entry &&
        entries_[bucket[i].entry].epoch[bucket[i].which] == old)
      expired_.push_back(bucket[i]);
  }
  bucket.clear();
  cursor_[update % kRing] = 0;
  sorted_[update % kRing] = false;
  Epoch& now = ring_[update % kRing];
  now.update = update;
  now.pose = std::move(*pose);
  now.needed = 0.0;
  return true;
}

std::uint32_t OpMemo::get(const OpSource& source, OpId id) {
  std::uint32_t& slot = index_[id.value];
  if (slot != 0) return slot - 1;
  const OpRef op = source.op(id);
  std::uint32_t e = 0;
  if (!free_.empty()) {
    e = free_.back();
    free_.pop_back();
  } else {
    e = static_cast<std::uint32_t>(entries_.size());
    entries_.emplace_back();
    ids_.emplace_back();
  }
  slot = e + 1;  // before anything else may grow index_
  std::vector<OpId> children;
  for (const FragmentTriangle& t : op->fragment) {
    if (t.killer.valid()) children.push_back(t.killer);
  }
  std::sort(children.begin(), children.end());
  children.erase(std::unique(children.begin(), children.end()), children.end());
  Entry& entry = entries_[e];
  entry = Entry{};
  entry.links = static_cast<std::uint32_t>(links_.size());
  entry.parents = static_cast<std::uint32_t>(op->parents.size());
  entry.children = static_cast<std::uint32_t>(children.size());
  entry.marked = update_;
  ids_[e] = id;
  link_ids_.insert(link_ids_.end(), op->parents.begin(), op->parents.end());
  link_ids_.insert(link_ids_.end(), children.begin(), children.end());
  links_.resize(link_ids_.size(), kNone);
  return e;
}

// The verdict and, when `seek`, a motion over which it provably holds: the largest of the rungs
// g * 2^k, k = -6..6, around a guess g of a few updates' motion (holding is monotone in the
// motion, each bound only loosening as it grows), or 0 when none holds (judged again next update).
// The search starts at the rung the verdict's last margin had: a definite answer there is the
// verdict itself (it holds for the unmoved camera too), and the margin climbs at most two rungs
// from it; otherwise the exact test gives the verdict and a binary search below finds the rung.
// Most lapsed verdicts take 2 tests this way, against 5 for the exact test and a full search.
OpMemo::Judged OpMemo::judge(const OpView& op, const OpSource& source, int which, bool seek,
                             int hint, double scale) const {
  const auto exact = [&] {
    return which == kFiner ? rcf_->is_finer(op, source) : rcf_->is_completely_finer(op, source);
  };
  if (!seek) return {exact(), 0.0, hint};
  const double guess = std::max(8.0 * steady_motion(), std::ldexp(scale, -12));
  const auto within = [&](int k) {
    const double m = std::ldexp(guess, k);
    const Motion motion{m, m / scale};
    return which == kFiner ? rcf_->finer_within(op, source, motion)
                           : rcf_->completely_finer_within(op, source, motion);
  };
  const int start = std::clamp(hint, -6, 6);
  const Tri first = within(start);
  if (first != Tri::kUnknown) {
    int lo = start;
    for (int step = 0; step < 2 && lo < 6 && within(lo + 1) == first; ++step) ++lo;
    return {first == Tri::kTrue, std::ldexp(guess, lo), lo};
  }
  const bool value = exact();
  const Tri want = to_tri(value);
  int lo = -7, hi = start;  // holds for k <= lo (-7: none known); not for k >= hi
  while (hi - lo > 1) {
    const int mid = lo + (hi - lo) / 2;
    (within(mid) == want ? lo : hi) = mid;
  }
  return {value, lo < -6 ? 0.0 : std::ldexp(guess, lo), std::max(lo, -6)};
}

bool OpMemo::verdict(const OpSource& source, std::uint32_t e, int which) {
  Entry& entry = entries_[e];
  const std::uint8_t bit = std::uint8_t(1u << which);
  const std::uint32_t at = entry.epoch[which];
  const std::uint8_t reported = std::uint8_t(kReported << which);
  if (at != 0 && at >= valid_from_ && update_ - at < kRing && (entry.verdicts & reported) == 0) {
    const Epoch& ep = ring_[at % kRing];
    if (ep.update == at && ep.needed <= double(entry.margin[which])) {
      ++kept_;
      return (entry.verdicts & bit) != 0;
    }
  }
  const OpRef op = source.op(ids_[e]);
  ++judged_;
  const double scale = ring_[update_ % kRing].pose.scale;
  // A verdict that lapsed one update after it was judged is likely to lapse again: it is judged
  // alone (no margin) on 7 updates of 8 (which ones varies by op, so no update pays for all), so
  // ops near the RCF's edge cost one test an update.
  // Nor is a margin sought in the first update of a run of poses (a cold start): with no motion
  // seen yet, a guess would be wasted more often than not. Nor in a jump (a motion 16 times the
  // steady one), which lapses nearly every verdict anyway. Those verdicts all lapse in the next
  // update, which seeks their margins at once (staggered, the restless rule would keep most of X
  // judged again for eight updates).
  const std::uint8_t cold = std::uint8_t(4u << which);
  const bool cold_start = previous() == nullptr || last_motion() > 16.0 * steady_motion();
  const bool restless = cold_start || (at + 1 == update_ && (entry.verdicts & cold) == 0 &&
                                       (update_ + ids_[e].value) % 8 != 0);
  const Judged j =
      judge(*op, source, which, !restless, entry.rung[which], scale > 0.0 ? scale : 1.0);
  const bool value = j.value;
  entry.rung[which] = std::int8_t(j.rung);
  double m = j.margin;
  // Margins come in powers of two of one guess, so verdicts judged in one update would lapse
  // together in a later one (a spike): each is cut by a factor in (3/4, 1] of its own.
  m *= 1.0 -
       0.25 * double(mix64(ids_[e].value * 2 + std::uint64_t(which) + update_) >> 11) * 0x1p-53;
  // Stored as a float no larger than the margin found.
  float f = static_cast<float>(m);
  if (double(f) > m) f = std::nextafter(f, 0.0f);
  if (at == 0 || at < valid_from_ || update_ - at >= kRing) ++held_;
  entry.margin[which] = f;
  entry.epoch[which] = update_;
  lapses_[update_ % kRing].push_back({f, e, std::uint8_t(which)});
  // The new value, judged cold or not, its lapse not reported.
  entry.verdicts = std::uint8_t((entry.verdicts & ~(bit | cold | reported)) | (value ? bit : 0) |
                                (cold_start ? cold : 0));
  return value;
}

void OpMemo::forget_idle(std::uint32_t idle) {
  std::vector<std::uint64_t> gone;
  index_.for_each([&](std::uint64_t id, std::uint32_t slot) {
    if (update_ - entries_[slot - 1].marked > idle) gone.push_back(id);
  });
  if (gone.empty()) return;
  for (std::uint64_t id : gone) {
    const std::uint32_t e = *index_.find(id) - 1;
    for (std::uint32_t at : entries_[e].epoch) {
      if (at != 0 && at >= valid_from_ && update_ - at < kRing) --held_;
    }
    entries_[e] = Entry{};
    free_.push_back(e);
    index_.erase(id);
  }
  // The live entries' links, packed again (a forgotten entry's are garbage, and links to it
  // would dangle: every link is looked up again).
  std::vector<std::uint32_t> links;
  std::vector<OpId> ids;
  index_.for_each([&](std::uint64_t, std::uint32_t slot) {
    Entry& entry = entries_[slot - 1];
    const std::uint32_t n = entry.parents + entry.children;
    const auto from = link_ids_.begin() + entry.links;
    entry.links = static_cast<std::uint32_t>(ids.size());
    ids.insert(ids.end(), from, from + n);
  });
  links.assign(ids.size(), kNone);
  links_.swap(links);
  link_ids_.swap(ids);
}

void OpMemo::collect_lapsed(std::vector<Lapse>& out) {
  for (std::uint32_t k = 0; k < kRing; ++k) {
    const Epoch& ep = ring_[k];
    if (ep.update == 0 || ep.update < valid_from_ || ep.update == update_) continue;
    auto& bucket = lapses_[k];
    std::uint32_t& at = cursor_[k];
    if (!sorted_[k]) {  // the bucket is complete once its update is over
      std::sort(bucket.begin() + at, bucket.end(),
                [](const Lapse& a, const Lapse& b) { return a.margin < b.margin; });
      sorted_[k] = true;
    }
    for (; at < bucket.size() && double(bucket[at].margin) < ep.needed; ++at) {
      const Lapse& l = bucket[at];
      if (entries_[l.entry].epoch[l.which] == ep.update) {
        out.push_back(l);
        // Reported once, so lapsed for good: the camera may come back within the margin, but
        // nothing would report the verdict when it leaves again.
        entries_[l.entry].verdicts |= std::uint8_t(kReported << l.which);
      }
    }
  }
  for (const Lapse& l : expired_) entries_[l.entry].verdicts |= std::uint8_t(kReported << l.which);
  out.insert(out.end(), expired_.begin(), expired_.end());
  expired_.clear();
}

const OpMemo::Epoch* OpMemo::previous() const {
  const Epoch& before = ring_[(update_ - 1) % kRing];
  return before.update + 1 == update_ && before.update >= valid_from_ ? &before : nullptr;
}

double OpMemo::last_motion() const {
  const Epoch* before = previous();
  return before == nullptr ? 0.0 : before->needed;
}

// The least of the last three updates' motions (a run of consecutive updates): a jump away and
// back does not make the margins sought after it a thousand times too wide (none would hold, and
// the verdicts would be judged again update after update).
double OpMemo::steady_motion() const {
  double least = last_motion();
  for (std::uint32_t back = 1; back <= 2 && update_ > back + 1; ++back) {
    const Epoch& a = ring_[(update_ - back) % kRing];
    const Epoch& b = ring_[(update_ - back - 1) % kRing];
    if (a.update != update_ - back || b.update + 1 != a.update || b.update < valid_from_) break;
    least = std::min(least, b.pose.needed_to(a.pose));
  }
  return least;
}

std::uint64_t OpMemo::memory_bytes() const {
  return index_.memory_bytes() + entries_.capacity() * sizeof(Entry) +
         ids_.capacity() * sizeof(OpId) + free_.capacity() * sizeof(std::uint32_t) +
         links_.capacity() * sizeof(std::uint32_t) + link_ids_.capacity() * sizeof(OpId) +
         lapse_bytes();
}

std::uint64_t OpMemo::lapse_bytes() const {
  std::uint64_t n = expired_.capacity();
  for (const auto& bucket : lapses_) n += bucket.capacity();
  return n * sizeof(Lapse);
}

}  // namespace smr
