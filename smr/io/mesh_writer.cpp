// OBJ / PLY writers. Everything goes through one 4 MiB block (ChunkBuffer) that numbers are
// formatted into in place (std::to_chars) or stored into as little-endian bytes, and that reaches
// the file in one write when full; on a little-endian host binary PLY's vertices are the
// positions array itself, written in one piece. benchmarks/bench_writers measures them.
#include "smr/io/mesh_writer.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <memory>
#include <string_view>

#include "base/error.h"
#include "smr/io/io_util.h"

namespace smr {

namespace {

using io_util::lower_extension;

void validate_mesh(const std::string& path, const TriangleMesh& mesh) {
  const std::size_t n = mesh.positions.size();
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    for (std::uint32_t v : mesh.triangles[t]) {
      if (v >= n) {
        throw_input("cannot write mesh '" + path + "': triangle " + std::to_string(t) +
                    " references vertex " + std::to_string(v) + " but the mesh has " +
                    std::to_string(n) + " vertices");
      }
    }
  }
  if (!mesh.triangle_values.empty() && mesh.triangle_values.size() != mesh.triangles.size()) {
    throw_input("cannot write mesh '" + path + "': it has " +
                std::to_string(mesh.triangle_values.size()) + " triangle values for " +
                std::to_string(mesh.triangles.size()) +
                " triangles (expected one per triangle or none)");
  }
}

// The writers' output buffer: numbers are formatted (or stored as little-endian bytes) straight
// into one kChunk-sized block, which reaches the file in one AtomicFile::write when full, so a
// mesh of millions of triangles costs a few dozen writes, whatever its format.
class ChunkBuffer {
 public:
  static constexpr std::size_t kChunk = std::size_t{1} << 22;  // 4 MiB

  explicit ChunkBuffer(AtomicFile& file)
      : file_(file), block_(std::make_unique_for_overwrite<char[]>(kChunk)) {}
  /// At least `n` (<= kChunk) free bytes: fill them, then advance() to the end of what was written.
  char* room(std::size_t n) {
    if (kChunk - used_ < n) flush();
    return block_.get() + used_;
  }
  void advance(char* end) { used_ = static_cast<std::size_t>(end - block_.get()); }
  /// Bytes as they are (data may be null when n is 0: an empty vector's); a large run goes to
  /// the file directly, without a copy.
  void put(const void* data, std::size_t n) {
    if (n == 0) return;
    if (n > kChunk / 2) {
      flush();
      file_.write(data, n);
      return;
    }
    char* p = room(n);
    std::memcpy(p, data, n);
    advance(p + n);
  }
  void put(std::string_view s) { put(s.data(), s.size()); }
  void flush() {
    file_.write(block_.get(), used_);
    used_ = 0;
  }

 private:
  AtomicFile& file_;
  std::unique_ptr<char[]> block_;
  std::size_t used_ = 0;
};

// ---- text: one line at a time, formatted in place -------------------------------------------

// The longest number below: a double in either notation ("-2.2250738585072014e-308", 24
// characters), a float (15) or a uint64 (20), with room to spare.
constexpr std::size_t kMaxNumber = 32;
// The longest line: four numbers and their separators (OBJ's `v x y z`, ASCII PLY's
// `3 a b c value`).
constexpr std::size_t kMaxLine = 4 * (kMaxNumber + 1) + 4;

char* put_text(char* p, std::string_view s) {
  std::memcpy(p, s.data(), s.size());
  return p + s.size();
}
// The shortest decimal that reads back as the same value (std::to_chars without a format).
template <typename T>
char* put_number(char* p, T v) {
  return std::to_chars(p, p + kMaxNumber, v).ptr;
}
// 17 significant digits, like %.17g, for ASCII PLY readers that expect a fixed precision.
char* put_precise(char* p, double v) {
  return std::to_chars(p, p + kMaxNumber, v, std::chars_format::general, 17).ptr;
}

// Calls line(p, i) for i in [0, n), each time with room for one line at p; line returns its end.
template <typename Line>
void put_lines(ChunkBuffer& out, std::size_t n, Line line) {
  for (std::size_t i = 0; i < n; ++i) out.advance(line(out.room(kMaxLine), i));
}

// ---- binary: little-endian, whatever the host -------------------------------------------------

template <typename T>
char* put_le(char* p, T v) {
  std::memcpy(p, &v, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(p, p + sizeof(T));
  return p + sizeof(T);
}

// The binary PLY vertices: x, y, z as little-endian doubles. On a little-endian host that is
// exactly the positions array's memory, which goes to the file as it is.
void put_binary_vertices(ChunkBuffer& out, const std::vector<Vec3>& positions) {
  if constexpr (std::endian::native == std::endian::little && sizeof(Vec3) == 3 * sizeof(double)) {
    out.put(positions.data(), positions.size() * sizeof(Vec3));
  } else {
    put_lines(out, positions.size(), [&](char* p, std::size_t i) {
      for (int k = 0; k < 3; ++k) p = put_le(p, positions[i][k]);
      return p;
    });
  }
}

// The binary PLY faces: uchar 3, three uint32 indices, and with kValues the float value; a
// chunk's worth of faces at a time.
template <bool kValues>
void put_binary_faces(ChunkBuffer& out, const TriangleMesh& mesh) {
  constexpr std::size_t kStride = 1 + 3 * sizeof(std::uint32_t) + (kValues ? sizeof(float) : 0);
  constexpr std::size_t kBatch = ChunkBuffer::kChunk / kStride;
  const std::size_t n = mesh.triangles.size();
  for (std::size_t first = 0; first < n; first += kBatch) {
    const std::size_t last = std::min(n, first + kBatch);
    char* p = out.room((last - first) * kStride);
    for (std::size_t t = first; t < last; ++t) {
      *p++ = 3;
      for (std::uint32_t v : mesh.triangles[t]) p = put_le(p, v);
      if constexpr (kValues) p = put_le(p, mesh.triangle_values[t]);
    }
    out.advance(p);
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Writers

void write_mesh(const std::string& path, const TriangleMesh& mesh) {
  const std::string ext = lower_extension(path);
  if (ext == ".obj") return write_obj(path, mesh);
  if (ext == ".ply") return write_ply(path, mesh, true);
  throw_input("cannot write mesh '" + path + "': unknown extension '" + ext +
              "' (expected .obj or .ply)");
}

void write_obj(const std::string& path, const TriangleMesh& mesh) {
  validate_mesh(path, mesh);
  AtomicFile file(path);
  ChunkBuffer out(file);
  out.put("# smrdb mesh: " + std::to_string(mesh.positions.size()) + " vertices, " +
          std::to_string(mesh.triangles.size()) + " triangles\n");
  put_lines(out, mesh.positions.size(), [&](char* p, std::size_t i) {
    const Vec3& v = mesh.positions[i];
    p = put_number(put_text(p, "v "), v.x);
    p = put_number(put_text(p, " "), v.y);
    p = put_number(put_text(p, " "), v.z);
    return put_text(p, "\n");
  });
  put_lines(out, mesh.triangles.size(), [&](char* p, std::size_t t) {
    p = put_text(p, "f");
    for (std::uint32_t v : mesh.triangles[t]) p = put_number(put_text(p, " "), v + 1ull);
    return put_text(p, "\n");
  });
  out.flush();
  file.commit();
}

void write_ply(const std::string& path, const TriangleMesh& mesh, bool binary) {
  validate_mesh(path, mesh);
  const bool values = !mesh.triangle_values.empty();
  std::string header = "ply\nformat ";
  header += binary ? "binary_little_endian" : "ascii";
  header += " 1.0\ncomment smrdb mesh\nelement vertex " + std::to_string(mesh.positions.size()) +
            "\nproperty double x\nproperty double y\nproperty double z\nelement face " +
            std::to_string(mesh.triangles.size()) + "\nproperty list uchar uint vertex_indices\n";
  if (values) header += "property float value\n";
  header += "end_header\n";

  AtomicFile file(path);
  ChunkBuffer out(file);
  out.put(header);
  if (binary) {
    put_binary_vertices(out, mesh.positions);
    if (values) {
      put_binary_faces<true>(out, mesh);
    } else {
      put_binary_faces<false>(out, mesh);
    }
  } else {
    put_lines(out, mesh.positions.size(), [&](char* p, std::size_t i) {
      const Vec3& v = mesh.positions[i];
      p = put_precise(p, v.x);
      p = put_precise(put_text(p, " "), v.y);
      p = put_precise(put_text(p, " "), v.z);
      return put_text(p, "\n");
    });
    put_lines(out, mesh.triangles.size(), [&](char* p, std::size_t t) {
      p = put_text(p, "3");
      for (std::uint32_t v : mesh.triangles[t]) p = put_number(put_text(p, " "), v);
      if (values) p = put_number(put_text(p, " "), mesh.triangle_values[t]);
      return put_text(p, "\n");
    });
  }
  out.flush();
  file.commit();
}

}  // namespace smr
