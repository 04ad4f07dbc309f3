// The 2.5-D object-space resolution function g: Omega -> [0, 1] (Brown 4.6.2), composed as the
// pointwise maximum of terms: a constant floor, Gaussian areas of interest, thresholded discs,
// 2-D wedges (the view frustum's footprint, a screen-centre cone) and critical lines.
// Each term gives its value at a point and its exact (or conservatively rounded up) maximum over
// a triangle and over a rectangle, which is what IsFiner/IsCompletelyFiner and the index need.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "smr/core/geometry.h"
#include "smr/rcf/camera.h"
#include "smr/rcf/critical_lines.h"

namespace smr {

class ObjectSpaceTerm {
 public:
  virtual ~ObjectSpaceTerm() = default;
  virtual std::string describe() const = 0;
  virtual double value(const Vec2& p) const = 0;
  /// >= value(p) for every p in the closed triangle (exact up to rounding, never below).
  virtual double max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const = 0;
  /// >= value(p) for every p in the closed rectangle [lo, hi].
  virtual double max_over_rect(const Vec2& lo, const Vec2& hi) const = 0;
  /// Built from a camera (it changes when the camera moves).
  virtual bool moves_with_camera() const { return false; }
};

/// A term judged in a MetricFrame: points, triangles and rectangles are mapped into the frame
/// (an axis scaling: triangles stay triangles and rectangles rectangles) and asked of `inner`.
class FramedTerm final : public ObjectSpaceTerm {
 public:
  FramedTerm(std::shared_ptr<const ObjectSpaceTerm> inner, MetricFrame frame)
      : inner_(std::move(inner)), frame_(frame) {}
  std::string describe() const override { return inner_->describe() + " (metric frame)"; }
  double value(const Vec2& p) const override { return inner_->value(frame_.apply(p)); }
  double max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const override {
    return inner_->max_over_triangle(frame_.apply(a), frame_.apply(b), frame_.apply(c));
  }
  double max_over_rect(const Vec2& lo, const Vec2& hi) const override {
    return inner_->max_over_rect(frame_.apply(lo), frame_.apply(hi));
  }
  bool moves_with_camera() const override { return inner_->moves_with_camera(); }

 private:
  std::shared_ptr<const ObjectSpaceTerm> inner_;
  MetricFrame frame_;
};

class ConstantTerm final : public ObjectSpaceTerm {
 public:
  explicit ConstantTerm(double level) : level_(level) {}
  std::string describe() const override;
  double value(const Vec2&) const override { return level_; }
  double max_over_triangle(const Vec2&, const Vec2&, const Vec2&) const override { return level_; }
  double max_over_rect(const Vec2&, const Vec2&) const override { return level_; }

 private:
  double level_;
};

/// level * exp(-d^2 / (2 radius^2)), d = distance to the centre (Brown's Gaussian AOI).
class GaussianTerm final : public ObjectSpaceTerm {
 public:
  GaussianTerm(Vec2 center, double radius, double level) : c_(center), r_(radius), level_(level) {}
  std::string describe() const override;
  double value(const Vec2& p) const override;
  double max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const override;
  double max_over_rect(const Vec2& lo, const Vec2& hi) const override;

 private:
  double at_distance(double d) const;
  Vec2 c_;
  double r_, level_;
};

/// level inside the closed disc, 0 outside (a thresholded area of interest).
class DiscTerm final : public ObjectSpaceTerm {
 public:
  DiscTerm(Vec2 center, double radius, double level) : c_(center), r_(radius), level_(level) {}
  std::string describe() const override;
  double value(const Vec2& p) const override;
  double max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const override;
  double max_over_rect(const Vec2& lo, const Vec2& hi) const override;

 private:
  Vec2 c_;
  double r_, level_;
};

/// level inside a 2-D wedge {apex + t*(cos a, sin a) : t >= 0, a in [a0, a1]}, a1 - a0 < pi,
/// or everywhere when `full_plane`. Built from a camera: the xy-footprint of its frustum, or of a
/// cone of half-angle `cone_deg` around its view direction (Brown Fig. 4.22 a, b).
class WedgeTerm final : public ObjectSpaceTerm {
 public:
  WedgeTerm(Vec2 apex, double a0, double a1, double level, bool full_plane, std::string label);
  static WedgeTerm frustum_footprint(const Camera& cam, double level);
  static WedgeTerm centre_cone(const Camera& cam, double cone_deg, double level);
  bool moves_with_camera() const override { return true; }
  std::string describe() const override;
  double value(const Vec2& p) const override;
  double max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const override;
  double max_over_rect(const Vec2& lo, const Vec2& hi) const override;
  bool contains(const Vec2& p, double slack) const;

 private:
  static WedgeTerm from_rays(const Camera& cam, const std::vector<Vec3>& rays, double level,
                             std::string label);
  bool meets_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const;
  Vec2 apex_;
  double a0_, a1_, level_;
  bool full_;
  std::string label_;
};

/// level at every critical-line sample (a sample lies in a triangle iff it is in the closed
/// triangle, with a 1e-7 grid-cell slack so the test errs towards refinement).
class CriticalLineTerm final : public ObjectSpaceTerm {
 public:
  CriticalLineTerm(std::shared_ptr<const CriticalLines> lines, double level)
      : lines_(std::move(lines)), level_(level) {}
  std::string describe() const override;
  double value(const Vec2& p) const override;
  double max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const override;
  double max_over_rect(const Vec2& lo, const Vec2& hi) const override;
  const CriticalLines& lines() const { return *lines_; }

 private:
  std::shared_ptr<const CriticalLines> lines_;
  double level_;
};

/// g = max over terms, clamped to [0, 1]; 0 when there are no terms.
class ObjectSpaceFunction {
 public:
  void add(std::shared_ptr<const ObjectSpaceTerm> term) { terms_.push_back(std::move(term)); }
  bool empty() const { return terms_.empty(); }
  const std::vector<std::shared_ptr<const ObjectSpaceTerm>>& terms() const { return terms_; }
  double value(const Vec2& p) const;
  double max_over_triangle(const Vec2& a, const Vec2& b, const Vec2& c) const;
  double max_over_rect(const Vec2& lo, const Vec2& hi) const;
  bool moves_with_camera() const;

 private:
  std::vector<std::shared_ptr<const ObjectSpaceTerm>> terms_;
};

}  // namespace smr
