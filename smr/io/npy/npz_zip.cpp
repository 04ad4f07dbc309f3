// The .npz container: a zip archive of .npy members (numpy.savez / savez_compressed), read per
// PKWARE's APPNOTE.TXT 6.3 section 4: the end of central directory record (4.3.16), the zip64 end
// record and its locator (4.3.14, 4.3.15), central directory headers (4.3.12) with the zip64
// extended information extra field (4.5.3), local file headers (4.3.7); members stored (method 0)
// or deflated (method 8, RFC 1951, inflated with zlib) and checked against their CRC-32.
#include <zlib.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <optional>
#include <string_view>

#include "base/error.h"
#include "smr/io/io_util.h"
#include "smr/io/npy.h"
#include "smr/io/npy/npy_internal.h"

namespace smr {

namespace {

using io_util::excerpt;
using npy_io::load_le;

// Bounds-checked little-endian reads from a byte span; `what` names the input for messages.
class Bytes {
 public:
  Bytes(std::span<const std::uint8_t> b, const std::string& what) : b_(b), what_(what) {}
  std::size_t size() const { return b_.size(); }
  bool has(std::size_t offset, std::size_t n) const {
    return offset <= b_.size() && n <= b_.size() - offset;
  }
  void need(std::size_t offset, std::size_t n, const char* record) const {
    if (!has(offset, n)) {
      throw_input("'" + what_ + "' is truncated or corrupt: the " + record + " at byte " +
                  std::to_string(offset) + " needs " + std::to_string(n) +
                  " bytes but the file has " + std::to_string(b_.size()));
    }
  }
  std::uint16_t u16(std::size_t o) const { return static_cast<std::uint16_t>(load_le(&b_[o], 2)); }
  std::uint32_t u32(std::size_t o) const { return static_cast<std::uint32_t>(load_le(&b_[o], 4)); }
  std::uint64_t u64(std::size_t o) const { return load_le(&b_[o], 8); }
  std::span<const std::uint8_t> sub(std::size_t o, std::size_t n) const { return b_.subspan(o, n); }

 private:
  std::span<const std::uint8_t> b_;
  const std::string& what_;
};

constexpr std::uint32_t kLocalSig = 0x04034b50;
constexpr std::uint32_t kCentralSig = 0x02014b50;
constexpr std::uint32_t kEndSig = 0x06054b50;
constexpr std::uint32_t kEnd64Sig = 0x06064b50;
constexpr std::uint32_t kEnd64LocatorSig = 0x07064b50;

std::vector<std::uint8_t> inflate_raw(std::span<const std::uint8_t> in, std::uint64_t out_size,
                                      const std::string& member) {
  std::vector<std::uint8_t> out(static_cast<std::size_t>(out_size));
  z_stream s{};
  if (inflateInit2(&s, -MAX_WBITS) != Z_OK) throw_io("zlib could not initialise for " + member);
  constexpr std::size_t kMax = std::numeric_limits<uInt>::max();
  std::size_t in_pos = 0, out_pos = 0;
  bool overflow = false;
  int rc = Z_OK;
  for (;;) {
    const std::size_t in_n = std::min(in.size() - in_pos, kMax);
    const std::size_t out_n = std::min(out.size() - out_pos, kMax);
    std::uint8_t spare = 0;  // detects output beyond the declared size
    // zlib does not write through next_in; its API is not const-correct.
    s.next_in = const_cast<Bytef*>(in.data() + in_pos);
    s.avail_in = static_cast<uInt>(in_n);
    s.next_out = out_n > 0 ? out.data() + out_pos : &spare;
    s.avail_out = out_n > 0 ? static_cast<uInt>(out_n) : 1;
    rc = inflate(&s, Z_NO_FLUSH);
    const std::size_t consumed = in_n - s.avail_in;
    const std::size_t produced = (out_n > 0 ? out_n : 1) - s.avail_out;
    in_pos += consumed;
    if (out_n == 0 && produced > 0) {
      overflow = true;
      break;
    }
    out_pos += produced;
    if (rc != Z_OK || (consumed == 0 && produced == 0)) break;
  }
  const std::string msg = s.msg != nullptr ? s.msg : "";
  inflateEnd(&s);
  if (overflow) {
    throw_input(member + " inflates to more than its declared " + std::to_string(out_size) +
                " bytes");
  }
  if (rc == Z_STREAM_END) {
    if (out_pos == out.size()) return out;
    throw_input(member + " inflates to " + std::to_string(out_pos) + " bytes; expected " +
                std::to_string(out_size));
  }
  if (rc == Z_DATA_ERROR || rc == Z_NEED_DICT) {
    throw_input(member + " has a corrupt deflate stream (zlib: " +
                (msg.empty() ? std::string("data error") : msg) + ")");
  }
  if (rc == Z_MEM_ERROR) throw_io(member + ": zlib ran out of memory");
  throw_input(member + " has a truncated deflate stream (inflated " + std::to_string(out_pos) +
              " of " + std::to_string(out_size) + " bytes)");
}

std::uint32_t crc32_of(std::span<const std::uint8_t> data) {
  uLong crc = crc32_z(0L, Z_NULL, 0);
  crc = crc32_z(crc, data.data(), data.size());
  return static_cast<std::uint32_t>(crc);
}

// Where the central directory is, from the end of central directory record (or its zip64 one).
struct CentralDirectory {
  std::uint64_t entries = 0, size = 0, offset = 0;
};

CentralDirectory find_central_directory(const Bytes& b, const std::string& what) {
  // End of central directory: the last 22-byte record whose comment reaches the end of the file.
  std::optional<std::size_t> eocd;
  if (b.size() >= 22) {
    const std::size_t last = b.size() - 22;
    const std::size_t first = last > 0xffff ? last - 0xffff : 0;
    for (std::size_t p = last + 1; p-- > first;) {
      if (b.u32(p) == kEndSig && p + 22 + b.u16(p + 20) == b.size()) {
        eocd = p;
        break;
      }
    }
  }
  if (!eocd) {
    throw_input("'" + what +
                "' is not a .npz (zip) archive or is truncated: no end-of-central-directory "
                "record at its end");
  }
  const std::size_t e = *eocd;
  if (b.u16(e + 4) != 0 || b.u16(e + 6) != 0) {
    throw_input("'" + what + "' is a multi-disk zip archive; expected a single .npz file");
  }
  CentralDirectory cd{b.u16(e + 10), b.u32(e + 12), b.u32(e + 16)};
  if (cd.entries == 0xffff || cd.size == 0xffffffff || cd.offset == 0xffffffff) {
    // zip64: locator just before the EOCD, pointing at the zip64 end record.
    if (e < 20 || b.u32(e - 20) != kEnd64LocatorSig) {
      throw_input("'" + what + "' is corrupt: zip64 values without a zip64 end locator");
    }
    const std::uint64_t rec = b.u64(e - 20 + 8);
    if (rec > b.size()) throw_input("'" + what + "' is corrupt: bad zip64 end record offset");
    b.need(static_cast<std::size_t>(rec), 56, "zip64 end of central directory record");
    const auto r = static_cast<std::size_t>(rec);
    if (b.u32(r) != kEnd64Sig) {
      throw_input("'" + what + "' is corrupt: no zip64 end record at byte " + std::to_string(r));
    }
    cd.entries = b.u64(r + 32);
    cd.size = b.u64(r + 40);
    cd.offset = b.u64(r + 48);
  }
  if (cd.offset > b.size() || cd.size > b.size() - cd.offset) {
    throw_input("'" + what + "' is truncated or corrupt: its central directory (" +
                std::to_string(cd.size) + " bytes at " + std::to_string(cd.offset) +
                ") lies outside the " + std::to_string(b.size()) + "-byte file");
  }
  if (cd.entries > cd.size / 46) {
    throw_input("'" + what + "' is corrupt: " + std::to_string(cd.entries) +
                " entries cannot fit in a " + std::to_string(cd.size) + "-byte central directory");
  }
  return cd;
}

// One central directory header, its sizes and offset completed from a zip64 extra field.
struct CentralEntry {
  std::string name;
  std::string member;  // "'<what>' member '<name>'", for messages
  std::uint16_t flags = 0, method = 0;
  std::uint32_t crc = 0;
  std::uint64_t csize = 0, usize = 0, local = 0;
};

// Reads entry k at byte p (advanced past it) of a central directory ending at cd_end.
CentralEntry read_central_entry(const Bytes& b, std::span<const std::uint8_t> bytes, std::size_t& p,
                                std::size_t cd_end, std::uint64_t k, const std::string& what) {
  if (p + 46 > cd_end) throw_input("'" + what + "' is corrupt: central directory overrun");
  if (b.u32(p) != kCentralSig) {
    throw_input("'" + what + "' is corrupt: bad central directory entry " + std::to_string(k) +
                " at byte " + std::to_string(p));
  }
  CentralEntry c;
  c.flags = b.u16(p + 8);
  c.method = b.u16(p + 10);
  c.crc = b.u32(p + 16);
  c.csize = b.u32(p + 20);
  c.usize = b.u32(p + 24);
  const std::size_t name_len = b.u16(p + 28), extra_len = b.u16(p + 30),
                    comment_len = b.u16(p + 32);
  c.local = b.u32(p + 42);
  const std::size_t entry_len = 46 + name_len + extra_len + comment_len;
  if (entry_len > cd_end - p) throw_input("'" + what + "' is corrupt: central directory overrun");
  c.name.assign(reinterpret_cast<const char*>(bytes.data() + p + 46), name_len);
  c.member = "'" + what + "' member '" + excerpt(c.name, 100) + "'";
  // zip64 extended information extra field.
  for (std::size_t x = p + 46 + name_len, xe = x + extra_len; x + 4 <= xe;) {
    const std::uint16_t id = b.u16(x), len = b.u16(x + 2);
    if (len > xe - x - 4) throw_input(c.member + " has a corrupt extra field");
    if (id == 0x0001) {
      std::size_t f = x + 4;
      const std::size_t fe = f + len;
      const auto take = [&](std::uint64_t& v) {
        if (f + 8 > fe) throw_input(c.member + " has a short zip64 extra field");
        v = b.u64(f);
        f += 8;
      };
      if (c.usize == 0xffffffff) take(c.usize);
      if (c.csize == 0xffffffff) take(c.csize);
      if (c.local == 0xffffffff) take(c.local);
    }
    x += 4 + static_cast<std::size_t>(len);
  }
  p += entry_len;
  return c;
}

// The compressed bytes of entry c, after its local header (checked, its own name and extra
// field skipped).
std::span<const std::uint8_t> member_data(const Bytes& b, std::span<const std::uint8_t> bytes,
                                          const CentralEntry& c) {
  if (c.flags & 0x1) throw_input(c.member + " is encrypted; expected a plain .npz");
  if (c.method != 0 && c.method != 8) {
    throw_input(c.member + " uses compression method " + std::to_string(c.method) +
                "; expected 0 (stored) or 8 (deflate)");
  }
  if (c.local > b.size()) throw_input(c.member + " has a local header offset beyond the file");
  const auto lh = static_cast<std::size_t>(c.local);
  b.need(lh, 30, "local file header");
  if (b.u32(lh) != kLocalSig) {
    throw_input(c.member + " has no local file header at byte " + std::to_string(lh));
  }
  const std::size_t lname = b.u16(lh + 26), lextra = b.u16(lh + 28);
  b.need(lh + 30, lname + lextra, "local file header");
  if (lname != c.name.size() ||
      std::memcmp(bytes.data() + lh + 30, c.name.data(), c.name.size()) != 0) {
    throw_input(c.member + ": the local header names a different file");
  }
  const std::size_t data_start = lh + 30 + lname + lextra;
  if (c.csize > b.size() - data_start) {
    throw_input(c.member + " is truncated: " + std::to_string(c.csize) +
                " compressed bytes declared but the file ends first");
  }
  return b.sub(data_start, static_cast<std::size_t>(c.csize));
}

// The member's bytes: stored, or inflated (with a check against deflate's largest ratio).
std::vector<std::uint8_t> decompress(std::span<const std::uint8_t> data, const CentralEntry& c) {
  if (c.method == 0) {
    if (c.usize != c.csize) {
      throw_input(c.member + " is stored with different compressed (" + std::to_string(c.csize) +
                  ") and uncompressed (" + std::to_string(c.usize) + ") sizes");
    }
    return std::vector<std::uint8_t>(data.begin(), data.end());
  }
  // Deflate cannot expand more than ~1032:1; a larger claim is corrupt (and would be a memory
  // bomb).
  if (c.usize > c.csize * 1032 + 64) {
    throw_input(c.member + " claims " + std::to_string(c.usize) + " bytes from " +
                std::to_string(c.csize) + " compressed bytes, more than deflate can produce");
  }
  return inflate_raw(data, c.usize, c.member);
}

}  // namespace

std::vector<NpzMember> unpack_npz(std::span<const std::uint8_t> bytes, const std::string& what) {
  const Bytes b(bytes, what);
  const CentralDirectory cd = find_central_directory(b, what);
  std::vector<NpzMember> members;
  std::size_t p = static_cast<std::size_t>(cd.offset);
  const std::size_t cd_end = static_cast<std::size_t>(cd.offset + cd.size);
  for (std::uint64_t k = 0; k < cd.entries; ++k) {
    const CentralEntry c = read_central_entry(b, bytes, p, cd_end, k, what);
    const std::string& name = c.name;
    if (name.size() < 4 || name.compare(name.size() - 4, 4, ".npy") != 0) continue;
    const std::span<const std::uint8_t> data = member_data(b, bytes, c);
    NpzMember m;
    m.name = name.substr(0, name.size() - 4);
    for (const NpzMember& other : members) {
      if (other.name == m.name) throw_input(c.member + " appears twice in the archive");
    }
    m.bytes = decompress(data, c);
    if (crc32_of(m.bytes) != c.crc) throw_input(c.member + " fails its CRC-32 check");
    members.push_back(std::move(m));
  }
  return members;
}

}  // namespace smr
