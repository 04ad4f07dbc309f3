// Checksums of stored values (xxhash XXH3, 64 bits; docs/design.md section 3: "every page and
// record carries a checksum"). A sealed value is its payload followed by the payload's 8-byte
// little-endian checksum.
#pragma once

#include <cstdint>
#include <string_view>

#include "storage/bytes.h"

namespace smr::storage {

// XXH3_64bits of `data` (seed 0). Stable across platforms and releases of xxhash >= 0.8.
std::uint64_t checksum(ByteView data);

// `payload` followed by checksum(payload), little-endian.
Bytes seal(ByteView payload);
// Appends seal(payload) to `out`.
void seal_into(ByteView payload, Bytes& out);

// Verifies a sealed value and returns its payload (a view into `sealed`). On a short value or a
// mismatch throws kCorrupt "table '<table>', key <key>: checksum mismatch (...)".
ByteView unseal(ByteView sealed, std::string_view table, std::string_view key);

}  // namespace smr::storage
