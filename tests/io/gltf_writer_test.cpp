// Tests of the glTF writer (smr/io/gltf_writer.h) on meshes extracted from real datasets: every
// file passes the Khronos glTF-Validator with zero errors and warnings; read back by the small
// GLB/glTF reader below (the glTF spec's layout, not the writer's code), the positions are the
// mesh's within the reported quantization error, the node transform and asset.extras.smrdb map
// the stored integers to the data and the scene frame, the normals are unit and agree with the
// surface, and the Draco and meshopt payloads decode to the same triangles as the plain file.
#include "smr/io/gltf_writer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <set>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/extract/extract.h"
#include "smr/rcf/spec.h"
#include "storage/mesh_compress.h"
#include "tests/query/written_database.h"
#include "tests/support/datasets.h"
#include "tests/support/files.h"
#include "tests/support/meshes.h"
#include "tests/support/node_tools.h"

namespace smr {
namespace {

using nlohmann::json;
using storage::Bytes;

Bytes read_bytes(const std::string& path) {
  const std::string s = test::read_file(path);
  return Bytes(s.begin(), s.end());
}

// fn throws smr::Error of `kind` whose message contains `needle`.
template <typename Fn>
void expect_error(Fn fn, ErrorKind kind, const std::string& needle) {
  try {
    fn();
    ADD_FAILURE() << "no error; expected one containing: " << needle;
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), kind) << e.what();
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

// ---- an independent reader: GLB container, data URIs, accessors, both compressions ----------

struct Gltf {
  json doc;
  Bytes bin;
};

std::uint32_t le32(const Bytes& b, std::size_t at) {
  return std::uint32_t(b[at]) | std::uint32_t(b[at + 1]) << 8 | std::uint32_t(b[at + 2]) << 16 |
         std::uint32_t(b[at + 3]) << 24;
}

Bytes unbase64(const std::string& s) {
  Bytes out;
  std::uint32_t acc = 0;
  int bits = 0;
  for (char c : s) {
    int v = -1;
    if (c >= 'A' && c <= 'Z') v = c - 'A';
    if (c >= 'a' && c <= 'z') v = c - 'a' + 26;
    if (c >= '0' && c <= '9') v = c - '0' + 52;
    if (c == '+') v = 62;
    if (c == '/') v = 63;
    if (v < 0) continue;
    acc = acc << 6 | std::uint32_t(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(std::uint8_t(acc >> bits));
    }
  }
  return out;
}

Gltf read_gltf(const std::string& path) {
  const Bytes bytes = read_bytes(path);
  Gltf g;
  if (path.ends_with(".glb")) {
    EXPECT_EQ(le32(bytes, 0), 0x46546C67u);
    EXPECT_EQ(le32(bytes, 4), 2u);
    EXPECT_EQ(le32(bytes, 8), bytes.size());
    const std::uint32_t json_len = le32(bytes, 12);
    EXPECT_EQ(le32(bytes, 16), 0x4E4F534Au);
    g.doc = json::parse(bytes.begin() + 20, bytes.begin() + 20 + json_len);
    const std::size_t bin_at = 20 + json_len;
    const std::uint32_t bin_len = le32(bytes, bin_at);
    EXPECT_EQ(le32(bytes, bin_at + 4), 0x004E4942u);
    g.bin.assign(bytes.begin() + long(bin_at + 8), bytes.begin() + long(bin_at + 8 + bin_len));
  } else {
    g.doc = json::parse(bytes.begin(), bytes.end());
    const std::string uri = g.doc["buffers"][0]["uri"];
    const std::string prefix = "data:application/octet-stream;base64,";
    EXPECT_TRUE(uri.starts_with(prefix));
    g.bin = unbase64(uri.substr(prefix.size()));
  }
  return g;
}

// What a primitive decodes to: integer positions, normals and triangles.
struct Decoded {
  std::vector<std::array<std::int64_t, 3>> positions, normals;
  std::vector<std::array<std::uint32_t, 3>> triangles;
};

// The bytes of buffer view `v`, uncompressed (EXT_meshopt_compression decoded here).
Bytes view_bytes(const Gltf& g, int v) {
  const json& view = g.doc["bufferViews"][std::size_t(v)];
  if (view.contains("extensions")) {
    const json& m = view["extensions"]["EXT_meshopt_compression"];
    const std::size_t at = m.value("byteOffset", 0), len = m["byteLength"];
    const storage::ByteView packed(g.bin.data() + at, len);
    const std::size_t count = m["count"], stride = m["byteStride"];
    if (m["mode"] == "TRIANGLES") {
      const auto idx = storage::meshopt_decode_triangles(packed, count, "test");
      Bytes out;
      for (std::uint32_t i : idx) {
        for (std::size_t k = 0; k < stride; ++k) out.push_back(std::uint8_t(i >> (8 * k)));
      }
      return out;
    }
    return storage::meshopt_decode_attributes(packed, count, stride, "test");
  }
  EXPECT_EQ(view["buffer"], 0);
  const std::size_t at = view.value("byteOffset", 0), len = view["byteLength"];
  return Bytes(g.bin.begin() + long(at), g.bin.begin() + long(at + len));
}

std::int64_t component(const std::uint8_t* p, int type) {
  switch (type) {
    case 5120:
      return std::int8_t(p[0]);
    case 5121:
      return p[0];
    case 5122:
      return std::int16_t(std::uint16_t(p[0] | p[1] << 8));
    case 5123:
      return std::uint16_t(p[0] | p[1] << 8);
    case 5125:
      return std::uint32_t(p[0] | p[1] << 8 | p[2] << 16 | std::uint32_t(p[3]) << 24);
    default:
      ADD_FAILURE() << "unexpected component type " << type;
      return 0;
  }
}

std::vector<std::int64_t> accessor_values(const Gltf& g, int a) {
  const json& acc = g.doc["accessors"][std::size_t(a)];
  const int type = acc["componentType"];
  const int size = type == 5125 ? 4 : type == 5122 || type == 5123 ? 2 : 1;
  const int n = acc["type"] == "VEC3" ? 3 : 1;
  const Bytes data = view_bytes(g, acc["bufferView"]);
  const json& view = g.doc["bufferViews"][acc["bufferView"].get<std::size_t>()];
  const std::size_t stride = view.value("byteStride", std::size_t(size * n));
  std::vector<std::int64_t> out;
  for (std::size_t i = 0; i < acc["count"].get<std::size_t>(); ++i) {
    for (int k = 0; k < n; ++k)
      out.push_back(component(
          data.data() + i * stride + std::size_t(acc.value("byteOffset", 0) + k * size), type));
  }
  return out;
}

Decoded decode_primitive(const Gltf& g) {
  const json& prim = g.doc["meshes"][0]["primitives"][0];
  Decoded d;
  if (prim.contains("extensions")) {
    const json& x = prim["extensions"]["KHR_draco_mesh_compression"];
    const json& view = g.doc["bufferViews"][x["bufferView"].get<std::size_t>()];
    const std::size_t at = view.value("byteOffset", 0), len = view["byteLength"];
    storage::DracoMesh ids;
    ids.position_id = x["attributes"]["POSITION"];
    ids.normal_id = x["attributes"].value("NORMAL", -1);
    const int bits =
        g.doc["accessors"][prim["attributes"]["NORMAL"].get<std::size_t>()]["componentType"] == 5120
            ? 8
            : 16;
    const auto m =
        storage::draco_decode_mesh(storage::ByteView(g.bin.data() + at, len), ids, bits, "test");
    for (const auto& p : m.positions) d.positions.push_back({p[0], p[1], p[2]});
    for (const auto& n : m.normals) d.normals.push_back({n[0], n[1], n[2]});
    d.triangles = m.triangles;
    return d;
  }
  const auto pos = accessor_values(g, prim["attributes"]["POSITION"]);
  const auto nor = accessor_values(g, prim["attributes"]["NORMAL"]);
  const auto idx = accessor_values(g, prim["indices"]);
  for (std::size_t i = 0; i < pos.size(); i += 3)
    d.positions.push_back({pos[i], pos[i + 1], pos[i + 2]});
  for (std::size_t i = 0; i < nor.size(); i += 3)
    d.normals.push_back({nor[i], nor[i + 1], nor[i + 2]});
  for (std::size_t i = 0; i < idx.size(); i += 3)
    d.triangles.push_back(
        {std::uint32_t(idx[i]), std::uint32_t(idx[i + 1]), std::uint32_t(idx[i + 2])});
  return d;
}

// Triangles as position triples rotated to start at the smallest: the same for any vertex order.
std::multiset<std::array<std::int64_t, 9>> triangle_set(const Decoded& d) {
  std::multiset<std::array<std::int64_t, 9>> out;
  for (const auto& t : d.triangles) {
    int first = 0;
    for (int k = 1; k < 3; ++k) {
      if (d.positions[t[std::size_t(k)]] < d.positions[t[std::size_t(first)]]) first = k;
    }
    std::array<std::int64_t, 9> key{};
    for (int k = 0; k < 3; ++k) {
      const auto& p = d.positions[t[std::size_t((first + k) % 3)]];
      std::copy(p.begin(), p.end(), key.begin() + 3 * k);
    }
    out.insert(key);
  }
  return out;
}

Vec3 vec(const json& j) {
  return {j[0].get<double>(), j[1].get<double>(), j[2].get<double>()};
}

// ---- the meshes under test ------------------------------------------------------------------

struct Case {
  TriangleMesh mesh;
  GltfOptions options;
};

Case terrain_case(const std::string& name, double floor) {
  const test::WrittenDatabase wdb(test::dataset(name).crmr);
  RcfSpec spec;
  spec.floor = floor;
  const Rcf rcf = make_rcf(spec, ModelKind::kTerrain, nullptr);
  const Extraction e = extract_minimal_surface(wdb.source(), rcf);
  Case c;
  c.mesh = to_mesh(wdb.database(), e.triangles);
  const CrmrInfo& info = wdb.database().info();
  c.options.grid_origin = wdb.database().grid().origin;
  c.options.grid_step = wdb.database().grid().step;
  c.options.terrain = true;
  c.options.georef = info.georef;
  c.options.reference = (info.bounds.lo + info.bounds.hi) * 0.5;
  c.options.reference.z = 0.0;
  c.options.extras_json = R"({"source": ")" + name + R"("})";
  return c;
}

Case mesh_case(const std::string& name) {
  const test::WrittenDatabase wdb(test::built_mesh(name).crmr);
  RcfSpec spec;
  spec.floor = 0.95;
  const Rcf rcf = make_rcf(spec, ModelKind::kMesh3d, nullptr);
  const Extraction e = extract_minimal_surface(wdb.source(), rcf);
  Case c;
  c.mesh = to_mesh(wdb.database(), e.triangles);
  c.options.grid_origin = wdb.database().grid().origin;
  c.options.grid_step = wdb.database().grid().step;
  const CrmrInfo& info = wdb.database().info();
  c.options.reference = (info.bounds.lo + info.bounds.hi) * 0.5;
  return c;
}

// Checks one file against the mesh it was written from; returns what it decodes to.
Decoded check_file(const std::string& path, const Case& c, const GltfReport& r) {
  SCOPED_TRACE(path);
  const Gltf g = read_gltf(path);
  const Decoded d = decode_primitive(g);
  const json& x = g.doc["asset"]["extras"]["smrdb"];
  const Vec3 offset = vec(x["position_to_data"]["offset"]),
             scale = vec(x["position_to_data"]["scale"]);
  const Vec3 ref = vec(x["data_to_gltf"]["reference"]), metric = vec(x["data_to_gltf"]["scale"]);
  EXPECT_EQ(d.triangles.size(), c.mesh.triangles.size());
  EXPECT_EQ(r.triangles, d.triangles.size());
  EXPECT_EQ(r.vertices, d.positions.size());
  if (c.options.terrain) {
    EXPECT_EQ(x["georef"]["x0"], c.options.georef.x0);
    EXPECT_EQ(x["georef"]["dy"], c.options.georef.dy);
    EXPECT_EQ(x["georef"]["geographic"], c.options.georef.geographic);
    EXPECT_EQ(x["georef"]["crs_wkt"], c.options.georef.crs_wkt);
  }
  // The node: T * R * S applied to the stored integers is the scene frame of the data.
  const json& node = g.doc["nodes"][0];
  const Vec3 t = vec(node["translation"]), s = vec(node["scale"]);
  const bool turned = node.contains("rotation");
  EXPECT_EQ(turned, c.options.terrain);
  const auto frame = [&](const Vec3& v) { return turned ? Vec3(v.x, v.z, -v.y) : v; };
  // Normals: unit length, and in the scene frame (R * S^-T * n) the area-weighted normal of the
  // source mesh's triangles around the vertex (matched by its stored integers: Draco may split
  // vertices), in the metric frame.
  for (std::size_t i = 0; i < d.positions.size(); ++i) {
    const Vec3 q(double(d.positions[i][0]), double(d.positions[i][1]), double(d.positions[i][2]));
    const Vec3 scene = t + frame(s * q);
    const Vec3 expected = frame(metric * (offset + scale * q - ref));
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(scene[k], expected[k], 1e-6 * (1 + std::abs(expected[k])));
  }
  std::vector<Vec3> around(c.mesh.positions.size(), Vec3(0.0));
  for (const auto& tri : c.mesh.triangles) {
    const auto& p = c.mesh.positions;
    const Vec3 f = glm::cross(metric * (p[tri[1]] - p[tri[0]]), metric * (p[tri[2]] - p[tri[0]]));
    for (std::uint32_t v : tri) around[v] += f;
  }
  std::map<std::array<std::int64_t, 3>, Vec3> source_normal;
  for (std::size_t i = 0; i < c.mesh.positions.size(); ++i) {
    const Vec3 q = glm::round((c.mesh.positions[i] - offset) / scale);
    source_normal.emplace(
        std::array<std::int64_t, 3>{std::int64_t(q.x), std::int64_t(q.y), std::int64_t(q.z)},
        around[i]);
  }
  const double top = r.normal_bits == 8 ? 127.0 : 32767.0;
  double worst = 0.0;
  for (std::size_t i = 0; i < d.normals.size(); ++i) {
    const Vec3 local =
        Vec3(double(d.normals[i][0]), double(d.normals[i][1]), double(d.normals[i][2])) / top;
    EXPECT_NEAR(glm::length(local), 1.0, r.normal_bits == 8 ? 0.005 : 2e-4) << "vertex " << i;
    const auto it = source_normal.find(d.positions[i]);
    if (it == source_normal.end() || glm::length(it->second) == 0.0) {
      ADD_FAILURE() << "vertex " << i << " is not a vertex of the source mesh";
      continue;
    }
    const Vec3 scene = frame(glm::normalize(local / s));
    worst = std::max(worst, glm::length(scene - frame(glm::normalize(it->second))));
  }
  EXPECT_LT(worst, r.normal_bits == 8 ? 0.03 : 1e-3);
  return d;
}

class GltfDatasets : public ::testing::TestWithParam<std::string> {};

TEST_P(GltfDatasets, ValidAndFaithfulInEveryForm) {
  const std::string name = GetParam();
  const Case c = name.ends_with(".off") ? mesh_case(name) : terrain_case(name, 0.9);
  ASSERT_GT(c.mesh.triangles.size(), 100u);
  test::TempDir dir;
  std::vector<std::string> files;
  std::map<std::string, Decoded> decoded;
  for (const char* compression : {"none", "draco", "meshopt"}) {
    for (const char* ext : {".glb", ".gltf"}) {
      GltfOptions o = c.options;
      o.compression = *parse_gltf_compression(compression);
      const std::string path = dir.file(std::string(compression) + ext);
      const GltfReport r = write_gltf(path, c.mesh, o);
      EXPECT_EQ(r.normal_bits, c.options.terrain ? 16 : 8);
      decoded[std::string(compression) + ext] = check_file(path, c, r);
      files.push_back(path);
      if (std::string(compression) == "none") {
        // The plain file keeps the mesh's vertex and triangle order, on the grid.
        const Decoded& d = decoded.at(std::string(compression) + ext);
        ASSERT_EQ(d.positions.size(), c.mesh.positions.size());
        EXPECT_EQ(d.triangles, c.mesh.triangles);
        const Gltf g = read_gltf(path);
        const json& x = g.doc["asset"]["extras"]["smrdb"]["position_to_data"];
        for (std::size_t i = 0; i < d.positions.size(); ++i) {
          for (int k = 0; k < 3; ++k) {
            const double v =
                vec(x["offset"])[k] + vec(x["scale"])[k] * double(d.positions[i][std::size_t(k)]);
            ASSERT_LE(std::abs(v - c.mesh.positions[i][k]),
                      r.max_position_error[k] * (1 + 1e-9) + 1e-9 * std::abs(v))
                << "vertex " << i << " axis " << k;
          }
        }
        if (c.options.terrain) {
          EXPECT_LE(r.shift[0], 0) << "x is exact on the DEM lattice";
          EXPECT_LE(r.shift[1], 0);
          EXPECT_EQ(r.max_position_error.x, 0.0);
        }
      }
    }
  }
  const auto plain = triangle_set(decoded.at("none.glb"));
  for (const auto& [form, d] : decoded) EXPECT_EQ(triangle_set(d), plain) << form;
  for (const auto& v : test::validate_gltf(files)) {
    EXPECT_EQ(v.errors, 0) << v.path << "\n" << v.messages;
    EXPECT_EQ(v.warnings, 0) << v.path << "\n" << v.messages;
  }
}

INSTANTIATE_TEST_SUITE_P(Real, GltfDatasets,
                         ::testing::Values("jacksboro", "elev", "topobathy", "blobby_3cc.off"),
                         [](const auto& param) {
                           std::string n = param.param;
                           std::replace(n.begin(), n.end(), '.', '_');
                           return n;
                         });

// The validator run above can fail: a file whose POSITION bounds are wrong is reported.
TEST(GltfWriter, ValidatorReportsABrokenFile) {
  const Case c = terrain_case("jacksboro", 0.5);
  test::TempDir dir;
  const std::string good = dir.file("good.gltf"), bad = dir.file("bad.gltf");
  write_gltf(good, c.mesh, c.options);
  json doc = json::parse(test::read_file(good));
  doc["accessors"][0]["max"][0] = doc["accessors"][0]["max"][0].get<int>() + 1;
  test::write_file(bad, doc.dump());
  const auto v = test::validate_gltf({good, bad});
  ASSERT_EQ(v.size(), 2u);
  EXPECT_EQ(v[0].errors, 0) << v[0].messages;
  EXPECT_GT(v[1].errors, 0);
  EXPECT_NE(v[1].messages.find("ACCESSOR_MAX_MISMATCH"), std::string::npos) << v[1].messages;
}

TEST(GltfWriter, RejectsBadInputAndLeavesNoFile) {
  test::TempDir dir;
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 2}};
  GltfOptions o;
  expect_error([&] { write_gltf(dir.file("a.gltf2"), m, o); }, ErrorKind::kInvalidInput,
               "unknown extension '.gltf2'");
  TriangleMesh bad = m;
  bad.triangles = {{0, 1, 3}};
  expect_error([&] { write_gltf(dir.file("a.glb"), bad, o); }, ErrorKind::kInvalidInput,
               "references vertex 3");
  TriangleMesh empty = m;
  empty.triangles.clear();
  expect_error([&] { write_gltf(dir.file("a.glb"), empty, o); }, ErrorKind::kInvalidInput,
               "no triangles");
  TriangleMesh far = m;
  far.positions[1].x = 1e12;
  expect_error([&] { write_gltf(dir.file("a.glb"), far, o); }, ErrorKind::kInvalidInput,
               "32-bit quantization grid");
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
  EXPECT_FALSE(parse_gltf_compression("zip"));
}

TEST(GltfWriter, MetresPerDegreeMatchesWgs84) {
  // WGS 84 (the ellipsoid, not a sphere, which gives 111 195 m for both): 111 320 m per degree
  // of longitude and 110 574 m of latitude at the equator, 111 694 m of latitude at the poles,
  // 55 800 m of longitude and 111 412 m of latitude at 60 degrees.
  EXPECT_NEAR(metres_per_degree(0.0)[0], 111320, 1);
  EXPECT_NEAR(metres_per_degree(0.0)[1], 110574, 1);
  EXPECT_NEAR(metres_per_degree(90.0)[1], 111694, 1);
  EXPECT_NEAR(metres_per_degree(60.0)[0], 55800, 1);
  EXPECT_NEAR(metres_per_degree(60.0)[1], 111412, 1);
}

}  // namespace
}  // namespace smr
