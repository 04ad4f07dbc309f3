// Elevation by descent through the DAG (elevation.h; Maheshwari et al. 4.1).
#include "smr/query/elevation.h"

#include <algorithm>

#include "base/error.h"
#include "index/hilbert.h"

namespace smr::query {

namespace {}  // namespace

double interpolate(const Triangle3& v, const Vec2& p) {
  const Vec2 a = xy(v[0]), b = xy(v[1]), c = xy(v[2]);
  const double area = orient2d(a, b, c);
  if (area == 0.0) return (v[0].z + v[1].z + v[2].z) / 3.0;
  const double wa = orient2d(p, b, c) / area;
  const double wb = orient2d(a, p, c) / area;
  const double wc = 1.0 - wa - wb;
  return wa * v[0].z + wb * v[1].z + wc * v[2].z;
}

int locate_in_fragment(const OpView& op, const Vec2& p) {
  int best = -1, nearest = -1;
  bool best_void = true;
  double best_score = -std::numeric_limits<double>::infinity(), nearest_score = best_score;
  for (std::size_t i = 0; i < op.fragment.size(); ++i) {
    const FragmentTriangle& t = op.fragment[i];
    const Vec2 a = xy(op.position(t, 0)), b = xy(op.position(t, 1)), c = xy(op.position(t, 2));
    const double area = orient2d(a, b, c);
    if (!(area > 0.0)) continue;
    // The smallest barycentric coordinate: >= 0 inside, slightly negative just outside. Most
    // triangles are far from p: the first coordinate well below 0 rules them out.
    const double wa = orient2d(p, b, c);
    if (wa < -1e-6 * area) continue;  // not even the nearest fallback (below) could use it
    const double score = std::min({wa, orient2d(a, p, c), orient2d(a, b, p)}) / area;
    if (score > nearest_score) {
      nearest = static_cast<int>(i);
      nearest_score = score;
    }
    if (score < -1e-9) continue;
    const bool is_void = t.is_void();
    // Strictly inside a triangle with data: no other triangle of the fragment contains p.
    if (score > 1e-9 && !is_void) return static_cast<int>(i);
    // Prefer data over void on a shared edge, then the most interior triangle.
    if (best < 0 || (best_void && !is_void) || (best_void == is_void && score > best_score)) {
      best = static_cast<int>(i);
      best_void = is_void;
      best_score = score;
    }
  }
  // A point a rounding error outside (on the domain's boundary, where the finer triangles are
  // smaller, the same distance is a larger share of them): the nearest triangle.
  if (best < 0 && nearest_score >= -1e-6) return nearest;
  return best;
}

ElevationQuery::ElevationQuery(const OpSource& source)
    : source_(source), domain_(terrain_domain(source.info())) {}

void ElevationQuery::check_inside(const Vec2& p) const {
  domain_.require(p, "point");
}

OpRef ElevationQuery::fetch(std::size_t level, OpId id) const {
  if (level < path_.size() && path_[level]->id == id) return path_[level];
  path_.resize(level);
  path_.push_back(source_.op(id));
  return path_.back();
}

ElevationAnswer ElevationQuery::at(const Vec2& p, const Accuracy& accuracy) const {
  check_inside(p);
  return descend(p, accuracy);
}

ElevationAnswer ElevationQuery::descend(const Vec2& p, const Accuracy& accuracy) const {
  ElevationAnswer ans;
  ans.p = p;
  OpRef op = fetch(0, kBaseOp);
  for (;;) {
    ++ans.ops_read;
    const int i = locate_in_fragment(*op, p);
    if (i < 0)
      throw Error(ErrorKind::kCorrupt, "op " + std::to_string(op->id.value) +
                                           ": no triangle of its fragment contains " +
                                           point_text(p) + ", though its predecessor's did");
    const FragmentTriangle& t = op->fragment[static_cast<std::size_t>(i)];
    const double err = triangle_error(source_, t);
    // A void triangle stands for no data only where it is final: a coarse one may still be
    // replaced by triangles with data (greedy_tin.cpp: a hole's boundary samples become vertices).
    const bool fine = !t.killer.valid() || (!t.is_void() && accuracy.allows(err));
    if (fine) {
      ans.triangle = TriRef{op->id, static_cast<std::uint32_t>(i)};
      ans.final = !t.killer.valid();
      ans.has_data = !t.is_void();
      ans.error_bound = err;
      if (ans.has_data) ans.z = interpolate(corners(*op, t), p);
      return ans;
    }
    op = fetch(ans.ops_read, t.killer);
  }
}

void ElevationQuery::at_many(
    std::span<const Vec2> points, const Accuracy& accuracy,
    const std::function<void(std::size_t, const ElevationAnswer&)>& take) const {
  for (const Vec2& p : points) check_inside(p);
  // Hilbert order on a 2^16 x 2^16 lattice over the domain.
  constexpr double kCells = 65535.0;
  const Vec2 size = glm::max(domain_.hi - domain_.lo, Vec2{1e-300});
  std::vector<std::pair<std::uint64_t, std::uint32_t>> order(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Vec2 c = (points[i] - domain_.lo) / size * kCells;
    order[i] = {index::hilbert_index(
                    {static_cast<std::uint32_t>(c.x), static_cast<std::uint32_t>(c.y), 0u}, 2),
                static_cast<std::uint32_t>(i)};
  }
  std::sort(order.begin(), order.end());
  for (const auto& [key, i] : order) take(i, descend(points[i], accuracy));
}

std::vector<ElevationAnswer> ElevationQuery::at_many(std::span<const Vec2> points,
                                                     const Accuracy& accuracy) const {
  std::vector<ElevationAnswer> out(points.size());
  at_many(points, accuracy, [&](std::size_t i, const ElevationAnswer& a) { out[i] = a; });
  return out;
}

}  // namespace smr::query
