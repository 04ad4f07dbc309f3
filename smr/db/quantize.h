// The database's one global quantization grid (docs/design.md section 3): every vertex position is
// stored as integers q on the grid origin + q * step, so a vertex shared by fragments in
// different pages decodes to bit-identical coordinates (no cracks by construction).
//
// Terrain: x and y use the DEM's own lattice (origin x0, y0; steps dx, dy), where every vertex
// already lies, so they are exact. z uses a power-of-two step (auto: the largest with
// range / step <= 2^24, e.g. 2^-14 m for a 1600 m range, or, for a model built to a max error,
// error_z_quantum of it if that is coarser); a DEM whose samples are multiples of it (integer
// DEMs, float32 values above range/2^... ) is stored exactly. Snapping z moves a
// triangle's plane by at most the largest vertex shift, so every stored error grows by that
// shift (0 when nothing moved): error bounds against the source stay true.
#pragma once

#include <array>
#include <cstdint>

#include "smr/core/crmr.h"

namespace smr {

struct QuantGrid {
  Vec3 origin{0.0};
  Vec3 step{1.0};

  std::array<std::int32_t, 3> quantize(const Vec3& p) const;  // throws if out of int32 range
  Vec3 dequantize(const std::array<std::int32_t, 3>& q) const {
    return {origin.x + q[0] * step.x, origin.y + q[1] * step.y, origin.z + q[2] * step.z};
  }
  friend bool operator==(const QuantGrid&, const QuantGrid&) = default;
};

/// 3-D meshes: one power-of-two step on all three axes, 2^-24 of the largest extent (rounded up
/// to a power of two: float32's precision there) unless given; the error bounds grow by the
/// largest vertex shift as above. 2^-28 took 4 more bits a coordinate in every page a vertex is
/// in: 6.8 bytes a model vertex on armadillo.
///
/// The grid for a model; z_quantum 0 = automatic, otherwise a positive step in data units (for a
/// 3-D mesh, the step of every axis). A terrain's automatic step is at least `error_quantum`
/// (error_z_quantum of the error it was built to; 0 = none).
QuantGrid choose_grid(const CrmrInfo& info, double z_quantum, double error_quantum = 0.0);

/// The z step a terrain built to `max_error` (> 0) can take: the largest power of two within
/// max_error / 32, so snapping moves a vertex by at most max_error / 64. A DEM's heights carry
/// more bits than such a model can tell apart: at 2^-14 m for a 1600 m range, heights took 3 of
/// the 4.6 bytes of a page vertex; at max_error / 32 the 4097^2 fBm's positions take 12.0 bytes
/// a model vertex instead of 16.7. 0 for max_error <= 0 (lossless), infinite or NaN.
double error_z_quantum(double max_error);

/// How a DEM ingested to `max_error` with `--z-quantum z_quantum` spends its error: the builder
/// gets build_error, the writer error_quantum (WriteOptions). With z_quantum 0 the step is
/// error_z_quantum(max_error) and the build aims half a step below max_error, so the database's
/// err_final stays within max_error (unless the height range needs more than 2^30 such steps:
/// max_error below ~2^-25 of the range, choose_grid); a z_quantum given is taken as it is.
/// `heights_on_step`: every height is a multiple of error_z_quantum(max_error) (integer DEMs),
/// so snapping moves none and the build keeps all of max_error (on Jacksboro, whole metres at
/// 1 m, keeping half a step back made 7 % more vertices).
struct TerrainErrorSplit {
  double build_error = 0.0, error_quantum = 0.0;
};
TerrainErrorSplit split_terrain_error(double max_error, double z_quantum,
                                      bool heights_on_step = false);

/// Snaps the vertices of `op` (of the model `model`) to `grid` and returns the largest move;
/// bounds are left to the caller. A terrain's vertices are then named by their DEM sample: id =
/// row * grid_width + col, the vertex's grid coordinates on a terrain grid (choose_grid), so the
/// ids are the same whichever builder made the model and pages derive them instead of storing
/// them (page.h); a vertex off the DEM's columns and rows throws kInternal.
double snap_vertices(Op& op, const QuantGrid& grid, const CrmrInfo& model);

/// Snaps every vertex of `crmr` to `grid` (snap_vertices), recomputes bounds and ROIs, raises err0
/// and err_final by the largest vertex shift, which it returns, rounds the ops' resolutions for
/// storage (round_for_storage) and sets their errors to stored_op_error.
double quantize(Crmr& crmr, const QuantGrid& grid);

/// Pages store resolutions as 32-bit floats (page.h), rounded so that every bound stays true: to
/// the largest float not above the resolution (a triangle then claims less resolution than it
/// has, so it reads a larger error and is refined at least as far). The rounding is monotone, so
/// orders between ops are kept, and a triangle's death_res stays its killer's birth_res.
double stored_resolution(double res);
/// Rounds op.birth_res and every fragment triangle's death_res as above.
void round_for_storage(Op& op);
/// An op's error as pages give it (they do not store it): the error its stored birth_res stands
/// for, error_at(birth_res), at most err0. Not below the op's true error, since birth_res was
/// rounded down.
double stored_op_error(const CrmrInfo& info, double birth_res);

/// Pages store an op's ROI as how far each side lies outside the op's own box, in units of
/// 2^roi_shift(error, step) grid steps on each axis: the largest power of two within an eighth of
/// the op's (stored) error, at most 2^24. The reader derives the shift from the op's stored
/// resolution, so it costs nothing. Each op's rounding adds less than an eighth of its error;
/// nested in its descendants' (finer) roundings, a stored ROI is looser than the exact one by up
/// to about the op's error (1.0 measured on Jacksboro), which moves no RCF verdict that matters
/// (distances to the eye, the frustum: the same views to 0.005 % of their triangles), and every
/// bound stays true (an ROI only grows).
int roi_shift(double error, double step);
/// `roi` pushed outwards so that each side lies a multiple of 2^roi_shift grid steps from `box`
/// (both on `grid`): the ROI a page gives back. Contains `roi`.
Box3 stored_roi(const Box3& roi, const Box3& box, double error, const QuantGrid& grid);

}  // namespace smr
