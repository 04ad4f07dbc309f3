// Data pages (docs/design.md section 3): the ops of one R-tree leaf, stored together. A page holds
// their geometry — the page's distinct vertices on the global quantization grid and every
// fragment triangle, in op order — through a storage codec (Draco, zstd or raw), and their
// compact records (ids, resolutions, PreF, DAG and Hypermesh links, ROI, subtree normal cone)
// as zstd-compressed varints. What an op's record can derive is not stored: box, sphere and normal
// cone are recomputed from the corners (compute_op_bounds), in-fragment neighbours from shared
// edges, and a triangle's death_res is its killer's birth_res (every killer is a child).
//
// Layout of the (unsealed) value: u8 format, u8 codec, varint op count, blob records
// (zstd), blob geometry (codec).
#pragma once

#include <span>
#include <string>
#include <vector>

#include "smr/core/op.h"
#include "smr/db/quantize.h"
#include "storage/bytes.h"
#include "storage/codec.h"

namespace smr {

inline constexpr std::uint8_t kPageFormat = 2;  // 2: subtree normal cones

/// Encodes `ops` (in the given order; the decoder returns them in it). The ops' positions must
/// lie on `grid` (quantize() the model first); throws kInternal otherwise.
storage::Bytes encode_page(std::span<const Op* const> ops, const QuantGrid& grid,
                           storage::CodecId codec);

/// Decodes a page; `context` (e.g. "pages/12") names it in every error. Malformed input throws
/// smr::Error (kCorrupt), never crashes.
std::vector<Op> decode_page(storage::ByteView page, const QuantGrid& grid,
                            const std::string& context);

/// One Hypermesh link of op `id` as pages store it (the stream writer's spool too): its triangle
/// and edge, the coarser triangle's op as a difference from `id`, its index and edge.
void write_link(storage::ByteWriter& w, const CoarserLink& link, std::uint64_t id);
CoarserLink read_link(storage::ByteReader& r, std::uint64_t id);

/// Heap bytes held by an op (what the page cache charges for it).
std::size_t op_memory_bytes(const Op& op);
/// What a heap block of `bytes` really takes (glibc malloc: an 8-byte header, 16-byte granules,
/// 32 bytes at least). Charging a cache only the requested bytes let it hold ~1.7x its budget.
std::size_t heap_block_bytes(std::size_t bytes);

}  // namespace smr
