// Byte format of R-tree nodes (the layout is described in index/rtree.h). Internal to index/:
// rtree.cpp encodes with it and decodes through it; tests use it to craft malformed nodes.
//
// Coordinates are quantised to 8 bits on a per-node frame (origin + q * step, one frame per
// axis, spanning the union of the node's roi boxes) and rounded outwards, so a stored box always
// contains the true one. res is stored as its error fraction 1 - res (the quantity RCFs
// threshold, Brown 4.4.2) in bfloat16 rounded up, i.e. res rounded down, within 2^-7 of the
// error. An item then takes 14 bytes plus a varint (a leaf entry ~17, against 31 with 16-bit
// boxes and f32 res): the index is read on every query, its bytes are read amplification.
// Encoding returns the values a reader will decode, bit for bit, so the writer can build parent
// summaries from what readers will see.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "index/box.h"
#include "storage/bytes.h"

namespace smr::index::detail {

// One item of a node: a leaf entry (value = id, res = its res) or a child summary
// (value = number of entries below, res = min res below).
struct NodeItem {
  Box roi;
  Box box;
  double res = 0;
  std::uint64_t value = 0;
};

struct Node {
  std::uint64_t level = 0;        // 0 = leaf
  std::uint64_t first_child = 0;  // internal nodes only
  std::vector<NodeItem> items;
};

// Per-axis quantisation grid.
struct Frame {
  std::array<double, 3> origin{};
  std::array<double, 3> step{};

  static Frame around(const Box& bounds);  // bounds: non-empty, finite
  double decode(int axis, std::uint8_t q) const;
  std::uint8_t quantize_lo(int axis, double v) const;  // a q with decode(q) <= v, ~the largest
  std::uint8_t quantize_hi(int axis, double v) const;  // a q with decode(q) >= v, ~the least
};

// res as 16 bits: the bfloat16 of 1 - res rounded towards +infinity, adjusted so that
// decode_res(encode_res(res)) <= res (res must not be NaN). Relative error of 1 - res < 2^-7.
std::uint16_t encode_res(double res);
double decode_res(std::uint16_t q);

// Appends the node's (unsealed) bytes to `out`; returns the node as a reader will decode it.
Node encode_node(const Node& node, storage::Bytes& out);
// Decodes an unsealed node; throws kCorrupt "<context>: ..." on any malformation of the bytes.
Node decode_node(storage::ByteView payload, const std::string& context);

}  // namespace smr::index::detail
