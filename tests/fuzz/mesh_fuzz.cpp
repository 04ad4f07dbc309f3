// The shared driver of the mesh reader fuzz targets (mesh_fuzz.h).
#include "tests/fuzz/mesh_fuzz.h"

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "tests/fuzz/fuzz_rng.h"

namespace smr::fuzz {

using Bytes = std::vector<std::uint8_t>;

void fail(const std::string& why, std::string_view input) {
  std::fprintf(stderr, "mesh fuzz: FAILURE: %s\n", why.c_str());
  std::fprintf(stderr, "input (%zu bytes):", input.size());
  for (std::size_t i = 0; i < input.size() && i < 512; ++i) {
    std::fprintf(stderr, "%s%02x", i % 32 == 0 ? "\n  " : " ",
                 static_cast<unsigned char>(input[i]));
  }
  std::fprintf(stderr, "\n");
  std::abort();
}

namespace {

const char* format_name(MeshFormat f) {
  switch (f) {
    case MeshFormat::kPly:
      return "ply";
    case MeshFormat::kObj:
      return "obj";
    case MeshFormat::kOff:
      return "off";
    case MeshFormat::kStl:
      return "stl";
  }
  return "?";
}

// ---------------------------------------------------------------------------------------------
// Independent invariant check (sorting and a union-find of its own).

std::uint32_t root(std::vector<std::uint32_t>& p, std::uint32_t x) {
  while (p[x] != x) x = p[x] = p[p[x]];
  return x;
}

}  // namespace

std::string check_mesh(const TriangleMesh& m, const MeshReport& rep) {
  const std::size_t n = m.positions.size(), f = m.triangles.size();
  if (f == 0) return "a mesh without faces was returned";
  if (rep.vertices != n || rep.faces != f) return "the report's counts differ from the mesh";
  if (!m.triangle_values.empty()) return "triangle values appeared";
  for (const auto& p : m.positions) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
      return "a non-finite coordinate survived";
    }
  }
  std::vector<std::uint8_t> used(n, 0);
  std::vector<std::array<std::uint32_t, 3>> sorted(f);
  struct Half {
    std::uint64_t key;  // (from << 32) | to
    std::uint32_t face;
  };
  std::vector<Half> halves;
  halves.reserve(3 * f);
  for (std::size_t t = 0; t < f; ++t) {
    const auto& tri = m.triangles[t];
    for (std::uint32_t v : tri) {
      if (v >= n) return "index out of range";
      used[v] = 1;
    }
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) return "degenerate face";
    sorted[t] = tri;
    std::sort(sorted[t].begin(), sorted[t].end());
    for (int k = 0; k < 3; ++k) {
      halves.push_back(
          {std::uint64_t{tri[k]} << 32 | tri[(k + 1) % 3], static_cast<std::uint32_t>(t)});
    }
  }
  for (std::size_t v = 0; v < n; ++v) {
    if (!used[v]) return "unreferenced vertex";
  }
  std::sort(sorted.begin(), sorted.end());
  if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) return "duplicate face";
  std::sort(halves.begin(), halves.end(),
            [](const Half& a, const Half& b) { return a.key < b.key; });
  for (std::size_t i = 1; i < halves.size(); ++i) {
    if (halves[i].key == halves[i - 1].key) return "an edge traversed twice in one direction";
  }
  // Undirected edges: at most two faces (implied by the above), glue faces for components.
  std::vector<std::uint32_t> comp(f);
  for (std::uint32_t t = 0; t < f; ++t) comp[t] = t;
  std::size_t boundary = 0;
  for (const Half& h : halves) {
    const auto a = static_cast<std::uint32_t>(h.key >> 32), b = static_cast<std::uint32_t>(h.key);
    const std::uint64_t rev = std::uint64_t{b} << 32 | a;
    const auto it = std::lower_bound(halves.begin(), halves.end(), rev,
                                     [](const Half& x, std::uint64_t k) { return x.key < k; });
    if (it == halves.end() || it->key != rev) {
      ++boundary;
    } else {
      comp[root(comp, h.face)] = root(comp, it->face);
    }
  }
  std::size_t components = 0;
  for (std::uint32_t t = 0; t < f; ++t) components += root(comp, t) == t ? 1 : 0;
  if (boundary != rep.boundary_edges) return "the report's boundary edge count is wrong";
  if (components != rep.components) return "the report's component count is wrong";
  if (rep.closed != (boundary == 0)) return "the report's closed flag is wrong";
  // One fan per vertex: corners at v joined when their faces share an edge (v, w).
  struct Spoke {
    std::uint64_t key;  // (v << 32) | w
    std::uint32_t corner;
  };
  std::vector<Spoke> spokes;
  spokes.reserve(6 * f);
  for (std::uint32_t t = 0; t < f; ++t) {
    for (std::uint32_t k = 0; k < 3; ++k) {
      const std::uint32_t v = m.triangles[t][k];
      for (std::uint32_t w : {m.triangles[t][(k + 1) % 3], m.triangles[t][(k + 2) % 3]}) {
        spokes.push_back({std::uint64_t{v} << 32 | w, 3 * t + k});
      }
    }
  }
  std::sort(spokes.begin(), spokes.end(),
            [](const Spoke& a, const Spoke& b) { return a.key < b.key; });
  std::vector<std::uint32_t> corner(3 * f);
  for (std::uint32_t c = 0; c < 3 * f; ++c) corner[c] = c;
  for (std::size_t i = 1; i < spokes.size(); ++i) {
    if (spokes[i].key == spokes[i - 1].key) {
      corner[root(corner, spokes[i].corner)] = root(corner, spokes[i - 1].corner);
    }
  }
  std::vector<std::uint32_t> fan_of(n, std::numeric_limits<std::uint32_t>::max());
  for (std::uint32_t c = 0; c < 3 * f; ++c) {
    const std::uint32_t v = m.triangles[c / 3][c % 3];
    const std::uint32_t r = root(corner, c);
    if (fan_of[v] == std::numeric_limits<std::uint32_t>::max()) {
      fan_of[v] = r;
    } else if (fan_of[v] != r) {
      return "a vertex with more than one fan";
    }
  }
  return {};
}

void expect_user_error(const Error& e, std::string_view name, std::string_view input,
                       const std::string& context) {
  if (e.kind() == ErrorKind::kInternal) fail("internal error " + context + ": " + e.what(), input);
  if (std::string_view(e.what()).find(name) == std::string_view::npos) {
    fail("an error message does not name the input " + context + ": " + e.what(), input);
  }
}

void check_parse(std::string_view bytes, MeshFormat format, Stats& stats) {
  ++stats.inputs;
  static const MeshRepair kRepairs[] = {MeshRepair{}, MeshRepair::all()};
  const std::string as = std::string("as ") + format_name(format);
  for (const MeshRepair& repair : kRepairs) {
    const std::string context = as + (repair.any() ? " with repairs" : "");
    ++stats.parses;
    try {
      MeshReport rep;
      const TriangleMesh m = parse_mesh(bytes, format, kName, repair, &rep);
      const std::string bad = check_mesh(m, rep);
      if (!bad.empty()) fail(context + ": " + bad, bytes);
      if (!repair.any() && rep.repairs() != 0) fail("repairs were made without being asked", bytes);
      ++stats.valid;
      if (repair.any() && rep.repairs() > 0) ++stats.repaired;
    } catch (const Error& e) {
      expect_user_error(e, kName, bytes, context);
      ++stats.errors;
    } catch (const std::exception& e) {
      fail("a non-smr exception " + context + ": " + e.what(), bytes);
    }
  }
}

namespace {

// ---------------------------------------------------------------------------------------------
// Seeds

Bytes text(const std::string& s) {
  return Bytes(s.begin(), s.end());
}

template <typename T>
void put(Bytes& b, T v, bool big = false) {
  unsigned char raw[sizeof(T)];
  std::memcpy(raw, &v, sizeof(T));
  if (big != (std::endian::native == std::endian::big)) std::reverse(raw, raw + sizeof(T));
  b.insert(b.end(), raw, raw + sizeof(T));
}

struct Shape {
  std::vector<std::array<double, 3>> v;
  std::vector<std::vector<std::uint32_t>> f;
};

Shape cube() {  // quads, outward
  return {{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}},
          {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4}, {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}}};
}
Shape tetra() {
  return {{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}},
          {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}}};
}
Shape bowtie() {
  return {{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}}, {{0, 1, 2}, {0, 3, 4}}};
}
Shape book() {
  return {{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 0}, {1, 0, 1}},
          {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}, {0, 4, 2}, {1, 2, 4}, {0, 1, 5}}};
}
Shape moebius() {
  return {{{1, 0, 0.2},
           {-0.5, 0.87, 0.2},
           {-0.5, -0.87, 0.2},
           {1, 0, -0.2},
           {-0.5, 0.87, -0.2},
           {-0.5, -0.87, -0.2}},
          {{0, 1, 4}, {0, 4, 3}, {1, 2, 5}, {1, 5, 4}, {2, 3, 0}, {2, 0, 5}}};
}
Shape messy() {  // flipped face, duplicate, degenerate, unused vertex, seam needing a weld
  return {{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {1, 1, 0}, {9, 9, 9}},
          {{0, 1, 2}, {0, 3, 2}, {0, 1, 2}, {1, 1, 3}, {2, 4, 3}}};
}

std::string num(double v) {
  char tmp[32];
  const int len = std::snprintf(tmp, sizeof tmp, "%.17g", v);
  return std::string(tmp, static_cast<std::size_t>(len));
}

// Appends " <v>" (built piecewise: GCC 12 reports a false -Wrestrict on " " + std::string&&).
void add_int(std::string& o, long v, const char* suffix = "") {
  o += ' ';
  o += std::to_string(v);
  o += suffix;
}

std::string off(const Shape& s, const std::string& keyword = "OFF") {
  std::string o = keyword + "\n# seed\n" + std::to_string(s.v.size()) + " " +
                  std::to_string(s.f.size()) + " 0\n";
  for (const auto& p : s.v) {
    o += num(p[0]) + " " + num(p[1]) + " " + num(p[2]);
    if (keyword == "COFF") o += " 1 0 0 1";
    o += "\n";
  }
  for (const auto& f : s.f) {
    o += std::to_string(f.size());
    for (std::uint32_t i : f) add_int(o, i);
    o += " # face\n";
  }
  return o;
}

std::string obj(const Shape& s) {
  std::string o = "# seed\nmtllib x.mtl\no seed\n";
  for (const auto& p : s.v) o += "v " + num(p[0]) + " " + num(p[1]) + " " + num(p[2]) + "\n";
  o += "vt 0 0\nvn 0 0 1\ng g\ns off\n";
  const auto nv = static_cast<long>(s.v.size());
  for (std::size_t k = 0; k < s.f.size(); ++k) {
    o += "f";
    for (std::uint32_t i : s.f[k]) {
      switch (k % 4) {
        case 0:
          add_int(o, i + 1L);
          break;
        case 1:
          add_int(o, i + 1L, "/1");
          break;
        case 2:
          add_int(o, i + 1L, "//1");
          break;
        default:
          add_int(o, static_cast<long>(i) - nv, "/1/1");  // relative
      }
    }
    o += "\n";
  }
  return o;
}

std::string ply_header(const Shape& s, const char* format, const char* coord) {
  return std::string("ply\nformat ") + format + " 1.0\ncomment seed\nelement vertex " +
         std::to_string(s.v.size()) + "\nproperty " + coord + " x\nproperty " + coord +
         " y\nproperty " + coord + " z\nproperty uchar red\nelement face " +
         std::to_string(s.f.size()) +
         "\nproperty list uchar int vertex_indices\nproperty float q\nelement edge 1\nproperty "
         "list uchar int ends\nend_header\n";
}

Bytes ply_ascii(const Shape& s) {
  std::string o = ply_header(s, "ascii", "double");
  for (const auto& p : s.v) o += num(p[0]) + " " + num(p[1]) + " " + num(p[2]) + " 7\n";
  for (const auto& f : s.f) {
    o += std::to_string(f.size());
    for (std::uint32_t i : f) add_int(o, i);
    o += " 0.5\n";
  }
  return text(o + "2 0 1\n");
}

Bytes ply_binary(const Shape& s, bool big, bool doubles) {
  Bytes b = text(ply_header(s, big ? "binary_big_endian" : "binary_little_endian",
                            doubles ? "double" : "float"));
  for (const auto& p : s.v) {
    for (double c : p) {
      if (doubles) {
        put(b, c, big);
      } else {
        put(b, static_cast<float>(c), big);
      }
    }
    put<std::uint8_t>(b, 7, big);
  }
  for (const auto& f : s.f) {
    put(b, static_cast<std::uint8_t>(f.size()), big);
    for (std::uint32_t i : f) put(b, static_cast<std::int32_t>(i), big);
    put(b, 0.5f, big);
  }
  put<std::uint8_t>(b, 2, big);
  put<std::int32_t>(b, 0, big);
  put<std::int32_t>(b, 1, big);
  return b;
}

std::vector<std::array<std::uint32_t, 3>> fan(const Shape& s) {
  std::vector<std::array<std::uint32_t, 3>> t;
  for (const auto& f : s.f) {
    for (std::size_t i = 1; i + 1 < f.size(); ++i) t.push_back({f[0], f[i], f[i + 1]});
  }
  return t;
}

Bytes stl_binary(const Shape& s) {
  Bytes b(80, ' ');
  std::memcpy(b.data(), "solid seed", 10);
  const auto tris = fan(s);
  put(b, static_cast<std::uint32_t>(tris.size()));
  for (const auto& t : tris) {
    for (int k = 0; k < 3; ++k) put(b, 0.0f);
    for (std::uint32_t i : t) {
      for (double c : s.v[i]) put(b, static_cast<float>(c));
    }
    put<std::uint16_t>(b, 0);
  }
  return b;
}

Bytes stl_ascii(const Shape& s) {
  std::string o = "solid seed\n";
  for (const auto& t : fan(s)) {
    o += "facet normal 0 0 1\n outer loop\n";
    for (std::uint32_t i : t) {
      o += "  vertex " + num(s.v[i][0]) + " " + num(s.v[i][1]) + " " + num(s.v[i][2]) + "\n";
    }
    o += " endloop\nendfacet\n";
  }
  return text(o + "endsolid seed\n");
}

std::vector<Bytes> encode(const Shape& s, MeshFormat format) {
  switch (format) {
    case MeshFormat::kOff:
      return {text(off(s))};
    case MeshFormat::kObj:
      return {text(obj(s))};
    case MeshFormat::kPly:
      return {ply_ascii(s), ply_binary(s, false, true), ply_binary(s, true, false)};
    case MeshFormat::kStl:
      return {stl_binary(s), stl_ascii(s)};
  }
  return {};
}

std::vector<Bytes> make_seeds(MeshFormat format) {
  std::vector<Bytes> seeds;
  for (const Shape& s : {cube(), tetra(), bowtie(), book(), moebius(), messy()}) {
    for (Bytes& b : encode(s, format)) seeds.push_back(std::move(b));
  }
  if (format == MeshFormat::kOff) {
    seeds.push_back(text(off(cube(), "COFF")));
    seeds.push_back(text(off(tetra(), "NOFF")));
  }
  return seeds;
}

Bytes read_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// The real meshes in `format`, and the smallest real mesh of any format re-encoded in it (read
// with every repair: a seed that is a real, valid mesh in every format).
std::vector<Bytes> real_meshes(MeshFormat format, std::vector<std::string>& names) {
  std::vector<Bytes> out;
  const char* dir = std::getenv("SMRDB_DATA_DIR");
  if (dir == nullptr || *dir == '\0') return out;
  const std::filesystem::path meshes = std::filesystem::path(dir) / "meshes";
  std::error_code ec;
  if (!std::filesystem::is_directory(meshes, ec)) return out;
  std::vector<std::filesystem::path> paths;
  for (const auto& e : std::filesystem::directory_iterator(meshes, ec)) {
    if (e.is_regular_file() && is_mesh_path(e.path().string())) paths.push_back(e.path());
  }
  std::sort(paths.begin(), paths.end());
  const std::filesystem::path* smallest = nullptr;
  for (const auto& p : paths) {
    if (smallest == nullptr ||
        std::filesystem::file_size(p) < std::filesystem::file_size(*smallest))
      smallest = &p;
    if (mesh_format_for_path(p.string()) != format) continue;
    out.push_back(read_bytes(p));
    names.push_back(p.filename().string());
  }
  if (smallest != nullptr) {
    const Bytes b = read_bytes(*smallest);
    const TriangleMesh m =
        parse_mesh(std::string_view(reinterpret_cast<const char*>(b.data()), b.size()),
                   mesh_format_for_path(smallest->string()), smallest->string(), MeshRepair::all());
    Shape s;
    for (const Vec3& p : m.positions) s.v.push_back({p.x, p.y, p.z});
    for (const auto& t : m.triangles) s.f.push_back({t[0], t[1], t[2]});
    for (Bytes& e : encode(s, format)) {
      out.push_back(std::move(e));
      names.push_back(smallest->filename().string() + " as " + format_name(format));
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Mutations (deterministic: splitmix64)

const char* const kTokens[] = {"0",
                               "-1",
                               "1",
                               "2",
                               "3",
                               "255",
                               "256",
                               "65535",
                               "2147483647",
                               "-2147483648",
                               "4000000000",
                               "4294967295",
                               "4294967296",
                               "18446744073709551615",
                               "99999999999999999999",
                               "nan",
                               "-nan",
                               "inf",
                               "-inf",
                               "1e308",
                               "1e999",
                               "1e-320",
                               "-0",
                               "0.5",
                               "1.0"};
const char* const kInserts[] = {" ",
                                "\n",
                                "\r\n",
                                "#",
                                "/",
                                "//",
                                "-",
                                "\\\n",
                                "e",
                                "nan",
                                "end_header\n",
                                "endsolid\n",
                                "facet normal 0 0 0\n",
                                "f 1 2 3\n",
                                "3 0 1 2\n",
                                "v 0 0 0\n",
                                "element face 1\n",
                                "\x00",
                                "\xff"};
const std::uint32_t kWords[] = {0,          1,          2,          3,          0xff,
                                0xffff,     0x7fffffff, 0x80000000, 0xffffffff, 0x7fc00000,
                                0x7f800000, 0xff800000, 0x3f800000};

void mutate(Bytes& b, Rng& rng, const std::vector<Bytes>& pool) {
  switch (rng.below(10)) {
    case 0:  // bit flip
      if (!b.empty()) b[rng.below(b.size())] ^= static_cast<std::uint8_t>(1u << rng.below(8));
      break;
    case 1: {  // interesting byte
      static const std::uint8_t kBytes[] = {0, 1, 0x7f, 0x80, 0xff, ' ', '\n', '-', '0', '9', '#'};
      if (!b.empty()) b[rng.below(b.size())] = kBytes[rng.below(std::size(kBytes))];
      break;
    }
    case 2: {  // insertion
      const std::string_view s = kInserts[rng.below(std::size(kInserts))];
      const std::size_t at = rng.below(b.size() + 1);
      if (s.empty()) {  // "\x00"
        b.insert(b.begin() + static_cast<std::ptrdiff_t>(at), std::uint8_t{0});
      } else {
        b.insert(b.begin() + static_cast<std::ptrdiff_t>(at), s.begin(), s.end());
      }
      break;
    }
    case 3: {  // deletion
      if (b.empty()) break;
      const std::size_t at = rng.below(b.size());
      const std::size_t n = std::min(b.size() - at, 1 + rng.below(16));
      b.erase(b.begin() + static_cast<std::ptrdiff_t>(at),
              b.begin() + static_cast<std::ptrdiff_t>(at + n));
      break;
    }
    case 4:  // truncation
      b.resize(rng.below(b.size() + 1));
      break;
    case 5: {  // copy a chunk elsewhere
      if (b.empty()) break;
      const std::size_t from = rng.below(b.size());
      const std::size_t n = std::min(b.size() - from, 1 + rng.below(64));
      const Bytes chunk(b.begin() + static_cast<std::ptrdiff_t>(from),
                        b.begin() + static_cast<std::ptrdiff_t>(from + n));
      const std::size_t at = rng.below(b.size() + 1);
      b.insert(b.begin() + static_cast<std::ptrdiff_t>(at), chunk.begin(), chunk.end());
      break;
    }
    case 6: {  // splice from another seed
      const Bytes& other = pool[rng.below(pool.size())];
      if (other.empty() || b.empty()) break;
      const std::size_t from = rng.below(other.size());
      const std::size_t n = std::min(other.size() - from, 1 + rng.below(128));
      const std::size_t at = rng.below(b.size());
      const std::size_t m = std::min(b.size() - at, n);
      b.erase(b.begin() + static_cast<std::ptrdiff_t>(at),
              b.begin() + static_cast<std::ptrdiff_t>(at + m));
      b.insert(b.begin() + static_cast<std::ptrdiff_t>(at),
               other.begin() + static_cast<std::ptrdiff_t>(from),
               other.begin() + static_cast<std::ptrdiff_t>(from + n));
      break;
    }
    case 7:
    case 8: {  // replace a numeric token
      std::vector<std::pair<std::size_t, std::size_t>> tokens;
      for (std::size_t i = 0; i < b.size() && tokens.size() < 4096;) {
        const auto digit = [&](std::size_t k) {
          return k < b.size() && ((b[k] >= '0' && b[k] <= '9') || b[k] == '-' || b[k] == '.' ||
                                  b[k] == 'e' || b[k] == '+');
        };
        if (digit(i) && (i == 0 || !digit(i - 1))) {
          std::size_t j = i;
          while (digit(j)) ++j;
          tokens.emplace_back(i, j - i);
          i = j;
        } else {
          ++i;
        }
      }
      if (tokens.empty()) break;
      const auto [at, len] = tokens[rng.below(tokens.size())];
      const std::string_view s = kTokens[rng.below(std::size(kTokens))];
      b.erase(b.begin() + static_cast<std::ptrdiff_t>(at),
              b.begin() + static_cast<std::ptrdiff_t>(at + len));
      b.insert(b.begin() + static_cast<std::ptrdiff_t>(at), s.begin(), s.end());
      break;
    }
    default: {  // overwrite a binary word (either byte order)
      if (b.size() < 4) break;
      std::uint32_t w = kWords[rng.below(std::size(kWords))];
      if (rng.below(2) == 1) {
        w = (w >> 24) | ((w >> 8) & 0xff00u) | ((w << 8) & 0xff0000u) | (w << 24);
      }
      const std::size_t at =
          rng.below(2) == 1 ? rng.below(b.size() - 3) : (rng.below(b.size() / 4) * 4);
      std::memcpy(b.data() + at, &w, 4);
    }
  }
}

std::string_view view(const Bytes& b) {
  return {reinterpret_cast<const char*>(b.data()), b.size()};
}

int smoke(const Target& target, std::size_t iterations, std::uint64_t seed) {
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<Bytes> seeds = make_seeds(target.format);
  // Splices come from the seeds of every format.
  std::vector<Bytes> pool;
  for (MeshFormat f : {MeshFormat::kPly, MeshFormat::kObj, MeshFormat::kOff, MeshFormat::kStl}) {
    for (Bytes& b : make_seeds(f)) pool.push_back(std::move(b));
  }
  std::vector<std::string> real_names;
  // Every real mesh is run once unmutated; the small ones (<= 400 KB) also seed mutations.
  const std::vector<Bytes> real = real_meshes(target.format, real_names);
  Stats stats;
  std::vector<Bytes> small_real;
  for (const Bytes& r : real) {
    target.run(view(r), stats);
    if (r.size() <= 400 * 1024) small_real.push_back(r);
  }
  for (const Bytes& s : seeds) target.run(view(s), stats);
  Rng rng(seed);
  for (std::size_t it = 0; it < iterations; ++it) {
    const bool use_real = !small_real.empty() && rng.below(100) < 2;
    Bytes b = use_real ? small_real[rng.below(small_real.size())] : seeds[rng.below(seeds.size())];
    const std::size_t rounds = 1 + rng.below(4);
    for (std::size_t r = 0; r < rounds; ++r) mutate(b, rng, pool);
    target.run(view(b), stats);
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf(
      "%s smoke (seed %#llx): %zu seeds (+%zu real meshes), %zu mutated inputs, %zu parses in "
      "%.2f s: %zu valid meshes (%zu needed repairs), %zu smr::Errors, 0 failures\n",
      target.name, static_cast<unsigned long long>(seed), seeds.size(), real.size(), iterations,
      stats.parses, s, stats.valid, stats.repaired, stats.errors);
  // A smoke run whose inputs are all rejected, or all accepted, explores one side only.
  if (stats.valid == 0 || stats.errors == 0) {
    std::fprintf(stderr, "%s: %zu valid meshes and %zu errors: the seeds do not reach both\n",
                 target.name, stats.valid, stats.errors);
    return 1;
  }
  return 0;
}

int run_main(int argc, char** argv, const Target& target) {
  std::size_t iterations = target.iterations;
  std::uint64_t seed = 0x5eed5eedULL;
  if (const char* env = std::getenv("SMRDB_FUZZ_SEED"); env != nullptr && *env != '\0') {
    seed = std::strtoull(env, nullptr, 0);
  }
  if (const char* env = std::getenv("SMRDB_FUZZ_ITERATIONS"); env != nullptr && *env != '\0') {
    iterations = static_cast<std::size_t>(std::strtoull(env, nullptr, 10));
  }
  if (argc >= 2) {
    char* end = nullptr;
    const unsigned long long n = std::strtoull(argv[1], &end, 10);
    if (end != argv[1] && *end == '\0') {
      iterations = static_cast<std::size_t>(n);
    } else {  // reproduce: run the given files
      Stats stats;
      for (int i = 1; i < argc; ++i) {
        std::ifstream in(argv[i], std::ios::binary);
        if (!in) {
          std::fprintf(stderr, "%s: cannot open %s\n", target.name, argv[i]);
          return 1;
        }
        const std::string bytes{std::istreambuf_iterator<char>(in),
                                std::istreambuf_iterator<char>()};
        target.run(bytes, stats);
      }
      std::printf("%s: %zu inputs, %zu parses: %zu valid, %zu smr::Errors\n", target.name,
                  stats.inputs, stats.parses, stats.valid, stats.errors);
      return 0;
    }
  }
  return smoke(target, iterations, seed);
}

}  // namespace

}  // namespace smr::fuzz

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  smr::fuzz::Stats stats;
  smr::fuzz::target().run(std::string_view(reinterpret_cast<const char*>(data), size), stats);
  return 0;
}

#ifndef SMRDB_LIBFUZZER
int main(int argc, char** argv) {
  return smr::fuzz::run_main(argc, argv, smr::fuzz::target());
}
#endif
