// PLY's scalar types and their binary loads (internal to smr/io/mesh; Turk 1994, "The PLY
// Polygon File Format", as documented at paulbourke.net/dataformats/ply): char .. double and
// their int8 .. float64 aliases, little- or big-endian. The binary STL reader uses the float32
// load too.
#pragma once

#include <bit>
#include <cstdint>
#include <string_view>
#include <utility>

namespace smr::mesh_io {

enum class PlyType : std::uint8_t { kI8, kU8, kI16, kU16, kI32, kU32, kF32, kF64 };

inline int ply_size(PlyType t) {
  switch (t) {
    case PlyType::kI8:
    case PlyType::kU8:
      return 1;
    case PlyType::kI16:
    case PlyType::kU16:
      return 2;
    case PlyType::kI32:
    case PlyType::kU32:
    case PlyType::kF32:
      return 4;
    case PlyType::kF64:
      return 8;
  }
  return 1;
}

inline bool ply_is_integer(PlyType t) {
  return t != PlyType::kF32 && t != PlyType::kF64;
}

/// The type named `s` (both PLY spellings); false for an unknown name.
inline bool ply_type(std::string_view s, PlyType& out) {
  static const std::pair<const char*, PlyType> kNames[] = {
      {"char", PlyType::kI8},     {"int8", PlyType::kI8},     {"uchar", PlyType::kU8},
      {"uint8", PlyType::kU8},    {"short", PlyType::kI16},   {"int16", PlyType::kI16},
      {"ushort", PlyType::kU16},  {"uint16", PlyType::kU16},  {"int", PlyType::kI32},
      {"int32", PlyType::kI32},   {"uint", PlyType::kU32},    {"uint32", PlyType::kU32},
      {"float", PlyType::kF32},   {"float32", PlyType::kF32}, {"double", PlyType::kF64},
      {"float64", PlyType::kF64},
  };
  for (const auto& [name, type] : kNames) {
    if (s == name) {
      out = type;
      return true;
    }
  }
  return false;
}

/// The n bytes at p as an unsigned integer, big- or little-endian.
inline std::uint64_t load_bits(const std::uint8_t* p, int n, bool big) {
  std::uint64_t v = 0;
  if (big) {
    for (int i = 0; i < n; ++i) v = (v << 8) | p[i];
  } else {
    for (int i = n - 1; i >= 0; --i) v = (v << 8) | p[i];
  }
  return v;
}

/// A value of type t at p, as a double.
inline double load_double(PlyType t, const std::uint8_t* p, bool big) {
  const std::uint64_t b = load_bits(p, ply_size(t), big);
  switch (t) {
    case PlyType::kI8:
      return static_cast<std::int8_t>(b);
    case PlyType::kU8:
      return static_cast<double>(b);
    case PlyType::kI16:
      return static_cast<std::int16_t>(b);
    case PlyType::kU16:
      return static_cast<double>(b);
    case PlyType::kI32:
      return static_cast<std::int32_t>(b);
    case PlyType::kU32:
      return static_cast<double>(b);
    case PlyType::kF32:
      return std::bit_cast<float>(static_cast<std::uint32_t>(b));
    case PlyType::kF64:
      return std::bit_cast<double>(b);
  }
  return 0;
}

/// A value of integer type t at p (floats are rejected in the header).
inline std::int64_t load_int(PlyType t, const std::uint8_t* p, bool big) {
  const std::uint64_t b = load_bits(p, ply_size(t), big);
  switch (t) {
    case PlyType::kI8:
      return static_cast<std::int8_t>(b);
    case PlyType::kI16:
      return static_cast<std::int16_t>(b);
    case PlyType::kI32:
      return static_cast<std::int32_t>(b);
    default:
      return static_cast<std::int64_t>(b);  // unsigned types (floats are rejected in the header)
  }
}

}  // namespace smr::mesh_io
