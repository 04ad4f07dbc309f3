// The spread of RCFs every extraction test runs (see rcf_spread.h).
#include "tests/support/rcf_spread.h"

#include <algorithm>

namespace smr::test {

// RCFs placed relative to the dataset's bounds, so they mean the same on every DEM.
Camera test_camera(const Vec3& eye, const Vec3& target) {
  Camera cam;
  cam.eye = eye;
  cam.target = target;
  cam.fov_y_deg = 50;
  cam.viewport_w = 800;
  cam.viewport_h = 600;
  return cam;
}

std::vector<NamedSpec> rcf_spread(const CrmrInfo& info) {
  const Box3& b = info.bounds;
  const Vec3 c = b.center();
  const double w = b.hi.x - b.lo.x, h = b.hi.y - b.lo.y, zr = std::max(1.0, b.hi.z - b.lo.z);
  const auto camera = test_camera;
  // Oblique from the south-west corner, above the highest point; looking north past the domain
  // (part of it out of view); straight down from above.
  const Camera oblique =
      camera({b.lo.x - 0.2 * w, b.lo.y - 0.2 * h, b.hi.z + 0.5 * zr}, {c.x, c.y, b.lo.z});
  const Camera aside =
      camera({c.x, b.lo.y + 0.3 * h, b.hi.z + 0.2 * zr}, {c.x + 0.3 * w, b.hi.y + h, b.lo.z});
  const Camera down = camera({c.x, c.y, b.hi.z + 2 * zr}, {c.x, c.y + 1e-3 * h, b.lo.z});

  std::vector<NamedSpec> out;
  for (double f : {0.0, 0.25, 0.5, 0.75, 0.9, 1.0}) {
    RcfSpec s;
    s.floor = f;
    out.push_back({"floor" + std::to_string(int(f * 100)), s});
  }
  {
    RcfSpec s;
    s.floor = 0.3;
    s.aois.push_back({c.x, c.y, 0.1 * w, 0.95});
    s.aois.push_back({b.lo.x + 0.2 * w, b.lo.y + 0.7 * h, 0.05 * w, 0.99});
    out.push_back({"aois", s});
  }
  {
    RcfSpec s;
    s.discs.push_back({b.lo.x + 0.7 * w, b.lo.y + 0.3 * h, 0.15 * w, 0.9});
    s.aois.push_back({c.x, c.y, 0.05 * w, 0.97});
    out.push_back({"disc", s});
  }
  {
    RcfSpec s;
    s.floor = 0.2;
    s.critical_level = 0.85;
    s.critical_relief = 0.05 * zr;
    out.push_back({"critical", s});
  }
  for (double px : {0.5, 1.0, 2.0, 4.0, 8.0}) {
    RcfSpec s;
    s.camera = oblique;
    s.pixel_error = px;
    out.push_back({"oblique_px" + std::to_string(int(px * 10)), s});
  }
  {
    RcfSpec s;
    s.camera = oblique;
    s.pixel_error = 2.0;
    s.cull = false;
    out.push_back({"oblique_nocull", s});
  }
  {
    RcfSpec s;
    s.camera = aside;
    s.pixel_error = 4.0;
    s.screen_aoi = ScreenAoi{{400, 300}, 120, 0.5};
    out.push_back({"aside_screen_aoi", s});
  }
  {
    RcfSpec s;
    s.camera = down;
    s.pixel_error = 1.0;
    out.push_back({"down", s});
  }
  {
    RcfSpec s;
    s.camera = oblique;
    s.floor = 0.1;
    s.frustum_level = 0.6;
    s.centre_cone = std::pair{8.0, 0.92};
    s.aois.push_back({oblique.eye.x + 0.3 * w, oblique.eye.y + 0.3 * h, 0.1 * w, 0.99});
    out.push_back({"frustum_cone", s});
  }
  {
    RcfSpec s;
    s.camera = aside;
    s.cull = false;
    s.frustum_level = 0.7;
    s.critical_level = 0.8;
    s.critical_relief = 0.05 * zr;
    out.push_back({"frustum_critical_nocull", s});
  }
  return out;
}

}  // namespace smr::test
