// Cesium's quantized-mesh-1.0 terrain tile format (github.com/CesiumGS/quantized-mesh): the
// encoder of one tile. Little-endian: an 88-byte header (tile centre, minimum and maximum height,
// bounding sphere, horizon occlusion point), the vertices as zig-zag deltas of u, v and height
// (each 0..32767 across the tile's rectangle and its height range), the triangles' indices with
// high-water-mark encoding (16-bit, or 32-bit above 65 536 vertices, aligned), the west, south,
// east and north edge vertex lists, then the extensions: oct-encoded vertex normals (id 1) and a
// JSON metadata object (id 4). The pyramid that cuts tiles from a database is smr/tiles.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "smr/core/geometry.h"

namespace smr {

struct QuantizedMeshTile {
  // Header: double centre (x, y, z), float min/max height, double bounding sphere centre and
  // radius, double horizon occlusion point, as the format defines them (Earth-centred, Earth-
  // fixed metres for a geographic tiling).
  Vec3 center{0.0};
  float min_height = 0.0f, max_height = 0.0f;
  Vec3 sphere_center{0.0};
  double sphere_radius = 0.0;
  Vec3 horizon_occlusion{0.0};

  std::vector<std::uint16_t> u, v, height;  // each 0..32767, one per vertex
  /// Counter-clockwise; vertices must be numbered in the order the triangles first use them
  /// (the high-water-mark code needs it; encode() checks).
  std::vector<std::array<std::uint32_t, 3>> triangles;
  std::vector<std::uint32_t> west, south, east, north;  // vertices on each edge of the rectangle
  /// Unit vertex normals for the octvertexnormals extension (empty: not written).
  std::vector<Vec3> normals;
  /// A JSON object for the metadata extension (empty: not written).
  std::string metadata;
};

/// The tile's bytes (not gzipped). Throws kInternal when the tile breaks the format's rules (a
/// coordinate above 32767, an index out of range or out of first-use order, a normal count that
/// is not the vertex count).
std::vector<std::uint8_t> encode_quantized_mesh(const QuantizedMeshTile& tile);

/// The format's oct encoding of a unit vector in two bytes (Cigolle et al. 2014, "A Survey of
/// Efficient Representations of Independent Unit Vectors", the octahedral map at 8 bits per
/// component, as the octvertexnormals extension stores it).
std::array<std::uint8_t, 2> oct_encode(const Vec3& n);

}  // namespace smr
