#include "tests/support/mesh_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <glm/geometric.hpp>

namespace smr::test {

TriangleSoupDistance::TriangleSoupDistance(std::vector<std::array<Vec3, 3>> triangles,
                                           std::vector<double> radii)
    : tris_(std::move(triangles)), radii_(std::move(radii)) {
  if (!radii_.empty() && radii_.size() != tris_.size()) {
    throw std::invalid_argument("TriangleSoupDistance: one radius per triangle");
  }
  for (double r : radii_) max_radius_ = std::max(max_radius_, r);
  for (const auto& t : tris_) {
    for (const Vec3& p : t) box_.add(p);
  }
  if (tris_.empty()) return;
  const Vec3 ext = glm::max(box_.hi - box_.lo, Vec3(1e-9));
  // About two triangles per bucket.
  const double volume = ext.x * ext.y * ext.z;
  cell_ = std::cbrt(volume / std::max<double>(1.0, double(tris_.size()) / 2.0));
  cell_ = std::max(cell_, std::max({ext.x, ext.y, ext.z}) / 256.0);
  for (int k = 0; k < 3; ++k)
    dims_[k] = std::max<std::int64_t>(1, std::int64_t(ext[k] / cell_) + 1);
  const auto bucket = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
    return std::size_t((z * dims_[1] + y) * dims_[0] + x);
  };
  std::vector<std::uint32_t> count(std::size_t(dims_[0] * dims_[1] * dims_[2]) + 1, 0);
  for (int pass = 0; pass < 2; ++pass) {
    for (std::uint32_t i = 0; i < tris_.size(); ++i) {
      Box3 b;
      for (const Vec3& p : tris_[i]) b.add(p);
      const auto lo = cell_of(b.lo), hi = cell_of(b.hi);
      for (std::int64_t z = lo[2]; z <= hi[2]; ++z) {
        for (std::int64_t y = lo[1]; y <= hi[1]; ++y) {
          for (std::int64_t x = lo[0]; x <= hi[0]; ++x) {
            if (pass == 0) {
              ++count[bucket(x, y, z) + 1];
            } else {
              items_[count[bucket(x, y, z)]++] = i;
            }
          }
        }
      }
    }
    if (pass == 0) {
      for (std::size_t b = 1; b < count.size(); ++b) count[b] += count[b - 1];
      start_ = count;
      items_.resize(count.back());
    }
  }
}

std::array<std::int64_t, 3> TriangleSoupDistance::cell_of(const Vec3& p) const {
  std::array<std::int64_t, 3> c{};
  for (int k = 0; k < 3; ++k) {
    c[k] = std::clamp<std::int64_t>(std::int64_t(std::floor((p[k] - box_.lo[k]) / cell_)), 0,
                                    dims_[k] - 1);
  }
  return c;
}

bool TriangleSoupDistance::within_own_radius(const Vec3& p, double scale) const {
  if (radii_.empty()) throw std::logic_error("TriangleSoupDistance: no radii given");
  bool found = false;
  // Rings of buckets outwards, as in search(), until a triangle is found or no farther bucket
  // is within the largest radius.
  const Vec3 outside = glm::max(glm::max(box_.lo - p, p - box_.hi), Vec3(0.0));
  const double to_box = glm::length(outside);
  const auto c = cell_of(p);
  const std::int64_t max_ring = std::max({dims_[0], dims_[1], dims_[2]});
  for (std::int64_t r = 0; r <= max_ring && !found; ++r) {
    if (std::max(to_box, double(r - 1) * cell_) > scale * max_radius_) break;
    for_ring(c, r, [&](std::uint32_t i) {
      const auto& t = tris_[i];
      found = found || point_triangle_distance3d(p, t[0], t[1], t[2]) <= scale * radii_[i];
    });
  }
  return found;
}

double TriangleSoupDistance::search(const Vec3& p, double radius) const {
  double best = std::numeric_limits<double>::infinity();
  if (tris_.empty()) return best;
  // Buckets at ring r or beyond are at least (r - 1) cells away, and never nearer than the box.
  const Vec3 outside = glm::max(glm::max(box_.lo - p, p - box_.hi), Vec3(0.0));
  const double to_box = glm::length(outside);
  const auto c = cell_of(p);
  const std::int64_t max_ring = std::max({dims_[0], dims_[1], dims_[2]});
  for (std::int64_t r = 0; r <= max_ring; ++r) {
    const double nearest_beyond = std::max(to_box, double(r - 1) * cell_);
    if (r > 0 && best <= nearest_beyond) break;
    if (radius >= 0.0 && (best <= radius || nearest_beyond > radius)) break;
    for_ring(c, r, [&](std::uint32_t i) {
      const auto& t = tris_[i];
      best = std::min(best, point_triangle_distance3d(p, t[0], t[1], t[2]));
    });
  }
  return best;
}

}  // namespace smr::test
