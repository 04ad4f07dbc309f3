#include "smr/db/quantize.h"

#include <cmath>

#include <glm/geometric.hpp>
#include <limits>
#include <string>

#include "storage/error.h"

namespace smr {

std::array<std::int32_t, 3> QuantGrid::quantize(const Vec3& p) const {
  std::array<std::int32_t, 3> q{};
  for (int k = 0; k < 3; ++k) {
    const double v = std::round((p[k] - origin[k]) / step[k]);
    if (!(std::abs(v) <= double(std::numeric_limits<std::int32_t>::max()))) {
      throw_input("vertex coordinate " + std::to_string(p[k]) +
                  " is outside the quantization grid (axis " + std::to_string(k) + ")");
    }
    q[k] = static_cast<std::int32_t>(v);
  }
  return q;
}

QuantGrid choose_grid(const CrmrInfo& info, double z_step) {
  QuantGrid g;
  if (info.kind != ModelKind::kTerrain) throw_internal("quantization: only terrains so far");
  g.origin = {info.georef.x0, info.georef.y0, 0.0};
  g.step = {info.georef.dx, info.georef.dy, 1.0};
  const double lo = info.bounds.empty() ? 0.0 : info.bounds.lo.z;
  const double hi = info.bounds.empty() ? 0.0 : info.bounds.hi.z;
  if (!(std::isfinite(lo) && std::isfinite(hi))) throw_input("model heights are not finite");
  if (z_step < 0.0 || !std::isfinite(z_step)) throw_input("z quantum must be a positive number");
  if (z_step == 0.0) {
    const double range = std::max(hi - lo, 1e-3);
    z_step = std::exp2(std::floor(std::log2(range / double(1 << 24))));
  }
  if ((hi - lo) / z_step > double(1 << 30)) {
    throw_input("z quantum " + std::to_string(z_step) + " is too fine for a height range of " +
                std::to_string(hi - lo) + " (at most 2^30 steps)");
  }
  g.step.z = z_step;
  g.origin.z = std::floor(lo / z_step) * z_step;
  return g;
}

double quantize(Crmr& crmr, const QuantGrid& grid) {
  double shift = 0.0;
  for (Op& op : crmr.ops) {
    for (Vertex& v : op.vertices) {
      const Vec3 q = grid.dequantize(grid.quantize(v.p));
      shift = std::max(shift, glm::length(q - v.p));
      v.p = q;
    }
  }
  crmr.header.bounds = Box3{};
  for (Op& op : crmr.ops) {
    for (const Vertex& v : op.vertices) crmr.header.bounds.add(v.p);
    compute_op_bounds(op);
    op.error += shift;
  }
  compute_rois(crmr);
  crmr.header.err0 += shift;
  crmr.header.err_final += shift;
  return shift;
}

}  // namespace smr
