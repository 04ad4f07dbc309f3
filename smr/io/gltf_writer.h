// Writing a triangle mesh as glTF 2.0 (.glb binary or .gltf JSON with an embedded base64 buffer),
// quantized with KHR_mesh_quantization and optionally compressed with KHR_draco_mesh_compression
// or EXT_meshopt_compression (storage/mesh_compress.h wraps both libraries).
//
// Positions: the database's global quantization grid (smr/db/quantize.h), per axis as uint16
// offsets from the mesh's smallest grid index in units of the grid step times 2^shift: the
// smallest shift (down to -16) whose units fit the mesh's span in 16 bits. A shift <= 0 keeps every
// position exactly on the grid (a short span, such as a terrain's x and y on its DEM lattice, in
// subdivided units, which keeps the node's scale near isotropic for the normals); a positive one
// coarsens the grid, within half a unit (GltfReport::max_position_error). The node's
// translation and scale undo the quantization; its rotation turns a terrain's z-up data into
// glTF's y-up.
//
// Scene frame. glTF = R * D * (data - reference), where R maps the data's (x, y, z) to glTF's
// (x, z, -y) for terrains (z up; identity for 3-D meshes), and D converts a geographic raster's
// degrees to metres: the WGS 84 metres per degree of longitude and of latitude at the reference
// latitude (a local equirectangular approximation; identity for projected rasters and meshes).
// Normals are the area-weighted vertex normals of the mesh in that metric frame, stored in the
// node's (anisotropically scaled) space so that renderers' normal matrices map them back: int8
// when the node's scale is uniform (3-D meshes), int16 otherwise (a terrain's z step is far finer
// than its x/y steps, which int8 could not resolve).
//
// Georeference: asset.extras.smrdb holds everything needed to get data coordinates back from the
// file: "position_to_data" (data = offset + scale * stored integer, per axis), "data_to_gltf"
// (reference, D's scale, the axes), the raster's georef (origin, spacing, CRS WKT, geographic)
// and the database grid, plus what the caller adds (the source database, the RCF...).
// docs/cli.md describes the format for users.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "smr/core/heightfield.h"
#include "smr/core/mesh.h"

namespace smr {

enum class GltfCompression { kNone, kDraco, kMeshopt };

/// "none", "draco", "meshopt" (nullopt for anything else).
std::optional<GltfCompression> parse_gltf_compression(std::string_view name);
std::string_view gltf_compression_name(GltfCompression c);

struct GltfOptions {
  GltfCompression compression = GltfCompression::kNone;
  /// The database's quantization grid: every position is origin + q * step for an integer q (a
  /// position off the grid is rounded to it).
  Vec3 grid_origin{0.0};
  Vec3 grid_step{1.0};
  /// A terrain: z up in the data (rotated to glTF's y up) and `georef` is the raster's.
  bool terrain = false;
  Georef georef;
  /// The data point at the glTF origin (the database's centre, say, so that every extraction of
  /// one database lines up).
  Vec3 reference{0.0};
  /// A JSON object (text) added to asset.extras.smrdb, e.g. the source and the RCF; empty: none.
  std::string extras_json;
};

struct GltfReport {
  std::uint64_t vertices = 0;    // in the file (Draco may duplicate some)
  std::uint64_t triangles = 0;   // in the file
  std::array<int, 3> shift{};    // per axis, units of grid step * 2^shift (<= 0: exact on the grid)
  Vec3 max_position_error{0.0};  // per axis, data units: half a coarsened step (0 when exact)
  int normal_bits = 16;
  std::uint64_t bytes = 0;  // file size
};

/// Writes `mesh` as glTF: binary (.glb) or JSON with the buffer embedded as a data URI (.gltf),
/// chosen by extension (anything else: kInvalidInput). A mesh with no triangles, an index out of
/// range, or a position whose grid offset does not fit 32 bits is kInvalidInput naming `path`.
/// Written atomically (atomic_file.h): a failed write leaves no file.
GltfReport write_gltf(const std::string& path, const TriangleMesh& mesh,
                      const GltfOptions& options);

}  // namespace smr
