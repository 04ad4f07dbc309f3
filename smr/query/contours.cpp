// Contour lines by selective refinement for the planes z = h (contours.h; Maheshwari et al. 4.2).
#include "smr/query/contours.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>

#include "base/error.h"
#include "smr/core/id_map.h"
#include "smr/query/geojson.h"

namespace smr::query {

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void require(bool ok, const std::string& what) {
  if (!ok) throw Error(ErrorKind::kInvalidInput, "contours: " + what);
}

std::string number_text(double v) {
  std::ostringstream os;
  os.precision(17);
  os << v;
  return os.str();
}

// Where a level crosses a mesh edge: the level's number and the edge's corners below and above
// it. Both triangles of the edge name it the same way, one as a segment's start, one as an end.
struct Crossing {
  std::int64_t level = std::numeric_limits<std::int64_t>::min();
  std::uint64_t below = ~std::uint64_t{0}, above = ~std::uint64_t{0};
  friend bool operator==(const Crossing&, const Crossing&) = default;
};

struct CrossingKeys {
  static constexpr Crossing empty() { return {}; }
  static std::size_t hash(const Crossing& c) {
    return std::size_t(mix64(c.below ^ mix64(c.above ^ mix64(std::uint64_t(c.level)))));
  }
};

// A triangle's piece of a contour, higher ground on its left: from `a` (on the edge the
// counter-clockwise boundary crosses going down) to `b` (going up).
struct Segment {
  Crossing from, to;
  Vec2 a{0.0}, b{0.0};
  double error = 0.0;
};

struct Corner {
  std::uint64_t id = 0;
  Vec3 p{0.0};
};

// The point where h crosses the edge from corner u (below h) to corner w (above), interpolated
// from u so that both triangles of the edge compute it bit for bit alike.
Vec2 crossing_point(const Corner& u, const Corner& w, double h) {
  const double t = (h - u.p.z) / (w.p.z - u.p.z);
  return xy(u.p) + t * (xy(w.p) - xy(u.p));
}

// The segment of level k (height h) in the counter-clockwise triangle c, which straddles h.
Segment segment_of(const std::array<Corner, 3>& c, std::int64_t k, double h, double error) {
  Segment s;
  s.error = error;
  for (int i = 0; i < 3; ++i) {
    const Corner& p = c[std::size_t(i)];
    const Corner& q = c[std::size_t((i + 1) % 3)];
    const bool p_above = p.p.z >= h, q_above = q.p.z >= h;
    if (p_above && !q_above) {
      s.from = {k, q.id, p.id};
      s.a = crossing_point(q, p, h);
    } else if (!p_above && q_above) {
      s.to = {k, p.id, q.id};
      s.b = crossing_point(p, q, h);
    }
  }
  return s;
}

// Every segment of every level in the triangles with data, in the triangles' order.
std::vector<Segment> march(const OpSource& src, std::span<const TriRef> triangles,
                           const LevelsRegion& levels, ContourStats& stats) {
  std::vector<Segment> out;
  OpRef op;
  for (const TriRef& r : triangles) {
    if (op == nullptr || op->id != r.op) op = src.op(r.op);
    const FragmentTriangle& t = op->triangle(r.index);
    if (t.is_void()) continue;
    ++stats.triangles_marched;
    std::array<Corner, 3> c;
    for (int k = 0; k < 3; ++k) c[std::size_t(k)] = {op->vertex_id(t, k).value, op->position(t, k)};
    const auto [lo, hi] = std::minmax({c[0].p.z, c[1].p.z, c[2].p.z});
    // Levels in (lo, hi]: a corner below each (z < h) and one above (z >= h).
    const std::int64_t first = levels.first_above(lo), end = levels.first_above(hi);
    if (first >= end) continue;
    const double error = triangle_error(src, t);
    for (std::int64_t k = first; k < end; ++k)
      out.push_back(segment_of(c, k, levels.level(k), error));
  }
  return out;
}

Error not_a_surface(const Crossing& c, const char* what) {
  return Error(ErrorKind::kInternal, "contours: level " + std::to_string(c.level) +
                                         " crosses the edge (vertex " + std::to_string(c.below) +
                                         ", vertex " + std::to_string(c.above) + ") " + what +
                                         ": the refined mesh is not a surface");
}

constexpr std::uint32_t kNone = ~std::uint32_t{0};

// next[i]: the segment starting where segment i ends (kNone at a line's open end).
std::vector<std::uint32_t> successors(std::span<const Segment> segs) {
  if (segs.size() >= kNone)
    throw Error(ErrorKind::kInvalidInput,
                "contours: more than 2^32 - 1 segments; ask for fewer levels");
  FlatMap<Crossing, std::uint32_t, CrossingKeys> starts(75);  // start crossing -> 1 + segment
  starts.reserve(segs.size());
  for (std::uint32_t i = 0; i < segs.size(); ++i) {
    std::uint32_t& slot = starts[segs[i].from];
    if (slot != 0) throw not_a_surface(segs[i].from, "twice downwards");
    slot = i + 1;
  }
  std::vector<std::uint32_t> next(segs.size(), kNone);
  std::vector<bool> has_pred(segs.size(), false);
  for (std::uint32_t i = 0; i < segs.size(); ++i) {
    const std::uint32_t* j = starts.find(segs[i].to);
    if (j == nullptr) continue;
    if (has_pred[*j - 1]) throw not_a_surface(segs[i].to, "twice upwards");
    has_pred[*j - 1] = true;
    next[i] = *j - 1;
  }
  return next;
}

// The line through segment `first`, following `next` until an open end or back to `first`. A
// point repeating the one before (a level through a vertex) is written once, except in a line
// that is a single point, written twice.
ContourLine walk(std::span<const Segment> segs, std::span<const std::uint32_t> next,
                 std::vector<bool>& used, std::uint32_t first, const LevelsRegion& levels) {
  ContourLine line;
  line.level = levels.level(segs[first].from.level);
  const auto add = [&line](const Vec2& p) {
    if (line.points.empty() || line.points.back() != p) line.points.push_back(p);
  };
  std::uint32_t i = first, last = first;
  do {
    used[i] = true;
    add(segs[i].a);
    line.error = std::max(line.error, segs[i].error);
    last = i;
    i = next[i];
  } while (i != kNone && i != first);
  line.points.push_back(segs[last].b);  // bit for bit segs[first].a on a ring
  if (line.points.size() > 2 && line.points.end()[-2] == line.points.back()) line.points.pop_back();
  line.closed = i == first;
  return line;
}

// Open lines first (from segments nothing precedes), then the rings left over.
std::vector<ContourLine> join(std::span<const Segment> segs, const LevelsRegion& levels) {
  const std::vector<std::uint32_t> next = successors(segs);
  std::vector<bool> starts_line(segs.size(), true), used(segs.size(), false);
  for (const std::uint32_t j : next)
    if (j != kNone) starts_line[j] = false;
  std::vector<ContourLine> lines;
  for (std::uint32_t i = 0; i < segs.size(); ++i)
    if (starts_line[i]) lines.push_back(walk(segs, next, used, i, levels));
  for (std::uint32_t i = 0; i < segs.size(); ++i)
    if (!used[i]) lines.push_back(walk(segs, next, used, i, levels));
  std::stable_sort(lines.begin(), lines.end(),
                   [](const ContourLine& x, const ContourLine& y) { return x.level < y.level; });
  return lines;
}

}  // namespace

LevelsRegion LevelsRegion::at(std::vector<double> levels) {
  require(!levels.empty(), "no levels given; expected at least one level or an interval");
  for (const double h : levels)
    require(std::isfinite(h), "level " + number_text(h) + " is not a finite number");
  std::sort(levels.begin(), levels.end());
  levels.erase(std::unique(levels.begin(), levels.end()), levels.end());
  LevelsRegion r;
  r.levels_ = std::move(levels);
  return r;
}

LevelsRegion LevelsRegion::every(double interval, double base) {
  require(std::isfinite(interval) && interval > 0.0,
          "interval " + number_text(interval) + ": expected a number > 0");
  require(std::isfinite(base), "base " + number_text(base) + ": expected a finite number");
  LevelsRegion r;
  r.interval_ = interval;
  r.base_ = base;
  return r;
}

std::string LevelsRegion::describe() const {
  if (levels_.empty())
    return "levels every " + number_text(interval_) + " from " + number_text(base_);
  std::string s = "levels";
  for (std::size_t i = 0; i < std::min<std::size_t>(levels_.size(), 5); ++i)
    s += (i == 0 ? " " : ", ") + number_text(levels_[i]);
  if (levels_.size() > 5) s += ", ... (" + std::to_string(levels_.size()) + ")";
  return s;
}

bool LevelsRegion::triangle_meets(const Triangle3& v, double error) const {
  const auto [lo, hi] = std::minmax({v[0].z, v[1].z, v[2].z});
  return meets(lo - error, hi + error);
}

bool LevelsRegion::box_meets(const Box3& box, double error) const {
  return !box.empty() && meets(box.lo.z - error, box.hi.z + error);
}

double LevelsRegion::level(std::int64_t k) const {
  if (levels_.empty()) return base_ + double(k) * interval_;
  return levels_.at(std::size_t(k));
}

std::int64_t LevelsRegion::first_at_or_above(double z) const {
  if (!levels_.empty())
    return std::lower_bound(levels_.begin(), levels_.end(), z) - levels_.begin();
  return first_where(z, false);
}

std::int64_t LevelsRegion::first_above(double z) const {
  if (!levels_.empty())
    return std::upper_bound(levels_.begin(), levels_.end(), z) - levels_.begin();
  return first_where(z, true);
}

std::int64_t LevelsRegion::first_where(double z, bool strictly_above) const {
  const auto past = [&](std::int64_t k) { return strictly_above ? level(k) > z : level(k) >= z; };
  // Near the answer by arithmetic, then exact by the very expression level() rounds with. Level
  // numbers stay within +-2^52, where consecutive levels differ.
  constexpr double kLimit = 4503599627370496.0;  // 2^52
  double q = std::floor((z - base_) / interval_);
  q = std::isnan(q) ? 0.0 : std::clamp(q, -kLimit, kLimit);
  auto k = static_cast<std::int64_t>(q);
  for (int i = 0; i < 4 && past(k); ++i) --k;
  for (int i = 0; i < 4 && !past(k); ++i) ++k;
  return k;
}

std::uint64_t LevelsRegion::count_in(double lo, double hi) const {
  const std::int64_t n = first_above(hi) - first_at_or_above(lo);
  return n > 0 ? std::uint64_t(n) : 0;
}

namespace {

// Every level is a pass over the marched triangles: refuse what would not end (or not fit).
void check_level_count(const ContourOptions& o, const Box3& bounds) {
  constexpr double kMaxLevels = 100000.0;
  constexpr double kLimit = 4503599627370496.0;  // 2^52: level numbers stay exact
  require(double(o.levels.size()) <= kMaxLevels, "at most 100000 levels");
  if (!o.interval || !(*o.interval > 0.0)) return;  // levels_region names a bad interval
  const double lo = bounds.lo.z, hi = bounds.hi.z, d = *o.interval;
  require(std::max(std::abs(lo - o.base), std::abs(hi - o.base)) / d < kLimit,
          "the interval is too small for the base and the data's heights (more than 2^52 steps)");
  const double n = (hi - lo) / d;
  if (n > kMaxLevels) {
    std::ostringstream os;
    os << "interval " << d << " gives about " << std::llround(n)
       << " levels over the data's heights " << lo << " .. " << hi << "; at most 100000";
    require(false, os.str());
  }
}

}  // namespace

LevelsRegion levels_region(const ContourOptions& o) {
  require(!o.interval || o.levels.empty(), "give levels or an interval, not both");
  return o.interval ? LevelsRegion::every(*o.interval, o.base) : LevelsRegion::at(o.levels);
}

ContourResult contours(const OpSource& src, const ContourOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  const CrmrInfo& info = src.info();
  terrain_domain(info);  // kInvalidInput for a 3-D mesh
  check_level_count(o, info.bounds);
  const auto levels = std::make_shared<const LevelsRegion>(levels_region(o));
  ContourResult r;
  ContourStats& st = r.stats;
  st.levels = levels->count_in(info.bounds.lo.z, info.bounds.hi.z);
  const Extraction e = refine(src, levels, o.accuracy);
  st.ops = e.x.size();
  st.triangles = e.triangles.size();
  st.refine_seconds = seconds_since(t0);
  const auto t1 = std::chrono::steady_clock::now();
  const std::vector<Segment> segs = march(src, e.triangles, *levels, st);
  st.segments = segs.size();
  st.march_seconds = seconds_since(t1);
  const auto t2 = std::chrono::steady_clock::now();
  r.lines = join(segs, *levels);
  st.join_seconds = seconds_since(t2);
  st.polylines = r.lines.size();
  for (const ContourLine& l : r.lines) {
    st.rings += l.closed ? 1 : 0;
    st.points += l.points.size();
  }
  st.seconds = seconds_since(t0);
  return r;
}

void write_geojson(std::ostream& out, const ContourResult& r, const Georef& georef) {
  GeoJsonWriter w(out, georef, "contours");
  for (const ContourLine& l : r.lines) {
    const std::array<Property, 2> properties{{{"elev", l.level}, {"error", l.error}}};
    w.line_string(l.points, properties);
  }
  w.finish();
}

}  // namespace smr::query
