// `smrdb query DB KIND ...`: the GIS queries of smr/query (Maheshwari et al. 3-4) from the
// command line. Coordinates are in the raster's own CRS, as ingest recorded it (`smrdb info`).
// Answers go to stdout or -o (written atomically); --json prints a report with the answers or a
// summary, the accuracy, the ops and pages each query read, and the time.
#include <charconv>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/core/clock.h"
#include "smr/db/database.h"
#include "smr/io/atomic_file.h"
#include "smr/io/mesh_writer.h"
#include "smr/query/contours.h"
#include "smr/query/elevation.h"
#include "smr/query/indexed_source.h"
#include "smr/query/region.h"
#include "smr/query/sight.h"
#include "tools/commands.h"
#include "tools/parse.h"
#include "tools/report_json.h"

namespace smr::tools {

namespace {

[[noreturn]] void throw_input(const std::string& m) {
  throw Error(ErrorKind::kInvalidInput, m);
}

query::Accuracy accuracy_of(const QueryArgs& a) {
  if (a.max_error && !(*a.max_error >= 0.0)) throw_input("--max-error expects a number >= 0");
  return a.max_error ? query::Accuracy::within(*a.max_error) : query::Accuracy::finest();
}

Vec2 parse_point(const std::string& text, const std::string& what) {
  const std::vector<double> v = parse_numbers(text, 2, what, "X,Y");
  return {v[0], v[1]};
}

// Where answers go: stdout, or a file that appears whole when the query succeeds.
class Output {
 public:
  explicit Output(const std::string& path) {
    if (!path.empty()) file_.emplace(path);
  }
  void write(const std::string& s) {
    if (file_) {
      file_->write(s);
    } else {
      std::fwrite(s.data(), 1, s.size(), stdout);
    }
  }
  /// A writer that takes a std::ostream (the GeoJSON writer): the file, or stdout.
  void write_stream(const std::function<void(std::ostream&)>& writer) {
    if (!file_) {
      std::fflush(stdout);
      writer(std::cout);
      std::cout.flush();
      return;
    }
    file_->close_stream();
    std::ofstream os(file_->temp_path(), std::ios::binary | std::ios::trunc);
    writer(os);
    os.close();
    if (!os) throw Error(ErrorKind::kIo, file_->path() + ": cannot write");
  }
  void commit() {
    if (file_) file_->commit();
  }

 private:
  std::optional<AtomicFile> file_;
};

std::string number(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 10);
  return std::string(buf, r.ptr);
}

nlohmann::json answer_json(const query::ElevationAnswer& a) {
  nlohmann::json j = {{"x", a.p.x}, {"y", a.p.y}};
  j["z"] = a.has_data ? nlohmann::json(a.z) : nlohmann::json(nullptr);
  j["error"] = a.error_bound;
  j["final"] = a.final;
  j["ops_read"] = a.ops_read;
  return j;
}

// The shortest text that reads back as the same double (coordinates echo as typed).
std::string exact(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

// One "x,y" per line (also "x y", "x;y" or tab-separated, runs of separators and spaces around
// commas being one separator); blank lines, '#' comments and a header (a first line whose first
// field is not a number) are skipped.
class PointReader {
 public:
  PointReader(std::istream& in, std::string name) : in_(in), name_(std::move(name)) {}
  bool next(Vec2& p) {
    std::string raw;
    while (std::getline(in_, raw)) {
      ++line_no_;
      std::string line;  // fields joined by single commas
      for (char c : raw) {
        const bool sep = c == ',' || c == ';' || c == '\t' || c == ' ' || c == '\r';
        if (!sep) {
          line += c;
        } else if (!line.empty() && line.back() != ',') {
          line += ',';
        }
      }
      if (!line.empty() && line.back() == ',') line.pop_back();
      if (line.empty() || line[0] == '#') continue;
      const bool first = !seen_content_;
      seen_content_ = true;
      const char c = line[0];
      if (first &&
          !(std::isdigit(static_cast<unsigned char>(c)) || c == '-' || c == '+' || c == '.'))
        continue;  // a header
      if (fast_pair(line, p)) return true;
      const std::vector<double> v = parse_numbers(line, 2, where(), "X,Y");  // names the fault
      p = {v[0], v[1]};
      return true;
    }
    return false;
  }
  std::string where() const { return name_ + " line " + std::to_string(line_no_); }

 private:
  // "x,y" as two finite numbers and nothing else (the common case, without parse_numbers'
  // streams); false sends the line to parse_numbers for its message.
  static bool fast_pair(const std::string& line, Vec2& p) {
    const char* s = line.data();
    const char* end = s + line.size();
    if (s != end && *s == '+') ++s;
    auto r = std::from_chars(s, end, p.x);
    if (r.ec != std::errc() || r.ptr == end || *r.ptr != ',') return false;
    s = r.ptr + 1;
    if (s != end && *s == '+') ++s;
    r = std::from_chars(s, end, p.y);
    return r.ec == std::errc() && r.ptr == end && std::isfinite(p.x) && std::isfinite(p.y);
  }
  std::istream& in_;
  std::string name_;
  std::uint64_t line_no_ = 0;
  bool seen_content_ = false;
};

// The member `key` of a GeoJSON object, of the expected kind.
const nlohmann::json& member(const nlohmann::json& j, const char* key, bool array,
                             const std::string& name) {
  if (!j.is_object() || !j.contains(key) || (array && !j[key].is_array()))
    throw_input(name + ": a GeoJSON " + j.value("type", std::string("object")) + " needs " +
                (array ? "an array " : "a member ") + "\"" + key + "\"");
  return j[key];
}

// Points of a GeoJSON document: Point and MultiPoint geometries, bare, in features or in a list.
void geojson_points(const nlohmann::json& j, std::vector<Vec2>& out, const std::string& name) {
  const auto coord = [&](const nlohmann::json& c) {
    if (!c.is_array() || c.size() < 2 || !c[0].is_number() || !c[1].is_number())
      throw_input(name + ": a GeoJSON position must be [x, y], got " + c.dump());
    out.push_back({c[0].get<double>(), c[1].get<double>()});
  };
  if (j.is_array()) {
    for (const auto& e : j) geojson_points(e, out, name);
    return;
  }
  const std::string type =
      j.is_object() && j.contains("type") && j["type"].is_string() ? j["type"] : "";
  if (type == "FeatureCollection") {
    for (const auto& f : member(j, "features", true, name)) geojson_points(f, out, name);
  } else if (type == "Feature") {
    const nlohmann::json& g = member(j, "geometry", false, name);
    if (!g.is_null()) geojson_points(g, out, name);
  } else if (type == "Point") {
    coord(member(j, "coordinates", true, name));
  } else if (type == "MultiPoint") {
    for (const auto& c : member(j, "coordinates", true, name)) coord(c);
  } else {
    throw_input(name + ": expected GeoJSON Point or MultiPoint geometries, got " +
                (type.empty() ? j.dump().substr(0, 60) : "type '" + type + "'"));
  }
}

// Batch elevation: points are checked as they are read (an error names the record), answered a
// chunk at a time in Hilbert order (ElevationQuery::at_many) and written in input order.
struct ElevationRun {
  static constexpr std::size_t kChunk = std::size_t{1} << 20;
  const query::ElevationQuery& q;
  query::Accuracy acc;
  bool json;
  Output& out;
  nlohmann::json answers = nlohmann::json::array();
  std::vector<Vec2> pending;
  std::uint64_t count = 0, nodata = 0, ops = 0;
  double worst_error = 0.0;

  void add(const Vec2& p, const std::string& where) {
    try {
      q.check_inside(p);
    } catch (const Error& e) {
      throw_input(where + ": " + e.what());
    }
    pending.push_back(p);
    if (pending.size() == kChunk) flush();
  }
  void flush() {
    // Each answer keeps what the output needs (not the whole ElevationAnswer: a chunk of a
    // million stays ~25 MB), then the lines go out in input order, about 4 MB at a time.
    struct Kept {
      double z, error;
      bool has_data;
    };
    std::vector<Kept> kept(pending.size());
    std::vector<nlohmann::json> slots(json ? pending.size() : 0);
    q.at_many(pending, acc, [&](std::size_t i, const query::ElevationAnswer& a) {
      ++count;
      ops += a.ops_read;
      nodata += a.has_data ? 0 : 1;
      worst_error = std::max(worst_error, a.error_bound);
      if (json) slots[i] = answer_json(a);
      kept[i] = {a.z, a.error_bound, a.has_data};
    });
    if (json) {
      for (nlohmann::json& j : slots) answers.push_back(std::move(j));
    } else {
      std::string text;
      for (std::size_t i = 0; i < pending.size(); ++i) {
        text += exact(pending[i].x) + "," + exact(pending[i].y) + "," +
                (kept[i].has_data ? number(kept[i].z) : "nodata") + "," + number(kept[i].error) +
                "\n";
        if (text.size() > (std::size_t{4} << 20)) {
          out.write(text);
          text.clear();
        }
      }
      out.write(text);
    }
    pending.clear();
  }
};

void read_points_file(const std::string& path, ElevationRun& run) {
  std::ifstream file;
  std::istream* in = &std::cin;
  const std::string name = path == "-" ? "stdin" : path;
  if (path != "-") {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec))
      throw Error(ErrorKind::kIo, path + ": not a readable file of points");
    file.open(path);
    if (!file) throw Error(ErrorKind::kIo, path + ": cannot open the points file");
    in = &file;
  }
  // A UTF-8 byte order mark and leading blanks say nothing of the format.
  if (in->peek() == 0xEF) {
    char bom[3];
    in->read(bom, 3);
    if (std::string(bom, 3) != "\xEF\xBB\xBF") throw_input(name + ": not UTF-8 text");
  }
  while (std::isspace(in->peek())) in->get();
  if (in->peek() == '{' || in->peek() == '[') {  // GeoJSON
    nlohmann::json j;
    try {
      j = nlohmann::json::parse(*in);
    } catch (const nlohmann::json::exception& e) {
      throw_input(name + ": not valid GeoJSON: " + e.what());
    }
    std::vector<Vec2> pts;
    geojson_points(j, pts, name);
    for (std::size_t i = 0; i < pts.size(); ++i)
      run.add(pts[i], name + " point " + std::to_string(i + 1));
    return;
  }
  PointReader reader(*in, name);
  Vec2 p;
  while (reader.next(p)) run.add(p, reader.where());
  if (in->bad()) throw Error(ErrorKind::kIo, name + ": read error");
}

nlohmann::json query_elevation(const IndexedSource& src, const QueryArgs& a) {
  if (a.args.empty() && a.input.empty())
    throw_input("elevation: give points as X,Y arguments or --input FILE (- for stdin)");
  const query::ElevationQuery q(src);
  Output out(a.out);
  // The answers go to -o (or stdout); with --json and no -o, into the report.
  const bool inline_json = a.json && a.out.empty();
  ElevationRun run{q, accuracy_of(a), inline_json, out, nlohmann::json::array(), {}, 0, 0, 0, 0.0};
  if (!inline_json) out.write("x,y,z,error\n");
  for (std::size_t i = 0; i < a.args.size(); ++i)
    run.add(parse_point(a.args[i], "point " + std::to_string(i + 1)),
            "point " + std::to_string(i + 1) + " (" + a.args[i] + ")");
  if (!a.input.empty()) read_points_file(a.input, run);
  run.flush();
  nlohmann::json r = {{"points", run.count},
                      {"no_data", run.nodata},
                      {"ops_read", run.ops},
                      {"max_error_bound", run.worst_error}};
  if (inline_json) r["answers"] = std::move(run.answers);
  out.commit();
  return r;
}

nlohmann::json query_window(const IndexedSource& src, const QueryArgs& a) {
  if (a.args.size() != 1) throw_input("window: expected one XMIN,YMIN,XMAX,YMAX argument");
  const std::vector<double> w = parse_numbers(a.args[0], 4, "window", "XMIN,YMIN,XMAX,YMAX");
  if (!(w[0] < w[2]) || !(w[1] < w[3]))
    throw_input("window " + a.args[0] + " is empty: expected XMIN < XMAX and YMIN < YMAX");
  const query::Domain dom = query::terrain_domain(src.info());
  if (w[2] < dom.lo.x || w[0] > dom.hi.x || w[3] < dom.lo.y || w[1] > dom.hi.y) {
    std::ostringstream os;
    os << "window " << a.args[0] << " lies outside the database's domain " << dom.lo.x << ','
       << dom.lo.y << " .. " << dom.hi.x << ',' << dom.hi.y;
    throw_input(os.str());
  }
  if (a.out.empty() && !a.json)
    throw_input("window: give -o FILE.{ply,obj} for the mesh, or --json for the report");
  const auto region = std::make_shared<query::WindowRegion>(Vec2{w[0], w[1]}, Vec2{w[2], w[3]});
  const Extraction e = query::refine(src, region, accuracy_of(a));
  // The triangles meeting the window, and the vertices inside it (Maheshwari Fig. 10's ratio).
  std::vector<TriRef> meeting;
  std::uint64_t inside = 0;
  double worst = 0.0;
  for (const TriRef& r : e.triangles) {
    const OpRef op = src.op(r.op);
    const FragmentTriangle& t = op->fragment[r.index];
    const Triangle3 v = corners(*op, t);
    if (t.is_void() || !region->triangle_meets(v, 0.0)) continue;
    meeting.push_back(r);
    worst = std::max(worst, query::triangle_error(src, t));
  }
  const TriangleMesh clipped = to_mesh(src, meeting);
  for (const Vec3& p : clipped.positions)
    inside += (p.x >= w[0] && p.x <= w[2] && p.y >= w[1] && p.y <= w[3]) ? 1 : 0;
  nlohmann::json r = {{"extraction", e.stats},
                      {"triangles", e.triangles.size() - e.stats.void_triangles},
                      {"triangles_meeting_window", meeting.size()},
                      {"vertices_in_window", inside},
                      {"max_error_in_window", worst}};
  if (!a.out.empty()) {
    const TriangleMesh mesh = a.clip ? clipped : to_mesh(src, e.triangles);
    write_mesh(a.out, mesh);
    r["output"] = {{"path", a.out},
                   {"vertices", mesh.positions.size()},
                   {"triangles", mesh.triangles.size()},
                   {"clipped", a.clip}};
  }
  return r;
}

// "X,Y,Z", or "X,Y,+H": H above the surface (its finest height there).
Vec3 parse_sight_end(const std::string& text, const std::string& what, const IndexedSource& src) {
  const std::vector<double> v = parse_numbers(text, 3, what, "X,Y,Z or X,Y,+H");
  const bool above = text.substr(text.rfind(',') + 1).starts_with('+');
  if (!above) return {v[0], v[1], v[2]};
  const query::ElevationAnswer g =
      query::ElevationQuery(src).at({v[0], v[1]}, query::Accuracy::finest());
  if (!g.has_data) throw_input(what + " " + text + ": no data there to stand on");
  return {v[0], v[1], g.z + v[2]};
}

std::string point_text(const Vec3& p) {
  return number(p.x) + "," + number(p.y) + "," + number(p.z);
}

nlohmann::json query_los(const IndexedSource& src, const QueryArgs& a) {
  if (a.args.size() != 2) throw_input("los: expected two points X1,Y1,Z1 X2,Y2,Z2");
  const Vec3 p = parse_sight_end(a.args[0], "observer", src);
  const Vec3 q = parse_sight_end(a.args[1], "target", src);
  const query::SightAnswer s = query::line_of_sight(src, p, q, accuracy_of(a));
  nlohmann::json r = {{"answer", query::to_string(s.sight)},
                      {"from", {p.x, p.y, p.z}},
                      {"to", {q.x, q.y, q.z}},
                      {"error_bound", s.error_bound},
                      {"ops_read", s.ops},
                      {"triangles_tested", s.triangles_tested}};
  std::string text = query::to_string(s.sight);
  if (s.sight == query::Sight::kBlocked) {
    r["blocked_at"] = {s.blocked_at.x, s.blocked_at.y, s.blocked_at.z};
    text += " at " + point_text(s.blocked_at);
  }
  if (s.undecided_at) {
    r["undecided_at"] = {s.undecided_at->x, s.undecided_at->y, s.undecided_at->z};
    text += (s.sight == query::Sight::kUndecided ? " within " : "; undecided before, within ") +
            number(s.error_bound) + " from " + point_text(*s.undecided_at);
  }
  if (s.no_data_at) {
    r["no_data_at"] = {s.no_data_at->x, s.no_data_at->y, s.no_data_at->z};
    text += "; no data from " + point_text(*s.no_data_at);
  }
  if (!a.json || !a.out.empty()) {
    Output out(a.out);
    out.write(text + "\n");
    out.commit();
  }
  return r;
}

nlohmann::json query_profile(const IndexedSource& src, const QueryArgs& a) {
  if (a.args.size() < 2) throw_input("profile: expected at least two points X1,Y1 X2,Y2 ...");
  std::vector<Vec2> line;
  for (std::size_t i = 0; i < a.args.size(); ++i)
    line.push_back(parse_point(a.args[i], "profile point " + std::to_string(i + 1)));
  const query::ProfileResult pr = query::profile(src, line, accuracy_of(a));
  nlohmann::json r = {{"points", pr.points.size()},
                      {"error_bound", pr.error_bound},
                      {"ops_read", pr.ops},
                      {"triangles", pr.triangles}};
  if (a.json && a.out.empty()) {
    nlohmann::json pts = nlohmann::json::array();
    for (const query::ProfilePoint& q : pr.points)
      pts.push_back({{"distance", q.distance},
                     {"x", q.p.x},
                     {"y", q.p.y},
                     {"z", q.has_data ? nlohmann::json(q.p.z) : nlohmann::json(nullptr)},
                     {"error", q.error_bound}});
    r["profile"] = std::move(pts);
    return r;
  }
  Output out(a.out);
  std::string text = "distance,x,y,z,error\n";
  for (const query::ProfilePoint& q : pr.points)
    text += number(q.distance) + "," + number(q.p.x) + "," + number(q.p.y) + "," +
            (std::isnan(q.p.z) ? "nodata" : number(q.p.z)) + "," + number(q.error_bound) + "\n";
  out.write(text);
  out.commit();
  return r;
}

double max_line_error(const query::ContourResult& c) {
  double e = 0.0;
  for (const query::ContourLine& l : c.lines) e = std::max(e, l.error);
  return e;
}

nlohmann::json query_contours(const IndexedSource& src, const QueryArgs& a) {
  query::ContourOptions o;
  if (!a.levels.empty()) o.levels = parse_numbers(a.levels, 0, "--levels", "H1,H2,...");
  o.interval = a.interval;
  o.base = a.base;
  o.accuracy = accuracy_of(a);
  if (o.levels.empty() && !o.interval) throw_input("contours: give --levels H,... or --interval D");
  if (a.json && a.out.empty())
    throw_input("contours --json prints a report on stdout: give -o FILE.geojson for the lines");
  const query::ContourResult c = query::contours(src, o);
  Output out(a.out);
  out.write_stream([&](std::ostream& os) { query::write_geojson(os, c, src.info().georef); });
  out.commit();
  const query::ContourStats& s = c.stats;
  return {{"levels", s.levels},
          {"ops", s.ops},
          {"triangles", s.triangles},
          {"triangles_marched", s.triangles_marched},
          {"segments", s.segments},
          {"lines", s.polylines},
          {"rings", s.rings},
          {"points", s.points},
          {"max_error", max_line_error(c)},
          {"seconds",
           {{"refine", s.refine_seconds}, {"march", s.march_seconds}, {"join", s.join_seconds}}}};
}

}  // namespace

void QueryArgs::add_common(CLI::App& app) {
  app.add_option("--max-error", max_error,
                 "Answer from triangles within this error (data units), not the finest mesh "
                 "(faster; the bound is in every answer)");
  app.add_option("-o,--output", out, "Write the answers here instead of stdout");
  app.add_option("--cache-mb", cache_mb, "Page cache budget in MiB")->check(CLI::PositiveNumber);
  app.add_flag("--json", json,
               "Print a JSON report on stdout (with the answers when there is no -o)");
  app.add_flag("-q,--quiet", quiet, "No summary on stderr");
}

void QueryArgs::add_to(CLI::App& query) {
  query.require_subcommand(1);
  CLI::App* elevation = query.add_subcommand(
      "elevation", "Height at points, with the error bound each answer holds (Maheshwari 4.1)");
  elevation->add_option("points", args, "X,Y ...");
  elevation->add_option("--input", input,
                        "Points from a CSV (x,y per line) or GeoJSON file; - reads stdin");
  CLI::App* window = query.add_subcommand(
      "window",
      "Every triangle meeting a window at full resolution (or --max-error), coarse "
      "elsewhere (Maheshwari 3.2); a mesh with -o");
  window->add_option("box", args, "XMIN,YMIN,XMAX,YMAX")->required();
  window->add_flag("--clip", clip, "Write only the triangles meeting the window");
  CLI::App* los = query.add_subcommand(
      "los",
      "Line of sight between two 3-D points: visible, blocked at a point, or undecided "
      "within the error bound (Maheshwari 4.3)");
  los->add_option("points", args, "X1,Y1,Z1 X2,Y2,Z2 (Z as +H: H above the ground)")->required();
  CLI::App* profile = query.add_subcommand(
      "profile", "The surface's exact piecewise-linear profile along a polyline (CSV)");
  profile->add_option("points", args, "X1,Y1 X2,Y2 ...")->required();
  CLI::App* contours =
      query.add_subcommand("contours",
                           "Contour lines as GeoJSON, each with its height and error bound "
                           "(Maheshwari 4.2)");
  contours->add_option("--levels", levels, "Heights H1,H2,...");
  contours->add_option("--interval", interval, "Every D (data units)");
  contours->add_option("--base", base, "With --interval: levels base + k * D (default 0)");
  for (CLI::App* sub : {elevation, window, los, profile, contours}) {
    add_common(*sub);
    sub->positionals_at_end(false);
  }
}

int cmd_query(const std::string& db_path, const std::string& kind, const QueryArgs& a) {
  const auto db = Database::open(db_path, {std::size_t(a.cache_mb) << 20});
  const IndexedSource src(*db);
  const auto t0 = Clock::now();
  nlohmann::json r;
  if (kind == "elevation") r = query_elevation(src, a);
  if (kind == "window") r = query_window(src, a);
  if (kind == "los") r = query_los(src, a);
  if (kind == "profile") r = query_profile(src, a);
  if (kind == "contours") r = query_contours(src, a);
  r["query"] = kind;
  r["accuracy"] = accuracy_of(a).describe();
  r["seconds"] = seconds_since(t0);
  r["io"] = db->stats();
  if (a.json) std::printf("%s\n", r.dump(2).c_str());
  if (!a.json && !a.quiet)
    std::fprintf(stderr, "%s: %s query (%s) in %.3f s, %llu pages read\n", db_path.c_str(),
                 kind.c_str(), r["accuracy"].get<std::string>().c_str(), r["seconds"].get<double>(),
                 static_cast<unsigned long long>(r["io"]["pages_read"].get<std::uint64_t>()));
  return 0;
}

}  // namespace smr::tools
