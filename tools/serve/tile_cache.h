// Encoded quantized-mesh tiles of smrdb serve, least recently used first out, within a byte
// budget: a tile is cut from the database once while it stays in the cache. Thread-safe.
#pragma once

#include <cstddef>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <utility>

namespace smr::serve {

struct CachedTile {
  std::string body;  // empty: the tile holds no data
  std::string etag;
};

class TileCache {
 public:
  explicit TileCache(std::size_t budget_bytes) : budget_(budget_bytes) {}
  /// The tile under `key`, or nullptr.
  std::shared_ptr<const CachedTile> get(const std::string& key);
  /// Keeps `tile` under `key` (nothing when the budget is 0), dropping the least recently used.
  void put(const std::string& key, std::shared_ptr<const CachedTile> tile);

 private:
  using Item = std::pair<std::string, std::shared_ptr<const CachedTile>>;
  std::mutex mutex_;
  std::list<Item> order_;  // most recently used first
  std::unordered_map<std::string, std::list<Item>::iterator> index_;
  std::size_t budget_, bytes_ = 0;
};

}  // namespace smr::serve
