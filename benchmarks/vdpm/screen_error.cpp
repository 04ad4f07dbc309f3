#include "benchmarks/vdpm/screen_error.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <glm/geometric.hpp>

namespace smr::bench::vdpm {

using nlohmann::json;

Vec3 closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Vec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + ab * (d1 / (d1 - d3));
  const Vec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0)
    return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = va + vb + vc;
  if (!(std::abs(denom) > 0.0)) {  // zero-area triangle: the nearest of its three edges
    auto seg = [&](const Vec3& s, const Vec3& t) {
      const Vec3 st = t - s;
      const double l2 = glm::dot(st, st);
      const double u = l2 > 0.0 ? std::clamp(glm::dot(p - s, st) / l2, 0.0, 1.0) : 0.0;
      return s + st * u;
    };
    const std::array<Vec3, 3> q{seg(a, b), seg(b, c), seg(c, a)};
    return *std::min_element(q.begin(), q.end(), [&](const Vec3& x, const Vec3& y) {
      return glm::dot(x - p, x - p) < glm::dot(y - p, y - p);
    });
  }
  const double v = vb / denom, w = vc / denom;
  return a + ab * v + ac * w;
}

SoupDistance::SoupDistance(std::vector<Triangle3> tris) : tris_(std::move(tris)) {
  for (const Triangle3& t : tris_)
    for (const Vec3& p : t) box_.add(p);
  if (tris_.empty()) return;
  const Vec3 ext = glm::max(box_.hi - box_.lo, Vec3(1e-12));
  const double diag = glm::length(ext);
  box_.lo -= Vec3(1e-9 * diag);
  box_.hi += Vec3(1e-9 * diag);
  const Vec3 e = box_.hi - box_.lo;
  // About one bucket per triangle, never thinner than 1/256 of the diagonal.
  const double volume =
      std::max(e.x, diag / 256) * std::max(e.y, diag / 256) * std::max(e.z, diag / 256);
  cell_ = std::max(std::cbrt(volume / double(tris_.size())), diag / 256);
  for (int i = 0; i < 3; ++i)
    dims_[i] = std::clamp<std::int64_t>(std::int64_t(std::ceil(e[i] / cell_)), 1, 512);
  const std::size_t n = std::size_t(dims_[0] * dims_[1] * dims_[2]);
  std::vector<std::uint32_t> count(n + 1, 0);
  auto for_cells = [&](const Triangle3& t, auto&& f) {
    smr::Box3 b;
    for (const Vec3& p : t) b.add(p);
    const auto lo = cell_of(b.lo), hi = cell_of(b.hi);
    for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
      for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
        for (std::int64_t x = lo[0]; x <= hi[0]; ++x) f(index(x, y, z));
  };
  for (const Triangle3& t : tris_) for_cells(t, [&](std::size_t c) { ++count[c + 1]; });
  std::partial_sum(count.begin(), count.end(), count.begin());
  start_ = count;
  items_.resize(count.back());
  for (std::uint32_t i = 0; i < tris_.size(); ++i)
    for_cells(tris_[i], [&](std::size_t c) { items_[count[c]++] = i; });
  stamp_.assign(tris_.size(), 0);
}

double SoupDistance::distance(const Vec3& p) const {
  if (tris_.empty()) return std::numeric_limits<double>::infinity();
  ++query_;
  const auto c = cell_of(p);
  double best2 = std::numeric_limits<double>::infinity();
  for (std::int64_t k = 0;; ++k) {
    // The shell of buckets at Chebyshev distance exactly k from c.
    for (std::int64_t dz = -k; dz <= k; ++dz) {
      const std::int64_t z = c[2] + dz;
      if (z < 0 || z >= dims_[2]) continue;
      for (std::int64_t dy = -k; dy <= k; ++dy) {
        const std::int64_t y = c[1] + dy;
        if (y < 0 || y >= dims_[1]) continue;
        const bool face = std::abs(dz) == k || std::abs(dy) == k;
        for (std::int64_t dx = -k; dx <= k; dx += face ? 1 : std::max<std::int64_t>(2 * k, 1)) {
          const std::int64_t x = c[0] + dx;
          if (x < 0 || x >= dims_[0]) continue;
          const std::size_t b = index(x, y, z);
          for (std::uint32_t j = start_[b]; j < start_[b + 1]; ++j) {
            const std::uint32_t i = items_[j];
            if (stamp_[i] == query_) continue;
            stamp_[i] = query_;
            const Triangle3& t = tris_[i];
            const Vec3 q = closest_point_on_triangle(p, t[0], t[1], t[2]);
            best2 = std::min(best2, glm::dot(q - p, q - p));
          }
        }
      }
    }
    // Triangles not seen yet lie outside the block of buckets within k of c (inside the grid),
    // so at least as far from p as the nearest face of that block that is not a grid face.
    double bound = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
      if (c[a] - k > 0) bound = std::min(bound, p[a] - (box_.lo[a] + double(c[a] - k) * cell_));
      if (c[a] + k + 1 < dims_[a])
        bound = std::min(bound, (box_.lo[a] + double(c[a] + k + 1) * cell_) - p[a]);
    }
    if (bound == std::numeric_limits<double>::infinity()) break;  // the block is the grid
    if (bound > 0.0 && best2 <= bound * bound) break;
  }
  return std::sqrt(best2);
}

std::array<std::int64_t, 3> SoupDistance::cell_of(const Vec3& p) const {
  std::array<std::int64_t, 3> c{};
  for (int i = 0; i < 3; ++i)
    c[i] = std::clamp<std::int64_t>(std::int64_t(std::floor((p[i] - box_.lo[i]) / cell_)), 0,
                                    dims_[i] - 1);
  return c;
}

std::size_t SoupDistance::index(std::int64_t x, std::int64_t y, std::int64_t z) const {
  return std::size_t((z * dims_[1] + y) * dims_[0] + x);
}

bool inside_frustum(const smr::Camera& cam, const std::array<smr::Plane, 6>& planes,
                    const Vec3& p) {
  if (glm::dot(p - cam.eye, cam.forward()) <= 0.0) return false;
  for (int i = 0; i < 4; ++i)
    if (planes[i].signed_distance(p) < 0.0) return false;
  return true;
}

bool visible_triangle(const smr::Camera& cam, const std::array<smr::Plane, 6>& planes,
                      const Triangle3& t) {
  const Vec3 n = glm::cross(t[1] - t[0], t[2] - t[0]);
  if (!(glm::dot(n, cam.eye - t[0]) > 0.0)) return false;
  for (int i = 0; i < 5; ++i) {
    if (planes[i].signed_distance(t[0]) < 0 && planes[i].signed_distance(t[1]) < 0 &&
        planes[i].signed_distance(t[2]) < 0)
      return false;
  }
  return true;
}

std::array<Vec3, 10> samples(const Triangle3& t) {
  const Vec3 g = (t[0] + t[1] + t[2]) / 3.0;
  auto in = [&](int i) { return (4.0 * t[i] + t[(i + 1) % 3] + t[(i + 2) % 3]) / 6.0; };
  return {t[0],  t[1],  t[2], 0.5 * (t[0] + t[1]), 0.5 * (t[1] + t[2]), 0.5 * (t[2] + t[0]), g,
          in(0), in(1), in(2)};
}

json ErrorStats::to_json() const {
  return {{"triangles_measured", triangles_measured},
          {"samples", samples},
          {"max_px", max_px},
          {"p99_px", p99_px},
          {"mean_px", mean_px},
          {"max_distance", max_distance}};
}

ErrorStats measure(const std::vector<Triangle3>& from, const SoupDistance& to,
                   const smr::Camera& cam) {
  ErrorStats s;
  const auto planes = cam.planes();
  const double focal = cam.focal_px();
  const Vec3 fwd = cam.forward();
  std::vector<double> px;
  double sum = 0.0;
  for (const Triangle3& t : from) {
    if (!visible_triangle(cam, planes, t)) continue;
    ++s.triangles_measured;
    for (const Vec3& p : samples(t)) {
      if (!inside_frustum(cam, planes, p)) continue;
      const double d = to.distance(p);
      const double e = d * focal / glm::dot(p - cam.eye, fwd);
      px.push_back(e);
      sum += e;
      s.max_distance = std::max(s.max_distance, d);
    }
  }
  s.samples = px.size();
  if (!px.empty()) {
    const std::size_t k = std::size_t(0.99 * double(px.size() - 1));
    std::nth_element(px.begin(), px.begin() + std::ptrdiff_t(k), px.end());
    s.p99_px = px[k];
    s.max_px = *std::max_element(px.begin(), px.end());
    s.mean_px = sum / double(px.size());
  }
  return s;
}

json TwoSided::to_json() const {
  return {{"max_px", max_px()},
          {"p99_px", p99_px()},
          {"output_to_source", to_source.to_json()},
          {"source_to_output", from_source.to_json()}};
}

TwoSided measure_both(const std::vector<Triangle3>& output, const std::vector<Triangle3>& source,
                      const SoupDistance& source_distance, const smr::Camera& cam) {
  TwoSided r;
  r.to_source = measure(output, source_distance, cam);
  const SoupDistance output_distance(output);
  r.from_source = measure(source, output_distance, cam);
  return r;
}

std::vector<Triangle3> triangles_of(const TriangleMesh& m) {
  std::vector<Triangle3> out;
  out.reserve(m.triangles.size());
  for (const auto& t : m.triangles)
    out.push_back({m.positions[t[0]], m.positions[t[1]], m.positions[t[2]]});
  return out;
}

double quantile(std::vector<double> v, double f) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::size_t(f * double(v.size() - 1))];
}

}  // namespace smr::bench::vdpm
