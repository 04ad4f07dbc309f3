// The measured screen-space error of a view-dependent output (Hoppe 1997's criterion, measured
// rather than bounded): exact distances from points to a triangle soup (Ericson, Real-Time
// Collision Detection 5.1.5, over a uniform grid of buckets), taken at ten samples of every
// visible triangle and projected to pixels as distance x focal_px / depth, both ways (output to
// source and source to output). bench_vdpm measures our cuts and OpenMesh VDPM's the same way.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <nlohmann/json.hpp>

#include "smr/core/geometry.h"
#include "smr/core/mesh.h"
#include "smr/rcf/camera.h"

namespace smr::bench::vdpm {

/// Closest point of the closed triangle abc to p (Ericson 5.1.5: Voronoi regions of the vertices,
/// then of the edges, else the face; a zero-area triangle: the nearest of its edges).
Vec3 closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

/// Uniform grid of buckets over a triangle soup: each triangle is listed in every bucket its box
/// meets. A query visits shells of buckets around the query's bucket and stops once no unvisited
/// bucket can hold a nearer triangle, so the answer is the minimum over all triangles.
class SoupDistance {
 public:
  explicit SoupDistance(std::vector<Triangle3> tris);

  bool empty() const { return tris_.empty(); }

  /// min over triangles of the distance from p to the closed triangle (infinity when empty).
  double distance(const Vec3& p) const;

 private:
  std::array<std::int64_t, 3> cell_of(const Vec3& p) const;
  std::size_t index(std::int64_t x, std::int64_t y, std::int64_t z) const;

  std::vector<Triangle3> tris_;
  Box3 box_;
  double cell_ = 1.0;
  std::array<std::int64_t, 3> dims_{1, 1, 1};
  std::vector<std::uint32_t> start_, items_;
  mutable std::vector<std::uint64_t> stamp_;  // the query that last saw each triangle
  mutable std::uint64_t query_ = 0;
};

/// In front of the eye and inside the four side planes of `planes` (cam.planes()).
bool inside_frustum(const Camera& cam, const std::array<Plane, 6>& planes, const Vec3& p);

/// A triangle is measured when it is front-facing and not wholly outside one frustum plane; of
/// its samples, those inside the frustum count.
bool visible_triangle(const Camera& cam, const std::array<Plane, 6>& planes, const Triangle3& t);

/// Vertices, edge midpoints, centroid and three interior points (barycentric 2/3, 1/6, 1/6).
std::array<Vec3, 10> samples(const Triangle3& t);

struct ErrorStats {
  std::uint64_t triangles_measured = 0;
  std::uint64_t samples = 0;
  double max_px = 0.0, p99_px = 0.0, mean_px = 0.0;
  double max_distance = 0.0;  // object space, model units
  nlohmann::json to_json() const;
};

/// Distance in pixels of each sample of each visible triangle of `from` to the surface `to`:
/// d x focal_px / depth, depth along the view direction.
ErrorStats measure(const std::vector<Triangle3>& from, const SoupDistance& to, const Camera& cam);

struct TwoSided {
  ErrorStats to_source;    // output samples -> source surface
  ErrorStats from_source;  // source samples -> output surface
  double max_px() const { return std::max(to_source.max_px, from_source.max_px); }
  double p99_px() const { return std::max(to_source.p99_px, from_source.p99_px); }
  nlohmann::json to_json() const;
};

/// Both ways: `output` to the source (through `source_distance`) and `source` to `output`.
TwoSided measure_both(const std::vector<Triangle3>& output, const std::vector<Triangle3>& source,
                      const SoupDistance& source_distance, const Camera& cam);

/// The triangles of `m` as a soup.
std::vector<Triangle3> triangles_of(const TriangleMesh& m);

/// v[f (n - 1)] of the sorted v (0 when empty).
double quantile(std::vector<double> v, double f);

}  // namespace smr::bench::vdpm
