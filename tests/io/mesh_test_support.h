// What the mesh reader tests share (mesh_reader_test.cpp: the readers on real meshes, format
// features and broken files; mesh_validator_test.cpp: validation and repair): an independent check
// of a validated mesh's invariants, writers for the formats the library does not write (OFF,
// STL, binary PLY variants), small meshes, and helpers that expect an error naming the file.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "smr/io/mesh_reader.h"
#include "smr/io/mesh_writer.h"
#include "tests/io/io_test_helpers.h"

namespace smr::mesh_test {

using test::expect_error;
using test::TempDir;
using Bytes = std::vector<std::uint8_t>;
using Tri = std::array<std::uint32_t, 3>;

// ---------------------------------------------------------------------------------------------
// Invariants of a validated mesh, checked independently of the implementation (maps and sets).

inline void expect_valid(const TriangleMesh& m, const std::string& what) {
  SCOPED_TRACE(what);
  const std::size_t n = m.positions.size();
  ASSERT_FALSE(m.triangles.empty());
  std::vector<int> used(n, 0);
  std::set<Tri> sets;
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
  for (const Tri& t : m.triangles) {
    for (std::uint32_t v : t) {
      ASSERT_LT(v, n);
      used[v] = 1;
    }
    ASSERT_TRUE(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]);
    Tri s = t;
    std::sort(s.begin(), s.end());
    ASSERT_TRUE(sets.insert(s).second) << "duplicate face";
    for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
  }
  for (std::size_t v = 0; v < n; ++v) ASSERT_TRUE(used[v]) << "unreferenced vertex " << v;
  for (const auto& [e, c] : directed) {
    ASSERT_EQ(c, 1) << "edge " << e.first << "->" << e.second << " traversed twice";
  }
  // Vertex fans: faces around a vertex connected through the edges at it.
  std::vector<std::vector<std::size_t>> star(n);
  for (std::size_t t = 0; t < m.triangles.size(); ++t) {
    for (std::uint32_t v : m.triangles[t]) star[v].push_back(t);
  }
  for (std::size_t v = 0; v < n; ++v) {
    std::map<std::uint32_t, std::vector<std::size_t>> by_neighbour;
    for (std::size_t t : star[v]) {
      for (std::uint32_t w : m.triangles[t]) {
        if (w != v) by_neighbour[w].push_back(t);
      }
    }
    std::map<std::size_t, std::size_t> parent;
    for (std::size_t t : star[v]) parent[t] = t;
    const auto find = [&](std::size_t x) {
      while (parent[x] != x) x = parent[x];
      return x;
    };
    for (const auto& [w, ts] : by_neighbour) {
      ASSERT_LE(ts.size(), 2u);
      if (ts.size() == 2) parent[find(ts[0])] = find(ts[1]);
    }
    std::set<std::size_t> roots;
    for (std::size_t t : star[v]) roots.insert(find(t));
    ASSERT_EQ(roots.size(), 1u) << "vertex " << v << " has " << roots.size() << " fans";
  }
}

inline std::size_t edge_count(const MeshReport& r) {
  return (3 * r.faces + r.boundary_edges) / 2;
}
inline long euler(const MeshReport& r) {
  return static_cast<long>(r.vertices) - static_cast<long>(edge_count(r)) +
         static_cast<long>(r.faces);
}

// ---------------------------------------------------------------------------------------------
// Writers for the formats the library does not write (and binary PLY variants).

inline std::string shortest(double v) {
  char tmp[32];
  const auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
  return std::string(tmp, r.ptr);
}
inline std::string shortest(float v) {
  char tmp[32];
  const auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
  return std::string(tmp, r.ptr);
}

inline std::string off_text(const TriangleMesh& m) {
  std::string s = "OFF\n# written by mesh_reader_test\n" + std::to_string(m.positions.size()) +
                  " " + std::to_string(m.triangles.size()) + " 0\n";
  for (const Vec3& p : m.positions) {
    s += shortest(p.x) + " " + shortest(p.y) + " " + shortest(p.z) + "\n";
  }
  for (const Tri& t : m.triangles) {
    s += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) +
         "\n";
  }
  return s;
}

template <typename T>
inline void put(Bytes& b, T v, bool big) {
  unsigned char raw[sizeof(T)];
  std::memcpy(raw, &v, sizeof(T));
  if (big != (std::endian::native == std::endian::big)) std::reverse(raw, raw + sizeof(T));
  b.insert(b.end(), raw, raw + sizeof(T));
}

inline Bytes text_bytes(const std::string& s) {
  return Bytes(s.begin(), s.end());
}

/// Binary PLY with double x, y, z among other vertex properties, an int-indexed face list with a
/// per-face property after it, and an extra element with a list before and after the faces.
inline Bytes ply_binary(const TriangleMesh& m, bool big) {
  std::string h = "ply\nformat " + std::string(big ? "binary_big_endian" : "binary_little_endian") +
                  " 1.0\ncomment test\nelement vertex " + std::to_string(m.positions.size()) +
                  "\nproperty uchar flag\nproperty double x\nproperty double y\nproperty double "
                  "z\nproperty float confidence\nelement material 2\nproperty list uchar short "
                  "stuff\nproperty int id\nelement face " +
                  std::to_string(m.triangles.size()) +
                  "\nproperty list uchar int vertex_indices\nproperty ushort group\nelement edge "
                  "1\nproperty int vertex1\nproperty int vertex2\nend_header\n";
  Bytes b = text_bytes(h);
  for (const Vec3& p : m.positions) {
    put<std::uint8_t>(b, 7, big);
    put(b, p.x, big);
    put(b, p.y, big);
    put(b, p.z, big);
    put(b, 0.5f, big);
  }
  for (int k = 0; k < 2; ++k) {  // material: a list of k + 1 shorts, an int
    put<std::uint8_t>(b, static_cast<std::uint8_t>(k + 1), big);
    for (int j = 0; j <= k; ++j) put<std::int16_t>(b, -3, big);
    put<std::int32_t>(b, 42, big);
  }
  for (const Tri& t : m.triangles) {
    put<std::uint8_t>(b, 3, big);
    for (std::uint32_t v : t) put(b, static_cast<std::int32_t>(v), big);
    put<std::uint16_t>(b, 9, big);
  }
  put<std::int32_t>(b, 0, big);
  put<std::int32_t>(b, 1, big);
  return b;
}

inline Bytes stl_binary(const TriangleMesh& m) {
  Bytes b(80, ' ');
  const char* header = "solid binary header text";  // binary files may start with "solid" too
  std::memcpy(b.data(), header, std::strlen(header));
  put(b, static_cast<std::uint32_t>(m.triangles.size()), false);
  for (const Tri& t : m.triangles) {
    for (int k = 0; k < 3; ++k) put(b, 0.0f, false);
    for (std::uint32_t v : t) {
      put(b, static_cast<float>(m.positions[v].x), false);
      put(b, static_cast<float>(m.positions[v].y), false);
      put(b, static_cast<float>(m.positions[v].z), false);
    }
    put<std::uint16_t>(b, 0, false);
  }
  return b;
}

inline std::string stl_ascii(const TriangleMesh& m) {
  std::string s = "solid test mesh\n";
  for (const Tri& t : m.triangles) {
    s += "  facet normal 0 0 1\n    outer loop\n";
    for (std::uint32_t v : t) {
      s += "      vertex " + shortest(static_cast<float>(m.positions[v].x)) + " " +
           shortest(static_cast<float>(m.positions[v].y)) + " " +
           shortest(static_cast<float>(m.positions[v].z)) + "\n";
    }
    s += "    endloop\n  endfacet\n";
  }
  return s + "endsolid test mesh\n";
}

// Not inlined on purpose: g++ 12.2 at -O2 miscompiles the loop below when the three
// (double)(float) conversions are visible to its SLP vectorizer (x and y come out unrounded; see
// the reproducer in the commit message / report).
[[gnu::noinline]] inline double round_to_float(double v) {
  return static_cast<float>(v);
}

inline TriangleMesh to_float(TriangleMesh m) {
  for (Vec3& p : m.positions)
    p = Vec3(round_to_float(p.x), round_to_float(p.y), round_to_float(p.z));
  return m;
}

/// Positions as ASCII STL stores them: the shortest decimal of the float, read as a double.
inline TriangleMesh float_text(TriangleMesh m) {
  const auto back = [](double v) {
    const std::string s = shortest(static_cast<float>(v));
    double d = 0;
    std::from_chars(s.data(), s.data() + s.size(), d);
    return d;
  };
  for (Vec3& p : m.positions) p = Vec3(back(p.x), back(p.y), back(p.z));
  return m;
}

/// Same triangles with the same corner positions (vertex numbering may differ: STL).
inline void expect_same_geometry(const TriangleMesh& a, const TriangleMesh& b) {
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  for (std::size_t t = 0; t < a.triangles.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      ASSERT_EQ(a.positions[a.triangles[t][k]], b.positions[b.triangles[t][k]])
          << "triangle " << t << " corner " << k;
    }
  }
}

inline void expect_equal(const TriangleMesh& a, const TriangleMesh& b) {
  ASSERT_EQ(a.positions.size(), b.positions.size());
  for (std::size_t i = 0; i < a.positions.size(); ++i) {
    using Bits = std::array<std::uint64_t, 3>;
    ASSERT_EQ(std::bit_cast<Bits>(a.positions[i]), std::bit_cast<Bits>(b.positions[i]))
        << "vertex " << i;
  }
  ASSERT_EQ(a.triangles, b.triangles);
}

// ---------------------------------------------------------------------------------------------
// Small meshes

inline TriangleMesh tetrahedron() {
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return m;
}

inline std::string off_of(const std::vector<Vec3>& p, const std::vector<Tri>& t) {
  TriangleMesh m;
  m.positions = p;
  m.triangles = t;
  return off_text(m);
}

inline const std::vector<Vec3> kSix = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0},
                                       {0, 0, 1}, {1, 1, 0}, {1, 0, 1}};

inline TriangleMesh parse(const std::string& text, MeshFormat f, const MeshRepair& r = {},
                          MeshReport* rep = nullptr) {
  return parse_mesh(text, f, "test", r, rep);
}

/// Writes `bytes` to `dir/name`, expects read_mesh to throw `kind` with a message naming the file
/// and containing every needle.
inline void expect_file_error(const TempDir& dir, const std::string& name, const Bytes& bytes,
                              const std::vector<std::string>& needles,
                              const MeshRepair& repair = {},
                              ErrorKind kind = ErrorKind::kInvalidInput) {
  SCOPED_TRACE(name);
  const std::string path = dir.file(name);
  test::write_bytes(path, bytes);
  std::vector<std::string> all = needles;
  all.push_back(path);
  expect_error([&] { (void)read_mesh(path, repair); }, kind, all);
}

inline void expect_file_error(const TempDir& dir, const std::string& name, const std::string& text,
                              const std::vector<std::string>& needles,
                              const MeshRepair& repair = {}) {
  expect_file_error(dir, name, text_bytes(text), needles, repair);
}

}  // namespace smr::mesh_test
