// Tests of mesh validation and repair (validate_mesh, smr/io/mesh_reader.h), through the readers
// and on meshes in memory: degenerate, zero-area and duplicate faces, non-manifold edges and
// vertices, orientation (and the Moebius strip no repair can orient), welding and unused
// vertices, per-triangle values following the faces.
#include <cstdint>
#include <limits>

#include <gtest/gtest.h>

#include "smr/io/mesh_reader.h"
#include "tests/io/io_test_helpers.h"
#include "tests/io/mesh_test_support.h"

namespace smr {
namespace {

using namespace mesh_test;  // the shared helpers of mesh_test_support.h

// ---------------------------------------------------------------------------------------------
// Validation and repair

TEST(MeshReaderBroken, DegenerateAndZeroAreaFaces) {
  TempDir dir;
  const std::string tet = off_text(tetrahedron());
  const std::string v = "OFF\n4 5 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n";
  const std::string faces = "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
  expect_file_error(dir, "deg.off", v + faces + "3 1 1 2\n",
                    {"face 4", "degenerate", "vertex 1 (1, 0, 0) twice", "--repair"});
  expect_file_error(dir, "two.off", v + faces + "2 0 1\n", {"face 4", "2 vertices", "at least 3"});
  expect_file_error(dir, "deg.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 2\n",
                    {"face 0 (line 4)", "vertex 2 (1, 0, 0) twice"});
  MeshReport rep;
  MeshRepair drop;
  drop.drop_degenerate = true;
  TriangleMesh m = parse("OFF\n4 7 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n" + faces + "3 1 1 2\n2 0 1\n0\n",
                         MeshFormat::kOff, drop, &rep);
  EXPECT_EQ(m.triangles, tetrahedron().triangles);
  EXPECT_EQ(rep.degenerate_faces_dropped, 3u);
  // A face whose vertices are distinct but collinear is kept and counted.
  const std::string flat = "OFF\n4 2 0\n0 0 0\n1 0 0\n2 0 0\n0 1 0\n3 0 1 3\n3 1 2 3\n";
  const TriangleMesh ok = parse(flat + "", MeshFormat::kOff, {}, &rep);
  EXPECT_EQ(rep.zero_area_faces, 0u);
  const TriangleMesh z = parse("OFF\n4 2 0\n0 0 0\n1 0 0\n2 0 0\n0 1 0\n3 0 1 3\n3 0 2 1\n",
                               MeshFormat::kOff, {}, &rep);
  EXPECT_EQ(z.triangles.size(), 2u);
  EXPECT_EQ(rep.zero_area_faces, 1u);
  expect_valid(z, "zero area");
  // Everything degenerate.
  expect_file_error(dir, "alldeg.off", "OFF\n2 1 0\n0 0 0\n1 0 0\n3 0 1 1\n", {"no faces left"},
                    drop);
  expect_file_error(dir, "nofaces.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", {"no faces"});
  expect_file_error(dir, "points.obj", "v 0 0 0\n", {"no faces"});
}

TEST(MeshReaderBroken, DuplicateFaces) {
  TempDir dir;
  const std::string v = "OFF\n4 5 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n";
  const std::string faces = "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
  for (const char* dup : {"3 1 3 0\n", "3 0 3 1\n"}) {  // same and opposite orientation
    SCOPED_TRACE(dup);
    expect_file_error(
        dir, "dup.off", v + faces + dup,
        {"face 4 (line 11) is a duplicate of face 1 (line 8)", "both use vertices", "--repair"});
    MeshReport rep;
    MeshRepair r;
    r.drop_duplicates = true;
    const TriangleMesh m = parse(v + faces + dup, MeshFormat::kOff, r, &rep);
    EXPECT_EQ(m.triangles, tetrahedron().triangles);
    EXPECT_EQ(rep.duplicate_faces_dropped, 1u);
  }
  // Three copies: two dropped.
  MeshReport rep;
  const TriangleMesh m =
      parse("OFF\n4 6 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n" + faces + "3 0 2 1\n3 2 1 0\n",
            MeshFormat::kOff, MeshRepair::all(), &rep);
  EXPECT_EQ(m.triangles.size(), 4u);
  EXPECT_EQ(rep.duplicate_faces_dropped, 2u);
  EXPECT_TRUE(rep.closed);
}

TEST(MeshReaderBroken, NonManifoldEdge) {
  TempDir dir;
  // Three faces on edge (0, 1).
  const std::string book = off_of(kSix, {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}});
  expect_file_error(
      dir, "book.off", book,
      {"edge between vertex 0 (0, 0, 0) and vertex 1 (1, 0, 0)", "non-manifold",
       "3 faces (face 0 (line 10), face 1 (line 11), face 2 (line 12))", "--repair detaches"});
  MeshReport rep;
  const TriangleMesh m = parse(book, MeshFormat::kOff, MeshRepair::all(), &rep);
  expect_valid(m, "book");
  EXPECT_EQ(rep.nonmanifold_edges_cut, 1u);
  EXPECT_EQ(m.triangles.size(), 3u);
  EXPECT_EQ(rep.vertices_split, 2u);  // face 2 gets its own copies of 0 and 1
  EXPECT_EQ(m.positions.size(), 7u);  // vertex 5 is unused
  EXPECT_EQ(rep.unused_vertices_dropped, 1u);
  EXPECT_EQ(rep.components, 2u);
  // The kept pair traverses the edge in opposite directions: faces 0 and 1.
  EXPECT_EQ(m.triangles[0], (Tri{0, 1, 2}));
  EXPECT_EQ(m.triangles[1], (Tri{1, 0, 3}));

  // The same, but the pages are joined around both ends of the spine, so cutting the spine alone
  // leaves face 2 on the same two vertices: it is detached completely.
  const std::string joined = off_of(kSix, {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}, {0, 4, 2}, {1, 2, 4}});
  const TriangleMesh j = parse(joined, MeshFormat::kOff, MeshRepair::all(), &rep);
  expect_valid(j, "joined book");
  EXPECT_EQ(rep.nonmanifold_edges_cut, 1u);
  EXPECT_EQ(j.triangles.size(), 5u);
  // Four faces on one edge, all in the same direction (needs flips as well).
  const std::string fan4 = off_of(kSix, {{0, 1, 2}, {0, 1, 3}, {0, 1, 4}, {0, 1, 5}});
  const TriangleMesh f = parse(fan4, MeshFormat::kOff, MeshRepair::all(), &rep);
  expect_valid(f, "fan of four");
  EXPECT_EQ(rep.nonmanifold_edges_cut, 1u);
  EXPECT_EQ(rep.faces_flipped, 1u);
  EXPECT_EQ(rep.components, 3u);
}

TEST(MeshReaderBroken, NonManifoldVertex) {
  TempDir dir;
  const std::string bowtie =
      off_of({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}}, {{0, 1, 2}, {0, 3, 4}});
  expect_file_error(dir, "bowtie.off", bowtie,
                    {"vertex 0 (0, 0, 0) is non-manifold", "face 0 (line 9) and face 1 (line 10)",
                     "--repair splits"});
  MeshReport rep;
  MeshRepair r;
  r.split_nonmanifold = true;
  const TriangleMesh m = parse(bowtie, MeshFormat::kOff, r, &rep);
  expect_valid(m, "bowtie");
  EXPECT_EQ(rep.vertices_split, 1u);
  EXPECT_EQ(m.positions.size(), 6u);
  EXPECT_EQ(m.positions[5], Vec3(0, 0, 0));
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {5, 3, 4}}));
  EXPECT_EQ(rep.components, 2u);
  // Two cones touching at their apex (closed surfaces pinched at a point).
  TriangleMesh two;
  two.positions = {{0, 0, 0},  {1, 0, 1},    {0, 1, 1}, {-1, -1, 1},
                   {1, 0, -1}, {-1, -1, -1}, {0, 1, -1}};
  two.triangles = {{0, 1, 2}, {0, 2, 3}, {0, 3, 1}, {1, 3, 2},
                   {0, 4, 5}, {0, 5, 6}, {0, 6, 4}, {4, 6, 5}};
  validate_mesh(two, "pinched", r, &rep);
  expect_valid(two, "pinched");
  EXPECT_EQ(rep.vertices_split, 1u);
  EXPECT_TRUE(rep.closed);
  EXPECT_EQ(rep.components, 2u);
}

TEST(MeshReaderBroken, InconsistentOrientation) {
  TempDir dir;
  const std::vector<Vec3> sq = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  const std::string flipped = off_of(sq, {{0, 1, 2}, {0, 3, 2}});
  expect_file_error(
      dir, "flip.off", flipped,
      {"face 0 (line 8) and face 1 (line 9) both go from vertex 2 (1, 1, 0) to vertex 0 "
       "(0, 0, 0)",
       "orientation", "--repair flips"});
  MeshReport rep;
  MeshRepair r;
  r.orient = true;
  const TriangleMesh m = parse(flipped, MeshFormat::kOff, r, &rep);
  EXPECT_EQ(m.triangles, (std::vector<Tri>{{0, 1, 2}, {0, 2, 3}}));
  EXPECT_EQ(rep.faces_flipped, 1u);
  // A tetrahedron with three faces flipped: flipping the fourth is cheaper.
  TriangleMesh t = tetrahedron();
  for (int f = 0; f < 3; ++f)
    std::swap(t.triangles[static_cast<std::size_t>(f)][1],
              t.triangles[static_cast<std::size_t>(f)][2]);
  const TriangleMesh expected = t;
  validate_mesh(t, "tet", r, &rep);
  EXPECT_EQ(rep.faces_flipped, 1u);
  EXPECT_EQ(t.triangles[3], (Tri{1, 3, 2}));
  EXPECT_EQ(t.triangles[0], expected.triangles[0]);
  expect_valid(t, "tet");
}

TEST(MeshReaderBroken, MoebiusStripIsNotOrientable) {
  TempDir dir;
  // A strip of three quads, u0 u1 u2 / w0 w1 w2, closed with a half twist: u3 = w0, w3 = u0.
  const std::vector<Vec3> p = {{1, 0, 0.2},  {-0.5, 0.87, 0.2},  {-0.5, -0.87, 0.2},
                               {1, 0, -0.2}, {-0.5, 0.87, -0.2}, {-0.5, -0.87, -0.2}};
  const std::uint32_t u0 = 0, u1 = 1, u2 = 2, w0 = 3, w1 = 4, w2 = 5;
  const std::vector<Tri> t = {{u0, u1, w1}, {u0, w1, w0}, {u1, u2, w2},
                              {u1, w2, w1}, {u2, w0, u0}, {u2, u0, w2}};
  const std::string off = off_of(p, t);
  for (const MeshRepair& r : {MeshRepair{}, MeshRepair::all()}) {
    expect_file_error(dir, "moebius.off", off, {"not orientable", "Moebius", "not repairable"}, r);
  }
}

TEST(MeshReaderBroken, WeldAndUnusedVertices) {
  // Two triangles of a square with their shared corners duplicated (and one of them -0).
  const std::string obj =
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv -0 0 0\nv 1 1 0\nv 0 1 0\nv 5 5 5\nf 1 2 3\nf 4 5 6\n";
  MeshReport rep;
  const TriangleMesh a = parse(obj, MeshFormat::kObj, {}, &rep);
  EXPECT_EQ(a.positions.size(), 6u);
  EXPECT_EQ(rep.components, 2u);
  EXPECT_EQ(rep.unused_vertices_dropped, 1u);
  MeshRepair r;
  r.weld = true;
  const TriangleMesh b = parse(obj, MeshFormat::kObj, r, &rep);
  EXPECT_EQ(b.positions.size(), 4u);
  EXPECT_EQ(b.triangles, (std::vector<Tri>{{0, 1, 2}, {0, 2, 3}}));
  EXPECT_EQ(rep.welded_vertices, 2u);
  EXPECT_EQ(rep.unused_vertices_dropped, 1u);
  EXPECT_EQ(rep.components, 1u);
  EXPECT_EQ(rep.boundary_edges, 4u);
  // Welding can make a face degenerate.
  const std::string pinch = "v 0 0 0\nv 1 0 0\nv 0 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n";
  TempDir dir;
  expect_file_error(dir, "pinch.obj", pinch, {"face 0 (line 5)", "degenerate", "after welding"}, r);
  const TriangleMesh c = parse(pinch, MeshFormat::kObj, MeshRepair::all(), &rep);
  EXPECT_EQ(c.triangles.size(), 1u);
  EXPECT_EQ(rep.degenerate_faces_dropped, 1u);
}

TEST(MeshReaderBroken, TriangleValuesFollowTheFaces) {
  TriangleMesh m = tetrahedron();
  m.triangles.push_back({0, 2, 1});  // a duplicate
  m.triangle_values = {1, 2, 3, 4, 5};
  validate_mesh(m, "values", MeshRepair::all());
  EXPECT_EQ(m.triangle_values, (std::vector<float>{1, 2, 3, 4}));
  m.triangle_values = {1};
  expect_error([&] { validate_mesh(m, "values"); }, ErrorKind::kInvalidInput,
               {"values", "1 triangle values for 4 triangles"});
}

}  // namespace
}  // namespace smr
