// The Resolution Control Function (Brown 4.6): an oracle telling whether a refinement operation
// is finer (its fragment F satisfies the RCF) or completely finer (its pre-operation set PreF
// already does) than the required resolution. Composed of culling components (view frustum,
// back-face) and similarity components (object-space g, screen-space tolerance tau), as in
// Brown's Fig. 4.19:
//   IsFiner(R)           = culled(R) or every similarity component accepts F(R)
//   IsCompletelyFiner(R) = R != R^0 and (culled(R) or every component accepts PreF(R))
// evaluated triangle by triangle. Culling of an op is decided on its box/sphere/cone, which cover
// F and PreF; a PreF triangle is culled when its own corners are (all outside one frustum plane, or
// facing away). A culled op's triangles are culled by the triangle test too, which keeps
// "all parents finer => completely finer" exact, and every test needs only the op's own record.
// Every component also answers conservatively for an index entry (a box holding the ROIs of many
// ops, with a minimum birth_res): true only if every such op is completely finer.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "smr/core/crmr.h"
#include "smr/rcf/camera.h"
#include "smr/rcf/object_space.h"

namespace smr {

/// A verdict over a set of cameras (Kleene's three values): true for every camera of the set,
/// false for every one, or not the same for all.
enum class Tri : std::uint8_t { kFalse, kTrue, kUnknown };
inline Tri to_tri(bool b) {
  return b ? Tri::kTrue : Tri::kFalse;
}

/// A set of cameras about a component's own: the eye moved by at most `delta` (in the component's
/// MetricFrame) and the view turned by at most `theta` radians, every other parameter the same.
/// Sessions keep a verdict while the camera stays in such a set (Session, smr/extract).
struct Motion {
  double delta = 0.0, theta = 0.0;
  bool zero() const { return delta == 0.0 && theta == 0.0; }
};

class CullingComponent {
 public:
  virtual ~CullingComponent() = default;
  virtual std::string describe() const = 0;
  /// True when F(op) and PreF(op) are invisible (and, for back faces, all that refines them).
  virtual bool culls(const OpView& op) const = 0;
  /// Conservative: true only if every op whose box lies inside `box` is culled.
  virtual bool culls_region(const Box3& box) const = 0;
  /// The triangle with these corners is invisible, so it may stand at any resolution. Never true
  /// unless culls(op) would be for an op holding only that triangle.
  virtual bool culls_triangle(const Triangle3& v) const = 0;
  /// culls / culls_triangle for every camera within `m` of this one; a component that cannot
  /// bound them answers kUnknown for any motion but none.
  virtual Tri culls_within(const OpView& op, const Motion& m) const {
    return m.zero() ? to_tri(culls(op)) : Tri::kUnknown;
  }
  virtual Tri culls_triangle_within(const Triangle3& v, const Motion& m) const {
    return m.zero() ? to_tri(culls_triangle(v)) : Tri::kUnknown;
  }
  /// culls_region for every camera within `m`: true only if it holds for them all.
  virtual bool culls_region_within(const Box3& box, const Motion& m) const {
    return m.zero() && culls_region(box);
  }
  /// The camera the component judges by, in its MetricFrame (nullptr: it has none).
  virtual const Camera* camera() const { return nullptr; }
};

/// A triangle that no op replaces is as fine as the model gets: it satisfies every similarity
/// criterion (Brown 4.6.2: "or if its fragment has no children"; the proof of Theorem 5.1.1 relies
/// on it). A void triangle covers no data and is never output.
inline bool is_final_or_void(const FragmentTriangle& t) {
  return t.is_void() || !t.killer.valid();
}

/// Whether a triangle that some op replaces, standing for resolution `res`, meets the resolution
/// level `level` (Brown 4.6.2: res >= level). Level 1 asks for the finest mesh itself, which no
/// replaced triangle is part of, not even one an op of zero error replaces (its birth_res is 1 as
/// well): so a full refinement always reaches the source, face for face.
inline bool meets_level(double res, double level) {
  return res >= level && level < 1.0;
}

class SimilarityComponent {
 public:
  virtual ~SimilarityComponent() = default;
  virtual std::string describe() const = 0;
  /// The triangle with corners v meets the criterion when it stands for resolution `res`.
  virtual bool triangle_satisfies(const Triangle3& v, double res, const CrmrInfo& info) const = 0;
  /// Conservative: true only if triangle_satisfies for every triangle inside `box` at every
  /// resolution >= min_res.
  virtual bool region_satisfies(const Box3& box, double min_res, const CrmrInfo& info) const = 0;
  /// triangle_satisfies / region_satisfies for every camera within `m` (CullingComponent's
  /// culls_within); components that no camera affects answer as for none.
  virtual Tri triangle_satisfies_within(const Triangle3& v, double res, const CrmrInfo& info,
                                        const Motion& m) const {
    return m.zero() ? to_tri(triangle_satisfies(v, res, info)) : Tri::kUnknown;
  }
  virtual Tri region_satisfies_within(const Box3& box, double min_res, const CrmrInfo& info,
                                      const Motion& m) const {
    return m.zero() ? to_tri(region_satisfies(box, min_res, info)) : Tri::kUnknown;
  }
  virtual const Camera* camera() const { return nullptr; }
};

class FrustumCulling final : public CullingComponent {
 public:
  /// `cam` in model coordinates; the tests run in `frame` (MetricFrame).
  explicit FrustumCulling(const Camera& cam, MetricFrame frame = {})
      : frame_(frame), cam_(frame.apply(cam)), frustum_(cam_) {}
  std::string describe() const override { return "frustum-culling"; }
  bool culls(const OpView& op) const override;
  bool culls_region(const Box3& box) const override {
    return box_outside(frustum_, frame_.apply(box));
  }
  bool culls_triangle(const Triangle3& v) const override;
  Tri culls_within(const OpView& op, const Motion& m) const override;
  Tri culls_triangle_within(const Triangle3& v, const Motion& m) const override;
  bool culls_region_within(const Box3& box, const Motion& m) const override;
  const Camera* camera() const override { return &cam_; }

 private:
  MetricFrame frame_;
  Camera cam_;  // in the frame
  Frustum frustum_;
};

class BackfaceCulling final : public CullingComponent {
 public:
  explicit BackfaceCulling(Camera cam) : cam_(std::move(cam)) {}
  std::string describe() const override { return "backface-culling"; }
  /// Every normal of the op and of all its descendants (subtree_cone, around the ROI) faces away:
  /// refining it can never show anything (Hoppe 1997 section 4.2). The op's own cone is not
  /// enough: at a silhouette a coarse back-facing fragment refines into visible detail.
  bool culls(const OpView& op) const override;
  bool culls_region(const Box3&) const override { return false; }  // no normals for a region
  /// Never: a triangle's corners say nothing about the refinements that replace it.
  bool culls_triangle(const Triangle3&) const override { return false; }
  Tri culls_within(const OpView& op, const Motion& m) const override;
  Tri culls_triangle_within(const Triangle3&, const Motion&) const override { return Tri::kFalse; }
  const Camera* camera() const override { return &cam_; }

 private:
  Camera cam_;
};

/// Brown 4.6.2: t satisfies g when death_res(t) >= g(p) for every p in its domain D(t); PreF(R)
/// satisfies g when birth_res(R) >= g(p) on D(PreF(R)) = D(F(R)) (2.5-D ops are complete).
class ObjectSpaceCriterion final : public SimilarityComponent {
 public:
  explicit ObjectSpaceCriterion(ObjectSpaceFunction g) : g_(std::move(g)) {}
  std::string describe() const override;
  bool triangle_satisfies(const Triangle3& v, double res, const CrmrInfo& info) const override;
  bool region_satisfies(const Box3& box, double min_res, const CrmrInfo& info) const override;
  /// Exact for any motion unless a term is built from the camera (then kUnknown but for none).
  Tri triangle_satisfies_within(const Triangle3& v, double res, const CrmrInfo& info,
                                const Motion& m) const override {
    return !m.zero() && g_.moves_with_camera() ? Tri::kUnknown
                                               : to_tri(triangle_satisfies(v, res, info));
  }
  Tri region_satisfies_within(const Box3& box, double min_res, const CrmrInfo& info,
                              const Motion& m) const override {
    return !m.zero() && g_.moves_with_camera() ? Tri::kUnknown
                                               : to_tri(region_satisfies(box, min_res, info));
  }
  const ObjectSpaceFunction& function() const { return g_; }

 private:
  ObjectSpaceFunction g_;
};

/// A volume of significance (Brown 4.6.2, 3-D): a ball with a resolution level, either Gaussian
/// (level * exp(-d^2 / (2 radius^2)), d = distance to the centre) or thresholded (level within
/// the closed ball, 0 outside).
struct Volume {
  Vec3 center{0.0};
  double radius = 1.0;
  double level = 0.0;
  bool gaussian = true;
  /// The largest value over points at distance >= d from the centre.
  double at_distance(double d) const;
};

/// g3 = max over volumes, evaluated in space: t satisfies it when its resolution is >= g3(p) for
/// every p of the triangle itself (the triangle's nearest point to each centre decides, exactly);
/// a region when min_res >= g3 anywhere in its box. For 3-D meshes, where the 2.5-D g over xy
/// would make every area of interest an infinite vertical cylinder.
class VolumeCriterion final : public SimilarityComponent {
 public:
  explicit VolumeCriterion(std::vector<Volume> volumes) : volumes_(std::move(volumes)) {}
  std::string describe() const override;
  bool triangle_satisfies(const Triangle3& v, double res, const CrmrInfo& info) const override;
  bool region_satisfies(const Box3& box, double min_res, const CrmrInfo& info) const override;
  Tri triangle_satisfies_within(const Triangle3& v, double res, const CrmrInfo& info,
                                const Motion&) const override {
    return to_tri(triangle_satisfies(v, res, info));  // no camera
  }
  Tri region_satisfies_within(const Box3& box, double min_res, const CrmrInfo& info,
                              const Motion&) const override {
    return to_tri(region_satisfies(box, min_res, info));
  }
  /// g3 at a point.
  double value(const Vec3& p) const;

 private:
  std::vector<Volume> volumes_;
};

/// A screen-space area of interest: inside the disc (pixels) the tolerance is `pixel_error`.
struct ScreenAoi {
  Vec2 center_px{0.0};
  double radius_px = 0.0;
  double pixel_error = 0.5;
};

/// Brown 4.6.3 after Hoppe 97 and Lindstrom: the projected size of a region's error must not
/// exceed tau(screen position) pixels. For a region B (a box) and error e (data units):
///   pixels(B, e) = e * s(B) * focal_px / dist(eye, B)
/// where dist is the minimum distance from the eye to B and s(B) bounds the sine of the angle
/// between the error direction (vertical for terrain) and the view ray over B (1 for 3-D).
/// Both are monotone in B, so a bound on a box bounds every region inside it. tau(B) is the
/// smallest tolerance of any screen position B may project to.
class ScreenSpaceCriterion final : public SimilarityComponent {
 public:
  /// `cam` in model coordinates; distances and angles are judged in `frame` (MetricFrame), and
  /// pixel_error_bound and tolerance take regions in that frame.
  ScreenSpaceCriterion(const Camera& cam, double pixel_error, std::optional<ScreenAoi> aoi,
                       bool vertical_error, MetricFrame frame = {})
      : frame_(frame),
        cam_(frame.apply(cam)),
        focal_px_(cam_.focal_px()),
        tau_(pixel_error),
        aoi_(aoi),
        vertical_(vertical_error) {}
  std::string describe() const override;
  bool triangle_satisfies(const Triangle3& v, double res, const CrmrInfo& info) const override;
  bool region_satisfies(const Box3& box, double min_res, const CrmrInfo& info) const override;

  /// With a screen-space area of interest the tolerance depends on where a region projects, which
  /// these do not bound: kUnknown for any motion but none.
  Tri triangle_satisfies_within(const Triangle3& v, double res, const CrmrInfo& info,
                                const Motion& m) const override;
  Tri region_satisfies_within(const Box3& box, double min_res, const CrmrInfo& info,
                              const Motion& m) const override;
  const Camera* camera() const override { return &cam_; }

  double pixel_error_bound(double error, const Box3& region) const;
  double tolerance(const Box3& region) const;
  double tolerance_at(const Vec2& pixel) const;

 private:
  Tri satisfies_within(const Box3& b, double error, const Motion& m) const;  // b in the frame

  MetricFrame frame_;
  Camera cam_;       // in the frame
  double focal_px_;  // cam_.focal_px(), once (a tangent per test otherwise)
  double tau_;
  std::optional<ScreenAoi> aoi_;
  bool vertical_;
};

/// An RCF's camera as a session compares it (RcfOracle::pose): verdicts carry over between RCFs
/// of one signature only (components, tolerances, field of view, viewport, clipping, frame), and
/// the motion between two poses bounds how far their verdicts may differ.
struct RcfPose {
  std::string signature;
  Vec3 eye{0.0};
  std::array<Vec3, 3> basis{Vec3{1, 0, 0}, Vec3{0, 1, 0}, Vec3{0, 0, 1}};  // right, up, forward
  /// A length (the eye's distance to its target, 1 without a camera): a session's verdict kept
  /// for motions up to m holds while the eye moves by at most m and the view turns by m / scale.
  double scale = 1.0;
  /// The motion between two poses: the eye's displacement and the angle of the rotation taking
  /// one basis to the other (both rounded up).
  static Motion between(const RcfPose& a, const RcfPose& b);
  /// The least m such that the motion to `to` is within m of this pose (delta <= m, theta <=
  /// m / scale): what a margin kept at this pose must reach to still hold at `to`.
  double needed_to(const RcfPose& to) const;
};

/// What extraction asks of an RCF (Brown 4.6, Fig. 4.19): IsFiner, IsCompletelyFiner, and the
/// conservative test on an index entry. Rcf (below) composes them from components; a session's
/// common-denominator RCF (Brown Theorem 6.4.1) combines two.
class RcfOracle {
 public:
  virtual ~RcfOracle() = default;
  virtual bool is_finer(const OpView& op, const OpSource& source) const = 0;
  virtual bool is_completely_finer(const OpView& op, const OpSource& source) const = 0;
  /// Conservative: true only if every op whose box lies in `box`, whose ROI lies in `roi` and
  /// whose birth_res >= min_birth_res is completely finer (an index entry or subtree: Rcf judges
  /// by the boxes; a query about heights, smr/query/region.h, by the ROIs).
  virtual bool region_completely_finer(const Box3& box, const Box3& roi, double min_birth_res,
                                       const CrmrInfo& info) const = 0;

  /// For verdicts kept from one camera to the next (Session): the camera the RCF judges by and
  /// all else it depends on, or nullopt when it cannot bound its verdicts under motion.
  virtual std::optional<RcfPose> pose() const { return std::nullopt; }
  /// IsFiner / IsCompletelyFiner for every camera within `m` of pose()'s.
  virtual Tri finer_within(const OpView& op, const OpSource& source, const Motion& m) const {
    return m.zero() ? to_tri(is_finer(op, source)) : Tri::kUnknown;
  }
  virtual Tri completely_finer_within(const OpView& op, const OpSource& source,
                                      const Motion& m) const {
    return m.zero() ? to_tri(is_completely_finer(op, source)) : Tri::kUnknown;
  }
  /// region_completely_finer for every camera within `m`: true only if it holds for them all.
  virtual bool region_completely_finer_within(const Box3& box, const Box3& roi,
                                              double min_birth_res, const CrmrInfo& info,
                                              const Motion& m) const {
    return m.zero() && region_completely_finer(box, roi, min_birth_res, info);
  }
};

/// An RCF whose index test holds for every camera within a motion of `rcf`'s (the other tests
/// are rcf's): an index query with it finds the candidates of every such camera at once.
class MovedIndexRcf final : public RcfOracle {
 public:
  MovedIndexRcf(const RcfOracle& rcf, Motion m) : rcf_(rcf), m_(m) {}
  bool is_finer(const OpView& op, const OpSource& source) const override {
    return rcf_.is_finer(op, source);
  }
  bool is_completely_finer(const OpView& op, const OpSource& source) const override {
    return rcf_.is_completely_finer(op, source);
  }
  bool region_completely_finer(const Box3& box, const Box3& roi, double min_birth_res,
                               const CrmrInfo& info) const override {
    return rcf_.region_completely_finer_within(box, roi, min_birth_res, info, m_);
  }

 private:
  const RcfOracle& rcf_;
  Motion m_;
};

class Rcf final : public RcfOracle {
 public:
  void add(std::shared_ptr<const CullingComponent> c) { culling_.push_back(std::move(c)); }
  void add(std::shared_ptr<const SimilarityComponent> s) { similarity_.push_back(std::move(s)); }

  /// Every triangle of F(op) that is not final or void satisfies every similarity component at
  /// its death_res, or op is culled.
  bool is_finer(const OpView& op, const OpSource& source) const override;
  /// op is not R^0, and op is culled or every non-void triangle t of PreF(op) is culled (its own
  /// corners) or satisfies every component at birth_res(op). Judging PreF triangle by
  /// triangle, like IsFiner judges F, makes "all parents finer => completely finer" exact, which
  /// Lemma 5.2.1 (reduced extraction) needs.
  bool is_completely_finer(const OpView& op, const OpSource& source) const override;
  /// Conservative test for an index entry: true only if every op whose box lies in `box` and whose
  /// birth_res >= min_birth_res is completely finer than the RCF.
  bool region_completely_finer(const Box3& box, const Box3& roi, double min_birth_res,
                               const CrmrInfo& info) const override;
  /// Every camera-dependent component's camera (they must be one), and describe() with the
  /// camera's intrinsics as the signature; nullopt when the components' cameras differ.
  std::optional<RcfPose> pose() const override;
  Tri finer_within(const OpView& op, const OpSource& source, const Motion& m) const override;
  Tri completely_finer_within(const OpView& op, const OpSource& source,
                              const Motion& m) const override;
  bool region_completely_finer_within(const Box3& box, const Box3& roi, double min_birth_res,
                                      const CrmrInfo& info, const Motion& m) const override;

  const std::vector<std::shared_ptr<const CullingComponent>>& culling() const { return culling_; }
  const std::vector<std::shared_ptr<const SimilarityComponent>>& similarity() const {
    return similarity_;
  }
  std::string describe() const;

 private:
  Tri culled_within(const OpView& op, const Motion& m) const;
  Tri triangle_within(const Triangle3& v, double res, const CrmrInfo& info, const Motion& m) const;

  std::vector<std::shared_ptr<const CullingComponent>> culling_;
  std::vector<std::shared_ptr<const SimilarityComponent>> similarity_;
};

/// Brown Theorem 6.4.1's "common denominator" of two RCFs: an op is finer (completely finer) than
/// it exactly when it is finer (completely finer) than both. A session's X after its coarsening
/// step is the minimal-surface X of this RCF for the old and the new RCF.
class CommonDenominatorRcf final : public RcfOracle {
 public:
  CommonDenominatorRcf(const RcfOracle& a, const RcfOracle& b) : a_(a), b_(b) {}
  bool is_finer(const OpView& op, const OpSource& source) const override {
    return a_.is_finer(op, source) && b_.is_finer(op, source);
  }
  bool is_completely_finer(const OpView& op, const OpSource& source) const override {
    return a_.is_completely_finer(op, source) && b_.is_completely_finer(op, source);
  }
  bool region_completely_finer(const Box3& box, const Box3& roi, double min_birth_res,
                               const CrmrInfo& info) const override {
    return a_.region_completely_finer(box, roi, min_birth_res, info) &&
           b_.region_completely_finer(box, roi, min_birth_res, info);
  }

 private:
  const RcfOracle& a_;
  const RcfOracle& b_;
};

/// Corners of a triangle of F(op) or PreF(op).
Triangle3 corners(const OpView& op, const FragmentTriangle& t);
Triangle3 corners(const OpView& op, const PreTriangle& t);
Box3 triangle_box(const Triangle3& v);

}  // namespace smr
