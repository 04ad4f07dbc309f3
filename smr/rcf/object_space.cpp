// Object-space resolution function terms (Brown 4.6.2, Fig. 4.20 and 4.22).
#include "smr/rcf/object_space.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <glm/geometric.hpp>

namespace smr {

namespace {

std::string fmt(const char* name, std::initializer_list<double> v) {
  std::ostringstream os;
  os << name << "(";
  bool first = true;
  for (double x : v) {
    os << (first ? "" : ",") << x;
    first = false;
  }
  os << ")";
  return os.str();
}

// Closed segments pq and rs intersect (with a small relative slack, erring towards "yes").
bool segments_meet(const Vec2& p, const Vec2& q, const Vec2& r, const Vec2& s) {
  const double scale = 1e-12 * (1.0 + glm::length(q - p)) * (1.0 + glm::length(s - r));
  const double d1 = orient2d(p, q, r), d2 = orient2d(p, q, s);
  const double d3 = orient2d(r, s, p), d4 = orient2d(r, s, q);
  if (((d1 > scale && d2 > scale) || (d1 < -scale && d2 < -scale))) return false;
  if (((d3 > scale && d4 > scale) || (d3 < -scale && d4 < -scale))) return false;
  // Collinear: compare projections.
  if (std::abs(d1) <= scale && std::abs(d2) <= scale) {
    const Vec2 dir = q - p;
    const double t0 = glm::dot(r - p, dir), t1 = glm::dot(s - p, dir), len = glm::dot(dir, dir);
    return std::max(t0, t1) >= -scale && std::min(t0, t1) <= len + scale;
  }
  return true;
}

bool in_triangle(const Vec2& p, const Vec2& a, const Vec2& b, const Vec2& c) {
  return point_triangle_distance2d(p, a, b, c) <= 0.0;
}

}  // namespace

// ---- constant ----
std::string ConstantTerm::describe() const {
  return fmt("floor", {level_});
}

// ---- Gaussian ----
std::string GaussianTerm::describe() const {
  return fmt("aoi", {c_.x, c_.y, r_, level_});
}
double GaussianTerm::at_distance(double d) const {
  if (r_ <= 0.0) return d <= 0.0 ? level_ : 0.0;
  return level_ * std::exp(-(d * d) / (2.0 * r_ * r_));
}
double GaussianTerm::value(const Vec2& p) const {
  return at_distance(glm::length(p - c_));
}
double GaussianTerm::max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const {
  // The maximum is at the point of the triangle nearest the centre; shrink the distance by a hair
  // so rounding never puts it below a sampled value.
  const double d = point_triangle_distance2d(c_, a, b, c);
  return at_distance(std::max(0.0, d * (1.0 - 1e-12) - 1e-12 * r_));
}
double GaussianTerm::max_over_rect(const Vec2& lo, const Vec2& hi) const {
  return at_distance(std::max(0.0, point_rect_distance2d(c_, lo, hi) * (1.0 - 1e-12)));
}

// ---- disc ----
std::string DiscTerm::describe() const {
  return fmt("disc", {c_.x, c_.y, r_, level_});
}
double DiscTerm::value(const Vec2& p) const {
  return glm::length(p - c_) <= r_ ? level_ : 0.0;
}
double DiscTerm::max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const {
  const double d = point_triangle_distance2d(c_, a, b, c);
  return d <= r_ * (1.0 + 1e-12) + 1e-12 ? level_ : 0.0;
}
double DiscTerm::max_over_rect(const Vec2& lo, const Vec2& hi) const {
  return point_rect_distance2d(c_, lo, hi) <= r_ * (1.0 + 1e-12) + 1e-12 ? level_ : 0.0;
}

// ---- wedge ----
WedgeTerm::WedgeTerm(Vec2 apex, double a0, double a1, double level, bool full_plane,
                     std::string label)
    : apex_(apex), a0_(a0), a1_(a1), level_(level), full_(full_plane), label_(std::move(label)) {}

WedgeTerm WedgeTerm::from_rays(const Camera& cam, const std::vector<Vec3>& rays, double level,
                               std::string label) {
  // The xy-projection of a pointed convex cone of rays is the wedge spanned by its extreme
  // projected rays; if the projected directions leave no gap wider than pi, it is the whole plane.
  std::vector<double> angles;
  for (const Vec3& r : rays) {
    if (std::hypot(r.x, r.y) < 1e-12) return WedgeTerm(xy(cam.eye), 0, 0, level, true, label);
    angles.push_back(std::atan2(r.y, r.x));
  }
  std::sort(angles.begin(), angles.end());
  double best_gap = -1.0;
  std::size_t best = 0;
  for (std::size_t i = 0; i < angles.size(); ++i) {
    const double next = i + 1 < angles.size() ? angles[i + 1] : angles[0] + 2 * M_PI;
    if (next - angles[i] > best_gap) {
      best_gap = next - angles[i];
      best = i;
    }
  }
  if (best_gap <= M_PI + 1e-12) return WedgeTerm(xy(cam.eye), 0, 0, level, true, label);
  // The wedge runs from the ray after the gap counter-clockwise to the ray before it.
  const double start = best + 1 < angles.size() ? angles[best + 1] : angles[0] + 2 * M_PI;
  const double end = angles[best] + 2 * M_PI;
  double a0 = start, a1 = end;
  if (a1 - a0 >= 2 * M_PI) a1 -= 2 * M_PI;
  while (a0 >= M_PI) {
    a0 -= 2 * M_PI;
    a1 -= 2 * M_PI;
  }
  return WedgeTerm(xy(cam.eye), a0, a1, level, false, std::move(label));
}

WedgeTerm WedgeTerm::frustum_footprint(const Camera& cam, double level) {
  const Vec3 f = cam.forward(), r = cam.right(), u = cam.true_up();
  std::vector<Vec3> rays;
  for (double sx : {-1.0, 1.0}) {
    for (double sy : {-1.0, 1.0})
      rays.push_back(f + sx * cam.tan_half_x() * r + sy * cam.tan_half_y() * u);
  }
  return from_rays(cam, rays, level, fmt("frustum", {level}));
}

WedgeTerm WedgeTerm::centre_cone(const Camera& cam, double cone_deg, double level) {
  const Vec3 f = cam.forward(), r = cam.right(), u = cam.true_up();
  const double t = std::tan(cone_deg * M_PI / 180.0);
  std::vector<Vec3> rays;
  for (int i = 0; i < 32; ++i) {
    const double phi = 2 * M_PI * i / 32;
    rays.push_back(f + t * (std::cos(phi) * r + std::sin(phi) * u));
  }
  return from_rays(cam, rays, level, fmt("centre-cone", {cone_deg, level}));
}

std::string WedgeTerm::describe() const {
  return label_;
}

bool WedgeTerm::contains(const Vec2& p, double slack) const {
  if (full_) return true;
  const Vec2 d = p - apex_;
  if (std::hypot(d.x, d.y) <= slack) return true;
  double a = std::atan2(d.y, d.x);
  while (a < a0_ - slack) a += 2 * M_PI;
  return a <= a1_ + slack;
}

double WedgeTerm::value(const Vec2& p) const {
  return contains(p, 0.0) ? level_ : 0.0;
}

bool WedgeTerm::meets_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const {
  if (full_) return true;
  const double slack = 1e-9;
  if (contains(a, slack) || contains(b, slack) || contains(c, slack)) return true;
  if (in_triangle(apex_, a, b, c)) return true;
  // A boundary ray crossing an edge: clip the rays at a length beyond the triangle.
  const double reach =
      2.0 * (glm::length(a - apex_) + glm::length(b - apex_) + glm::length(c - apex_)) + 1.0;
  for (double ang : {a0_, a1_}) {
    const Vec2 end = apex_ + reach * Vec2{std::cos(ang), std::sin(ang)};
    if (segments_meet(apex_, end, a, b) || segments_meet(apex_, end, b, c) ||
        segments_meet(apex_, end, c, a)) {
      return true;
    }
  }
  return false;
}

double WedgeTerm::max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const {
  return meets_triangle(a, b, c) ? level_ : 0.0;
}
double WedgeTerm::max_over_rect(const Vec2& lo, const Vec2& hi) const {
  const Vec2 p01{lo.x, hi.y}, p10{hi.x, lo.y};
  return (meets_triangle(lo, p10, hi) || meets_triangle(lo, hi, p01)) ? level_ : 0.0;
}

// ---- critical lines ----
std::string CriticalLineTerm::describe() const {
  return fmt("critical-lines", {level_, double(lines_->count())});
}

double CriticalLineTerm::value(const Vec2& p) const {
  const Georef& g = lines_->georef();
  const double gx = (p.x - g.x0) / g.dx, gy = (p.y - g.y0) / g.dy;
  const double cx = std::round(gx), cy = std::round(gy);
  if (std::abs(gx - cx) > 1e-9 || std::abs(gy - cy) > 1e-9) return 0.0;
  if (cx < 0 || cy < 0 || cx >= lines_->width() || cy >= lines_->height()) return 0.0;
  return lines_->flagged(int(cx), int(cy)) ? level_ : 0.0;
}

double CriticalLineTerm::max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const {
  const Georef& g = lines_->georef();
  const Vec2 p[3] = {{(a.x - g.x0) / g.dx, (a.y - g.y0) / g.dy},
                     {(b.x - g.x0) / g.dx, (b.y - g.y0) / g.dy},
                     {(c.x - g.x0) / g.dx, (c.y - g.y0) / g.dy}};
  constexpr double kSlack = 1e-7;
  const double ylo = std::min({p[0].y, p[1].y, p[2].y}), yhi = std::max({p[0].y, p[1].y, p[2].y});
  const double xlo = std::min({p[0].x, p[1].x, p[2].x}), xhi = std::max({p[0].x, p[1].x, p[2].x});
  const int r0 = int(std::ceil(ylo - kSlack)), r1 = int(std::floor(yhi + kSlack));
  const int c0 = int(std::ceil(xlo - kSlack)), c1 = int(std::floor(xhi + kSlack));
  if (lines_->count_in_rect(c0, r0, c1, r1) == 0) return 0.0;
  for (int row = std::max(r0, 0); row <= std::min(r1, lines_->height() - 1); ++row) {
    // x-extent of the closed triangle on this row.
    double xl = std::numeric_limits<double>::infinity(), xr = -xl;
    for (int e = 0; e < 3; ++e) {
      const Vec2& u = p[e];
      const Vec2& v = p[(e + 1) % 3];
      const double ya = std::min(u.y, v.y), yb = std::max(u.y, v.y);
      if (row < ya - kSlack || row > yb + kSlack) continue;
      if (yb - ya < kSlack) {
        xl = std::min({xl, u.x, v.x});
        xr = std::max({xr, u.x, v.x});
        continue;
      }
      const double t = std::clamp((row - u.y) / (v.y - u.y), 0.0, 1.0);
      const double x = u.x + t * (v.x - u.x);
      xl = std::min(xl, x);
      xr = std::max(xr, x);
    }
    if (xl > xr) continue;
    if (lines_->count_in_row(row, int(std::ceil(xl - kSlack)), int(std::floor(xr + kSlack))) > 0) {
      return level_;
    }
  }
  return 0.0;
}

double CriticalLineTerm::max_over_rect(const Vec2& lo, const Vec2& hi) const {
  const Georef& g = lines_->georef();
  const int c0 = int(std::ceil((lo.x - g.x0) / g.dx - 1e-7)),
            c1 = int(std::floor((hi.x - g.x0) / g.dx + 1e-7));
  const int r0 = int(std::ceil((lo.y - g.y0) / g.dy - 1e-7)),
            r1 = int(std::floor((hi.y - g.y0) / g.dy + 1e-7));
  return lines_->count_in_rect(c0, r0, c1, r1) > 0 ? level_ : 0.0;
}

// ---- the function ----
double ObjectSpaceFunction::value(const Vec2& p) const {
  double g = 0.0;
  for (const auto& t : terms_) g = std::max(g, t->value(p));
  return std::clamp(g, 0.0, 1.0);
}
double ObjectSpaceFunction::max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const {
  double g = 0.0;
  for (const auto& t : terms_) {
    g = std::max(g, t->max_over_triangle(a, b, c));
    if (g >= 1.0) break;
  }
  return std::clamp(g, 0.0, 1.0);
}
double ObjectSpaceFunction::max_over_rect(const Vec2& lo, const Vec2& hi) const {
  double g = 0.0;
  for (const auto& t : terms_) g = std::max(g, t->max_over_rect(lo, hi));
  return std::clamp(g, 0.0, 1.0);
}

bool ObjectSpaceFunction::moves_with_camera() const {
  return std::any_of(terms_.begin(), terms_.end(),
                     [](const auto& t) { return t->moves_with_camera(); });
}

}  // namespace smr
