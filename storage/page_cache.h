// A least-recently-used cache of decoded pages under a byte budget (docs/design.md section 3: reads
// go through a page cache; section 8.7: extraction stays within its memory budget). Generic over
// the decoded value; thread-safe (one mutex; loads run outside it).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <span>
#include <unordered_map>
#include <vector>

namespace smr::storage {

struct CacheStats {
  std::uint64_t hits = 0, misses = 0, evictions = 0;
  std::uint64_t bytes_read = 0;       // sum of Loaded::bytes_read over all loads
  std::uint64_t bytes_decoded = 0;    // sum of Loaded::charged_bytes over all loads
  std::uint64_t held_bytes = 0;       // charged bytes of the values held now
  std::uint64_t peak_held_bytes = 0;  // never more than budget()
};

template <class Value>
class PageCache {
 public:
  explicit PageCache(std::size_t budget_bytes) : budget_(budget_bytes) {}
  PageCache(const PageCache&) = delete;
  PageCache& operator=(const PageCache&) = delete;

  struct Loaded {
    std::shared_ptr<const Value> value;
    std::size_t charged_bytes = 0;  // what holding the value costs against the budget
    std::size_t bytes_read = 0;     // bytes read from storage to produce it (statistics only)
  };

  // The cached value for `key`, or the result of load() on a miss. A value is charged
  // `charged_bytes` while it is in the cache; the cache holds at most budget() bytes and evicts
  // the least recently used values first; a value larger than the whole budget is returned but
  // not kept. Evicted values stay alive while callers hold them. load() runs without the lock,
  // so two threads missing the same key may both load it (the first one stored is kept); an
  // exception from load() propagates and caches nothing.
  template <class Load>  // Loaded load()
  std::shared_ptr<const Value> get(std::uint64_t key, Load&& load) {
    {
      std::lock_guard lock(mutex_);
      if (auto it = index_.find(key); it != index_.end()) {
        ++stats_.hits;
        lru_.splice(lru_.begin(), lru_, it->second);
        return it->second->value;
      }
      ++stats_.misses;
    }
    Loaded loaded = load();
    std::lock_guard lock(mutex_);
    stats_.bytes_read += loaded.bytes_read;
    stats_.bytes_decoded += loaded.charged_bytes;
    if (auto it = index_.find(key); it != index_.end()) {  // another thread was faster
      lru_.splice(lru_.begin(), lru_, it->second);
      return it->second->value;
    }
    if (loaded.charged_bytes > budget_) return std::move(loaded.value);
    while (stats_.held_bytes + loaded.charged_bytes > budget_) evict_one();
    lru_.push_front(Entry{key, loaded.value, loaded.charged_bytes});
    index_.emplace(key, lru_.begin());
    stats_.held_bytes += loaded.charged_bytes;
    stats_.peak_held_bytes = std::max(stats_.peak_held_bytes, stats_.held_bytes);
    return std::move(loaded.value);
  }

  // True if `key` is cached (does not count as a hit or change the LRU order).
  bool contains(std::uint64_t key) const {
    std::lock_guard lock(mutex_);
    return index_.count(key) != 0;
  }

  // The keys that are not cached, in the given order (one lock for all; no statistics change).
  std::vector<std::uint64_t> missing(std::span<const std::uint64_t> keys) const {
    std::vector<std::uint64_t> out;
    std::lock_guard lock(mutex_);
    for (std::uint64_t k : keys) {
      if (index_.count(k) == 0) out.push_back(k);
    }
    return out;
  }

  CacheStats stats() const {
    std::lock_guard lock(mutex_);
    return stats_;
  }
  std::size_t budget() const { return budget_; }
  std::size_t size() const {
    std::lock_guard lock(mutex_);
    return index_.size();
  }

  // Drops the cached values whose key satisfies `drop` (counters are kept; not counted as
  // evictions). Readers holding one keep it.
  template <class Pred>
  void erase_if(Pred&& drop) {
    std::lock_guard lock(mutex_);
    for (auto it = lru_.begin(); it != lru_.end();) {
      if (!drop(it->key)) {
        ++it;
        continue;
      }
      stats_.held_bytes -= it->charged_bytes;
      index_.erase(it->key);
      it = lru_.erase(it);
    }
  }

  // Drops every cached value (counters are kept; held_bytes becomes 0).
  void clear() {
    std::lock_guard lock(mutex_);
    lru_.clear();
    index_.clear();
    stats_.held_bytes = 0;
  }

 private:
  struct Entry {
    std::uint64_t key;
    std::shared_ptr<const Value> value;
    std::size_t charged_bytes;
  };

  void evict_one() {  // mutex_ held, lru_ not empty
    const Entry& victim = lru_.back();
    stats_.held_bytes -= victim.charged_bytes;
    ++stats_.evictions;
    index_.erase(victim.key);
    lru_.pop_back();
  }

  const std::size_t budget_;
  mutable std::mutex mutex_;
  std::list<Entry> lru_;  // most recently used first
  std::unordered_map<std::uint64_t, typename std::list<Entry>::iterator> index_;
  CacheStats stats_;
};

}  // namespace smr::storage
