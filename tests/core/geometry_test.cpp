// point_triangle_distance3d (Voronoi-region closest point) against two oracles: the textbook
// "project onto the plane if inside, else the nearest edge" formula, and a dense barycentric
// sampling of the triangle (an upper bound within the sampling step of the true distance).
#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <utility>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include "smr/core/geometry.h"
#include "smr/core/mesh.h"
#include "tests/support/mesh_distance.h"

namespace smr {
namespace {

TEST(Geometry, PointTriangleDistanceMatchesTheOracles) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto point = [&] { return Vec3{u(rng), u(rng), u(rng)}; };
  for (int i = 0; i < 20000; ++i) {
    const Vec3 a = point(), b = point(), c = point();
    const Vec3 p = 2.0 * point();
    const double d = point_triangle_distance3d(p, a, b, c);
    ASSERT_NEAR(d, test::textbook_triangle_distance(p, a, b, c), 1e-12) << "case " << i;
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

// Normal cones: the union holds both cones and every direction sampled in them; the stored
// (canonical) form holds the cone it was made from and encodes exactly.
TEST(Geometry, BoxesIntersectWhenClosedAndNeverWhenEmpty) {
  Box3 a, b;
  a.add(Vec3{0, 0, 0});
  a.add(Vec3{1, 1, 1});
  b.add(Vec3{1, 1, 1});  // one shared corner: closed boxes meet
  b.add(Vec3{2, 2, 2});
  EXPECT_TRUE(a.intersects(b));
  EXPECT_TRUE(b.intersects(a));
  Box3 c;
  c.add(Vec3{1.5, 0, 0});
  c.add(Vec3{2, 1, 1});  // apart along x only
  EXPECT_FALSE(a.intersects(c));
  EXPECT_FALSE(c.intersects(a));
  EXPECT_FALSE(a.intersects(Box3{}));
  EXPECT_FALSE(Box3{}.intersects(a));
}

TEST(Geometry, ConeUnionAndCanonicalFormHoldTheirCones) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> g;
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const auto random_axis = [&] { return glm::normalize(Vec3{g(rng), g(rng), g(rng)}); };
  // A direction inside `c` (on its rim when t = 1).
  const auto inside = [&](const NormalCone& c, double t) {
    Vec3 o = glm::cross(c.axis, random_axis());
    o = glm::normalize(o);
    const double a = t * c.half_angle;
    return std::cos(a) * c.axis + std::sin(a) * o;
  };
  const auto holds = [](const NormalCone& c, const Vec3& d) {
    return c.half_angle >= M_PI ||
           std::acos(std::clamp(glm::dot(c.axis, d), -1.0, 1.0)) <= c.half_angle + 1e-9;
  };
  int partial = 0;
  for (int i = 0; i < 2000; ++i) {
    const NormalCone a{random_axis(), u(rng) * 0.8}, b{random_axis(), u(rng) * 0.8};
    const NormalCone ab = cone_union(a, b);
    EXPECT_TRUE(cone_contains(ab, a) && cone_contains(ab, b));
    for (int k = 0; k < 8; ++k) {
      EXPECT_TRUE(holds(ab, inside(a, k == 0 ? 1.0 : u(rng))));
      EXPECT_TRUE(holds(ab, inside(b, k == 0 ? 1.0 : u(rng))));
    }
    // Never wider than the two cones side by side.
    const double between = std::acos(std::clamp(glm::dot(a.axis, b.axis), -1.0, 1.0));
    EXPECT_LE(ab.half_angle, std::max({a.half_angle, b.half_angle,
                                       0.5 * (between + a.half_angle + b.half_angle) + 1e-8}));
    const NormalCone c = canonical_cone(ab);
    EXPECT_TRUE(cone_contains(c, ab));
    EXPECT_EQ(decode_cone(cone_code(c)), c);
    // Idempotent: the DAG re-canonicalises a child's cone at every level (compute_rois).
    EXPECT_EQ(canonical_cone(c), c);
    if (c.half_angle < M_PI) {
      ++partial;
      // Rounding costs little: the axis's shift (half a code on each component of a vector of
      // length >= kConeAxisMax) and a step of the angle.
      const double shift = std::asin(std::sqrt(3.0) / 2.0 / double(kConeAxisMax));
      EXPECT_LE(c.half_angle, ab.half_angle + shift + kConeStep + 1e-9);
    }
  }
  EXPECT_GT(partial, 500);
  // Cones of pi/2 or more never cull: stored as the full cone.
  EXPECT_EQ(canonical_cone(NormalCone{Vec3{0, 0, 1}, M_PI / 2}).half_angle, M_PI);
  EXPECT_FALSE(cone_contains(NormalCone{Vec3{0, 0, 1}, 0.5}, NormalCone{Vec3{0, 0, 1}, M_PI}));
}

// Midpoint subdivision of a tetrahedron: V + E vertices, 4T triangles, the same area, every new
// vertex the midpoint of an edge, and still a closed, consistently oriented surface (each
// directed edge once, its reverse once).
TEST(MidpointSubdivided, KeepsTheSurfaceAndItsOrientation) {
  TriangleMesh tet;
  tet.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  tet.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  const auto area = [](const TriangleMesh& m) {
    double a = 0.0;
    for (const auto& t : m.triangles) {
      a += 0.5 * glm::length(glm::cross(m.positions[t[1]] - m.positions[t[0]],
                                        m.positions[t[2]] - m.positions[t[0]]));
    }
    return a;
  };
  const TriangleMesh twice = midpoint_subdivided(midpoint_subdivided(tet));
  ASSERT_EQ(twice.triangles.size(), 64u);
  EXPECT_EQ(twice.positions.size(), 34u);  // 4 + 6, then 10 + 24
  EXPECT_NEAR(area(twice), area(tet), 1e-12);
  std::set<std::pair<std::uint32_t, std::uint32_t>> directed;
  for (const auto& t : twice.triangles) {
    for (int k = 0; k < 3; ++k) EXPECT_TRUE(directed.insert({t[k], t[(k + 1) % 3]}).second);
  }
  for (const auto& [a, b] : directed) EXPECT_EQ(directed.count({b, a}), 1u);
  const TriangleMesh once = midpoint_subdivided(tet);
  for (std::uint32_t v = 4; v < once.positions.size(); ++v) {
    bool is_midpoint = false;
    for (std::uint32_t a = 0; a < 4; ++a) {
      for (std::uint32_t b = a + 1; b < 4; ++b) {
        is_midpoint =
            is_midpoint || once.positions[v] == 0.5 * (tet.positions[a] + tet.positions[b]);
      }
    }
    EXPECT_TRUE(is_midpoint) << v;
  }
}

}  // namespace
}  // namespace smr
