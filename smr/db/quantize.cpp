#include "smr/db/quantize.h"

#include <algorithm>
#include <cmath>

#include <glm/geometric.hpp>
#include <limits>
#include <string>

#include "base/error.h"

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

namespace {

// 3-D meshes: one power-of-two step on every axis (auto: 2^-24 of P, the largest extent rounded
// up to a power of two): float32 coordinates of magnitude P/2 or more are exact (their spacing
// is the step), the rest move by at most 2^-25 P, float32's own rounding at the extent; at most
// 2^24 steps per axis.
QuantGrid choose_mesh_grid(const CrmrInfo& info, double step) {
  QuantGrid g;
  if (info.bounds.empty()) throw_input("the mesh has no vertices");
  const Vec3 lo = info.bounds.lo, hi = info.bounds.hi;
  for (int k = 0; k < 3; ++k) {
    if (!(std::isfinite(lo[k]) && std::isfinite(hi[k])))
      throw_input("mesh coordinates are not finite");
  }
  const double extent = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z, 1e-30});
  if (step < 0.0 || !std::isfinite(step)) throw_input("the quantum must be a positive number");
  if (step == 0.0) step = std::exp2(std::ceil(std::log2(extent)) - 24);
  if (extent / step > double(1 << 30)) {
    throw_input("quantum " + std::to_string(step) + " is too fine for a mesh extent of " +
                std::to_string(extent) + " (at most 2^30 steps)");
  }
  g.step = Vec3(step);
  for (int k = 0; k < 3; ++k) g.origin[k] = std::floor(lo[k] / step) * step;
  return g;
}

}  // namespace

double error_z_quantum(double max_error) {
  if (!(max_error > 0.0) || !std::isfinite(max_error)) return 0.0;
  return std::ldexp(1.0, std::ilogb(max_error) - 5);  // exact: 2^floor(log2 e) / 32
}

TerrainErrorSplit split_terrain_error(double max_error, double z_quantum, bool heights_on_step) {
  const double q = z_quantum == 0.0 ? error_z_quantum(max_error) : 0.0;
  return {heights_on_step ? max_error : max_error - q / 2.0, q};
}

QuantGrid choose_grid(const CrmrInfo& info, double z_quantum, double error_quantum) {
  if (info.kind == ModelKind::kMesh3d) return choose_mesh_grid(info, z_quantum);
  QuantGrid g;
  g.origin = {info.georef.x0, info.georef.y0, 0.0};
  g.step = {info.georef.dx, info.georef.dy, 1.0};
  const double lo = info.bounds.empty() ? 0.0 : info.bounds.lo.z;
  const double hi = info.bounds.empty() ? 0.0 : info.bounds.hi.z;
  if (!(std::isfinite(lo) && std::isfinite(hi))) throw_input("model heights are not finite");
  if (z_quantum < 0.0 || !std::isfinite(z_quantum))
    throw_input("z quantum must be a positive number");
  if (z_quantum == 0.0) {
    const double range = std::max(hi - lo, 1e-3);
    // Built to an error: its step, unless the range needs more than 2^30 of them (the model
    // then passes the error by up to half of the coarser step); else range / 2^24.
    z_quantum =
        error_quantum > 0.0
            ? std::max(error_quantum, std::exp2(std::ceil(std::log2(range / double(1 << 30)))))
            : std::exp2(std::floor(std::log2(range / double(1 << 24))));
  }
  if ((hi - lo) / z_quantum > double(1 << 30)) {
    throw_input("z quantum " + std::to_string(z_quantum) + " is too fine for a height range of " +
                std::to_string(hi - lo) + " (at most 2^30 steps)");
  }
  g.step.z = z_quantum;
  g.origin.z = std::floor(lo / z_quantum) * z_quantum;
  return g;
}

double snap_vertices(Op& op, const QuantGrid& grid, const CrmrInfo& model) {
  double shift = 0.0;
  for (Vertex& v : op.vertices) {
    const auto q = grid.quantize(v.p);
    const Vec3 p = grid.dequantize(q);
    shift = std::max(shift, glm::length(p - v.p));
    v.p = p;
    if (model.kind != ModelKind::kTerrain) continue;
    if (q[0] < 0 || q[0] >= model.grid_width || q[1] < 0)
      throw_internal("terrain vertex " + std::to_string(v.id.value) + " is off the DEM's grid");
    v.id = VertexId(std::uint64_t(q[1]) * std::uint64_t(model.grid_width) + std::uint64_t(q[0]));
  }
  return shift;
}

double stored_resolution(double res) {
  float f = static_cast<float>(res);
  if (double(f) > res) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
  return f;
}

double stored_op_error(const CrmrInfo& info, double birth_res) {
  return std::min(info.err0, error_at(info, birth_res));
}

int roi_shift(double error, double step) {
  const double units = error / 8.0 / step;
  if (!(units >= 2.0)) return 0;  // also NaN
  return std::min(24, std::ilogb(units));
}

Box3 stored_roi(const Box3& roi, const Box3& box, double error, const QuantGrid& grid) {
  const auto blo = grid.quantize(box.lo), bhi = grid.quantize(box.hi);
  auto rlo = grid.quantize(roi.lo), rhi = grid.quantize(roi.hi);
  for (int k = 0; k < 3; ++k) {
    const int s = roi_shift(error, grid.step[k]);
    const std::int64_t unit = std::int64_t{1} << s;
    const std::int64_t below = (std::int64_t(blo[k]) - rlo[k] + unit - 1) / unit * unit;
    const std::int64_t above = (std::int64_t(rhi[k]) - bhi[k] + unit - 1) / unit * unit;
    if (below < 0 || above < 0) throw_internal("stored_roi: an ROI that does not hold its box");
    const std::int64_t lo = std::int64_t(blo[k]) - below, hi = std::int64_t(bhi[k]) + above;
    constexpr std::int64_t kMax = std::numeric_limits<std::int32_t>::max();
    if (lo < -kMax || hi > kMax) throw_input("an op's region of influence leaves the grid");
    rlo[k] = std::int32_t(lo);
    rhi[k] = std::int32_t(hi);
  }
  return Box3{grid.dequantize(rlo), grid.dequantize(rhi)};
}

void round_for_storage(Op& op) {
  op.birth_res = stored_resolution(op.birth_res);
  for (FragmentTriangle& t : op.fragment) t.death_res = stored_resolution(t.death_res);
}

double quantize(Crmr& crmr, const QuantGrid& grid) {
  double shift = 0.0;
  for (Op& op : crmr.ops) shift = std::max(shift, snap_vertices(op, grid, crmr.header));
  crmr.header.bounds = Box3{};
  for (Op& op : crmr.ops) {
    for (const Vertex& v : op.vertices) crmr.header.bounds.add(v.p);
    compute_op_bounds(op);
    round_for_storage(op);
  }
  compute_rois(crmr);
  crmr.header.err0 += shift;
  crmr.header.err_final += shift;
  for (Op& op : crmr.ops) op.error = stored_op_error(crmr.header, op.birth_res);
  // ROIs as pages store them (stored_roi), children first (they have larger ids): compute_rois'
  // rule with each op's ROI rounded before its parents take it in.
  for (std::uint64_t i = crmr.ops.size(); i-- > 0;) {
    Op& op = crmr.ops[i];
    Box3 roi = op.box;
    for (OpId c : op.children) roi.add(crmr.ops.at(c.value).roi);
    op.roi = stored_roi(roi, op.box, op.error, grid);
  }
  return shift;
}

}  // namespace smr
