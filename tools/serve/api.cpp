// smrdb serve's routes (api.h): databases, info, extract, tiles and sessions; the queries are
// in api_query.cpp.
#include "tools/serve/api.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <optional>

#include "base/error.h"
#include "smr/extract/extract.h"
#include "smr/extract/session.h"
#include "smr/query/level_cut.h"
#include "smr/rcf/spec.h"
#include "smr/tiles/pyramid.h"
#include "tools/report_json.h"
#include "tools/serve/api_db.h"
#include "tools/serve/frame.h"
#include "tools/serve/params.h"

namespace smr::serve {

namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

Response json_response(const json& j) {
  Response r;
  r.body = j.dump();
  return r;
}

std::vector<std::string> split_path(const std::string& path) {
  std::vector<std::string> parts;
  std::size_t start = 1;
  while (start <= path.size()) {
    const std::size_t slash = path.find('/', start);
    parts.push_back(path.substr(start, slash == std::string::npos ? slash : slash - start));
    if (slash == std::string::npos) break;
    start = slash + 1;
  }
  return parts;
}

bool etag_matches(const std::string& if_none_match, const std::string& etag) {
  if (if_none_match.empty()) return false;
  if (if_none_match.find('*') != std::string::npos) return true;
  // The tag without its quotes: "h" matches "h-gz", the same bytes gzip-encoded (http.cpp).
  return if_none_match.find(etag.substr(1, etag.size() - 2)) != std::string::npos;
}

Response cacheable(std::string body, const std::string& type, const std::string& etag,
                   const Request& request) {
  Response r;
  r.content_type = type;
  r.etag = etag;
  r.headers.push_back({"Cache-Control", "public, max-age=3600"});
  if (etag_matches(request.if_none_match, etag)) {
    r.status = 304;
    return r;
  }
  r.body = std::move(body);
  return r;
}

// The camera and pixel tolerance of an extract or session update, or a floor.
RcfSpec camera_spec(const Params& p, bool allow_floor) {
  RcfSpec s;
  const bool camera = p.has("eye") || p.has("target");
  if (camera) {
    Camera cam;
    cam.eye = p.vec3("eye");
    cam.target = p.vec3("target");
    if (p.has("up")) cam.up = p.vec3("up");
    cam.fov_y_deg = p.number("fov", 0.0, 179.0, 60.0, true);
    std::tie(cam.viewport_w, cam.viewport_h) = p.viewport("viewport", {1024, 768});
    s.camera = cam;
    s.pixel_error = p.number("px", 0.1, 1000.0, 1.0);
  } else {
    for (const char* name : {"up", "fov", "viewport", "px"})
      if (p.has(name))
        fail(400, std::string("parameter '") + name + "' needs a camera: give eye and target");
  }
  if (allow_floor && p.has("floor")) s.floor = p.number("floor", 0.0, 1.0);
  if (!camera && !s.floor)
    fail(400, allow_floor ? "give a camera (parameters 'eye' and 'target') or 'floor'"
                          : "parameters 'eye' and 'target' are missing: expected x,y,z each");
  try {
    validate(s);
  } catch (const Error& e) {
    fail(400, e.what());
  }
  return s;
}

// The frame header's "stats": FrameStats as the CLI reports it (report_json.h), plus the
// contract's "seconds" and the update's "pages_read".
json frame_stats(const FrameStats& stats, std::uint64_t pages_read) {
  json j = stats;
  j["seconds"] = stats.seconds;
  j["pages_read"] = pages_read;
  return j;
}

}  // namespace

Response error_response(int status, const std::string& message) {
  Response r;
  r.status = status;
  r.body = json{{"error", message}}.dump();
  return r;
}

std::string default_name(const std::string& path) {
  return std::filesystem::path(path).stem().string();
}

bool valid_name(const std::string& name) {
  if (name.empty() || name.size() > 64) return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
           c == '-';
  });
}

Api::Api(const std::vector<std::pair<std::string, std::string>>& databases, std::size_t cache_bytes,
         const ApiOptions& options, GlbWriter glb)
    : options_(options),
      glb_(std::move(glb)),
      sessions_(options.max_sessions, options.session_idle),
      tile_cache_(options.tile_cache_bytes) {
  if (databases.empty()) throw_input("serve: give at least one database (NAME=PATH)");
  for (const auto& [name, path] : databases) {
    if (!valid_name(name))
      throw_input("serve: database name '" + name + "' (for " + path +
                  ") must be 1-64 characters of A-Z a-z 0-9 _ -");
    for (const auto& d : dbs_)
      if (d->name == name) throw_input("serve: database name '" + name + "' is given twice");
    dbs_.push_back(std::make_unique<Db>(name, path, cache_bytes));
  }
}

Api::~Api() = default;

Response Api::handle(const Request& request) {
  try {
    return route(request);
  } catch (const HttpError& e) {
    return error_response(e.status(), e.what());
  } catch (const Error& e) {
    // The library's own checks (a point outside the domain, a bad camera): the request's fault.
    if (e.kind() == ErrorKind::kInvalidInput) return error_response(400, e.what());
    return error_response(500, e.what());
  } catch (const std::bad_alloc&) {
    return error_response(503, "out of memory");
  } catch (const std::exception& e) {
    return error_response(500, std::string("internal error: ") + e.what());
  }
}

Response Api::route(const Request& request) {
  const std::vector<std::string> parts = split_path(request.path);
  const std::string& m = request.method;
  if (parts.size() < 2 || parts[0] != "v1") fail(404, "no such route: " + request.path);
  if (parts.size() == 2 && parts[1] == "databases" && m == "GET") return databases();
  Db* db = nullptr;
  for (const auto& d : dbs_)
    if (d->name == parts[1]) db = d.get();
  if (db == nullptr) fail(404, "no database named '" + parts[1].substr(0, 64) + "'");
  const std::size_t n = parts.size();
  const std::string what = n >= 3 ? parts[2] : "";
  if (m == "GET" && n == 3 && what == "info") return info(*db);
  if (m == "GET" && n == 3 && what == "extract") return extract(*db, request);
  if (m == "GET" && n == 3 && what == "layer.json") return layer(*db, request);
  if (m == "GET" && n == 6 && what == "tiles") return tile(*db, parts, request);
  if (m == "GET" && n == 4 && what == "query") return query(*db, parts[3], request);
  if (m == "POST" && n == 3 && what == "session") return session_create(*db);
  if (m == "GET" && n == 5 && what == "session" && parts[4] == "update")
    return session_update(*db, parts[3], request);
  if (m == "DELETE" && n == 4 && what == "session") return session_delete(*db, parts[3]);
  // layer.json's template is relative, {z}/{x}/{y}.terrain (as `smrdb tiles` writes it beside its
  // tiles), so a standard client such as CesiumJS asks for /v1/{db}/{z}/{x}/{y}.terrain.
  if (m == "GET" && n == 5 && parts[4].ends_with(".terrain"))
    return tile(*db, {parts[0], parts[1], "tiles", parts[2], parts[3], parts[4]}, request);
  fail(404, "no such route: " + m + " " + request.path.substr(0, 200));
}

Response Api::databases() const {
  json list = json::array();
  for (const auto& d : dbs_)
    list.push_back({{"name", d->name}, {"kind", d->terrain ? "terrain" : "mesh"}});
  return json_response(list);
}

Response Api::info(const Db& db) const {
  json out = db.info;
  out["limits"] = {{"max_triangles", options_.max_triangles},
                   {"timeout_ms", options_.timeout_ms},
                   {"max_sessions", options_.max_sessions}};
  return json_response(out);
}

namespace {
std::string too_many(std::uint64_t cap) {
  return "the mesh would pass " + std::to_string(cap) +
         " triangles (the server's --max-triangles): give max_triangles for a budgeted mesh, or a "
         "coarser px/floor";
}
}  // namespace

Response Api::extract(const Db& db, const Request& request) {
  const auto t0 = Clock::now();
  const Params p(request.params);
  p.only({"eye", "target", "up", "fov", "viewport", "px", "floor", "max_triangles"});
  const RcfSpec spec = camera_spec(p, true);
  const bool user_cap = p.has("max_triangles");
  const auto cap = std::uint64_t(p.integer("max_triangles", 1, std::int64_t(options_.max_triangles),
                                           std::int64_t(options_.max_triangles)));
  const Rcf rcf = make_rcf(spec, db.db->info(), nullptr);
  const auto respond = [&](const TriangleMesh& mesh, bool complete) {
    Response r;
    r.content_type = "model/gltf-binary";
    r.body = glb_(*db.db, mesh, json{{"rcf", rcf.describe()}});
    r.headers.push_back({"X-Smrdb-Triangles", std::to_string(mesh.triangles.size())});
    r.headers.push_back({"X-Smrdb-Complete", complete ? "true" : "false"});
    return r;
  };
  // A constant floor alone: the level cut, as smrdb extract takes it (the same mesh, byte for
  // byte), on this request's thread (the server serves requests on several), when it fits the
  // cap; past the cap, a budgeted mesh when max_triangles was given (below), else 413.
  if (const std::optional<double> level = constant_level(spec)) {
    LevelCutStats cut;
    const std::optional<TriangleMesh> mesh =
        extract_level_cut(*db.db, *level, {.threads = 1, .max_triangles = cap}, &cut);
    if (mesh) return respond(*mesh, true);
    if (cut.over_budget && !user_cap) fail(413, too_many(cap));
  }
  ExpansionOptions expansion;  // as smrdb extract's defaults
  const SessionBudget budget{.max_period_ms = options_.timeout_ms, .max_triangles = cap};
  FrameStats fs;
  Extraction e = extract_budgeted(*db.source, rcf, budget, expansion, &fs);
  if (!fs.complete) {
    if (ms_since(t0) >= options_.timeout_ms)
      fail(504, "the extraction did not finish within " + std::to_string(options_.timeout_ms) +
                    " ms (--timeout-ms)");
    if (!user_cap) fail(413, too_many(cap));
  }
  const TriangleMesh mesh = to_mesh(*db.db, e.triangles);
  e = Extraction{};
  return respond(mesh, fs.complete);
}

Response Api::layer(const Db& db, const Request& request) const {
  if (!db.terrain) fail(404, "database '" + db.name + "' is a 3-D mesh: no terrain tiles");
  return cacheable(db.layer_json, "application/json", db.layer_etag, request);
}

Response Api::tile(const Db& db, const std::vector<std::string>& parts, const Request& request) {
  if (!db.terrain) fail(404, "database '" + db.name + "' is a 3-D mesh: no terrain tiles");
  const std::string& last = parts[5];
  const std::string ext = ".terrain";
  if (last.size() <= ext.size() || last.compare(last.size() - ext.size(), ext.size(), ext) != 0)
    fail(404, "a tile is /v1/{db}/tiles/{z}/{x}/{y}.terrain");
  const Params p(
      {{"z", parts[3]}, {"x", parts[4]}, {"y", last.substr(0, last.size() - ext.size())}});
  const int z = int(p.integer("z", 0, tiles::kMaxZoom));
  const auto x = p.integer("x", 0, (std::int64_t{1} << 26) - 1);
  const auto y = p.integer("y", 0, (std::int64_t{1} << 26) - 1);
  if (z > db.max_zoom)
    fail(404, "no tile at zoom " + std::to_string(z) + ": the pyramid's zooms are 0.." +
                  std::to_string(db.max_zoom));
  const tiles::TileRange range = db.scheme->covering(z);
  if (x < range.x0 || x > range.x1 || y < range.y0 || y > range.y1)
    fail(404, "tile " + std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y) +
                  " lies outside the database's domain");
  const std::string key =
      db.name + "/" + std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y);
  std::shared_ptr<const CachedTile> cached = tile_cache_.get(key);
  if (!cached) {
    const tiles::TileId id{z, std::uint32_t(x), std::uint32_t(y)};
    const QuantizedMeshTile t = tiles::cut_tile(*db.db, *db.scheme, id, db.height_step, nullptr);
    auto made = std::make_shared<CachedTile>();
    // A tile that layer.json lists but that holds only no-data is a valid tile with no vertices:
    // a standard client (CesiumJS) takes a 404 for a listed tile as a failure.
    const std::vector<std::uint8_t> bytes = encode_quantized_mesh(t);
    made->body.assign(bytes.begin(), bytes.end());
    made->etag = strong_etag(made->body);
    tile_cache_.put(key, made);
    cached = std::move(made);
  }
  return cacheable(cached->body, "application/vnd.quantized-mesh", cached->etag, request);
}

Response Api::session_create(Db& db) {
  auto session = std::make_unique<Session>(*db.source);
  std::string id;
  const auto entry = sessions_.create(db.name, std::move(session), id);
  if (!entry)
    fail(503, "the session table is full (" + std::to_string(options_.max_sessions) +
                  " sessions, --max-sessions): retry later or DELETE a session");
  std::lock_guard lock(entry->busy);
  std::vector<TriRef> in(entry->session->triangles().begin(), entry->session->triangles().end());
  std::sort(in.begin(), in.end());
  FrameStats stats;
  stats.x = 1;
  stats.triangles = stats.triangles_in = in.size();
  const json header = {
      {"session", id}, {"frame", entry->frame++}, {"stats", frame_stats(stats, 0)}};
  Response r;
  r.content_type = "application/octet-stream";
  r.body = encode_frame(*db.db, db.origin, header, {}, in, nullptr);
  return r;
}

Response Api::session_update(Db& db, const std::string& id, const Request& request) {
  const Params p(request.params);
  p.only({"eye", "target", "up", "fov", "viewport", "px", "max_ms", "max_triangles"});
  const RcfSpec spec = camera_spec(p, false);
  const double max_ms = p.number("max_ms", 0.0, options_.timeout_ms, options_.timeout_ms / 2, true);
  const auto cap = std::uint64_t(p.integer("max_triangles", 1, std::int64_t(options_.max_triangles),
                                           std::int64_t(options_.max_triangles)));
  const auto entry = sessions_.find(db.name, id.substr(0, 64));
  if (!entry) fail(404, "no session '" + id.substr(0, 64) + "' on database '" + db.name + "'");
  std::unique_lock lock(entry->busy, std::try_to_lock);
  if (!lock.owns_lock()) fail(409, "session '" + id + "' is busy with another update");
  const Rcf rcf = make_rcf(spec, db.db->info(), nullptr);
  const std::uint64_t pages_before = db.db->stats().pages_read;
  const Frame f = entry->session->update(rcf, {.max_period_ms = max_ms, .max_triangles = cap});
  const json header = {{"session", id},
                       {"frame", entry->frame++},
                       {"stats", frame_stats(f.stats, db.db->stats().pages_read - pages_before)}};
  Response r;
  r.content_type = "application/octet-stream";
  r.body = encode_frame(*db.db, db.origin, header, f.triangles_out, f.triangles_in, &f.morph);
  return r;
}

Response Api::session_delete(Db& db, const std::string& id) {
  if (!sessions_.remove(db.name, id))
    fail(404, "no session '" + id.substr(0, 64) + "' on database '" + db.name + "'");
  Response r;
  r.status = 200;
  r.body = json{{"deleted", id}}.dump();
  return r;
}

}  // namespace smr::serve
