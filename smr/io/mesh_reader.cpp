// Mesh readers (PLY, OBJ, OFF, STL) and mesh validation / repair (smr/io/mesh_reader.h).
//
// Formats: PLY (Turk 1994, as documented at paulbourke.net/dataformats/ply), Wavefront OBJ
// (Wavefront Advanced Visualizer manual, appendix B1), OFF (Geomview manual, OFF(5)), STL
// (3D Systems, StereoLithography Interface Specification, 1989).
//
// Validation works on flat arrays in O(V + F) (plus tiny per-vertex sorts): face edges are
// bucketed by their lower vertex (a counting sort), which groups every undirected edge's faces
// together; the faces around each vertex are split into fans with a union-find over face corners
// (two corners at the same vertex are joined when their faces are glued along an edge through
// it); orientation is a breadth-first traversal over glued edges (the classic half-edge
// consistency check, e.g. Botsch et al., "Polygon Mesh Processing", 2010, section 2.5).
#include "smr/io/mesh_reader.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <numeric>
#include <span>
#include <vector>

#include "base/error.h"
#include "storage/mapped_file.h"

namespace smr {

namespace {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
// Face corners (3 per triangle) are numbered with 32 bits.
constexpr std::size_t kMaxTriangles = (std::size_t{kNone} - 1) / 3;
constexpr std::size_t kMaxVertices = std::size_t{kNone} - 1;

// ---------------------------------------------------------------------------------------------
// Small helpers

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

// Printable excerpt of untrusted text for error messages.
std::string excerpt(std::string_view s, std::size_t max = 40) {
  std::string out;
  for (std::size_t i = 0; i < s.size() && i < max; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02x", c);
      out += hex;
    }
  }
  if (s.size() > max) out += "...";
  return out;
}

std::string num(double v) {
  char tmp[32];
  const auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
  return std::string(tmp, r.ptr);
}

std::string num(std::uint64_t v) {
  return std::to_string(v);
}

std::string pos_text(const Vec3& p) {
  // Built piecewise: GCC 12 reports a false -Wrestrict on "(" + std::string(...).
  std::string s = "(";
  s += num(p.x);
  s += ", ";
  s += num(p.y);
  s += ", ";
  s += num(p.z);
  s += ")";
  return s;
}

bool parse_double(std::string_view tok, double& out) {
  if (tok.size() > 1 && tok[0] == '+') tok.remove_prefix(1);
  if (tok.empty()) return false;
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), out);
  if (r.ptr != tok.data() + tok.size()) return false;
  if (r.ec == std::errc::result_out_of_range) {
    // from_chars leaves `out` alone on overflow and underflow; strtod (on a copy, so it cannot
    // read past the token) gives +-HUGE_VAL or the nearest denormal / zero.
    const std::string copy(tok);
    out = std::strtod(copy.c_str(), nullptr);
    return true;
  }
  return r.ec == std::errc();
}

bool parse_int(std::string_view tok, std::int64_t& out) {
  if (tok.size() > 1 && tok[0] == '+') tok.remove_prefix(1);
  if (tok.empty()) return false;
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), out);
  return r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

bool parse_uint(std::string_view tok, std::uint64_t& out) {
  if (tok.size() > 1 && tok[0] == '+') tok.remove_prefix(1);
  if (tok.empty() || tok[0] == '-') return false;
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), out);
  return r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

std::uint64_t mix64(std::uint64_t x) {  // splitmix64 finaliser
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return x;
}

// Hash of a position compared as numbers: adding +0.0 turns -0.0 into +0.0.
std::uint64_t position_hash(const Vec3& p) {
  const auto bx = std::bit_cast<std::uint64_t>(p.x + 0.0);
  const auto by = std::bit_cast<std::uint64_t>(p.y + 0.0);
  const auto bz = std::bit_cast<std::uint64_t>(p.z + 0.0);
  return mix64(bx ^ mix64(by ^ mix64(bz)));
}

// Merges equal positions (open addressing, linear probing, power-of-two table grown at half
// load). `add` returns the index of the first position equal to p, appending p when new.
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

// ---------------------------------------------------------------------------------------------
// Where a mesh came from, for messages: face and vertex numbering as the file has it.

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

void push_vertex(TriangleMesh& mesh, Source& src, const Vec3& v) {
  mesh.positions.push_back(v);
  if (src.streaming() && mesh.positions.size() >= kStreamBatch) {
    src.vertex_batch(mesh.positions);
    mesh.positions.clear();
  }
}

// Hands what is left of a streamed mesh over.
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

// Collects faces from a parser: fan-triangulates polygons, handles faces of fewer than three
// vertices, and keeps the triangle -> file face map when the two differ.
class FaceSink {
 public:
  FaceSink(TriangleMesh& mesh, Source& src, const MeshRepair& repair, MeshReport& report,
           bool lines)
      : mesh_(mesh), src_(src), repair_(repair), report_(report), lines_(lines) {}

  void add(std::span<const std::uint32_t> idx, std::size_t line) {
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
    if (src_.streaming()) {
      // Nothing validates a streamed mesh afterwards: what one face can show is checked here.
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
  std::size_t faces() const { return faces_; }

 private:
  std::string face_label_for(std::uint32_t f) const {
    std::string s = std::string(src_.face_word) + " " + num(std::uint64_t{f});
    if (f < src_.line_of_face.size())
      s += " (line " + num(std::uint64_t{src_.line_of_face[f]}) + ")";
    return s;
  }
  void start_map() {
    if (mapped_) return;
    mapped_ = true;
    src_.face_of_triangle.resize(mesh_.triangles.size());
    std::iota(src_.face_of_triangle.begin(), src_.face_of_triangle.end(), std::uint32_t{0});
  }

  TriangleMesh& mesh_;
  Source& src_;
  const MeshRepair& repair_;
  MeshReport& report_;
  bool lines_;
  bool mapped_ = false;
  std::size_t faces_ = 0;
  std::uint64_t triangles_ = 0;
};

bool finite3(const Vec3& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

[[noreturn]] void non_finite(const std::string& what, const std::string& label, const Vec3& p,
                             const std::string& where) {
  const double c[3] = {p.x, p.y, p.z};
  int k = 0;
  while (k < 2 && std::isfinite(c[k])) ++k;
  throw_input("'" + what + "': " + label + (where.empty() ? "" : " (" + where + ")") + " has " +
              (std::isnan(c[k]) ? "a NaN" : "an infinite") + " " + "xyz"[k] +
              " coordinate; expected finite coordinates (not repairable)");
}

// ---------------------------------------------------------------------------------------------
// Text scanning shared by the text formats.

class Text {
 public:
  Text(std::string_view s, bool hash_comments, bool continuations = false)
      : p_(s.data()),
        end_(s.data() + s.size()),
        comments_(hash_comments),
        continuations_(continuations) {}

  bool at_end() const { return p_ == end_; }
  std::size_t line() const { return line_; }
  std::size_t remaining() const { return static_cast<std::size_t>(end_ - p_); }

  // Skips blanks within the line (and comments up to the newline).
  void skip_blanks() {
    while (p_ != end_) {
      const char c = *p_;
      if (c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f') {
        ++p_;
      } else if (comments_ && c == '#') {
        while (p_ != end_ && *p_ != '\n') ++p_;
      } else if (continuations_ && c == '\\' && continues()) {
        while (*p_ != '\n') ++p_;
        ++p_;
        ++line_;
      } else {
        break;
      }
    }
  }
  // Skips blanks, comments and newlines.
  void skip_space() {
    for (;;) {
      skip_blanks();
      if (p_ != end_ && *p_ == '\n') {
        ++p_;
        ++line_;
      } else {
        return;
      }
    }
  }
  bool at_eol() {
    skip_blanks();
    return p_ == end_ || *p_ == '\n';
  }
  // Moves to the start of the next line.
  void skip_line() {
    while (p_ != end_ && *p_ != '\n') {
      if (continuations_ && *p_ == '\\' && continues()) {
        while (*p_ != '\n') ++p_;
        ++line_;
      }
      ++p_;
    }
    if (p_ != end_) {
      ++p_;
      ++line_;
    }
  }
  // The next token within the current line; empty at the end of the line.
  std::string_view token_in_line() {
    skip_blanks();
    return raw_token();
  }
  // The next token, on this line or a later one; empty at the end of the input.
  std::string_view token() {
    skip_space();
    return raw_token();
  }
  // The rest of the current line (for names after `solid`).
  void rest_of_line() { skip_line(); }

 private:
  bool continues() const {  // at a backslash: is it followed by (\r) \n ?
    const char* q = p_ + 1;
    while (q != end_ && *q == '\r') ++q;
    return q != end_ && *q == '\n';
  }
  std::string_view raw_token() {
    const char* b = p_;
    while (p_ != end_) {
      const char c = *p_;
      if (c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f') break;
      if (comments_ && c == '#') break;
      ++p_;
    }
    return {b, static_cast<std::size_t>(p_ - b)};
  }

  const char* p_;
  const char* end_;
  bool comments_;
  bool continuations_;
  std::size_t line_ = 1;
};

std::string at_line(std::size_t line) {
  return "line " + num(std::uint64_t{line});
}

// ---------------------------------------------------------------------------------------------
// OFF

void parse_off(std::string_view bytes, Source& src, TriangleMesh& mesh, const MeshRepair& repair,
               MeshReport& report) {
  const std::string& what = src.what;
  Text t(bytes, true);
  const std::string_view kw = t.token();
  if (kw.empty()) throw_input("'" + what + "' is empty; expected an OFF file starting with 'OFF'");
  // [ST][C][N][4][n]OFF
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
  FaceSink sink(mesh, src, repair, report, true);
  std::vector<std::uint32_t> idx;
  for (std::uint64_t f = 0; f < nf; ++f) {
    const std::string_view tok = t.token();
    if (tok.empty()) {
      throw_input("'" + what + "' is truncated: it ends after " + num(f) + " of " + num(nf) +
                  " faces (" + at_line(t.line()) + ")");
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
        throw_input("'" + what + "': face " + num(f) + " (" + at_line(line) +
                    ") references vertex " + std::to_string(v) + ", which is out of range: the " +
                    "file has " + num(nv) + " vertices (indices 0 to " +
                    (nv == 0 ? "none" : num(nv - 1)) + ")");
      }
      idx.push_back(static_cast<std::uint32_t>(v));
    }
    sink.add(idx, line);
    t.skip_line();  // optional colour
  }
}

// ---------------------------------------------------------------------------------------------
// OBJ

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
        non_finite(what, "vertex " + num(std::uint64_t{mesh.positions.size() + 1}), p,
                   at_line(line));
      }
      if (mesh.positions.size() >= kMaxVertices)
        throw_input("'" + what + "' has too many vertices");
      mesh.positions.push_back(p);
    } else if (kw == "f") {
      idx.clear();
      for (;;) {
        const std::string_view ref = t.token_in_line();
        if (ref.empty()) break;
        const std::string_view head = ref.substr(0, ref.find('/'));
        std::int64_t i = 0;
        if (!parse_int(head, i)) {
          throw_input("'" + what + "': the face on " + at_line(line) +
                      " has the vertex reference '" + excerpt(ref) +
                      "'; expected i, i/t, i//n or i/t/n with integer i");
        }
        const auto count = static_cast<std::int64_t>(mesh.positions.size());
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
            throw_input("'" + what + "': the face on " + at_line(line) +
                        " references relative vertex " + std::to_string(i) +
                        ", which is out of range: only " + std::to_string(count) +
                        " vertices precede it");
          }
        } else {
          throw_input("'" + what + "': the face on " + at_line(line) +
                      " references vertex 0, which is out of range: OBJ indices start at 1 "
                      "(negative ones count back from the last vertex)");
        }
        idx.push_back(static_cast<std::uint32_t>(v));
      }
      sink.add(idx, line);
    }
    t.skip_line();  // everything else (vt, vn, g, o, s, usemtl, mtllib, l, p, comments) is ignored
  }
}

// ---------------------------------------------------------------------------------------------
// PLY

enum class PlyType : std::uint8_t { kI8, kU8, kI16, kU16, kI32, kU32, kF32, kF64 };

int ply_size(PlyType t) {
  switch (t) {
    case PlyType::kI8:
    case PlyType::kU8:
      return 1;
    case PlyType::kI16:
    case PlyType::kU16:
      return 2;
    case PlyType::kI32:
    case PlyType::kU32:
    case PlyType::kF32:
      return 4;
    case PlyType::kF64:
      return 8;
  }
  return 1;
}

bool ply_is_integer(PlyType t) {
  return t != PlyType::kF32 && t != PlyType::kF64;
}

bool ply_type(std::string_view s, PlyType& out) {
  static const std::pair<const char*, PlyType> kNames[] = {
      {"char", PlyType::kI8},     {"int8", PlyType::kI8},     {"uchar", PlyType::kU8},
      {"uint8", PlyType::kU8},    {"short", PlyType::kI16},   {"int16", PlyType::kI16},
      {"ushort", PlyType::kU16},  {"uint16", PlyType::kU16},  {"int", PlyType::kI32},
      {"int32", PlyType::kI32},   {"uint", PlyType::kU32},    {"uint32", PlyType::kU32},
      {"float", PlyType::kF32},   {"float32", PlyType::kF32}, {"double", PlyType::kF64},
      {"float64", PlyType::kF64},
  };
  for (const auto& [name, type] : kNames) {
    if (s == name) {
      out = type;
      return true;
    }
  }
  return false;
}

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

std::uint64_t load_bits(const std::uint8_t* p, int n, bool big) {
  std::uint64_t v = 0;
  if (big) {
    for (int i = 0; i < n; ++i) v = (v << 8) | p[i];
  } else {
    for (int i = n - 1; i >= 0; --i) v = (v << 8) | p[i];
  }
  return v;
}

double load_double(PlyType t, const std::uint8_t* p, bool big) {
  const std::uint64_t b = load_bits(p, ply_size(t), big);
  switch (t) {
    case PlyType::kI8:
      return static_cast<std::int8_t>(b);
    case PlyType::kU8:
      return static_cast<double>(b);
    case PlyType::kI16:
      return static_cast<std::int16_t>(b);
    case PlyType::kU16:
      return static_cast<double>(b);
    case PlyType::kI32:
      return static_cast<std::int32_t>(b);
    case PlyType::kU32:
      return static_cast<double>(b);
    case PlyType::kF32:
      return std::bit_cast<float>(static_cast<std::uint32_t>(b));
    case PlyType::kF64:
      return std::bit_cast<double>(b);
  }
  return 0;
}

std::int64_t load_int(PlyType t, const std::uint8_t* p, bool big) {
  const std::uint64_t b = load_bits(p, ply_size(t), big);
  switch (t) {
    case PlyType::kI8:
      return static_cast<std::int8_t>(b);
    case PlyType::kI16:
      return static_cast<std::int16_t>(b);
    case PlyType::kI32:
      return static_cast<std::int32_t>(b);
    default:
      return static_cast<std::int64_t>(b);  // unsigned types (floats are rejected in the header)
  }
}

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

void parse_ply(std::string_view bytes, Source& src, TriangleMesh& mesh, const MeshRepair& repair,
               MeshReport& report) {
  const std::string& what = src.what;
  if (bytes.empty())
    throw_input("'" + what + "' is empty; expected a PLY file starting with 'ply'");
  // Header lines.
  std::size_t pos = 0, line_no = 0;
  const auto next_line = [&](std::string_view& line) {
    if (pos >= bytes.size()) return false;
    const std::size_t nl = bytes.find('\n', pos);
    const std::size_t e = nl == std::string_view::npos ? bytes.size() : nl;
    line = bytes.substr(pos, e - pos);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos = nl == std::string_view::npos ? bytes.size() : nl + 1;
    ++line_no;
    return true;
  };
  const auto split = [](std::string_view line) {
    std::vector<std::string_view> out;
    std::size_t i = 0;
    while (i < line.size() && out.size() < 8) {
      while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
      const std::size_t b = i;
      while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
      if (i > b) out.push_back(line.substr(b, i - b));
    }
    return out;
  };
  std::string_view line;
  next_line(line);
  while (!line.empty() && (line.back() == ' ' || line.back() == '\t')) line.remove_suffix(1);
  if (line != "ply") {
    throw_input("'" + what + "' is not a PLY file: it starts with '" + excerpt(line) +
                "'; expected the line 'ply'");
  }
  enum class Encoding { kUnset, kAscii, kLittle, kBig } enc = Encoding::kUnset;
  std::vector<PlyElement> elements;
  bool ended = false;
  const auto bad_header = [&](const std::string& why) {
    throw_input("'" + what + "' has a malformed PLY header: " + why + " (line " +
                num(std::uint64_t{line_no}) + ": '" + excerpt(line, 60) + "')");
  };
  while (next_line(line)) {
    const std::vector<std::string_view> tok = split(line);
    if (tok.empty()) continue;
    if (tok[0] == "end_header") {
      ended = true;
      break;
    }
    if (tok[0] == "comment" || tok[0] == "obj_info") continue;
    if (tok[0] == "format") {
      if (enc != Encoding::kUnset) bad_header("a second 'format' line");
      if (tok.size() != 3) bad_header("expected 'format <ascii|binary_little_endian|...> 1.0'");
      if (tok[1] == "ascii") {
        enc = Encoding::kAscii;
      } else if (tok[1] == "binary_little_endian") {
        enc = Encoding::kLittle;
      } else if (tok[1] == "binary_big_endian") {
        enc = Encoding::kBig;
      } else {
        bad_header("unknown format '" + excerpt(tok[1]) +
                   "' (expected ascii, binary_little_endian or binary_big_endian)");
      }
    } else if (tok[0] == "element") {
      if (tok.size() != 3) bad_header("expected 'element <name> <count>'");
      PlyElement e;
      e.name = std::string(tok[1]);
      if (!parse_uint(tok[2], e.count)) {
        bad_header("the count of element '" + excerpt(tok[1]) + "' is '" + excerpt(tok[2]) +
                   "'; expected a non-negative integer");
      }
      for (const PlyElement& other : elements) {
        if (other.name == e.name) bad_header("element '" + excerpt(e.name) + "' is declared twice");
      }
      elements.push_back(std::move(e));
    } else if (tok[0] == "property") {
      if (elements.empty()) bad_header("a property before any element");
      PlyProperty p;
      if (tok.size() >= 2 && tok[1] == "list") {
        if (tok.size() != 5) bad_header("expected 'property list <count type> <item type> <name>'");
        if (!ply_type(tok[2], p.count_type) || !ply_type(tok[3], p.type)) {
          bad_header(
              "unknown property type (expected char, uchar, short, ushort, int, uint, "
              "float, double or int8 .. float64)");
        }
        if (!ply_is_integer(p.count_type)) bad_header("a list count type must be an integer type");
        p.list = true;
        p.name = std::string(tok[4]);
      } else {
        if (tok.size() != 3) bad_header("expected 'property <type> <name>'");
        if (!ply_type(tok[1], p.type)) {
          bad_header("unknown property type '" + excerpt(tok[1]) +
                     "' (expected char, uchar, short, ushort, int, uint, float, double or "
                     "int8 .. float64)");
        }
        p.name = std::string(tok[2]);
      }
      elements.back().props.push_back(std::move(p));
    } else {
      bad_header("unexpected line");
    }
  }
  if (!ended) {
    throw_input("'" + what +
                "' is truncated or not a PLY file: its header has no 'end_header' "
                "line");
  }
  if (enc == Encoding::kUnset) {
    throw_input("'" + what + "' has a malformed PLY header: no 'format' line");
  }
  // The roles of the elements.
  int vertex_el = -1, face_el = -1;
  int xyz[3] = {-1, -1, -1};
  int list_prop = -1;
  for (std::size_t i = 0; i < elements.size(); ++i) {
    const PlyElement& e = elements[i];
    if (e.name == "vertex") {
      vertex_el = static_cast<int>(i);
      for (std::size_t j = 0; j < e.props.size(); ++j) {
        for (int a = 0; a < 3; ++a) {
          if (e.props[j].name == std::string(1, "xyz"[a])) {
            if (e.props[j].list) {
              throw_input("'" + what + "': the vertex property '" + e.props[j].name +
                          "' is a list; expected a scalar coordinate");
            }
            xyz[a] = static_cast<int>(j);
          }
        }
      }
    } else if (e.name == "face") {
      face_el = static_cast<int>(i);
      for (std::size_t j = 0; j < e.props.size(); ++j) {
        const PlyProperty& p = e.props[j];
        if (p.name == "vertex_indices" || p.name == "vertex_index") {
          if (!p.list) {
            throw_input("'" + what + "': the face property '" + p.name +
                        "' is not a list; expected 'property list <count type> <index type> " +
                        p.name + "'");
          }
          if (!ply_is_integer(p.type)) {
            throw_input("'" + what + "': the face property '" + p.name +
                        "' has a floating-point index type; expected an integer type");
          }
          if (list_prop < 0) list_prop = static_cast<int>(j);
        }
      }
    }
  }
  if (vertex_el < 0) throw_input("'" + what + "' has no 'vertex' element; expected a mesh");
  for (int a = 0; a < 3; ++a) {
    if (xyz[a] < 0) {
      throw_input("'" + what + "': the vertex element has no property '" +
                  std::string(1, "xyz"[a]) + "'; expected x, y and z");
    }
  }
  if (face_el < 0) {
    throw_input("'" + what + "' has no 'face' element; expected a mesh, not a point cloud");
  }
  if (list_prop < 0) {
    throw_input("'" + what +
                "': the face element has no list property 'vertex_indices' or "
                "'vertex_index'");
  }
  // Counts against the size of the data.
  const bool binary = enc != Encoding::kAscii;
  const bool big = enc == Encoding::kBig;
  const std::size_t data_size = bytes.size() - pos;
  {
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
  const std::uint64_t nv = elements[static_cast<std::size_t>(vertex_el)].count;
  if (nv > kMaxVertices) throw_input("'" + what + "' has too many vertices");
  if (!src.streaming()) mesh.positions.reserve(static_cast<std::size_t>(nv));
  FaceSink sink(mesh, src, repair, report, !binary && !src.streaming());
  std::vector<std::uint32_t> idx;
  const auto bad_index = [&](std::uint64_t f, std::int64_t v, const std::string& where) {
    throw_input("'" + what + "': face " + num(f) + (where.empty() ? "" : " (" + where + ")") +
                " references vertex " + std::to_string(v) + ", which is out of range: the file " +
                "has " + num(nv) + " vertices (indices 0 to " + (nv == 0 ? "none" : num(nv - 1)) +
                ")");
  };

  if (binary) {
    const auto* data = reinterpret_cast<const std::uint8_t*>(bytes.data());
    std::size_t at = pos;
    const auto need = [&](std::size_t n, const PlyElement& e, std::uint64_t i) {
      if (n > bytes.size() - at) {
        throw_input("'" + what + "' is truncated: " + element_one(e) + " " + num(i) + " of " +
                    num(e.count) + " needs " + num(std::uint64_t{n}) + " bytes at byte " +
                    num(std::uint64_t{at}) + ", but the file has " +
                    num(std::uint64_t{bytes.size()}));
      }
    };
    for (std::size_t ei = 0; ei < elements.size(); ++ei) {
      const PlyElement& e = elements[ei];
      if (e.props.empty()) continue;
      const bool is_vertex = static_cast<int>(ei) == vertex_el;
      const bool is_face = static_cast<int>(ei) == face_el;
      bool fixed = true;
      std::size_t stride = 0;
      std::size_t offs[3] = {0, 0, 0};
      for (std::size_t j = 0; j < e.props.size(); ++j) {
        if (e.props[j].list) fixed = false;
        for (int a = 0; a < 3; ++a) {
          if (is_vertex && static_cast<int>(j) == xyz[a]) offs[a] = stride;
        }
        stride += static_cast<std::size_t>(ply_size(e.props[j].type));
      }
      if (fixed) {
        // Fixed-size records (the count was checked against the size above, but earlier elements
        // may have used more than their minimum).
        if (e.count > (bytes.size() - at) / stride) {
          const std::uint64_t i = (bytes.size() - at) / stride;
          at += static_cast<std::size_t>(i) * stride;
          need(stride, e, i);
        }
        if (is_vertex) {
          const PlyProperty* p[3] = {&e.props[static_cast<std::size_t>(xyz[0])],
                                     &e.props[static_cast<std::size_t>(xyz[1])],
                                     &e.props[static_cast<std::size_t>(xyz[2])]};
          for (std::uint64_t i = 0; i < e.count; ++i) {
            const std::uint8_t* r = data + at + static_cast<std::size_t>(i) * stride;
            const Vec3 v{load_double(p[0]->type, r + offs[0], big),
                         load_double(p[1]->type, r + offs[1], big),
                         load_double(p[2]->type, r + offs[2], big)};
            if (!finite3(v)) non_finite(what, "vertex " + num(i), v, "");
            push_vertex(mesh, src, v);
          }
        }
        at += static_cast<std::size_t>(e.count) * stride;
        continue;
      }
      for (std::uint64_t i = 0; i < e.count; ++i) {
        Vec3 v{0.0};
        for (std::size_t j = 0; j < e.props.size(); ++j) {
          const PlyProperty& p = e.props[j];
          if (!p.list) {
            const auto sz = static_cast<std::size_t>(ply_size(p.type));
            need(sz, e, i);
            if (is_vertex) {
              for (int a = 0; a < 3; ++a) {
                if (static_cast<int>(j) == xyz[a]) v[a] = load_double(p.type, data + at, big);
              }
            }
            at += sz;
            continue;
          }
          const auto csz = static_cast<std::size_t>(ply_size(p.count_type));
          need(csz, e, i);
          const std::int64_t n = load_int(p.count_type, data + at, big);
          at += csz;
          if (n < 0) {
            throw_input("'" + what + "': " + element_one(e) + " " + num(i) + " has a list '" +
                        p.name + "' of " + std::to_string(n) + " items; expected a count >= 0");
          }
          const auto isz = static_cast<std::size_t>(ply_size(p.type));
          if (static_cast<std::uint64_t>(n) > (bytes.size() - at) / isz) {
            throw_input("'" + what + "' is truncated: " + element_one(e) + " " + num(i) + " of " +
                        num(e.count) + " has a list '" + p.name + "' of " + std::to_string(n) +
                        " items at byte " + num(std::uint64_t{at}) + ", but the file has only " +
                        num(std::uint64_t{bytes.size() - at}) + " more bytes");
          }
          const auto count = static_cast<std::size_t>(n);
          if (is_face && static_cast<int>(j) == list_prop) {
            idx.clear();
            for (std::size_t q = 0; q < count; ++q) {
              const std::int64_t x = load_int(p.type, data + at + q * isz, big);
              if (x < 0 || static_cast<std::uint64_t>(x) >= nv) bad_index(i, x, "");
              idx.push_back(static_cast<std::uint32_t>(x));
            }
          }
          at += count * isz;
        }
        if (is_vertex) {
          if (!finite3(v)) non_finite(what, "vertex " + num(i), v, "");
          push_vertex(mesh, src, v);
        }
        if (is_face) sink.add(idx, 0);
      }
    }
    flush_stream(mesh, src);
    return;
  }

  // ASCII: whitespace-separated tokens, element after element.
  Text t(bytes.substr(pos), false);
  const std::size_t line0 = line_no;
  const auto line_of = [&]() { return line0 + t.line(); };
  for (std::size_t ei = 0; ei < elements.size(); ++ei) {
    const PlyElement& e = elements[ei];
    if (e.props.empty()) continue;
    const bool is_vertex = static_cast<int>(ei) == vertex_el;
    const bool is_face = static_cast<int>(ei) == face_el;
    const auto next = [&](std::uint64_t i, const PlyProperty& p) {
      const std::string_view tok = t.token();
      if (tok.empty()) {
        throw_input("'" + what + "' is truncated: it ends in " + element_one(e) + " " + num(i) +
                    " of " + num(e.count) + " (line " + num(std::uint64_t{line_of()}) +
                    "), before its property '" + excerpt(p.name) + "'");
      }
      return tok;
    };
    const auto bad_number = [&](std::uint64_t i, const PlyProperty& p, std::string_view tok,
                                const char* expected) {
      throw_input("'" + what + "': " + element_one(e) + " " + num(i) + " (line " +
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
              if (static_cast<int>(j) == xyz[a] && !parse_double(tok, v[a])) {
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
          throw_input("'" + what + "': " + element_one(e) + " " + num(i) + " (line " +
                      num(std::uint64_t{line_of()}) + ") has a list of " + std::to_string(n) +
                      " items, more than the rest of the file can hold (truncated or corrupt)");
        }
        const bool indices = is_face && static_cast<int>(j) == list_prop;
        if (indices) {
          idx.clear();
          face_line = line_of();
        }
        for (std::int64_t q = 0; q < n; ++q) {
          const std::string_view tok = next(i, p);
          if (!indices) continue;
          std::int64_t x = 0;
          if (!parse_int(tok, x)) bad_number(i, p, tok, "an integer vertex index");
          if (x < 0 || static_cast<std::uint64_t>(x) >= nv) {
            bad_index(i, x, "line " + num(std::uint64_t{line_of()}));
          }
          idx.push_back(static_cast<std::uint32_t>(x));
        }
      }
      if (is_vertex) {
        if (!finite3(v)) non_finite(what, "vertex " + num(i), v, at_line(line_of()));
        push_vertex(mesh, src, v);
      }
      if (is_face) sink.add(idx, face_line);
    }
  }
  flush_stream(mesh, src);
}

// ---------------------------------------------------------------------------------------------
// STL

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

void parse_stl(std::string_view bytes, Source& src, TriangleMesh& mesh, const MeshRepair& repair,
               MeshReport& report) {
  const std::string& what = src.what;
  src.vertex_base = -1;
  src.face_word = "facet";
  if (bytes.empty()) throw_input("'" + what + "' is empty; expected an STL file");
  PositionWelder welder(mesh.positions);
  const bool ascii = bytes.size() < 84 ? starts_with_solid(bytes) : looks_like_ascii_stl(bytes);
  if (!ascii) {
    if (bytes.size() < 84) {
      throw_input("'" + what + "' is not an STL file: it is too short for a binary STL (" +
                  num(std::uint64_t{bytes.size()}) + " bytes, the header alone is 84) and does " +
                  "not start with 'solid'");
    }
    const std::uint64_t n =
        load_bits(reinterpret_cast<const std::uint8_t*>(bytes.data()) + 80, 4, false);
    if (bytes.size() != 84 + 50 * n) {
      throw_input("'" + what + "' is truncated or not an STL file: as binary STL its header " +
                  "says " + num(n) + " facets, which need 84 + 50 * " + num(n) + " = " +
                  num(84 + 50 * n) + " bytes, but the file has " +
                  num(std::uint64_t{bytes.size()}) + " (and it is not ASCII STL)");
    }
    if (n > kMaxTriangles) throw_input("'" + what + "' has too many facets");
    const auto* data = reinterpret_cast<const std::uint8_t*>(bytes.data());
    mesh.triangles.reserve(static_cast<std::size_t>(n));
    FaceSink sink(mesh, src, repair, report, false);
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
    return;
  }
  Text t(bytes, false);
  FaceSink sink(mesh, src, repair, report, true);
  std::vector<std::uint32_t> idx;
  std::uint64_t facet = 0;
  bool in_facet = false;
  const auto where = [&]() {
    return (in_facet ? "in facet " + num(facet) + " " : std::string()) + "(" + at_line(t.line()) +
           ")";
  };
  const auto expect = [&](std::string_view word) {
    const std::string_view tok = t.token();
    if (tok == word) return;
    if (tok.empty() || t.at_end()) {
      throw_input("'" + what + "' is truncated: it ends " + where() + " where '" +
                  std::string(word) + "' was expected");
    }
    throw_input("'" + what + "': found '" + excerpt(tok) + "' " + where() + "; expected '" +
                std::string(word) + "'");
  };
  const auto number = [&]() {
    const std::string_view tok = t.token();
    double v = 0;
    if (tok.empty()) throw_input("'" + what + "' is truncated: it ends " + where());
    if (!parse_double(tok, v)) {
      if (t.at_end()) {
        throw_input("'" + what + "' is truncated: it ends with '" + excerpt(tok) + "' " + where() +
                    ", where a number was expected");
      }
      throw_input("'" + what + "': found '" + excerpt(tok) + "' " + where() +
                  "; expected a number");
    }
    return v;
  };
  expect("solid");
  t.rest_of_line();
  for (;;) {
    const std::string_view tok = t.token();
    if (tok == "facet") {
      const std::size_t line = t.line();
      in_facet = true;
      expect("normal");
      for (int k = 0; k < 3; ++k) (void)number();
      expect("outer");
      expect("loop");
      idx.clear();
      for (;;) {
        const std::string_view w = t.token();
        if (w == "endloop") break;
        if (w != "vertex") {
          if (w.empty() || t.at_end()) {
            throw_input("'" + what + "' is truncated: it ends " + where());
          }
          throw_input("'" + what + "': found '" + excerpt(w) + "' " + where() +
                      "; expected 'vertex' or 'endloop'");
        }
        const double x = number();
        const double y = number();
        const double z = number();
        const Vec3 p{x, y, z};
        if (!finite3(p)) {
          non_finite(what, "corner " + std::to_string(idx.size()) + " of facet " + num(facet), p,
                     at_line(t.line()));
        }
        idx.push_back(welder.add(p));
      }
      expect("endfacet");
      sink.add(idx, line);
      in_facet = false;
      ++facet;
    } else if (tok == "endsolid") {
      t.rest_of_line();
      t.skip_space();
      if (t.at_end()) break;
      expect("solid");
      t.rest_of_line();
    } else if (tok.empty() || t.at_end()) {
      throw_input("'" + what + "' is truncated: it ends after " + num(facet) +
                  " facets without 'endsolid' (" + at_line(t.line()) + ")");
    } else {
      throw_input("'" + what + "': found '" + excerpt(tok) + "' (" + at_line(t.line()) +
                  "); expected 'facet' or 'endsolid'");
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Validation

// Union-find over face corners with path halving.
std::uint32_t find_root(std::vector<std::uint32_t>& parent, std::uint32_t x) {
  while (parent[x] != x) {
    parent[x] = parent[parent[x]];
    x = parent[x];
  }
  return x;
}

void unite(std::vector<std::uint32_t>& parent, std::uint32_t a, std::uint32_t b) {
  a = find_root(parent, a);
  b = find_root(parent, b);
  if (a == b) return;
  if (a < b) std::swap(a, b);
  parent[a] = b;  // the lower corner is the root
}

void validate_impl(TriangleMesh& mesh, const Source& src, const MeshRepair& repair,
                   MeshReport& rep) {
  const std::string& what = src.what;
  std::vector<Vec3>& P = mesh.positions;
  std::vector<std::array<std::uint32_t, 3>>& T = mesh.triangles;
  const std::string prefix = "'" + what + "': ";
  const bool has_values = !mesh.triangle_values.empty();
  if (has_values && mesh.triangle_values.size() != T.size()) {
    throw_input(prefix + "it has " + num(std::uint64_t{mesh.triangle_values.size()}) +
                " triangle values for " + num(std::uint64_t{T.size()}) +
                " triangles; expected one per triangle or none");
  }
  if (T.size() > kMaxTriangles) {
    throw_input(prefix + "more than " + num(std::uint64_t{kMaxTriangles}) +
                " triangles are not supported");
  }
  if (P.size() > kMaxVertices) throw_input(prefix + "too many vertices");
  const auto n = static_cast<std::uint32_t>(P.size());
  const std::size_t m = T.size();

  // 1. Finite coordinates.
  for (std::uint32_t v = 0; v < n; ++v) {
    if (!finite3(P[v])) {
      non_finite(what, src.vertex_base < 0 ? "a vertex" : "vertex " + vertex_number(src, v), P[v],
                 "");
    }
  }
  // 2. Indices in range.
  for (std::size_t t = 0; t < m; ++t) {
    for (std::uint32_t v : T[t]) {
      if (v >= n) {
        throw_input(prefix + face_label(src, t) + " references vertex " + vertex_number(src, v) +
                    ", which is out of range: the mesh has " + num(std::uint64_t{n}) + " vertices");
      }
    }
  }
  // 3. Weld.
  std::vector<std::uint32_t> welded_to;  // empty: no weld
  if (repair.weld && n > 0) {
    welded_to.resize(n);
    std::vector<Vec3> firsts;
    firsts.reserve(n);
    std::vector<std::uint32_t> first_id;
    first_id.reserve(n);
    PositionWelder welder(firsts, n);
    for (std::uint32_t v = 0; v < n; ++v) {
      const std::uint32_t k = welder.add(P[v]);
      if (k == first_id.size()) first_id.push_back(v);
      welded_to[v] = first_id[k];
      if (welded_to[v] != v) ++rep.welded_vertices;
    }
    if (rep.welded_vertices > 0) {
      for (auto& tri : T) {
        for (std::uint32_t& v : tri) v = welded_to[v];
      }
    }
  }
  // 4. Degenerate and zero-area faces.
  std::vector<std::uint8_t> dead(m, 0);
  std::size_t live = m;
  for (std::size_t t = 0; t < m; ++t) {
    const auto& f = T[t];
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) {
      if (!repair.drop_degenerate) {
        const std::uint32_t twice = f[0] == f[1] || f[0] == f[2] ? f[0] : f[1];
        throw_input(prefix + face_label(src, t) + " is degenerate: it uses " +
                    vertex_label(src, P, twice) + " twice" +
                    (rep.welded_vertices > 0 ? " (after welding)" : "") +
                    "; expected three distinct vertices (repairable: --repair drops degenerate "
                    "faces)");
      }
      dead[t] = 1;
      --live;
      ++rep.degenerate_faces_dropped;
      continue;
    }
    const Vec3 u = P[f[1]] - P[f[0]], w = P[f[2]] - P[f[0]];
    if (u.y * w.z - u.z * w.y == 0.0 && u.z * w.x - u.x * w.z == 0.0 &&
        u.x * w.y - u.y * w.x == 0.0) {
      ++rep.zero_area_faces;
    }
  }
  if (live == 0) {
    if (m == 0) throw_input("'" + what + "' has no faces; expected at least one triangle");
    throw_input("'" + what + "' has no faces left after dropping " + num(std::uint64_t{m}) +
                " degenerate ones");
  }

  // Face edges ("slots" 3t + k: from T[t][k] to T[t][k+1]) bucketed by their lower vertex, then
  // sorted by the upper one within each bucket.
  const auto from = [&](std::uint32_t s) { return T[s / 3][s % 3]; };
  const auto to = [&](std::uint32_t s) { return T[s / 3][(s % 3 + 1) % 3]; };
  const auto lo_of = [&](std::uint32_t s) { return std::min(from(s), to(s)); };
  const auto hi_of = [&](std::uint32_t s) { return std::max(from(s), to(s)); };
  std::vector<std::uint32_t> start(std::size_t{n} + 1, 0);
  for (std::size_t t = 0; t < m; ++t) {
    if (dead[t]) continue;
    for (std::uint32_t k = 0; k < 3; ++k) ++start[lo_of(static_cast<std::uint32_t>(3 * t + k))];
  }
  for (std::uint32_t v = 1; v <= n; ++v) start[v] += start[v - 1];  // start[v] = end of bucket v
  std::vector<std::uint32_t> slots(3 * live);
  for (std::size_t t = m; t-- > 0;) {
    if (dead[t]) continue;
    for (std::uint32_t k = 3; k-- > 0;) {
      const auto s = static_cast<std::uint32_t>(3 * t + k);
      slots[--start[lo_of(s)]] = s;
    }
  }
  start[n] = static_cast<std::uint32_t>(slots.size());
  for (std::uint32_t v = 0; v < n; ++v) {
    const auto b = slots.begin() + start[v], e = slots.begin() + start[v + 1];
    if (e - b < 2) continue;
    const auto less = [&](std::uint32_t a, std::uint32_t c) {
      const std::uint32_t ha = hi_of(a), hc = hi_of(c);
      return ha != hc ? ha < hc : a < c;
    };
    if (e - b <= 16) {  // insertion sort: buckets hold about three edges
      for (auto i = b + 1; i < e; ++i) {
        const std::uint32_t x = *i;
        auto j = i;
        for (; j > b && less(x, *(j - 1)); --j) *j = *(j - 1);
        *j = x;
      }
    } else {
      std::sort(b, e, less);
    }
  }
  // Calls fn(begin, end) for every group of slots sharing an undirected edge.
  const auto for_each_edge = [&](auto&& fn) {
    for (std::uint32_t v = 0; v < n; ++v) {
      std::uint32_t i = start[v];
      const std::uint32_t e = start[v + 1];
      while (i < e) {
        std::uint32_t j = i + 1;
        const std::uint32_t h = hi_of(slots[i]);
        while (j < e && hi_of(slots[j]) == h) ++j;
        fn(i, j);
        i = j;
      }
    }
  };

  // 5. Duplicate faces: two faces with the same vertex set share the edge between their two lower
  // vertices and have the same third (highest) vertex; each face is considered at that edge only.
  {
    std::vector<std::pair<std::uint32_t, std::uint32_t>> canon;  // (third vertex, face)
    std::size_t first_dup = kNone, first_orig = kNone;
    for_each_edge([&](std::uint32_t b, std::uint32_t e) {
      if (e - b < 2) return;
      canon.clear();
      for (std::uint32_t i = b; i < e; ++i) {
        const std::uint32_t s = slots[i];
        const std::uint32_t third = T[s / 3][(s % 3 + 2) % 3];
        if (third > hi_of(s)) canon.emplace_back(third, s / 3);
      }
      if (canon.size() < 2) return;
      std::sort(canon.begin(), canon.end());
      for (std::size_t i = 1; i < canon.size(); ++i) {
        if (canon[i].first != canon[i - 1].first) continue;
        std::size_t k = i - 1;  // the first face of this run
        while (k > 0 && canon[k - 1].first == canon[i].first) --k;
        const std::uint32_t dup = canon[i].second, orig = canon[k].second;
        if (repair.drop_duplicates) {
          dead[dup] = 1;
          --live;
          ++rep.duplicate_faces_dropped;
        } else if (dup < first_dup) {
          first_dup = dup;
          first_orig = orig;
        }
      }
    });
    if (first_dup != kNone) {
      const auto& f = T[first_dup];
      throw_input(prefix + face_label(src, first_dup) + " is a duplicate of " +
                  face_label(src, first_orig) + ": both use vertices " + vertex_number(src, f[0]) +
                  ", " + vertex_number(src, f[1]) + " and " + vertex_number(src, f[2]) +
                  "; expected no duplicate faces (repairable: --repair drops duplicate faces)");
    }
  }
  // 6. Glue faces along edges: twin[s] is the slot of the other face on s's edge, or kNone.
  std::vector<std::uint32_t> twin(3 * m, kNone);
  std::vector<std::uint32_t> nm_slots, nm_begin;  // groups of slots on non-manifold edges
  {
    std::vector<std::uint32_t> g;
    for_each_edge([&](std::uint32_t b, std::uint32_t e) {
      g.clear();
      for (std::uint32_t i = b; i < e; ++i) {
        if (!dead[slots[i] / 3]) g.push_back(slots[i]);
      }
      if (g.size() == 2) {
        twin[g[0]] = g[1];
        twin[g[1]] = g[0];
      } else if (g.size() > 2) {
        const std::uint32_t lo = lo_of(g[0]), hi = hi_of(g[0]);
        if (!repair.split_nonmanifold) {
          std::string faces;
          for (std::size_t i = 0; i < g.size() && i < 4; ++i) {
            faces += (i == 0 ? "" : ", ") + face_label(src, g[i] / 3);
          }
          if (g.size() > 4) faces += ", ...";
          throw_input(prefix + "the edge between " + vertex_label(src, P, lo) + " and " +
                      vertex_label(src, P, hi) + " is non-manifold: it has " +
                      num(std::uint64_t{g.size()}) + " faces (" + faces +
                      "); expected at most 2 (repairable: --repair detaches the extra faces)");
        }
        ++rep.nonmanifold_edges_cut;
        std::uint32_t a = kNone, c = kNone;  // the first slot in each direction
        for (std::uint32_t s : g) {
          if (from(s) == lo) {
            if (a == kNone) a = s;
          } else if (c == kNone) {
            c = s;
          }
        }
        if (a == kNone || c == kNone) {
          a = g[0];
          c = g[1];
        }
        twin[a] = c;
        twin[c] = a;
        nm_begin.push_back(static_cast<std::uint32_t>(nm_slots.size()));
        nm_slots.insert(nm_slots.end(), g.begin(), g.end());
      }
    });
    nm_begin.push_back(static_cast<std::uint32_t>(nm_slots.size()));
  }
  slots = {};
  start = {};

  // 7. Fans: corners (3t + k, at vertex T[t][k]) joined across glued edges; each class of corners
  // becomes one output vertex (the first class of a vertex keeps its number, the others get
  // copies appended after the input vertices).
  std::vector<std::uint32_t> parent(3 * m);
  std::vector<std::uint32_t> out(3 * m);  // corner -> output vertex
  std::vector<std::uint32_t> origin;      // copy n + i is a copy of vertex origin[i]
  std::vector<std::uint8_t> taken(n);
  const auto assign_vertices = [&]() {
    std::iota(parent.begin(), parent.end(), std::uint32_t{0});
    for (std::size_t t = 0; t < m; ++t) {
      if (dead[t]) continue;
      for (std::uint32_t k = 0; k < 3; ++k) {
        const auto s = static_cast<std::uint32_t>(3 * t + k);
        const std::uint32_t u = twin[s];
        if (u == kNone || u < s) continue;
        const std::uint32_t s_next = 3 * (s / 3) + (k + 1) % 3;
        const std::uint32_t u_next = 3 * (u / 3) + (u % 3 + 1) % 3;
        if (from(u) == from(s)) {  // same direction
          unite(parent, s, u);
          unite(parent, s_next, u_next);
        } else {
          unite(parent, s, u_next);
          unite(parent, s_next, u);
        }
      }
    }
    std::fill(out.begin(), out.end(), kNone);
    std::fill(taken.begin(), taken.end(), 0);
    origin.clear();
    for (std::size_t t = 0; t < m; ++t) {
      if (dead[t]) continue;
      for (std::uint32_t k = 0; k < 3; ++k) {
        const auto c = static_cast<std::uint32_t>(3 * t + k);
        const std::uint32_t r = find_root(parent, c);
        if (out[r] == kNone) {
          const std::uint32_t v = T[t][k];
          if (!taken[v]) {
            taken[v] = 1;
            out[r] = v;
          } else {
            if (!repair.split_nonmanifold) {
              // Name a face of another fan of v.
              std::size_t other = 0;
              for (std::size_t q = 0; q < m && other == 0; ++q) {
                if (dead[q]) continue;
                for (std::uint32_t kk = 0; kk < 3; ++kk) {
                  if (T[q][kk] == v) {
                    other = q + 1;
                    break;
                  }
                }
              }
              throw_input(prefix + vertex_label(src, P, v) +
                          " is non-manifold: its faces form more than one fan (" +
                          face_label(src, other - 1) + " and " + face_label(src, t) +
                          " share it but are not connected through edges around it); expected "
                          "one fan per vertex (repairable: --repair splits it into one copy per "
                          "fan)");
            }
            if (std::size_t{n} + origin.size() >= kMaxVertices) {
              throw_input(prefix + "too many vertices after splitting non-manifold ones");
            }
            out[r] = n + static_cast<std::uint32_t>(origin.size());
            origin.push_back(v);
          }
        }
        out[c] = out[r];
      }
    }
  };
  assign_vertices();
  // Detached faces that still share both output vertices of a non-manifold edge with other faces
  // (their fans close up around the edge's ends) are detached completely.
  if (rep.nonmanifold_edges_cut > 0) {
    std::vector<std::pair<std::uint64_t, std::uint32_t>> keys;
    const auto collect = [&](std::size_t gi) {
      keys.clear();
      for (std::uint32_t i = nm_begin[gi]; i < nm_begin[gi + 1]; ++i) {
        const std::uint32_t s = nm_slots[i];
        const std::uint32_t a = out[s], b = out[3 * (s / 3) + (s % 3 + 1) % 3];
        keys.emplace_back(std::uint64_t{std::min(a, b)} << 32 | std::max(a, b), s);
      }
      std::sort(keys.begin(), keys.end());
    };
    bool isolated = false;
    for (std::size_t gi = 0; gi + 1 < nm_begin.size(); ++gi) {
      collect(gi);
      for (std::size_t i = 0; i < keys.size();) {
        std::size_t j = i + 1;
        while (j < keys.size() && keys[j].first == keys[i].first) ++j;
        if (j - i >= 2) {
          for (std::size_t q = i; q < j; ++q) {
            const std::uint32_t s = keys[q].second;
            if (twin[s] != kNone) continue;  // the kept pair
            const std::uint32_t t = s / 3;
            for (std::uint32_t k = 0; k < 3; ++k) {
              const std::uint32_t x = 3 * t + k;
              if (twin[x] != kNone) {
                twin[twin[x]] = kNone;
                twin[x] = kNone;
              }
            }
            isolated = true;
          }
        }
        i = j;
      }
    }
    if (isolated) {
      assign_vertices();
      for (std::size_t gi = 0; gi + 1 < nm_begin.size(); ++gi) {
        collect(gi);
        for (std::size_t i = 0; i + 1 < keys.size(); ++i) {
          if (keys[i].first == keys[i + 1].first && (twin[keys[i].second] != keys[i + 1].second)) {
            throw_internal(prefix + "detaching faces at a non-manifold edge failed");
          }
        }
      }
    }
  }
  rep.vertices_split = origin.size();

  // 8. Orientation: breadth-first over glued edges; flip[t] makes faces agree with the first face
  // of their component. A contradiction means the component is not orientable.
  std::vector<std::uint8_t> state(m, 0);  // bit 0: visited, bit 1: flip
  std::vector<std::uint32_t> order;
  order.reserve(live);
  std::uint32_t same_a = kNone, same_b = kNone, same_s = kNone;
  std::size_t flips = 0, components = 0;
  for (std::size_t t0 = 0; t0 < m; ++t0) {
    if (dead[t0] || state[t0]) continue;
    ++components;
    const std::size_t begin = order.size();
    state[t0] = 1;
    order.push_back(static_cast<std::uint32_t>(t0));
    for (std::size_t head = begin; head < order.size(); ++head) {
      const std::uint32_t t = order[head];
      const std::uint8_t ft = state[t] >> 1;
      for (std::uint32_t k = 0; k < 3; ++k) {
        const std::uint32_t s = 3 * t + k;
        const std::uint32_t u = twin[s];
        if (u == kNone) continue;
        const std::uint32_t t2 = u / 3;
        const bool same = from(u) == from(s);
        const auto want = static_cast<std::uint8_t>(ft ^ (same ? 1 : 0));
        if (same && same_s == kNone) {
          same_a = t;
          same_b = t2;
          same_s = s;
        }
        if (!state[t2]) {
          state[t2] = static_cast<std::uint8_t>(1 | (want << 1));
          order.push_back(t2);
        } else if ((state[t2] >> 1) != want) {
          throw_input(prefix + "the part of the mesh containing " + face_label(src, t0) +
                      " is not orientable (like a Moebius strip): " + face_label(src, t) + " and " +
                      face_label(src, t2) +
                      " cannot agree on the direction of their shared edge whichever way the "
                      "faces around it are flipped (not repairable)");
        }
      }
    }
    std::size_t flipped = 0;
    for (std::size_t i = begin; i < order.size(); ++i) flipped += state[order[i]] >> 1;
    const std::size_t size = order.size() - begin;
    if (2 * flipped > size) {
      for (std::size_t i = begin; i < order.size(); ++i) state[order[i]] ^= 2;
      flipped = size - flipped;
    }
    flips += flipped;
  }
  if (flips > 0 && !repair.orient) {
    throw_input(prefix + face_label(src, same_a) + " and " + face_label(src, same_b) +
                " both go from " + vertex_label(src, P, from(same_s)) + " to " +
                vertex_label(src, P, to(same_s)) +
                ", so their orientations disagree; expected faces sharing an edge to traverse it "
                "in opposite directions (inconsistent orientation; repairable: --repair flips "
                "faces)");
  }
  rep.faces_flipped = flips;

  // Boundary edges.
  std::size_t boundary = 0;
  for (std::size_t t = 0; t < m; ++t) {
    if (dead[t]) continue;
    for (std::uint32_t k = 0; k < 3; ++k) boundary += twin[3 * t + k] == kNone ? 1 : 0;
  }
  twin = {};
  parent = {};

  // 9. Output: faces in order (flipped ones as (a, c, b)), referenced vertices in order.
  const std::size_t total = std::size_t{n} + origin.size();
  std::vector<std::uint32_t> renum(total, kNone);
  for (std::size_t t = 0; t < m; ++t) {
    if (dead[t]) continue;
    for (std::uint32_t k = 0; k < 3; ++k) renum[out[3 * t + k]] = 0;
  }
  std::uint32_t next = 0;
  for (std::size_t v = 0; v < total; ++v) {
    if (renum[v] == kNone) {
      if (v < n && (welded_to.empty() || welded_to[v] == v)) ++rep.unused_vertices_dropped;
      continue;
    }
    renum[v] = next++;
  }
  std::vector<Vec3> positions(next);
  for (std::size_t v = 0; v < total; ++v) {
    if (renum[v] != kNone) positions[renum[v]] = P[v < n ? v : origin[v - n]];
  }
  std::size_t w = 0;
  for (std::size_t t = 0; t < m; ++t) {
    if (dead[t]) continue;
    std::array<std::uint32_t, 3> f = {renum[out[3 * t]], renum[out[3 * t + 1]],
                                      renum[out[3 * t + 2]]};
    if (state[t] & 2) std::swap(f[1], f[2]);
    T[w] = f;
    if (has_values) mesh.triangle_values[w] = mesh.triangle_values[t];
    ++w;
  }
  T.resize(w);
  if (has_values) mesh.triangle_values.resize(w);
  P = std::move(positions);

  rep.vertices = P.size();
  rep.faces = T.size();
  rep.components = components;
  rep.boundary_edges = boundary;
  rep.closed = boundary == 0;
}

std::vector<char> read_file(const std::string& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (!std::filesystem::exists(status)) throw_io("cannot open '" + path + "': no such file");
  if (std::filesystem::is_directory(status)) {
    throw_input("cannot read '" + path + "': it is a directory, expected a mesh file");
  }
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) throw_io("cannot open '" + path + "': " + std::strerror(errno));
  std::vector<char> bytes;
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (!ec && size < (std::uintmax_t{1} << 40)) bytes.reserve(static_cast<std::size_t>(size));
  char chunk[1 << 16];
  for (;;) {
    const std::size_t got = std::fread(chunk, 1, sizeof chunk, f);
    bytes.insert(bytes.end(), chunk, chunk + got);
    if (got < sizeof chunk) break;
  }
  const bool failed = std::ferror(f) != 0;
  const int err = errno;
  std::fclose(f);
  if (failed) throw_io("cannot read '" + path + "': " + std::strerror(err));
  return bytes;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Public API

std::string MeshReport::summary() const {
  std::string s =
      num(std::uint64_t{vertices}) + " vertices, " + num(std::uint64_t{faces}) + " faces, " +
      num(std::uint64_t{components}) + (components == 1 ? " component, " : " components, ") +
      (closed ? std::string("closed") : num(std::uint64_t{boundary_edges}) + " boundary edges");
  std::string r;
  const auto add = [&](std::size_t count, const char* text) {
    if (count == 0) return;
    r += (r.empty() ? "" : ", ") + num(std::uint64_t{count}) + " " + text;
  };
  add(welded_vertices, "vertices welded");
  add(degenerate_faces_dropped, "degenerate faces dropped");
  add(duplicate_faces_dropped, "duplicate faces dropped");
  add(nonmanifold_edges_cut, "non-manifold edges cut");
  add(vertices_split, "vertices split");
  add(faces_flipped, "faces flipped");
  if (!r.empty()) s += "; repaired: " + r;
  std::string notes;
  const auto note = [&](std::size_t count, const char* text) {
    if (count == 0) return;
    notes += (notes.empty() ? "" : ", ") + num(std::uint64_t{count}) + " " + text;
  };
  note(unused_vertices_dropped, "unused vertices dropped");
  note(polygons_triangulated, "polygons triangulated");
  note(zero_area_faces, "zero-area faces");
  if (!notes.empty()) s += "; " + notes;
  return s;
}

bool is_mesh_path(const std::string& path) {
  const std::string ext = lower_extension(path);
  return ext == ".ply" || ext == ".obj" || ext == ".off" || ext == ".stl";
}

MeshFormat mesh_format_for_path(const std::string& path) {
  const std::string ext = lower_extension(path);
  if (ext == ".ply") return MeshFormat::kPly;
  if (ext == ".obj") return MeshFormat::kObj;
  if (ext == ".off") return MeshFormat::kOff;
  if (ext == ".stl") return MeshFormat::kStl;
  throw_input("cannot read mesh '" + path + "': " +
              (ext.empty() ? std::string("it has no extension")
                           : "unknown extension '" + excerpt(ext) + "'") +
              " (supported: .ply, .obj, .off, .stl)");
}

namespace {

TriangleMesh parse_only(std::string_view bytes, MeshFormat format, Source& src,
                        const MeshRepair& repair, MeshReport& rep) {
  TriangleMesh mesh;
  switch (format) {
    case MeshFormat::kPly:
      parse_ply(bytes, src, mesh, repair, rep);
      break;
    case MeshFormat::kObj:
      parse_obj(bytes, src, mesh, repair, rep);
      break;
    case MeshFormat::kOff:
      parse_off(bytes, src, mesh, repair, rep);
      break;
    case MeshFormat::kStl:
      parse_stl(bytes, src, mesh, repair, rep);
      break;
  }
  return mesh;
}

}  // namespace

TriangleMesh parse_mesh(std::string_view bytes, MeshFormat format, const std::string& name,
                        const MeshRepair& repair, MeshReport* report) {
  MeshReport local;
  MeshReport& rep = report != nullptr ? *report : local;
  rep = MeshReport{};
  Source src;
  src.what = name;
  TriangleMesh mesh = parse_only(bytes, format, src, repair, rep);
  validate_impl(mesh, src, repair, rep);
  return mesh;
}

TriangleMesh read_mesh(const std::string& path, const MeshRepair& repair, MeshReport* report) {
  const MeshFormat format = mesh_format_for_path(path);
  MeshReport local;
  MeshReport& rep = report != nullptr ? *report : local;
  rep = MeshReport{};
  Source src;
  src.what = path;
  TriangleMesh mesh;
  {
    const std::vector<char> bytes = read_file(path);  // freed before validation
    mesh = parse_only(std::string_view(bytes.data(), bytes.size()), format, src, repair, rep);
  }
  validate_impl(mesh, src, repair, rep);
  return mesh;
}

namespace {

// A PLY file streamed: each pass maps the file and parses it front to back, its pages dropped
// from the resident set as it goes (storage::PageTrimmer), handing batches over.
class PlyStream final : public MeshStream {
 public:
  explicit PlyStream(std::string path) : path_(std::move(path)) {
    // The counts the header declares (the parse checks them against the data), so the
    // builder can size its arrays before the first pass.
    const storage::MappedFile file(path_);
    const std::string_view b = file.bytes();
    const std::string_view head = b.substr(0, std::min<std::size_t>(b.size(), 1 << 20));
    std::size_t at = 0;
    while (at < head.size()) {
      const std::size_t nl = head.find('\n', at);
      const std::string_view line =
          head.substr(at, (nl == std::string_view::npos ? head.size() : nl) - at);
      at = nl == std::string_view::npos ? head.size() : nl + 1;
      if (line.starts_with("end_header")) break;
      std::uint64_t n = 0;
      for (const auto& [prefix, out] :
           {std::pair{std::string_view("element vertex "), &vertices_},
            std::pair{std::string_view("element face "), &triangles_}}) {
        if (!line.starts_with(prefix)) continue;
        std::string_view rest = line.substr(prefix.size());
        while (!rest.empty() && (rest.back() == '\r' || rest.back() == ' ')) rest.remove_suffix(1);
        if (parse_uint(rest, n)) *out = n;
      }
    }
  }
  std::string name() const override { return path_; }
  std::uint64_t vertex_count() const override { return vertices_; }
  std::uint64_t triangle_count() const override { return triangles_; }
  void vertices(const std::function<void(std::span<const Vec3>)>& f) const override {
    std::uint64_t nv = 0, nt = 0;
    pass([&](std::span<const Vec3> b) { nv += b.size(), f(b); },
         [&](std::span<const std::array<std::uint32_t, 3>> b) { nt += b.size(); });
    vertices_ = nv;
    triangles_ = nt;
  }
  void triangles(
      const std::function<void(std::span<const std::array<std::uint32_t, 3>>)>& f) const override {
    pass([](std::span<const Vec3>) {}, f);
  }

 private:
  void pass(const std::function<void(std::span<const Vec3>)>& v,
            const std::function<void(std::span<const std::array<std::uint32_t, 3>>)>& t) const {
    const storage::MappedFile file(path_);
    const storage::PageTrimmer trimmer(file.bytes().data(), file.bytes().size());
    Source src;
    src.what = path_;
    src.vertex_batch = v;
    src.triangle_batch = t;
    MeshReport report;
    TriangleMesh mesh;
    parse_ply(file.bytes(), src, mesh, MeshRepair{}, report);
  }

  std::string path_;
  mutable std::uint64_t vertices_ = 0, triangles_ = 0;
};

}  // namespace

std::unique_ptr<MeshStream> open_mesh_stream(const std::string& path) {
  if (mesh_format_for_path(path) != MeshFormat::kPly) {
    throw_input("'" + path +
                "': only PLY meshes can be streamed (out-of-core ingest with --memory); "
                "convert it to PLY or ingest it in memory");
  }
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw_io("cannot open '" + path + "': no such file");
  return std::make_unique<PlyStream>(path);
}

void validate_mesh(TriangleMesh& mesh, const std::string& what, const MeshRepair& repair,
                   MeshReport* report) {
  MeshReport local;
  MeshReport& rep = report != nullptr ? *report : local;
  rep = MeshReport{};
  Source src;
  src.what = what;
  validate_impl(mesh, src, repair, rep);
}

}  // namespace smr
