// A pinhole camera: view frustum planes, projection to pixels, and the geometric bounds the RCF
// needs (Brown 4.6.1: bounding-sphere frustum test, normal-cone back-face test; 4.6.3 projection).
#pragma once

#include <array>
#include <optional>

#include "smr/core/geometry.h"
#include "smr/core/heightfield.h"

namespace smr {

struct Plane {
  Vec3 n{0.0};  // unit normal pointing into the frustum
  double d = 0.0;
  double signed_distance(const Vec3& p) const { return n.x * p.x + n.y * p.y + n.z * p.z + d; }
};

struct Camera {
  Vec3 eye{0.0};
  Vec3 target{0.0, 1.0, 0.0};
  Vec3 up{0.0, 0.0, 1.0};
  double fov_y_deg = 60.0;  // vertical field of view
  int viewport_w = 1024, viewport_h = 768;
  double near_distance = 0.0;  // along the view direction
  double far_distance = 0.0;   // 0 = no far plane

  /// Throws smr::Error (naming the parameter) on a degenerate camera.
  void validate() const;

  Vec3 forward() const;
  Vec3 right() const;
  Vec3 true_up() const;
  /// Pixels per unit of tan(angle) from the view axis: (viewport_h / 2) / tan(fov_y / 2).
  double focal_px() const;
  double tan_half_x() const;
  double tan_half_y() const;
  /// Pixel coordinates (x right, y down) of p, or nullopt when p is not in front of the eye.
  std::optional<Vec2> project(const Vec3& p) const;
  /// Frustum planes: left, right, bottom, top, near, and far when far_distance > 0.
  std::array<Plane, 6> planes() const;
  int plane_count() const { return far_distance > 0.0 ? 6 : 5; }
};

/// Model coordinates to a frame where a camera's distances and angles mean something (metres on
/// every axis). The identity for models in one unit; for a geographic raster (x, y degrees of
/// longitude and latitude, z metres) the local equirectangular map about the model's centre
/// (x0, y0): x' = (x - x0) mx, y' = (y - y0) my with mx, my the WGS 84 metres per degree at
/// latitude y0 (metres_per_degree); over a degree of latitude its x scale is off by < 2 %. An axis
/// scaling and shift: boxes map to boxes and triangles to triangles exactly, so every camera test
/// judges the mapped geometry as it would metric data.
struct MetricFrame {
  Vec2 origin{0.0};
  double kx = 1.0, ky = 1.0;  // metres per model unit along x and y (z is metres already)

  static MetricFrame of(const Georef& georef, const Box3& bounds);
  bool identity() const { return kx == 1.0 && ky == 1.0 && origin == Vec2(0.0); }
  Vec3 apply(const Vec3& p) const { return {(p.x - origin.x) * kx, (p.y - origin.y) * ky, p.z}; }
  Vec2 apply(const Vec2& p) const { return {(p.x - origin.x) * kx, (p.y - origin.y) * ky}; }
  Box3 apply(const Box3& b) const { return {apply(b.lo), apply(b.hi)}; }
  /// A sphere holding the image of `s` (the scaling is not uniform).
  Sphere apply(const Sphere& s) const;
  Triangle3 apply(const Triangle3& t) const { return {apply(t[0]), apply(t[1]), apply(t[2])}; }
  /// The camera placed at the images of its eye and target (up, field of view, viewport and
  /// clipping distances as given: they are metres and angles already).
  Camera apply(const Camera& c) const;
};

/// A camera's frustum planes, computed once (Camera::planes() works them out on every call).
struct Frustum {
  explicit Frustum(const Camera& cam) : planes(cam.planes()), count(cam.plane_count()) {}
  std::array<Plane, 6> planes;
  int count;
};
/// True when the whole sphere lies outside one frustum plane.
bool sphere_outside(const Frustum& f, const Sphere& s);
bool sphere_outside(const Camera& cam, const Sphere& s);
/// True when all eight corners of the box lie outside one frustum plane.
bool box_outside(const Frustum& f, const Box3& b);
bool box_outside(const Camera& cam, const Box3& b);
/// True when every normal of the cone faces away from the eye at every point of the sphere:
/// angle(axis, c - eye) + cone half-angle + asin(r / |c - eye|) < pi/2 (Hoppe 97's test, exact).
bool backfacing(const Camera& cam, const Sphere& s, const NormalCone& cone);
/// Minimum distance from the eye to the box (0 when the eye is inside).
double distance_to_box(const Vec3& eye, const Box3& b);
/// Upper bound of sin(angle between `dir` = +z and p - eye) over points p of the box: how much of
/// a vertical error can face the viewer. Monotone: a larger box never gives a smaller bound.
double max_sin_vertical(const Vec3& eye, const Box3& b);

}  // namespace smr
