// The NumPy .npy format (NumPy Enhancement Proposal 1, "A simple file format for NumPy arrays",
// and numpy.lib.format; versions 1.0, 2.0 and 3.0): a magic string, a version, a header length, a
// Python dict literal header ({'descr': '<f4', 'fortran_order': False, 'shape': (344, 403), })
// padded to a 64-byte boundary, then the data. Parsed here by hand, every byte bounds-checked;
// also the writer (version 1.0, little-endian float32, C order).
#include <algorithm>
#include <bit>
#include <cstring>
#include <limits>
#include <optional>
#include <string_view>

#include "base/error.h"
#include "smr/io/io_util.h"
#include "smr/io/mesh_writer.h"
#include "smr/io/npy.h"
#include "smr/io/npy/npy_internal.h"

namespace smr {

namespace npy_io {

using io_util::excerpt;

std::string shape_text(const std::vector<std::size_t>& shape) {
  std::string s = "(";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    if (i > 0) s += ", ";
    s += std::to_string(shape[i]);
  }
  if (shape.size() == 1) s += ",";
  return s + ")";
}

namespace {

// ---------------------------------------------------------------------------------------------
// .npy header: a Python dict literal such as
//   {'descr': '<f4', 'fortran_order': False, 'shape': (344, 403), }

class HeaderParser {
 public:
  HeaderParser(std::string_view text, const std::string& what) : s_(text), what_(what) {}

  void parse(NpyArray& a) {
    std::optional<std::string> descr;
    std::optional<bool> fortran;
    std::optional<std::vector<std::size_t>> shape;
    skip_ws();
    expect('{');
    for (;;) {
      skip_ws();
      if (consume('}')) break;
      const std::string key = parse_string();
      skip_ws();
      expect(':');
      skip_ws();
      if (key == "descr") {
        if (descr) fail("duplicate key 'descr'");
        if (peek() != '\'' && peek() != '"') {
          fail("structured dtypes are not supported (expected a string for 'descr')");
        }
        descr = parse_string();
      } else if (key == "fortran_order") {
        if (fortran) fail("duplicate key 'fortran_order'");
        fortran = parse_bool();
      } else if (key == "shape") {
        if (shape) fail("duplicate key 'shape'");
        shape = parse_shape();
      } else {
        fail("unexpected key '" + excerpt(key, 40) + "'");
      }
      skip_ws();
      if (!consume(',') && peek() != '}') fail("expected ',' or '}'");
    }
    skip_ws();
    if (i_ != s_.size()) fail("unexpected text after the header dictionary");
    if (!descr || !fortran || !shape) {
      fail("the header must have the keys 'descr', 'fortran_order' and 'shape'");
    }
    parse_descr(*descr, a);
    a.fortran_order = *fortran;
    a.shape = std::move(*shape);
  }

 private:
  [[noreturn]] void fail(const std::string& why) const {
    throw_input("'" + what_ + "' has a malformed .npy header: " + why + " (at header offset " +
                std::to_string(i_) + " in \"" + excerpt(s_, 120) + "\")");
  }
  char peek() const { return i_ < s_.size() ? s_[i_] : '\0'; }
  void skip_ws() {
    while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\t' || s_[i_] == '\n' || s_[i_] == '\r'))
      ++i_;
  }
  // Skips c when it is next.
  bool consume(char c) {
    if (peek() != c) return false;
    ++i_;
    return true;
  }
  void expect(char c) {
    if (peek() != c) fail(std::string("expected '") + c + "'");
    ++i_;
  }
  std::string parse_string() {
    const char q = peek();
    if (q != '\'' && q != '"') fail("expected a quoted string");
    ++i_;
    const std::size_t start = i_;
    while (i_ < s_.size() && s_[i_] != q) {
      if (s_[i_] == '\\') fail("escapes in strings are not supported");
      ++i_;
    }
    if (i_ >= s_.size()) fail("unterminated string");
    std::string out(s_.substr(start, i_ - start));
    ++i_;
    return out;
  }
  bool parse_bool() {
    if (s_.substr(i_, 4) == "True") {
      i_ += 4;
      return true;
    }
    if (s_.substr(i_, 5) == "False") {
      i_ += 5;
      return false;
    }
    fail("expected True or False");
  }
  std::vector<std::size_t> parse_shape() {
    std::vector<std::size_t> shape;
    expect('(');
    for (;;) {
      skip_ws();
      if (consume(')')) break;
      if (peek() < '0' || peek() > '9') fail("expected a dimension (a non-negative integer)");
      std::uint64_t v = 0;
      while (peek() >= '0' && peek() <= '9') {
        if (v > (std::uint64_t{1} << 58)) fail("dimension too large");
        v = v * 10 + static_cast<std::uint64_t>(peek() - '0');
        ++i_;
      }
      if (peek() == 'L') ++i_;  // Python 2 long literal
      shape.push_back(static_cast<std::size_t>(v));
      if (shape.size() > 32) fail("more than 32 dimensions");
      skip_ws();
      if (!consume(',') && peek() != ')') fail("expected ',' or ')' in the shape");
    }
    return shape;
  }
  void parse_descr(const std::string& d, NpyArray& a) const {
    const auto unsupported = [&](const std::string& why) {
      throw_input("'" + what_ + "' has an unsupported dtype '" + excerpt(d, 20) + "': " + why +
                  " (supported: bool, int8..int64, uint8..uint64, float32, float64)");
    };
    if (d.size() < 3 || d.size() > 4) unsupported("not a simple dtype");
    const char order = d[0];
    const char kind = d[1];
    int size = 0;
    for (std::size_t k = 2; k < d.size(); ++k) {
      if (d[k] < '0' || d[k] > '9') unsupported("bad item size");
      size = size * 10 + (d[k] - '0');
    }
    if (order != '<' && order != '>' && order != '|' && order != '=') {
      unsupported("bad byte order character");
    }
    switch (kind) {
      case 'b':
        if (size != 1) unsupported("bool must be 1 byte");
        a.kind = NpyKind::kBool;
        break;
      case 'i':
      case 'u':
        if (size != 1 && size != 2 && size != 4 && size != 8) unsupported("bad integer size");
        a.kind = kind == 'i' ? NpyKind::kInt : NpyKind::kUInt;
        break;
      case 'f':
        if (size == 2) unsupported("float16 is not supported");
        if (size != 4 && size != 8) unsupported("bad float size");
        a.kind = NpyKind::kFloat;
        break;
      default:
        unsupported("only bool, integer and float arrays are supported");
    }
    if (order == '|' && size != 1) unsupported("'|' byte order for a multi-byte type");
    a.item_size = size;
    a.big_endian = order == '>' || (order == '=' && std::endian::native == std::endian::big);
  }

  std::string_view s_;
  const std::string& what_;
  std::size_t i_ = 0;
};

}  // namespace

// The array a .npy describes (its `data` left empty) and the offset of its data, from the first
// bytes of the file: `bytes` must hold at least the preamble and the header.
std::pair<NpyArray, std::size_t> parse_npy_header(std::span<const std::uint8_t> bytes,
                                                  const std::string& what) {
  static constexpr std::uint8_t kMagic[6] = {0x93, 'N', 'U', 'M', 'P', 'Y'};
  if (bytes.size() < 10) {
    throw_input("'" + what + "' is not a .npy array: " + std::to_string(bytes.size()) +
                " bytes is shorter than the 10-byte .npy preamble");
  }
  if (!std::equal(std::begin(kMagic), std::end(kMagic), bytes.begin())) {
    throw_input("'" + what + "' is not a .npy array: it does not start with \"\\x93NUMPY\"");
  }
  const int major = bytes[6], minor = bytes[7];
  std::size_t header_len = 0, header_start = 0;
  if (major == 1) {
    header_len = static_cast<std::size_t>(load_le(&bytes[8], 2));
    header_start = 10;
  } else if (major == 2 || major == 3) {
    if (bytes.size() < 12) throw_input("'" + what + "' is truncated inside its .npy preamble");
    header_len = static_cast<std::size_t>(load_le(&bytes[8], 4));
    header_start = 12;
  } else {
    throw_input("'" + what + "' has unsupported .npy format version " + std::to_string(major) +
                "." + std::to_string(minor) + " (expected 1.0, 2.0 or 3.0)");
  }
  if (header_len > bytes.size() - header_start) {
    throw_input("'" + what + "' is truncated: its .npy header claims " +
                std::to_string(header_len) + " bytes but only " +
                std::to_string(bytes.size() - header_start) + " follow");
  }
  const std::string_view header(reinterpret_cast<const char*>(bytes.data() + header_start),
                                header_len);
  NpyArray a;
  HeaderParser(header, what).parse(a);

  // Element count and byte size, with overflow checks.
  std::size_t count = 1;
  for (std::size_t d : a.shape) {
    if (d != 0 && count > std::numeric_limits<std::size_t>::max() / 16 / d) {
      throw_input("'" + what + "' has shape " + shape_text(a.shape) + ", too large");
    }
    count *= d;
  }
  return {a, header_start + header_len};
}

// The byte size of the array's data (checked against overflow by parse_npy_header).
std::size_t data_bytes(const NpyArray& a) {
  return a.count() * static_cast<std::size_t>(a.item_size);
}

// Checks that the `have` bytes after a .npy's header are exactly the array's data.
void check_data_size(const NpyArray& a, std::size_t have, const std::string& what) {
  const std::size_t expected = data_bytes(a);
  if (have != expected) {
    throw_input("'" + what + "' has " + std::to_string(have) + " bytes of array data; expected " +
                std::to_string(expected) + " for shape " + shape_text(a.shape) + " of " +
                a.dtype() + (have < expected ? " (the file is truncated)" : ""));
  }
}

}  // namespace npy_io

using npy_io::load_be;
using npy_io::load_le;

// ---------------------------------------------------------------------------------------------
// NpyArray

std::size_t NpyArray::count() const {
  std::size_t n = 1;
  for (std::size_t d : shape) n *= d;  // overflow is excluded by parse_npy
  return n;
}

std::string NpyArray::dtype() const {
  std::string s;
  s += item_size == 1 ? '|' : (big_endian ? '>' : '<');
  s += kind == NpyKind::kBool   ? 'b'
       : kind == NpyKind::kInt  ? 'i'
       : kind == NpyKind::kUInt ? 'u'
                                : 'f';
  s += std::to_string(item_size);
  return s;
}

double NpyArray::value(std::size_t i) const {
  const std::uint8_t* p = data.data() + i * static_cast<std::size_t>(item_size);
  const std::uint64_t bits = big_endian ? load_be(p, item_size) : load_le(p, item_size);
  switch (kind) {
    case NpyKind::kBool:
      return bits != 0 ? 1.0 : 0.0;
    case NpyKind::kUInt:
      return static_cast<double>(bits);
    case NpyKind::kInt: {
      const int shift = 64 - 8 * item_size;
      return static_cast<double>(static_cast<std::int64_t>(bits << shift) >> shift);
    }
    case NpyKind::kFloat:
      return item_size == 4 ? double(std::bit_cast<float>(static_cast<std::uint32_t>(bits)))
                            : std::bit_cast<double>(bits);
  }
  return 0.0;
}

// ---------------------------------------------------------------------------------------------
// parse_npy

NpyArray parse_npy(std::span<const std::uint8_t> bytes, const std::string& what) {
  auto [a, data_start] = npy_io::parse_npy_header(bytes, what);
  npy_io::check_data_size(a, bytes.size() - data_start, what);
  a.data = bytes.subspan(data_start, npy_io::data_bytes(a));
  return a;
}

// ---------------------------------------------------------------------------------------------
// Writing

std::vector<std::uint8_t> encode_npy(std::span<const float> values, std::size_t rows,
                                     std::size_t cols) {
  std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (" +
                       std::to_string(rows) + ", " + std::to_string(cols) + "), }";
  // Pad with spaces and a newline so that the data starts on a 64-byte boundary.
  const std::size_t total = (10 + header.size() + 1 + 63) / 64 * 64;
  header.append(total - 10 - header.size() - 1, ' ');
  header += '\n';
  std::vector<std::uint8_t> out(10 + header.size() + values.size() * 4);
  const std::uint8_t preamble[8] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0};
  std::memcpy(out.data(), preamble, 8);
  out[8] = static_cast<std::uint8_t>(header.size() & 0xff);
  out[9] = static_cast<std::uint8_t>(header.size() >> 8);
  std::memcpy(out.data() + 10, header.data(), header.size());
  std::uint8_t* p = out.data() + 10 + header.size();
  for (float v : values) {
    const auto bits = std::bit_cast<std::uint32_t>(v);
    for (int k = 0; k < 4; ++k) *p++ = static_cast<std::uint8_t>(bits >> (8 * k));
  }
  return out;
}

void write_npy(const std::string& path, const Heightfield& h) {
  if (h.has_nodata()) {
    throw_input("cannot write '" + path + "': the heightfield '" + h.source +
                "' has no-data samples, which .npy cannot mark (write a GeoTIFF instead)");
  }
  if (h.width <= 0 || h.height <= 0 ||
      h.z.size() != static_cast<std::size_t>(h.width) * static_cast<std::size_t>(h.height)) {
    throw_input("cannot write '" + path + "': the heightfield '" + h.source + "' is " +
                std::to_string(h.width) + " x " + std::to_string(h.height) + " with " +
                std::to_string(h.z.size()) + " samples; expected a non-empty, consistent grid");
  }
  const std::vector<std::uint8_t> bytes =
      encode_npy(h.z, static_cast<std::size_t>(h.height), static_cast<std::size_t>(h.width));
  AtomicFile file(path);
  file.write(bytes.data(), bytes.size());
  file.commit();
}

}  // namespace smr
