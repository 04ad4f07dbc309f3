// Tests of the OBJ / PLY writers and AtomicFile (smr/io/mesh_writer.h): files are parsed back by
// the small readers below and must give bit-identical vertices, the same triangles and values.
#include "smr/io/mesh_writer.h"

#include <sys/resource.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <csignal>
#include <cstring>
#include <limits>
#include <sstream>

#include <gtest/gtest.h>

#include "tests/io/io_test_helpers.h"

namespace smr {
namespace {

using test::expect_error;
using test::TempDir;

TriangleMesh sample_mesh() {
  TriangleMesh m;
  m.positions = {{-84.41375, 36.73291666666667, 483.0},
                 {1.0 / 3.0, 2.0 / 3.0, -1e-300},
                 {1e17, -0.1, 4.9e-324},
                 {std::nextafter(1.0, 2.0), -0.0, 123456789.123456789},
                 {0, 0, 0}};
  m.triangles = {{0, 1, 2}, {2, 3, 0}, {4, 3, 2}};
  m.triangle_values = {0.25f, 1.0f / 3.0f, -7.5f};
  return m;
}

struct ParsedMesh {
  std::vector<Vec3> positions;
  std::vector<std::array<std::uint32_t, 3>> triangles;
  std::vector<float> values;
};

ParsedMesh parse_obj(const std::string& path) {
  ParsedMesh m;
  const std::vector<std::uint8_t> bytes = test::read_bytes(path);
  std::istringstream in(std::string(bytes.begin(), bytes.end()));
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string tag;
    ls >> tag;
    if (tag == "v") {
      std::string x, y, z;
      ls >> x >> y >> z;
      m.positions.push_back({std::strtod(x.c_str(), nullptr), std::strtod(y.c_str(), nullptr),
                             std::strtod(z.c_str(), nullptr)});
    } else if (tag == "f") {
      std::uint32_t a, b, c;
      ls >> a >> b >> c;
      m.triangles.push_back({a - 1, b - 1, c - 1});
    } else {
      EXPECT_TRUE(tag.empty() || tag[0] == '#') << "unexpected OBJ line: " << line;
    }
  }
  return m;
}

ParsedMesh parse_ply(const std::string& path) {
  ParsedMesh m;
  const std::vector<std::uint8_t> bytes = test::read_bytes(path);
  const std::string text(bytes.begin(), bytes.end());
  const std::size_t end = text.find("end_header\n");
  EXPECT_NE(end, std::string::npos);
  std::istringstream header(text.substr(0, end));
  std::string line, format;
  std::size_t nv = 0, nf = 0;
  bool values = false;
  while (std::getline(header, line)) {
    std::istringstream ls(line);
    std::string a, b, c;
    ls >> a >> b >> c;
    if (a == "format") format = b;
    if (a == "element" && b == "vertex") nv = std::stoul(c);
    if (a == "element" && b == "face") nf = std::stoul(c);
    if (a == "property" && b == "float" && c == "value") values = true;
  }
  std::size_t p = end + 11;
  if (format == "binary_little_endian") {
    const auto take = [&](void* out, std::size_t n) {
      EXPECT_LE(p + n, bytes.size());
      if (p + n > bytes.size()) return;
      std::memcpy(out, bytes.data() + p, n);  // the test machine is little-endian
      p += n;
    };
    for (std::size_t i = 0; i < nv; ++i) {
      Vec3 v;
      take(&v.x, 8);
      take(&v.y, 8);
      take(&v.z, 8);
      m.positions.push_back(v);
    }
    for (std::size_t i = 0; i < nf; ++i) {
      std::uint8_t count = 0;
      take(&count, 1);
      EXPECT_EQ(count, 3);
      std::array<std::uint32_t, 3> t{};
      take(t.data(), 12);
      m.triangles.push_back(t);
      if (values) {
        float v;
        take(&v, 4);
        m.values.push_back(v);
      }
    }
    EXPECT_EQ(p, bytes.size());
  } else {
    EXPECT_EQ(format, "ascii");
    std::istringstream body(text.substr(p));
    for (std::size_t i = 0; i < nv; ++i) {
      std::string x, y, z;
      body >> x >> y >> z;
      m.positions.push_back({std::strtod(x.c_str(), nullptr), std::strtod(y.c_str(), nullptr),
                             std::strtod(z.c_str(), nullptr)});
    }
    for (std::size_t i = 0; i < nf; ++i) {
      int count;
      std::array<std::uint32_t, 3> t{};
      body >> count >> t[0] >> t[1] >> t[2];
      EXPECT_EQ(count, 3);
      m.triangles.push_back(t);
      if (values) {
        std::string v;
        body >> v;
        m.values.push_back(std::strtof(v.c_str(), nullptr));
      }
    }
  }
  return m;
}

void expect_same_positions(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      // Bit-identical, so -0.0 and denormals must survive too.
      EXPECT_EQ(std::memcmp(&a[i][k], &b[i][k], sizeof(double)), 0)
          << "vertex " << i << " axis " << k << ": " << a[i][k] << " vs " << b[i][k];
    }
  }
}

TEST(MeshWriter, ObjRoundTripIsExact) {
  TempDir dir;
  const TriangleMesh mesh = sample_mesh();
  const std::string path = dir.file("mesh.obj");
  write_obj(path, mesh);
  const ParsedMesh back = parse_obj(path);
  expect_same_positions(back.positions, mesh.positions);
  EXPECT_EQ(back.triangles, mesh.triangles);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"mesh.obj"});
}

TEST(MeshWriter, BinaryAndAsciiPlyRoundTripsAreExact) {
  TempDir dir;
  const TriangleMesh mesh = sample_mesh();
  for (bool binary : {true, false}) {
    const std::string path = dir.file(binary ? "bin.ply" : "ascii.ply");
    write_ply(path, mesh, binary);
    const ParsedMesh back = parse_ply(path);
    expect_same_positions(back.positions, mesh.positions);
    EXPECT_EQ(back.triangles, mesh.triangles);
    EXPECT_EQ(back.values, mesh.triangle_values);
  }
  // Without values there is no value property.
  TriangleMesh plain = sample_mesh();
  plain.triangle_values.clear();
  write_ply(dir.file("plain.ply"), plain);
  const ParsedMesh back = parse_ply(dir.file("plain.ply"));
  EXPECT_TRUE(back.values.empty());
  EXPECT_EQ(back.triangles, plain.triangles);
}

// ---- byte identity ---------------------------------------------------------------------------
// The writers' exact bytes are part of the contract (scripts/same-bytes.sh compares extraction
// outputs across binaries), so they are checked against bytes spelled out here from the formats'
// definitions: the IEEE-754 bit patterns written out by hand, little-endian byte by byte, and the
// decimal strings of std::to_chars (shortest round trip for OBJ and float values, 17 significant
// digits like %.17g for ASCII PLY doubles).

// 300 vertices (indices above 255 need every byte of a uint32): three with awkward doubles, then
// 297 at the origin; three triangles with values.
TriangleMesh golden_mesh() {
  TriangleMesh m;
  m.positions = {{1.0, -2.5, 0.1}, {-0.0, 1e17, 1.0 / 3.0}, {123456789.125, 4.9e-324, 0.0}};
  m.positions.resize(300, Vec3{0, 0, 0});
  m.triangles = {{0, 1, 2}, {299, 256, 2}, {2, 257, 298}};
  m.triangle_values = {0.25f, -7.5f, 1e20f};
  return m;
}

void append_le(std::string& out, std::uint64_t bits, int bytes) {
  for (int i = 0; i < bytes; ++i) out += static_cast<char>((bits >> (8 * i)) & 0xff);
}

std::string ply_header(const char* format, bool values, std::uint32_t vertices = 300,
                       std::uint32_t faces = 3) {
  return std::string("ply\nformat ") + format + " 1.0\ncomment smrdb mesh\nelement vertex " +
         std::to_string(vertices) +
         "\nproperty double x\nproperty double y\nproperty double z\nelement face " +
         std::to_string(faces) + "\nproperty list uchar uint vertex_indices\n" +
         (values ? "property float value\n" : "") + "end_header\n";
}

std::string golden_binary_ply(bool values) {
  std::string s = ply_header("binary_little_endian", values);
  const std::uint64_t doubles[9] = {0x3ff0000000000000, 0xc004000000000000, 0x3fb999999999999a,
                                    0x8000000000000000, 0x4376345785d8a000, 0x3fd5555555555555,
                                    0x419d6f3454800000, 0x0000000000000001, 0};
  for (std::uint64_t d : doubles) append_le(s, d, 8);
  s.append(297 * 3 * 8, '\0');  // 297 vertices (0, 0, 0)
  const std::uint32_t faces[3][3] = {{0, 1, 2}, {299, 256, 2}, {2, 257, 298}};
  const std::uint32_t value_bits[3] = {0x3e800000, 0xc0f00000, 0x60ad78ec};
  for (int f = 0; f < 3; ++f) {
    s += '\3';
    for (std::uint32_t v : faces[f]) append_le(s, v, 4);
    if (values) append_le(s, value_bits[f], 4);
  }
  return s;
}

std::string read_text(const std::string& path) {
  const std::vector<std::uint8_t> bytes = test::read_bytes(path);
  return std::string(bytes.begin(), bytes.end());
}

// For files too large to print: the sizes and the first differing byte.
void expect_bytes(const std::string& path, const std::string& expected) {
  const std::string got = read_text(path);
  const auto diff = std::mismatch(got.begin(), got.end(), expected.begin(), expected.end());
  EXPECT_TRUE(diff.first == got.end() && diff.second == expected.end())
      << path << ": " << got.size() << " bytes, expected " << expected.size()
      << "; first difference at byte " << (diff.first - got.begin());
}

TEST(MeshWriter, BinaryPlyBytesAreTheFormatsDefinition) {
  TempDir dir;
  TriangleMesh mesh = golden_mesh();
  write_ply(dir.file("v.ply"), mesh);
  EXPECT_EQ(read_text(dir.file("v.ply")), golden_binary_ply(true));
  mesh.triangle_values.clear();
  write_mesh(dir.file("p.ply"), mesh);
  EXPECT_EQ(read_text(dir.file("p.ply")), golden_binary_ply(false));
}

// A text file of golden_mesh(): `head`, the three special vertices' lines, 297 times the line of
// a vertex at the origin, then the faces' lines.
std::string golden_text(std::string head, const char* vertices, const char* origin,
                        const char* faces) {
  head += vertices;
  for (int i = 3; i < 300; ++i) head += origin;
  return head + faces;
}

TEST(MeshWriter, AsciiPlyBytesAreTheFormatsDefinition) {
  TempDir dir;
  write_ply(dir.file("a.ply"), golden_mesh(), false);
  EXPECT_EQ(read_text(dir.file("a.ply")),
            golden_text(ply_header("ascii", true),
                        "1 -2.5 0.10000000000000001\n"
                        "-0 1e+17 0.33333333333333331\n"
                        "123456789.125 4.9406564584124654e-324 0\n",
                        "0 0 0\n", "3 0 1 2 0.25\n3 299 256 2 -7.5\n3 2 257 298 1e+20\n"));
}

TEST(MeshWriter, ObjBytesAreTheFormatsDefinition) {
  TempDir dir;
  write_mesh(dir.file("m.obj"), golden_mesh());
  EXPECT_EQ(read_text(dir.file("m.obj")),
            golden_text("# smrdb mesh: 300 vertices, 3 triangles\n",
                        "v 1 -2.5 0.1\n"
                        "v -0 1e+17 0.3333333333333333\n"
                        "v 123456789.125 5e-324 0\n",
                        "v 0 0 0\n", "f 1 2 3\nf 300 257 3\nf 3 258 299\n"));
}

// Files of several MiB, so that every format crosses the writers' output chunks (and binary PLY
// writes its vertex array in one piece): coordinates i + 0.25, -(i + 0.5), 0.75 and values
// t + 0.25, whose decimal forms are those of the integers with ".25" / ".5" appended.
TEST(MeshWriter, LargeMeshBytesAreTheFormatsDefinition) {
  constexpr std::uint32_t kVertices = 100000, kTriangles = 300000;
  TriangleMesh mesh;
  for (std::uint32_t i = 0; i < kVertices; ++i)
    mesh.positions.push_back({i + 0.25, -(i + 0.5), 0.75});
  for (std::uint32_t t = 0; t < kTriangles; ++t) {
    mesh.triangles.push_back({t % kVertices, (7 * t + 1) % kVertices, (13 * t + 2) % kVertices});
    mesh.triangle_values.push_back(static_cast<float>(t) + 0.25f);
  }
  const auto x = [](std::uint32_t i) { return std::to_string(i) + ".25"; };
  const auto y = [](std::uint32_t i) {
    return std::string("-").append(std::to_string(i)).append(".5");
  };
  TempDir dir;

  write_obj(dir.file("m.obj"), mesh);
  std::string obj = "# smrdb mesh: 100000 vertices, 300000 triangles\n";
  for (std::uint32_t i = 0; i < kVertices; ++i) obj += "v " + x(i) + " " + y(i) + " 0.75\n";
  for (const auto& t : mesh.triangles) {
    obj += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " +
           std::to_string(t[2] + 1) + "\n";
  }
  ASSERT_GT(obj.size(), 4u << 20);  // more than one of the writers' 4 MiB chunks
  expect_bytes(dir.file("m.obj"), obj);

  write_ply(dir.file("a.ply"), mesh, false);
  std::string ascii = ply_header("ascii", true, kVertices, kTriangles);
  for (std::uint32_t i = 0; i < kVertices; ++i) ascii += x(i) + " " + y(i) + " 0.75\n";
  for (std::uint32_t t = 0; t < kTriangles; ++t) {
    const auto& f = mesh.triangles[t];
    ascii += "3 " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) +
             " " + x(t) + "\n";
  }
  expect_bytes(dir.file("a.ply"), ascii);

  write_ply(dir.file("b.ply"), mesh);
  std::string binary = ply_header("binary_little_endian", true, kVertices, kTriangles);
  for (const Vec3& p : mesh.positions) {
    for (int k = 0; k < 3; ++k) append_le(binary, std::bit_cast<std::uint64_t>(p[k]), 8);
  }
  for (std::uint32_t t = 0; t < kTriangles; ++t) {
    binary += '\3';
    for (std::uint32_t v : mesh.triangles[t]) append_le(binary, v, 4);
    append_le(binary, std::bit_cast<std::uint32_t>(mesh.triangle_values[t]), 4);
  }
  expect_bytes(dir.file("b.ply"), binary);
}

TEST(MeshWriter, EmptyMeshBytes) {
  TempDir dir;
  write_obj(dir.file("e.obj"), TriangleMesh{});
  EXPECT_EQ(read_text(dir.file("e.obj")), "# smrdb mesh: 0 vertices, 0 triangles\n");
  write_ply(dir.file("e.ply"), TriangleMesh{});
  EXPECT_EQ(read_text(dir.file("e.ply")),
            "ply\nformat binary_little_endian 1.0\ncomment smrdb mesh\nelement vertex 0\n"
            "property double x\nproperty double y\nproperty double z\nelement face 0\n"
            "property list uchar uint vertex_indices\nend_header\n");
}

TEST(MeshWriter, WriteMeshDispatchesOnExtension) {
  TempDir dir;
  const TriangleMesh mesh = sample_mesh();
  write_mesh(dir.file("a.OBJ"), mesh);
  EXPECT_EQ(parse_obj(dir.file("a.OBJ")).triangles, mesh.triangles);
  write_mesh(dir.file("b.ply"), mesh);
  const std::vector<std::uint8_t> bytes = test::read_bytes(dir.file("b.ply"));
  EXPECT_NE(std::string(bytes.begin(), bytes.begin() + 60).find("binary_little_endian"),
            std::string::npos);
  expect_error([&] { write_mesh(dir.file("c.stl"), mesh); }, ErrorKind::kInvalidInput,
               {"c.stl", ".stl", ".obj or .ply"});
  EXPECT_EQ(dir.entries(), (std::vector<std::string>{"a.OBJ", "b.ply"}));
}

TEST(MeshWriter, EmptyMeshWritesValidFiles) {
  TempDir dir;
  write_obj(dir.file("e.obj"), TriangleMesh{});
  write_ply(dir.file("e.ply"), TriangleMesh{});
  EXPECT_TRUE(parse_obj(dir.file("e.obj")).positions.empty());
  EXPECT_TRUE(parse_ply(dir.file("e.ply")).triangles.empty());
}

TEST(MeshWriter, BadMeshesAreInvalidInputAndWriteNothing) {
  TempDir dir;
  TriangleMesh bad = sample_mesh();
  bad.triangles.push_back({0, 1, 5});
  bad.triangle_values.push_back(0);
  expect_error([&] { write_obj(dir.file("bad.obj"), bad); }, ErrorKind::kInvalidInput,
               {"bad.obj", "vertex 5", "5 vertices"});
  TriangleMesh values = sample_mesh();
  values.triangle_values.pop_back();
  expect_error([&] { write_ply(dir.file("bad.ply"), values); }, ErrorKind::kInvalidInput,
               {"bad.ply", "2 triangle values for 3 triangles"});
  EXPECT_TRUE(dir.entries().empty());
}

TEST(MeshWriter, UnwritablePathsAreIoErrors) {
  TempDir dir;
  const TriangleMesh mesh = sample_mesh();
  expect_error([&] { write_obj("/nonexistent-smrdb-dir/m.obj", mesh); }, ErrorKind::kIo,
               {"/nonexistent-smrdb-dir/m.obj"});
  expect_error([&] { write_ply("/nonexistent-smrdb-dir/m.ply", mesh); }, ErrorKind::kIo,
               {"/nonexistent-smrdb-dir/m.ply"});
  expect_error([&] { write_mesh(dir.path().string() + "/", mesh); }, ErrorKind::kInvalidInput, {});
  std::filesystem::create_directory(dir.path() / "sub.obj");
  expect_error([&] { write_obj(dir.file("sub.obj"), mesh); }, ErrorKind::kIo,
               {"sub.obj", "directory"});
}

TEST(MeshWriter, FailedWriteLeavesNoFile) {
  // A file-size limit makes write(2) fail with EFBIG part-way, as a full disk would.
  TempDir dir;
  TriangleMesh big;
  for (int i = 0; i < 20000; ++i) big.positions.push_back({i * 0.1, i * 0.2, i * 0.3});
  rlimit old{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old), 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit small = old;
  small.rlim_cur = 64 * 1024;
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  const std::string path = dir.file("big.obj");
  try {
    write_obj(path, big);
    ADD_FAILURE() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kIo);
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  setrlimit(RLIMIT_FSIZE, &old);
  std::signal(SIGXFSZ, old_handler);
  EXPECT_TRUE(dir.entries().empty());
}

TEST(AtomicFile, ReplacesOnlyOnCommit) {
  TempDir dir;
  const std::string path = dir.file("x.txt");
  test::write_text(path, "old");
  {
    AtomicFile f(path);
    f.write("new contents");
    // Before commit the old file is intact and the temporary file sits beside it.
    EXPECT_EQ(test::read_bytes(path).size(), 3u);
    EXPECT_EQ(dir.entries().size(), 2u);
  }  // destroyed without commit: discarded
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"x.txt"});
  {
    AtomicFile f(path);
    f.write("new contents");
    f.commit();
  }
  const std::vector<std::uint8_t> bytes = test::read_bytes(path);
  EXPECT_EQ(std::string(bytes.begin(), bytes.end()), "new contents");
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"x.txt"});
}

}  // namespace
}  // namespace smr
