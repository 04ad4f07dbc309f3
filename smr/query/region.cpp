// Region queries as an RCF (region.h; Maheshwari et al. 3.2, 4).
#include "smr/query/region.h"

#include <array>
#include <span>
#include <sstream>

#include "base/error.h"

namespace smr::query {

namespace {

// Separating-axis test for two convex point sets in the plane (a triangle against a rectangle, a
// segment or a point): they meet unless some edge normal of either separates their projections.
// Touching counts as meeting, and a gap must exceed a relative slack of 1e-12 of the coordinates
// to separate, so rounding never loses a region that touches a triangle (conservative).
bool separated_on(const Vec2& axis, std::span<const Vec2> a, std::span<const Vec2> b,
                  double slack) {
  double amin = std::numeric_limits<double>::infinity(), amax = -amin;
  double bmin = amin, bmax = -amin;
  for (const Vec2& p : a) {
    const double d = glm::dot(axis, p);
    amin = std::min(amin, d);
    amax = std::max(amax, d);
  }
  for (const Vec2& p : b) {
    const double d = glm::dot(axis, p);
    bmin = std::min(bmin, d);
    bmax = std::max(bmax, d);
  }
  const double tol = slack * glm::length(axis);
  return amax < bmin - tol || bmax < amin - tol;
}

bool separated_by_edges_of(std::span<const Vec2> poly, std::span<const Vec2> a,
                           std::span<const Vec2> b, double slack) {
  const std::size_t n = poly.size();
  if (n < 2) return false;
  const std::size_t edges = n == 2 ? 1 : n;
  for (std::size_t i = 0; i < edges; ++i) {
    const Vec2 e = poly[(i + 1) % n] - poly[i];
    if (e.x == 0.0 && e.y == 0.0) continue;
    if (separated_on(Vec2{-e.y, e.x}, a, b, slack)) return true;
  }
  return false;
}

double magnitude(std::span<const Vec2> pts) {
  double m = 0.0;
  for (const Vec2& p : pts) m = std::max({m, std::abs(p.x), std::abs(p.y)});
  return m;
}

bool convex_meet(std::span<const Vec2> a, std::span<const Vec2> b) {
  const double slack = 1e-12 * std::max({1.0, magnitude(a), magnitude(b)});
  if (separated_on(Vec2{1.0, 0.0}, a, b, slack) || separated_on(Vec2{0.0, 1.0}, a, b, slack))
    return false;
  return !separated_by_edges_of(a, a, b, slack) && !separated_by_edges_of(b, a, b, slack);
}

std::array<Vec2, 3> footprint(const Triangle3& v) {
  return {xy(v[0]), xy(v[1]), xy(v[2])};
}

std::array<Vec2, 4> rectangle(const Vec2& lo, const Vec2& hi) {
  return {lo, Vec2{hi.x, lo.y}, hi, Vec2{lo.x, hi.y}};
}

void check_accuracy(const Accuracy& accuracy) {
  if (accuracy.max_error && !(*accuracy.max_error >= 0.0))
    throw Error(ErrorKind::kInvalidInput, "max error: expected a number >= 0");
}

}  // namespace

std::string Accuracy::describe() const {
  if (!max_error) return "finest mesh";
  std::ostringstream os;
  os << "error <= " << *max_error;
  return os.str();
}

std::string WindowRegion::describe() const {
  return "window " + point_text(lo_) + " .. " + point_text(hi_);
}

bool WindowRegion::triangle_meets(const Triangle3& v, double) const {
  const auto t = footprint(v);
  const auto r = rectangle(lo_, hi_);
  return convex_meet(t, r);
}

bool WindowRegion::box_meets(const Box3& box, double) const {
  return !box.empty() && box.lo.x <= hi_.x && box.hi.x >= lo_.x && box.lo.y <= hi_.y &&
         box.hi.y >= lo_.y;
}

std::string PathRegion::describe() const {
  return "path " + point_text(a_) + " -> " + point_text(b_);
}

bool PathRegion::triangle_meets(const Triangle3& v, double) const {
  const auto t = footprint(v);
  const std::array<Vec2, 2> s{a_, b_};
  return convex_meet(t, s);
}

bool PathRegion::box_meets(const Box3& box, double) const {
  if (box.empty()) return false;
  const auto r = rectangle(xy(box.lo), xy(box.hi));
  const std::array<Vec2, 2> s{a_, b_};
  return convex_meet(r, s);
}

std::string UnionRegion::describe() const {
  std::string s;
  for (const auto& p : parts_) s += (s.empty() ? "" : " + ") + p->describe();
  return s.empty() ? "nothing" : s;
}

bool UnionRegion::triangle_meets(const Triangle3& v, double error) const {
  for (const auto& p : parts_)
    if (p->triangle_meets(v, error)) return true;
  return false;
}

bool UnionRegion::box_meets(const Box3& box, double error) const {
  for (const auto& p : parts_)
    if (p->box_meets(box, error)) return true;
  return false;
}

bool UnionRegion::depends_on_height() const {
  for (const auto& p : parts_)
    if (p->depends_on_height()) return true;
  return false;
}

std::string RegionCriterion::describe() const {
  return region_->describe() + " at " + accuracy_.describe();
}

bool RegionCriterion::triangle_satisfies(const Triangle3& v, double res,
                                         const CrmrInfo& info) const {
  const double e = error_at(info, res);
  return accuracy_.allows(e) || !region_->triangle_meets(v, e);
}

bool RegionCriterion::region_satisfies(const Box3& box, double min_res,
                                       const CrmrInfo& info) const {
  const double e = error_at(info, min_res);  // the largest error of any triangle there
  return accuracy_.allows(e) || !region_->box_meets(box, e);
}

Rcf region_rcf(std::shared_ptr<const Region> region, Accuracy accuracy) {
  check_accuracy(accuracy);
  Rcf rcf;
  rcf.add(std::shared_ptr<const SimilarityComponent>(
      std::make_shared<RegionCriterion>(std::move(region), accuracy)));
  return rcf;
}

HeightRegionRcf::HeightRegionRcf(std::shared_ptr<const Region> region, Accuracy accuracy)
    : region_(std::move(region)), accuracy_(accuracy) {
  check_accuracy(accuracy_);
}

bool HeightRegionRcf::is_finer(const OpView& op, const OpSource& source) const {
  bool all = true;
  for (const FragmentTriangle& t : op.fragment)
    all = all && (!t.killer.valid() || accuracy_.allows(source.error_at(t.death_res)));
  return all || !region_->box_meets(op.roi, 0.0);
}

bool HeightRegionRcf::is_completely_finer(const OpView& op, const OpSource& source) const {
  if (op.id == kBaseOp) return false;
  return accuracy_.allows(source.error_at(op.birth_res)) || !region_->box_meets(op.roi, 0.0);
}

bool HeightRegionRcf::region_completely_finer(const Box3&, const Box3& roi, double min_birth_res,
                                              const CrmrInfo& info) const {
  return accuracy_.allows(error_at(info, min_birth_res)) || !region_->box_meets(roi, 0.0);
}

Extraction refine(const OpSource& source, std::shared_ptr<const Region> region, Accuracy accuracy) {
  ExpansionOptions options;
  options.fronts = false;  // the set formula: same triangles, no fans needed
  if (region->depends_on_height()) {
    const HeightRegionRcf rcf(std::move(region), accuracy);
    return extract_minimal_surface(source, rcf, options);
  }
  const Rcf rcf = region_rcf(std::move(region), accuracy);
  return extract_minimal_surface(source, rcf, options);
}

double triangle_error(const OpSource& source, const FragmentTriangle& t) {
  return t.killer.valid() ? source.error_at(t.death_res) : source.info().err_final;
}

std::string point_text(const Vec2& p) {
  std::ostringstream os;
  os.precision(15);
  os << '(' << p.x << ", " << p.y << ')';
  return os.str();
}

void Domain::require(const Vec2& p, const std::string& what) const {
  if (std::isfinite(p.x) && std::isfinite(p.y) && contains(p)) return;
  throw Error(ErrorKind::kInvalidInput, what + " " + point_text(p) +
                                            " is outside the database's domain " + point_text(lo) +
                                            " .. " + point_text(hi));
}

Domain terrain_domain(const CrmrInfo& info) {
  if (info.kind != ModelKind::kTerrain)
    throw Error(ErrorKind::kInvalidInput,
                "this query needs a terrain database; this one holds a 3-D mesh");
  const Georef& g = info.georef;
  Domain d;
  d.lo = {g.x0, g.y0};
  d.hi = {g.x0 + (info.grid_width - 1) * g.dx, g.y0 + (info.grid_height - 1) * g.dy};
  return d;
}

}  // namespace smr::query
