// Line of sight and profiles (sight.h; Maheshwari et al. 4.3).
#include "smr/query/sight.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <unordered_map>

#include "base/error.h"
#include "index/visitors.h"
#include "smr/core/clock.h"
#include "smr/query/elevation.h"

namespace smr::query {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Relative slack of the footprint clip (the separating-axis slack of region.cpp) and of heights.
constexpr double kClipSlack = 1e-12;
constexpr double kHeightSlack = 1e-9;

// A stretch of the segment a + t (b - a), t in [t0, t1], over one result triangle.
struct Piece {
  double t0 = 0.0, t1 = 0.0;
  Triangle3 v{};
  double error = 0.0;
  bool is_void = false;
};

struct Span {
  double t0, t1;
};

double magnitude(const Triangle3& v, const Vec2& a, const Vec2& b) {
  double m = std::max({1.0, std::abs(a.x), std::abs(a.y), std::abs(b.x), std::abs(b.y)});
  for (const Vec3& c : v) m = std::max({m, std::abs(c.x), std::abs(c.y)});
  return m;
}

// The parameters of a + t (b - a), t in [0, 1], over the closed x-y footprint of v, each edge's
// half-plane grown by a relative slack (conservative). Nothing for a degenerate footprint.
std::optional<Span> clip_to_footprint(const Vec2& a, const Vec2& b, const Triangle3& v) {
  const double area = orient2d(xy(v[0]), xy(v[1]), xy(v[2]));
  if (area == 0.0) return std::nullopt;
  const double sign = area > 0.0 ? 1.0 : -1.0;
  const double mag = magnitude(v, a, b);
  Span s{0.0, 1.0};
  for (int k = 0; k < 3; ++k) {
    const Vec2 e0 = xy(v[k]), e1 = xy(v[(k + 1) % 3]);
    const double fa = sign * orient2d(e0, e1, a), fb = sign * orient2d(e0, e1, b);
    const double tol = kClipSlack * mag * glm::length(e1 - e0);
    if (fa < -tol && fb < -tol) return std::nullopt;
    if (fa < -tol) s.t0 = std::max(s.t0, (-tol - fa) / (fb - fa));
    if (fb < -tol) s.t1 = std::min(s.t1, (-tol - fa) / (fb - fa));
  }
  if (s.t0 > s.t1) return std::nullopt;
  return s;
}

Vec3 along(const Vec3& p, const Vec3& q, double t) {
  return p + t * (q - p);
}

// The segment's height above the plane of v at parameter t (linear in t).
double gap_at(const Triangle3& v, const Vec3& p, const Vec3& q, double t) {
  const Vec3 s = along(p, q, t);
  return s.z - interpolate(v, xy(s));
}

// The first t in [t0, t1] where d, linear from d0 to d1, is below `level`; infinity if none.
double first_below(double t0, double t1, double d0, double d1, double level) {
  if (d0 < level) return t0;
  if (!(d1 < level)) return kInf;
  return t0 + (t1 - t0) * (d0 - level) / (d0 - d1);
}

// The first t in [t0, t1] where |d| <= e (d linear from d0 to d1); infinity if none.
double first_within(double t0, double t1, double d0, double d1, double e) {
  if (std::abs(d0) <= e) return t0;
  if (d0 > e) return d1 <= e ? t0 + (t1 - t0) * (d0 - e) / (d0 - d1) : kInf;
  return d1 >= -e ? t0 + (t1 - t0) * (d0 + e) / (d0 - d1) : kInf;  // d0 < -e: rising into it
}

// The triangles of `result` whose footprints meet the 2-D segment ab, as pieces of it ordered by
// where they begin.
std::vector<Piece> pieces_along(const OpSource& source, const Extraction& result, const Vec2& a,
                                const Vec2& b) {
  std::vector<Piece> pieces;
  OpRef op;
  for (const TriRef& r : result.triangles) {
    if (!op || op->id != r.op) op = source.op(r.op);
    const FragmentTriangle& t = op->fragment[r.index];
    const Triangle3 v = corners(*op, t);
    const std::optional<Span> s = clip_to_footprint(a, b, v);
    if (!s) continue;
    pieces.push_back({s->t0, s->t1, v, triangle_error(source, t), t.is_void()});
  }
  std::sort(pieces.begin(), pieces.end(),
            [](const Piece& x, const Piece& y) { return x.t0 < y.t0; });
  return pieces;
}

// Line of sight by descent through the DAG along pq. The segment's x-y path is cut into spans,
// one per triangle, taken in order from p: a final triangle decides its span exactly (within
// err_final); a coarse one whose band the segment enters, when its error is within the accuracy,
// leaves its span undecided; any other coarse triangle is settled by its killer K, whose ROI holds
// every triangle that refines it: a span above the ROI is clear, else F(K)'s triangles over the
// span replace it. A coarse triangle's own band bounds the grid samples under it, not the finest
// mesh between them (a finer triangulation may cross its edges), so only the ROI and final
// triangles decide. Spans beyond the first certain block are never refined.
class SightDescent {
 public:
  SightDescent(const OpSource& source, const Vec3& p, const Vec3& q, const Accuracy& accuracy)
      : source_(source), p_(p), q_(q), accuracy_(accuracy) {}
  SightAnswer run();

 private:
  struct Item {
    double t0, t1;
    OpRef op;
    std::uint32_t tri;
  };
  struct Band {
    double t, error;  // where the segment enters a triangle's band, and its error
  };
  OpRef fetch(OpId id);
  void push_fragment(const OpRef& op, double t0, double t1);
  void settle(const Item& it);
  // Where along the span the segment enters the band of error e, and where it goes under it.
  struct Verdict {
    double enter, below;  // infinity: never
  };
  Verdict judge(const Item& it, const Triangle3& v, double e) const;
  SightAnswer answer() const;

  const OpSource& source_;
  Vec3 p_, q_;
  Accuracy accuracy_;
  std::vector<Item> stack_;  // spans still to settle, the nearest to p on top
  std::unordered_map<OpId, OpRef> ops_;
  std::vector<Band> bands_;
  double blocked_ = kInf, no_data_ = kInf;
  std::uint64_t tested_ = 0;
};

OpRef SightDescent::fetch(OpId id) {
  auto [it, added] = ops_.try_emplace(id);
  if (added) it->second = source_.op(id);
  return it->second;
}

void SightDescent::push_fragment(const OpRef& op, double t0, double t1) {
  const std::size_t first = stack_.size();
  for (std::uint32_t i = 0; i < op->fragment.size(); ++i) {
    const FragmentTriangle& t = op->fragment[i];
    const Triangle3 v = corners(*op, t);
    const std::optional<Span> s = clip_to_footprint(xy(p_), xy(q_), v);
    if (!s || s->t1 < t0 || s->t0 > t1) continue;
    stack_.push_back({std::max(s->t0, t0), std::min(s->t1, t1), op, i});
  }
  std::sort(stack_.begin() + static_cast<std::ptrdiff_t>(first), stack_.end(),
            [](const Item& a, const Item& b) { return a.t0 > b.t0; });
}

SightDescent::Verdict SightDescent::judge(const Item& it, const Triangle3& v, double e) const {
  const double d0 = gap_at(v, p_, q_, it.t0), d1 = gap_at(v, p_, q_, it.t1);
  return {first_within(it.t0, it.t1, d0, d1, e), first_below(it.t0, it.t1, d0, d1, -e)};
}

void SightDescent::settle(const Item& it) {
  ++tested_;
  const FragmentTriangle& t = it.op->fragment[it.tri];
  const Triangle3 v = corners(*it.op, t);
  const double e = triangle_error(source_, t);
  if (!t.killer.valid()) {
    if (t.is_void()) {
      no_data_ = std::min(no_data_, it.t0);
      return;
    }
    const Verdict j = judge(it, v, e);
    blocked_ = std::min(blocked_, j.below);
    if (j.enter < kInf) bands_.push_back({j.enter, e});
    return;
  }
  // When the accuracy allows this error and the segment enters the band without going under it,
  // the rest of the span is undecided; the stretch before the band is still to be proven clear.
  double t1 = it.t1;
  if (!t.is_void() && accuracy_.allows(e)) {
    const Verdict j = judge(it, v, e);
    if (j.enter < kInf && j.below == kInf) {
      bands_.push_back({j.enter, e});
      t1 = j.enter;
    }
  }
  // A span clear of the killer's ROI, grown by the finest mesh's own error, is clear of the band
  // of every triangle refining it. (No data is looked for below void triangles only: they refine
  // into no data and slivers of data between samples.)
  const OpRef killer = fetch(t.killer);
  const Vec3 a = along(p_, q_, it.t0), b = along(p_, q_, t1);
  const double ef = source_.info().err_final;
  const bool clear = !SightRegion(a, b).box_meets(killer->roi, ef) && a.z > killer->roi.hi.z + ef;
  if (!clear || t.is_void()) push_fragment(killer, it.t0, t1);
}

SightAnswer SightDescent::run() {
  push_fragment(fetch(kBaseOp), 0.0, 1.0);
  while (!stack_.empty()) {
    const Item it = stack_.back();
    stack_.pop_back();
    if (it.t0 <= blocked_) settle(it);
  }
  return answer();
}

SightAnswer SightDescent::answer() const {
  SightAnswer a;
  a.p = p_;
  a.q = q_;
  double undecided = kInf;
  for (const Band& b : bands_) {
    if (b.t > blocked_) continue;
    a.error_bound = std::max(a.error_bound, b.error);
    if (b.error > 0.0) undecided = std::min(undecided, b.t);
  }
  if (blocked_ < kInf) {
    a.sight = Sight::kBlocked;
    a.blocked_at = along(p_, q_, blocked_);
  } else {
    a.sight = undecided < kInf ? Sight::kUndecided : Sight::kVisible;
  }
  if (undecided < kInf) a.undecided_at = along(p_, q_, undecided);
  if (no_data_ <= blocked_ && no_data_ < kInf) a.no_data_at = along(p_, q_, no_data_);
  a.ops = ops_.size();
  a.triangles_tested = tested_;
  return a;
}

// Along a leg, pieces may overlap: a triangle the leg only touches, or two sharing the edge the leg
// runs along (data on one side, no data on the other, triangulated differently). So the leg is cut
// at every piece's start and end, and each stretch between cuts (cuts closer than kSameT merged)
// takes a piece covering it, one with data when any does.
constexpr double kSameT = 1e-9;

std::vector<double> cuts_of(const std::vector<Piece>& pieces) {
  std::vector<double> all{0.0, 1.0};
  for (const Piece& c : pieces) {
    all.push_back(std::clamp(c.t0, 0.0, 1.0));
    all.push_back(std::clamp(c.t1, 0.0, 1.0));
  }
  std::sort(all.begin(), all.end());
  std::vector<double> cuts;
  for (double t : all)
    if (cuts.empty() || t > cuts.back() + kSameT) cuts.push_back(t);
  cuts.back() = 1.0;
  return cuts;
}

struct Leg {
  Vec2 a, b;
  std::uint32_t index = 0;
  double distance = 0.0;  // of a along the polyline
};

// Appends the breakpoints of one leg: the start of every stretch whose piece differs from the one
// before (a leg's end is the next leg's start, or the profile's last point). `pieces` are sorted
// by t0; `last` is the piece before the leg (or null).
const Piece* append_leg(const Leg& leg, const std::vector<Piece>& pieces, const Piece* last,
                        std::vector<ProfilePoint>& out) {
  const double length = glm::length(leg.b - leg.a);
  const std::vector<double> cuts = cuts_of(pieces);
  std::vector<const Piece*> active;  // pieces begun before the stretch's middle
  std::size_t next = 0;
  const Piece* current = nullptr;
  for (std::size_t i = 0; i + 1 < cuts.size(); ++i) {
    const double mid = 0.5 * (cuts[i] + cuts[i + 1]);
    for (; next < pieces.size() && pieces[next].t0 <= mid; ++next) active.push_back(&pieces[next]);
    std::erase_if(active, [&](const Piece* c) { return c->t1 < mid; });
    const Piece* best = nullptr;
    for (const Piece* c : active)
      if (best == nullptr || (best->is_void && !c->is_void)) best = c;
    if (best == nullptr || best == current) continue;
    const Vec2 at = leg.a + cuts[i] * (leg.b - leg.a);
    const Piece* surface =
        !best->is_void ? best : (last != nullptr && !last->is_void ? last : nullptr);
    const double z =
        surface != nullptr ? interpolate(surface->v, at) : std::numeric_limits<double>::quiet_NaN();
    out.push_back(
        {leg.distance + cuts[i] * length, Vec3{at, z}, leg.index, best->error, !best->is_void});
    current = last = best;
  }
  return last;
}

// The profile's last point: the polyline's end, on the last piece.
void append_end(const Leg& leg, const Piece& last, std::vector<ProfilePoint>& out) {
  const double z =
      last.is_void ? std::numeric_limits<double>::quiet_NaN() : interpolate(last.v, leg.b);
  out.push_back({leg.distance + glm::length(leg.b - leg.a), Vec3{leg.b, z}, leg.index, last.error,
                 !last.is_void});
}

}  // namespace

std::string SightRegion::describe() const {
  std::ostringstream os;
  os.precision(15);
  os << "segment (" << p_.x << ", " << p_.y << ", " << p_.z << ") -> (" << q_.x << ", " << q_.y
     << ", " << q_.z << ")";
  return os.str();
}

bool SightRegion::triangle_meets(const Triangle3& v, double error) const {
  const std::optional<Span> s = clip_to_footprint(xy(p_), xy(q_), v);
  if (!s) return false;
  const double d0 = gap_at(v, p_, q_, s->t0), d1 = gap_at(v, p_, q_, s->t1);
  double zmag = std::max({1.0, std::abs(p_.z), std::abs(q_.z)});
  for (const Vec3& c : v) zmag = std::max(zmag, std::abs(c.z));
  const double band = error + kHeightSlack * zmag;
  return !(std::min(d0, d1) > band) && !(std::max(d0, d1) < -band);
}

bool SightRegion::box_meets(const Box3& box, double error) const {
  if (box.empty()) return false;
  // Ten times the triangle test's height slack, and more than its clip's in x-y: a box never
  // misses what a triangle inside it meets.
  const double mag =
      std::max({1.0, std::abs(box.lo.x), std::abs(box.hi.x), std::abs(box.lo.y), std::abs(box.hi.y),
                std::abs(box.lo.z), std::abs(box.hi.z), std::abs(p_.z), std::abs(q_.z)});
  const double grow_xy = 10 * kHeightSlack * mag, grow_z = error + 10 * kHeightSlack * mag;
  index::Box b;
  b.lo = {box.lo.x - grow_xy, box.lo.y - grow_xy, box.lo.z - grow_z};
  b.hi = {box.hi.x + grow_xy, box.hi.y + grow_xy, box.hi.z + grow_z};
  return index::segment_meets({p_.x, p_.y, p_.z}, {q_.x, q_.y, q_.z}, b);
}

const char* to_string(Sight s) {
  switch (s) {
    case Sight::kVisible:
      return "visible";
    case Sight::kBlocked:
      return "blocked";
    case Sight::kUndecided:
      return "undecided";
  }
  return "?";
}

SightAnswer line_of_sight(const OpSource& source, const Vec3& p, const Vec3& q,
                          const Accuracy& accuracy) {
  const auto t0 = Clock::now();
  const Domain domain = terrain_domain(source.info());
  domain.require(xy(p), "point");
  domain.require(xy(q), "point");
  if (!std::isfinite(p.z) || !std::isfinite(q.z))
    throw Error(ErrorKind::kInvalidInput, "line of sight: heights must be finite numbers");
  SightAnswer a = SightDescent(source, p, q, accuracy).run();
  a.seconds = seconds_since(t0);
  return a;
}

ProfileResult profile(const OpSource& source, std::span<const Vec2> polyline,
                      const Accuracy& accuracy) {
  const auto t0 = Clock::now();
  const Domain domain = terrain_domain(source.info());
  if (polyline.size() < 2)
    throw Error(ErrorKind::kInvalidInput, "profile: a polyline needs at least two points");
  std::vector<std::shared_ptr<const Region>> walls;
  for (std::size_t i = 0; i < polyline.size(); ++i) {
    domain.require(polyline[i], "polyline point");
    if (i > 0) walls.push_back(std::make_shared<PathRegion>(polyline[i - 1], polyline[i]));
  }
  const Extraction result = refine(source, std::make_shared<UnionRegion>(walls), accuracy);
  ProfileResult out;
  // Every leg's pieces stay alive: a leg's first point may take its height from the last piece of
  // the leg before.
  std::vector<std::vector<Piece>> legs(polyline.size() - 1);
  const Piece* last = nullptr;
  Leg leg;
  double distance = 0.0;
  for (std::size_t i = 0; i < legs.size(); ++i) {
    leg = {polyline[i], polyline[i + 1], static_cast<std::uint32_t>(i), distance};
    distance += glm::length(leg.b - leg.a);
    legs[i] = pieces_along(source, result, leg.a, leg.b);
    out.triangles += legs[i].size();
    last = append_leg(leg, legs[i], last, out.points);
  }
  if (last == nullptr) throw_internal("profile: the refined mesh does not cover the polyline");
  append_end(leg, *last, out.points);
  for (const ProfilePoint& pt : out.points)
    if (pt.has_data) out.error_bound = std::max(out.error_bound, pt.error_bound);
  out.ops = result.x.size();
  out.seconds = seconds_since(t0);
  return out;
}

}  // namespace smr::query
