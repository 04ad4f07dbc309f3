// Opening a database for smrdb serve (api_db.h).
#include "tools/serve/api_db.h"

#include <algorithm>
#include <cstdio>

#include "smr/tiles/pyramid.h"

namespace smr::serve {

namespace {

nlohmann::json vec(const Vec3& v) {
  return nlohmann::json::array({v.x, v.y, v.z});
}

}  // namespace

std::string strong_etag(const std::string& bytes) {
  std::uint64_t h = 1469598103934665603ull;  // FNV-1a 64
  for (const unsigned char c : bytes) h = (h ^ c) * 1099511628211ull;
  char text[24];
  std::snprintf(text, sizeof text, "\"%016llx\"", static_cast<unsigned long long>(h));
  return text;
}

Api::Db::Db(std::string name_, const std::string& path, std::size_t cache_bytes)
    : name(std::move(name_)) {
  db = Database::open(path, {cache_bytes});
  source = std::make_unique<IndexedSource>(*db);
  const CrmrInfo& ci = db->info();
  terrain = ci.kind == ModelKind::kTerrain;
  origin = (ci.bounds.lo + ci.bounds.hi) * 0.5;
  // What `smrdb info --json` prints (tools/info_cmd.cpp), the path replaced by the name.
  nlohmann::json meta = nlohmann::json::parse(db->meta_json());
  const auto vertices = meta["model"]["vertex_count"].get<std::uint64_t>();
  info = {
      {"name", name},
      {"path", name},
      {"file_bytes", db->file_bytes()},
      {"bytes_per_vertex", double(db->file_bytes()) / double(std::max<std::uint64_t>(1, vertices))},
      {"dag_depth", meta["counts"]["dag_depth"]},
      {"rtree_height", db->rtree().height()},
      {"meta", meta},
      {"kind", terrain ? "terrain" : "mesh"},
      {"origin", vec(origin)},
      {"bounds", {{"min", vec(ci.bounds.lo)}, {"max", vec(ci.bounds.hi)}}},
      {"err0", ci.err0},
      {"err_final", ci.err_final}};
  if (terrain) {
    const Georef& g = ci.georef;
    info["georef"] = {{"x0", g.x0},
                      {"y0", g.y0},
                      {"dx", g.dx},
                      {"dy", g.dy},
                      {"crs_wkt", g.crs_wkt},
                      {"geographic", g.geographic},
                      {"grid_width", ci.grid_width},
                      {"grid_height", ci.grid_height}};
    scheme = tiles::TilingScheme::for_terrain(ci);
    max_zoom = scheme->default_max_zoom(ci.err_final);
    height_step = tiles::global_height_step(*db);
    layer_json = tiles::covering_layer_json(*db, max_zoom);
    layer_etag = strong_etag(layer_json);
    info["tiles"] = {{"max_zoom", max_zoom}, {"projection", scheme->projection()}};
  }
}

}  // namespace smr::serve
