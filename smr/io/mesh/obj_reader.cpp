// Wavefront OBJ reader (Wavefront Advanced Visualizer manual, appendix B1, "Object files"):
// `v x y z [w | r g b]` and `f` with references `i`, `i/t`, `i//n`, `i/t/n`; negative indices
// count back from the last vertex read, positive ones may refer to vertices defined later in the
// file; every other statement (vt, vn, g, o, s, usemtl, mtllib, l, p, ...) is ignored; `\` at
// the end of a line continues it; `#` starts a comment.
#include <string>
#include <string_view>
#include <vector>

#include "smr/io/mesh/source.h"
#include "smr/io/mesh/text.h"

namespace smr::mesh_io {

namespace {

// The rest of a `v` statement on `line`.
void read_obj_vertex(Text& t, const std::string& what, std::size_t line, TriangleMesh& mesh) {
  double c[3];
  for (int a = 0; a < 3; ++a) {
    const std::string_view tok = t.token_in_line();
    if (tok.empty()) {
      throw_input("'" + what + "': the 'v' statement on " + at_line(line) + " has " +
                  std::to_string(a) + " coordinates; expected x y z");
    }
    if (!parse_double(tok, c[a])) {
      throw_input("'" + what + "': the 'v' statement on " + at_line(line) + " has '" +
                  excerpt(tok) + "' as its " + "xyz"[a] + " coordinate; expected a number");
    }
  }
  const Vec3 p{c[0], c[1], c[2]};
  if (!finite3(p)) {
    non_finite(what, "vertex " + num(std::uint64_t{mesh.positions.size() + 1}), p, at_line(line));
  }
  if (mesh.positions.size() >= kMaxVertices) throw_input("'" + what + "' has too many vertices");
  mesh.positions.push_back(p);
}

// One vertex reference `i[/t][/n]` of the face on `line` as a 0-based index; `count` vertices
// precede it.
std::uint32_t obj_vertex_ref(std::string_view ref, const std::string& what, std::size_t line,
                             std::int64_t count) {
  const std::string_view head = ref.substr(0, ref.find('/'));
  std::int64_t i = 0;
  if (!parse_int(head, i)) {
    throw_input("'" + what + "': the face on " + at_line(line) + " has the vertex reference '" +
                excerpt(ref) + "'; expected i, i/t, i//n or i/t/n with integer i");
  }
  std::int64_t v;
  if (i > 0) {
    v = i - 1;  // may refer to a vertex defined later; checked after the whole file
    if (v >= static_cast<std::int64_t>(kMaxVertices)) {
      throw_input("'" + what + "': the face on " + at_line(line) + " references vertex " +
                  std::to_string(i) + ", which is out of range (too large)");
    }
  } else if (i < 0) {
    v = count + i;
    if (v < 0) {
      throw_input("'" + what + "': the face on " + at_line(line) + " references relative vertex " +
                  std::to_string(i) + ", which is out of range: only " + std::to_string(count) +
                  " vertices precede it");
    }
  } else {
    throw_input("'" + what + "': the face on " + at_line(line) +
                " references vertex 0, which is out of range: OBJ indices start at 1 "
                "(negative ones count back from the last vertex)");
  }
  return static_cast<std::uint32_t>(v);
}

}  // namespace

void parse_obj(std::string_view bytes, Source& src, TriangleMesh& mesh, const MeshRepair& repair,
               MeshReport& report) {
  const std::string& what = src.what;
  src.vertex_base = 1;
  if (bytes.empty()) throw_input("'" + what + "' is empty; expected an OBJ file");
  Text t(bytes, true, true);
  FaceSink sink(mesh, src, repair, report, true);
  std::vector<std::uint32_t> idx;
  while (!t.at_end()) {
    const std::size_t line = t.line();
    const std::string_view kw = t.token_in_line();
    if (kw == "v") {
      read_obj_vertex(t, what, line, mesh);
    } else if (kw == "f") {
      idx.clear();
      const auto count = static_cast<std::int64_t>(mesh.positions.size());
      for (std::string_view ref = t.token_in_line(); !ref.empty(); ref = t.token_in_line()) {
        idx.push_back(obj_vertex_ref(ref, what, line, count));
      }
      sink.add(idx, line);
    }
    t.skip_line();  // everything else (vt, vn, g, o, s, usemtl, mtllib, l, p, comments) is ignored
  }
}

}  // namespace smr::mesh_io
