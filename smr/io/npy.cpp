// NumPy .npy / .npz codec (formats: numpy.lib.format, PKWARE APPNOTE.TXT 6.3.x section 4).
// Everything read from the input is bounds-checked; every malformed thing throws kInvalidInput.
#include "smr/io/npy.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string_view>
#include <tuple>
#include <utility>

#include "base/error.h"
#include "smr/io/dem_reader.h"
#include "smr/io/mesh_writer.h"

namespace smr {

namespace {

// ---------------------------------------------------------------------------------------------
// Small helpers

std::uint64_t load_le(const std::uint8_t* p, int n) {
  std::uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

std::uint64_t load_be(const std::uint8_t* p, int n) {
  std::uint64_t v = 0;
  for (int i = 0; i < n; ++i) v = (v << 8) | p[i];
  return v;
}

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

// Printable excerpt of untrusted text for error messages.
std::string excerpt(std::string_view s, std::size_t max = 80) {
  std::string out;
  for (std::size_t i = 0; i < s.size() && i < max; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02x", c);
      out += hex;
    }
  }
  if (s.size() > max) out += "...";
  return out;
}

std::string shape_text(const std::vector<std::size_t>& shape) {
  std::string s = "(";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    if (i > 0) s += ", ";
    s += std::to_string(shape[i]);
  }
  if (shape.size() == 1) s += ",";
  return s + ")";
}

// A missing path is kIo, a directory kInvalidInput, both naming the path.
void check_is_file(const std::string& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (!std::filesystem::exists(status)) {
    throw_io("cannot open '" + path + "': no such file");
  }
  if (std::filesystem::is_directory(status)) {
    throw_input("cannot read '" + path + "': it is a directory, expected a file");
  }
}

std::vector<std::uint8_t> read_file_bytes(const std::string& path) {
  check_is_file(path);
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) throw_io("cannot open '" + path + "': " + std::strerror(errno));
  std::vector<std::uint8_t> bytes;
  std::uint8_t chunk[1 << 16];
  for (;;) {
    const std::size_t n = std::fread(chunk, 1, sizeof chunk, f);
    bytes.insert(bytes.end(), chunk, chunk + n);
    if (n < sizeof chunk) break;
  }
  const bool failed = std::ferror(f) != 0;
  const int err = errno;
  std::fclose(f);
  if (failed) throw_io("cannot read '" + path + "': " + std::strerror(err));
  return bytes;
}

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
      if (peek() == '}') {
        ++i_;
        break;
      }
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
      if (peek() == ',') {
        ++i_;
      } else if (peek() != '}') {
        fail("expected ',' or '}'");
      }
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
      if (peek() == ')') {
        ++i_;
        break;
      }
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
      if (peek() == ',') {
        ++i_;
      } else if (peek() != ')') {
        fail("expected ',' or ')' in the shape");
      }
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

// ---------------------------------------------------------------------------------------------
// Conversion of a 2-D array to heightfield samples (array order: z row r = array row r).

struct Grid {
  int width = 0, height = 0;
  std::vector<float> z;
};

[[noreturn]] void bad_sample(const std::string& what, std::size_t r, std::size_t c,
                             const std::string& why) {
  throw_input("'" + what + "' has " + why + " at index [" + std::to_string(r) + ", " +
              std::to_string(c) + "]; expected finite elevations");
}

bool integer_fits_float(std::uint64_t magnitude) {
  if (magnitude <= (std::uint64_t{1} << 24)) return true;
  magnitude >>= std::countr_zero(magnitude);
  return magnitude < (std::uint64_t{1} << 24);
}

// The (rows, cols) of a 2-D array that fits a heightfield.
std::pair<std::size_t, std::size_t> grid_shape(const NpyArray& a, const std::string& what) {
  if (a.shape.size() != 2) {
    throw_input("'" + what + "' has shape " + shape_text(a.shape) +
                "; expected a 2-D array (rows, cols) of elevations");
  }
  const std::size_t rows = a.shape[0], cols = a.shape[1];
  if (rows == 0 || cols == 0) {
    throw_input("'" + what + "' is empty (shape " + shape_text(a.shape) +
                "); expected at least one row and one column");
  }
  if (rows > static_cast<std::size_t>(INT_MAX) || cols > static_cast<std::size_t>(INT_MAX)) {
    throw_input("'" + what + "' has shape " + shape_text(a.shape) +
                ", too large for a heightfield");
  }
  return {rows, cols};
}

// True when the elements are native float32s, which are copied as they are.
bool native_float32(const NpyArray& a) {
  return a.kind == NpyKind::kFloat && a.item_size == 4 &&
         a.big_endian == (std::endian::native == std::endian::big);
}

// Checks that float32 samples are finite: z[i] is elevation [r0 + i / w, c0 + i % w].
void check_finite(std::span<const float> z, std::size_t r0, std::size_t c0, std::size_t w,
                  const std::string& what) {
  for (std::size_t i = 0; i < z.size(); ++i) {
    if (!std::isfinite(z[i])) {
      bad_sample(what, r0 + i / w, c0 + i % w, std::isnan(z[i]) ? "NaN" : "an infinite value");
    }
  }
}

// The element at `p` of array `a` as a float32 elevation; (r, c) name it in errors.
float element(const NpyArray& a, const std::uint8_t* p, const std::string& what, std::size_t r,
              std::size_t c) {
  const int n = a.item_size;
  const std::uint64_t bits = a.big_endian ? load_be(p, n) : load_le(p, n);
  switch (a.kind) {
    case NpyKind::kFloat: {
      const double v = n == 4 ? double(std::bit_cast<float>(static_cast<std::uint32_t>(bits)))
                              : std::bit_cast<double>(bits);
      if (std::isnan(v)) bad_sample(what, r, c, "NaN");
      if (std::isinf(v)) bad_sample(what, r, c, "an infinite value");
      if (std::fabs(v) > double(std::numeric_limits<float>::max())) {
        bad_sample(what, r, c, "a value outside the float32 range");
      }
      return static_cast<float>(v);
    }
    case NpyKind::kBool:
      return bits != 0 ? 1.0f : 0.0f;
    case NpyKind::kUInt:
      if (!integer_fits_float(bits)) {
        bad_sample(what, r, c, "the integer " + std::to_string(bits) + ", not exactly a float32");
      }
      return static_cast<float>(bits);
    case NpyKind::kInt: {
      const int shift = 64 - 8 * n;
      const std::int64_t v = static_cast<std::int64_t>(bits << shift) >> shift;  // sign-extend
      const std::uint64_t magnitude =
          v < 0 ? static_cast<std::uint64_t>(-(v + 1)) + 1 : static_cast<std::uint64_t>(v);
      if (!integer_fits_float(magnitude)) {
        bad_sample(what, r, c, "the integer " + std::to_string(v) + ", not exactly a float32");
      }
      return static_cast<float>(v);
    }
  }
  return 0.0f;  // unreachable: every kind is handled above
}

Grid to_grid(const NpyArray& a, const std::string& what) {
  const auto [rows, cols] = grid_shape(a, what);
  Grid g;
  g.width = static_cast<int>(cols);
  g.height = static_cast<int>(rows);
  g.z.resize(rows * cols);
  const std::uint8_t* base = a.data.data();
  if (native_float32(a) && !a.fortran_order) {
    std::memcpy(g.z.data(), base, g.z.size() * sizeof(float));  // the common case
    check_finite(g.z, 0, 0, cols, what);
    return g;
  }
  const auto n = static_cast<std::size_t>(a.item_size);
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t c = 0; c < cols; ++c) {
      const std::size_t i = a.fortran_order ? c * rows + r : r * cols + c;
      g.z[r * cols + c] = element(a, base + i * n, what, r, c);
    }
  }
  return g;
}

void flip_rows(Grid& g) {
  const auto w = static_cast<std::size_t>(g.width);
  for (int r = 0, s = g.height - 1; r < s; ++r, --s) {
    std::swap_ranges(g.z.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(r) * w),
                     g.z.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(r + 1) * w),
                     g.z.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(s) * w));
  }
}

Heightfield to_heightfield(Grid g, const std::string& source) {
  Heightfield h;
  h.width = g.width;
  h.height = g.height;
  h.z = std::move(g.z);
  h.source = source;
  return h;
}

// ---------------------------------------------------------------------------------------------
// zip

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

// ---------------------------------------------------------------------------------------------
// .npz georeferencing

const NpyArray* find(const std::map<std::string, NpyArray>& arrays, const std::string& name) {
  const auto it = arrays.find(name);
  return it == arrays.end() ? nullptr : &it->second;
}

double scalar(const NpyArray& a, const std::string& what) {
  if (a.count() != 1 || a.shape.size() > 1) {
    throw_input("'" + what + "' has shape " + shape_text(a.shape) + "; expected a scalar");
  }
  const double v = a.value(0);
  if (!std::isfinite(v)) throw_input("'" + what + "' is not finite; expected a number");
  return v;
}

// Origin and spacing of one axis given by an extent [lo, hi] and a spacing d for n samples.
void axis_from_extent(double a, double b, double d, std::size_t n, const std::string& what,
                      double& origin) {
  const double lo = std::min(a, b), span = std::fabs(b - a);
  const double nd = static_cast<double>(n);
  if (!(d > 0.0)) throw_input(what + ": the spacing must be positive");
  if (std::fabs(span - nd * d) <= 0.01 * d) {
    origin = lo + 0.5 * d;  // extent = cell edges
  } else if (n > 1 && std::fabs(span - (nd - 1.0) * d) <= 0.01 * d) {
    origin = lo;  // extent = sample centres
  } else {
    throw_input(what + ": the extent " + std::to_string(span) + " does not match " +
                std::to_string(n) + " samples at spacing " + std::to_string(d) +
                " (expected n * d for cell edges or (n - 1) * d for sample centres)");
  }
}

struct AxisFit {
  double first = 0.0, step = 0.0;
};

AxisFit fit_axis(const NpyArray& a, std::size_t n, const std::string& what, bool allow_decreasing) {
  if (a.shape.size() != 1 || a.shape[0] != n) {
    throw_input("'" + what + "' has shape " + shape_text(a.shape) + "; expected (" +
                std::to_string(n) + ",) to match the elevation array");
  }
  std::vector<double> v(n);
  for (std::size_t i = 0; i < n; ++i) {
    v[i] = a.value(i);
    if (!std::isfinite(v[i])) {
      throw_input("'" + what + "' has a non-finite value at index " + std::to_string(i));
    }
  }
  AxisFit fit{v[0], 0.0};
  if (n == 1) return fit;
  fit.step = (v[n - 1] - v[0]) / static_cast<double>(n - 1);
  if (fit.step == 0.0 || (!allow_decreasing && fit.step < 0.0)) {
    throw_input("'" + what + "' must be strictly " +
                std::string(allow_decreasing ? "monotonic" : "increasing"));
  }
  for (std::size_t i = 1; i < n; ++i) {
    if ((v[i] - v[i - 1]) * fit.step <= 0.0) {
      throw_input("'" + what + "' is not strictly monotonic at index " + std::to_string(i));
    }
  }
  for (std::size_t i = 0; i < n; ++i) {
    const double dev = std::fabs(v[i] - (v[0] + static_cast<double>(i) * fit.step));
    if (dev > 0.5 * std::fabs(fit.step)) {
      throw_input("'" + what + "' is not uniformly spaced: value " + std::to_string(i) + " is " +
                  std::to_string(dev / std::fabs(fit.step)) +
                  " cells from a uniform grid (expected at most 0.5)");
    }
  }
  return fit;
}

}  // namespace

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

namespace {

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

}  // namespace

NpyArray parse_npy(std::span<const std::uint8_t> bytes, const std::string& what) {
  auto [a, data_start] = parse_npy_header(bytes, what);
  check_data_size(a, bytes.size() - data_start, what);
  a.data = bytes.subspan(data_start, data_bytes(a));
  return a;
}

// ---------------------------------------------------------------------------------------------
// unpack_npz

std::vector<NpzMember> unpack_npz(std::span<const std::uint8_t> bytes, const std::string& what) {
  const Bytes b(bytes, what);
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
  std::uint64_t entries = b.u16(e + 10);
  std::uint64_t cd_size = b.u32(e + 12);
  std::uint64_t cd_offset = b.u32(e + 16);
  if (entries == 0xffff || cd_size == 0xffffffff || cd_offset == 0xffffffff) {
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
    entries = b.u64(r + 32);
    cd_size = b.u64(r + 40);
    cd_offset = b.u64(r + 48);
  }
  if (cd_offset > b.size() || cd_size > b.size() - cd_offset) {
    throw_input("'" + what + "' is truncated or corrupt: its central directory (" +
                std::to_string(cd_size) + " bytes at " + std::to_string(cd_offset) +
                ") lies outside the " + std::to_string(b.size()) + "-byte file");
  }
  if (entries > cd_size / 46) {
    throw_input("'" + what + "' is corrupt: " + std::to_string(entries) +
                " entries cannot fit in a " + std::to_string(cd_size) + "-byte central directory");
  }

  std::vector<NpzMember> members;
  std::size_t p = static_cast<std::size_t>(cd_offset);
  const std::size_t cd_end = static_cast<std::size_t>(cd_offset + cd_size);
  for (std::uint64_t k = 0; k < entries; ++k) {
    if (p + 46 > cd_end) throw_input("'" + what + "' is corrupt: central directory overrun");
    if (b.u32(p) != kCentralSig) {
      throw_input("'" + what + "' is corrupt: bad central directory entry " + std::to_string(k) +
                  " at byte " + std::to_string(p));
    }
    const std::uint16_t flags = b.u16(p + 8);
    const std::uint16_t method = b.u16(p + 10);
    const std::uint32_t crc = b.u32(p + 16);
    std::uint64_t csize = b.u32(p + 20);
    std::uint64_t usize = b.u32(p + 24);
    const std::size_t name_len = b.u16(p + 28), extra_len = b.u16(p + 30),
                      comment_len = b.u16(p + 32);
    std::uint64_t local = b.u32(p + 42);
    const std::size_t entry_len = 46 + name_len + extra_len + comment_len;
    if (entry_len > cd_end - p) throw_input("'" + what + "' is corrupt: central directory overrun");
    const std::string name(reinterpret_cast<const char*>(bytes.data() + p + 46), name_len);
    const std::string member = "'" + what + "' member '" + excerpt(name, 100) + "'";
    // zip64 extended information extra field.
    for (std::size_t x = p + 46 + name_len, xe = x + extra_len; x + 4 <= xe;) {
      const std::uint16_t id = b.u16(x), len = b.u16(x + 2);
      if (len > xe - x - 4) throw_input(member + " has a corrupt extra field");
      if (id == 0x0001) {
        std::size_t f = x + 4;
        const std::size_t fe = f + len;
        const auto take = [&](std::uint64_t& v) {
          if (f + 8 > fe) throw_input(member + " has a short zip64 extra field");
          v = b.u64(f);
          f += 8;
        };
        if (usize == 0xffffffff) take(usize);
        if (csize == 0xffffffff) take(csize);
        if (local == 0xffffffff) take(local);
      }
      x += 4 + static_cast<std::size_t>(len);
    }
    p += entry_len;

    if (name.size() < 4 || name.compare(name.size() - 4, 4, ".npy") != 0) continue;
    if (flags & 0x1) throw_input(member + " is encrypted; expected a plain .npz");
    if (method != 0 && method != 8) {
      throw_input(member + " uses compression method " + std::to_string(method) +
                  "; expected 0 (stored) or 8 (deflate)");
    }
    // Local header: check it and skip its own name and extra field.
    if (local > b.size()) throw_input(member + " has a local header offset beyond the file");
    const auto lh = static_cast<std::size_t>(local);
    b.need(lh, 30, "local file header");
    if (b.u32(lh) != kLocalSig) {
      throw_input(member + " has no local file header at byte " + std::to_string(lh));
    }
    const std::size_t lname = b.u16(lh + 26), lextra = b.u16(lh + 28);
    b.need(lh + 30, lname + lextra, "local file header");
    if (lname != name_len || std::memcmp(bytes.data() + lh + 30, name.data(), name_len) != 0) {
      throw_input(member + ": the local header names a different file");
    }
    const std::size_t data_start = lh + 30 + lname + lextra;
    if (csize > b.size() - data_start) {
      throw_input(member + " is truncated: " + std::to_string(csize) +
                  " compressed bytes declared but the file ends first");
    }
    const auto data = b.sub(data_start, static_cast<std::size_t>(csize));
    NpzMember m;
    m.name = name.substr(0, name.size() - 4);
    for (const NpzMember& other : members) {
      if (other.name == m.name) throw_input(member + " appears twice in the archive");
    }
    if (method == 0) {
      if (usize != csize) {
        throw_input(member + " is stored with different compressed (" + std::to_string(csize) +
                    ") and uncompressed (" + std::to_string(usize) + ") sizes");
      }
      m.bytes.assign(data.begin(), data.end());
    } else {
      // Deflate cannot expand more than ~1032:1; a larger claim is corrupt (and would be a
      // memory bomb).
      if (usize > csize * 1032 + 64) {
        throw_input(member + " claims " + std::to_string(usize) + " bytes from " +
                    std::to_string(csize) + " compressed bytes, more than deflate can produce");
      }
      m.bytes = inflate_raw(data, usize, member);
    }
    if (crc32_of(m.bytes) != crc) throw_input(member + " fails its CRC-32 check");
    members.push_back(std::move(m));
  }
  return members;
}

// ---------------------------------------------------------------------------------------------
// Heightfields

Heightfield heightfield_from_npy(std::span<const std::uint8_t> bytes, const std::string& what) {
  const NpyArray a = parse_npy(bytes, what);
  return to_heightfield(to_grid(a, what), what);
}

Heightfield heightfield_from_npz(std::span<const std::uint8_t> bytes, const std::string& what) {
  const std::vector<NpzMember> members = unpack_npz(bytes, what);
  std::map<std::string, NpyArray> arrays;
  for (const NpzMember& m : members) arrays[m.name] = parse_npy(m.bytes, what + ":" + m.name);

  // The elevation array.
  std::vector<std::string> grids;
  for (const auto& [name, a] : arrays) {
    if (a.shape.size() == 2) grids.push_back(name);
  }
  std::string elevation;
  if (grids.size() == 1) {
    elevation = grids[0];
  } else {
    for (const char* preferred : {"elevation", "topo", "z"}) {
      if (std::find(grids.begin(), grids.end(), preferred) != grids.end()) {
        elevation = preferred;
        break;
      }
    }
  }
  if (elevation.empty()) {
    std::string list;
    for (const auto& [name, a] : arrays) {
      list += (list.empty() ? "" : ", ") + excerpt(name, 40) + shape_text(a.shape);
    }
    throw_input("'" + what + "' has " + (grids.empty() ? "no" : std::to_string(grids.size())) +
                " 2-D arrays; expected exactly one, or one named 'elevation', 'topo' or 'z' "
                "(arrays: " +
                (list.empty() ? "none" : list) + ")");
  }
  const std::string elev_what = what + ":" + elevation;
  Grid g = to_grid(arrays.at(elevation), elev_what);
  const auto cols = static_cast<std::size_t>(g.width), rows = static_cast<std::size_t>(g.height);
  Georef geo;

  static const char* const kExtent[] = {"xmin", "xmax", "ymin", "ymax", "dx", "dy"};
  int extent_count = 0;
  for (const char* name : kExtent) extent_count += find(arrays, name) != nullptr ? 1 : 0;
  const NpyArray* lon = find(arrays, "longitude");
  const NpyArray* lat = find(arrays, "latitude");

  if (extent_count > 0) {
    double v[6];
    for (int k = 0; k < 6; ++k) {
      const NpyArray* a = find(arrays, kExtent[k]);
      if (a == nullptr) {
        throw_input("'" + what +
                    "' has some of the arrays xmin, xmax, ymin, ymax, dx, dy but not '" +
                    kExtent[k] + "'; expected all six for georeferencing");
      }
      v[k] = scalar(*a, what + ":" + kExtent[k]);
    }
    geo.dx = v[4];
    geo.dy = v[5];
    axis_from_extent(v[0], v[1], geo.dx, cols, "'" + what + "' xmin/xmax/dx", geo.x0);
    axis_from_extent(v[2], v[3], geo.dy, rows, "'" + what + "' ymin/ymax/dy", geo.y0);
    const double xlo = std::min(v[0], v[1]), xhi = std::max(v[0], v[1]);
    const double ylo = std::min(v[2], v[3]), yhi = std::max(v[2], v[3]);
    geo.geographic = xlo >= -360.0 && xhi <= 360.0 && ylo >= -90.0 && yhi <= 90.0 && geo.dx < 0.1 &&
                     geo.dy < 0.1;
    flip_rows(g);  // image order: array row 0 is the northern row
  } else if (lon != nullptr || lat != nullptr) {
    if (lon == nullptr || lat == nullptr) {
      throw_input("'" + what + "' has only one of the arrays 'longitude' and 'latitude'; " +
                  "expected both for georeferencing");
    }
    const AxisFit fx = fit_axis(*lon, cols, what + ":longitude", false);
    const AxisFit fy = fit_axis(*lat, rows, what + ":latitude", true);
    geo.dx = fx.step != 0.0 ? fx.step : (fy.step != 0.0 ? std::fabs(fy.step) : 1.0);
    geo.dy = fy.step != 0.0 ? std::fabs(fy.step) : geo.dx;
    geo.x0 = fx.first;
    if (fy.step < 0.0) {
      geo.y0 = fy.first + fy.step * static_cast<double>(rows - 1);
      flip_rows(g);
    } else {
      geo.y0 = fy.first;
    }
    geo.geographic = true;
  }
  Heightfield h = to_heightfield(std::move(g), what);
  h.georef = geo;
  return h;
}

Heightfield read_npy(const std::string& path) {
  const std::vector<std::uint8_t> bytes = read_file_bytes(path);
  return heightfield_from_npy(bytes, path);
}

namespace {

// A plain .npy read by windows: each window's rows (or, in Fortran order, columns) are read with
// pread, converted and checked like read_npy's whole array, so no more than a window of the file
// is ever in memory. pread keeps reads from several threads independent.
class NpyWindows final : public RasterWindows {
 public:
  explicit NpyWindows(const std::string& path) : path_(path) {
    check_is_file(path);
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw_io("cannot open '" + path + "': " + std::strerror(errno));
    try {
      open_header();
    } catch (...) {
      ::close(fd_);
      throw;
    }
  }
  ~NpyWindows() override { ::close(fd_); }
  NpyWindows(const NpyWindows&) = delete;
  NpyWindows& operator=(const NpyWindows&) = delete;

  int width() const override { return static_cast<int>(cols_); }
  int height() const override { return static_cast<int>(rows_); }
  const Georef& georef() const override { return georef_; }  // a plain .npy has none
  const std::string& source() const override { return path_; }

  bool random_access() const override { return true; }

  Heightfield read(int col0, int row0, int w, int h) const override {
    Heightfield out;
    read_into(out, col0, row0, w, h);
    return out;
  }

  void read_into(Heightfield& out, int col0, int row0, int w, int h) const override {
    if (col0 < 0 || row0 < 0 || w <= 0 || h <= 0 || col0 > width() - w || row0 > height() - h) {
      throw_input("window " + std::to_string(w) + " x " + std::to_string(h) + " at (" +
                  std::to_string(col0) + ", " + std::to_string(row0) + ") is outside '" + path_ +
                  "' (" + std::to_string(cols_) + " x " + std::to_string(rows_) + ")");
    }
    set_window_header(out, georef_, path_, col0, row0, w, h);  // its pages, already faulted in
    out.valid.clear();  // a plain .npy has no no-data samples
    const auto c0 = static_cast<std::size_t>(col0), r0 = static_cast<std::size_t>(row0);
    const auto ww = static_cast<std::size_t>(w), hh = static_cast<std::size_t>(h);
    out.z.resize(ww * hh);
    const auto n = static_cast<std::size_t>(array_.item_size);
    if (!array_.fortran_order) {  // row by row
      std::vector<std::uint8_t> row(native_float32(array_) ? 0 : ww * n);
      for (std::size_t r = 0; r < hh; ++r) {
        const std::size_t at = ((r0 + r) * cols_ + c0) * n;
        float* z = out.z.data() + r * ww;
        if (row.empty()) {
          read_exactly(reinterpret_cast<std::uint8_t*>(z), ww * n, at);
          check_finite({z, ww}, r0 + r, c0, ww, path_);
          continue;
        }
        read_exactly(row.data(), row.size(), at);
        for (std::size_t c = 0; c < ww; ++c) {
          z[c] = element(array_, row.data() + c * n, path_, r0 + r, c0 + c);
        }
      }
    } else {  // column by column
      std::vector<std::uint8_t> column(hh * n);
      for (std::size_t c = 0; c < ww; ++c) {
        read_exactly(column.data(), column.size(), ((c0 + c) * rows_ + r0) * n);
        for (std::size_t r = 0; r < hh; ++r) {
          out.z[r * ww + c] = element(array_, column.data() + r * n, path_, r0 + r, c0 + c);
        }
      }
    }
  }

 private:
  void open_header() {
    struct stat st {};
    if (::fstat(fd_, &st) != 0) throw_io("cannot stat '" + path_ + "': " + std::strerror(errno));
    file_size_ = static_cast<std::uint64_t>(st.st_size);
    // The preamble, then the header whose length it gives (parse_npy_header reports a header
    // longer than the file).
    std::vector<std::uint8_t> head(std::min<std::uint64_t>(12, file_size_));
    read_at(head.data(), head.size(), 0);
    std::size_t need = head.size();
    if (head.size() >= 10 && head[6] == 1) {
      need = 10 + static_cast<std::size_t>(load_le(&head[8], 2));
    } else if (head.size() >= 12 && (head[6] == 2 || head[6] == 3)) {
      need = 12 + static_cast<std::size_t>(load_le(&head[8], 4));
    }
    head.resize(std::min<std::uint64_t>(need, file_size_));
    read_at(head.data(), head.size(), 0);
    auto [a, data_start] = parse_npy_header(head, path_);
    array_ = std::move(a);
    std::tie(rows_, cols_) = grid_shape(array_, path_);
    check_data_size(array_, file_size_ - data_start, path_);
    data_start_ = data_start;
  }

  // Reads n bytes at byte `at` of the file; the file ending first is an error.
  void read_at(std::uint8_t* out, std::size_t n, std::uint64_t at) const {
    for (std::size_t done = 0; done < n;) {
      const ssize_t got = ::pread(fd_, out + done, n - done, static_cast<off_t>(at + done));
      if (got < 0 && errno == EINTR) continue;
      if (got < 0) throw_io("cannot read '" + path_ + "': " + std::strerror(errno));
      if (got == 0) {
        throw_io("'" + path_ + "' ended at byte " + std::to_string(at + done) +
                 " while it was read (was it truncated meanwhile?)");
      }
      done += static_cast<std::size_t>(got);
    }
  }

  void read_exactly(std::uint8_t* out, std::size_t n, std::uint64_t data_offset) const {
    read_at(out, n, data_start_ + data_offset);
  }

  std::string path_;
  int fd_ = -1;
  std::uint64_t file_size_ = 0;
  NpyArray array_;
  std::size_t rows_ = 0, cols_ = 0, data_start_ = 0;
  Georef georef_;
};

}  // namespace

std::unique_ptr<RasterWindows> open_npy(const std::string& path) {
  return std::make_unique<NpyWindows>(path);
}

Heightfield read_npz(const std::string& path) {
  const std::vector<std::uint8_t> bytes = read_file_bytes(path);
  return heightfield_from_npz(bytes, path);
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
