// Mesh utilities (mesh.h).
#include <algorithm>
#include <unordered_map>

#include "smr/core/mesh.h"

namespace smr {

TriangleMesh midpoint_subdivided(const TriangleMesh& in) {
  TriangleMesh out;
  out.positions = in.positions;
  out.positions.reserve(in.positions.size() + in.triangles.size() * 3 / 2 + 16);
  out.triangles.reserve(in.triangles.size() * 4);
  std::unordered_map<std::uint64_t, std::uint32_t> mid;
  mid.reserve(in.triangles.size() * 2);
  auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
    const std::uint64_t key = (std::uint64_t(std::min(a, b)) << 32) | std::uint64_t(std::max(a, b));
    auto [it, inserted] = mid.try_emplace(key, std::uint32_t(out.positions.size()));
    if (inserted) out.positions.push_back(0.5 * (in.positions[a] + in.positions[b]));
    return it->second;
  };
  for (const auto& t : in.triangles) {
    const std::uint32_t ab = midpoint(t[0], t[1]), bc = midpoint(t[1], t[2]),
                        ca = midpoint(t[2], t[0]);
    out.triangles.push_back({t[0], ab, ca});
    out.triangles.push_back({ab, t[1], bc});
    out.triangles.push_back({ca, bc, t[2]});
    out.triangles.push_back({ab, bc, ca});
  }
  return out;
}

}  // namespace smr
