// Exact selective refinement of a query region (Maheshwari et al. 3.2 and 4; docs/design.md
// section 7). A query asks for the mesh that is final (or within a stated error) wherever the
// region may matter and as coarse as the model allows elsewhere: the region is a window (3.2), a
// vertical line (4.1, elevation), a 3-D segment (4.3, line of sight) or the plane z = h (4.2,
// contours).
//
// Here a region becomes a similarity component of an ordinary RCF (Brown 4.6): a triangle that
// meets the region must be final (no op refines it) or carry an error no larger than the one
// asked for; every other triangle satisfies it. Minimal-surface extraction (Brown 5.1) with that
// RCF is the query: AddToList visits only ops whose PreF meets the region (plus their
// ancestors), the R-tree rules out subtrees whose boxes miss it (Maheshwari 4.4, through
// IndexedSource), and Brown Theorem 5.1.1 guarantees every output triangle meeting the region is
// final. That also removes the caveat of Maheshwari's Fig. 9 (the ops whose ROI meets the region
// may leave coarse triangles that still meet it): the RCF keeps refining until none is left.
//
// A region that depends on heights (the plane z = h, a 3-D segment) cannot be judged on a
// triangle and its error: the error bounds the triangle's deviation at the grid samples under it,
// but the finer triangles that replace it cross its edges, so the finest surface over its
// footprint can leave its error band (measured on the test DEMs: up to 86 times the error). Such
// regions are judged by ROI instead (Maheshwari 3.2 retrieves the ops whose ROI meets the
// region; the ROI holds every triangle that refines the op): HeightRegionRcf below. Then a
// triangle that stays coarse has a killer whose ROI misses the region, so nothing that refines it
// meets the region, and at the finest accuracy the answer is exactly the finest mesh's.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "smr/core/geometry.h"
#include "smr/core/op_source.h"
#include "smr/extract/extract.h"
#include "smr/rcf/rcf.h"

namespace smr::query {

/// How fine an answer must be.
struct Accuracy {
  /// Absent: the finest mesh (every triangle that matters is final; for a lossless database that
  /// is the source itself). Present: triangles that matter have error <= max_error data units.
  std::optional<double> max_error;
  static Accuracy finest() { return {}; }
  static Accuracy within(double e) { return {e}; }
  /// A triangle of this error is fine enough (never, at the finest accuracy: only final ones).
  bool allows(double error) const { return max_error && error <= *max_error; }
  std::string describe() const;
};

/// A query region as the refinement sees it. Both tests must be conservative and monotone: a
/// bigger box or a bigger error may only say "meets" more often.
class Region {
 public:
  virtual ~Region() = default;
  virtual std::string describe() const = 0;
  /// The surface within `error` (vertically) of the triangle with corners v may meet the region.
  virtual bool triangle_meets(const Triangle3& v, double error) const = 0;
  /// The surface within `error` of any triangle inside `box` may meet the region.
  virtual bool box_meets(const Box3& box, double error) const = 0;
  /// Whether meeting depends on heights (then refine() judges ops by their ROIs).
  virtual bool depends_on_height() const { return false; }
};

/// The 2-D window [lo, hi] in x-y (Maheshwari 3.2): closed, any height.
class WindowRegion final : public Region {
 public:
  WindowRegion(Vec2 lo, Vec2 hi) : lo_(lo), hi_(hi) {}
  std::string describe() const override;
  bool triangle_meets(const Triangle3& v, double error) const override;
  bool box_meets(const Box3& box, double error) const override;

 private:
  Vec2 lo_, hi_;
};

/// The 2-D segment ab in x-y (the vertical wall over it): a profile's support.
class PathRegion final : public Region {
 public:
  PathRegion(Vec2 a, Vec2 b) : a_(a), b_(b) {}
  std::string describe() const override;
  bool triangle_meets(const Triangle3& v, double error) const override;
  bool box_meets(const Box3& box, double error) const override;

 private:
  Vec2 a_, b_;
};

/// Several regions at once: meets when any does.
class UnionRegion final : public Region {
 public:
  explicit UnionRegion(std::vector<std::shared_ptr<const Region>> parts)
      : parts_(std::move(parts)) {}
  std::string describe() const override;
  bool triangle_meets(const Triangle3& v, double error) const override;
  bool box_meets(const Box3& box, double error) const override;
  bool depends_on_height() const override;

 private:
  std::vector<std::shared_ptr<const Region>> parts_;
};

/// The similarity component a region query runs with: a triangle meeting the region (at its own
/// error, error_at(res)) satisfies it only when its error is <= Accuracy::max_error; with
/// Accuracy::finest() never (only final triangles, which every component accepts, do).
class RegionCriterion final : public SimilarityComponent {
 public:
  RegionCriterion(std::shared_ptr<const Region> region, Accuracy accuracy)
      : region_(std::move(region)), accuracy_(accuracy) {}
  std::string describe() const override;
  bool triangle_satisfies(const Triangle3& v, double res, const CrmrInfo& info) const override;
  bool region_satisfies(const Box3& box, double min_res, const CrmrInfo& info) const override;

 private:
  std::shared_ptr<const Region> region_;
  Accuracy accuracy_;
};

/// The RCF of a region query whose region does not depend on heights.
Rcf region_rcf(std::shared_ptr<const Region> region, Accuracy accuracy);

/// The refinement condition of a region that depends on heights, judged by ROI: an op is
/// completely finer when its error (error_at(birth_res)) is within the accuracy or its ROI misses
/// the region; finer when every triangle of its fragment is final or within the accuracy, or its
/// ROI misses the region (conservative: AddToList then judges its children exactly). An index
/// entry or subtree is completely finer when its ROI union misses the region.
class HeightRegionRcf final : public RcfOracle {
 public:
  HeightRegionRcf(std::shared_ptr<const Region> region, Accuracy accuracy);
  bool is_finer(const OpView& op, const OpSource& source) const override;
  bool is_completely_finer(const OpView& op, const OpSource& source) const override;
  bool region_completely_finer(const Box3& box, const Box3& roi, double min_birth_res,
                               const CrmrInfo& info) const override;

 private:
  std::shared_ptr<const Region> region_;
  Accuracy accuracy_;
};

/// Selective refinement for a region: the minimal-surface mesh (set formula, page order; pass an
/// IndexedSource so the R-tree prunes) of region_rcf, or of HeightRegionRcf when the region
/// depends on heights. Every triangle of the result meeting the region is final, or within
/// accuracy.max_error; for a region about heights, at the finest accuracy, every triangle left
/// coarse is one that nothing refining it meets the region.
Extraction refine(const OpSource& source, std::shared_ptr<const Region> region, Accuracy accuracy);

/// The error a triangle of the result carries: err_final (0 for a lossless build) when it is
/// final, error_at(death_res) otherwise.
double triangle_error(const OpSource& source, const FragmentTriangle& t);

/// "(x, y)" for messages (15 significant digits).
std::string point_text(const Vec2& p);

/// The domain of a terrain database: the source grid's extent in its own coordinates.
struct Domain {
  Vec2 lo{0.0}, hi{0.0};
  bool contains(const Vec2& p) const {
    return p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y;
  }
  /// Throws smr::Error (kInvalidInput) naming `what`, p and the domain unless p is finite and
  /// inside.
  void require(const Vec2& p, const std::string& what) const;
};
/// Throws smr::Error (kInvalidInput) naming the database kind when `info` is not a terrain.
Domain terrain_domain(const CrmrInfo& info);

}  // namespace smr::query
