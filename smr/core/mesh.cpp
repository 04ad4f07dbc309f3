// Mesh utilities (mesh.h).
#include <algorithm>
#include <tuple>
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

namespace {

// The triangles as corner positions, each rotated to start at its least corner (the winding
// kept), with its value, sorted.
std::vector<std::tuple<std::array<double, 9>, float>> canonical(const TriangleMesh& m,
                                                                bool values) {
  std::vector<std::tuple<std::array<double, 9>, float>> out;
  out.reserve(m.triangles.size());
  for (std::size_t i = 0; i < m.triangles.size(); ++i) {
    std::array<std::array<double, 3>, 3> c;
    for (int k = 0; k < 3; ++k) {
      const Vec3& p = m.positions[m.triangles[i][std::size_t(k)]];
      c[std::size_t(k)] = {p.x, p.y, p.z};
    }
    std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
    std::array<double, 9> flat;
    for (std::size_t k = 0; k < 9; ++k) flat[k] = c[k / 3][k % 3];
    out.emplace_back(flat, values ? m.triangle_values[i] : 0.0f);
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

bool same_triangles(const TriangleMesh& a, const TriangleMesh& b) {
  if (a.triangles.size() != b.triangles.size()) return false;
  const bool values = a.triangle_values.size() == a.triangles.size() &&
                      b.triangle_values.size() == b.triangles.size();
  return canonical(a, values) == canonical(b, values);
}

}  // namespace smr
