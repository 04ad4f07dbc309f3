// PLY reader (Turk 1994, "The PLY Polygon File Format", as documented at
// paulbourke.net/dataformats/ply): ascii, binary_little_endian and binary_big_endian. The
// `vertex` element must have scalar properties x, y, z of any PLY type; the `face` element a list
// property `vertex_indices` or `vertex_index` with integer count and index types; every other
// property and element is skipped. The steps: the header, the roles of its elements, the declared
// counts against the size of the data, then the data (binary: fixed-size records read in place,
// others property by property; ascii: token by token). The same parse serves the streamed path
// (ply_stream.cpp), which hands vertices and triangles over in batches instead of holding them.
#include <string>
#include <string_view>
#include <vector>

#include "smr/io/mesh/ply_types.h"
#include "smr/io/mesh/source.h"
#include "smr/io/mesh/text.h"

namespace smr::mesh_io {

namespace {

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kF32;       // scalar type, or list item type
  PlyType count_type = PlyType::kU8;  // list count type
  bool list = false;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> props;
};

enum class PlyEncoding { kUnset, kAscii, kLittle, kBig };

struct PlyHeader {
  PlyEncoding encoding = PlyEncoding::kUnset;
  std::vector<PlyElement> elements;
  std::size_t data_start = 0;  // the byte after the 'end_header' line
  std::size_t lines = 0;       // the header's lines
};

std::string element_noun(const PlyElement& e) {
  if (e.name == "vertex") return "vertices";
  if (e.name == "face") return "faces";
  std::string s = "'";
  s += excerpt(e.name);
  s += "' elements";
  return s;
}

std::string element_one(const PlyElement& e) {
  if (e.name == "vertex" || e.name == "face") return e.name;
  std::string s = "'";
  s += excerpt(e.name);
  s += "' element";
  return s;
}

// ---------------------------------------------------------------------------------------------
// Header

// The header's lines one by one ("\r\n" or "\n"), and its error message naming the current line.
class HeaderLines {
 public:
  HeaderLines(std::string_view bytes, const std::string& what) : bytes_(bytes), what_(what) {}

  bool next() {
    if (pos_ >= bytes_.size()) return false;
    const std::size_t nl = bytes_.find('\n', pos_);
    const std::size_t e = nl == std::string_view::npos ? bytes_.size() : nl;
    line_ = bytes_.substr(pos_, e - pos_);
    if (!line_.empty() && line_.back() == '\r') line_.remove_suffix(1);
    pos_ = nl == std::string_view::npos ? bytes_.size() : nl + 1;
    ++line_no_;
    return true;
  }
  std::string_view& line() { return line_; }
  std::size_t pos() const { return pos_; }
  std::size_t line_no() const { return line_no_; }
  // The line's first (up to 8) blank-separated tokens.
  std::vector<std::string_view> tokens() const {
    std::vector<std::string_view> out;
    std::size_t i = 0;
    while (i < line_.size() && out.size() < 8) {
      while (i < line_.size() && (line_[i] == ' ' || line_[i] == '\t')) ++i;
      const std::size_t b = i;
      while (i < line_.size() && line_[i] != ' ' && line_[i] != '\t') ++i;
      if (i > b) out.push_back(line_.substr(b, i - b));
    }
    return out;
  }
  [[noreturn]] void bad(const std::string& why) const {
    throw_input("'" + what_ + "' has a malformed PLY header: " + why + " (line " +
                num(std::uint64_t{line_no_}) + ": '" + excerpt(line_, 60) + "')");
  }

 private:
  std::string_view bytes_;
  const std::string& what_;
  std::string_view line_;
  std::size_t pos_ = 0, line_no_ = 0;
};

void read_format_line(const HeaderLines& h, const std::vector<std::string_view>& tok,
                      PlyEncoding& enc) {
  if (enc != PlyEncoding::kUnset) h.bad("a second 'format' line");
  if (tok.size() != 3) h.bad("expected 'format <ascii|binary_little_endian|...> 1.0'");
  if (tok[1] == "ascii") {
    enc = PlyEncoding::kAscii;
  } else if (tok[1] == "binary_little_endian") {
    enc = PlyEncoding::kLittle;
  } else if (tok[1] == "binary_big_endian") {
    enc = PlyEncoding::kBig;
  } else {
    h.bad("unknown format '" + excerpt(tok[1]) +
          "' (expected ascii, binary_little_endian or binary_big_endian)");
  }
}

void read_element_line(const HeaderLines& h, const std::vector<std::string_view>& tok,
                       std::vector<PlyElement>& elements) {
  if (tok.size() != 3) h.bad("expected 'element <name> <count>'");
  PlyElement e;
  e.name = std::string(tok[1]);
  if (!parse_uint(tok[2], e.count)) {
    h.bad("the count of element '" + excerpt(tok[1]) + "' is '" + excerpt(tok[2]) +
          "'; expected a non-negative integer");
  }
  for (const PlyElement& other : elements) {
    if (other.name == e.name) h.bad("element '" + excerpt(e.name) + "' is declared twice");
  }
  elements.push_back(std::move(e));
}

PlyProperty read_property_line(const HeaderLines& h, const std::vector<std::string_view>& tok) {
  PlyProperty p;
  if (tok.size() >= 2 && tok[1] == "list") {
    if (tok.size() != 5) h.bad("expected 'property list <count type> <item type> <name>'");
    if (!ply_type(tok[2], p.count_type) || !ply_type(tok[3], p.type)) {
      h.bad(
          "unknown property type (expected char, uchar, short, ushort, int, uint, "
          "float, double or int8 .. float64)");
    }
    if (!ply_is_integer(p.count_type)) h.bad("a list count type must be an integer type");
    p.list = true;
    p.name = std::string(tok[4]);
  } else {
    if (tok.size() != 3) h.bad("expected 'property <type> <name>'");
    if (!ply_type(tok[1], p.type)) {
      h.bad("unknown property type '" + excerpt(tok[1]) +
            "' (expected char, uchar, short, ushort, int, uint, float, double or "
            "int8 .. float64)");
    }
    p.name = std::string(tok[2]);
  }
  return p;
}

PlyHeader read_ply_header(std::string_view bytes, const std::string& what) {
  if (bytes.empty())
    throw_input("'" + what + "' is empty; expected a PLY file starting with 'ply'");
  HeaderLines h(bytes, what);
  h.next();
  std::string_view& first = h.line();
  while (!first.empty() && (first.back() == ' ' || first.back() == '\t')) first.remove_suffix(1);
  if (first != "ply") {
    throw_input("'" + what + "' is not a PLY file: it starts with '" + excerpt(first) +
                "'; expected the line 'ply'");
  }
  PlyHeader header;
  bool ended = false;
  while (h.next()) {
    const std::vector<std::string_view> tok = h.tokens();
    if (tok.empty()) continue;
    if (tok[0] == "end_header") {
      ended = true;
      break;
    }
    if (tok[0] == "comment" || tok[0] == "obj_info") continue;
    if (tok[0] == "format") {
      read_format_line(h, tok, header.encoding);
    } else if (tok[0] == "element") {
      read_element_line(h, tok, header.elements);
    } else if (tok[0] == "property") {
      if (header.elements.empty()) h.bad("a property before any element");
      header.elements.back().props.push_back(read_property_line(h, tok));
    } else {
      h.bad("unexpected line");
    }
  }
  if (!ended) {
    throw_input("'" + what +
                "' is truncated or not a PLY file: its header has no 'end_header' "
                "line");
  }
  if (header.encoding == PlyEncoding::kUnset) {
    throw_input("'" + what + "' has a malformed PLY header: no 'format' line");
  }
  header.data_start = h.pos();
  header.lines = h.line_no();
  return header;
}

// ---------------------------------------------------------------------------------------------
// The roles of the elements

struct PlyRoles {
  int vertex_el = -1, face_el = -1;  // element numbers
  int xyz[3] = {-1, -1, -1};         // property numbers in the vertex element
  int list_prop = -1;                // the index list's property number in the face element
};

void find_vertex_roles(const PlyElement& e, const std::string& what, PlyRoles& roles) {
  for (std::size_t j = 0; j < e.props.size(); ++j) {
    for (int a = 0; a < 3; ++a) {
      if (e.props[j].name == std::string(1, "xyz"[a])) {
        if (e.props[j].list) {
          throw_input("'" + what + "': the vertex property '" + e.props[j].name +
                      "' is a list; expected a scalar coordinate");
        }
        roles.xyz[a] = static_cast<int>(j);
      }
    }
  }
}

void find_face_roles(const PlyElement& e, const std::string& what, PlyRoles& roles) {
  for (std::size_t j = 0; j < e.props.size(); ++j) {
    const PlyProperty& p = e.props[j];
    if (p.name == "vertex_indices" || p.name == "vertex_index") {
      if (!p.list) {
        throw_input("'" + what + "': the face property '" + p.name +
                    "' is not a list; expected 'property list <count type> <index type> " + p.name +
                    "'");
      }
      if (!ply_is_integer(p.type)) {
        throw_input("'" + what + "': the face property '" + p.name +
                    "' has a floating-point index type; expected an integer type");
      }
      if (roles.list_prop < 0) roles.list_prop = static_cast<int>(j);
    }
  }
}

PlyRoles find_roles(const std::vector<PlyElement>& elements, const std::string& what) {
  PlyRoles roles;
  for (std::size_t i = 0; i < elements.size(); ++i) {
    const PlyElement& e = elements[i];
    if (e.name == "vertex") {
      roles.vertex_el = static_cast<int>(i);
      find_vertex_roles(e, what, roles);
    } else if (e.name == "face") {
      roles.face_el = static_cast<int>(i);
      find_face_roles(e, what, roles);
    }
  }
  if (roles.vertex_el < 0) throw_input("'" + what + "' has no 'vertex' element; expected a mesh");
  for (int a = 0; a < 3; ++a) {
    if (roles.xyz[a] < 0) {
      throw_input("'" + what + "': the vertex element has no property '" +
                  std::string(1, "xyz"[a]) + "'; expected x, y and z");
    }
  }
  if (roles.face_el < 0) {
    throw_input("'" + what + "' has no 'face' element; expected a mesh, not a point cloud");
  }
  if (roles.list_prop < 0) {
    throw_input("'" + what +
                "': the face element has no list property 'vertex_indices' or "
                "'vertex_index'");
  }
  return roles;
}

// Every element's count against the size of the data: a record needs at least the sizes of its
// properties (binary) or two bytes per property (ascii: a digit and a separator).
void check_counts(const std::vector<PlyElement>& elements, bool binary, std::size_t data_size,
                  const std::string& what) {
  std::uint64_t used = 0;
  for (const PlyElement& e : elements) {
    std::uint64_t min = 0;
    for (const PlyProperty& p : e.props) {
      min += binary ? static_cast<std::uint64_t>(ply_size(p.list ? p.count_type : p.type)) : 2;
    }
    if (min == 0) continue;
    const std::uint64_t avail = std::uint64_t{data_size} + (binary ? 0 : 1);
    const std::uint64_t room = (used >= avail ? 0 : avail - used) / min;
    if (e.count > room) {
      throw_input("'" + what + "': the header says " + num(e.count) + " " + element_noun(e) +
                  ", but the rest of the file (" + num(std::uint64_t{data_size}) +
                  " bytes of data) has room for at most " + num(room) + " (each needs at least " +
                  num(min) + " bytes; truncated or corrupt header)");
    }
    used += e.count * min;
  }
}

// ---------------------------------------------------------------------------------------------
// The data

// What reading the data needs: the input, the header's elements and roles, and where the mesh
// goes.
struct PlyBody {
  const std::string& what;
  std::string_view bytes;
  const std::vector<PlyElement>& elements;
  const PlyRoles& roles;
  std::uint64_t nv;  // the vertex count
  TriangleMesh& mesh;
  Source& src;
  FaceSink& sink;
};

[[noreturn]] void bad_index(const PlyBody& b, std::uint64_t f, std::int64_t v,
                            const std::string& where) {
  throw_input("'" + b.what + "': face " + num(f) + (where.empty() ? "" : " (" + where + ")") +
              " references vertex " + std::to_string(v) + ", which is out of range: the file " +
              "has " + num(b.nv) + " vertices (indices 0 to " +
              (b.nv == 0 ? "none" : num(b.nv - 1)) + ")");
}

// Binary: record i of element e needs n bytes at byte `at`.
void need(const PlyBody& b, std::size_t at, std::size_t n, const PlyElement& e, std::uint64_t i) {
  if (n > b.bytes.size() - at) {
    throw_input("'" + b.what + "' is truncated: " + element_one(e) + " " + num(i) + " of " +
                num(e.count) + " needs " + num(std::uint64_t{n}) + " bytes at byte " +
                num(std::uint64_t{at}) + ", but the file has " +
                num(std::uint64_t{b.bytes.size()}));
  }
}

// Binary element of scalar properties only: fixed-size records, read in place.
void read_fixed_records(const PlyBody& b, const PlyElement& e, bool is_vertex, bool big,
                        std::size_t& at) {
  std::size_t stride = 0;
  std::size_t offs[3] = {0, 0, 0};
  for (std::size_t j = 0; j < e.props.size(); ++j) {
    for (int a = 0; a < 3; ++a) {
      if (is_vertex && static_cast<int>(j) == b.roles.xyz[a]) offs[a] = stride;
    }
    stride += static_cast<std::size_t>(ply_size(e.props[j].type));
  }
  // The count was checked against the size before, but earlier elements may have used more than
  // their minimum.
  if (e.count > (b.bytes.size() - at) / stride) {
    const std::uint64_t i = (b.bytes.size() - at) / stride;
    at += static_cast<std::size_t>(i) * stride;
    need(b, at, stride, e, i);
  }
  if (is_vertex) {
    const auto* data = reinterpret_cast<const std::uint8_t*>(b.bytes.data());
    const PlyProperty* p[3] = {&e.props[static_cast<std::size_t>(b.roles.xyz[0])],
                               &e.props[static_cast<std::size_t>(b.roles.xyz[1])],
                               &e.props[static_cast<std::size_t>(b.roles.xyz[2])]};
    for (std::uint64_t i = 0; i < e.count; ++i) {
      const std::uint8_t* r = data + at + static_cast<std::size_t>(i) * stride;
      const Vec3 v{load_double(p[0]->type, r + offs[0], big),
                   load_double(p[1]->type, r + offs[1], big),
                   load_double(p[2]->type, r + offs[2], big)};
      if (!finite3(v)) non_finite(b.what, "vertex " + num(i), v, "");
      push_vertex(b.mesh, b.src, v);
    }
  }
  at += static_cast<std::size_t>(e.count) * stride;
}

// Binary element with list properties: record by record, property by property.
void read_variable_records(const PlyBody& b, const PlyElement& e, bool is_vertex, bool is_face,
                           bool big, std::size_t& at) {
  const auto* data = reinterpret_cast<const std::uint8_t*>(b.bytes.data());
  std::vector<std::uint32_t> idx;
  for (std::uint64_t i = 0; i < e.count; ++i) {
    Vec3 v{0.0};
    for (std::size_t j = 0; j < e.props.size(); ++j) {
      const PlyProperty& p = e.props[j];
      if (!p.list) {
        const auto sz = static_cast<std::size_t>(ply_size(p.type));
        need(b, at, sz, e, i);
        if (is_vertex) {
          for (int a = 0; a < 3; ++a) {
            if (static_cast<int>(j) == b.roles.xyz[a]) v[a] = load_double(p.type, data + at, big);
          }
        }
        at += sz;
        continue;
      }
      const auto csz = static_cast<std::size_t>(ply_size(p.count_type));
      need(b, at, csz, e, i);
      const std::int64_t n = load_int(p.count_type, data + at, big);
      at += csz;
      if (n < 0) {
        throw_input("'" + b.what + "': " + element_one(e) + " " + num(i) + " has a list '" +
                    p.name + "' of " + std::to_string(n) + " items; expected a count >= 0");
      }
      const auto isz = static_cast<std::size_t>(ply_size(p.type));
      if (static_cast<std::uint64_t>(n) > (b.bytes.size() - at) / isz) {
        throw_input("'" + b.what + "' is truncated: " + element_one(e) + " " + num(i) + " of " +
                    num(e.count) + " has a list '" + p.name + "' of " + std::to_string(n) +
                    " items at byte " + num(std::uint64_t{at}) + ", but the file has only " +
                    num(std::uint64_t{b.bytes.size() - at}) + " more bytes");
      }
      const auto count = static_cast<std::size_t>(n);
      if (is_face && static_cast<int>(j) == b.roles.list_prop) {
        idx.clear();
        for (std::size_t q = 0; q < count; ++q) {
          const std::int64_t x = load_int(p.type, data + at + q * isz, big);
          if (x < 0 || static_cast<std::uint64_t>(x) >= b.nv) bad_index(b, i, x, "");
          idx.push_back(static_cast<std::uint32_t>(x));
        }
      }
      at += count * isz;
    }
    if (is_vertex) {
      if (!finite3(v)) non_finite(b.what, "vertex " + num(i), v, "");
      push_vertex(b.mesh, b.src, v);
    }
    if (is_face) b.sink.add(idx, 0);
  }
}

void read_binary(const PlyBody& b, std::size_t data_start, bool big) {
  std::size_t at = data_start;
  for (std::size_t ei = 0; ei < b.elements.size(); ++ei) {
    const PlyElement& e = b.elements[ei];
    if (e.props.empty()) continue;
    const bool is_vertex = static_cast<int>(ei) == b.roles.vertex_el;
    const bool is_face = static_cast<int>(ei) == b.roles.face_el;
    bool fixed = true;
    for (const PlyProperty& p : e.props) fixed = fixed && !p.list;
    if (fixed) {
      read_fixed_records(b, e, is_vertex, big, at);
    } else {
      read_variable_records(b, e, is_vertex, is_face, big, at);
    }
  }
}

// ASCII: whitespace-separated tokens, element after element; `line0` header lines precede them.
void read_ascii(const PlyBody& b, std::size_t data_start, std::size_t line0) {
  Text t(b.bytes.substr(data_start), false);
  const auto line_of = [&]() { return line0 + t.line(); };
  std::vector<std::uint32_t> idx;
  for (std::size_t ei = 0; ei < b.elements.size(); ++ei) {
    const PlyElement& e = b.elements[ei];
    if (e.props.empty()) continue;
    const bool is_vertex = static_cast<int>(ei) == b.roles.vertex_el;
    const bool is_face = static_cast<int>(ei) == b.roles.face_el;
    const auto next = [&](std::uint64_t i, const PlyProperty& p) {
      const std::string_view tok = t.token();
      if (tok.empty()) {
        throw_input("'" + b.what + "' is truncated: it ends in " + element_one(e) + " " + num(i) +
                    " of " + num(e.count) + " (line " + num(std::uint64_t{line_of()}) +
                    "), before its property '" + excerpt(p.name) + "'");
      }
      return tok;
    };
    const auto bad_number = [&](std::uint64_t i, const PlyProperty& p, std::string_view tok,
                                const char* expected) {
      throw_input("'" + b.what + "': " + element_one(e) + " " + num(i) + " (line " +
                  num(std::uint64_t{line_of()}) + ") has '" + excerpt(tok) + "' for property '" +
                  excerpt(p.name) + "'; expected " + expected);
    };
    for (std::uint64_t i = 0; i < e.count; ++i) {
      Vec3 v{0.0};
      std::size_t face_line = 0;
      for (std::size_t j = 0; j < e.props.size(); ++j) {
        const PlyProperty& p = e.props[j];
        if (!p.list) {
          const std::string_view tok = next(i, p);
          if (is_vertex) {
            for (int a = 0; a < 3; ++a) {
              if (static_cast<int>(j) == b.roles.xyz[a] && !parse_double(tok, v[a])) {
                bad_number(i, p, tok, "a number");
              }
            }
          }
          continue;
        }
        const std::string_view ctok = next(i, p);
        std::int64_t n = 0;
        if (!parse_int(ctok, n) || n < 0) bad_number(i, p, ctok, "a list count (an integer >= 0)");
        if (static_cast<std::uint64_t>(n) > t.remaining() / 2 + 1) {
          throw_input("'" + b.what + "': " + element_one(e) + " " + num(i) + " (line " +
                      num(std::uint64_t{line_of()}) + ") has a list of " + std::to_string(n) +
                      " items, more than the rest of the file can hold (truncated or corrupt)");
        }
        const bool indices = is_face && static_cast<int>(j) == b.roles.list_prop;
        if (indices) {
          idx.clear();
          face_line = line_of();
        }
        for (std::int64_t q = 0; q < n; ++q) {
          const std::string_view tok = next(i, p);
          if (!indices) continue;
          std::int64_t x = 0;
          if (!parse_int(tok, x)) bad_number(i, p, tok, "an integer vertex index");
          if (x < 0 || static_cast<std::uint64_t>(x) >= b.nv) {
            bad_index(b, i, x, "line " + num(std::uint64_t{line_of()}));
          }
          idx.push_back(static_cast<std::uint32_t>(x));
        }
      }
      if (is_vertex) {
        if (!finite3(v)) non_finite(b.what, "vertex " + num(i), v, at_line(line_of()));
        push_vertex(b.mesh, b.src, v);
      }
      if (is_face) b.sink.add(idx, face_line);
    }
  }
}

}  // namespace

void parse_ply(std::string_view bytes, Source& src, TriangleMesh& mesh, const MeshRepair& repair,
               MeshReport& report) {
  const std::string& what = src.what;
  const PlyHeader header = read_ply_header(bytes, what);
  const PlyRoles roles = find_roles(header.elements, what);
  const bool binary = header.encoding != PlyEncoding::kAscii;
  check_counts(header.elements, binary, bytes.size() - header.data_start, what);
  const std::uint64_t nv = header.elements[static_cast<std::size_t>(roles.vertex_el)].count;
  if (nv > kMaxVertices) throw_input("'" + what + "' has too many vertices");
  if (!src.streaming()) mesh.positions.reserve(static_cast<std::size_t>(nv));
  FaceSink sink(mesh, src, repair, report, !binary && !src.streaming());
  const PlyBody body{what, bytes, header.elements, roles, nv, mesh, src, sink};
  if (binary) {
    read_binary(body, header.data_start, header.encoding == PlyEncoding::kBig);
  } else {
    read_ascii(body, header.data_start, header.lines);
  }
  flush_stream(mesh, src);
}

}  // namespace smr::mesh_io
