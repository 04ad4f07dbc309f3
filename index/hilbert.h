// Hilbert curve index of a grid cell in 2-D or 3-D (Skilling, "Programming the Hilbert curve",
// AIP Conf. Proc. 707, 2004: the transpose form). Used to order index entries so that entries
// adjacent on the curve are adjacent in space (Kamel & Faloutsos' Hilbert-packed R-tree; the
// packed R-tree of Maheshwari et al. section 4.4).
#pragma once

#include <array>
#include <cstdint>

namespace smr::index {

// Bits per axis that fit a 64-bit index: 31 in 2-D, 21 in 3-D.
constexpr int hilbert_bits(int dims) {
  return dims == 2 ? 31 : 21;
}

// Position along the Hilbert curve of the cell `cell` (first `dims` coordinates used, each
// < 2^hilbert_bits(dims)). `dims` is 2 or 3. Consecutive indices are face-adjacent cells.
std::uint64_t hilbert_index(std::array<std::uint32_t, 3> cell, int dims);

}  // namespace smr::index
