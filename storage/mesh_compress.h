// Compressing a quantized triangle mesh for delivery (glTF's KHR_draco_mesh_compression and
// EXT_meshopt_compression; smr/io/gltf_writer.h): the Draco half in mesh_draco.cpp, the
// meshoptimizer half in mesh_meshopt.cpp, so that each library is wrapped in one place and never
// appears in a header. Positions are unsigned 16-bit integers and normals signed normalized 8- or
// 16-bit integers (KHR_mesh_quantization's types); both codecs keep them exactly (no further
// quantization), so a decoder returns the integers it was given.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "storage/bytes.h"

namespace smr::storage {

/// A triangle mesh as a glTF primitive stores it: per vertex three uint16 position components and
/// three normal components of `normal_bits` (8 or 16) bits, held in int16 either way.
struct QuantizedMesh {
  std::vector<std::array<std::uint16_t, 3>> positions;
  std::vector<std::array<std::int16_t, 3>> normals;  // empty: none
  int normal_bits = 16;
  std::vector<std::array<std::uint32_t, 3>> triangles;
};

// ---- Draco (KHR_draco_mesh_compression) -------------------------------------------------------

/// A Draco bitstream and the unique ids of its attributes (the extension's `attributes` map).
struct DracoMesh {
  Bytes bytes;
  int position_id = -1;
  int normal_id = -1;  // -1: no normals
};

/// Encodes `mesh` with Draco's edgebreaker (integer attributes, no quantization: lossless; Draco
/// may reorder vertices and triangles). Throws kInvalidInput on an index out of range.
DracoMesh draco_encode_mesh(const QuantizedMesh& mesh);
/// Decodes what draco_encode_mesh wrote (for tests and tools): the same vertices and triangles,
/// possibly in another order. Throws kCorrupt naming `context` on bytes it cannot decode.
QuantizedMesh draco_decode_mesh(ByteView in, const DracoMesh& ids, int normal_bits,
                                const char* context);

// ---- meshoptimizer (EXT_meshopt_compression) --------------------------------------------------

/// Reorders `triangles` for the post-transform vertex cache, then numbers the vertices in the
/// order the triangles first use them (meshoptimizer's vertex cache and fetch optimizers, which
/// the extension recommends before encoding). Returns new_index[old_index] (unused vertices go
/// last, in their old order); `triangles` is renumbered in place.
std::vector<std::uint32_t> meshopt_reorder(std::span<std::array<std::uint32_t, 3>> triangles,
                                           std::size_t vertex_count);
/// Mode ATTRIBUTES: `count` elements of `stride` bytes (a multiple of 4, at most 256).
Bytes meshopt_encode_attributes(ByteView data, std::size_t count, std::size_t stride);
/// Mode TRIANGLES: the index list (a multiple of 3 long).
Bytes meshopt_encode_triangles(std::span<const std::uint32_t> indices, std::size_t vertex_count);
/// The decoders (for tests): throw kCorrupt naming `context` when the bytes do not decode.
Bytes meshopt_decode_attributes(ByteView in, std::size_t count, std::size_t stride,
                                const char* context);
std::vector<std::uint32_t> meshopt_decode_triangles(ByteView in, std::size_t index_count,
                                                    const char* context);

}  // namespace smr::storage
