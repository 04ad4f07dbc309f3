// OBJ / PLY writers.
#include "smr/io/mesh_writer.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cstring>
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

// Appends text to a buffer that is flushed to the file in large chunks.
class TextSink {
 public:
  explicit TextSink(AtomicFile& file) : file_(file) { buffer_.reserve(kChunk + 256); }
  void put(std::string_view s) {
    buffer_.append(s);
    maybe_flush();
  }
  void put(double v) {
    char tmp[32];
    const auto r = std::to_chars(tmp, tmp + sizeof tmp, v);  // shortest exact round trip
    buffer_.append(tmp, r.ptr);
  }
  void put_precise(double v) {  // like %.17g, for ASCII PLY readers that expect fixed precision
    char tmp[40];
    const auto r = std::to_chars(tmp, tmp + sizeof tmp, v, std::chars_format::general, 17);
    buffer_.append(tmp, r.ptr);
  }
  void put(std::uint64_t v) {
    char tmp[24];
    const auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
    buffer_.append(tmp, r.ptr);
  }
  void put(float v) {
    char tmp[32];
    const auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
    buffer_.append(tmp, r.ptr);
  }
  void flush() {
    file_.write(buffer_.data(), buffer_.size());
    buffer_.clear();
  }
  void maybe_flush() {
    if (buffer_.size() >= kChunk) flush();
  }

 private:
  static constexpr std::size_t kChunk = 1 << 20;
  AtomicFile& file_;
  std::string buffer_;
};

// Little-endian binary output through a chunk buffer.
class BinarySink {
 public:
  explicit BinarySink(AtomicFile& file) : file_(file) { buffer_.reserve(kChunk + 64); }
  template <typename T>
  void put(T v) {
    unsigned char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if constexpr (std::endian::native == std::endian::big) std::reverse(b, b + sizeof(T));
    buffer_.insert(buffer_.end(), b, b + sizeof(T));
    if (buffer_.size() >= kChunk) flush();
  }
  void flush() {
    file_.write(buffer_.data(), buffer_.size());
    buffer_.clear();
  }

 private:
  static constexpr std::size_t kChunk = 1 << 20;
  AtomicFile& file_;
  std::vector<unsigned char> buffer_;
};

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
  TextSink out(file);
  out.put("# smrdb mesh: ");
  out.put(std::uint64_t{mesh.positions.size()});
  out.put(" vertices, ");
  out.put(std::uint64_t{mesh.triangles.size()});
  out.put(" triangles\n");
  for (const Vec3& p : mesh.positions) {
    out.put("v ");
    out.put(p.x);
    out.put(" ");
    out.put(p.y);
    out.put(" ");
    out.put(p.z);
    out.put("\n");
  }
  for (const auto& t : mesh.triangles) {
    out.put("f ");
    out.put(std::uint64_t{t[0]} + 1);
    out.put(" ");
    out.put(std::uint64_t{t[1]} + 1);
    out.put(" ");
    out.put(std::uint64_t{t[2]} + 1);
    out.put("\n");
  }
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
  file.write(header);
  if (binary) {
    BinarySink out(file);
    for (const Vec3& p : mesh.positions) {
      out.put(p.x);
      out.put(p.y);
      out.put(p.z);
    }
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
      out.put(std::uint8_t{3});
      for (std::uint32_t v : mesh.triangles[t]) out.put(v);
      if (values) out.put(mesh.triangle_values[t]);
    }
    out.flush();
  } else {
    TextSink out(file);
    for (const Vec3& p : mesh.positions) {
      out.put_precise(p.x);
      out.put(" ");
      out.put_precise(p.y);
      out.put(" ");
      out.put_precise(p.z);
      out.put("\n");
    }
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
      out.put("3");
      for (std::uint32_t v : mesh.triangles[t]) {
        out.put(" ");
        out.put(std::uint64_t{v});
      }
      if (values) {
        out.put(" ");
        out.put(mesh.triangle_values[t]);
      }
      out.put("\n");
    }
    out.flush();
  }
  file.commit();
}

}  // namespace smr
