// Skilling 2004, "Programming the Hilbert curve": AxestoTranspose, then bit interleaving.
#include "index/hilbert.h"

#include "base/error.h"

namespace smr::index {

std::uint64_t hilbert_index(std::array<std::uint32_t, 3> cell, int dims) {
  if (dims != 2 && dims != 3) throw_internal("hilbert_index: dims must be 2 or 3");
  const int bits = hilbert_bits(dims);
  std::array<std::uint32_t, 3> x = cell;
  const std::uint32_t top = std::uint32_t{1} << (bits - 1);
  // Inverse undo of the excess work.
  for (std::uint32_t q = top; q > 1; q >>= 1) {
    const std::uint32_t p = q - 1;
    for (int i = 0; i < dims; ++i) {
      if (x[i] & q) {
        x[0] ^= p;  // invert
      } else {
        const std::uint32_t t = (x[0] ^ x[i]) & p;  // exchange
        x[0] ^= t;
        x[i] ^= t;
      }
    }
  }
  // Gray encode.
  for (int i = 1; i < dims; ++i) x[i] ^= x[i - 1];
  std::uint32_t t = 0;
  for (std::uint32_t q = top; q > 1; q >>= 1) {
    if (x[dims - 1] & q) t ^= q - 1;
  }
  for (int i = 0; i < dims; ++i) x[i] ^= t;
  // Interleave: the most significant bit of axis 0 first.
  std::uint64_t index = 0;
  for (int b = bits - 1; b >= 0; --b) {
    for (int i = 0; i < dims; ++i) index = (index << 1) | ((x[i] >> b) & 1u);
  }
  return index;
}

}  // namespace smr::index
