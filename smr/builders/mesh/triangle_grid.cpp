// A hierarchical grid of triangle boxes (Ericson, "Real-Time Collision Detection", ch. 7):
// triangle_grid.h.
#include "smr/builders/mesh/triangle_grid.h"

#include <algorithm>

namespace smr::qem {

void TriangleGrid::reset(const Vec3& origin, double cell) {
  origin_ = origin;
  cell_ = cell > 0.0 ? cell : 1.0;
  levels_.assign(std::size_t(kSets) * kLevels, {});
  entries_.clear();
}

void TriangleGrid::insert(std::uint32_t id, const Box3& b, int set) {
  erase(id);  // a triangle is in one cell at most
  const Vec3 e = b.hi - b.lo;
  const double extent = std::max({e.x, e.y, e.z});
  int level = 0;
  double size = cell_;
  while (size < extent && level + 1 < kLevels) size *= 2.0, ++level;
  level += set * kLevels;
  Level& l = levels_[std::size_t(level)];
  const std::uint64_t key = key_of(index_of(0.5 * (b.lo + b.hi), size));
  std::uint32_t& slot = l.index[key];  // the cell's index + 1; 0: a new cell
  if (slot == 0) {
    l.keys.push_back(key);
    l.head.push_back(0);
    slot = static_cast<std::uint32_t>(l.keys.size());
  }
  const std::uint32_t cell = slot - 1;
  if (l.head[cell] == 0) ++l.occupied;
  if (entries_.size() <= id) entries_.resize(std::size_t(id) + 1);
  Entry& x = entries_[id];
  x.set_box(b);
  x.next = l.head[cell];
  x.cell = cell;
  x.level = level;
  l.head[cell] = id + 1;
}

void TriangleGrid::erase(std::uint32_t id) {
  if (id >= entries_.size() || entries_[id].level == kNoLevel) return;
  Entry& x = entries_[id];
  Level& l = levels_[std::size_t(x.level)];
  std::uint32_t* link = &l.head[x.cell];
  while (*link != id + 1) link = &entries_[*link - 1].next;
  *link = x.next;
  if (l.head[x.cell] == 0) --l.occupied;
  x.level = kNoLevel;
  x.next = 0;
}

}  // namespace smr::qem
