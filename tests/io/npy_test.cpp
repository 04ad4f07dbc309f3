// Tests of the .npy / .npz readers and the .npy writer (smr/io/npy.h, smr/io/dem_reader.h):
// the real matplotlib samples, every dtype and layout, georeferencing conventions, and a battery
// of malformed inputs (including every truncated prefix, for the sanitizer build).
#include "smr/io/npy.h"

#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>

#include <gtest/gtest.h>

#include "smr/io/dem_reader.h"
#include "smr/io/synthetic.h"
#include "tests/io/io_test_helpers.h"
#include "tests/support/test_data.h"

namespace smr {
namespace {

using test::expect_error;
using test::TempDir;
using Bytes = std::vector<std::uint8_t>;

// ---------------------------------------------------------------------------------------------
// Builders

/// A .npy image with the given header fields and raw data bytes.
Bytes make_npy(const std::string& descr, bool fortran, const std::string& shape, const Bytes& data,
               int version = 1) {
  std::string header = "{'descr': '" + descr +
                       "', 'fortran_order': " + (fortran ? "True" : "False") +
                       ", 'shape': " + shape + ", }";
  const std::size_t pre = version == 1 ? 10 : 12;
  while ((pre + header.size() + 1) % 64 != 0) header += ' ';
  header += '\n';
  Bytes out = {0x93, 'N', 'U', 'M', 'P', 'Y', static_cast<std::uint8_t>(version), 0};
  const auto n = static_cast<std::uint32_t>(header.size());
  out.push_back(static_cast<std::uint8_t>(n));
  out.push_back(static_cast<std::uint8_t>(n >> 8));
  if (version != 1) {
    out.push_back(static_cast<std::uint8_t>(n >> 16));
    out.push_back(static_cast<std::uint8_t>(n >> 24));
  }
  out.insert(out.end(), header.begin(), header.end());
  out.insert(out.end(), data.begin(), data.end());
  return out;
}

/// Encodes values as the elements of dtype `descr` (e.g. ">i4").
Bytes encode(const std::vector<double>& values, const std::string& descr) {
  const bool big = descr[0] == '>';
  const char kind = descr[1];
  const int size = std::stoi(descr.substr(2));
  Bytes out;
  for (double v : values) {
    std::uint64_t bits = 0;
    if (kind == 'f') {
      bits = size == 4 ? std::bit_cast<std::uint32_t>(static_cast<float>(v))
                       : std::bit_cast<std::uint64_t>(v);
    } else if (kind == 'i') {
      bits = static_cast<std::uint64_t>(static_cast<std::int64_t>(v));
    } else {
      bits = static_cast<std::uint64_t>(v);
    }
    for (int k = 0; k < size; ++k) {
      const int shift = 8 * (big ? size - 1 - k : k);
      out.push_back(static_cast<std::uint8_t>(bits >> shift));
    }
  }
  return out;
}

Bytes npy_f8_scalar(double v) {
  return make_npy("<f8", false, "()", encode({v}, "<f8"));
}

Bytes deflate_raw(const Bytes& in) {
  z_stream s{};
  EXPECT_EQ(deflateInit2(&s, 9, Z_DEFLATED, -MAX_WBITS, 8, Z_DEFAULT_STRATEGY), Z_OK);
  Bytes out(deflateBound(&s, static_cast<uLong>(in.size())) + 16);
  s.next_in = const_cast<Bytef*>(in.data());
  s.avail_in = static_cast<uInt>(in.size());
  s.next_out = out.data();
  s.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(deflate(&s, Z_FINISH), Z_STREAM_END);
  out.resize(s.total_out);
  deflateEnd(&s);
  return out;
}

struct ZipEntry {
  std::string name;    // member name, e.g. "elevation.npy"
  Bytes data;          // uncompressed
  int method = 0;      // 0 stored, 8 deflate
  bool zip64 = false;  // sizes and offset in a zip64 extra field of the central directory
};

void put16(Bytes& b, std::uint32_t v) {
  b.push_back(static_cast<std::uint8_t>(v));
  b.push_back(static_cast<std::uint8_t>(v >> 8));
}
void put32(Bytes& b, std::uint32_t v) {
  put16(b, v & 0xffff);
  put16(b, v >> 16);
}
void put64(Bytes& b, std::uint64_t v) {
  put32(b, static_cast<std::uint32_t>(v));
  put32(b, static_cast<std::uint32_t>(v >> 32));
}

Bytes make_zip(const std::vector<ZipEntry>& entries) {
  Bytes out, central;
  for (const ZipEntry& e : entries) {
    const Bytes packed = e.method == 8 ? deflate_raw(e.data) : e.data;
    const auto crc =
        static_cast<std::uint32_t>(crc32(0, e.data.data(), static_cast<uInt>(e.data.size())));
    const auto offset = static_cast<std::uint32_t>(out.size());
    put32(out, 0x04034b50);
    put16(out, 20);
    put16(out, 0);
    put16(out, static_cast<std::uint32_t>(e.method));
    put16(out, 0);
    put16(out, 0x21);
    put32(out, crc);
    put32(out, static_cast<std::uint32_t>(packed.size()));
    put32(out, static_cast<std::uint32_t>(e.data.size()));
    put16(out, static_cast<std::uint32_t>(e.name.size()));
    put16(out, 0);
    out.insert(out.end(), e.name.begin(), e.name.end());
    out.insert(out.end(), packed.begin(), packed.end());

    put32(central, 0x02014b50);
    put16(central, 45);
    put16(central, 20);
    put16(central, 0);
    put16(central, static_cast<std::uint32_t>(e.method));
    put16(central, 0);
    put16(central, 0x21);
    put32(central, crc);
    put32(central, e.zip64 ? 0xffffffffu : static_cast<std::uint32_t>(packed.size()));
    put32(central, e.zip64 ? 0xffffffffu : static_cast<std::uint32_t>(e.data.size()));
    put16(central, static_cast<std::uint32_t>(e.name.size()));
    put16(central, e.zip64 ? 28 : 0);
    put16(central, 0);
    put16(central, 0);
    put16(central, 0);
    put32(central, 0);
    put32(central, e.zip64 ? 0xffffffffu : offset);
    central.insert(central.end(), e.name.begin(), e.name.end());
    if (e.zip64) {
      put16(central, 1);
      put16(central, 24);
      put64(central, e.data.size());
      put64(central, packed.size());
      put64(central, offset);
    }
  }
  const auto cd_offset = static_cast<std::uint32_t>(out.size());
  out.insert(out.end(), central.begin(), central.end());
  put32(out, 0x06054b50);
  put16(out, 0);
  put16(out, 0);
  put16(out, static_cast<std::uint32_t>(entries.size()));
  put16(out, static_cast<std::uint32_t>(entries.size()));
  put32(out, static_cast<std::uint32_t>(central.size()));
  put32(out, cd_offset);
  put16(out, 0);
  return out;
}

/// A 4 x 3 (cols x rows) float32 elevation array: value = 10 * row + col.
Bytes small_elevation_npy() {
  std::vector<double> v;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) v.push_back(10.0 * r + c);
  return make_npy("<f4", false, "(3, 4)", encode(v, "<f4"));
}

/// Runs the npz parser and expects an smr::Error whose message names `what`.
void expect_npz_error(const Bytes& bytes, const std::vector<std::string>& needles) {
  std::vector<std::string> all = needles;
  all.push_back("test.npz");
  expect_error([&] { (void)heightfield_from_npz(bytes, "test.npz"); }, ErrorKind::kInvalidInput,
               all);
}

void expect_npy_error(const Bytes& bytes, const std::vector<std::string>& needles) {
  std::vector<std::string> all = needles;
  all.push_back("test.npy");
  expect_error([&] { (void)heightfield_from_npy(bytes, "test.npy"); }, ErrorKind::kInvalidInput,
               all);
}

float min_z(const Heightfield& h) {
  float m = std::numeric_limits<float>::infinity();
  for (std::size_t i = 0; i < h.z.size(); ++i)
    if (h.valid.empty() || h.valid[i]) m = std::min(m, h.z[i]);
  return m;
}
float max_z(const Heightfield& h) {
  float m = -std::numeric_limits<float>::infinity();
  for (std::size_t i = 0; i < h.z.size(); ++i)
    if (h.valid.empty() || h.valid[i]) m = std::max(m, h.z[i]);
  return m;
}

// ---------------------------------------------------------------------------------------------
// Real data

TEST(Npz, JacksboroShapeGeorefAndOrientation) {
  const std::string path = test::data_path("jacksboro_fault_dem.npz");
  const Heightfield h = read_npz(path);
  EXPECT_EQ(h.width, 403);
  EXPECT_EQ(h.height, 344);
  ASSERT_EQ(h.z.size(), 403u * 344u);
  EXPECT_TRUE(h.valid.empty());
  EXPECT_EQ(h.source, path);
  // Scalars in the file: dx = dy = 1/1200 deg, xmin -84.41375, xmax -84.07791666666667,
  // "ymin" 36.73291666666667 (the northern edge), "ymax" 36.44625; the extent is cell edges.
  const double d = 0.0008333333333333334;
  EXPECT_DOUBLE_EQ(h.georef.dx, d);
  EXPECT_DOUBLE_EQ(h.georef.dy, d);
  EXPECT_NEAR(h.georef.x0, -84.41375 + d / 2, 1e-12);
  EXPECT_NEAR(h.georef.y0, 36.44625 + d / 2, 1e-12);
  EXPECT_NEAR(h.georef.x0 + 402 * d + d / 2, -84.07791666666667, 1e-9);
  EXPECT_NEAR(h.georef.y0 + 343 * d + d / 2, 36.73291666666667, 1e-9);
  EXPECT_TRUE(h.georef.geographic);
  EXPECT_EQ(min_z(h), 236.0f);
  EXPECT_EQ(max_z(h), 1076.0f);
  // Array row 0 is the northern row (image order): elevation[0][0] = 483, [0][402] = 444,
  // [343][0] = 545.
  EXPECT_EQ(h.at(0, 343), 483.0f);
  EXPECT_EQ(h.at(402, 343), 444.0f);
  EXPECT_EQ(h.at(0, 0), 545.0f);
  // read_dem dispatches on the extension.
  const Heightfield d2 = read_dem(path);
  EXPECT_EQ(d2.z, h.z);
  EXPECT_EQ(d2.georef, h.georef);
}

TEST(Npz, TopobathyShapeGeorefAndOrientation) {
  const std::string path = test::data_path("topobathy.npz");
  const Heightfield h = read_dem(path);
  EXPECT_EQ(h.width, 120);
  EXPECT_EQ(h.height, 91);
  EXPECT_TRUE(h.valid.empty());
  // longitude[0] = 234.01669311523438, longitude[119] = 237.9833984375 (float32 values);
  // latitude[0] = 48.0163688659668 increasing to latitude[90] = 49.98418045043945.
  EXPECT_NEAR(h.georef.x0, 234.01669311523438, 1e-9);
  EXPECT_NEAR(h.georef.dx, (237.9833984375 - 234.01669311523438) / 119, 1e-12);
  EXPECT_NEAR(h.georef.y0, 48.0163688659668, 1e-9);
  EXPECT_NEAR(h.georef.dy, (49.98418045043945 - 48.0163688659668) / 90, 1e-12);
  EXPECT_TRUE(h.georef.geographic);
  EXPECT_EQ(min_z(h), -1437.0f);
  EXPECT_EQ(max_z(h), 2205.0f);
  // Latitude increases with the array row, so array row 0 is the southern row: topo[0][0] =
  // -1405, topo[0][119] = 99, topo[90][0] = 989.
  EXPECT_EQ(h.at(0, 0), -1405.0f);
  EXPECT_EQ(h.at(119, 0), 99.0f);
  EXPECT_EQ(h.at(0, 90), 989.0f);
}

TEST(Npz, TruncatedRealFileIsAnErrorNamingTheFile) {
  TempDir dir;
  const Bytes full = test::read_bytes(test::data_path("jacksboro_fault_dem.npz"));
  ASSERT_GT(full.size(), 1000u);
  const std::string path = dir.file("half.npz");
  test::write_bytes(path, Bytes(full.begin(), full.begin() + static_cast<long>(full.size() / 2)));
  expect_error([&] { (void)read_npz(path); }, ErrorKind::kInvalidInput, {path, "truncated"});
}

TEST(Npz, StridedPrefixesOfRealFilesAreErrors) {
  for (const char* name : {"jacksboro_fault_dem.npz", "topobathy.npz"}) {
    const Bytes full = test::read_bytes(test::data_path(name));
    for (std::size_t n = 0; n < full.size(); n += 997) {
      EXPECT_THROW((void)heightfield_from_npz(std::span(full.data(), n), name), Error)
          << name << " prefix " << n;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// .npy

TEST(Npy, WriteReadRoundTripIsExact) {
  TempDir dir;
  const Heightfield h = make_fbm(37, 23, 5);
  const std::string path = dir.file("fbm.npy");
  write_npy(path, h);
  const Heightfield r = read_npy(path);
  EXPECT_EQ(r.width, 37);
  EXPECT_EQ(r.height, 23);
  EXPECT_EQ(r.z, h.z);
  EXPECT_TRUE(r.valid.empty());
  EXPECT_EQ(r.georef, Georef{});
  EXPECT_EQ(r.source, path);
  const Heightfield d = read_dem(path);
  EXPECT_EQ(d.z, h.z);
  // The data starts 64-byte aligned, as NumPy writes it.
  const Bytes bytes = test::read_bytes(path);
  EXPECT_EQ((bytes.size() - 37 * 23 * 4) % 64, 0u);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"fbm.npy"});
}

TEST(Npy, WriteRejectsNoData) {
  TempDir dir;
  Heightfield h = make_fbm(4, 4, 1);
  h.valid.assign(16, 1);
  h.valid[3] = 0;
  expect_error([&] { write_npy(dir.file("x.npy"), h); }, ErrorKind::kInvalidInput,
               {"x.npy", "no-data"});
  EXPECT_TRUE(dir.entries().empty());
}

TEST(Npy, WriteToMissingDirectoryIsIoError) {
  const Heightfield h = make_fbm(4, 4, 1);
  expect_error([&] { write_npy("/nonexistent-smrdb-dir/x.npy", h); }, ErrorKind::kIo,
               {"/nonexistent-smrdb-dir/x.npy"});
}

TEST(Npy, EveryDtypeConvertsExactly) {
  const std::vector<double> values = {1, 2, 3, 4, 5, 6};
  for (const char* descr : {"<i2", ">i2", "<i4", ">i4", "|u1", "|i1", "<u2", ">u2", "<u4", ">u4",
                            "<i8", ">i8", "<u8", ">u8", "<f4", ">f4", "<f8", ">f8"}) {
    SCOPED_TRACE(descr);
    const Heightfield h =
        heightfield_from_npy(make_npy(descr, false, "(2, 3)", encode(values, descr)), "t.npy");
    ASSERT_EQ(h.width, 3);
    ASSERT_EQ(h.height, 2);
    EXPECT_EQ(h.z, std::vector<float>({1, 2, 3, 4, 5, 6}));
    EXPECT_EQ(h.georef, Georef{});
  }
  const Heightfield b = heightfield_from_npy(make_npy("|b1", false, "(1, 3)", {0, 1, 7}), "b.npy");
  EXPECT_EQ(b.z, std::vector<float>({0, 1, 1}));
  // Negative and extreme integers that float32 holds exactly.
  const std::vector<double> ints = {-32768, 32767, -1, 0};
  EXPECT_EQ(heightfield_from_npy(make_npy("<i2", false, "(2, 2)", encode(ints, "<i2")), "i.npy").z,
            std::vector<float>({-32768, 32767, -1, 0}));
  const std::vector<double> big = {std::ldexp(1.0, 40), -std::ldexp(1.0, 63), 16777216, -16777216};
  EXPECT_EQ(heightfield_from_npy(make_npy("<i8", false, "(2, 2)", encode(big, "<i8")), "i8.npy").z,
            std::vector<float>({std::ldexp(1.0f, 40), -std::ldexp(1.0f, 63), 16777216, -16777216}));
}

TEST(Npy, FortranOrderIsTransposed) {
  // Logical array a[r][c] = 10 r + c, shape (2, 3), stored column by column.
  const std::vector<double> column_major = {0, 10, 1, 11, 2, 12};
  for (const char* descr : {"<f4", ">i2"}) {
    const Heightfield h =
        heightfield_from_npy(make_npy(descr, true, "(2, 3)", encode(column_major, descr)), "f.npy");
    ASSERT_EQ(h.width, 3);
    ASSERT_EQ(h.height, 2);
    for (int r = 0; r < 2; ++r)
      for (int c = 0; c < 3; ++c) EXPECT_EQ(h.at(c, r), static_cast<float>(10 * r + c)) << descr;
  }
}

TEST(Npy, Versions2And3AndPython2LongShapes) {
  const Bytes data = encode({1, 2, 3, 4}, "<f4");
  EXPECT_EQ(heightfield_from_npy(make_npy("<f4", false, "(2, 2)", data, 2), "v2.npy").z,
            std::vector<float>({1, 2, 3, 4}));
  EXPECT_EQ(heightfield_from_npy(make_npy("<f4", false, "(2, 2)", data, 3), "v3.npy").z,
            std::vector<float>({1, 2, 3, 4}));
  EXPECT_EQ(heightfield_from_npy(make_npy("<f4", false, "(2L, 2L)", data), "py2.npy").width, 2);
}

TEST(Npy, ParseGivesShapeAndDtype) {
  const Bytes bytes = make_npy(">i4", true, "(2, 3, 4)", encode(std::vector<double>(24, 1), ">i4"));
  const NpyArray a = parse_npy(bytes, "a.npy");
  EXPECT_EQ(a.shape, (std::vector<std::size_t>{2, 3, 4}));
  EXPECT_EQ(a.dtype(), ">i4");
  EXPECT_TRUE(a.fortran_order);
  EXPECT_EQ(a.count(), 24u);
  EXPECT_EQ(a.value(23), 1.0);
}

TEST(Npy, NonFiniteAndInexactSamplesAreErrorsNamingThePosition) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  expect_npy_error(make_npy("<f4", false, "(2, 3)", encode({0, 1, 2, 3, 4, nan}, "<f4")),
                   {"NaN", "[1, 2]"});
  expect_npy_error(make_npy(">f4", false, "(2, 3)", encode({0, 1, 2, 3, 4, nan}, ">f4")),
                   {"NaN", "[1, 2]"});
  expect_npy_error(make_npy("<f8", false, "(2, 2)", encode({0, -inf, 2, 3}, "<f8")),
                   {"infinite", "[0, 1]"});
  expect_npy_error(make_npy("<f8", false, "(1, 2)", encode({0, 1e300}, "<f8")),
                   {"float32 range", "[0, 1]"});
  expect_npy_error(make_npy("<i4", false, "(1, 2)", encode({0, 16777217}, "<i4")),
                   {"16777217", "[0, 1]"});
  expect_npy_error(make_npy("<u8", false, "(1, 1)", encode({18446744073709549568.0}, "<u8")),
                   {});  // 2^64 - 2^11: 53 significant bits, not a float32
}

TEST(Npy, MalformedInputsAreErrors) {
  const Bytes data = encode({1, 2, 3, 4}, "<f4");
  expect_npy_error({}, {"shorter than"});
  expect_npy_error(Bytes(9, 0x93), {"shorter than"});
  expect_npy_error(Bytes(64, 'x'), {"\\x93NUMPY"});
  Bytes v9 = make_npy("<f4", false, "(2, 2)", data);
  v9[6] = 9;
  expect_npy_error(v9, {"version 9.0"});
  Bytes long_header = make_npy("<f4", false, "(2, 2)", data);
  long_header[8] = 0xff;
  long_header[9] = 0xff;
  expect_npy_error(long_header, {"truncated"});
  expect_npy_error(make_npy("<f4", false, "(0, 4)", {}), {"empty"});
  expect_npy_error(make_npy("<f4", false, "(4,)", data), {"2-D"});
  expect_npy_error(make_npy("<f4", false, "(1, 2, 2)", data), {"2-D"});
  expect_npy_error(make_npy("<f4", false, "()", encode({1}, "<f4")), {"2-D"});
  expect_npy_error(make_npy("<f4", false, "(2, 3)", data), {"expected 24", "truncated"});
  Bytes trailing = make_npy("<f4", false, "(2, 2)", data);
  trailing.push_back(0);
  expect_npy_error(trailing, {"expected 16"});
  expect_npy_error(make_npy("<c8", false, "(2, 2)", data), {"unsupported dtype"});
  expect_npy_error(make_npy("<f2", false, "(2, 2)", data), {"float16"});
  expect_npy_error(make_npy("<U4", false, "(2, 2)", data), {"unsupported dtype"});
  expect_npy_error(make_npy("|f4", false, "(2, 2)", data), {"unsupported dtype"});
  expect_npy_error(make_npy("<f4", false, "(2, -2)", data), {"malformed"});
  expect_npy_error(make_npy("<f4", false, "(99999999999999999999, 2)", data), {"too large"});
  expect_npy_error(make_npy("<f4", false, "(4294967296, 4294967296)", data), {"too large"});

  // Hand-written headers.
  const auto with_header = [&](const std::string& h) {
    std::string text("\x93NUMPY\x01\x00", 8);
    text += static_cast<char>(h.size());
    text += '\0';
    text += h;
    Bytes out(text.begin(), text.end());
    out.insert(out.end(), data.begin(), data.end());
    return out;
  };
  expect_npy_error(with_header("{'descr': '<f4', 'fortran_order': Maybe, 'shape': (2, 2), }"),
                   {"True or False"});
  expect_npy_error(with_header("{'descr': '<f4', 'shape': (2, 2), }"), {"keys"});
  expect_npy_error(with_header("{'descr': '<f4', 'descr': '<f4', 'fortran_order': False, "
                               "'shape': (2, 2)}"),
                   {"duplicate"});
  expect_npy_error(
      with_header("{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (2, 2)}"),
      {"structured"});
  expect_npy_error(with_header("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2), 'x': 1}"),
                   {"unexpected key"});
  expect_npy_error(with_header("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2)} junk"),
                   {"after the header"});
  expect_npy_error(with_header("{'descr': '<f4"), {"unterminated"});
  expect_npy_error(with_header("['descr']"), {"expected '{'"});
  expect_npy_error(with_header(std::string("{'descr\0': '<f4'}", 16)), {"malformed"});
  expect_npy_error(with_header("{\"descr\": \"<f4\", \"fortran_order\": False, \"shape\": (2,2) "),
                   {"expected ',' or '}'"});
}

TEST(Npy, FileErrorsNameTheFile) {
  TempDir dir;
  const std::string missing = dir.file("missing.npy");
  expect_error([&] { (void)read_npy(missing); }, ErrorKind::kIo, {missing, "no such file"});
  expect_error([&] { (void)read_dem(missing); }, ErrorKind::kIo, {missing});
  const std::string empty = dir.file("empty.npy");
  test::write_bytes(empty, {});
  expect_error([&] { (void)read_npy(empty); }, ErrorKind::kInvalidInput, {empty});
  const std::string zero = dir.file("zero-size.npy");
  test::write_bytes(zero, make_npy("<f4", false, "(0, 0)", {}));
  expect_error([&] { (void)read_dem(zero); }, ErrorKind::kInvalidInput, {zero, "empty"});
  const std::string text = dir.file("text.npy");
  test::write_text(text, "this is not an array\n");
  expect_error([&] { (void)read_npy(text); }, ErrorKind::kInvalidInput, {text, "not a .npy"});
  const std::string bogus = dir.file("bogus.npy");
  Bytes b = small_elevation_npy();
  std::memcpy(b.data() + 10, "{'dexx", 6);
  test::write_bytes(bogus, b);
  expect_error([&] { (void)read_npy(bogus); }, ErrorKind::kInvalidInput, {bogus, "header"});
  expect_error([&] { (void)read_npy(dir.path().string()); }, ErrorKind::kInvalidInput,
               {"directory"});
}

TEST(Npy, EveryTruncatedPrefixIsAnError) {
  const std::vector<Bytes> images = {
      small_elevation_npy(),
      make_npy(">i2", true, "(3, 2)", encode({1, 2, 3, 4, 5, 6}, ">i2"), 2),
      make_npy("<f8", false, "(2, 2)", encode({1, 2, 3, 4}, "<f8"), 3),
  };
  for (const Bytes& full : images) {
    ASSERT_NO_THROW((void)heightfield_from_npy(full, "full.npy"));
    for (std::size_t n = 0; n < full.size(); ++n) {
      // A copy of exactly n bytes, so the sanitizer sees any read past the end.
      const Bytes prefix(full.begin(), full.begin() + static_cast<long>(n));
      EXPECT_THROW((void)heightfield_from_npy(prefix, "prefix.npy"), Error) << "prefix " << n;
    }
  }
}

TEST(Npy, MutatedBytesNeverCrash) {
  const Bytes full = small_elevation_npy();
  std::uint64_t state = 12345;
  for (int round = 0; round < 3000; ++round) {
    Bytes b = full;
    for (int k = 0; k < 1 + round % 4; ++k) {
      state = state * 6364136223846793005ULL + 1442695040888963407ULL;
      const std::size_t at = (state >> 33) % std::min<std::size_t>(b.size(), 128);
      b[at] = static_cast<std::uint8_t>(state >> 24);
    }
    try {
      (void)heightfield_from_npy(b, "mutated.npy");
    } catch (const Error&) {
    }
  }
}

// ---------------------------------------------------------------------------------------------
// .npy by windows (open_npy, used by the out-of-core builder)

/// Every window in `windows` read through open_npy(path) equals the same window of the whole
/// array read by read_npy.
void expect_windows_match(const std::string& path, const std::vector<std::array<int, 4>>& windows) {
  const Heightfield whole = read_npy(path);
  const HeightfieldWindows reference(whole);
  const std::unique_ptr<RasterWindows> w = open_npy(path);
  ASSERT_EQ(w->width(), whole.width);
  ASSERT_EQ(w->height(), whole.height);
  EXPECT_EQ(w->georef(), whole.georef);
  EXPECT_EQ(w->source(), path);
  for (const auto& [c0, r0, ww, hh] : windows) {
    SCOPED_TRACE(std::to_string(ww) + "x" + std::to_string(hh) + " at " + std::to_string(c0) + "," +
                 std::to_string(r0));
    const Heightfield got = w->read(c0, r0, ww, hh), want = reference.read(c0, r0, ww, hh);
    EXPECT_EQ(got.z, want.z);
    EXPECT_TRUE(got.valid.empty());
    EXPECT_EQ(got.georef, want.georef);
    EXPECT_EQ(got.width, ww);
    EXPECT_EQ(got.height, hh);
  }
}

TEST(NpyWindows, EveryDtypeOrderAndVersionReadsTheSameSamplesAsTheWholeArray) {
  TempDir dir;
  const std::size_t rows = 23, cols = 37;
  std::vector<double> values(rows * cols);
  for (std::size_t i = 0; i < values.size(); ++i) values[i] = double((i * 7919) % 251) - 100.0;
  // Windows: whole, one sample, a row, a column, corners and interior pieces.
  std::vector<std::array<int, 4>> windows = {{0, 0, 37, 23}, {5, 7, 1, 1},   {0, 22, 37, 1},
                                             {36, 0, 1, 23}, {30, 15, 7, 8}, {0, 0, 16, 16}};
  for (int c0 = 0; c0 < 37; c0 += 9) {
    for (int r0 = 0; r0 < 23; r0 += 6)
      windows.push_back({c0, r0, std::min(10, 37 - c0), std::min(5, 23 - r0)});
  }
  int k = 0;
  for (const std::string descr : {"<f4", ">f4", "<f8", ">i2", "<u2", "|i1", "<i8"}) {
    for (const bool fortran : {false, true}) {
      SCOPED_TRACE(descr + (fortran ? " Fortran order" : " C order"));
      std::vector<double> stored = values;
      if (fortran) {
        for (std::size_t r = 0; r < rows; ++r)
          for (std::size_t c = 0; c < cols; ++c) stored[c * rows + r] = values[r * cols + c];
      }
      if (descr[1] == 'u') {
        for (double& v : stored) v += 100.0;
      }
      const std::string path = dir.file(descr.substr(1) + "_" + std::to_string(k++) + ".npy");
      test::write_bytes(path,
                        make_npy(descr, fortran, "(23, 37)", encode(stored, descr), 1 + k % 3));
      expect_windows_match(path, windows);
    }
  }
}

TEST(NpyWindows, ErrorsNameTheFileAndOnlyTheWindowWithABadSampleFails) {
  TempDir dir;
  const std::string missing = dir.file("missing.npy");
  expect_error([&] { (void)open_npy(missing); }, ErrorKind::kIo, {missing, "no such file"});
  expect_error([&] { (void)open_dem(missing); }, ErrorKind::kIo, {missing});
  expect_error([&] { (void)open_npy(dir.path().string()); }, ErrorKind::kInvalidInput,
               {"directory"});
  const std::string text = dir.file("text.npy");
  test::write_text(text, "this is not an array\n");
  expect_error([&] { (void)open_npy(text); }, ErrorKind::kInvalidInput, {text, "not a .npy"});
  const std::string cube = dir.file("cube.npy");
  test::write_bytes(cube,
                    make_npy("<f4", false, "(2, 2, 2)", encode(std::vector<double>(8, 1), "<f4")));
  expect_error([&] { (void)open_npy(cube); }, ErrorKind::kInvalidInput, {cube, "2-D"});
  const std::string truncated = dir.file("truncated.npy");
  Bytes t = small_elevation_npy();
  t.resize(t.size() - 3);
  test::write_bytes(truncated, t);
  expect_error([&] { (void)open_dem(truncated); }, ErrorKind::kInvalidInput,
               {truncated, "truncated"});

  // A NaN at [2, 3] of a 4 x 5 array: windows without it read; the window with it names it.
  std::vector<double> v(20, 1.0);
  v[2 * 5 + 3] = std::numeric_limits<double>::quiet_NaN();
  for (const char* descr : {"<f4", ">f8"}) {
    const std::string path = dir.file(std::string("nan") + (descr[0] == '<' ? "4" : "8") + ".npy");
    test::write_bytes(path, make_npy(descr, false, "(4, 5)", encode(v, descr)));
    const std::unique_ptr<RasterWindows> w = open_npy(path);
    EXPECT_NO_THROW((void)w->read(0, 0, 5, 2));
    EXPECT_NO_THROW((void)w->read(0, 0, 3, 4));
    expect_error([&] { (void)w->read(1, 1, 4, 3); }, ErrorKind::kInvalidInput,
                 {path, "NaN", "[2, 3]"});
    expect_error([&] { (void)w->read(2, 0, 4, 1); }, ErrorKind::kInvalidInput, {path, "outside"});
  }

  // The file cut short after it was opened: the read that reaches the missing bytes says so.
  const std::string cut = dir.file("cut.npy");
  const Bytes full =
      make_npy("<f4", false, "(64, 64)", encode(std::vector<double>(4096, 2), "<f4"));
  test::write_bytes(cut, full);
  const std::unique_ptr<RasterWindows> w = open_npy(cut);
  test::write_bytes(cut, Bytes(full.begin(), full.begin() + 2048));
  expect_error([&] { (void)w->read(0, 32, 64, 32); }, ErrorKind::kIo, {cut, "ended"});
}

TEST(NpyWindows, EveryTruncatedPrefixIsAnError) {
  TempDir dir;
  const std::string path = dir.file("prefix.npy");
  const Bytes full = make_npy(">i2", true, "(3, 2)", encode({1, 2, 3, 4, 5, 6}, ">i2"), 2);
  for (std::size_t n = 0; n < full.size(); ++n) {
    test::write_bytes(path, Bytes(full.begin(), full.begin() + static_cast<long>(n)));
    EXPECT_THROW(
        {
          const std::unique_ptr<RasterWindows> w = open_npy(path);
          (void)w->read(0, 0, w->width(), w->height());
        },
        Error)
        << "prefix " << n;
  }
}

// ---------------------------------------------------------------------------------------------
// .npz

TEST(Npz, StoredDeflatedAndZip64MembersRead) {
  for (int method : {0, 8}) {
    for (bool zip64 : {false, true}) {
      SCOPED_TRACE(std::to_string(method) + (zip64 ? " zip64" : ""));
      const Bytes zip = make_zip({{"elevation.npy", small_elevation_npy(), method, zip64}});
      const Heightfield h = heightfield_from_npz(zip, "t.npz");
      ASSERT_EQ(h.width, 4);
      ASSERT_EQ(h.height, 3);
      // No georef arrays: rows as stored, unit grid.
      EXPECT_EQ(h.at(3, 2), 23.0f);
      EXPECT_EQ(h.georef, Georef{});
      const std::vector<NpzMember> members = unpack_npz(zip, "t.npz");
      ASSERT_EQ(members.size(), 1u);
      EXPECT_EQ(members[0].name, "elevation");
      EXPECT_EQ(members[0].bytes, small_elevation_npy());
    }
  }
}

TEST(Npz, ChoosesTheElevationArray) {
  const Bytes e = small_elevation_npy();
  const Bytes other = make_npy("<f4", false, "(1, 2)", encode({7, 8}, "<f4"));
  const Bytes line = make_npy("<f4", false, "(2,)", encode({7, 8}, "<f4"));
  // A single 2-D array whatever its name; 1-D and scalar arrays are ignored.
  EXPECT_EQ(heightfield_from_npz(make_zip({{"grid.npy", e}, {"v.npy", line}}), "t.npz").width, 4);
  // Several 2-D arrays: the preferred names win.
  for (const char* name : {"elevation.npy", "topo.npy", "z.npy"}) {
    EXPECT_EQ(heightfield_from_npz(make_zip({{"a.npy", other}, {name, e}}), "t.npz").width, 4);
  }
  expect_npz_error(make_zip({{"a.npy", other}, {"b.npy", e}}),
                   {"2 2-D arrays", "a(1, 2)", "b(3, 4)"});
  expect_npz_error(make_zip({{"v.npy", line}}), {"no 2-D arrays", "v(2,)"});
  expect_npz_error(make_zip({}), {"no 2-D arrays", "none"});
  // Non-.npy members are skipped.
  EXPECT_EQ(heightfield_from_npz(make_zip({{"README", {'h', 'i'}}, {"z.npy", e}}), "t.npz").width,
            4);
  expect_npz_error(make_zip({{"z.npy", e}, {"z.npy", e}}), {"twice"});
}

TEST(Npz, ExtentScalarsGeoreference) {
  const Bytes e = small_elevation_npy();  // 4 cols x 3 rows, array row 0 = north
  const auto zip_with = [&](double xmin, double xmax, double ymin, double ymax, double dx,
                            double dy) {
    return make_zip({{"elevation.npy", e},
                     {"xmin.npy", npy_f8_scalar(xmin)},
                     {"xmax.npy", npy_f8_scalar(xmax)},
                     {"ymin.npy", npy_f8_scalar(ymin)},
                     {"ymax.npy", npy_f8_scalar(ymax)},
                     {"dx.npy", npy_f8_scalar(dx)},
                     {"dy.npy", npy_f8_scalar(dy)}});
  };
  // Cell edges, metric: x in [1000, 1040], y in [500, 530] at 10 m.
  Heightfield h = heightfield_from_npz(zip_with(1000, 1040, 500, 530, 10, 10), "t.npz");
  EXPECT_DOUBLE_EQ(h.georef.x0, 1005);
  EXPECT_DOUBLE_EQ(h.georef.y0, 505);
  EXPECT_FALSE(h.georef.geographic);
  EXPECT_EQ(h.at(0, 2), 0.0f);   // array [0][0] is the north-west corner
  EXPECT_EQ(h.at(3, 0), 23.0f);  // array [2][3] is the south-east corner
  // Sample centres, geographic, ymin/ymax swapped as in jacksboro_fault_dem.npz.
  h = heightfield_from_npz(zip_with(10.0, 10.03, 45.02, 45.0, 0.01, 0.01), "t.npz");
  EXPECT_DOUBLE_EQ(h.georef.x0, 10.0);
  EXPECT_DOUBLE_EQ(h.georef.y0, 45.0);
  EXPECT_TRUE(h.georef.geographic);
  // Inconsistent extent, missing scalar, non-scalar, bad spacing.
  expect_npz_error(zip_with(0, 100, 0, 30, 10, 10), {"xmin/xmax/dx", "4 samples"});
  expect_npz_error(zip_with(0, 40, 0, 30, 10, -10), {"positive"});
  expect_npz_error(make_zip({{"elevation.npy", e}, {"xmin.npy", npy_f8_scalar(0)}}),
                   {"'xmax'", "all six"});
  expect_npz_error(make_zip({{"elevation.npy", e},
                             {"xmin.npy", make_npy("<f8", false, "(2,)", encode({0, 1}, "<f8"))},
                             {"xmax.npy", npy_f8_scalar(1)},
                             {"ymin.npy", npy_f8_scalar(1)},
                             {"ymax.npy", npy_f8_scalar(1)},
                             {"dx.npy", npy_f8_scalar(1)},
                             {"dy.npy", npy_f8_scalar(1)}}),
                   {"test.npz:xmin", "scalar"});
}

TEST(Npz, LongitudeLatitudeGeoreference) {
  const Bytes e = small_elevation_npy();  // 4 cols x 3 rows
  const auto lonlat = [&](const std::vector<double>& lon, const std::vector<double>& lat) {
    return make_zip(
        {{"topo.npy", e},
         {"longitude.npy",
          make_npy("<f8", false, "(" + std::to_string(lon.size()) + ",)", encode(lon, "<f8"))},
         {"latitude.npy",
          make_npy("<f8", false, "(" + std::to_string(lat.size()) + ",)", encode(lat, "<f8"))}});
  };
  // Latitude increasing with the row: rows as stored.
  Heightfield h = heightfield_from_npz(lonlat({1, 2, 3, 4}, {40, 40.5, 41}), "t.npz");
  EXPECT_DOUBLE_EQ(h.georef.x0, 1);
  EXPECT_DOUBLE_EQ(h.georef.dx, 1);
  EXPECT_DOUBLE_EQ(h.georef.y0, 40);
  EXPECT_DOUBLE_EQ(h.georef.dy, 0.5);
  EXPECT_TRUE(h.georef.geographic);
  EXPECT_EQ(h.at(0, 0), 0.0f);
  // Latitude decreasing: flipped, so row 0 holds the southern samples (array row 2).
  h = heightfield_from_npz(lonlat({1, 2, 3, 4}, {41, 40.5, 40}), "t.npz");
  EXPECT_DOUBLE_EQ(h.georef.y0, 40);
  EXPECT_DOUBLE_EQ(h.georef.dy, 0.5);
  EXPECT_EQ(h.at(0, 0), 20.0f);
  EXPECT_EQ(h.at(3, 2), 3.0f);
  // Slightly irregular spacing (under half a cell) is accepted.
  h = heightfield_from_npz(lonlat({1, 2.2, 3.3, 4}, {40, 40.5, 41}), "t.npz");
  EXPECT_DOUBLE_EQ(h.georef.dx, 1);
  expect_npz_error(lonlat({1, 2.9, 3, 4}, {40, 40.5, 41}), {"longitude", "uniformly"});
  expect_npz_error(lonlat({4, 3, 2, 1}, {40, 40.5, 41}), {"longitude", "increasing"});
  expect_npz_error(lonlat({1, 3, 2, 4}, {40, 40.5, 41}), {"longitude", "monotonic"});
  expect_npz_error(lonlat({1, 2, 3}, {40, 40.5, 41}), {"longitude", "(4,)"});
  expect_npz_error(
      make_zip({{"topo.npy", e},
                {"longitude.npy", make_npy("<f8", false, "(4,)", encode({1, 2, 3, 4}, "<f8"))}}),
      {"latitude"});
}

TEST(Npz, CorruptArchivesAreErrors) {
  const Bytes e = small_elevation_npy();
  // Corrupted deflate stream: block type 3 is reserved.
  Bytes z = make_zip({{"elevation.npy", e, 8}});
  z[30 + 13] = 0xff;
  expect_npz_error(z, {"corrupt deflate stream", "elevation.npy"});
  // A flipped data byte fails the CRC.
  z = make_zip({{"elevation.npy", e, 0}});
  z[30 + 13 + 100] ^= 0x55;
  expect_npz_error(z, {"CRC-32", "elevation.npy"});
  // Declared sizes that disagree with the stream.
  z = make_zip({{"elevation.npy", e, 8}});
  z[z.size() - 22 - 13 - 46 + 24] ^= 0x01;  // central directory uncompressed size
  expect_npz_error(z, {"elevation.npy"});
  // A huge claimed size is rejected before any allocation.
  z = make_zip({{"elevation.npy", e, 8}});
  z[z.size() - 22 - 13 - 46 + 27] = 0x7f;
  expect_npz_error(z, {"more than deflate can produce"});
  // Not a zip at all / unsupported features.
  expect_npz_error(Bytes(100, 'a'), {"not a .npz"});
  expect_npz_error({}, {"not a .npz"});
  z = make_zip({{"elevation.npy", e, 0}});
  z[z.size() - 22 - 13 - 46 + 10] = 12;  // bzip2
  expect_npz_error(z, {"compression method 12"});
  z = make_zip({{"elevation.npy", e, 0}});
  z[z.size() - 22 - 13 - 46 + 8] = 1;  // encrypted
  expect_npz_error(z, {"encrypted"});
  z = make_zip({{"elevation.npy", e, 0}});
  z[z.size() - 22 + 16] ^= 0x40;  // central directory offset
  expect_npz_error(z, {"central directory"});
  z = make_zip({{"elevation.npy", e, 0}});
  z[0] = 'X';  // local header signature
  expect_npz_error(z, {"local file header"});
  // A member that is not a valid .npy names the member.
  expect_npz_error(make_zip({{"elevation.npy", {1, 2, 3}}}), {"test.npz:elevation"});
}

TEST(Npz, FileErrorsNameTheFile) {
  TempDir dir;
  const std::string missing = dir.file("none.npz");
  expect_error([&] { (void)read_npz(missing); }, ErrorKind::kIo, {missing});
  const std::string text = dir.file("text.npz");
  test::write_text(text, "not a zip archive\n");
  expect_error([&] { (void)read_dem(text); }, ErrorKind::kInvalidInput, {text, "not a .npz"});
  const std::string bad = dir.file("bad-deflate.npz");
  Bytes z = make_zip({{"elevation.npy", small_elevation_npy(), 8}});
  z[30 + 13] = 0xff;
  test::write_bytes(bad, z);
  expect_error([&] { (void)read_npz(bad); }, ErrorKind::kInvalidInput, {bad, "deflate"});
}

TEST(Npz, EveryTruncatedPrefixIsAnError) {
  const Bytes e = small_elevation_npy();
  const Bytes line = make_npy("<f8", false, "(4,)", encode({1, 2, 3, 4}, "<f8"));
  for (int method : {0, 8}) {
    for (bool zip64 : {false, true}) {
      const Bytes full =
          make_zip({{"longitude.npy", line, method, zip64},
                    {"elevation.npy", e, method, zip64},
                    {"latitude.npy", make_npy("<f8", false, "(3,)", encode({5, 6, 7}, "<f8")),
                     method, zip64}});
      ASSERT_NO_THROW((void)heightfield_from_npz(full, "full.npz"));
      for (std::size_t n = 0; n < full.size(); ++n) {
        const Bytes prefix(full.begin(), full.begin() + static_cast<long>(n));
        EXPECT_THROW((void)heightfield_from_npz(prefix, "prefix.npz"), Error)
            << "method " << method << " prefix " << n;
      }
    }
  }
}

TEST(Npz, MutatedBytesNeverCrash) {
  const Bytes line = make_npy("<f8", false, "(4,)", encode({1, 2, 3, 4}, "<f8"));
  for (int method : {0, 8}) {
    const Bytes full = make_zip({{"elevation.npy", small_elevation_npy(), method, method == 8},
                                 {"longitude.npy", line, method}});
    std::uint64_t state = 99 + static_cast<std::uint64_t>(method);
    for (int round = 0; round < 3000; ++round) {
      Bytes b = full;
      for (int k = 0; k < 1 + round % 3; ++k) {
        state = state * 6364136223846793005ULL + 1442695040888963407ULL;
        b[(state >> 33) % b.size()] = static_cast<std::uint8_t>(state >> 24);
      }
      try {
        (void)heightfield_from_npz(b, "mutated.npz");
      } catch (const Error&) {
      }
    }
  }
}

}  // namespace
}  // namespace smr
