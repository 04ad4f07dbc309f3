// smrdb serve's GIS queries (api.h): elevation, profile, line of sight and contours, answered by
// smr/query as `smrdb query` answers them.
#include <cmath>
#include <sstream>

#include "base/error.h"
#include "smr/query/contours.h"
#include "smr/query/elevation.h"
#include "smr/query/sight.h"
#include "tools/serve/api.h"
#include "tools/serve/api_db.h"
#include "tools/serve/params.h"

namespace smr::serve {

namespace {

using nlohmann::json;

constexpr std::size_t kMaxProfilePoints = 1'000'000;
constexpr double kMaxLevels = 1000;

query::Accuracy accuracy(const Params& p) {
  if (!p.has("max_error")) return query::Accuracy::finest();
  return query::Accuracy::within(p.number("max_error", 0.0, 1e15));
}

json z_or_null(double z, bool has_data) {
  return has_data && std::isfinite(z) ? json(z) : json();
}

Response json_answer(const json& j) {
  Response r;
  r.body = j.dump();
  return r;
}

Response elevation(const Api::Db& db, const Params& p) {
  p.only({"x", "y", "max_error"});
  const Vec2 pt{p.number("x", -1e15, 1e15), p.number("y", -1e15, 1e15)};
  const query::Accuracy acc = accuracy(p);
  const query::ElevationQuery q(*db.source);
  json out = {{"x", pt.x}, {"y", pt.y}, {"z", nullptr}, {"error_bound", nullptr}};
  if (!q.domain().contains(pt)) return json_answer(out);
  const query::ElevationAnswer a = q.at(pt, acc);
  out["z"] = z_or_null(a.z, a.has_data);
  if (a.has_data) out["error_bound"] = a.error_bound;
  return json_answer(out);
}

// N points evenly spaced along the exact profile (linear between its breakpoints).
json resample(const query::ProfileResult& r, std::int64_t n) {
  json points = json::array();
  const auto& pts = r.points;
  const double length = pts.back().distance;
  std::size_t i = 0;
  for (std::int64_t k = 0; k < n; ++k) {
    const double d = length * double(k) / double(n - 1);
    while (i + 2 < pts.size() && pts[i + 1].distance < d) ++i;
    const query::ProfilePoint& a = pts[i];
    const query::ProfilePoint& b = pts[std::min(i + 1, pts.size() - 1)];
    const double span = b.distance - a.distance;
    const double t = span > 0 ? std::clamp((d - a.distance) / span, 0.0, 1.0) : 0.0;
    const Vec3 q = a.p + t * (b.p - a.p);
    points.push_back({d, q.x, q.y, z_or_null(q.z, a.has_data)});
  }
  return points;
}

Response profile(const Api::Db& db, const Params& p) {
  p.only({"from", "to", "samples", "max_error"});
  const std::vector<Vec2> line{p.vec2("from"), p.vec2("to")};
  const bool sampled = p.has("samples");
  const std::int64_t n = p.integer("samples", 2, 100'000, 2);
  const query::ProfileResult r = query::profile(*db.source, line, accuracy(p));
  if (r.points.size() > kMaxProfilePoints)
    fail(413, "the profile has " + std::to_string(r.points.size()) +
                  " breakpoints: give 'samples' (at most 100000)");
  json points = json::array();
  if (sampled) {
    points = resample(r, n);
  } else {
    for (const query::ProfilePoint& q : r.points)
      points.push_back({q.distance, q.p.x, q.p.y, z_or_null(q.p.z, q.has_data)});
  }
  return json_answer({{"points", std::move(points)}, {"error_bound", r.error_bound}});
}

Response line_of_sight(const Api::Db& db, const Params& p) {
  p.only({"from", "to", "max_error"});
  const Vec3 a = p.vec3("from"), b = p.vec3("to");
  const query::SightAnswer s = query::line_of_sight(*db.source, a, b, accuracy(p));
  const Vec3& at = s.blocked_at;
  return json_answer(
      {{"visible", s.sight == query::Sight::kVisible},
       {"blocked_at", s.sight == query::Sight::kBlocked ? json::array({at.x, at.y, at.z}) : json()},
       {"sight", query::to_string(s.sight)},
       {"error_bound", s.error_bound}});
}

// The runs of a line's points inside the box, each of at least two points.
void clip_to_box(const query::ContourLine& line, const std::vector<double>& box,
                 std::vector<query::ContourLine>& out) {
  query::ContourLine run{line.level, line.error, false, {}};
  auto flush = [&] {
    if (run.points.size() >= 2) out.push_back(run);
    run.points.clear();
  };
  for (const Vec2& q : line.points) {
    if (q.x >= box[0] && q.x <= box[2] && q.y >= box[1] && q.y <= box[3])
      run.points.push_back(q);
    else
      flush();
  }
  if (run.points.size() == line.points.size()) run.closed = line.closed;
  flush();
}

Response contours(const Api::Db& db, const Params& p) {
  p.only({"interval", "base", "bbox", "max_error"});
  query::ContourOptions o;
  o.interval = p.number("interval", 0.0, 1e15, std::nullopt, true);
  o.base = p.number("base", -1e15, 1e15, 0.0);
  o.accuracy = accuracy(p);
  const Box3& b = db.db->info().bounds;
  if ((b.hi.z - b.lo.z) / *o.interval > kMaxLevels)
    fail(400, "parameter 'interval' gives more than 1000 levels over the data's heights [" +
                  std::to_string(b.lo.z) + ", " + std::to_string(b.hi.z) + "]");
  std::vector<double> box;
  if (p.has("bbox")) {
    box = p.numbers("bbox", 4, "x0,y0,x1,y1");
    if (!(box[0] < box[2] && box[1] < box[3]))
      fail(400, "parameter 'bbox' must be x0,y0,x1,y1 with x0 < x1 and y0 < y1");
  }
  query::ContourResult c = query::contours(*db.source, o);
  if (!box.empty()) {
    std::vector<query::ContourLine> kept;
    for (const auto& line : c.lines) clip_to_box(line, box, kept);
    c.lines = std::move(kept);
  }
  std::ostringstream os;
  query::write_geojson(os, c, db.db->info().georef);
  Response r;
  r.content_type = "application/geo+json";
  r.body = os.str();
  return r;
}

}  // namespace

Response Api::query(const Db& db, const std::string& kind, const Request& request) const {
  if (!db.terrain) fail(400, "database '" + db.name + "' is a 3-D mesh: queries need a terrain");
  const Params p(request.params);
  if (kind == "elevation") return elevation(db, p);
  if (kind == "profile") return profile(db, p);
  if (kind == "los") return line_of_sight(db, p);
  if (kind == "contours") return contours(db, p);
  fail(404, "no query '" + kind.substr(0, 64) + "' (elevation, profile, los, contours)");
}

}  // namespace smr::serve
