// OFF reader (Geomview manual, OFF(5)): the keyword `[ST][C][N]OFF` (per-vertex texture
// coordinates, colours and normals are skipped), the counts `V F [E]` (E ignored), V vertices
// `x y z`, then F faces `n i1 .. in [colour]`; `#` comments anywhere. 4-D and n-D variants
// (4OFF, nOFF) are rejected.
#include <string>
#include <string_view>
#include <vector>

#include "smr/io/mesh/source.h"
#include "smr/io/mesh/text.h"

namespace smr::mesh_io {

namespace {

// The keyword `[ST][C][N][4][n]OFF`; true when the vertex lines carry more than x y z.
bool read_off_keyword(Text& t, const std::string& what) {
  const std::string_view kw = t.token();
  if (kw.empty()) throw_input("'" + what + "' is empty; expected an OFF file starting with 'OFF'");
  std::string_view k = kw;
  bool extended = false;
  if (k.substr(0, 2) == "ST") {
    k.remove_prefix(2);
    extended = true;
  }
  if (!k.empty() && k[0] == 'C') {
    k.remove_prefix(1);
    extended = true;
  }
  if (!k.empty() && k[0] == 'N') {
    k.remove_prefix(1);
    extended = true;
  }
  if (k != "OFF") {
    if (k.size() > 3 && k.substr(k.size() - 3) == "OFF" &&
        (k.find('4') != std::string_view::npos || k.find('n') != std::string_view::npos)) {
      throw_input("'" + what + "' is a " + excerpt(kw) +
                  " file (4-D or n-D vertices), which is not supported; expected 3-D OFF");
    }
    throw_input("'" + what + "' is not an OFF file: its header starts with '" + excerpt(kw) +
                "'; expected OFF (or COFF, NOFF, CNOFF, STOFF ...)");
  }
  return extended;
}

struct OffCounts {
  std::uint64_t vertices = 0, faces = 0;
};

// The counts `V F [E]`, checked against what the rest of the file can hold.
OffCounts read_off_counts(Text& t, const std::string& what) {
  const auto read_count = [&](const char* name) {
    const std::string_view tok = t.token();
    std::uint64_t v = 0;
    if (tok.empty()) {
      throw_input("'" + what + "' is truncated: the OFF header ends before the " + name +
                  " count (" + at_line(t.line()) + ")");
    }
    if (!parse_uint(tok, v)) {
      throw_input("'" + what + "' has a malformed OFF header: the " + name + " count is '" +
                  excerpt(tok) + "' (" + at_line(t.line()) + "); expected a non-negative integer");
    }
    return v;
  };
  const std::uint64_t nv = read_count("vertex");
  const std::uint64_t nf = read_count("face");
  if (!t.at_eol()) {
    const std::string_view ne = t.token_in_line();
    std::uint64_t unused = 0;
    if (!parse_uint(ne, unused)) {
      throw_input("'" + what + "' has a malformed OFF header: the edge count is '" + excerpt(ne) +
                  "' (" + at_line(t.line()) + "); expected a non-negative integer");
    }
  }
  // A vertex needs at least 6 bytes ("0 0 0\n"), a face at least 2 ("0\n", degenerate).
  const std::uint64_t room = t.remaining() + 1;
  if (nv > room / 6) {
    throw_input("'" + what + "': the header says " + num(nv) + " vertices, but the rest of the " +
                "file (" + num(std::uint64_t{t.remaining()}) + " bytes) has room for at most " +
                num(room / 6) + " (truncated or corrupt header)");
  }
  if (nf > (room - nv * 6) / 2) {
    throw_input("'" + what + "': the header says " + num(nv) + " vertices and " + num(nf) +
                " faces, but the rest of the file (" + num(std::uint64_t{t.remaining()}) +
                " bytes) has room for at most " + num((room - nv * 6) / 2) +
                " faces after the vertices (truncated or corrupt header)");
  }
  if (nv > kMaxVertices) throw_input("'" + what + "' has too many vertices");
  return {nv, nf};
}

void read_off_vertices(Text& t, const std::string& what, std::uint64_t nv, bool extended,
                       TriangleMesh& mesh) {
  mesh.positions.reserve(static_cast<std::size_t>(nv));
  for (std::uint64_t i = 0; i < nv; ++i) {
    double c[3];
    for (int a = 0; a < 3; ++a) {
      const std::string_view tok = t.token();
      if (tok.empty()) {
        throw_input("'" + what + "' is truncated: it ends in vertex " + num(i) + " of " + num(nv) +
                    " (" + at_line(t.line()) + "); expected 3 coordinates per vertex");
      }
      if (!parse_double(tok, c[a])) {
        throw_input("'" + what + "': vertex " + num(i) + " (" + at_line(t.line()) + ") has '" +
                    excerpt(tok) + "' as its " + "xyz"[a] + " coordinate; expected a number");
      }
    }
    const Vec3 p{c[0], c[1], c[2]};
    if (!finite3(p)) non_finite(what, "vertex " + num(i), p, at_line(t.line()));
    mesh.positions.push_back(p);
    if (extended) t.skip_line();  // normals, colours, texture coordinates
  }
}

// Face f's vertex indices (its count already read on `line`) into idx.
void read_off_face(Text& t, const std::string& what, std::uint64_t nv, std::uint64_t f,
                   std::size_t line, std::int64_t n, std::vector<std::uint32_t>& idx) {
  idx.clear();
  for (std::int64_t j = 0; j < n; ++j) {
    const std::string_view it = t.token_in_line();
    if (it.empty()) {
      throw_input("'" + what + "': face " + num(f) + " (" + at_line(line) + ") says it has " +
                  std::to_string(n) + " vertices but its line lists only " + std::to_string(j) +
                  (t.at_end() ? " (the file is truncated)" : ""));
    }
    std::int64_t v = 0;
    if (!parse_int(it, v)) {
      throw_input("'" + what + "': face " + num(f) + " (" + at_line(line) + ") has '" +
                  excerpt(it) + "' as a vertex index; expected an integer");
    }
    if (v < 0 || static_cast<std::uint64_t>(v) >= nv) {
      throw_input("'" + what + "': face " + num(f) + " (" + at_line(line) + ") references vertex " +
                  std::to_string(v) + ", which is out of range: the " + "file has " + num(nv) +
                  " vertices (indices 0 to " + (nv == 0 ? "none" : num(nv - 1)) + ")");
    }
    idx.push_back(static_cast<std::uint32_t>(v));
  }
}

void read_off_faces(Text& t, const std::string& what, const OffCounts& counts, FaceSink& sink) {
  std::vector<std::uint32_t> idx;
  for (std::uint64_t f = 0; f < counts.faces; ++f) {
    const std::string_view tok = t.token();
    if (tok.empty()) {
      throw_input("'" + what + "' is truncated: it ends after " + num(f) + " of " +
                  num(counts.faces) + " faces (" + at_line(t.line()) + ")");
    }
    const std::size_t line = t.line();
    std::int64_t n = 0;
    if (!parse_int(tok, n) || n < 0) {
      throw_input("'" + what + "': face " + num(f) + " (" + at_line(line) + ") starts with '" +
                  excerpt(tok) + "'; expected its vertex count (a non-negative integer)");
    }
    if (static_cast<std::uint64_t>(n) > t.remaining() / 2 + 1) {
      throw_input("'" + what + "': face " + num(f) + " (" + at_line(line) + ") says it has " +
                  std::to_string(n) +
                  " vertices, more than the rest of the file can hold (truncated or corrupt)");
    }
    read_off_face(t, what, counts.vertices, f, line, n, idx);
    sink.add(idx, line);
    t.skip_line();  // optional colour
  }
}

}  // namespace

void parse_off(std::string_view bytes, Source& src, TriangleMesh& mesh, const MeshRepair& repair,
               MeshReport& report) {
  Text t(bytes, true);
  const bool extended = read_off_keyword(t, src.what);
  const OffCounts counts = read_off_counts(t, src.what);
  read_off_vertices(t, src.what, counts.vertices, extended, mesh);
  FaceSink sink(mesh, src, repair, report, true);
  read_off_faces(t, src.what, counts, sink);
}

}  // namespace smr::mesh_io
