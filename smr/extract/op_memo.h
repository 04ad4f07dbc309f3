// What a session keeps of the ops its traversals meet, from one update to the next (session.h):
// each op's DAG links (the database never changes them) and its two RCF verdicts, each with the
// camera it was judged for and a motion margin. A verdict is reused while the camera stays within
// its margin of that camera: the RCF's components bound their tests over every camera of such a
// set (RcfOracle::finer_within, rcf.h), and the margin is a motion over which the verdict
// provably holds (a few updates' worth, more for verdicts far from changing). An update's
// traversal then reads and judges only the ops whose verdicts lapsed or that it meets first.
//
// The traversal visits every entry of X and of its candidates each update, so entries are small
// records in one array (their links, entry numbers, in another): they stay in cache.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "smr/core/id_map.h"
#include "smr/core/op_source.h"
#include "smr/rcf/rcf.h"

namespace smr {

class OpMemo {
 public:
  static constexpr int kFiner = 0, kCompletelyFiner = 1;
  static constexpr std::uint32_t kNone = ~std::uint32_t{0};
  static constexpr std::uint32_t kRuledOut = std::uint32_t{1} << 31;  // links_: not an entry

  struct Entry {
    std::uint32_t links = 0;    // its parents', then its children's, entries in links_
    std::uint32_t parents = 0;  // how many of each
    std::uint32_t children = 0;
    std::uint32_t marked = 0;  // update `marks` belong to (and the last that met the entry)
    std::array<std::uint32_t, 2> epoch{0, 0};  // update that judged each verdict (0: never)
    std::array<float, 2> margin{0.0f, 0.0f};   // motion each verdict holds for (rounded down)
    /// Bit kFiner, bit kCompletelyFiner; 4 << which: judged cold; kReported << which: its lapse
    /// was reported (collect_lapsed), so it is judged again when next asked for.
    std::uint8_t verdicts = 0;
    std::uint8_t marks = 0;                 // the current traversal's (Session)
    std::array<std::int8_t, 2> rung{0, 0};  // each margin's rung (OpMemo::judge)
    bool in_x = false;                      // the op is in the session's X (kept by Session)
    /// A witness's: some predecessor in the reachability graph of X (Session) has a lower one.
    std::uint32_t level = 0;
  };

  /// Starts update number `update` (increasing from 1) for `rcf`: verdicts judged under another
  /// signature lapse; returns false if the RCF cannot bound its verdicts (no pose).
  bool begin(const RcfOracle& rcf, std::uint32_t update);

  /// The entry of `id` (its number), read from `source` the first time.
  std::uint32_t get(const OpSource& source, OpId id);
  /// The entry of `id`, or kNone.
  std::uint32_t find(OpId id) const {
    const std::uint32_t* slot = index_.find(id.value);
    return slot == nullptr ? kNone : *slot - 1;
  }
  Entry& operator[](std::uint32_t e) { return entries_[e]; }
  /// Entry e's marks for the current update's traversal (cleared the first time it touches e).
  std::uint8_t& marks(std::uint32_t e) {
    Entry& entry = entries_[e];
    if (entry.marked != update_) {
      entry.marked = update_;
      entry.marks = 0;
    }
    return entry.marks;
  }
  /// Entry c and those of its ancestors that `skip` does not exclude (nor `seen` in their marks),
  /// each once and marked `seen`, into `group` parents first (a depth-first post-order over the
  /// parent links, `up` its stack). Each parent gathered gets its child's level + 1: its witness
  /// is that child, which joins X with it (Session).
  template <class Skip>
  void gather(const OpSource& source, std::uint32_t c, std::uint8_t seen, Skip skip,
              std::vector<std::uint32_t>& group,
              std::vector<std::pair<std::uint32_t, std::uint32_t>>& up) {
    group.clear();
    up.assign(1, {c, 0});
    while (!up.empty()) {
      auto& [e, next] = up.back();
      if (next == entries_[e].parents) {
        group.push_back(e);
        up.pop_back();
        continue;
      }
      const std::uint32_t level = entries_[e].level + 1;
      const std::uint32_t parent = this->parent(source, e, next++);
      std::uint8_t& m = marks(parent);
      if ((m & seen) || skip(parent)) continue;
      m |= seen;
      entries_[parent].level = level;
      up.push_back({parent, 0});
    }
  }
  OpId id(std::uint32_t e) const { return ids_[e]; }
  /// Parent i of entry e, read the first time.
  std::uint32_t parent(const OpSource& source, std::uint32_t e, std::uint32_t i) {
    return linked(source, entries_[e].links + i);
  }
  /// Child i of entry e if the memo has it, else kNone (child() reads it).
  std::uint32_t child_if_known(std::uint32_t e, std::uint32_t i) {
    const std::uint32_t at = entries_[e].links + entries_[e].parents + i;
    if (links_[at] & kRuledOut) {  // not looked up yet (or ruled out by an older test)
      const std::uint32_t found = find(link_ids_[at]);
      if (found == kNone) return kNone;
      links_[at] = found;
    }
    return links_[at];
  }
  std::uint32_t child(const OpSource& source, std::uint32_t e, std::uint32_t i) {
    return linked(source, entries_[e].links + entries_[e].parents + i);
  }
  OpId child_id(std::uint32_t e, std::uint32_t i) const {
    return link_ids_[entries_[e].links + entries_[e].parents + i];
  }
  /// A child the memo lacks, marked as ruled out by the caller's test number `tag` (1 to
  /// kRuledOut - 2; a link holds either an entry number or such a mark).
  bool child_ruled_out(std::uint32_t e, std::uint32_t i, std::uint32_t tag) const {
    return links_[entries_[e].links + entries_[e].parents + i] == (kRuledOut | tag);
  }
  void rule_out_child(std::uint32_t e, std::uint32_t i, std::uint32_t tag) {
    std::uint32_t& link = links_[entries_[e].links + entries_[e].parents + i];
    if (link & kRuledOut) link = kRuledOut | tag;  // a child the memo has is not marked
  }
  /// A verdict of entry e's op for the current RCF: kept, or judged again (counted).
  bool verdict(const OpSource& source, std::uint32_t e, int which);
  /// The verdict last judged, lapsed or not.
  bool stored(std::uint32_t e, int which) const {
    return (entries_[e].verdicts & (1u << which)) != 0;
  }
  /// A verdict judged in an update, kept for `margin`.
  struct Lapse {
    float margin = 0.0f;
    std::uint32_t entry = 0;
    std::uint8_t which = 0;
  };
  /// Appends every verdict that lapses in this update and was not judged since (each judged
  /// verdict waits in its update's bucket, sorted by margin; the motion from that update's pose
  /// only grows the prefix that lapsed), without looking at the others: an update that needs no
  /// traversal of X (Session) learns what may have changed. Each lapse is reported once, and a
  /// verdict reported stays lapsed (verdict() judges it again) even if the camera comes back
  /// within its margin: nothing would report it when the camera left again.
  void collect_lapsed(std::vector<Lapse>& out);
  /// Verdicts held (judged for this signature, within the ring), lapsed or not.
  std::uint64_t held() const { return held_; }
  /// Whether the previous update was the one before this, for the same signature.
  bool continuous() const { return previous() != nullptr; }

  /// f(e) for every live entry e.
  template <class F>
  void for_each_entry(F&& f) {
    index_.for_each([&](std::uint64_t, std::uint32_t slot) { f(slot - 1); });
  }
  /// Forgets entries no update met in the last `idle` updates.
  void forget_idle(std::uint32_t idle);
  std::uint64_t judged() const { return judged_; }
  std::uint64_t kept() const { return kept_; }
  std::size_t size() const { return index_.size(); }
  std::uint64_t memory_bytes() const;
  /// The motion from the previous update's camera to the current one (0 without one).
  double last_motion() const;
  /// The least motion of the last three updates (the margin search's guess: OpMemo::judge).
  double steady_motion() const;
  const RcfPose& pose() const { return ring_[update_ % kRing].pose; }

 private:
  std::uint32_t linked(const OpSource& source, std::uint32_t at) {
    if (links_[at] & kRuledOut) {
      const std::uint32_t e = get(source, link_ids_[at]);  // may grow links_
      links_[at] = e;
    }
    return links_[at];
  }
  struct Judged {
    bool value = false;
    double margin = 0.0;
    int rung = 0;  // where the next search starts
  };
  Judged judge(const OpView& op, const OpSource& source, int which, bool seek, int hint,
               double scale) const;

  static constexpr std::uint32_t kRing = 256;    // poses kept: older verdicts lapse
  static constexpr std::uint8_t kReported = 16;  // Entry::verdicts: a lapse reported
  struct Epoch {
    std::uint32_t update = 0;
    RcfPose pose;
    double needed = 0.0;  // the motion from this pose to the current one, in its scale
  };
  const Epoch* previous() const;  // the previous update's, if it was the one before this
  std::uint64_t lapse_bytes() const;

  const RcfOracle* rcf_ = nullptr;
  std::uint32_t update_ = 0;
  std::uint32_t valid_from_ = 1;  // verdicts of earlier updates lapse (another signature)
  std::string signature_;
  std::array<Epoch, kRing> ring_{};
  IdMap<std::uint32_t> index_;  // op id -> 1 + entry
  std::vector<Entry> entries_;
  std::vector<OpId> ids_;             // by entry
  std::vector<std::uint32_t> free_;   // entries forgotten
  std::vector<std::uint32_t> links_;  // entry numbers; kNone: not looked up; kRuledOut | tag
  std::vector<OpId> link_ids_;        // parallel to links_
  std::uint64_t judged_ = 0, kept_ = 0, held_ = 0;
  std::array<std::vector<Lapse>, kRing> lapses_;  // by update: the verdicts it judged
  std::array<std::uint32_t, kRing> cursor_{};     // in each: those before it lapsed already
  std::array<bool, kRing> sorted_{};
  std::vector<Lapse> expired_;  // judged kRing updates ago (begin)
};

}  // namespace smr
