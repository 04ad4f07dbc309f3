#include "smr/db/meta.h"

#include <string>

namespace smr {

using nlohmann::json;

json vec_json(const Vec3& v) {
  return json::array({v.x, v.y, v.z});
}
Vec3 json_vec(const json& j) {
  return {j.at(0).get<double>(), j.at(1).get<double>(), j.at(2).get<double>()};
}

json info_json(const CrmrInfo& info) {
  return {{"kind", info.kind == ModelKind::kTerrain ? "terrain" : "mesh"},
          {"georef",
           {{"x0", info.georef.x0},
            {"y0", info.georef.y0},
            {"dx", info.georef.dx},
            {"dy", info.georef.dy},
            {"crs_wkt", info.georef.crs_wkt},
            {"geographic", info.georef.geographic}}},
          {"grid_width", info.grid_width},
          {"grid_height", info.grid_height},
          {"err0", info.err0},
          {"err_final", info.err_final},
          {"bounds", {{"lo", vec_json(info.bounds.lo)}, {"hi", vec_json(info.bounds.hi)}}},
          {"source", info.source},
          {"builder", info.builder},
          {"vertex_count", info.vertex_count}};
}

CrmrInfo json_info(const json& j) {
  CrmrInfo info;
  info.kind =
      j.at("kind").get<std::string>() == "terrain" ? ModelKind::kTerrain : ModelKind::kMesh3d;
  const json& g = j.at("georef");
  info.georef.x0 = g.at("x0").get<double>();
  info.georef.y0 = g.at("y0").get<double>();
  info.georef.dx = g.at("dx").get<double>();
  info.georef.dy = g.at("dy").get<double>();
  info.georef.crs_wkt = g.at("crs_wkt").get<std::string>();
  info.georef.geographic = g.at("geographic").get<bool>();
  info.grid_width = j.at("grid_width").get<int>();
  info.grid_height = j.at("grid_height").get<int>();
  info.err0 = j.at("err0").get<double>();
  info.err_final = j.at("err_final").get<double>();
  info.bounds = Box3{json_vec(j.at("bounds").at("lo")), json_vec(j.at("bounds").at("hi"))};
  info.source = j.at("source").get<std::string>();
  info.builder = j.at("builder").get<std::string>();
  info.vertex_count = j.at("vertex_count").get<std::uint64_t>();
  return info;
}

}  // namespace smr
