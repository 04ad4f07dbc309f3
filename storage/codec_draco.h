// Internal to storage/: the Draco half of codec.cpp, kept in its own translation unit so that
// Draco is wrapped in exactly one place. Not part of the public API.
#pragma once

#include <cstddef>
#include <string_view>

#include "storage/codec.h"

namespace smr::storage::detail {

// Appends the Draco payload of `blob` (faces validated by the caller).
void draco_encode(const GeometryBlob& blob, Bytes& out);
GeometryBlob draco_decode(ByteView in, std::string_view context);
// Measurement only: the size of a Draco edgebreaker encoding of `blob` with the same integer
// position attribute, WITHOUT the point/face permutation needed to restore the order.
std::size_t draco_edgebreaker_size(const GeometryBlob& blob);

}  // namespace smr::storage::detail
