// The tile cache of smrdb serve (tile_cache.h).
#include "tools/serve/tile_cache.h"

namespace smr::serve {

namespace {

std::size_t cost(const std::string& key, const CachedTile& t) {
  return key.size() + t.body.size() + t.etag.size() + 64;
}

}  // namespace

std::shared_ptr<const CachedTile> TileCache::get(const std::string& key) {
  std::lock_guard lock(mutex_);
  const auto it = index_.find(key);
  if (it == index_.end()) return nullptr;
  order_.splice(order_.begin(), order_, it->second);
  return it->second->second;
}

void TileCache::put(const std::string& key, std::shared_ptr<const CachedTile> tile) {
  const std::size_t c = cost(key, *tile);
  if (c > budget_) return;
  std::lock_guard lock(mutex_);
  if (index_.count(key) != 0) return;  // another thread cut it meanwhile
  order_.emplace_front(key, std::move(tile));
  index_[key] = order_.begin();
  bytes_ += c;
  while (bytes_ > budget_) {
    const Item& last = order_.back();
    bytes_ -= cost(last.first, *last.second);
    index_.erase(last.first);
    order_.pop_back();
  }
}

}  // namespace smr::serve
