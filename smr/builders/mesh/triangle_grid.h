// Triangles by their bounding boxes, for the QEM builder's self-intersection test
// (collapse_crossings.h): a hierarchical grid (Ericson, "Real-Time Collision Detection", ch. 7),
// cell sizes cell * 2^level, cells in open-addressing tables (std::unordered_map's node chains
// made the lookups most of the test's time on large meshes), each triangle in the one cell of
// the level whose cells are at least its box's extent that holds its box's centre. At a level of
// cell size s, a box then meets only triangles of the cells holding its own box grown by s / 2;
// where that range has more cells than the level holds, the level's cells are scanned instead.
// The grid keeps each triangle's box, so the boxes that miss the query are dropped without
// touching the mesh. A cell's boxes lie side by side in a slab of a shared pool (slabs of 2, 3,
// 4, 6, 8, 12 ... items, reused through free lists per size): a query scans ~8 boxes for every one
// it meets (the loose cells, and the dead triangles the test keeps), and when each box was a record
// by triangle id chained from its cell, every one of them was a cache miss (40 % of the visits'
// time, the largest single cost of a mesh ingest). A triangle's place (level, cell, slot) is
// kept by id; erasing moves its cell's last box into its slot. Visited in no particular order.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

#include "smr/core/geometry.h"
#include "smr/core/id_map.h"

namespace smr::qem {

class TriangleGrid {
 public:
  // Two sets of triangles share the grid's records (a triangle is in one of them at most): the
  // self-intersection test's live and recently dead triangles, and the others it keeps
  // (collapse_crossings.h).
  static constexpr int kSets = 2;
  void reset(const Vec3& origin, double cell);
  // Puts triangle `id` in `set` with `key` (taking it out of where it was).
  void insert(std::uint32_t id, const Box3& b, int set = 0,
              double key = std::numeric_limits<double>::infinity());
  void erase(std::uint32_t id);
  // A new key for triangle `id` (none if it is not in the grid). Keys let a query pass over
  // triangles without reading anything but the grid's own memory (collapse_crossings.cpp: a dead
  // triangle's key is its destroyer's bound).
  void set_key(std::uint32_t id, double key);
  // f(id, box) for every triangle of `set` whose box meets b (box: its box, rounded outwards to
  // floats), except some whose key is at most `least`: a key is kept rounded up to a float, so a
  // triangle passed over has its key <= least, and f still sees some that do.
  template <class F>
  void visit(const Box3& b, F&& f, int set = 0,
             double least = -std::numeric_limits<double>::infinity()) const {
    double size = cell_;
    for (int level = 0; level < kLevels; ++level, size *= 2.0) {
      const Level& l = levels_[std::size_t(set * kLevels + level)];
      if (l.occupied == 0) continue;
      const Vec3 half(0.5 * size);
      const std::array<std::int64_t, 3> lo = index_of(b.lo - half, size),
                                        hi = index_of(b.hi + half, size);
      double range = 1.0;
      for (int k = 0; k < 3; ++k) range *= double(hi[std::size_t(k)] - lo[std::size_t(k)] + 1);
      const auto inside = [&](std::uint64_t key) {
        for (int k = 0; k < 3; ++k) {
          const auto i = std::int64_t((key >> (21 * k)) & kMask) - kOffset;
          if (i < lo[std::size_t(k)] || i > hi[std::size_t(k)]) return false;
        }
        return true;
      };
      if (range > double(l.keys.size())) {  // fewer cells than the range: all of them
        for (std::size_t c = 0; c < l.keys.size(); ++c) {
          if (l.cells[c].size == 0 || !inside(l.keys[c])) continue;
          visit_cell(l.cells[c], b, least, f);
        }
        continue;
      }
      for (std::int64_t x = lo[0]; x <= hi[0]; ++x) {
        for (std::int64_t y = lo[1]; y <= hi[1]; ++y) {
          for (std::int64_t z = lo[2]; z <= hi[2]; ++z) {
            const std::uint64_t key = key_of({x, y, z});
            if (!l.may_hold(key)) continue;
            const std::uint32_t* slot = l.index.find(key);
            if (slot != nullptr) visit_cell(l.cells[*slot - 1], b, least, f);
          }
        }
      }
    }
  }

 private:
  static constexpr int kLevels = 40;              // kSets * kLevels < kNoLevel
  static constexpr std::uint32_t kNoLevel = 127;  // Where: not in the grid
  static constexpr int kCellBits = 25;            // Where: cells per level < 2^25
  static_assert(kSets * kLevels < int(kNoLevel) && kNoLevel < (1u << (32 - kCellBits)));
  static constexpr std::int64_t kOffset = std::int64_t{1} << 20;
  static constexpr std::uint64_t kMask = (std::uint64_t{1} << 21) - 1;
  static constexpr std::uint8_t kFirstSlab = 1;                        // the least slab: 2 items
  static constexpr std::uint64_t kHashFactor = 0x9e3779b97f4a7c15ull;  // Level::seen
  // Slab sizes grow by 3/2 or 4/3 in turn (1: 2 items, 2: 3, 3: 4, 4: 6, 5: 8, ...): a growing
  // cell's slab is at least 2/3 full once it holds 2 items or more (erasures do not shrink it).
  static std::uint32_t slab_size(std::uint8_t slab) {
    return slab % 2 ? std::uint32_t{1} << ((slab + 1) / 2) : std::uint32_t{3} << (slab / 2 - 1);
  }
  // A triangle's box in floats, rounded outwards, its id and its key, rounded up.
  struct Item {
    std::array<float, 3> lo, hi;
    std::uint32_t id = 0;
    float key = 0.0f;
    void set_box(const Box3& b) {
      for (int k = 0; k < 3; ++k) {
        lo[std::size_t(k)] = below(b.lo[k]);
        hi[std::size_t(k)] = above(b.hi[k]);
      }
    }
    // The largest float <= x and the smallest >= x (outside floats' range: the float at its end
    // or an infinity, never a conversion out of range).
    static float below(double x) {
      constexpr float kMax = std::numeric_limits<float>::max();
      if (x > double(kMax)) return kMax;
      if (x < -double(kMax)) return -std::numeric_limits<float>::infinity();
      const auto f = static_cast<float>(x);
      return double(f) <= x ? f : std::nextafter(f, -std::numeric_limits<float>::infinity());
    }
    static float above(double x) {
      constexpr float kMax = std::numeric_limits<float>::max();
      if (x > double(kMax)) return std::numeric_limits<float>::infinity();
      if (x < -double(kMax)) return -kMax;
      const auto f = static_cast<float>(x);
      return double(f) >= x ? f : std::nextafter(f, std::numeric_limits<float>::infinity());
    }
    template <class F>
    void visit(const Box3& b, double least, F& f) const {
      if (double(key) <= least) return;
      for (int k = 0; k < 3; ++k) {
        if (double(lo[std::size_t(k)]) > b.hi[k] || double(hi[std::size_t(k)]) < b.lo[k]) return;
      }
      Box3 box;
      box.lo = Vec3(lo[0], lo[1], lo[2]);
      box.hi = Vec3(hi[0], hi[1], hi[2]);
      f(id, box);
    }
  };
  // A cell: its items, items_[begin, begin + size), in a slab of slab_size(slab) items (slab 0:
  // none).
  struct Cell {
    std::uint32_t begin = 0, size = 0;
    std::uint8_t slab = 0;
  };
  // One grid: its cells in a flat hash table (cells emptied stay, to be filled again; their slabs
  // go back to the pool).
  //
  // A query's range is mostly cells the level never had (~65 lookups a query, most of them
  // misses, each a cache miss in the table): a bit per hash of a cell key, 16 to 32 bits a cell
  // (at least 4096 a level), answers most of them first. Made with the level's first cell: visit()
  // reads it only in levels holding a triangle.
  struct Level {
    IdMap<std::uint32_t> index;       // cell key -> its index + 1
    std::vector<std::uint64_t> keys;  // per cell
    std::vector<Cell> cells;          // per cell
    std::size_t occupied = 0;         // cells holding a triangle
    std::vector<std::uint64_t> seen;  // bit hash(key): some cell has that hash
    unsigned seen_shift = 52;         // hash(key) = (key * odd) >> seen_shift

    std::uint64_t bit_of(std::uint64_t key) const { return (key * kHashFactor) >> seen_shift; }
    bool may_hold(std::uint64_t key) const {
      const std::uint64_t h = bit_of(key);
      return (seen[h >> 6] >> (h & 63)) & 1u;
    }
    void mark(std::uint64_t key) {
      const std::uint64_t h = bit_of(key);
      seen[h >> 6] |= std::uint64_t{1} << (h & 63);
    }
    // A new cell's key, in keys and in seen (which doubles, all keys marked again, as it fills).
    void add_key(std::uint64_t key);
  };
  // Where a triangle is, by id: its level (set * kLevels + level; kNoLevel: not in the grid) and
  // cell in one word, and its slot.
  struct Where {
    std::uint32_t place = kNoLevel << kCellBits;
    std::uint32_t slot = 0;
    std::uint32_t level() const { return place >> kCellBits; }
    std::uint32_t cell() const { return place & ((std::uint32_t{1} << kCellBits) - 1); }
  };
  template <class F>
  void visit_cell(const Cell& c, const Box3& b, double least, F& f) const {
    const Item* it = items_.data() + c.begin;
    for (const Item* end = it + c.size; it != end; ++it) it->visit(b, least, f);
  }
  // A slab of slab_size(slab) items: one freed before, or new at the pool's end.
  std::uint32_t take_slab(std::uint8_t slab);
  std::array<std::int64_t, 3> index_of(const Vec3& p, double size) const {
    std::array<std::int64_t, 3> i{};
    for (int k = 0; k < 3; ++k) {
      const double c = std::floor((p[k] - origin_[k]) / size);
      i[std::size_t(k)] = std::int64_t(std::clamp(c, -double(kOffset), double(kOffset - 1)));
    }
    return i;
  }
  // 3 x 21 bits: never IdMap's empty key.
  static std::uint64_t key_of(const std::array<std::int64_t, 3>& i) {
    std::uint64_t key = 0;
    for (int k = 0; k < 3; ++k) key |= std::uint64_t(i[std::size_t(k)] + kOffset) << (21 * k);
    return key;
  }
  Vec3 origin_{0.0};
  double cell_ = 1.0;
  std::vector<Level> levels_;
  std::vector<Item> items_;                       // the slabs
  std::vector<std::vector<std::uint32_t>> free_;  // per slab size: the free slabs' starts
  std::vector<Where> where_;                      // by triangle id
};

}  // namespace smr::qem
