// point_triangle_distance3d (Voronoi-region closest point) against two oracles: the textbook
// "project onto the plane if inside, else the nearest edge" formula, and a dense barycentric
// sampling of the triangle (an upper bound within the sampling step of the true distance).
#include <algorithm>
#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include "smr/core/geometry.h"

namespace smr {
namespace {

double segment(const Vec3& p, const Vec3& a, const Vec3& b) {
  const Vec3 ab = b - a;
  const double l2 = glm::dot(ab, ab);
  const double t = l2 > 0.0 ? std::clamp(glm::dot(p - a, ab) / l2, 0.0, 1.0) : 0.0;
  return glm::length(p - (a + t * ab));
}

double textbook(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 n = glm::normalize(glm::cross(b - a, c - a));
  const double d = glm::dot(p - a, n);
  const Vec3 q = p - d * n;
  const bool inside = glm::dot(glm::cross(b - a, q - a), n) >= 0.0 &&
                      glm::dot(glm::cross(c - b, q - b), n) >= 0.0 &&
                      glm::dot(glm::cross(a - c, q - c), n) >= 0.0;
  if (inside) return std::abs(d);
  return std::min({segment(p, a, b), segment(p, b, c), segment(p, c, a)});
}

TEST(Geometry, PointTriangleDistanceMatchesTheOracles) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto point = [&] { return Vec3{u(rng), u(rng), u(rng)}; };
  for (int i = 0; i < 20000; ++i) {
    const Vec3 a = point(), b = point(), c = point();
    const Vec3 p = 2.0 * point();
    const double d = point_triangle_distance3d(p, a, b, c);
    ASSERT_NEAR(d, textbook(p, a, b, c), 1e-12) << "case " << i;
    if (i % 100 == 0) {
      double sampled = 1e300;
      const int n = 200;
      for (int s = 0; s <= n; ++s) {
        for (int t = 0; s + t <= n; ++t) {
          const double bs = double(s) / n, bt = double(t) / n;
          sampled = std::min(sampled, glm::length(p - (a + bs * (b - a) + bt * (c - a))));
        }
      }
      const double step = 2.0 * std::max({glm::length(b - a), glm::length(c - a)}) / n;
      EXPECT_LE(d, sampled + 1e-12);
      EXPECT_GE(d, sampled - step);
    }
  }
  // Degenerate triangles: the nearest edge.
  const Vec3 a{0, 0, 0}, b{1, 0, 0}, c{2, 0, 0};
  EXPECT_NEAR(point_triangle_distance3d({0.5, 1, 0}, a, b, c), 1.0, 1e-15);
  EXPECT_NEAR(point_triangle_distance3d({3, 0, 0}, a, b, c), 1.0, 1e-15);
  EXPECT_NEAR(point_triangle_distance3d({1, 1, 1}, a, a, a), std::sqrt(3.0), 1e-15);
}

}  // namespace
}  // namespace smr
