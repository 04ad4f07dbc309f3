// The records the block TIN builder's passes share (block_tin.h describes the method): the
// block grid and the settings the survey fixes (Setup), the mesh M^m and every triangle made
// from it by vertex removal (Mesh), and the exact predicates on grid points.
//
// Geometry is exact where it decides topology: vertices sit on integer grid positions, so the
// orientation and in-circle tests (Guibas & Stolfi 1985, "Primitives for the manipulation of
// general subdivisions and the computation of Voronoi diagrams") are evaluated exactly in 64-
// and 128-bit integers. Errors are doubles, rounded outward by the DEM's exact tolerance.
#pragma once

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <limits>
#include <vector>

#include "smr/builders/terrain/block_tin.h"
#include "smr/core/chunked.h"
#include "smr/core/clock.h"
#include "smr/core/id_map.h"

namespace smr::block_tin {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
constexpr double kInfeasible = std::numeric_limits<double>::infinity();

struct MVert {
  std::int32_t col = 0, row = 0;
  float z = 0.0f;
  std::uint32_t tri = kNone;  // a live triangle having this vertex
  bool sticky = false;        // a corner of a void triangle: never removed
};

/// One-sided bounds of the source against a triangle's plane: source - plane <= up and
/// plane - source <= down over the triangle; zlo <= source <= zhi there. Signed bounds combine
/// across an overlay much more tightly than |source - plane|: the largest plane difference in
/// one direction adds to one side only.
struct TriBound {
  double up = 0.0, down = 0.0;
  float zlo = 0.0f, zhi = 0.0f;
  double err() const { return std::max(up, down); }
};

struct MTri {
  std::array<std::uint32_t, 3> v{};                       // counter-clockwise in grid space
  std::array<std::uint32_t, 3> nbr{kNone, kNone, kNone};  // across edge k = (v[k], v[k+1])
  TriBound bound;                   // of the source against the triangle's plane
  std::uint32_t creator = kNone;    // removal whose hole it fills; kNone = M^m
  std::uint32_t destroyer = kNone;  // removal whose star it is in; kNone = alive
  bool is_void = false;
  bool copied = false;  // handed to a level-0 block while leaves were still being merged
};

struct Removal {
  std::uint32_t vertex = 0;
  std::uint32_t star_begin = 0, star_end = 0;  // into Mesh::star_ids, counter-clockwise
  std::uint32_t new_begin = 0, new_end = 0;    // triangle ids (consecutive)
  double err = 0.0;                            // the largest error of the hole's triangles
};

inline std::int64_t orient(const MVert& a, const MVert& b, const MVert& c) {
  return std::int64_t(b.col - a.col) * (c.row - a.row) -
         std::int64_t(b.row - a.row) * (c.col - a.col);
}

__extension__ using Int128 = __int128;  // exact in-circle on grid coordinates up to 2^30

/// > 0 iff d lies strictly inside the circle through the counter-clockwise a, b, c.
inline bool in_circle(const MVert& a, const MVert& b, const MVert& c, const MVert& d) {
  const Int128 adx = a.col - d.col, ady = a.row - d.row, bdx = b.col - d.col, bdy = b.row - d.row,
               cdx = c.col - d.col, cdy = c.row - d.row;
  const Int128 det = (adx * adx + ady * ady) * (bdx * cdy - cdx * bdy) +
                     (bdx * bdx + bdy * bdy) * (cdx * ady - adx * cdy) +
                     (cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady);
  return det > 0;
}

/// z = a * col + b * row + c through three grid points.
struct Plane {
  double a = 0.0, b = 0.0, c = 0.0;
  Plane(const MVert& p, const MVert& q, const MVert& r) {
    const double x1 = q.col - p.col, y1 = q.row - p.row, x2 = r.col - p.col, y2 = r.row - p.row;
    const double z1 = double(q.z) - p.z, z2 = double(r.z) - p.z;
    const double det = x1 * y2 - x2 * y1;
    a = (z1 * y2 - z2 * y1) / det;
    b = (z2 * x1 - z1 * x2) / det;
    c = double(p.z) - a * p.col - b * p.row;
  }
  double at(double col, double row) const { return a * col + b * row + c; }
};

template <class Tri>
int index_of(const Tri& t, std::uint32_t v) {
  for (int k = 0; k < 3; ++k) {
    if (t.v[k] == v) return k;
  }
  return -1;
}

inline std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
  return (std::uint64_t(a) << 32) | b;
}

/// The grid of blocks: the DEM's W x H samples, leaf blocks of B cells (bw x bh of them), and
/// the levels of 2x2 merges above them (the root is level `levels`, one block).
struct Grid {
  int W = 0, H = 0;
  int B = 256, bw = 1, bh = 1, levels = 0;

  int block_col0(int bx) const { return bx * B; }
  int block_col1(int bx) const { return std::min(bx * B + B, W - 1); }
  int block_row0(int by) const { return by * B; }
  int block_row1(int by) const { return std::min(by * B + B, H - 1); }

  bool is_corner(const MVert& v) const {
    return (v.col == 0 || v.col == W - 1) && (v.row == 0 || v.row == H - 1);
  }
  /// Locked at `level`: on the border line of a level-`level` block (the domain's own boundary
  /// is not a block border: its vertices are removed along it).
  bool locked(const MVert& v, int level) const {
    if (v.sticky || is_corner(v)) return true;
    if (level >= levels) return false;
    const int span = B << level;
    return (v.col % span == 0 && v.col > 0 && v.col < W - 1) ||
           (v.row % span == 0 && v.row > 0 && v.row < H - 1);
  }
  bool on_domain_boundary(const MVert& v) const {
    return v.col == 0 || v.row == 0 || v.col == W - 1 || v.row == H - 1;
  }
  /// Both ends on the same side of the domain: an edge of the domain's boundary.
  bool boundary_edge(const MVert& a, const MVert& b) const {
    return (a.col == 0 && b.col == 0) || (a.row == 0 && b.row == 0) ||
           (a.col == W - 1 && b.col == W - 1) || (a.row == H - 1 && b.row == H - 1);
  }
};

/// What every pass reads and none changes once the survey is done (the workers share it).
struct Setup {
  const RasterWindows& dem;
  const BlockTinOptions& opt;
  Grid grid;
  /// options.exact_window_samples, capped by the memory budget.
  std::uint64_t exact_window_samples = 0;
  /// The error M^m is built to, and the first stage's tolerance (block_tin.cpp's survey).
  double stop_error = 0.0, eps0 = 0.0;
};

inline void report(const BlockTinOptions& opt, double f) {
  if (opt.progress) opt.progress(std::clamp(f, 0.0, 1.0));
}

/// A mesh's build records: the whole mesh's (the calling thread), or a leaf block's or a copied
/// block's, which a worker builds and the calling thread merges into the whole mesh's. Each
/// removal's star and hole are triangles that stay in `tris` (marked destroyer and creator), so
/// the records hold every triangle ever made.
struct Mesh {
  std::vector<MVert> verts;
  Chunked<MTri> tris;
  std::vector<Removal> removals;
  Chunked<std::uint32_t> star_ids;  // the removals' stars
  IdMap<std::uint32_t> open_edges;  // edge -> (tri << 2 | edge): waiting for a neighbour
  double tol = 0.0;                 // errors at most this count as zero (float rounding)
  double err_final = 0.0;           // the largest error of M^m
  std::uint64_t finest_triangles = 0;
  std::uint64_t scanned = 0, plans = 0;  // sample visits of exact bounds; removals planned
};

/// The neighbour o's edge (a, b), if o exists, now borders triangle t.
inline void relink(Mesh& mesh, std::uint32_t o, std::uint32_t a, std::uint32_t b, std::uint32_t t) {
  if (o == kNone) return;
  MTri& m = mesh.tris[o];
  for (int j = 0; j < 3; ++j) {
    if (m.v[j] == a && m.v[(j + 1) % 3] == b) m.nbr[j] = t;
  }
}

/// Seconds since t, and t moved to now.
inline double since(Clock::time_point& t) {
  const Clock::time_point now = Clock::now();
  const double s = std::chrono::duration<double>(now - t).count();
  t = now;
  return s;
}

}  // namespace smr::block_tin
