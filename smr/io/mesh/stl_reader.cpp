// STL reader (3D Systems, "StereoLithography Interface Specification", 1989): binary when the
// size is exactly 84 + 50 * (the little-endian triangle count at byte 80), else ASCII (`solid` ..
// `facet normal` .. `outer loop` .. `vertex` x3 .. `endloop` .. `endfacet` .. `endsolid`, several
// solids allowed). STL stores every triangle with its own three corners, so corners with equal
// positions are merged into shared vertices in order of first appearance (how STL encodes
// connectivity, not a repair).
#include <cctype>
#include <string>
#include <string_view>
#include <vector>

#include "smr/io/mesh/ply_types.h"
#include "smr/io/mesh/source.h"
#include "smr/io/mesh/text.h"

namespace smr::mesh_io {

namespace {

bool starts_with_solid(std::string_view b) {
  std::size_t i = 0;
  while (i < b.size() && (b[i] == ' ' || b[i] == '\t' || b[i] == '\r' || b[i] == '\n')) ++i;
  return b.substr(i, 5) == "solid";
}

// ASCII STL: starts with "solid", its first line is text and the next word is "facet" or
// "endsolid". (Binary files often start with "solid" too: their 80-byte header is free text.)
bool looks_like_ascii_stl(std::string_view b) {
  if (!starts_with_solid(b)) return false;
  const std::size_t nl = b.find('\n');
  if (nl == std::string_view::npos || nl > 65536) return false;
  for (std::size_t i = 0; i < nl; ++i) {
    const auto c = static_cast<unsigned char>(b[i]);
    if ((c < 0x20 && c != '\t' && c != '\r') || c >= 0x7f) return false;
  }
  std::size_t i = nl + 1;
  while (i < b.size() && std::isspace(static_cast<unsigned char>(b[i]))) ++i;
  return b.substr(i, 5) == "facet" || b.substr(i, 8) == "endsolid";
}

// Binary STL: an 80-byte header, the facet count, then 50 bytes per facet (normal, three
// corners as float32, a 2-byte attribute).
void read_binary_stl(std::string_view bytes, const std::string& what, PositionWelder& welder,
                     FaceSink& sink, TriangleMesh& mesh) {
  if (bytes.size() < 84) {
    throw_input("'" + what + "' is not an STL file: it is too short for a binary STL (" +
                num(std::uint64_t{bytes.size()}) + " bytes, the header alone is 84) and does " +
                "not start with 'solid'");
  }
  const auto* data = reinterpret_cast<const std::uint8_t*>(bytes.data());
  const std::uint64_t n = load_bits(data + 80, 4, false);
  if (bytes.size() != 84 + 50 * n) {
    throw_input("'" + what + "' is truncated or not an STL file: as binary STL its header " +
                "says " + num(n) + " facets, which need 84 + 50 * " + num(n) + " = " +
                num(84 + 50 * n) + " bytes, but the file has " + num(std::uint64_t{bytes.size()}) +
                " (and it is not ASCII STL)");
  }
  if (n > kMaxTriangles) throw_input("'" + what + "' has too many facets");
  mesh.triangles.reserve(static_cast<std::size_t>(n));
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t* r = data + 84 + 50 * i + 12;
    std::uint32_t idx[3];
    for (int c = 0; c < 3; ++c) {
      const Vec3 p{load_double(PlyType::kF32, r + 12 * c, false),
                   load_double(PlyType::kF32, r + 12 * c + 4, false),
                   load_double(PlyType::kF32, r + 12 * c + 8, false)};
      if (!finite3(p)) {
        non_finite(what, "corner " + std::to_string(c) + " of facet " + num(i), p, "");
      }
      idx[c] = welder.add(p);
    }
    sink.add(idx, 0);
  }
}

// ASCII STL, keyword by keyword; messages say where (facet and line) the text went wrong.
class AsciiStl {
 public:
  AsciiStl(std::string_view bytes, const std::string& what) : t_(bytes, false), what_(what) {}

  void read(PositionWelder& welder, FaceSink& sink) {
    expect("solid");
    t_.rest_of_line();
    for (;;) {
      const std::string_view tok = t_.token();
      if (tok == "facet") {
        read_facet(welder, sink);
      } else if (tok == "endsolid") {
        t_.rest_of_line();
        t_.skip_space();
        if (t_.at_end()) break;
        expect("solid");
        t_.rest_of_line();
      } else if (tok.empty() || t_.at_end()) {
        throw_input("'" + what_ + "' is truncated: it ends after " + num(facet_) +
                    " facets without 'endsolid' (" + at_line(t_.line()) + ")");
      } else {
        throw_input("'" + what_ + "': found '" + excerpt(tok) + "' (" + at_line(t_.line()) +
                    "); expected 'facet' or 'endsolid'");
      }
    }
  }

 private:
  // After `facet`: `normal` n n n `outer loop` (`vertex` x y z)* `endloop` `endfacet`.
  void read_facet(PositionWelder& welder, FaceSink& sink) {
    const std::size_t line = t_.line();
    in_facet_ = true;
    expect("normal");
    for (int k = 0; k < 3; ++k) (void)number();
    expect("outer");
    expect("loop");
    idx_.clear();
    for (;;) {
      const std::string_view w = t_.token();
      if (w == "endloop") break;
      if (w != "vertex") {
        if (w.empty() || t_.at_end()) {
          throw_input("'" + what_ + "' is truncated: it ends " + where());
        }
        throw_input("'" + what_ + "': found '" + excerpt(w) + "' " + where() +
                    "; expected 'vertex' or 'endloop'");
      }
      const double x = number();
      const double y = number();
      const double z = number();
      const Vec3 p{x, y, z};
      if (!finite3(p)) {
        non_finite(what_, "corner " + std::to_string(idx_.size()) + " of facet " + num(facet_), p,
                   at_line(t_.line()));
      }
      idx_.push_back(welder.add(p));
    }
    expect("endfacet");
    sink.add(idx_, line);
    in_facet_ = false;
    ++facet_;
  }

  std::string where() const {
    return (in_facet_ ? "in facet " + num(facet_) + " " : std::string()) + "(" +
           at_line(t_.line()) + ")";
  }

  void expect(std::string_view word) {
    const std::string_view tok = t_.token();
    if (tok == word) return;
    if (tok.empty() || t_.at_end()) {
      throw_input("'" + what_ + "' is truncated: it ends " + where() + " where '" +
                  std::string(word) + "' was expected");
    }
    throw_input("'" + what_ + "': found '" + excerpt(tok) + "' " + where() + "; expected '" +
                std::string(word) + "'");
  }

  double number() {
    const std::string_view tok = t_.token();
    double v = 0;
    if (tok.empty()) throw_input("'" + what_ + "' is truncated: it ends " + where());
    if (!parse_double(tok, v)) {
      if (t_.at_end()) {
        throw_input("'" + what_ + "' is truncated: it ends with '" + excerpt(tok) + "' " + where() +
                    ", where a number was expected");
      }
      throw_input("'" + what_ + "': found '" + excerpt(tok) + "' " + where() +
                  "; expected a number");
    }
    return v;
  }

  Text t_;
  const std::string& what_;
  std::vector<std::uint32_t> idx_;
  std::uint64_t facet_ = 0;
  bool in_facet_ = false;
};

}  // namespace

void parse_stl(std::string_view bytes, Source& src, TriangleMesh& mesh, const MeshRepair& repair,
               MeshReport& report) {
  const std::string& what = src.what;
  src.vertex_base = -1;
  src.face_word = "facet";
  if (bytes.empty()) throw_input("'" + what + "' is empty; expected an STL file");
  PositionWelder welder(mesh.positions);
  const bool ascii = bytes.size() < 84 ? starts_with_solid(bytes) : looks_like_ascii_stl(bytes);
  if (!ascii) {
    FaceSink sink(mesh, src, repair, report, false);
    read_binary_stl(bytes, what, welder, sink, mesh);
    return;
  }
  FaceSink sink(mesh, src, repair, report, true);
  AsciiStl(bytes, what).read(welder, sink);
}

}  // namespace smr::mesh_io
