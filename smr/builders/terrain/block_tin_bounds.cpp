// Error bounds of the block TIN builder's triangles; block_tin_bounds.h describes them.
#include "smr/builders/terrain/block_tin_bounds.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "smr/builders/terrain/triangle_rows.h"

namespace smr::block_tin {
namespace {

/// The samples z[xl..xr] of one row against the plane pa * col + zrow: the largest
/// z - plane into up, plane - z into down, the range into lo, hi. Four columns a step in SSE
/// lanes (GCC vector extensions), so the max chains do not wait on each other. Each lane does
/// the scalar loop's arithmetic (column numbers are exact doubles), and max and min are exact
/// in any order, so the result is the scalar loop's to the bit.
void scan_row(const float* z, std::int64_t xl, std::int64_t xr, double pa, double zrow, double& up,
              double& down, float& lo, float& hi) {
  using V2d = double __attribute__((vector_size(16)));
  using V4f = float __attribute__((vector_size(16)));
  V2d u01 = {up, up}, u23 = u01, d01 = {down, down}, d23 = d01;
  V4f l4 = {lo, lo, lo, lo}, h4 = {hi, hi, hi, hi};
  const V2d slope = {pa, pa}, base = {zrow, zrow}, step = {4.0, 4.0};
  V2d c01 = {double(xl), double(xl + 1)}, c23 = {double(xl + 2), double(xl + 3)};
  std::int64_t col = xl;
  for (; col + 3 <= xr; col += 4) {
    V4f zf;
    std::memcpy(&zf, z + col, sizeof zf);
    l4 = zf < l4 ? zf : l4;
    h4 = zf > h4 ? zf : h4;
    const V2d z01 = {double(zf[0]), double(zf[1])}, z23 = {double(zf[2]), double(zf[3])};
    const V2d e01 = z01 - (slope * c01 + base), e23 = z23 - (slope * c23 + base);
    u01 = e01 > u01 ? e01 : u01;
    u23 = e23 > u23 ? e23 : u23;
    d01 = -e01 > d01 ? -e01 : d01;
    d23 = -e23 > d23 ? -e23 : d23;
    c01 += step;
    c23 += step;
  }
  up = std::max({up, u01[0], u01[1], u23[0], u23[1]});
  down = std::max({down, d01[0], d01[1], d23[0], d23[1]});
  lo = std::min({lo, l4[0], l4[1], l4[2], l4[3]});
  hi = std::max({hi, h4[0], h4[1], h4[2], h4[3]});
  for (; col <= xr; ++col) {
    const double e = double(z[col]) - (pa * double(col) + zrow);
    up = std::max(up, e);
    down = std::max(down, -e);
    lo = std::min(lo, z[col]);
    hi = std::max(hi, z[col]);
  }
}

}  // namespace

TriBound exact_bound(Mesh& mesh, const std::array<std::uint32_t, 3>& v, const Heightfield& w,
                     int c0, int r0, bool outward, double limit) {
  const MVert &a = mesh.verts[v[0]], &b = mesh.verts[v[1]], &c = mesh.verts[v[2]];
  const Plane pl(a, b, c);
  TriBound tb;
  tb.zlo = std::min({a.z, b.z, c.z});
  tb.zhi = std::max({a.z, b.z, c.z});
  const std::int64_t x[3] = {a.col - c0, b.col - c0, c.col - c0};
  const std::int64_t y[3] = {a.row - r0, b.row - r0, c.row - r0};
  build::TriangleRows rows(x, y);
  const double pa = pl.a, pc = pl.c + pl.a * c0 + pl.b * r0;  // the plane in window coordinates
  double up = 0.0, down = 0.0;
  float lo = tb.zlo, hi = tb.zhi;
  for (std::int64_t row = rows.ymin(); row <= rows.ymax(); ++row) {
    std::int64_t xl, xr;
    rows.next(xl, xr);
    if (xl > xr) continue;
    const std::size_t base = static_cast<std::size_t>(row) * static_cast<std::size_t>(w.width);
    if (w.has_nodata()) {
      for (std::int64_t col = xl; col <= xr; ++col) {
        if (w.valid[base + static_cast<std::size_t>(col)] == 0) {
          tb.up = kInfeasible;
          return tb;
        }
      }
    }
    mesh.scanned += static_cast<std::uint64_t>(xr - xl + 1);
    const float* z = w.z.data() + base;
    scan_row(z, xl, xr, pa, pl.b * double(row) + pc, up, down, lo, hi);
    if (up > limit || down > limit) break;
  }
  tb.up = up;
  tb.down = down;
  tb.zlo = lo;
  tb.zhi = hi;
  if (outward) {
    tb.up = tb.up <= mesh.tol ? 0.0 : tb.up + mesh.tol;
    tb.down = tb.down <= mesh.tol ? 0.0 : tb.down + mesh.tol;
  }
  return tb;
}

std::pair<int, int> worst_sample(std::span<const MVert> verts,
                                 const std::array<std::uint32_t, 3>& v, const Heightfield& w,
                                 int c0, int r0) {
  const MVert &a = verts[v[0]], &b = verts[v[1]], &c = verts[v[2]];
  const Plane pl(a, b, c);
  const std::int64_t x[3] = {a.col - c0, b.col - c0, c.col - c0};
  const std::int64_t y[3] = {a.row - r0, b.row - r0, c.row - r0};
  build::TriangleRows rows(x, y);
  double best = -1.0;
  std::pair<int, int> at{a.col, a.row};
  for (std::int64_t row = rows.ymin(); row <= rows.ymax(); ++row) {
    std::int64_t xl, xr;
    rows.next(xl, xr);
    for (std::int64_t col = xl; col <= xr; ++col) {
      const double e =
          std::abs(double(w.at(int(col), int(row))) - pl.at(double(col + c0), double(row + r0)));
      if (e > best) {
        best = e;
        at = {int(col + c0), int(row + r0)};
      }
    }
  }
  return at;
}

TriBound overlay_bound(const Mesh& mesh, const std::array<std::uint32_t, 3>& nt,
                       std::span<const std::uint32_t> star, ClipScratch& scratch) {
  const std::vector<MVert>& verts = mesh.verts;
  const MVert &a = verts[nt[0]], &b = verts[nt[1]], &c = verts[nt[2]];
  const Plane pn(a, b, c);
  TriBound tb;
  const float vlo = std::min({a.z, b.z, c.z}), vhi = std::max({a.z, b.z, c.z});
  tb.zlo = vlo;
  tb.zhi = vhi;
  std::vector<std::array<double, 2>>& poly = scratch.a;
  std::vector<std::array<double, 2>>& next = scratch.b;
  for (std::uint32_t ot : star) {
    const MTri& o = mesh.tris[ot];
    poly = {{double(a.col), double(a.row)},
            {double(b.col), double(b.row)},
            {double(c.col), double(c.row)}};
    for (int k = 0; k < 3 && !poly.empty(); ++k) {  // clip by o's edge k (keep its left side)
      const MVert &e0 = verts[o.v[k]], &e1 = verts[o.v[(k + 1) % 3]];
      const double ex = e1.col - e0.col, ey = e1.row - e0.row;
      auto side = [&](const std::array<double, 2>& q) {
        return ex * (q[1] - e0.row) - ey * (q[0] - e0.col);
      };
      next.clear();
      for (std::size_t i = 0; i < poly.size(); ++i) {
        const auto& q0 = poly[i];
        const auto& q1 = poly[(i + 1) % poly.size()];
        const double s0 = side(q0), s1 = side(q1);
        if (s0 >= 0) next.push_back(q0);
        if ((s0 > 0 && s1 < 0) || (s0 < 0 && s1 > 0)) {
          const double t = s0 / (s0 - s1);
          next.push_back({q0[0] + t * (q1[0] - q0[0]), q0[1] + t * (q1[1] - q0[1])});
        }
      }
      poly.swap(next);
    }
    if (poly.size() < 3) continue;
    const Plane po(verts[o.v[0]], verts[o.v[1]], verts[o.v[2]]);
    double above = 0.0, below = 0.0;  // largest o - new and new - o over the overlap
    for (const auto& q : poly) {
      const double d = po.at(q[0], q[1]) - pn.at(q[0], q[1]);
      above = std::max(above, d);
      below = std::max(below, -d);
    }
    tb.up = std::max(tb.up, o.bound.up + above);
    tb.down = std::max(tb.down, o.bound.down + below);
    tb.zlo = std::min(tb.zlo, o.bound.zlo);
    tb.zhi = std::max(tb.zhi, o.bound.zhi);
  }
  tb.up = std::min(tb.up, double(tb.zhi) - double(vlo)) + mesh.tol;
  tb.down = std::min(tb.down, double(vhi) - double(tb.zlo)) + mesh.tol;
  return tb;
}

}  // namespace smr::block_tin
