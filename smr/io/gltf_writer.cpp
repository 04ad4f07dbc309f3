// glTF 2.0 writer (gltf_writer.h), after the glTF 2.0 specification (3.6 buffers and accessors,
// 3.7.2 meshes, 4.4 GLB) and the KHR_mesh_quantization, KHR_draco_mesh_compression and
// EXT_meshopt_compression extension specifications. One primitive: POSITION (uint16 x 3, stride
// 8), NORMAL (int8 x 3 stride 4, or int16 x 3 stride 8, normalized) and the triangle indices
// (uint16 below 65 535 vertices, else uint32). The binary sections are built whole and reach the
// file in a few large writes, like mesh_writer.cpp's.
#include "smr/io/gltf_writer.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/io/atomic_file.h"
#include "smr/io/io_util.h"
#include "storage/mesh_compress.h"

namespace smr {

namespace {

using nlohmann::json;
using storage::Bytes;

constexpr int kByte = 5120, kShort = 5122, kUnsignedShort = 5123, kUnsignedInt = 5125;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;
constexpr std::uint32_t kGlbMagic = 0x46546C67;  // "glTF"
constexpr std::uint32_t kChunkJson = 0x4E4F534A, kChunkBin = 0x004E4942;

template <typename T>
void put_le(Bytes& out, T v) {
  std::uint8_t b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(b, b + sizeof(T));
  out.insert(out.end(), b, b + sizeof(T));
}

void pad4(Bytes& out, std::uint8_t fill = 0) {
  while (out.size() % 4 != 0) out.push_back(fill);
}

// ---- quantization -----------------------------------------------------------------------------

struct Quantized {
  storage::QuantizedMesh mesh;
  std::array<int, 3> shift{};
  Vec3 offset{0.0}, scale{1.0};  // data = offset + scale * stored integer
  Vec3 max_error{0.0};
};

// The smallest k >= -kMaxRefine with round(span * 2^-k) <= 65535: a negative k subdivides the
// grid step (positions stay exactly on the grid, at multiples of 2^-k units) to use the 16 bits a
// short span leaves; a positive one coarsens it. Using the bits keeps the node's scale close to
// isotropic, which the normals need (see quantize_normals).
constexpr int kMaxRefine = 16;
int fitting_shift(std::int64_t span) {
  int k = 0;
  while (((span + (k > 0 ? (std::int64_t{1} << (k - 1)) : 0)) >> k) > 65535) ++k;
  while (k <= 0 && k > -kMaxRefine && (span << (1 - k)) <= 65535) --k;
  return k;
}

void quantize_positions(const std::string& path, const TriangleMesh& mesh, const GltfOptions& o,
                        Quantized& out) {
  const std::size_t n = mesh.positions.size();
  std::vector<std::array<std::int64_t, 3>> q(n);
  std::array<std::int64_t, 3> lo{}, hi{};
  lo.fill(std::numeric_limits<std::int64_t>::max());
  hi.fill(std::numeric_limits<std::int64_t>::min());
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      const double g = std::round((mesh.positions[i][a] - o.grid_origin[a]) / o.grid_step[a]);
      if (!(std::abs(g) < 2147483648.0))
        throw_input("cannot write glTF '" + path + "': vertex " + std::to_string(i) +
                    " is not finite or lies outside the 32-bit quantization grid");
      q[i][a] = static_cast<std::int64_t>(g);
      lo[a] = std::min(lo[a], q[i][a]);
      hi[a] = std::max(hi[a], q[i][a]);
    }
  }
  for (int a = 0; a < 3; ++a) out.shift[a] = fitting_shift(hi[a] - lo[a]);
  if (!o.terrain) {  // one shift on every axis: a uniform node scale (int8 normals)
    const int k = *std::max_element(out.shift.begin(), out.shift.end());
    out.shift.fill(k);
  }
  for (int a = 0; a < 3; ++a) {
    const double unit = std::ldexp(o.grid_step[a], out.shift[a]);
    out.offset[a] = o.grid_origin[a] + o.grid_step[a] * double(lo[a]);
    out.scale[a] = unit;
    out.max_error[a] = out.shift[a] > 0 ? unit / 2 : 0.0;
  }
  out.mesh.positions.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      const int k = out.shift[a];
      const std::int64_t d = q[i][a] - lo[a];
      const std::int64_t v = k > 0 ? (d + (std::int64_t{1} << (k - 1))) >> k : d << -k;
      out.mesh.positions[i][a] = static_cast<std::uint16_t>(v);
    }
  }
}

// The metric frame's scale D (degrees to metres for a geographic terrain).
Vec3 metric_scale(const GltfOptions& o) {
  if (!o.terrain || !o.georef.geographic) return Vec3(1.0);
  const auto m = metres_per_degree(o.reference.y);
  return {m[0], m[1], 1.0};
}

// Area-weighted vertex normals in the metric frame, turned into the node's local space (scaled
// by the node scale, then normalized) and stored as normalized integers of `bits` bits.
void quantize_normals(const TriangleMesh& mesh, const Vec3& metric, const Vec3& node_scale,
                      int bits, Quantized& out) {
  const std::size_t n = mesh.positions.size();
  std::vector<Vec3> sum(n, Vec3(0.0));
  for (const auto& t : mesh.triangles) {
    const Vec3 a = metric * mesh.positions[t[0]];
    const Vec3 b = metric * mesh.positions[t[1]];
    const Vec3 c = metric * mesh.positions[t[2]];
    const Vec3 f = glm::cross(b - a, c - a);
    for (std::uint32_t v : t) sum[v] += f;
  }
  const double top = bits == 8 ? 127.0 : 32767.0;
  out.mesh.normal_bits = bits;
  out.mesh.normals.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    Vec3 local = node_scale * sum[i];
    const double len = glm::length(local);
    local = len > 0.0 && std::isfinite(len) ? local / len : Vec3(0.0, 0.0, 1.0);
    // Round each component. With 8 bits, of the roundings one step either way keep the one
    // nearest to unit length (plain rounding can be 1 % off, which validators reject); 16 bits are
    // within 1e-4 as they are, and the step would turn a terrain's nearly horizontal local
    // normals (its z step is far finer than its x/y steps) by up to 3 %.
    std::array<std::int16_t, 3> best{};
    double best_err = std::numeric_limits<double>::infinity();
    for (int d = bits == 8 ? 0 : 13; d < (bits == 8 ? 27 : 14); ++d) {
      std::array<std::int16_t, 3> c{};
      double len2 = 0.0;
      for (int k = 0; k < 3; ++k) {
        const int step = (d / (k == 0 ? 1 : k == 1 ? 3 : 9)) % 3 - 1;  // d = 13: no step
        const double v = std::clamp(std::round(local[k] * top) + step, -top, top);
        c[k] = static_cast<std::int16_t>(v);
        len2 += (v / top) * (v / top);
      }
      const double err = std::abs(std::sqrt(len2) - 1.0) +
                         1e-3 * glm::length(Vec3(c[0], c[1], c[2]) / top - local);
      if (err < best_err) best_err = err, best = c;
    }
    out.mesh.normals[i] = best;
  }
}

// ---- layout -----------------------------------------------------------------------------------

// The raw (uncompressed) vertex and index data of a quantized mesh, as glTF lays them out.
struct Raw {
  Bytes positions, normals, indices;
  std::size_t position_stride = 8, normal_stride = 8, index_size = 2;
};

Raw raw_data(const storage::QuantizedMesh& m) {
  Raw r;
  r.normal_stride = m.normal_bits == 8 ? 4 : 8;
  r.index_size = m.positions.size() < 65535 ? 2 : 4;
  r.positions.reserve(m.positions.size() * 8);
  for (const auto& p : m.positions) {
    for (std::uint16_t v : p) put_le(r.positions, v);
    put_le(r.positions, std::uint16_t{0});
  }
  for (const auto& nrm : m.normals) {
    if (m.normal_bits == 8) {
      for (std::int16_t v : nrm) put_le(r.normals, static_cast<std::int8_t>(v));
      put_le(r.normals, std::int8_t{0});
    } else {
      for (std::int16_t v : nrm) put_le(r.normals, v);
      put_le(r.normals, std::int16_t{0});
    }
  }
  for (const auto& t : m.triangles) {
    for (std::uint32_t v : t) {
      if (r.index_size == 2) {
        put_le(r.indices, static_cast<std::uint16_t>(v));
      } else {
        put_le(r.indices, v);
      }
    }
  }
  return r;
}

json bounds_json(const storage::QuantizedMesh& m, bool want_max) {
  std::array<int, 3> v{};
  v.fill(want_max ? 0 : 65535);
  for (const auto& p : m.positions) {
    for (int a = 0; a < 3; ++a)
      v[a] = want_max ? std::max<int>(v[a], p[a]) : std::min<int>(v[a], p[a]);
  }
  return json(v);
}

// The document being built: JSON arrays and buffer 0 (the GLB BIN chunk or the data URI).
struct Document {
  json views = json::array(), accessors = json::array();
  Bytes bin;

  // A view over bytes appended to buffer 0 (4-byte aligned).
  int add_view(const Bytes& data, std::size_t stride, int target) {
    pad4(bin);
    json v = {{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", data.size()}};
    if (stride != 0) v["byteStride"] = stride;
    if (target != 0) v["target"] = target;
    bin.insert(bin.end(), data.begin(), data.end());
    views.push_back(std::move(v));
    return static_cast<int>(views.size()) - 1;
  }
  int add_accessor(json a) {
    accessors.push_back(std::move(a));
    return static_cast<int>(accessors.size()) - 1;
  }
};

// Accessors of the primitive (views -1: none, as Draco's are) and its attributes/indices JSON.
json primitive_json(Document& doc, const storage::QuantizedMesh& m, std::array<int, 3> view) {
  const auto with_view = [&](json a, int v) {
    if (v >= 0) a["bufferView"] = v;
    return a;
  };
  const std::size_t n = m.positions.size();
  const int pos = doc.add_accessor(with_view({{"componentType", kUnsignedShort},
                                              {"count", n},
                                              {"type", "VEC3"},
                                              {"min", bounds_json(m, false)},
                                              {"max", bounds_json(m, true)}},
                                             view[0]));
  json prim = {{"attributes", {{"POSITION", pos}}}, {"mode", 4}};
  if (!m.normals.empty()) {
    prim["attributes"]["NORMAL"] =
        doc.add_accessor(with_view({{"componentType", m.normal_bits == 8 ? kByte : kShort},
                                    {"normalized", true},
                                    {"count", n},
                                    {"type", "VEC3"}},
                                   view[1]));
  }
  prim["indices"] =
      doc.add_accessor(with_view({{"componentType", n < 65535 ? kUnsignedShort : kUnsignedInt},
                                  {"count", m.triangles.size() * 3},
                                  {"type", "SCALAR"}},
                                 view[2]));
  return prim;
}

// Uncompressed: three views in buffer 0.
json plain_primitive(Document& doc, const storage::QuantizedMesh& m) {
  const Raw r = raw_data(m);
  const int pv = doc.add_view(r.positions, r.position_stride, kArrayBuffer);
  const int nv = m.normals.empty() ? -1 : doc.add_view(r.normals, r.normal_stride, kArrayBuffer);
  const int iv = doc.add_view(r.indices, 0, kElementArrayBuffer);
  return primitive_json(doc, m, {pv, nv, iv});
}

// EXT_meshopt_compression: the views keep their uncompressed layout in a fallback buffer (1,
// no data) and point at their compressed bytes in buffer 0.
json meshopt_primitive(Document& doc, storage::QuantizedMesh& m, std::size_t& fallback_bytes) {
  const std::vector<std::uint32_t> remap =
      storage::meshopt_reorder(m.triangles, m.positions.size());
  storage::QuantizedMesh reordered = m;
  for (std::size_t i = 0; i < remap.size(); ++i) {
    reordered.positions[remap[i]] = m.positions[i];
    if (!m.normals.empty()) reordered.normals[remap[i]] = m.normals[i];
  }
  m = std::move(reordered);
  const Raw r = raw_data(m);
  const std::size_t n = m.positions.size();
  fallback_bytes = 0;
  const auto add = [&](const Bytes& raw, std::size_t stride, std::size_t count, int target,
                       const char* mode) {
    Bytes packed;
    if (std::strcmp(mode, "TRIANGLES") == 0) {
      std::vector<std::uint32_t> idx;
      idx.reserve(m.triangles.size() * 3);
      for (const auto& t : m.triangles) idx.insert(idx.end(), t.begin(), t.end());
      packed = storage::meshopt_encode_triangles(idx, n);
    } else {
      packed = storage::meshopt_encode_attributes(raw, count, stride);
    }
    const int v = doc.add_view(packed, 0, 0);
    json& view = doc.views[static_cast<std::size_t>(v)];
    json ext = {{"buffer", 0},
                {"byteOffset", view["byteOffset"]},
                {"byteLength", packed.size()},
                {"byteStride", stride},
                {"count", count},
                {"mode", mode}};
    fallback_bytes = (fallback_bytes + 3) / 4 * 4;
    view = {{"buffer", 1},
            {"byteOffset", fallback_bytes},
            {"byteLength", raw.size()},
            {"target", target},
            {"extensions", {{"EXT_meshopt_compression", std::move(ext)}}}};
    if (target == kArrayBuffer) view["byteStride"] = stride;
    fallback_bytes += raw.size();
    return v;
  };
  const int pv = add(r.positions, r.position_stride, n, kArrayBuffer, "ATTRIBUTES");
  const int nv =
      m.normals.empty() ? -1 : add(r.normals, r.normal_stride, n, kArrayBuffer, "ATTRIBUTES");
  const int iv =
      add(r.indices, r.index_size, m.triangles.size() * 3, kElementArrayBuffer, "TRIANGLES");
  return primitive_json(doc, m, {pv, nv, iv});
}

// KHR_draco_mesh_compression: one view of Draco bytes; the accessors describe the decoded mesh
// (the extension asks generators to take them from the decoded data: Draco may add vertices).
json draco_primitive(Document& doc, storage::QuantizedMesh& m) {
  const storage::DracoMesh d = storage::draco_encode_mesh(m);
  m = storage::draco_decode_mesh(d.bytes, d, m.normal_bits, "draco output");
  const int v = doc.add_view(d.bytes, 0, 0);
  json prim = primitive_json(doc, m, {-1, -1, -1});
  json attrs = {{"POSITION", d.position_id}};
  if (d.normal_id >= 0) attrs["NORMAL"] = d.normal_id;
  prim["extensions"] = {
      {"KHR_draco_mesh_compression", {{"bufferView", v}, {"attributes", std::move(attrs)}}}};
  return prim;
}

std::string base64(const Bytes& in) {
  static constexpr char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((in.size() + 2) / 3 * 4);
  for (std::size_t i = 0; i < in.size(); i += 3) {
    const std::uint32_t b0 = in[i], b1 = i + 1 < in.size() ? in[i + 1] : 0u,
                        b2 = i + 2 < in.size() ? in[i + 2] : 0u;
    const std::uint32_t w = (b0 << 16) | (b1 << 8) | b2;
    out += kAlphabet[(w >> 18) & 63];
    out += kAlphabet[(w >> 12) & 63];
    out += i + 1 < in.size() ? kAlphabet[(w >> 6) & 63] : '=';
    out += i + 2 < in.size() ? kAlphabet[w & 63] : '=';
  }
  return out;
}

json extras_json(const GltfOptions& o, const Quantized& q, const Vec3& metric) {
  const auto vec = [](const Vec3& v) { return json::array({v.x, v.y, v.z}); };
  json smrdb = {
      {"position_to_data",
       {{"offset", vec(q.offset)},
        {"scale", vec(q.scale)},
        {"meaning", "data = offset + scale * POSITION (the stored integers), per axis"}}},
      {"max_position_error", vec(q.max_error)},
      {"data_to_gltf",
       {{"reference", vec(o.reference)},
        {"scale", vec(metric)},
        {"axes", o.terrain ? "glTF (x, y, z) = (X, Z, -Y) for the data X east, Y north, Z up"
                           : "glTF (x, y, z) = (X, Y, Z)"},
        {"meaning", "glTF = axes(scale * (data - reference))"}}},
      {"grid", {{"origin", vec(o.grid_origin)}, {"step", vec(o.grid_step)}}},
  };
  if (o.terrain) {
    smrdb["georef"] = {{"x0", o.georef.x0},
                       {"y0", o.georef.y0},
                       {"dx", o.georef.dx},
                       {"dy", o.georef.dy},
                       {"geographic", o.georef.geographic},
                       {"crs_wkt", o.georef.crs_wkt}};
    if (o.georef.geographic)
      smrdb["data_to_gltf"]["scale_meaning"] =
          "WGS 84 metres per degree of longitude and latitude at the reference latitude";
  }
  if (!o.extras_json.empty()) {
    const json extra = json::parse(o.extras_json, nullptr, false);
    if (!extra.is_object()) throw_internal("glTF extras: not a JSON object");
    smrdb.update(extra);
  }
  return smrdb;
}

void check_mesh(const std::string& path, const TriangleMesh& mesh) {
  if (mesh.triangles.empty())
    throw_input("cannot write glTF '" + path + "': the mesh has no triangles");
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    for (std::uint32_t v : mesh.triangles[t]) {
      if (v >= mesh.positions.size())
        throw_input("cannot write glTF '" + path + "': triangle " + std::to_string(t) +
                    " references vertex " + std::to_string(v) + " but the mesh has " +
                    std::to_string(mesh.positions.size()) + " vertices");
    }
  }
}

// The node's transform: M = T * R * S with S = D * position scale, R the z-up to y-up turn, and
// T = R * D * (offset - reference).
json node_json(const GltfOptions& o, const Quantized& q, const Vec3& metric) {
  const auto turn = [&](const Vec3& v) { return o.terrain ? Vec3(v.x, v.z, -v.y) : v; };
  const Vec3 t = turn(metric * (q.offset - o.reference));
  const Vec3 s = metric * q.scale;
  json node = {
      {"mesh", 0}, {"name", "smrdb"}, {"translation", {t.x, t.y, t.z}}, {"scale", {s.x, s.y, s.z}}};
  if (o.terrain) {
    const double h = std::numbers::sqrt2 / 2;
    node["rotation"] = {-h, 0.0, 0.0, h};  // -90 degrees about x: (x, y, z) -> (x, z, -y)
  }
  return node;
}

}  // namespace

std::optional<GltfCompression> parse_gltf_compression(std::string_view name) {
  if (name == "none") return GltfCompression::kNone;
  if (name == "draco") return GltfCompression::kDraco;
  if (name == "meshopt") return GltfCompression::kMeshopt;
  return std::nullopt;
}

std::string_view gltf_compression_name(GltfCompression c) {
  switch (c) {
    case GltfCompression::kDraco:
      return "draco";
    case GltfCompression::kMeshopt:
      return "meshopt";
    case GltfCompression::kNone:
      break;
  }
  return "none";
}

GltfReport write_gltf(const std::string& path, const TriangleMesh& mesh, const GltfOptions& o) {
  const std::string ext = io_util::lower_extension(path);
  if (ext != ".glb" && ext != ".gltf")
    throw_input("cannot write glTF '" + path + "': unknown extension '" + ext +
                "' (expected .glb or .gltf)");
  check_mesh(path, mesh);
  Quantized q;
  quantize_positions(path, mesh, o, q);
  const Vec3 metric = metric_scale(o);
  const Vec3 node_scale = metric * q.scale;
  const bool uniform = node_scale.x == node_scale.y && node_scale.y == node_scale.z;
  quantize_normals(mesh, metric, node_scale, uniform ? 8 : 16, q);
  q.mesh.triangles = mesh.triangles;

  Document doc;
  json used = {"KHR_mesh_quantization"};
  json prim;
  std::size_t fallback_bytes = 0;
  switch (o.compression) {
    case GltfCompression::kNone:
      prim = plain_primitive(doc, q.mesh);
      break;
    case GltfCompression::kMeshopt:
      prim = meshopt_primitive(doc, q.mesh, fallback_bytes);
      used.push_back("EXT_meshopt_compression");
      break;
    case GltfCompression::kDraco:
      prim = draco_primitive(doc, q.mesh);
      used.push_back("KHR_draco_mesh_compression");
      break;
  }
  pad4(doc.bin);
  const bool glb = ext == ".glb";
  json buffers = json::array();
  buffers.push_back({{"byteLength", doc.bin.size()}});
  if (!glb) buffers[0]["uri"] = "data:application/octet-stream;base64," + base64(doc.bin);
  if (fallback_bytes > 0)
    buffers.push_back({{"byteLength", fallback_bytes},
                       {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}});
  json gltf = {
      {"asset",
       {{"version", "2.0"},
        {"generator", "smrdb"},
        {"extras", {{"smrdb", extras_json(o, q, metric)}}}}},
      {"extensionsUsed", used},
      {"extensionsRequired", used},
      {"scene", 0},
      {"scenes", {{{"nodes", {0}}}}},
      {"nodes", {node_json(o, q, metric)}},
      {"meshes", {{{"primitives", {std::move(prim)}}}}},
      {"accessors", std::move(doc.accessors)},
      {"bufferViews", std::move(doc.views)},
      {"buffers", std::move(buffers)},
  };
  std::string text = gltf.dump();

  GltfReport report;
  report.vertices = q.mesh.positions.size();
  report.triangles = q.mesh.triangles.size();
  report.shift = q.shift;
  report.max_position_error = q.max_error;
  report.normal_bits = q.mesh.normal_bits;
  AtomicFile file(path);
  if (glb) {
    while (text.size() % 4 != 0) text += ' ';
    const std::uint64_t total = 12 + 8 + text.size() + 8 + doc.bin.size();
    if (total > std::numeric_limits<std::uint32_t>::max())
      throw_input("cannot write glTF '" + path + "': " + std::to_string(total) +
                  " bytes exceed GLB's 4 GiB limit (write .gltf or compress)");
    Bytes head;
    put_le(head, kGlbMagic);
    put_le(head, std::uint32_t{2});
    put_le(head, static_cast<std::uint32_t>(total));
    put_le(head, static_cast<std::uint32_t>(text.size()));
    put_le(head, kChunkJson);
    file.write(head.data(), head.size());
    file.write(text);
    head.clear();
    put_le(head, static_cast<std::uint32_t>(doc.bin.size()));
    put_le(head, kChunkBin);
    file.write(head.data(), head.size());
    file.write(doc.bin.data(), doc.bin.size());
    report.bytes = total;
  } else {
    file.write(text);
    report.bytes = text.size();
  }
  file.commit();
  return report;
}

}  // namespace smr
