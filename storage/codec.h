// Geometry page codecs (docs/design.md section 3, "Geometry codec"): a triangle-mesh chunk on a
// GLOBAL integer grid chosen by the caller, stored raw, as a zstd-compressed integer stream or with
// Draco. Coordinates are integers, so every codec is lossless and a vertex shared by two blobs
// decodes to the same integers: no cracks by construction.
//
// CONTRACT: decode_geometry(c, encode_geometry(c, b)) == b exactly, for every codec: the same
// positions in the same order and the same faces in the same order and rotation (callers refer
// to triangle i and its edge k). Positions no face refers to are kept. Decoding bytes that were
// not produced by encode_geometry throws smr::Error (kCorrupt) naming `context`; it never crashes.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

#include "storage/bytes.h"

namespace smr::storage {

struct GeometryBlob {
  std::vector<std::array<std::int32_t, 3>> positions;  // quantized coordinates, any int32
  std::vector<std::array<std::uint32_t, 3>> faces;     // indices into positions
  friend bool operator==(const GeometryBlob&, const GeometryBlob&) = default;
};

enum class CodecId : std::uint8_t {
  kRaw = 0,    // counts + little-endian int32/uint32 arrays: largest, fastest
  kZstd = 1,   // counts + zstd(delta/zigzag varints of coordinates and indices)
  kDraco = 2,  // Draco sequential mesh coding, integer position attribute (order-preserving)
};

std::string_view codec_name(CodecId codec);  // "raw", "zstd", "draco"
std::optional<CodecId> parse_codec(std::string_view name);

// Appends the encoding of `blob` to `out`. Throws kInvalidInput if a face index is out of range.
void encode_geometry(CodecId codec, const GeometryBlob& blob, Bytes& out);
// Throws kCorrupt "<context>: ..." on anything encode_geometry could not have produced.
GeometryBlob decode_geometry(CodecId codec, ByteView in, std::string_view context);

// zstd frame of `in` (content size recorded in the frame).
Bytes zstd_compress(ByteView in, int level = 3);
// Decompresses one zstd frame; throws kCorrupt naming `context` on a bad frame, trailing bytes or
// output larger than `max_bytes` (checked while decompressing: garbage never allocates more).
Bytes zstd_decompress(ByteView in, std::size_t max_bytes, std::string_view context);

}  // namespace smr::storage
