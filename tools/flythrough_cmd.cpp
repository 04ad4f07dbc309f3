// smrdb flythrough: replays a camera path through a geomorphing session (smr/extract/session.h,
// Brown ch. 6) and reports what each frame's update did and cost (issue 35 item 4; Brown
// Fig. 7.21). Each frame: a screen-space RCF for the frame's camera (frustum and back-face
// culling), Session::update within --max-period, a record (pending work, local morphs, triangles,
// pages read, time); with --compare-fresh also a from-scratch extraction of the same RCF.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/core/clock.h"
#include "smr/db/database.h"
#include "smr/extract/extract.h"
#include "smr/extract/session.h"
#include "smr/io/render.h"
#include "smr/query/indexed_source.h"
#include "smr/rcf/spec.h"
#include "tools/commands.h"
#include "tools/parse.h"
#include "tools/progress.h"
#include "tools/report_json.h"
#include "tools/rss.h"

namespace smr::tools {

namespace {

constexpr double kDegree = std::numbers::pi / 180.0;
// The default eye speed ("walking"): this fraction of the model's extent per second, so a flight
// across the model takes 100 s (6 000 frames at 60 fps).
constexpr double kWalkingFraction = 0.01;

// A camera of the path: where it is, where it looks, its vertical field of view.
struct Key {
  Vec3 eye{0.0}, target{0.0};
  double fov = 60.0;
};

// Throws kInvalidInput prefixed with `where` when `cam` is degenerate (Camera::validate's words).
void check_camera(Camera cam, const std::string& where) {
  try {
    cam.validate();
  } catch (const Error& e) {
    throw_input(where + ": " + e.what());
  }
}

Vec3 json_vec3(const nlohmann::json& c, const char* name, const std::string& where) {
  const auto it = c.find(name);
  if (it == c.end() || !it->is_array() || it->size() != 3)
    throw_input(where + ": \"" + name + "\" must be a list of 3 numbers [x, y, z]");
  Vec3 v{0.0};
  for (int i = 0; i < 3; ++i) {
    const auto& x = (*it)[std::size_t(i)];
    if (!x.is_number() || !std::isfinite(x.get<double>()))
      throw_input(where + ": \"" + name + "\" must be a list of 3 finite numbers");
    v[i] = x.get<double>();
  }
  return v;
}

// --path: [{"eye":[x,y,z],"target":[x,y,z],"fov":deg}, ...] ("fov" optional: --fov).
std::vector<Key> read_path_file(const std::string& file, double default_fov) {
  std::ifstream in(file);
  if (!in) throw_input("--path " + file + ": cannot open the file");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw_input("--path " + file + ": not valid JSON (" + e.what() + ")");
  }
  if (!j.is_array() || j.empty())
    throw_input("--path " + file +
                ": expects a non-empty JSON list of {\"eye\": [x, y, z], \"target\": [x, y, z], "
                "\"fov\": degrees (optional)}");
  std::vector<Key> keys;
  for (std::size_t i = 0; i < j.size(); ++i) {
    const std::string where = "--path " + file + ": camera " + std::to_string(i);
    if (!j[i].is_object()) throw_input(where + " is not a JSON object");
    Key k{json_vec3(j[i], "eye", where), json_vec3(j[i], "target", where), default_fov};
    if (const auto f = j[i].find("fov"); f != j[i].end()) {
      if (!f->is_number()) throw_input(where + ": \"fov\" must be a number of degrees");
      k.fov = f->get<double>();
    }
    Camera cam;
    cam.eye = k.eye;
    cam.target = k.target;
    cam.fov_y_deg = k.fov;
    check_camera(cam, where);
    keys.push_back(k);
  }
  return keys;
}

double horizontal_extent(const Box3& b) {
  return std::max(b.hi.x - b.lo.x, b.hi.y - b.lo.y);
}

// One turn around the bounds' centre, a key per degree. Terrain: at 0.4 of the horizontal extent
// from the centre and 0.2 of it above the highest point, looking at the centre at mid height. A
// 3-D mesh: at 1.2 bounding radii / sin(fov / 2) from the centre (the model fills the view),
// 20 degrees above its equator, looking at the centre.
std::vector<Key> orbit_keys(const CrmrInfo& info, double fov) {
  const Box3& b = info.bounds;
  const Vec3 c = 0.5 * (b.lo + b.hi);
  const double e = horizontal_extent(b);
  double radius = 0.4 * e, height = b.hi.z + 0.2 * e;
  if (info.kind != ModelKind::kTerrain) {
    const double d = 1.2 * 0.5 * glm::length(b.hi - b.lo) / std::sin(0.5 * fov * kDegree);
    radius = d * std::cos(20.0 * kDegree);
    height = c.z + d * std::sin(20.0 * kDegree);
  }
  std::vector<Key> keys;
  for (int deg = 0; deg <= 360; ++deg) {
    const double a = deg * kDegree;
    keys.push_back({{c.x + radius * std::cos(a), c.y + radius * std::sin(a), height}, c, fov});
  }
  return keys;
}

// --line X1,Y1,Z1:X2,Y2,Z2: the eye flies from the first point to the second, looking ahead
// (along the flight's horizontal direction) and `pitch` degrees down.
std::vector<Key> line_keys(const std::string& text, double pitch, double fov, double extent) {
  const auto colon = text.find(':');
  if (colon == std::string::npos)
    throw_input("--line expects X1,Y1,Z1:X2,Y2,Z2, got '" + text + "'");
  const auto a = parse_numbers(text.substr(0, colon), 3, "--line", "X1,Y1,Z1:X2,Y2,Z2");
  const auto b = parse_numbers(text.substr(colon + 1), 3, "--line", "X1,Y1,Z1:X2,Y2,Z2");
  const Vec3 p{a[0], a[1], a[2]}, q{b[0], b[1], b[2]};
  const Vec2 h{q.x - p.x, q.y - p.y};
  if (glm::length(h) <= 0.0)
    throw_input("--line: the two eye points must differ in x or y, got '" + text + "'");
  const Vec2 u = glm::normalize(h);
  const double look = std::max(extent, 1.0);
  const Vec3 ahead{u.x * std::cos(pitch * kDegree) * look, u.y * std::cos(pitch * kDegree) * look,
                   -std::sin(pitch * kDegree) * look};
  return {{p, p + ahead, fov}, {q, q + ahead, fov}};
}

struct Sampled {
  std::vector<Key> cams;
  double step = 0.0;  // between frames, in model units along the eye's path
};

// The frames' cameras: interpolated along the keys by the eye's arc length (by key index when
// the eye does not move), linearly in eye, target and fov, `step` apart (held at the end).
Sampled sample_path(const std::vector<Key>& keys, const FlythroughArgs& a, double extent) {
  std::vector<double> at{0.0};  // cumulative arc length at each key
  for (std::size_t i = 1; i < keys.size(); ++i)
    at.push_back(at.back() + glm::length(keys[i].eye - keys[i - 1].eye));
  if (at.back() <= 0.0) {
    for (std::size_t i = 0; i < keys.size(); ++i) at[i] = double(i);
  }
  const double total = at.back();
  double step = (a.speed ? *a.speed : kWalkingFraction * extent) / a.fps;
  std::uint64_t frames = a.frames;
  if (a.frames != 0 && !a.speed) {
    step = frames > 1 ? total / double(frames - 1) : 0.0;
  } else if (frames == 0) {
    const double n = step > 0.0 ? std::floor(total / step + 1e-9) + 1.0 : 1.0;
    if (n > 1e6) throw_input("the path would take over a million frames: pass --frames");
    frames = std::uint64_t(n);
  }
  Sampled out;
  out.step = step;
  std::size_t seg = 1;
  for (std::uint64_t f = 0; f < frames; ++f) {
    const double s = std::min(double(f) * step, total);
    if (keys.size() == 1) {
      out.cams.push_back(keys[0]);
      continue;
    }
    while (seg + 1 < keys.size() && at[seg] < s) ++seg;
    const double len = at[seg] - at[seg - 1];
    const double u = len > 0.0 ? std::clamp((s - at[seg - 1]) / len, 0.0, 1.0) : 1.0;
    const Key& k0 = keys[seg - 1];
    const Key& k1 = keys[seg];
    out.cams.push_back({k0.eye + u * (k1.eye - k0.eye), k0.target + u * (k1.target - k0.target),
                        k0.fov + u * (k1.fov - k0.fov)});
  }
  return out;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto rank = std::size_t(std::ceil(q * double(v.size())));
  return v[std::min(v.size() - 1, rank == 0 ? 0 : rank - 1)];
}

nlohmann::json spread(const std::vector<double>& v) {
  double sum = 0.0;
  for (double x : v) sum += x;
  return {{"p50", percentile(v, 0.50)},
          {"p95", percentile(v, 0.95)},
          {"p99", percentile(v, 0.99)},
          {"max", percentile(v, 1.0)},
          {"mean", v.empty() ? 0.0 : sum / double(v.size())}};
}

// Everything the frames share: the database, its index, the session and the flags.
struct Flight {
  const Database& db;
  const IndexedSource& source;
  Session& session;
  const FlythroughArgs& args;
  int viewport_w, viewport_h;
  bool verify;
};

Rcf frame_rcf(const Flight& f, const Key& k) {
  RcfSpec s;
  Camera cam;
  cam.eye = k.eye;
  cam.target = k.target;
  cam.fov_y_deg = k.fov;
  cam.viewport_w = f.viewport_w;
  cam.viewport_h = f.viewport_h;
  s.camera = cam;
  s.cull = !f.args.no_cull;
  s.pixel_error = f.args.pixel_error;
  validate(s);
  return make_rcf(s, f.db.info(), nullptr);
}

// The fresh extraction of `rcf` (the set formula page by page: the fastest from scratch), timed,
// and whether it agrees with the session when the update was complete.
void compare_fresh(const Flight& f, const Rcf& rcf, const FrameStats& st, nlohmann::json& rec) {
  ExpansionOptions options;
  options.fronts = false;
  const auto t0 = Clock::now();
  Extraction e = extract_minimal_surface(f.source, rcf, options);
  rec["fresh_ms"] = 1000.0 * seconds_since(t0);
  rec["fresh_triangles"] = e.triangles.size();
  rec["fresh_x"] = e.x.size();
  if (!st.complete) return;
  bool match = e.triangles.size() == st.triangles && e.x.size() == st.x;
  if (match && f.verify) {  // the triangle sets themselves
    std::vector<TriRef> mine(f.session.triangles().begin(), f.session.triangles().end());
    std::sort(mine.begin(), mine.end());
    std::sort(e.triangles.begin(), e.triangles.end());
    match = mine == e.triangles;
  }
  rec["fresh_match"] = match;
}

// One frame: the update towards `k`'s RCF within `budget`, and its record.
nlohmann::json fly_frame(const Flight& f, const Key& k, const SessionBudget& budget) {
  const Rcf rcf = frame_rcf(f, k);
  const std::uint64_t pages_before = f.db.stats().pages_read;
  const Frame frame = f.session.update(rcf, budget);
  const std::uint64_t pages_read = f.db.stats().pages_read - pages_before;
  const FrameStats& s = frame.stats;
  nlohmann::json rec = s;
  rec.update({{"eye", {k.eye.x, k.eye.y, k.eye.z}}, {"pages_read", pages_read}});
  if (f.args.compare_fresh) compare_fresh(f, rcf, s, rec);
  return rec;
}

void write_frame_png(const Flight& f, std::uint64_t frame) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%04llu.png", static_cast<unsigned long long>(frame));
  RenderOptions ro;
  ro.geographic = f.db.info().georef.geographic;
  render_png((std::filesystem::path(f.args.png_dir) / name).string(), f.session.mesh(), ro);
}

// The summary over the frames after the first (the first is a cold extraction from R^0).
nlohmann::json summarize(const nlohmann::json& frames, const Flight& f) {
  std::vector<double> update, fresh, pct;
  std::uint64_t mismatches = 0, incomplete = 0, pages = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const auto& r = frames[i];
    pages += r["pages_read"].get<std::uint64_t>();
    if (!r["complete"].get<bool>()) ++incomplete;
    if (r.contains("fresh_match") && !r["fresh_match"].get<bool>()) ++mismatches;
    if (i == 0 && frames.size() > 1) continue;
    update.push_back(r["update_ms"].get<double>());
    pct.push_back(r["local_morphs_pct"].get<double>());
    if (r.contains("fresh_ms")) fresh.push_back(r["fresh_ms"].get<double>());
  }
  nlohmann::json s = {{"frames", frames.size()},
                      {"incomplete_frames", incomplete},
                      {"first_frame_ms", frames[0]["update_ms"]},
                      {"update_ms", spread(update)},
                      {"local_morphs_pct", spread(pct)},
                      {"pages_read", pages},
                      {"session_mib", double(f.session.memory_bytes()) / double(1 << 20)},
                      {"cache_mib", f.args.cache_mb}};
  if (f.args.compare_fresh) {
    s["fresh_ms"] = spread(fresh);
    s["fresh_mismatches"] = mismatches;
    const double up50 = s["update_ms"]["p50"].get<double>();
    const double up_mean = s["update_ms"]["mean"].get<double>();
    s["fresh_over_update_p50"] = up50 > 0.0 ? s["fresh_ms"]["p50"].get<double>() / up50 : 0.0;
    s["fresh_over_update_mean"] =
        up_mean > 0.0 ? s["fresh_ms"]["mean"].get<double>() / up_mean : 0.0;
  }
  s["peak_rss_mib"] = peak_rss_mb();
  return s;
}

void print_summary(const std::string& db_path, const nlohmann::json& s) {
  std::fprintf(stderr, "%s: %llu frames, update p50 %.3f ms p99 %.3f ms max %.3f ms, first %.1f ms",
               db_path.c_str(), static_cast<unsigned long long>(s["frames"].get<std::uint64_t>()),
               s["update_ms"]["p50"].get<double>(), s["update_ms"]["p99"].get<double>(),
               s["update_ms"]["max"].get<double>(), s["first_frame_ms"].get<double>());
  if (s.contains("fresh_ms")) {
    std::fprintf(stderr, "; fresh p50 %.3f ms (x%.1f), %llu mismatches",
                 s["fresh_ms"]["p50"].get<double>(), s["fresh_over_update_p50"].get<double>(),
                 static_cast<unsigned long long>(s["fresh_mismatches"].get<std::uint64_t>()));
  }
  std::fprintf(stderr, "; local morphs p50 %.2f %% max %.2f %% of |X|; peak RSS %.0f MiB\n",
               s["local_morphs_pct"]["p50"].get<double>(),
               s["local_morphs_pct"]["max"].get<double>(), s["peak_rss_mib"].get<double>());
}

}  // namespace

void FlythroughArgs::add_to(CLI::App& app) {
  app.add_option("--path", path,
                 "Camera path: a JSON list of {\"eye\":[x,y,z],\"target\":[x,y,z],\"fov\":deg}");
  app.add_flag("--orbit", orbit, "Fly one turn around the model's bounds centre");
  app.add_option("--line", line, "Fly straight between two eye points X1,Y1,Z1:X2,Y2,Z2");
  app.add_flag("--keyframes", keyframes,
               "One frame per camera of --path, no interpolation (ignores --frames, --speed)");
  app.add_option("--frames", frames,
                 "Number of frames (default: the path's length at --speed; without --speed the "
                 "frames span the whole path)");
  app.add_option("--fps", fps, "Frames per second (with --speed: the distance between frames)")
      ->capture_default_str();
  app.add_option("--speed", speed,
                 "Eye speed in model units per second (default: walking, 1 % of the model's "
                 "horizontal extent per second)");
  app.add_option("--pitch", pitch, "--line: degrees the camera looks down")->capture_default_str();
  app.add_option("--max-period", max_period_ms,
                 "Maximum geomorphing period per update in ms (Brown 6.3; 0 = none)")
      ->capture_default_str();
  app.add_flag("--settle", settle,
               "After the path, one more update at the last camera without the period");
  app.add_option("--pixel-error", pixel_error, "Screen-space tolerance in pixels")
      ->capture_default_str();
  app.add_option("--viewport", viewport, "Viewport size WxH in pixels")->capture_default_str();
  app.add_option("--fov", fov, "Vertical field of view in degrees (cameras without one)")
      ->capture_default_str();
  app.add_flag("--no-cull", no_cull, "Disable view-frustum and back-face culling");
  app.add_flag("--no-morph", no_morph, "Do not build the frames' morphs (SessionOptions::morph)");
  app.add_option("--cache-mb", cache_mb, "Page cache budget in MiB")->capture_default_str();
  app.add_option("--png-dir", png_dir, "Write a top-down picture of the mesh per frame here");
  app.add_option("--png-every", png_every, "With --png-dir: every k-th frame")
      ->capture_default_str();
  app.add_flag("--compare-fresh", compare_fresh,
               "Also extract each frame's RCF from scratch: its time, and whether it agrees");
}

void FlythroughArgs::validate() const {
  const int sources = int(!path.empty()) + int(orbit) + int(!line.empty());
  if (sources != 1) throw_input("flythrough needs exactly one of --path, --orbit and --line");
  if (keyframes && path.empty()) throw_input("--keyframes needs --path");
  if (!(fps > 0.0) || !std::isfinite(fps)) throw_input("--fps must be a positive number");
  if (speed && (!(*speed > 0.0) || !std::isfinite(*speed)))
    throw_input("--speed must be a positive number of model units per second");
  if (!(pitch > -90.0 && pitch < 90.0)) throw_input("--pitch must be in (-90, 90) degrees");
  if (!(max_period_ms >= 0.0) || !std::isfinite(max_period_ms))
    throw_input("--max-period must be >= 0 ms");
  if (!(pixel_error > 0.0) || !std::isfinite(pixel_error))
    throw_input("--pixel-error must be a positive number of pixels");
  if (cache_mb < 1 || cache_mb > (std::uint64_t{1} << 20))
    throw_input("--cache-mb must be in [1, 1048576]");
  if (png_every < 1) throw_input("--png-every must be at least 1");
  if (frames > 10'000'000) throw_input("--frames must be at most 10000000");
}

int cmd_flythrough(const std::string& db_path, const FlythroughArgs& a, const CommonFlags& flags) {
  a.validate();
  const auto [vw, vh] = parse_viewport(a.viewport, "--viewport");
  std::vector<Key> keys = a.path.empty() ? std::vector<Key>{} : read_path_file(a.path, a.fov);
  const auto t0 = Clock::now();
  const auto db = Database::open(db_path, {std::size_t(a.cache_mb) << 20});
  const CrmrInfo& info = db->info();
  const double extent =
      std::max(horizontal_extent(info.bounds), info.bounds.hi.z - info.bounds.lo.z);
  if (a.orbit) keys = orbit_keys(info, a.fov);
  if (!a.line.empty()) keys = line_keys(a.line, a.pitch, a.fov, extent);
  const Sampled sampled = a.keyframes ? Sampled{keys, 0.0} : sample_path(keys, a, extent);
  const std::vector<Key>& cams = sampled.cams;
  if (!a.png_dir.empty()) std::filesystem::create_directories(a.png_dir);
  const IndexedSource source(*db);
  Session session(source, SessionOptions{.morph = !a.no_morph});
  const Flight f{*db, source, session, a, vw, vh, flags.verify};
  SessionBudget budget;
  budget.max_period_ms = a.max_period_ms;
  nlohmann::json frames = nlohmann::json::array();
  ProgressBar bar(flags.quiet ? nullptr : stderr);
  for (std::size_t i = 0; i < cams.size(); ++i) {
    nlohmann::json rec = {{"frame", i}};
    rec.update(fly_frame(f, cams[i], budget));
    if (i == 0) rec["open_to_first_frame_ms"] = 1000.0 * seconds_since(t0);
    frames.push_back(std::move(rec));
    if (!a.png_dir.empty() && i % a.png_every == 0) write_frame_png(f, i);
    bar.update(double(i + 1) / double(cams.size()));
  }
  bar.done();
  nlohmann::json report;
  report["database"] = db_path;
  report["flight"] = {{"source", !a.path.empty() ? "path"
                                 : a.orbit       ? "orbit"
                                                 : "line"},
                      {"keys", keys.size()},
                      {"fps", a.fps},
                      {"step", sampled.step},
                      {"speed", sampled.step * a.fps},
                      {"max_period_ms", a.max_period_ms},
                      {"pixel_error", a.pixel_error},
                      {"viewport", a.viewport},
                      {"cull", !a.no_cull},
                      {"morph", !a.no_morph}};
  report["summary"] = summarize(frames, f);
  report["summary"]["open_to_first_frame_ms"] = frames[0]["open_to_first_frame_ms"];
  if (a.settle) report["settle"] = fly_frame(f, cams.back(), SessionBudget{});
  report["io"] = db->stats();
  report["frames"] = std::move(frames);
  print_report(report, flags.json);
  if (!flags.quiet) print_summary(db_path, report["summary"]);
  return 0;
}

}  // namespace smr::tools
