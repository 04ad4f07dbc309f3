// The mesh builder's star distance bounds (smr/builders/mesh/star_distance.h) against brute force:
// dense samples of each triangle, each measured against every target. On random stars (a hub and a
// ring of 5-8 corners at random heights, the targets with random offsets) a half-edge collapse of
// the hub onto a ring corner gives the new star:
//  - backward, bound() over a new triangle (and over random triangles near the star) is at least
//    the sampled max over it of min over old triangles k (distance to k + k's offset), and at
//    most that plus a sixteenth of the triangle's diameter; on average over the random
//    triangles, within 0.0004 of it (the prune that stops splitting where a point already
//    reaches the upper bound must not stop it early);
//  - with a floor, bound() is still at least the sampled max, and the larger of it and the floor
//    is the same as without one (the builder passes the collapse's bound so far as the floor);
//  - forward, charge() of every old triangle leaves each of its samples within some new triangle's
//    charge, less the old triangle's offset.
#include "smr/builders/mesh/star_distance.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

namespace smr {
namespace {

constexpr int kSamples = 48;

struct Star {
  Vec3 hub;
  std::vector<Vec3> ring;
  std::vector<double> offsets;  // per fan triangle (hub, ring[i], ring[i + 1])
};

Star random_star(std::mt19937_64& rng, double relief) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Star s;
  s.hub = {0.0, 0.0, 0.5 * relief * (u(rng) - 0.5)};
  const int n = 5 + int(u(rng) * 4.0);
  for (int i = 0; i < n; ++i) {
    const double a = 2.0 * M_PI * (i + 0.3 * (u(rng) - 0.5)) / n;
    const double r = 0.6 + 0.8 * u(rng);
    s.ring.push_back({r * std::cos(a), r * std::sin(a), relief * (u(rng) - 0.5)});
    // Half the stars have zero offsets (source triangles), the others bounds of earlier collapses.
    s.offsets.push_back(n % 2 == 0 ? 0.0 : 0.05 * u(rng));
  }
  return s;
}

// Samples of triangle (a, b, c) on a barycentric grid (corners and edges included).
std::vector<Vec3> samples(const Vec3& a, const Vec3& b, const Vec3& c) {
  std::vector<Vec3> out;
  for (int i = 0; i <= kSamples; ++i) {
    for (int j = 0; i + j <= kSamples; ++j) {
      const double x = double(i) / kSamples, y = double(j) / kSamples;
      out.push_back(a + x * (b - a) + y * (c - a));
    }
  }
  return out;
}

// min over targets of (distance + offset) at q.
double nearest(const std::vector<StarDistance::Target>& targets, const Vec3& q) {
  double best = std::numeric_limits<double>::infinity();
  for (const StarDistance::Target& t : targets)
    best = std::min(best, t.offset + std::sqrt(t.distance.squared(q)));
  return best;
}

double diameter(const StarDistance::Target& t) {
  return std::max({glm::length(t.b - t.a), glm::length(t.c - t.b), glm::length(t.a - t.c)});
}

TEST(StarDistance, BoundsHoldAgainstDenseSamplesAndAreTight) {
  std::mt19937_64 rng(20261204);
  int checked = 0, slack_used = 0;
  int floors_coarser = 0;      // bounds with a floor above the ones without (pieces left whole)
  double worst_excess = 0.0;   // (bound - sampled max) / diameter
  double random_excess = 0.0;  // its sum over the random triangles
  int random_checked = 0;
  for (int trial = 0; trial < 120; ++trial) {
    const Star s = random_star(rng, trial % 3 == 0 ? 0.6 : (trial % 3 == 1 ? 0.1 : 0.02));
    const std::size_t n = s.ring.size();
    const std::size_t to = std::size_t(trial) % n;  // the hub collapses onto ring[to]
    std::vector<StarDistance::Target> old_targets, new_targets;
    std::vector<std::size_t> image, preimage;  // old -> new (the 2 on the edge: 0), new -> old
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t j = (i + 1) % n;
      old_targets.emplace_back(s.hub, s.ring[i], s.ring[j], s.offsets[i]);
      if (i == to || j == to) {
        image.push_back(0);
        continue;
      }
      image.push_back(new_targets.size());
      preimage.push_back(i);
      new_targets.emplace_back(s.ring[to], s.ring[i], s.ring[j], 0.0);
    }
    StarDistance to_old, to_new;
    to_old.reset(old_targets, s.hub);
    to_new.reset(new_targets, s.ring[to]);

    // Backward: the bound over triangle t to the old star against its samples; returns the
    // excess over their maximum as a fraction of t's diameter.
    auto backward = [&](const StarDistance::Target& t, std::size_t first, const char* what, int k) {
      const double bound = to_old.bound(t.a, t.b, t.c, 0.0, kStarBoundDepth, first);
      double sampled = 0.0;
      for (const Vec3& q : samples(t.a, t.b, t.c))
        sampled = std::max(sampled, nearest(old_targets, q));
      const double d = diameter(t);
      EXPECT_GE(bound, sampled - 1e-12) << "trial " << trial << " " << what << " " << k;
      // The brute force misses the true maximum by at most the sample spacing (the function is
      // 1-Lipschitz); depth 3 leaves pieces of an eighth of the triangle.
      EXPECT_LE(bound, sampled + d / 16.0 + d / kSamples)
          << "trial " << trial << " " << what << " " << k;
      // With a floor (the builder passes the collapse's bound so far), pieces below it are not
      // refined: the result is still an upper bound, and above the floor it is the same.
      for (const double f : {0.5 * bound, 0.97 * bound, 1.5 * bound}) {
        const double floored = to_old.bound(t.a, t.b, t.c, f, kStarBoundDepth, first);
        EXPECT_GE(floored, sampled - 1e-12) << "trial " << trial << " " << what << " floor " << f;
        EXPECT_NEAR(std::max(floored, f), std::max(bound, f), 1e-12 * d)
            << "trial " << trial << " " << what << " floor " << f;
        floors_coarser += floored > bound + 1e-9;
      }
      worst_excess = std::max(worst_excess, (bound - sampled) / d);
      slack_used += bound > sampled + 1e-9;
      ++checked;
      return (bound - sampled) / d;
    };
    // Every new triangle.
    for (std::size_t k = 0; k < new_targets.size(); ++k)
      backward(new_targets[k], preimage[k], "new triangle", int(k));
    // Any triangle near the star (its pieces' cells then straddle the targets' Voronoi regions,
    // where only splitting tightens the bound).
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int k = 0; k < 3; ++k) {
      std::array<Vec3, 3> p;
      for (Vec3& c : p) c = {u(rng), u(rng), 0.3 * u(rng)};
      random_excess += backward({p[0], p[1], p[2], 0.0}, 0, "random triangle", k);
      ++random_checked;
    }

    // Forward: every point of an old triangle, within its offset of the source, is charged to
    // some new triangle.
    std::vector<double> charges(new_targets.size(), 0.0);
    double ceiling = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const StarDistance::Target& t = old_targets[i];
      to_new.charge(t.a, t.b, t.c, t.offset, kStarBoundDepth, image[i], charges, ceiling);
    }
    for (std::size_t i = 0; i < n; ++i) {
      const StarDistance::Target& t = old_targets[i];
      for (const Vec3& q : samples(t.a, t.b, t.c)) {
        bool held = false;
        for (std::size_t k = 0; k < new_targets.size() && !held; ++k) {
          held = t.offset + std::sqrt(new_targets[k].distance.squared(q)) <= charges[k] + 1e-12;
        }
        ASSERT_TRUE(held) << "trial " << trial << ": a point of old triangle " << i
                          << " is charged to no new triangle";
      }
    }
    EXPECT_LE(*std::max_element(charges.begin(), charges.end()), ceiling);
  }
  std::printf(
      "%d backward bounds: %d above the sampled maximum, at most by %.4f of the diameter; "
      "random triangles: %.5f on average; %d of %d with a floor coarser\n",
      checked, slack_used, worst_excess, random_excess / random_checked, floors_coarser,
      3 * checked);
  EXPECT_GT(checked, 300);
  EXPECT_GT(floors_coarser, 0);  // the floors above were not all idle
  // Splitting tightens the bounds of triangles that straddle the targets' regions: 0.00022 of
  // the diameter on average here, 0.00055 when no piece is split (the prune in bound() must not
  // stop splitting where a split still lowers the bound).
  EXPECT_LT(random_excess / random_checked, 0.0004);
}

}  // namespace
}  // namespace smr
