// smrdb serve on loopback (docs/serve.md): every endpoint against what the CLI and the library
// answer for the same parameters, the session frames applied by a client, and hostile input.
#include <signal.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>
#include <httplib.h>

#include "smr/db/database.h"
#include "smr/db/writer.h"
#include "smr/extract/extract.h"
#include "smr/query/contours.h"
#include "smr/query/elevation.h"
#include "smr/query/indexed_source.h"
#include "smr/query/sight.h"
#include "smr/rcf/spec.h"
#include "smr/tiles/pyramid.h"
#include "tests/serve/serve_client.h"
#include "tests/support/datasets.h"
#include "tests/support/files.h"
#include "tests/support/meshes.h"
#include "tests/support/process.h"
#include "tests/support/rcf_spread.h"
#include "tests/support/sanitized.h"

namespace smr {
namespace {

using nlohmann::json;

// The server's --timeout-ms: short, for the slow-client tests, but long enough for the
// extractions the tests ask for to end by their triangle cap, not by the deadline (a 504), also
// under the sanitizers on a loaded machine.
constexpr int kTimeoutMs = test::kSanitized ? 5000 : 1500;

// One server for the suite: jacksboro (geographic) and fbm257 (grid units) written to scratch
// databases. The suite has one parameter so that CTest runs it in one process
// (tests/discover_grouped.cmake): one server, one build of each dataset.
class Serve : public ::testing::TestWithParam<std::string> {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir("smrdb-serve");
    db_path_ = dir_->file("jacksboro.smrdb");
    Crmr copy = test::dataset("jacksboro").crmr;
    write_database(copy, db_path_, {});
    db_ = Database::open(db_path_, {std::size_t{64} << 20}).release();
    source_ = new IndexedSource(*db_);
    fbm_path_ = dir_->file("fbm257.smrdb");
    Crmr fbm = test::dataset("fbm257").crmr;
    write_database(fbm, fbm_path_, {});
    fbm_ = Database::open(fbm_path_, {std::size_t{64} << 20}).release();
    fbm_source_ = new IndexedSource(*fbm_);
    mesh_path_ = dir_->file("bunny.smrdb");
    Crmr bunny = test::built_mesh("bunny00.off").crmr;
    write_database(bunny, mesh_path_, {});
    mesh_ = Database::open(mesh_path_, {std::size_t{64} << 20}).release();
    mesh_source_ = new IndexedSource(*mesh_);
    std::filesystem::create_directories(dir_->file("viewer/assets"));
    test::write_file(dir_->file("viewer/index.html"), "<html>viewer</html>");
    test::write_file(dir_->file("viewer/assets/app.js"), "console.log(1);");
    server_ = new test::ServerProcess(
        {"j=" + db_path_, fbm_path_, "bunny=" + mesh_path_, "--threads", "4", "--queue", "8",
         "--timeout-ms", std::to_string(kTimeoutMs), "--max-sessions", "3", "--max-triangles",
         "50000", "--session-idle-s", "4", "--max-connections", "100", "--viewer",
         dir_->file("viewer")},
        dir_->file("server.log"));
  }
  static void TearDownTestSuite() {
    const int status = server_->stop();
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
        << "the server did not exit cleanly on SIGTERM (status " << status << ")";
    delete server_;
    delete source_;
    delete db_;
    delete fbm_source_;
    delete fbm_;
    delete mesh_source_;
    delete mesh_;
    delete dir_;
  }
  static httplib::Result get(const std::string& path, const httplib::Headers& headers = {}) {
    httplib::Client c("127.0.0.1", server_->port());
    c.set_read_timeout(20, 0);
    return c.Get(path.c_str(), headers);
  }
  static json get_json(const std::string& path, int status = 200) {
    const auto r = get(path);
    EXPECT_TRUE(r) << path;
    if (!r) return {};
    EXPECT_EQ(r->status, status) << path << ": " << r->body.substr(0, 200);
    EXPECT_EQ(r->get_header_value("Access-Control-Allow-Origin"), "*") << path;
    return json::parse(r->body, nullptr, false);
  }

  static test::TempDir* dir_;
  static std::string db_path_;
  static Database* db_;
  static IndexedSource* source_;
  static std::string fbm_path_;  // served as "fbm257" (a bare path: named by its stem)
  static Database* fbm_;
  static IndexedSource* fbm_source_;
  static std::string mesh_path_;  // "bunny": a 3-D mesh
  static Database* mesh_;
  static IndexedSource* mesh_source_;
  static test::ServerProcess* server_;
};

test::TempDir* Serve::dir_ = nullptr;
std::string Serve::db_path_;
Database* Serve::db_ = nullptr;
IndexedSource* Serve::source_ = nullptr;
std::string Serve::fbm_path_;
Database* Serve::fbm_ = nullptr;
IndexedSource* Serve::fbm_source_ = nullptr;
std::string Serve::mesh_path_;
Database* Serve::mesh_ = nullptr;
IndexedSource* Serve::mesh_source_ = nullptr;
test::ServerProcess* Serve::server_ = nullptr;

// A camera over a database in grid units (fbm257): eye and target as fractions of its bounds.
struct View {
  Vec3 eye, target;
  double px;
  std::string query() const {
    std::ostringstream os;
    os.precision(17);
    os << "eye=" << eye.x << ',' << eye.y << ',' << eye.z << "&target=" << target.x << ','
       << target.y << ',' << target.z << "&fov=50&viewport=800x600&px=" << px;
    return os.str();
  }
  std::string flags() const {
    std::ostringstream os;
    os.precision(17);
    os << "--eye=" << eye.x << ',' << eye.y << ',' << eye.z << " --target=" << target.x << ','
       << target.y << ',' << target.z << " --fov 50 --viewport 800x600 --pixel-error " << px;
    return os.str();
  }
  Rcf rcf(const CrmrInfo& info) const {
    RcfSpec s;
    s.camera = test::test_camera(eye, target);
    s.pixel_error = px;
    validate(s);
    return make_rcf(s, info, nullptr);
  }
};

// A fly-by: low over one corner looking across, moving, then farther and coarser.
std::vector<View> views(const Box3& b) {
  const auto at = [&](double fx, double fy, double fz) {
    return Vec3{b.lo.x + fx * (b.hi.x - b.lo.x), b.lo.y + fy * (b.hi.y - b.lo.y),
                b.lo.z + fz * (b.hi.z - b.lo.z)};
  };
  return {{at(-0.2, -0.2, 1.5), at(0.5, 0.5, 0.3), 2.0},
          {at(0.1, -0.1, 1.2), at(0.6, 0.7, 0.3), 1.0},
          {at(0.9, 0.1, 1.2), at(0.3, 0.6, 0.3), 1.0},
          {at(-0.5, -0.5, 3.0), at(0.5, 0.5, 0.3), 4.0}};
}

TEST_P(Serve, DatabasesAndInfo) {
  const json list = get_json("/v1/databases");
  EXPECT_EQ(
      list,
      json::parse(
          R"([{"name":"j","kind":"terrain"},{"name":"fbm257","kind":"terrain"},{"name":"bunny","kind":"mesh"}])"));
  const json info = get_json("/v1/j/info");
  const Box3& b = db_->info().bounds;
  EXPECT_EQ(info["kind"], "terrain");
  EXPECT_EQ(info["path"], "j") << "the server's file path must not leak";
  EXPECT_DOUBLE_EQ(info["origin"][0].get<double>(), (b.lo.x + b.hi.x) / 2);
  EXPECT_DOUBLE_EQ(info["bounds"]["max"][2].get<double>(), b.hi.z);
  EXPECT_TRUE(info["georef"]["geographic"].get<bool>());
  EXPECT_EQ(info["meta"], json::parse(db_->meta_json()));
  EXPECT_EQ(info["dag_depth"], info["meta"]["counts"]["dag_depth"]);
}

TEST_P(Serve, ExtractGlbIsTheCliGlb) {
  const View v = views(fbm_->info().bounds)[1];
  struct Case {
    std::string query, flags;
  };
  const Case cases[] = {{v.query(), v.flags()},
                        {v.query() + "&max_triangles=300", v.flags() + " --max-triangles 300"},
                        {"floor=0.8", "--floor 0.8"}};
  for (const Case& c : cases) {
    const std::string out = dir_->file("cli.glb");
    const auto r = test::run_command(std::string(SMRDB_BIN) + " extract " + fbm_path_ + " -o " +
                                     out + " -q " + c.flags);
    ASSERT_EQ(r.code, 0) << r.out;
    const auto res = get("/v1/fbm257/extract?" + c.query);
    ASSERT_TRUE(res);
    ASSERT_EQ(res->status, 200) << res->body;
    EXPECT_EQ(res->get_header_value("Content-Type"), "model/gltf-binary");
    EXPECT_EQ(res->body, test::read_file(out)) << c.query;
    EXPECT_GT(std::stoi(res->get_header_value("X-Smrdb-Triangles")), 100) << c.query;
  }
  // The server's cap: a mesh beyond it is 413 unless the request gives a budget.
  // fbm257's finest mesh has 73363 triangles.
  const auto budgeted = get("/v1/fbm257/extract?floor=1&max_triangles=50000");
  ASSERT_TRUE(budgeted);
  ASSERT_EQ(budgeted->status, 200);
  EXPECT_EQ(budgeted->get_header_value("X-Smrdb-Complete"), "false");
  EXPECT_LE(std::stoi(budgeted->get_header_value("X-Smrdb-Triangles")), 50000);
  const json big = get_json("/v1/fbm257/extract?floor=1", 413);
  EXPECT_NE(big["error"].get<std::string>().find("max_triangles"), std::string::npos);
}

TEST_P(Serve, TilesAreTheStaticPyramidsBytes) {
  const std::string out = dir_->file("pyramid");
  const tiles::PyramidReport report = tiles::write_pyramid(*db_, out, {});
  const tiles::TilingScheme scheme = tiles::TilingScheme::for_terrain(db_->info());
  std::uint64_t compared = 0;
  for (int z = 0; z <= report.max_zoom; ++z) {
    const tiles::TileRange range = scheme.covering(z);
    for (std::int64_t y = range.y0; y <= range.y1; ++y) {
      for (std::int64_t x = range.x0; x <= range.x1; ++x) {
        const std::string rel =
            std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y) + ".terrain";
        const auto res = get("/v1/j/tiles/" + rel);
        ASSERT_TRUE(res);
        if (!std::filesystem::exists(out + "/" + rel)) {
          // Listed in layer.json but holding only no-data: a valid tile with no vertex (the
          // 88-byte header, then a vertex count of 0), not a 404 a client would count as failed.
          ASSERT_EQ(res->status, 200) << rel;
          ASSERT_GE(res->body.size(), 92u) << rel;
          std::uint32_t vertices = 1;
          std::memcpy(&vertices, res->body.data() + 88, 4);
          EXPECT_EQ(vertices, 0u) << rel;
          continue;
        }
        ASSERT_EQ(res->status, 200) << rel << ": " << res->body;
        EXPECT_EQ(res->body, test::read_file(out + "/" + rel)) << rel;
        EXPECT_EQ(res->get_header_value("Content-Type"), "application/vnd.quantized-mesh");
        // Where layer.json's relative template leads a standard client: the same bytes.
        const auto beside = get("/v1/j/" + rel);
        ASSERT_TRUE(beside);
        EXPECT_EQ(beside->status, 200) << rel;
        EXPECT_EQ(beside->body, res->body) << rel;
        ++compared;
      }
    }
  }
  EXPECT_EQ(compared, report.tiles);
  // layer.json: every covered tile was written here, so the bytes are the pyramid's.
  const auto layer = get("/v1/j/layer.json");
  ASSERT_TRUE(layer);
  EXPECT_EQ(layer->body, test::read_file(out + "/layer.json"));
  // ETag and 304; gzip on the wire (the client decompressed the bodies above).
  std::string largest;
  for (const auto& e : std::filesystem::recursive_directory_iterator(out))
    if (e.path().extension() == ".terrain" &&
        (largest.empty() || e.file_size() > std::filesystem::file_size(out + "/" + largest)))
      largest = std::filesystem::relative(e.path(), out).string();
  const auto tile = get("/v1/j/tiles/" + largest, {{"Accept-Encoding", "gzip"}});
  ASSERT_TRUE(tile);
  EXPECT_EQ(tile->body, test::read_file(out + "/" + largest));
  const std::string etag = tile->get_header_value("ETag");
  ASSERT_FALSE(etag.empty());
  EXPECT_EQ(tile->get_header_value("Content-Encoding"), "gzip");
  const auto again = get("/v1/j/tiles/" + largest, {{"If-None-Match", etag}});
  ASSERT_TRUE(again);
  EXPECT_EQ(again->status, 304);
  EXPECT_TRUE(again->body.empty());
  const auto layer304 =
      get("/v1/j/layer.json", {{"If-None-Match", layer->get_header_value("ETag")}});
  ASSERT_TRUE(layer304);
  EXPECT_EQ(layer304->status, 304);
  EXPECT_EQ(get_json("/v1/j/tiles/30/0/0.terrain", 400)["error"].get<std::string>().find("'z'"),
            std::string("parameter ").size());
  get_json("/v1/j/tiles/" + std::to_string(report.max_zoom + 1) + "/0/0.terrain", 404);
  get_json("/v1/j/tiles/0/99/0.terrain", 404);
}

TEST_P(Serve, QueriesAnswerAsTheLibrary) {
  const query::ElevationQuery eq(*source_);
  for (const Vec2 p : {Vec2{-84.3, 36.6}, Vec2{-84.2, 36.5}, Vec2{-84.12345, 36.7}}) {
    std::ostringstream q;
    q.precision(17);
    q << "/v1/j/query/elevation?x=" << p.x << "&y=" << p.y;
    const json j = get_json(q.str());
    const query::ElevationAnswer a = eq.at(p, query::Accuracy::finest());
    ASSERT_TRUE(a.has_data);
    EXPECT_EQ(j["z"].get<double>(), a.z);
    EXPECT_EQ(j["error_bound"].get<double>(), a.error_bound);
  }
  EXPECT_TRUE(get_json("/v1/j/query/elevation?x=0&y=0")["z"].is_null());

  const std::vector<Vec2> line{{-84.3, 36.5}, {-84.2, 36.6}};
  const query::ProfileResult pr = query::profile(*source_, line, query::Accuracy::finest());
  const json pj = get_json("/v1/j/query/profile?from=-84.3,36.5&to=-84.2,36.6");
  ASSERT_EQ(pj["points"].size(), pr.points.size());
  for (std::size_t i = 0; i < pr.points.size(); ++i) {
    EXPECT_EQ(pj["points"][i][0].get<double>(), pr.points[i].distance);
    EXPECT_EQ(pj["points"][i][3].get<double>(), pr.points[i].p.z);
  }
  const json ps = get_json("/v1/j/query/profile?from=-84.3,36.5&to=-84.2,36.6&samples=7");
  ASSERT_EQ(ps["points"].size(), 7u);
  EXPECT_EQ(ps["points"][0][3].get<double>(), pr.points.front().p.z);
  EXPECT_NEAR(ps["points"][6][3].get<double>(), pr.points.back().p.z, 1e-6);

  for (const auto& [a, b] : {std::pair{Vec3{-84.3, 36.5, 2000}, Vec3{-84.2, 36.6, 300}},
                             std::pair{Vec3{-84.3, 36.5, 3000}, Vec3{-84.2, 36.6, 3000}}}) {
    std::ostringstream q;
    q.precision(17);
    q << "/v1/j/query/los?from=" << a.x << ',' << a.y << ',' << a.z << "&to=" << b.x << ',' << b.y
      << ',' << b.z;
    const json j = get_json(q.str());
    const query::SightAnswer s = query::line_of_sight(*source_, a, b, query::Accuracy::finest());
    EXPECT_EQ(j["visible"].get<bool>(), s.sight == query::Sight::kVisible);
    if (s.sight == query::Sight::kBlocked) {
      EXPECT_EQ(j["blocked_at"], json::array({s.blocked_at.x, s.blocked_at.y, s.blocked_at.z}));
    } else {
      EXPECT_TRUE(j["blocked_at"].is_null());
    }
  }

  query::ContourOptions o;
  o.interval = 100.0;
  std::ostringstream geo;
  query::write_geojson(geo, query::contours(*source_, o), db_->info().georef);
  const auto cj = get("/v1/j/query/contours?interval=100");
  ASSERT_TRUE(cj);
  EXPECT_EQ(cj->body, geo.str());
  const json boxed = get_json("/v1/j/query/contours?interval=100&bbox=-84.3,36.5,-84.25,36.55");
  ASSERT_FALSE(boxed["features"].empty());
  for (const auto& f : boxed["features"])
    for (const auto& p : f["geometry"]["coordinates"])
      EXPECT_TRUE(p[0] >= -84.3 && p[0] <= -84.25 && p[1] >= 36.5 && p[1] <= 36.55);
}

// The client of docs/serve.md: a map key -> triangle, frames applied in order.
struct Client {
  std::map<std::array<std::uint32_t, 3>, test::FrameTriangle> held;
};

double area(const std::array<float, 3>& a, const std::array<float, 3>& b,
            const std::array<float, 3>& c, bool flat) {
  const double ux = b[0] - a[0], uy = b[1] - a[1], uz = flat ? 0 : b[2] - a[2];
  const double vx = c[0] - a[0], vy = c[1] - a[1], vz = flat ? 0 : c[2] - a[2];
  const double x = uy * vz - uz * vy, y = uz * vx - ux * vz, z = ux * vy - uy * vx;
  return 0.5 * std::sqrt(x * x + y * y + z * z);
}

double area(const test::FrameTriangle& t, bool flat) {
  const auto& p = t.pos;
  return area({p[0], p[1], p[2]}, {p[3], p[4], p[5]}, {p[6], p[7], p[8]}, flat);
}

// The morph's area at t = 0 or 1 (pieces with data there; `flat`: all pieces, in x-y).
double morph_area(const test::DecodedFrame& f, bool end, bool flat) {
  double sum = 0;
  for (std::size_t i = 0; i < f.m_tris.size(); ++i) {
    if (!flat && (f.m_flags[i] & (end ? 2 : 1)) != 0) continue;
    const auto& v = end ? f.m_end : f.m_start;
    const auto& t = f.m_tris[i];
    sum += area(v[t[0]], v[t[1]], v[t[2]], flat);
  }
  return sum;
}

// A session on database `name` along `path`, its frames applied by a Client: after each update the
// client's triangles are the fresh extraction's, and the morph covers what changed. `terrain`: the
// x-y areas are checked too (a terrain's morph keeps x-y; a 3-D morph moves vertices).
void fly_session(int port, const std::string& name, const Database& db, const IndexedSource& src,
                 const std::vector<View>& path, bool terrain) {
  httplib::Client c("127.0.0.1", port);
  c.set_read_timeout(20, 0);
  const auto created = c.Post(("/v1/" + name + "/session").c_str());
  ASSERT_TRUE(created);
  ASSERT_EQ(created->status, 200) << created->body;
  const test::DecodedFrame f0 = test::decode_frame(created->body);
  const std::string id = f0.header["session"];
  EXPECT_EQ(f0.header["frame"], 0);
  EXPECT_TRUE(f0.out.empty());
  EXPECT_TRUE(f0.m_tris.empty());
  Client client;
  for (const auto& t : f0.in) client.held[t.key] = t;
  EXPECT_EQ(client.held.size(), f0.in.size());
  const Vec3 origin = (db.info().bounds.lo + db.info().bounds.hi) * 0.5;
  for (std::size_t k = 0; k < path.size(); ++k) {
    const View& v = path[k];
    const auto res =
        c.Get(("/v1/" + name + "/session/" + id + "/update?" + v.query() + "&max_ms=1400").c_str());
    ASSERT_TRUE(res);
    ASSERT_EQ(res->status, 200) << res->body;
    const test::DecodedFrame f = test::decode_frame(res->body);
    EXPECT_EQ(f.header["frame"], k + 1);
    for (const char* field :
         {"coarsenings", "refinings", "pending_coarsenings", "pending_refinings", "complete", "x",
          "triangles", "triangles_in", "triangles_out", "ops_tested", "morph_triangles", "seconds",
          "pages_read"})
      EXPECT_TRUE(f.header["stats"].contains(field)) << field;
    EXPECT_EQ(f.header["stats"]["triangles_in"], f.in.size());
    EXPECT_EQ(f.header["stats"]["triangles_out"], f.out.size());
    double out_flat = 0, out_area = 0, in_flat = 0, in_area = 0;
    for (const auto& key : f.out) {
      const auto it = client.held.find(key);
      ASSERT_NE(it, client.held.end()) << "frame " << k + 1 << " removes a triangle not held";
      out_flat += area(it->second, true);
      if ((it->second.flags & 1) == 0) out_area += area(it->second, false);
      client.held.erase(it);
    }
    for (const auto& t : f.in) {
      EXPECT_TRUE(client.held.emplace(t.key, t).second) << "frame adds a triangle already held";
      in_flat += area(t, true);
      if ((t.flags & 1) == 0) in_area += area(t, false);
    }
    // The morph covers the region out covered (t = 0) and becomes the in triangles (t = 1).
    if (terrain) {
      EXPECT_NEAR(morph_area(f, false, true), out_flat, 1e-6 * out_flat + 1e-12);
      EXPECT_NEAR(morph_area(f, true, true), in_flat, 1e-6 * in_flat + 1e-12);
    }
    EXPECT_NEAR(morph_area(f, false, false), out_area, 1e-4 * out_area + 1e-9);
    EXPECT_NEAR(morph_area(f, true, false), in_area, 1e-4 * in_area + 1e-9);
    if (!f.out.empty()) {
      EXPECT_FALSE(f.m_tris.empty());
    }
    // The client's mesh is the fresh extraction's, key for key and corner for corner.
    ASSERT_TRUE(f.header["stats"]["complete"].get<bool>());
    const Extraction e = extract_minimal_surface(src, v.rcf(db.info()), {});
    EXPECT_GT(e.triangles.size(), 100u);
    ASSERT_EQ(client.held.size(), e.triangles.size()) << "frame " << k + 1;
    for (const TriRef& t : e.triangles) {
      const std::array<std::uint32_t, 3> key{std::uint32_t(t.op.value & 0xffffffffu),
                                             std::uint32_t(t.op.value >> 32), t.index};
      const auto it = client.held.find(key);
      ASSERT_NE(it, client.held.end());
      const OpRef op = db.op(t.op);
      const FragmentTriangle& ft = op->fragment[t.index];
      for (int corner = 0; corner < 3; ++corner) {
        const Vec3 p = op->position(ft, corner) - origin;
        EXPECT_EQ(it->second.pos[3 * corner], float(p.x));
        EXPECT_EQ(it->second.pos[3 * corner + 2], float(p.z));
      }
      EXPECT_EQ(it->second.flags & 1, ft.is_void() ? 1 : 0);
    }
  }
  const auto del = c.Delete(("/v1/" + name + "/session/" + id).c_str());
  ASSERT_TRUE(del);
  EXPECT_EQ(del->status, 200);
  const auto gone =
      c.Get(("/v1/" + name + "/session/" + id + "/update?" + path[0].query()).c_str());
  ASSERT_TRUE(gone);
  EXPECT_EQ(gone->status, 404);
}

TEST_P(Serve, SessionFramesRebuildTheMesh) {
  fly_session(server_->port(), "fbm257", *fbm_, *fbm_source_, views(fbm_->info().bounds), true);
}

TEST_P(Serve, MeshDatabase) {
  const json info = get_json("/v1/bunny/info");
  EXPECT_EQ(info["kind"], "mesh");
  EXPECT_FALSE(info.contains("tiles"));
  get_json("/v1/bunny/layer.json", 404);
  get_json("/v1/bunny/tiles/0/0/0.terrain", 404);
  get_json("/v1/bunny/query/elevation?x=0&y=0", 400);
  const std::string out = dir_->file("bunny.glb");
  const auto r = test::run_command(std::string(SMRDB_BIN) + " extract " + mesh_path_ + " -o " +
                                   out + " -q --floor 0.6");
  ASSERT_EQ(r.code, 0) << r.out;
  const auto glb = get("/v1/bunny/extract?floor=0.6");
  ASSERT_TRUE(glb);
  ASSERT_EQ(glb->status, 200) << glb->body.substr(0, 200);
  EXPECT_EQ(glb->body, test::read_file(out));
  // A 3-D session: cameras around the model at 3 and 1.5 radii.
  const Box3& b = mesh_->info().bounds;
  const Vec3 c = (b.lo + b.hi) * 0.5;
  const double r3 = 1.5 * std::max({b.hi.x - b.lo.x, b.hi.y - b.lo.y, b.hi.z - b.lo.z});
  const std::vector<View> path = {{c + Vec3{r3, -r3, 0.5 * r3}, c, 2.0},
                                  {c + Vec3{0.5 * r3, -0.5 * r3, 0.3 * r3}, c, 1.0},
                                  {c + Vec3{-0.5 * r3, -0.5 * r3, 0.3 * r3}, c, 1.0},
                                  {c + Vec3{-2 * r3, 2 * r3, r3}, c, 4.0}};
  fly_session(server_->port(), "bunny", *mesh_, *mesh_source_, path, false);
}

TEST_P(Serve, SessionTableIsBounded) {
  httplib::Client c("127.0.0.1", server_->port());
  std::vector<std::string> ids;
  for (int i = 0; i < 3; ++i) {
    const auto r = c.Post("/v1/j/session");
    ASSERT_TRUE(r);
    ASSERT_EQ(r->status, 200);
    ids.push_back(test::decode_frame(r->body).header["session"]);
  }
  const auto full = c.Post("/v1/j/session");
  ASSERT_TRUE(full);
  EXPECT_EQ(full->status, 503);
  EXPECT_TRUE(json::parse(full->body).contains("error"));
  for (const auto& id : ids) EXPECT_EQ(c.Delete(("/v1/j/session/" + id).c_str())->status, 200);
  EXPECT_EQ(c.Delete(("/v1/j/session/" + ids[0]).c_str())->status, 404);
}

TEST_P(Serve, IdleSessionsExpire) {
  httplib::Client c("127.0.0.1", server_->port());
  const auto r = c.Post("/v1/fbm257/session");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200);
  const std::string id = test::decode_frame(r->body).header["session"];
  const std::string update =
      "/v1/fbm257/session/" + id + "/update?" + views(fbm_->info().bounds)[3].query();
  EXPECT_EQ(get(update)->status, 200);  // touched: idle from now
  std::this_thread::sleep_for(std::chrono::milliseconds(4300));
  get_json(update, 404);
}

TEST_P(Serve, BadParametersAre400NamingTheParameter) {
  const std::string cam = "eye=-84.3,36.4,3000&target=-84.25,36.6,500";
  const std::pair<std::string, std::string> cases[] = {
      {"/v1/j/extract?eye=nan,36.4,3000&target=-84.25,36.6,500", "eye"},
      {"/v1/j/extract?eye=inf,36.4,3000&target=-84.25,36.6,500", "eye"},
      {"/v1/j/extract?eye=1e400,36.4,3000&target=-84.25,36.6,500", "eye"},
      {"/v1/j/extract?eye=-84.3,36.4&target=-84.25,36.6,500", "eye"},
      {"/v1/j/extract?" + cam + "&viewport=100000x100000", "viewport"},
      {"/v1/j/extract?" + cam + "&viewport=-5x10", "viewport"},
      {"/v1/j/extract?" + cam + "&px=0", "px"},
      {"/v1/j/extract?" + cam + "&px=-1", "px"},
      {"/v1/j/extract?" + cam + "&fov=180", "fov"},
      {"/v1/j/extract?" + cam + "&fov=0", "fov"},
      {"/v1/j/extract?" + cam + "&max_triangles=-3", "max_triangles"},
      {"/v1/j/extract?" + cam + "&max_triangles=99999999999", "max_triangles"},
      {"/v1/j/extract?target=-84.25,36.6,500", "eye"},
      {"/v1/j/extract?floor=2", "floor"},
      {"/v1/j/extract?" + cam + "&px=1&px=2", "px"},
      {"/v1/j/extract?" + cam + "&bogus=1", "bogus"},
      {"/v1/j/query/elevation?x=1", "y"},
      {"/v1/j/query/elevation?x=0x10&y=1", "x"},
      {"/v1/j/query/profile?from=1,2&to=3,4&samples=1", "samples"},
      {"/v1/j/query/contours?interval=0", "interval"},
      {"/v1/j/query/contours?interval=0.001", "interval"},
      {"/v1/j/query/contours?interval=100&bbox=1,1,0,0", "bbox"},
      {"/v1/j/tiles/-1/0/0.terrain", "z"},
      {"/v1/j/tiles/0/x/0.terrain", "x"}};
  for (const auto& [path, name] : cases) {
    const json j = get_json(path, 400);
    ASSERT_TRUE(j.contains("error")) << path;
    EXPECT_NE(j["error"].get<std::string>().find("'" + name + "'"), std::string::npos)
        << path << " -> " << j.dump();
  }
  // The camera's own checks (eye on the target) are 400 too.
  get_json("/v1/j/extract?eye=1,1,1&target=1,1,1", 400);
}

TEST_P(Serve, UnknownNamesAndPathTricksAre404) {
  for (const std::string path :
       {"/v1/nosuchdb/info", "/v1/j/nosuchroute", "/v1/j/query/nosuch?x=1", "/v2/j/info",
        "/v1/j/session/0123/update?eye=1,1,1&target=2,2,2", "/v1/../../etc/passwd",
        "/v1/j/%2e%2e/%2e%2e/etc/passwd", "/%2e%2e/%2e%2e/etc/passwd", "/../tools/serve_cmd.cpp",
        "/assets/../../jacksboro.smrdb", "/jacksboro.smrdb", "/v1/j/tiles/0/0/0.terrain/.."}) {
    const auto r = get(path);
    ASSERT_TRUE(r) << path;
    EXPECT_TRUE(r->status == 404 || r->status == 400) << path << " -> " << r->status;
    EXPECT_EQ(r->body.find("xxh3"), std::string::npos);
  }
  // The viewer: enumerated files only, / redirects to /index.html.
  EXPECT_EQ(get("/index.html")->body, "<html>viewer</html>");
  EXPECT_EQ(get("/assets/app.js")->body, "console.log(1);");
  httplib::Client c("127.0.0.1", server_->port());
  const auto root = c.Get("/");
  ASSERT_TRUE(root);
  EXPECT_EQ(root->status, 302);
  EXPECT_EQ(root->get_header_value("Location"), "/index.html");
}

TEST_P(Serve, MalformedHttpDoesNotCrashTheServer) {
  const std::string requests[] = {
      "GARBAGE\r\n\r\n",
      "GET\r\n\r\n",
      "GET /v1/databases HTTP/9.9\r\n\r\n",
      "GET /v1/databases HTTP/1.1\r\nContent-Length: -5\r\n\r\n",
      "POST /v1/j/session HTTP/1.1\r\nContent-Length: 99999999999999999999\r\n\r\n",
      "POST /v1/j/session HTTP/1.1\r\nContent-Length: 100000\r\n\r\n" + std::string(5000, 'x'),
      "GET /v1/databases HTTP/1.1\r\nHost: x\r\n" + std::string(20000, 'h') + "\r\n\r\n",
      "GET /" + std::string(10000, 'a') + " HTTP/1.1\r\n\r\n",
      "GET /v1/j/query/elevation?x=%zz&y=%00 HTTP/1.1\r\n\r\n",
      std::string("\0\0\0\xff\xfe GET / HTTP/1.1\r\n\r\n", 24),
      "GET /v1/databases HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n"};
  for (const std::string& req : requests) {
    test::RawSocket s(server_->port());
    s.send(req);
    const std::string reply = s.read_all(3 * kTimeoutMs, true);
    EXPECT_FALSE(reply.empty()) << "no answer to " << req.substr(0, 60);
    if (!reply.empty()) {
      EXPECT_EQ(reply.rfind("HTTP/1.1 ", 0), 0u) << reply.substr(0, 80);
      EXPECT_EQ(reply.find("HTTP/1.1 200"), std::string::npos) << req.substr(0, 60);
    }
    ASSERT_TRUE(server_->alive()) << "after " << req.substr(0, 60);
  }
  const auto overlong = get("/v1/j/extract?floor=" + std::string(9000, '1'));
  ASSERT_TRUE(overlong);
  EXPECT_GE(overlong->status, 400);
  EXPECT_EQ(get_json("/v1/databases").size(), 3u);
}

TEST_P(Serve, SlowClientIsCutOff) {
  // A request's headers must arrive within --timeout-ms of its first byte: a byte every 200 ms
  // (slowloris) is disconnected before the request is complete.
  test::RawSocket s(server_->port());
  const std::string req =
      "GET /v1/databases HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Pad: " + std::string(100, 'p') +
      "\r\n\r\n";
  const auto t0 = std::chrono::steady_clock::now();
  std::size_t sent = 0;
  while (sent < req.size() && s.send(req.substr(sent, 1))) {
    ++sent;
    if (s.closed_within(200)) break;
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(sent, req.size()) << "the whole trickled request was read";
  EXPECT_LT(seconds, kTimeoutMs / 1000.0 + 1.5);
  EXPECT_GT(seconds, kTimeoutMs / 1000.0 - 0.5);
}

TEST_P(Serve, ParallelConnectionsAreBounded) {
  // Connections that send nothing wait in the acceptor, holding no worker: real requests are
  // answered meanwhile.
  std::vector<std::unique_ptr<test::RawSocket>> idle;
  for (int i = 0; i < 60; ++i) idle.push_back(std::make_unique<test::RawSocket>(server_->port()));
  std::vector<std::thread> threads;
  std::atomic<int> ok{0}, busy{0};
  const auto fetch_tiles = [&](int n) {
    for (int i = 0; i < n; ++i)
      threads.emplace_back([&] {
        const auto r = get("/v1/j/tiles/1/1/1.terrain");
        if (r && r->status == 200) ++ok;
        if (r && r->status == 503) ++busy;
      });
    for (auto& t : threads) t.join();
    threads.clear();
  };
  fetch_tiles(8);
  EXPECT_EQ(ok, 8) << "idle connections must not hold the 4 workers";
  // --max-connections 100 of them at most: beyond, 503 at once.
  for (int i = 0; i < 100; ++i) idle.push_back(std::make_unique<test::RawSocket>(server_->port()));
  int rejected = 0;
  for (auto& s : idle)
    if (s->read_all(20).rfind("HTTP/1.1 503", 0) == 0) ++rejected;
  // 60 at least when none of the first 60 reached its deadline meanwhile (a slow machine: fewer).
  EXPECT_GE(rejected, 30);
  EXPECT_LE(rejected, 160 - 100 + 2);
  // The held ones are closed at --timeout-ms.
  EXPECT_TRUE(idle.front()->closed_within(kTimeoutMs + 1000));
  idle.clear();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  // 32 concurrent requests on 4 threads and a queue of 8: all answered, 200 or 503.
  ok = 0;
  fetch_tiles(32);
  EXPECT_EQ(ok + busy, 32);
  EXPECT_GE(ok, 4);
  EXPECT_TRUE(server_->alive());
}

INSTANTIATE_TEST_SUITE_P(Loopback, Serve, ::testing::Values(std::string("loopback")),
                         [](const auto& p) { return p.param; });

}  // namespace
}  // namespace smr
