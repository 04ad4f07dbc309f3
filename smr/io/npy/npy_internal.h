// What the .npy / .npz files share (internal to smr/io/npy): byte loads, the .npy header, and
// the conversion of array elements to float32 elevations (whole arrays in npy_grid.cpp, windows
// in npy_windows.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "smr/io/npy.h"

namespace smr::npy_io {

inline std::uint64_t load_le(const std::uint8_t* p, int n) {
  std::uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

inline std::uint64_t load_be(const std::uint8_t* p, int n) {
  std::uint64_t v = 0;
  for (int i = 0; i < n; ++i) v = (v << 8) | p[i];
  return v;
}

/// A shape as Python prints it: "(344, 403)", "(5,)", "()".
std::string shape_text(const std::vector<std::size_t>& shape);

/// The array a .npy describes (its `data` left empty) and the offset of its data, from the first
/// bytes of the file: `bytes` must hold at least the preamble and the header.
std::pair<NpyArray, std::size_t> parse_npy_header(std::span<const std::uint8_t> bytes,
                                                  const std::string& what);

/// The byte size of the array's data (checked against overflow by parse_npy_header).
std::size_t data_bytes(const NpyArray& a);

/// Checks that the `have` bytes after a .npy's header are exactly the array's data.
void check_data_size(const NpyArray& a, std::size_t have, const std::string& what);

/// The (rows, cols) of a 2-D array that fits a heightfield.
std::pair<std::size_t, std::size_t> grid_shape(const NpyArray& a, const std::string& what);

/// True when the elements are native float32s, which are copied as they are.
bool native_float32(const NpyArray& a);

/// Checks that float32 samples are finite: z[i] is elevation [r0 + i / w, c0 + i % w].
void check_finite(std::span<const float> z, std::size_t r0, std::size_t c0, std::size_t w,
                  const std::string& what);

/// The element at `p` of array `a` as a float32 elevation; (r, c) name it in errors.
float element(const NpyArray& a, const std::uint8_t* p, const std::string& what, std::size_t r,
              std::size_t c);

}  // namespace smr::npy_io
