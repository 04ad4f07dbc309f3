// What the mesh readers share (internal to smr/io/mesh): where a mesh came from, for messages
// (face and vertex numbering as the file has it), the face sink every parser hands its faces to
// (fan triangulation, faces of fewer than three vertices, streamed batches), the position welder
// (STL corners, the weld repair) and the reader entry points.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "base/error.h"
#include "smr/core/ids.h"
#include "smr/core/mesh.h"
#include "smr/io/mesh_reader.h"

namespace smr::mesh_io {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
// Face corners (3 per triangle) are numbered with 32 bits.
constexpr std::size_t kMaxTriangles = (std::size_t{kNone} - 1) / 3;
constexpr std::size_t kMaxVertices = std::size_t{kNone} - 1;

/// Where a mesh came from, for messages: face and vertex numbering as the file has it.
struct Source {
  std::string what;
  const char* face_word = "face";
  int vertex_base = 0;  // 0 or 1 (OBJ); -1: vertices have no number in the file (STL)
  std::vector<std::uint32_t> face_of_triangle;  // empty: triangle t is face t
  std::vector<std::uint32_t> line_of_face;      // empty: no line numbers (binary formats)
  // Streaming (open_mesh_stream, PLY): positions and triangles are handed over in batches and
  // dropped, so the mesh is never held; faces get no line numbers.
  std::function<void(std::span<const Vec3>)> vertex_batch;
  std::function<void(std::span<const std::array<std::uint32_t, 3>>)> triangle_batch;
  bool streaming() const { return static_cast<bool>(vertex_batch); }
};

constexpr std::size_t kStreamBatch = std::size_t{1} << 16;

inline void push_vertex(TriangleMesh& mesh, Source& src, const Vec3& v) {
  mesh.positions.push_back(v);
  if (src.streaming() && mesh.positions.size() >= kStreamBatch) {
    src.vertex_batch(mesh.positions);
    mesh.positions.clear();
  }
}

/// Hands what is left of a streamed mesh over.
void flush_stream(TriangleMesh& mesh, Source& src);

/// "face 12 (line 40, fan triangle 1)", "facet 3": triangle t as the file numbers it.
std::string face_label(const Source& src, std::size_t t);
/// "vertex 7 (x, y, z)" (numbered as the file does), or "the vertex at (x, y, z)" (STL).
std::string vertex_label(const Source& src, const std::vector<Vec3>& positions, std::uint32_t v);
/// Vertex v's number in the file.
std::string vertex_number(const Source& src, std::uint64_t v);

inline bool finite3(const Vec3& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

/// Throws kInvalidInput for the first non-finite coordinate of p; `label` names the vertex,
/// `where` (when not empty) its line.
[[noreturn]] void non_finite(const std::string& what, const std::string& label, const Vec3& p,
                             const std::string& where);

/// Collects faces from a parser: fan-triangulates polygons, handles faces of fewer than three
/// vertices, and keeps the triangle -> file face map when the two differ.
class FaceSink {
 public:
  FaceSink(TriangleMesh& mesh, Source& src, const MeshRepair& repair, MeshReport& report,
           bool lines)
      : mesh_(mesh), src_(src), repair_(repair), report_(report), lines_(lines) {}

  /// Adds the face with vertices `idx` (all in range), found on `line` (text formats).
  void add(std::span<const std::uint32_t> idx, std::size_t line);
  std::size_t faces() const { return faces_; }

 private:
  std::string face_label_for(std::uint32_t f) const;
  void check_streamed(std::span<const std::uint32_t> idx, std::uint32_t f) const;
  void start_map();

  TriangleMesh& mesh_;
  Source& src_;
  const MeshRepair& repair_;
  MeshReport& report_;
  bool lines_;
  bool mapped_ = false;
  std::size_t faces_ = 0;
  std::uint64_t triangles_ = 0;
};

/// Hash of a position compared as numbers: adding +0.0 turns -0.0 into +0.0.
inline std::uint64_t position_hash(const Vec3& p) {
  const auto bx = std::bit_cast<std::uint64_t>(p.x + 0.0);
  const auto by = std::bit_cast<std::uint64_t>(p.y + 0.0);
  const auto bz = std::bit_cast<std::uint64_t>(p.z + 0.0);
  return mix64(bx ^ mix64(by ^ mix64(bz)));
}

/// Merges equal positions (open addressing, linear probing, power-of-two table grown at half
/// load). `add` returns the index of the first position equal to p, appending p when new.
class PositionWelder {
 public:
  explicit PositionWelder(std::vector<Vec3>& positions, std::size_t expected = 512)
      : positions_(positions) {
    grow(std::bit_ceil(std::max<std::size_t>(expected, 512) * 2));
  }
  std::uint32_t add(const Vec3& p) {
    if ((positions_.size() + 1) * 2 > table_.size()) grow(table_.size() * 2);
    std::size_t i = position_hash(p) & (table_.size() - 1);
    for (;;) {
      const std::uint32_t e = table_[i];
      if (e == kNone) break;
      if (positions_[e] == p) return e;
      i = (i + 1) & (table_.size() - 1);
    }
    if (positions_.size() >= kMaxVertices) throw_input("too many vertices");
    const auto id = static_cast<std::uint32_t>(positions_.size());
    table_[i] = id;
    positions_.push_back(p);
    return id;
  }

 private:
  void grow(std::size_t size) {
    table_.assign(size, kNone);
    for (std::size_t v = 0; v < positions_.size(); ++v) {
      std::size_t i = position_hash(positions_[v]) & (size - 1);
      while (table_[i] != kNone) i = (i + 1) & (size - 1);
      table_[i] = static_cast<std::uint32_t>(v);
    }
  }
  std::vector<Vec3>& positions_;
  std::vector<std::uint32_t> table_;
};

// The readers (one file each): parse `bytes` into `mesh`, faces through a FaceSink, numbering
// recorded in `src`. PLY may stream (src.vertex_batch set), the others never do.
void parse_ply(std::string_view bytes, Source& src, TriangleMesh& mesh, const MeshRepair& repair,
               MeshReport& report);
void parse_obj(std::string_view bytes, Source& src, TriangleMesh& mesh, const MeshRepair& repair,
               MeshReport& report);
void parse_off(std::string_view bytes, Source& src, TriangleMesh& mesh, const MeshRepair& repair,
               MeshReport& report);
void parse_stl(std::string_view bytes, Source& src, TriangleMesh& mesh, const MeshRepair& repair,
               MeshReport& report);

/// validate_mesh's work (validator.cpp): checks and repairs `mesh` in place, filling `rep`.
void validate_faces(TriangleMesh& mesh, const Source& src, const MeshRepair& repair,
                    MeshReport& rep);

}  // namespace smr::mesh_io
