// What the mesh readers share (smr/io/mesh/source.h): message labels and the face sink.
#include "smr/io/mesh/source.h"

#include <numeric>

#include "smr/io/mesh/text.h"

namespace smr::mesh_io {

void flush_stream(TriangleMesh& mesh, Source& src) {
  if (!src.streaming()) return;
  if (!mesh.positions.empty()) src.vertex_batch(mesh.positions);
  if (!mesh.triangles.empty()) src.triangle_batch(mesh.triangles);
  mesh.positions.clear();
  mesh.triangles.clear();
}

std::string face_label(const Source& src, std::size_t t) {
  const std::size_t f = src.face_of_triangle.empty() ? t : src.face_of_triangle[t];
  std::string s = std::string(src.face_word) + " " + num(std::uint64_t{f});
  std::string extra;
  if (f < src.line_of_face.size()) extra = "line " + num(std::uint64_t{src.line_of_face[f]});
  if (!src.face_of_triangle.empty()) {
    const bool polygon = (t > 0 && src.face_of_triangle[t - 1] == f) ||
                         (t + 1 < src.face_of_triangle.size() && src.face_of_triangle[t + 1] == f);
    if (polygon) {
      std::size_t first = t;
      while (first > 0 && src.face_of_triangle[first - 1] == f) --first;
      extra += (extra.empty() ? "" : ", ") + std::string("fan triangle ") +
               num(std::uint64_t{t - first});
    }
  }
  if (!extra.empty()) s += " (" + extra + ")";
  return s;
}

std::string vertex_label(const Source& src, const std::vector<Vec3>& positions, std::uint32_t v) {
  const std::string at = v < positions.size() ? pos_text(positions[v]) : "(?)";
  if (src.vertex_base < 0) return "the vertex at " + at;
  return "vertex " + num(std::uint64_t{v} + static_cast<std::uint64_t>(src.vertex_base)) + " " + at;
}

std::string vertex_number(const Source& src, std::uint64_t v) {
  return num(v + static_cast<std::uint64_t>(std::max(src.vertex_base, 0)));
}

void non_finite(const std::string& what, const std::string& label, const Vec3& p,
                const std::string& where) {
  const double c[3] = {p.x, p.y, p.z};
  int k = 0;
  while (k < 2 && std::isfinite(c[k])) ++k;
  throw_input("'" + what + "': " + label + (where.empty() ? "" : " (" + where + ")") + " has " +
              (std::isnan(c[k]) ? "a NaN" : "an infinite") + " " + "xyz"[k] +
              " coordinate; expected finite coordinates (not repairable)");
}

// ---------------------------------------------------------------------------------------------
// FaceSink

void FaceSink::add(std::span<const std::uint32_t> idx, std::size_t line) {
  if (faces_ >= kNone) throw_input("'" + src_.what + "' has too many faces");
  const auto f = static_cast<std::uint32_t>(faces_++);
  if (lines_) {
    src_.line_of_face.push_back(static_cast<std::uint32_t>(std::min<std::size_t>(line, kNone)));
  }
  if (idx.size() < 3) {
    if (!repair_.drop_degenerate) {
      throw_input("'" + src_.what + "': " + face_label_for(f) + " has " +
                  num(std::uint64_t{idx.size()}) + (idx.size() == 1 ? " vertex" : " vertices") +
                  "; expected at least 3 (repairable: --repair drops degenerate faces)");
    }
    ++report_.degenerate_faces_dropped;
    if (!src_.streaming()) start_map();
    return;
  }
  if (triangles_ + idx.size() - 2 > kMaxTriangles) {
    throw_input("'" + src_.what + "' has more than " + num(std::uint64_t{kMaxTriangles}) +
                " triangles, which is not supported");
  }
  if (src_.streaming()) check_streamed(idx, f);
  if (idx.size() > 3) {
    ++report_.polygons_triangulated;
    if (!src_.streaming()) start_map();
  }
  for (std::size_t i = 1; i + 1 < idx.size(); ++i) {
    mesh_.triangles.push_back({idx[0], idx[i], idx[i + 1]});
    ++triangles_;
    if (mapped_) src_.face_of_triangle.push_back(f);
  }
  if (src_.streaming() && mesh_.triangles.size() >= kStreamBatch) {
    src_.triangle_batch(mesh_.triangles);
    mesh_.triangles.clear();
  }
}

// Nothing validates a streamed mesh afterwards: what one face can show is checked here.
void FaceSink::check_streamed(std::span<const std::uint32_t> idx, std::uint32_t f) const {
  for (std::size_t i = 0; i < idx.size(); ++i) {
    for (std::size_t j = i + 1; j < idx.size(); ++j) {
      if (idx[i] == idx[j]) {
        throw_input("'" + src_.what + "': " + face_label_for(f) + " uses vertex " +
                    num(std::uint64_t{idx[i]}) +
                    " twice (degenerate); a streamed mesh cannot be repaired: ingest it in "
                    "memory (without --memory) with --repair");
      }
    }
  }
}

std::string FaceSink::face_label_for(std::uint32_t f) const {
  std::string s = std::string(src_.face_word) + " " + num(std::uint64_t{f});
  if (f < src_.line_of_face.size()) s += " (line " + num(std::uint64_t{src_.line_of_face[f]}) + ")";
  return s;
}

void FaceSink::start_map() {
  if (mapped_) return;
  mapped_ = true;
  src_.face_of_triangle.resize(mesh_.triangles.size());
  std::iota(src_.face_of_triangle.begin(), src_.face_of_triangle.end(), std::uint32_t{0});
}

}  // namespace smr::mesh_io
