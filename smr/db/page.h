// Data pages (docs/design.md section 3): the ops of one R-tree leaf, stored together. A page holds
// their geometry — the page's distinct vertices on the global quantization grid and every
// fragment triangle, in op order — through a storage codec (Draco, zstd or raw), and their
// compact records (ids, resolutions, PreF, DAG and Hypermesh links, ROI, subtree normal cone)
// as zstd-compressed varints. What an op's record can derive is not stored: box and sphere are
// recomputed from its vertices (compute_op_bounds' values), its own normal cone and in-fragment
// neighbours only by readers that need them (op_bounds, fragment_neighbours), and a triangle's
// death_res is its killer's birth_res (every killer is a child).
// Resolutions are 32-bit floats, rounded by the writer so that every bound stays true, and an
// op's error is the one its resolution stands for (smr/db/quantize.h: round_for_storage,
// stored_op_error).
//
// Layout of the (unsealed) page, the second part of its `pages` value (PageValue below), format 5
// (4 with two-byte cone codes): u8 format, u8 codec,
// varint op count, seven varint totals (page vertices, op vertex-list entries, fragment triangles,
// PreF triangles, links, parents, children: the decoder sizes its one block from them), blob
// records (zstd), blob geometry (codec: the page's vertex positions, in the order ops first list
// them; no faces). The records are streams, one per field of every op (page.cpp, Stream), each
// preceded in a table by its length, so that zstd sees like next to like. What format 4 no longer
// stores:
// - a fragment triangle's corners index its op's vertex list (a few values, not page indices);
// - a vertex-list entry is "the next new page vertex" or how far back in the page's table;
// - a Hypermesh link is one code per boundary edge of F (model boundary, or the link the PreF
//   triangle inside the edge gives: 77 % of terrain links), the rest stored;
// - a child on the same page gives its birth_res (the death_res of what it kills).
// A decoded page (DecodedPage) is one allocation: every op's arrays lie in it, each op is an
// OpView over them, and fragment and PreF corners index the page's vertex table directly.
#pragma once

#include <array>
#include <cstddef>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "smr/core/op.h"
#include "smr/db/quantize.h"
#include "storage/bytes.h"
#include "storage/codec.h"

namespace smr {

// 5: one-byte cone codes; 4: streams, derived links; 3: one-block decoding.
inline constexpr std::uint8_t kPageFormat = 5;

/// The ops of one data page, decoded into one block. Immutable once made.
class DecodedPage {
 public:
  DecodedPage(const DecodedPage&) = delete;
  DecodedPage& operator=(const DecodedPage&) = delete;
  ~DecodedPage();

  std::span<const OpView> ops() const { return {ops_, op_count_}; }
  std::size_t size() const { return op_count_; }
  const OpView& operator[](std::size_t i) const { return ops_[i]; }
  /// What holding the page costs: its block and this object (as the heap allocates them).
  std::size_t memory_bytes() const;

 private:
  friend class PageDecoder;
  DecodedPage() = default;
  std::unique_ptr<std::byte[]> block_;
  std::size_t block_bytes_ = 0;
  OpView* ops_ = nullptr;
  std::size_t op_count_ = 0;
};

/// Encodes `ops` (in the given order; the decoder returns them in it). The ops' positions must
/// lie on `grid` (quantize() the model first) and their resolutions and errors be as
/// round_for_storage() leaves them; throws kInternal otherwise.
storage::Bytes encode_page(std::span<const Op* const> ops, const QuantGrid& grid,
                           storage::CodecId codec);

/// Decodes a page of the model `info` (its errors are derived: stored_op_error); `context` (e.g.
/// "pages/12") names it in every error. Malformed input throws smr::Error (kCorrupt), never
/// crashes. Without `links` the Hypermesh links are neither decoded nor checked: every op's
/// `coarser` is empty and its `links` false (OpView::links), and the page is smaller by them.
std::shared_ptr<const DecodedPage> decode_page(storage::ByteView page, const QuantGrid& grid,
                                               const CrmrInfo& info, const std::string& context,
                                               bool links = true);

/// What a cut at one level takes from a data page (smr/query/level_cut.h): X is R^0 and the ops
/// whose birth_res is below `below`, and the page's triangles in it are those of its ops in X whose
/// killer is not in X (Brown's set formula, Lemma 5.1.1). Only the streams that decide it are read
/// (heads, resolutions, vertex ids, lists, corners, children and their resolutions, killers,
/// voids); what is read is checked as decode_page checks it. Vertices are the page's that those
/// triangles use, in order of first use.
struct PageCut {
  std::vector<std::uint64_t> vertex_ids;                // used page vertices: their ids
  std::vector<Vec3> positions;                          // and positions
  std::vector<std::array<std::uint32_t, 3>> triangles;  // corners index vertex_ids
  std::vector<float> values;                            // per triangle: its death_res
  std::uint64_t ops_in_x = 0;
};

/// The cut of one page (PageCut). Returns false, `out` then unspecified, if the page holds a void
/// triangle (in a fragment or a PreF): void triangles make an op completely finer whatever its
/// resolution (Rcf::is_completely_finer), so X is no longer a function of birth_res alone.
/// Malformed input throws smr::Error (kCorrupt) naming `context`.
bool cut_page(storage::ByteView page, const QuantGrid& grid, double below, PageCut& out,
              const std::string& context);

/// A page's parts as stored (the layout above), before anything is decompressed or checked
/// beyond the framing: for tools that measure pages. Throws kCorrupt naming `context`.
struct PageSections {
  std::uint8_t format = 0, codec = 0;
  std::uint64_t ops = 0;
  std::array<std::uint64_t, 7> totals{};  // in the stored order
  storage::ByteView records, geometry;    // zstd records, codec geometry
};
PageSections page_sections(storage::ByteView page, const std::string& context);

/// A value of the `pages` table (database format 5): varint n, the sealed R-tree leaf of the page
/// (n bytes; its entries are the page's ops, slot for slot), then the sealed page. The leaf lives
/// beside its page so that neither takes LMDB overflow pages of its own (a ~2.6 KB leaf filled a
/// 4 KiB page alone), and a query that enters a leaf and then reads the page reads one value.
struct PageValue {
  storage::ByteView leaf, page;  // both sealed
};
/// Throws kCorrupt "table '<table>', key <key>: ..." when the framing is malformed (checksums are
/// the reader's).
PageValue split_page_value(storage::ByteView value, std::string_view table, const std::string& key);
/// What a reader of a leaf asks the OS for of a pages value (storage::ReadTxn::get's `head`): its
/// first LMDB page, which holds the usual leaf (~2.6 KB); a longer one faults its rest in.
inline constexpr std::size_t kLeafHeadBytes = 4096;
storage::Bytes join_page_value(storage::ByteView leaf, storage::ByteView page);
/// The bytes join_page_value adds to a sealed page whose sealed leaf takes `leaf_bytes`.
std::size_t page_value_overhead(std::size_t leaf_bytes);
/// The page of a `pages` value, checked and unsealed; errors name "<table>" and "<key>".
storage::ByteView page_payload(storage::ByteView value, std::string_view table,
                               const std::string& key);

/// The streams of a page's records (page.cpp, Stream), decompressed, by name: for tools that
/// measure what each field costs. Throws kCorrupt naming `context`.
std::vector<std::pair<std::string, storage::Bytes>> page_record_streams(storage::ByteView page,
                                                                        const std::string& context);

/// One Hypermesh link of op `id` as pages store it (the stream writer's spool too): its triangle
/// and edge, the coarser triangle's op as a difference from `id`, its index and edge.
void write_link(storage::ByteWriter& w, const CoarserLink& link, std::uint64_t id);
CoarserLink read_link(storage::ByteReader& r, std::uint64_t id);

/// What a heap block of `bytes` really takes (glibc malloc: an 8-byte header, 16-byte granules,
/// 32 bytes at least). Charging a cache only the requested bytes let it hold ~1.7x its budget.
std::size_t heap_block_bytes(std::size_t bytes);

}  // namespace smr
