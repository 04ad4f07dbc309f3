// Ready-made R-tree visitors for exact selective refinement (Maheshwari et al. 3.2: retrieve
// every op whose roi meets the query region q; Lemma 1 shows this reconstructs every triangle
// meeting q). The region is a window (3.2), a vertical line through a point (4.1, point location
// and elevation), a 3-D segment (4.3, line of sight) or the plane z = h (4.2, contour lines).
// `enter` applies the same test to a subtree's roi union, `accept` to an entry's roi; both see
// the stored, conservatively rounded boxes (index/rtree.h), so results can only be supersets of
// the exact answer. The predicates are exposed so callers can reuse them on their own boxes.
#pragma once

#include <array>

#include "index/box.h"
#include "index/rtree.h"

namespace smr::index {

using Point3 = std::array<double, 3>;

// Closed-box overlap. A window with z = -inf..+inf is a 2-D window.
bool window_meets(const Box& window, const Box& box);
// The vertical line through (x, y) meets `box`.
bool point_meets(double x, double y, const Box& box);
// The closed segment pq meets `box` (slab test, with a relative slack of 1e-12 on the segment
// parameter so rounding never loses a touching box). Monotone: a bigger box never fails.
bool segment_meets(const Point3& p, const Point3& q, const Box& box);
// `box` spans the plane z = h.
bool plane_meets(double h, const Box& box);

class WindowVisitor : public Visitor {
 public:
  explicit WindowVisitor(const Box& window) : window_(window) {}
  bool enter(const Summary& s) override { return window_meets(window_, s.roi); }
  bool accept(const Entry& e) override { return window_meets(window_, e.roi); }

 private:
  Box window_;
};

class PointVisitor : public Visitor {
 public:
  PointVisitor(double x, double y) : x_(x), y_(y) {}
  bool enter(const Summary& s) override { return point_meets(x_, y_, s.roi); }
  bool accept(const Entry& e) override { return point_meets(x_, y_, e.roi); }

 private:
  double x_;
  double y_;
};

class SegmentVisitor : public Visitor {
 public:
  SegmentVisitor(const Point3& p, const Point3& q) : p_(p), q_(q) {}
  bool enter(const Summary& s) override { return segment_meets(p_, q_, s.roi); }
  bool accept(const Entry& e) override { return segment_meets(p_, q_, e.roi); }

 private:
  Point3 p_;
  Point3 q_;
};

class PlaneVisitor : public Visitor {
 public:
  explicit PlaneVisitor(double h) : h_(h) {}
  bool enter(const Summary& s) override { return plane_meets(h_, s.roi); }
  bool accept(const Entry& e) override { return plane_meets(h_, e.roi); }

 private:
  double h_;
};

}  // namespace smr::index
