// Tests of the mesh readers (smr/io/mesh_reader.h): the eight real meshes in
// $SMRDB_DATA_DIR/meshes with their known counts and topology, round trips through every writer
// (the library's and those of mesh_test_support.h), format features, and a corpus of broken files
// (every truncated prefix, NaN, huge counts, bad indices, header garbage, mutations). Validation
// and repair: mesh_validator_test.cpp.
#include "smr/io/mesh_reader.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <limits>

#include <gtest/gtest.h>

#include "smr/io/mesh_writer.h"
#include "tests/io/io_test_helpers.h"
#include "tests/io/mesh_test_support.h"
#include "tests/support/datasets.h"

namespace smr {
namespace {

using namespace mesh_test;  // the shared helpers of mesh_test_support.h

// ---------------------------------------------------------------------------------------------
// Real meshes

struct RealMesh {
  const char* name;
  std::size_t vertices, faces, components, boundary_edges;
  long euler;
  bool needs_repair;  // pig.stl has non-manifold (pinched) vertices
};

// Counts cross-checked with an independent Python script (vertices welded by exact position for
// the STL); Euler characteristic V - E + F.
const RealMesh kReal[] = {
    {"bunny00.off", 37706, 75408, 1, 0, 2, false},
    {"armadillo.off", 26002, 52000, 1, 0, 2, false},
    {"refined_elephant.off", 44460, 88928, 1, 0, -4, false},   // genus 3
    {"ChineseDragon-10kv.off", 10000, 19994, 1, 6, 0, false},  // two holes
    {"blobby_3cc.off", 1820, 3417, 3, 219, 2, false},
    {"elephant-with-holes.off", 2798, 4463, 1, 1353, -110, false},
    {"mech-holes-shark.off", 5246, 10192, 1, 304, -2, false},
    // 8642 welded vertices, 421 of them pinch points shared by 2+ fans: 443 copies; the pig is 17
    // edge-connected parts.
    {"pig.stl", 8642 + 443, 16848, 17, 1296, 13, true},
};

TEST(MeshReaderReal, CountsAndTopology) {
  for (const RealMesh& r : kReal) {
    SCOPED_TRACE(r.name);
    const std::string path = test::mesh_path(r.name);
    MeshReport rep;
    const auto t0 = std::chrono::steady_clock::now();
    const TriangleMesh m = read_mesh(path, r.needs_repair ? MeshRepair::all() : MeshRepair{}, &rep);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("  %-24s %8zu v %8zu f  %.3f s  %s\n", r.name, m.positions.size(),
                m.triangles.size(), s, rep.summary().c_str());
    EXPECT_EQ(m.positions.size(), r.vertices);
    EXPECT_EQ(m.triangles.size(), r.faces);
    EXPECT_EQ(rep.vertices, r.vertices);
    EXPECT_EQ(rep.faces, r.faces);
    EXPECT_EQ(rep.components, r.components);
    EXPECT_EQ(rep.boundary_edges, r.boundary_edges);
    EXPECT_EQ(rep.closed, r.boundary_edges == 0);
    EXPECT_EQ(euler(rep), r.euler);
    EXPECT_EQ(rep.zero_area_faces, 0u);
    EXPECT_EQ(rep.unused_vertices_dropped, 0u);
    EXPECT_EQ(rep.polygons_triangulated, 0u);
    EXPECT_EQ(rep.faces_flipped, 0u);
    EXPECT_EQ(rep.vertices_split, r.needs_repair ? 443u : 0u);
    EXPECT_EQ(rep.repairs(), r.needs_repair ? 443u : 0u);
    expect_valid(m, r.name);
    // Validating a valid mesh changes nothing.
    TriangleMesh again = m;
    validate_mesh(again, r.name);
    expect_equal(again, m);
  }
}

TEST(MeshReaderReal, PigNeedsRepairForItsPinchedVertices) {
  const std::string path = test::mesh_path("pig.stl");
  expect_error([&] { (void)read_mesh(path); }, ErrorKind::kInvalidInput,
               {path, "non-manifold", "the vertex at (", "--repair"});
}

TEST(MeshReaderReal, RoundTripThroughEveryWriter) {
  TempDir dir;
  for (const RealMesh& r : kReal) {
    SCOPED_TRACE(r.name);
    const MeshRepair repair = r.needs_repair ? MeshRepair::all() : MeshRepair{};
    const TriangleMesh m = read_mesh(test::mesh_path(r.name), repair);
    const std::string base = dir.file(std::string(r.name) + ".out");

    write_ply(base + ".ply", m, true);
    expect_equal(read_mesh(base + ".ply"), m);
    write_ply(base + ".ascii.ply", m, false);
    expect_equal(read_mesh(base + ".ascii.ply"), m);
    write_obj(base + ".obj", m);
    expect_equal(read_mesh(base + ".obj"), m);
    test::write_text(base + ".off", off_text(m));
    expect_equal(read_mesh(base + ".off"), m);
    test::write_bytes(base + ".be.ply", ply_binary(m, true));
    expect_equal(read_mesh(base + ".be.ply"), m);
    test::write_bytes(base + ".le.ply", ply_binary(m, false));
    expect_equal(read_mesh(base + ".le.ply"), m);

    // STL stores float corners, welded back by position: vertices that were distinct but
    // share a float position (seams, pig's split copies) merge again, so read with repairs; the
    // faces and their corner positions must come back unchanged. ASCII STL keeps the decimal
    // text of each float as a double.
    const TriangleMesh f = to_float(m);
    MeshReport rep;
    test::write_bytes(base + ".stl", stl_binary(m));
    const TriangleMesh s = read_mesh(base + ".stl", MeshRepair::all(), &rep);
    EXPECT_EQ(rep.faces, m.triangles.size());
    expect_same_geometry(s, f);
    test::write_text(base + ".ascii.stl", stl_ascii(m));
    expect_same_geometry(read_mesh(base + ".ascii.stl", MeshRepair::all()), float_text(m));
    std::printf("  %-24s STL round trip: %s\n", r.name, rep.summary().c_str());
  }
}

// ---------------------------------------------------------------------------------------------
// Format features

TEST(MeshReaderFormats, OffCommentsColoursPolygonsAndVariants) {
  const std::string off =
      "# leading comment\nOFF # keyword comment\n\n  6 3 0 # counts\n"
      "0 0 0\n1 0 0\n1 1 0 # a comment\n0 1 0\n2 0 0\n2 1 0\n"
      "4 0 1 2 3 255 0 0\n"  // a quad with a colour
      "3 1 4 5 0.1 0.2 0.3 1\n"
      "3 1 5 2\n";
  MeshReport rep;
  const TriangleMesh m = parse(off, MeshFormat::kOff, {}, &rep);
  EXPECT_EQ(m.positions.size(), 6u);
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {0, 2, 3}, {1, 4, 5}, {1, 5, 2}}));
  EXPECT_EQ(rep.polygons_triangulated, 1u);
  EXPECT_EQ(rep.components, 1u);
  EXPECT_EQ(rep.boundary_edges, 6u);
  // Counts on the keyword line, no edge count; COFF / NOFF / STOFF vertex lines.
  EXPECT_EQ(parse("OFF 3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", MeshFormat::kOff).triangles.size(),
            1u);
  EXPECT_EQ(
      parse("COFF\n3 1 0\n0 0 0 1 0 0 1\n1 0 0 0 1 0 1\n0 1 0 0 0 1 1\n3 0 1 2\n", MeshFormat::kOff)
          .positions[1],
      Vec3(1, 0, 0));
  EXPECT_EQ(parse("NOFF\n3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n", MeshFormat::kOff)
                .positions[2],
            Vec3(0, 1, 0));
  EXPECT_EQ(parse("STCNOFF\n3 1 0\n0 0 0 0 0 1 1 1 1 1 0 0\n1 0 0 0 0 1 1 1 1 1 0 0\n0 1 0 0 0 1 1 "
                  "1 1 1 0 0\n3 0 1 2\n",
                  MeshFormat::kOff)
                .positions.size(),
            3u);
  // CRLF line ends, exponents, signs.
  const TriangleMesh c = parse(
      "OFF\r\n3 1 0\r\n+1e0 -0 .5\r\n1.5E+1 0 0\r\n0 1e-3 0\r\n3 0 1 2\r\n", MeshFormat::kOff);
  EXPECT_EQ(c.positions[0], Vec3(1, 0, 0.5));
  EXPECT_EQ(c.positions[1], Vec3(15, 0, 0));
  EXPECT_EQ(c.positions[2], Vec3(0, 1e-3, 0));
}

TEST(MeshReaderFormats, ObjReferenceFormsNegativeIndicesAndIgnoredStatements) {
  const std::string obj =
      "# comment\r\nmtllib x.mtl\no thing\nv 0 0 0\nv 1 0 0 1.0\nv 1 1 0 0.5 0.5 0.5\nv 0 1 0\n"
      "vt 0 0\nvt 1 0\nvn 0 0 1\ng group\nusemtl m\ns 1\n"
      "f 1/1/1 2/2/1 3//1 4\n"  // a quad with mixed reference forms
      "v 2 0 0\nv 2 1 0\n"
      "f -5 -2 \\\n -1\n"  // relative indices, continued line: (2, 5, 6) 1-based
      "f 2 6 3 # comment\n"
      "l 1 2\np 1\n";
  MeshReport rep;
  const TriangleMesh m = parse(obj, MeshFormat::kObj, {}, &rep);
  EXPECT_EQ(m.positions.size(), 6u);
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {0, 2, 3}, {1, 4, 5}, {1, 5, 2}}));
  EXPECT_EQ(rep.polygons_triangulated, 1u);
  // Forward references are allowed.
  EXPECT_EQ(parse("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", MeshFormat::kObj).triangles.size(), 1u);
}

TEST(MeshReaderFormats, PlyAsciiAnyTypesAndSkippedElements) {
  const std::string ply =
      "ply\r\nformat ascii 1.0\r\ncomment hi\r\nobj_info x\r\n"
      "element vertex 5\r\nproperty short x\r\nproperty int8 y\r\nproperty float64 z\r\n"
      "property list uchar float texture\r\nproperty uchar red\r\n"
      "element junk 2\r\nproperty list int int stuff\r\n"
      "element face 2\r\nproperty uchar flags\r\nproperty list int8 uint32 vertex_index\r\n"
      "property float quality\r\n"
      "end_header\r\n"
      "0 0 0 2 0.5 0.5 255\r\n1 0 0 0 7\r\n1 1 0.25 1 9 3\r\n0 1 -0 0 1\r\n2 0 0 0 1\r\n"
      "3 1 2 3\r\n0\r\n"
      "0 4 0 1 2 3 0.5\r\n"
      "1 3 1 4 2 0.25\r\n";
  MeshReport rep;
  const TriangleMesh m = parse(ply, MeshFormat::kPly, {}, &rep);
  EXPECT_EQ(m.positions,
            (std::vector<Vec3>{{0, 0, 0}, {1, 0, 0}, {1, 1, 0.25}, {0, 1, 0}, {2, 0, 0}}));
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {0, 2, 3}, {1, 4, 2}}));
  EXPECT_EQ(rep.polygons_triangulated, 1u);
}

TEST(MeshReaderFormats, PlyBinaryFloatCoordinatesAndUcharIndices) {
  for (bool big : {false, true}) {
    std::string h = std::string("ply\nformat ") +
                    (big ? "binary_big_endian" : "binary_little_endian") +
                    " 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 1\nproperty list uint16 uchar vertex_indices\nend_header\n";
    Bytes b = text_bytes(h);
    for (float v : {0.f, 0.f, 0.f, 1.5f, 0.f, 0.f, 0.f, -2.25f, 0.f}) put(b, v, big);
    put<std::uint16_t>(b, 3, big);
    for (std::uint8_t v : {std::uint8_t{0}, std::uint8_t{1}, std::uint8_t{2}}) put(b, v, big);
    const TriangleMesh m =
        parse_mesh(std::string_view(reinterpret_cast<const char*>(b.data()), b.size()),
                   MeshFormat::kPly, "f.ply");
    EXPECT_EQ(m.positions, (std::vector<Vec3>{{0, 0, 0}, {1.5, 0, 0}, {0, -2.25, 0}}));
    EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}}));
  }
}

TEST(MeshReaderFormats, StlAsciiSeveralSolidsWeldedByPosition) {
  const std::string stl =
      "solid a\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n"
      "   vertex 0 1 0\n  endloop\n endfacet\nendsolid a\r\n"
      "solid b\r\n facet normal 0 0 1\r\n outer loop\r\n vertex 1 0 0\r\n vertex 1 1 0\r\n"
      " vertex -0 1 0\r\n endloop\r\n endfacet\r\nendsolid\r\n";
  MeshReport rep;
  const TriangleMesh m = parse(stl, MeshFormat::kStl, {}, &rep);
  EXPECT_EQ(m.positions.size(), 4u);  // -0 == 0: welded
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {1, 3, 2}}));
  EXPECT_EQ(rep.welded_vertices, 0u);  // STL welding is not a repair
  EXPECT_EQ(rep.components, 1u);
}

TEST(MeshReaderFormats, DispatchByExtension) {
  EXPECT_TRUE(is_mesh_path("a/b.PLY"));
  EXPECT_TRUE(is_mesh_path("x.obj"));
  EXPECT_TRUE(is_mesh_path("x.Off"));
  EXPECT_TRUE(is_mesh_path("x.stl"));
  EXPECT_FALSE(is_mesh_path("x.tif"));
  EXPECT_FALSE(is_mesh_path("x.npz"));
  EXPECT_FALSE(is_mesh_path("ply"));
  EXPECT_EQ(mesh_format_for_path("X.STL"), MeshFormat::kStl);
  TempDir dir;
  const std::string tif = dir.file("mesh.xyz");
  test::write_text(tif, "x");
  expect_error([&] { (void)read_mesh(tif); }, ErrorKind::kInvalidInput,
               {tif, "'.xyz'", ".ply, .obj, .off, .stl"});
  expect_error([&] { (void)read_mesh(dir.file("noext")); }, ErrorKind::kInvalidInput,
               {"no extension", ".ply, .obj, .off, .stl"});
  expect_error([&] { (void)read_mesh(dir.file("missing.off")); }, ErrorKind::kIo,
               {dir.file("missing.off"), "no such file"});
  std::filesystem::create_directories(dir.file("d.obj"));
  expect_error([&] { (void)read_mesh(dir.file("d.obj")); }, ErrorKind::kInvalidInput,
               {dir.file("d.obj"), "directory"});
}

TEST(MeshReaderFormats, ReportSummary) {
  MeshReport rep;
  (void)parse(off_text(tetrahedron()), MeshFormat::kOff, {}, &rep);
  EXPECT_EQ(rep.summary(), "4 vertices, 4 faces, 1 component, closed");
  EXPECT_TRUE(rep.closed);
  EXPECT_EQ(euler(rep), 2);
}

// ---------------------------------------------------------------------------------------------
// Broken files

TEST(MeshReaderBroken, EveryTruncatedPrefixIsAnError) {
  const TriangleMesh t = tetrahedron();
  TempDir dir;
  write_ply(dir.file("t.ply"), t, true);
  write_ply(dir.file("t_ascii.ply"), t, false);
  struct Case {
    std::string name;
    Bytes bytes;
    MeshFormat format;
    std::size_t valid_from;  // prefixes at least this long may parse (trailing text)
  };
  std::vector<Case> cases = {
      {"le.ply", test::read_bytes(dir.file("t.ply")), MeshFormat::kPly, 0},
      {"be.ply", ply_binary(t, true), MeshFormat::kPly, 0},
      {"ext.ply", ply_binary(t, false), MeshFormat::kPly, 0},
      {"ascii.ply", test::read_bytes(dir.file("t_ascii.ply")), MeshFormat::kPly, 0},
      {"t.off", text_bytes(off_text(t)), MeshFormat::kOff, 0},
      {"t.stl", stl_binary(t), MeshFormat::kStl, 0},
      {"ascii.stl", text_bytes(stl_ascii(t)), MeshFormat::kStl, 0},
  };
  for (Case& c : cases) {
    // Text formats may lose their final newline (or the name after endsolid) and stay valid.
    c.valid_from = c.bytes.size();
    if (c.name == "ascii.ply" || c.name == "t.off") c.valid_from = c.bytes.size() - 1;
    if (c.name == "ascii.stl") c.valid_from = c.bytes.size() - std::strlen(" test mesh\n");
    const std::string_view full(reinterpret_cast<const char*>(c.bytes.data()), c.bytes.size());
    ASSERT_NO_THROW((void)parse_mesh(full, c.format, c.name)) << c.name;
    for (std::size_t n = 0; n < c.valid_from; ++n) {
      try {
        (void)parse_mesh(full.substr(0, n), c.format, c.name);
        ADD_FAILURE() << c.name << " prefix " << n << " parsed";
      } catch (const Error& e) {
        const std::string msg = e.what();
        EXPECT_EQ(e.kind(), ErrorKind::kInvalidInput) << msg;
        EXPECT_NE(msg.find(c.name), std::string::npos) << msg;
        const bool keyword =
            msg.find("truncated") != std::string::npos || msg.find("empty") != std::string::npos ||
            msg.find("header") != std::string::npos || msg.find("not a") != std::string::npos ||
            msg.find("room for") != std::string::npos;
        EXPECT_TRUE(keyword) << c.name << " prefix " << n << ": " << msg;
      }
    }
    for (std::size_t n = c.valid_from; n < c.bytes.size(); ++n) {
      EXPECT_NO_THROW((void)parse_mesh(full.substr(0, n), c.format, c.name)) << c.name << " " << n;
    }
  }
  // One truncated file through read_mesh, naming the path.
  const Bytes le = test::read_bytes(dir.file("t.ply"));
  expect_file_error(dir, "cut.ply", Bytes(le.begin(), le.end() - 5), {"truncated", "face 3"});
}

TEST(MeshReaderBroken, NonFiniteCoordinates) {
  TempDir dir;
  const std::string faces = "3 0 1 2\n";
  expect_file_error(dir, "nan.off", "OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n" + faces,
                    {"vertex 1", "NaN y coordinate", "line 4", "not repairable"});
  expect_file_error(dir, "inf.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 -inf\n" + faces,
                    {"vertex 2", "infinite z"}, MeshRepair::all());
  expect_file_error(dir, "big.off", "OFF\n3 1 0\n1e999 0 0\n1 0 0\n0 1 0\n" + faces,
                    {"vertex 0", "infinite x"});
  expect_file_error(dir, "nan.obj", "v 0 0 0\nv 1 0 0\nv NaN 1 0\nf 1 2 3\n",
                    {"vertex 3", "NaN", "line 3"});
  expect_file_error(dir, "inf.ply",
                    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float "
                    "y\nproperty float z\nelement face 1\nproperty list uchar int "
                    "vertex_indices\nend_header\n0 0 0\n1 0 inf\n0 1 0\n3 0 1 2\n",
                    {"vertex 1", "infinite z", "line 11"});
  TriangleMesh t = tetrahedron();
  t.positions[3].y = std::numeric_limits<double>::quiet_NaN();
  expect_file_error(dir, "nan.ply", ply_binary(t, true), {"vertex 3", "NaN y"});
  expect_file_error(dir, "nan.stl", stl_binary(t), {"facet 1", "NaN y"});
  expect_file_error(dir, "nan_ascii.stl", stl_ascii(t), {"facet 1", "NaN y"});
  expect_error([&] { validate_mesh(t, "memory mesh"); }, ErrorKind::kInvalidInput,
               {"memory mesh", "vertex 3", "NaN"});
}

TEST(MeshReaderBroken, HugeCountsAreRejectedBeforeAllocating) {
  TempDir dir;
  expect_file_error(dir, "huge.off", "OFF\n4000000000 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
                    {"4000000000 vertices", "room for at most"});
  expect_file_error(dir, "huge_faces.off",
                    "OFF\n3 18446744073709551615 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
                    {"18446744073709551615 faces", "room for at most"});
  expect_file_error(dir, "overflow.off", "OFF\n3 99999999999999999999999 0\n",
                    {"malformed OFF header", "face count"});
  expect_file_error(dir, "polygon.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2000000000 0 1 2\n",
                    {"face 0", "2000000000 vertices", "more than the rest"});
  const std::string head = "ply\nformat binary_little_endian 1.0\nelement vertex ";
  const std::string rest =
      "\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list "
      "uchar int vertex_indices\nend_header\n";
  expect_file_error(dir, "huge.ply", head + "4000000000" + rest + std::string(64, '\0'),
                    {"4000000000 vertices", "room for at most 5", "12 bytes"});
  expect_file_error(dir, "huge_ascii.ply",
                    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 4000000000\nproperty list uchar int "
                    "vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
                    {"4000000000 faces", "room for at most"});
  expect_file_error(dir, "count.ply", head + "99999999999999999999" + rest,
                    {"malformed PLY header", "count of element 'vertex'"});
  // A list count larger than the rest of the file.
  Bytes b = text_bytes(head + "3" + rest);
  for (int k = 0; k < 9; ++k) put(b, 0.0f + static_cast<float>(k % 4 == 0), false);
  put<std::uint8_t>(b, 255, false);
  put<std::int32_t>(b, 0, false);
  expect_file_error(dir, "list.ply", b, {"truncated", "face 0", "255 items"});
  // Binary STL whose count does not match its size.
  Bytes s = stl_binary(tetrahedron());
  s[80] = 0xff;
  s[83] = 0x7f;
  expect_file_error(dir, "count.stl", s, {"2130706687 facets", "bytes", "truncated"});
}

TEST(MeshReaderBroken, IndicesOutOfRange) {
  TempDir dir;
  const std::string v = "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n";
  expect_file_error(dir, "big.off", v + "3 0 1 2\n3 1 4 2\n",
                    {"face 1", "line 8", "vertex 4", "out of range", "4 vertices"});
  expect_file_error(dir, "neg.off", v + "3 0 -1 2\n3 1 3 2\n",
                    {"face 0", "vertex -1", "out of range"});
  expect_file_error(dir, "float.off", v + "3 0 1.0 2\n3 1 3 2\n", {"face 0", "'1.0'", "integer"});
  expect_file_error(dir, "short.off", v + "3 0 1\n3 1 3 2\n", {"face 0", "lists only 2"});
  const std::string o = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  expect_file_error(dir, "big.obj", o + "f 1 2 9\n",
                    {"face 0 (line 4)", "vertex 9", "out of range"});
  expect_file_error(dir, "zero.obj", o + "f 0 1 2\n", {"line 4", "vertex 0", "start at 1"});
  expect_file_error(dir, "rel.obj", o + "f -4 1 2\n", {"line 4", "relative vertex -4", "only 3"});
  expect_file_error(dir, "bad.obj", o + "f 1 x 2\n", {"line 4", "'x'"});
  TriangleMesh t = tetrahedron();
  Bytes p = ply_binary(t, false);
  t.triangles[2][1] = 4;
  expect_file_error(dir, "big.ply", ply_binary(t, false), {"face 2", "vertex 4", "out of range"});
  t.triangles[2][1] = static_cast<std::uint32_t>(-1);
  expect_file_error(dir, "neg.ply", ply_binary(t, true), {"face 2", "vertex -1", "out of range"});
  TriangleMesh mem = tetrahedron();
  mem.triangles[1][2] = 7;
  expect_error([&] { validate_mesh(mem, "mem"); }, ErrorKind::kInvalidInput,
               {"mem", "face 1", "vertex 7", "out of range"});
}

TEST(MeshReaderBroken, EmptyFilesAndHeaderGarbage) {
  TempDir dir;
  for (const char* name : {"e.ply", "e.obj", "e.off", "e.stl"}) {
    expect_file_error(dir, name, "", {"empty"});
  }
  expect_file_error(dir, "g.off", "OFX\n3 1 0\n", {"not an OFF file", "'OFX'"});
  expect_file_error(dir, "g4.off", "4OFF\n3 1 0\n", {"4OFF", "not supported"});
  expect_file_error(dir, "c.off", "OFF\nthree 1 0\n", {"malformed OFF header", "'three'"});
  expect_file_error(dir, "bin.off", Bytes{0x00, 0xff, 0x13, 0x37}, {"not an OFF file", "\\x00"});
  expect_file_error(dir, "g.ply", "PLY\nformat ascii 1.0\n", {"not a PLY file", "'PLY'"});
  const std::string ply = "ply\nformat ascii 1.0\n";
  const std::string xyz = "property float x\nproperty float y\nproperty float z\n";
  const std::string face = "element face 0\nproperty list uchar int vertex_indices\n";
  expect_file_error(dir, "fmt.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n",
                    {"malformed PLY header", "unknown format", "line 2"});
  expect_file_error(dir, "type.ply", ply + "element vertex 1\nproperty float128 x\nend_header\n",
                    {"unknown property type 'float128'", "line 4"});
  expect_file_error(dir, "list.ply",
                    ply + "element face 1\nproperty list float int vertex_indices\nend_header\n",
                    {"list count type"});
  expect_file_error(dir, "noend.ply", ply + "element vertex 1\n" + xyz, {"end_header"});
  expect_file_error(dir, "noformat.ply", "ply\nelement vertex 0\nend_header\n", {"no 'format'"});
  expect_file_error(dir, "junk.ply", ply + "hello world\nend_header\n",
                    {"unexpected line", "'hello world'"});
  expect_file_error(dir, "orphan.ply", ply + "property float x\nend_header\n",
                    {"property before any element"});
  expect_file_error(dir, "twice.ply", ply + "element vertex 0\nelement vertex 0\nend_header\n",
                    {"declared twice"});
  expect_file_error(
      dir, "noy.ply",
      ply + "element vertex 0\nproperty float x\nproperty float z\n" + face + "end_header\n",
      {"no property 'y'"});
  expect_file_error(dir, "noface.ply", ply + "element vertex 0\n" + xyz + "end_header\n",
                    {"no 'face' element", "point cloud"});
  expect_file_error(dir, "nolist.ply",
                    ply + "element vertex 0\n" + xyz +
                        "element face 0\nproperty list uchar int corners\nend_header\n",
                    {"no list property 'vertex_indices'"});
  expect_file_error(dir, "floatidx.ply",
                    ply + "element vertex 0\n" + xyz +
                        "element face 0\nproperty list uchar float vertex_indices\nend_header\n",
                    {"floating-point index type"});
  expect_file_error(dir, "word.ply",
                    ply + "element vertex 1\n" + xyz + face + "end_header\n0 zero 0\n",
                    {"vertex 0", "'zero'", "property 'y'", "line 10"});
  expect_file_error(dir, "g.stl", "hello", {"not an STL file", "too short"});
  expect_file_error(dir, "g2.stl", std::string(200, 'x'), {"not an STL file", "not ASCII STL"});
  expect_file_error(dir, "a.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0\nendloop\n",
                    {"'endloop'", "facet 0", "expected a number"});
  expect_file_error(dir, "b.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n",
                    {"truncated", "facet 0"});
  expect_file_error(dir, "c.stl", "solid x\nfacets\n",
                    {"'facets'", "expected 'facet' or 'endsolid'"});
  expect_file_error(dir, "d.stl", "solid x\n", {"truncated", "without 'endsolid'"});
}

TEST(MeshReaderBroken, BinaryPlyWithWrongSizes) {
  TempDir dir;
  const TriangleMesh t = tetrahedron();
  TempDir tmp;
  write_ply(tmp.file("t.ply"), t, true);
  const Bytes good = test::read_bytes(tmp.file("t.ply"));
  const std::string text(good.begin(), good.end());
  // The header claims one vertex more than the data holds.
  std::string more = text;
  more.replace(more.find("element vertex 4"), 16, "element vertex 5");
  expect_file_error(dir, "more.ply", text_bytes(more), {"face 0"});
  // ... or one face more.
  std::string faces = text;
  faces.replace(faces.find("element face 4"), 14, "element face 5");
  expect_file_error(dir, "faces.ply", text_bytes(faces), {"truncated", "face 4 of 5"});
  // The header claims int counts but the data has uchar counts: the indices are misread.
  std::string wide = text;
  wide.replace(wide.find("list uchar uint"), 15, "list int uint");
  expect_file_error(dir, "wide.ply", text_bytes(wide), {"face 0"});
  // Doubles declared as floats: every record shifts; garbage is caught somewhere.
  std::string narrow = text;
  for (std::size_t at; (at = narrow.find("property double")) != std::string::npos;) {
    narrow.replace(at, 15, "property float");
  }
  try {
    (void)parse_mesh(narrow, MeshFormat::kPly, "narrow.ply");
    ADD_FAILURE() << "narrow.ply parsed";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidInput);
    EXPECT_NE(std::string(e.what()).find("narrow.ply"), std::string::npos);
  }
}

TEST(MeshReaderBroken, MutatedFilesNeverCrash) {
  // A short in-test fuzz loop (the fuzz target does more): every outcome is a valid mesh or an
  // smr::Error.
  const TriangleMesh t = tetrahedron();
  const std::vector<std::pair<Bytes, MeshFormat>> seeds = {
      {ply_binary(t, false), MeshFormat::kPly},
      {ply_binary(t, true), MeshFormat::kPly},
      {text_bytes(off_text(t)), MeshFormat::kOff},
      {stl_binary(t), MeshFormat::kStl},
      {text_bytes(stl_ascii(t)), MeshFormat::kStl},
      {text_bytes("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"),
       MeshFormat::kObj}};
  std::uint64_t state = 12345;
  std::size_t ok = 0;
  for (int round = 0; round < 4000; ++round) {
    const auto& [seed, format] = seeds[static_cast<std::size_t>(round) % seeds.size()];
    Bytes b = seed;
    for (int k = 0; k < 1 + round % 4; ++k) {
      state = state * 6364136223846793005ULL + 1442695040888963407ULL;
      b[(state >> 33) % b.size()] = static_cast<std::uint8_t>(state >> 24);
    }
    for (const MeshRepair& r : {MeshRepair{}, MeshRepair::all()}) {
      try {
        const TriangleMesh m =
            parse_mesh(std::string_view(reinterpret_cast<const char*>(b.data()), b.size()), format,
                       "mutated", r);
        expect_valid(m, "mutated");
        ++ok;
      } catch (const Error& e) {
        EXPECT_NE(e.kind(), ErrorKind::kInternal) << e.what();
      }
    }
  }
  EXPECT_GT(ok, 100u);
}

}  // namespace
}  // namespace smr
