// The one place xxhash is used.
#include "storage/checksum.h"

#include <cstdio>
#include <string>

#include <xxhash.h>

#include "base/error.h"

namespace smr::storage {
namespace {

constexpr std::size_t kChecksumBytes = 8;

std::string hex(std::uint64_t v) {
  char buf[19];
  std::snprintf(buf, sizeof buf, "0x%016llx", static_cast<unsigned long long>(v));
  return buf;
}

std::string where(std::string_view table, std::string_view key) {
  return "table '" + std::string(table) + "', key " + std::string(key);
}

}  // namespace

std::uint64_t checksum(ByteView data) {
  return XXH3_64bits(data.data(), data.size());
}

void seal_into(ByteView payload, Bytes& out) {
  ByteWriter w(out);
  w.bytes(payload);
  w.u64(checksum(payload));
}

Bytes seal(ByteView payload) {
  Bytes out;
  out.reserve(payload.size() + kChecksumBytes);
  seal_into(payload, out);
  return out;
}

ByteView unseal(ByteView sealed, std::string_view table, std::string_view key) {
  if (sealed.size() < kChecksumBytes) {
    throw_corrupt(where(table, key) + ": value of " + std::to_string(sealed.size()) +
                  " bytes is too short to hold its 8-byte checksum");
  }
  const ByteView payload = sealed.first(sealed.size() - kChecksumBytes);
  ByteReader r(sealed.last(kChecksumBytes), where(table, key));
  const std::uint64_t stored = r.u64();
  const std::uint64_t computed = checksum(payload);
  if (stored != computed) {
    throw_corrupt(where(table, key) + ": checksum mismatch (stored " + hex(stored) + ", computed " +
                  hex(computed) + " over " + std::to_string(payload.size()) + " bytes)");
  }
  return payload;
}

}  // namespace smr::storage
