// A hierarchical grid of triangle boxes (Ericson, "Real-Time Collision Detection", ch. 7):
// triangle_grid.h.
#include "smr/builders/mesh/triangle_grid.h"

#include <algorithm>
#include <bit>
#include <limits>

#include "base/error.h"

namespace smr::qem {

void TriangleGrid::reset(const Vec3& origin, double cell) {
  origin_ = origin;
  cell_ = cell > 0.0 ? cell : 1.0;
  levels_.assign(std::size_t(kSets) * kLevels, {});
  items_.clear();
  free_.clear();
  where_.clear();
}

std::uint32_t TriangleGrid::take_slab(std::uint8_t slab) {
  if (free_.size() <= slab) free_.resize(std::size_t(slab) + 1);
  std::vector<std::uint32_t>& free = free_[slab];
  if (!free.empty()) {
    const std::uint32_t begin = free.back();
    free.pop_back();
    return begin;
  }
  const std::size_t begin = items_.size();
  const std::size_t end = begin + slab_size(slab);
  if (end > std::numeric_limits<std::uint32_t>::max()) {
    throw_internal("triangle grid: more than 2^32 boxes in one block");
  }
  items_.resize(end);
  return static_cast<std::uint32_t>(begin);
}

void TriangleGrid::insert(std::uint32_t id, const Box3& b, int set, double key) {
  erase(id);  // a triangle is in one cell at most
  const Vec3 e = b.hi - b.lo;
  const double extent = std::max({e.x, e.y, e.z});
  int level = 0;
  double size = cell_;
  while (size < extent && level + 1 < kLevels) size *= 2.0, ++level;
  level += set * kLevels;
  Level& l = levels_[std::size_t(level)];
  const std::uint64_t cell_key = key_of(index_of(0.5 * (b.lo + b.hi), size));
  std::uint32_t& number = l.index[cell_key];  // the cell's index + 1; 0: a new cell
  if (number == 0) {
    if (l.keys.size() + 1 >= (std::size_t{1} << kCellBits))
      throw_internal("triangle grid: more than 2^25 cells in one level of one block");
    l.add_key(cell_key);
    l.cells.emplace_back();
    number = static_cast<std::uint32_t>(l.keys.size());
  }
  const std::uint32_t index = number - 1;
  Cell& c = l.cells[index];
  if (c.size == 0) ++l.occupied;
  if (c.slab == 0 || c.size == slab_size(c.slab)) {  // the next slab size
    const std::uint8_t slab = c.slab == 0 ? kFirstSlab : std::uint8_t(c.slab + 1);
    const std::uint32_t begin = take_slab(slab);
    std::copy_n(items_.begin() + c.begin, c.size, items_.begin() + begin);
    if (c.slab != 0) free_[c.slab].push_back(c.begin);
    c.begin = begin;
    c.slab = slab;
  }
  Item& x = items_[std::size_t(c.begin) + c.size];
  x.set_box(b);
  x.id = id;
  x.key = Item::above(key);
  if (where_.size() <= id) where_.resize(std::size_t(id) + 1);
  where_[id] = {std::uint32_t(level) << kCellBits | index, c.size};
  ++c.size;
}

void TriangleGrid::Level::add_key(std::uint64_t key) {
  constexpr std::size_t kBitsPerCell = 16, kLeastBits = 4096;
  // The bits first, so that keys and cells stay in step if making them throws.
  if ((keys.size() + 1) * kBitsPerCell > seen.size() * 64) {
    const std::size_t bits = std::max(kLeastBits, 2 * seen.size() * 64);
    std::vector<std::uint64_t> more(bits / 64, 0);
    seen.swap(more);
    seen_shift = 64 - static_cast<unsigned>(std::countr_zero(bits));
    for (const std::uint64_t k : keys) mark(k);
  }
  keys.push_back(key);
  mark(key);
}

void TriangleGrid::set_key(std::uint32_t id, double key) {
  if (id >= where_.size() || where_[id].level() == kNoLevel) return;  // not in the grid
  const Where& w = where_[id];
  const Cell& c = levels_[w.level()].cells[w.cell()];
  items_[std::size_t(c.begin) + w.slot].key = Item::above(key);
}

void TriangleGrid::erase(std::uint32_t id) {
  if (id >= where_.size() || where_[id].level() == kNoLevel) return;
  Where& w = where_[id];
  Level& l = levels_[w.level()];
  Cell& c = l.cells[w.cell()];
  const std::uint32_t last = c.size - 1;
  if (w.slot != last) {
    const Item& moved = items_[std::size_t(c.begin) + last];
    where_[moved.id].slot = w.slot;
    items_[std::size_t(c.begin) + w.slot] = moved;
  }
  if (--c.size == 0) {  // the slab goes back to the pool
    --l.occupied;
    free_[c.slab].push_back(c.begin);
    c.slab = 0;
  }
  w = Where{};
}

}  // namespace smr::qem
