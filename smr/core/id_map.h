// A flat hash map from 64-bit ids (OpId values, vertex ids) to small values: open addressing with
// linear probing, a power-of-two capacity and a load of at most 1/2 (or as chosen). Extraction
// keeps one entry per op of X, which on a whole-database output is every op: std::unordered_map
// spends ~40-50 bytes per entry on nodes and buckets, this map 2 x (8 + sizeof(V)) at worst, in two
// arrays. Erase shifts the following entries of the probe run back (no tombstones). The id ~0 is
// reserved as the empty marker. FlatMap is the same map over any key with an empty marker and a
// hash (KeyTraits): the expansion's front, keyed by (op, directed edge).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "base/error.h"
#include "smr/core/ids.h"  // mix64

namespace smr {

/// Keys of an IdMap: 64-bit ids, ~0 reserved.
struct IdKeys {
  static constexpr std::uint64_t empty() { return ~std::uint64_t{0}; }
  static std::size_t hash(std::uint64_t id) { return std::size_t(mix64(id)); }
};

template <class K, class V, class KeyTraits>
class FlatMap {
 public:
  using Key = K;
  static constexpr K kEmpty = KeyTraits::empty();

  FlatMap() = default;
  /// A map filled to at most `max_load_percent` of its slots (50 by default; a big map known in
  /// advance trades a few more probes for half the memory at 60-75).
  explicit FlatMap(unsigned max_load_percent) : max_load_(max_load_percent) {}

  std::size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }

  /// The value of `id`, inserted as V{} when absent. `id` must not be kEmpty.
  V& operator[](const K& id) {
    if ((size_ + 1) * 100 > keys_.size() * max_load_) grow();
    std::size_t i = slot(id);
    while (keys_[i] != kEmpty && keys_[i] != id) i = (i + 1) & mask_;
    if (keys_[i] == kEmpty) {
      keys_[i] = id;
      values_[i] = V{};
      ++size_;
    }
    return values_[i];
  }
  /// Inserts `id` (with V{}); false if it was there already.
  bool insert(const K& id) {
    const std::size_t before = size_;
    (*this)[id];
    return size_ != before;
  }
  const V* find(const K& id) const {
    if (size_ == 0) return nullptr;
    for (std::size_t i = slot(id);; i = (i + 1) & mask_) {
      if (keys_[i] == id) return &values_[i];
      if (keys_[i] == kEmpty) return nullptr;
    }
  }
  V* find(const K& id) { return const_cast<V*>(static_cast<const FlatMap&>(*this).find(id)); }
  bool contains(const K& id) const { return find(id) != nullptr; }
  /// Removes `id`; false if it was absent.
  bool erase(const K& id) {
    if (size_ == 0) return false;
    std::size_t i = slot(id);
    while (keys_[i] != id) {
      if (keys_[i] == kEmpty) return false;
      i = (i + 1) & mask_;
    }
    // Backward shift: move every later entry of the run whose home is not in (i, j] into i.
    for (std::size_t j = (i + 1) & mask_; keys_[j] != kEmpty; j = (j + 1) & mask_) {
      const std::size_t home = slot(keys_[j]);
      const bool stays = i <= j ? (i < home && home <= j) : (i < home || home <= j);
      if (stays) continue;
      keys_[i] = keys_[j];
      values_[i] = std::move(values_[j]);
      i = j;
    }
    keys_[i] = kEmpty;
    values_[i] = V{};
    --size_;
    return true;
  }
  /// Starts loading the slot where `id` would be (a lookup soon after then rarely waits on memory:
  /// callers looking up many scattered ids issue this a few ids ahead).
  void prefetch(const K& id) const {
    if (keys_.empty()) return;
    const std::size_t i = slot(id);
    __builtin_prefetch(&keys_[i]);
    __builtin_prefetch(&values_[i]);
  }
  /// Room for n entries without growing (one rehash at most).
  void reserve(std::size_t n) {
    std::size_t capacity = std::max<std::size_t>(16, keys_.size());
    while (n * 100 > capacity * max_load_) capacity *= 2;
    if (capacity > keys_.size()) rehash(capacity);
  }
  /// The bytes of its two arrays.
  std::size_t memory_bytes() const {
    return keys_.capacity() * sizeof(K) + values_.capacity() * sizeof(V);
  }
  /// Calls f(id, value) for every entry, in no particular order.
  template <class F>
  void for_each(F&& f) const {
    for (std::size_t i = 0; i < keys_.size(); ++i) {
      if (keys_[i] != kEmpty) f(keys_[i], values_[i]);
    }
  }

 private:
  std::size_t slot(const K& id) const { return KeyTraits::hash(id) & mask_; }
  void grow() { rehash(std::max<std::size_t>(16, 2 * keys_.size())); }
  void rehash(std::size_t capacity) {
    std::vector<K> keys(capacity, kEmpty);
    std::vector<V> values(keys.size());
    keys.swap(keys_);
    values.swap(values_);
    mask_ = keys_.size() - 1;
    for (std::size_t i = 0; i < keys.size(); ++i) {
      if (keys[i] == kEmpty) continue;
      std::size_t j = slot(keys[i]);
      while (keys_[j] != kEmpty) j = (j + 1) & mask_;
      keys_[j] = keys[i];
      values_[j] = std::move(values[i]);
    }
  }

  std::vector<K> keys_;
  std::vector<V> values_;
  std::size_t mask_ = 0;
  std::size_t size_ = 0;
  std::size_t max_load_ = 50;  // percent
};

template <class V>
using IdMap = FlatMap<std::uint64_t, V, IdKeys>;

/// Small values for the ids below `n` (op ids of a source), V{} until set: a plain array while it
/// takes at most kDenseBytes, else an IdMap, whose memory follows the ids set rather than n (a
/// view of a huge database sets few). The array is what a whole-database traversal wants: no
/// hashing, one byte per op.
template <class V>
class IdTable {
 public:
  static constexpr std::uint64_t kDenseBytes = std::uint64_t{8} << 20;
  explicit IdTable(std::uint64_t n) : dense_(n * sizeof(V) <= kDenseBytes) {
    if (dense_) array_.assign(std::size_t(n), V{});
  }
  /// The value of `id` (< n), to set.
  V& operator[](std::uint64_t id) {
    if (!dense_) return map_[id];
    if (id >= array_.size())
      throw_internal("IdTable: id " + std::to_string(id) + " beyond the table");
    return array_[std::size_t(id)];
  }
  /// True when it is an array over every id: a scan over ids then costs n, not a sort.
  bool dense() const { return dense_; }
  std::uint64_t size() const { return array_.size(); }  // n when dense
  V get(std::uint64_t id) const {
    if (dense_) return id < array_.size() ? array_[std::size_t(id)] : V{};
    const V* v = map_.find(id);
    return v != nullptr ? *v : V{};
  }

 private:
  bool dense_;
  std::vector<V> array_;
  IdMap<V> map_;
};

}  // namespace smr
