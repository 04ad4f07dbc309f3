// Shared helpers of the index tests: random entries, an in-memory node store, brute force.
#pragma once

#include <cmath>
#include <cstdint>
#include <map>
#include <random>
#include <vector>

#include "base/error.h"
#include "index/rtree.h"

namespace smr::index::test {

// The node table a caller would keep in LMDB, named "rtree" in the tree's messages.
struct MemoryStore {
  std::map<std::uint64_t, Bytes> nodes;
  std::vector<std::uint64_t> put_order;
  Bytes header;

  auto putter() {
    return [this](std::uint64_t id, ByteView node) {
      nodes[id] = Bytes(node.begin(), node.end());
      put_order.push_back(id);
    };
  }
  auto fetcher() const {
    return [this](std::uint64_t id) -> Bytes {
      const auto it = nodes.find(id);
      if (it == nodes.end()) throw Error(ErrorKind::kIo, "no node " + std::to_string(id));
      return it->second;
    };
  }
  RTree tree() const { return RTree(header, fetcher(), "rtree"); }
};

struct Built {
  Plan plan;
  MemoryStore store;
};

inline Built build(const std::vector<Entry>& entries, const BuildOptions& options) {
  Built b;
  b.plan = plan(entries, options);
  b.store.header = write(b.plan, entries, options, b.store.putter());
  return b;
}

// Random ops: boxes anywhere in [0, 1000]^2 x [0, 100] of sizes spanning four decades, rois
// grown from them, res in [0, 1), weights up to 600 bytes.
inline std::vector<Entry> random_entries(std::size_t n, std::uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Entry> out;
  out.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    Entry e;
    e.id = i * 7 + 3;
    const double size = 1000.0 * std::pow(10.0, -4.0 * unit(rng));
    const double extent[3] = {1000, 1000, 100};
    for (int a = 0; a < 3; ++a) {
      const double s = size * extent[a] / 1000.0 * (0.2 + unit(rng));
      const double c = extent[a] * unit(rng);
      e.box.lo[a] = c - s / 2;
      e.box.hi[a] = c + s / 2;
      e.roi.lo[a] = e.box.lo[a] - s * unit(rng);
      e.roi.hi[a] = e.box.hi[a] + s * unit(rng);
    }
    e.res = unit(rng);
    e.weight = static_cast<std::uint32_t>(unit(rng) * 600);
    out.push_back(e);
  }
  return out;
}

// Every stored entry, leaf by leaf.
inline std::vector<std::pair<std::uint32_t, Entry>> stored_entries(const RTree& tree) {
  std::vector<std::pair<std::uint32_t, Entry>> out;
  for (std::uint32_t leaf = 0; leaf < tree.leaf_count(); ++leaf) {
    for (const Entry& e : tree.leaf_entries(leaf)) out.emplace_back(leaf, e);
  }
  return out;
}

// The hits a full scan of the stored entries gives, in storage order.
template <typename Accept>
std::vector<Hit> brute_force(const std::vector<std::pair<std::uint32_t, Entry>>& stored,
                             Accept accept) {
  std::vector<Hit> hits;
  for (const auto& [leaf, e] : stored) {
    if (accept(e)) hits.push_back({leaf, e.id});
  }
  return hits;
}

}  // namespace smr::index::test
