// NumPy .npy / .npz codec: the format is parsed here by hand (no Python, no cnpy) so that every
// byte read from disk is bounds-checked; this is a fuzz target.
//
// Format: https://numpy.org/doc/stable/reference/generated/numpy.lib.format.html (versions 1.0,
// 2.0, 3.0); .npz is a zip archive (PKWARE APPNOTE 6.3: local headers, central directory, end of
// central directory, zip64 extensions) of .npy members, stored (method 0) or deflated (method 8).
//
// Supported dtypes: bool (|b1), signed and unsigned integers of 1, 2, 4 and 8 bytes (i1 .. u8),
// float32 and float64, little or big endian; C or Fortran order; any number of dimensions.
// Structured, string, object, float16 and complex dtypes are rejected with a message.
//
// Implementation: smr/io/npy/ (npy_format.cpp: the .npy format and writer; npz_zip.cpp: the zip
// container and inflate; npy_grid.cpp: elevation grids and .npz georeferencing; npy_windows.cpp:
// windowed reads of a plain .npy).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "smr/core/heightfield.h"

namespace smr {

enum class NpyKind { kBool, kInt, kUInt, kFloat };

/// A parsed .npy array. `data` borrows the bytes given to parse_npy.
struct NpyArray {
  NpyKind kind = NpyKind::kFloat;
  int item_size = 4;  // bytes per element
  bool big_endian = false;
  bool fortran_order = false;
  std::vector<std::size_t> shape;      // empty for a 0-d (scalar) array
  std::span<const std::uint8_t> data;  // exactly count() * item_size bytes

  std::size_t count() const;  // product of shape (1 for a scalar)
  std::string dtype() const;  // NumPy's descr, e.g. "<f4"
  /// Element `i` in storage order, converted to double (exact for all but 64-bit integers
  /// beyond 2^53). Precondition: i < count().
  double value(std::size_t i) const;
};

/// Parses a .npy image. `what` names it in error messages (e.g. "dem.npy" or "a.npz:elevation").
/// Throws smr::Error(kInvalidInput) on anything malformed; never reads outside `bytes`.
NpyArray parse_npy(std::span<const std::uint8_t> bytes, const std::string& what);

/// One member of a .npz archive, decompressed: `name` without the ".npy" suffix.
struct NpzMember {
  std::string name;
  std::vector<std::uint8_t> bytes;
};

/// Unpacks every `.npy` member of a .npz (zip) image, checking sizes and CRC-32s. Other members
/// (directories, non-.npy names) are skipped. Throws smr::Error(kInvalidInput) when malformed.
std::vector<NpzMember> unpack_npz(std::span<const std::uint8_t> bytes, const std::string& what);

/// In-memory read_npy / read_npz (dem_reader.h): `what` is used for messages and as
/// Heightfield::source. These are the fuzzing entry points.
Heightfield heightfield_from_npy(std::span<const std::uint8_t> bytes, const std::string& what);
Heightfield heightfield_from_npz(std::span<const std::uint8_t> bytes, const std::string& what);

/// A version-1.0 .npy image of a little-endian float32 C-order array of shape (rows, cols).
/// Precondition: values.size() == rows * cols.
std::vector<std::uint8_t> encode_npy(std::span<const float> values, std::size_t rows,
                                     std::size_t cols);

/// Writes h.z as float32, shape (height, width), heightfield row 0 (south) stored first, so that
/// read_npy(path) returns the same z values (georef is not stored: .npy has no place for it).
/// Throws kInvalidInput when h has no-data samples (.npy cannot mark them: use write_geotiff) and
/// kIo when the file cannot be written (a failed write leaves no partial file).
void write_npy(const std::string& path, const Heightfield& h);

}  // namespace smr
