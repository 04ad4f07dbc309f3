// A hierarchical grid of triangle boxes (Ericson, "Real-Time Collision Detection", ch. 7):
// triangle_grid.h.
#include "smr/builders/mesh/triangle_grid.h"

#include <algorithm>

namespace smr::qem {

void TriangleGrid::reset(const Vec3& origin, double cell) {
  origin_ = origin;
  cell_ = cell > 0.0 ? cell : 1.0;
  levels_.assign(kLevels, {});
  where_.clear();
}

void TriangleGrid::insert(std::uint32_t id, const Box3& b) {
  const Vec3 e = b.hi - b.lo;
  const double extent = std::max({e.x, e.y, e.z});
  int level = 0;
  double size = cell_;
  while (size < extent && level + 1 < kLevels) size *= 2.0, ++level;
  Level& l = levels_[std::size_t(level)];
  const std::uint64_t key = key_of(index_of(0.5 * (b.lo + b.hi), size));
  std::uint32_t& slot = l.index[key];  // the cell's index + 1; 0: a new cell
  if (slot == 0) {
    l.keys.push_back(key);
    l.ids.emplace_back();
    slot = static_cast<std::uint32_t>(l.keys.size());
  }
  const std::uint32_t cell = slot - 1;
  if (l.ids[cell].empty()) ++l.occupied;
  l.ids[cell].push_back(Entry::of(id, b));
  if (where_.size() <= id) where_.resize(std::size_t(id) + 1, {kNoLevel, 0});
  where_[id] = {level, cell};
}

void TriangleGrid::erase(std::uint32_t id) {
  if (id >= where_.size() || where_[id].first == kNoLevel) return;
  Level& l = levels_[std::size_t(where_[id].first)];
  std::vector<Entry>& ids = l.ids[where_[id].second];
  *std::find_if(ids.begin(), ids.end(), [&](const Entry& e) { return e.id == id; }) = ids.back();
  ids.pop_back();
  if (ids.empty()) --l.occupied;
  where_[id].first = kNoLevel;
}

}  // namespace smr::qem
