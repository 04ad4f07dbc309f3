// Writing triangle meshes (OBJ, PLY) and the crash-safe file writing every smrdb writer uses.
//
// All writers write to a temporary file beside the target and rename it over the target only when
// everything was written and flushed, so a failed write (unwritable directory, disk full) never
// leaves a partial file; such failures throw smr::Error(kIo) naming the path.
#pragma once

#include <cstddef>
#include <cstdio>
#include <string>

#include "smr/core/mesh.h"
#include "smr/io/atomic_file.h"

namespace smr {

/// Writes `mesh`, choosing the format by extension (case-insensitive): `.obj` -> write_obj,
/// `.ply` -> write_ply (binary). Any other extension -> kInvalidInput.
/// Every writer rejects (kInvalidInput) a triangle index outside `positions` and a
/// `triangle_values` whose size is neither 0 nor the triangle count.
void write_mesh(const std::string& path, const TriangleMesh& mesh);

/// Wavefront OBJ: `v x y z` lines with the shortest decimal that round-trips each double exactly
/// (std::to_chars; at most 17 significant digits, like %.17g), then `f a b c` (1-based).
/// triangle_values are not stored (OBJ has no per-face scalar).
void write_obj(const std::string& path, const TriangleMesh& mesh);

/// PLY: `property double x/y/z` (double, so geographic coordinates in degrees survive exactly),
/// faces as `property list uchar uint vertex_indices`, plus `property float value` on faces when
/// triangle_values is set. Binary little-endian by default, ASCII (17 significant digits) when
/// `binary` is false.
void write_ply(const std::string& path, const TriangleMesh& mesh, bool binary = true);

}  // namespace smr
