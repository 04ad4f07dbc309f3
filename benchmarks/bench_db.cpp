// bench_db: I/O benchmarks of the on-disk database (docs/design.md sections 3, 5, 6, 8.7). Prints
// one JSON object. Modes:
//
//   extract DB   For one view (a named camera placed relative to the database's bounds, or an
//                explicit --eye/--target) and each --pixel-error and algorithm (minimal surface,
//                its triangles by the set formula, "minimal-pages", and reduced extraction from the
//                R-tree):
//                - read amplification: bytes fetched from LMDB (pages, R-tree nodes, op locators)
//                  / bytes of the pages the output needs. A page is *needed* when some output
//                  triangle (void ones included) belongs to one of its ops; a page is *touched*
//                  when the extraction fetched it (recorded through a forwarding OpSource, and
//                  checked against pages_read of a run whose cache holds everything);
//                - times: cold (the file dropped from the OS page cache with
//                  posix_fadvise(POSIX_FADV_DONTNEED), then a fresh Database), warm (fresh
//                  Database, file in the OS page cache; median of --repeat), hot (the same Database
//                  again: decoded pages in its cache; median);
//                - the physical limit: reading the same data pages from LMDB without decoding
//                  (cold and warm), and the ratio extraction time / raw read time.
//   codecs DEM   Builds the CRMR of a DEM (or --fbm N) once, writes one database per codec (raw,
//                zstd, draco) and measures on every real page: geometry bytes per vertex and per
//                triangle, decode_geometry throughput (MB/s of input, triangles/s) and whole-page
//                decode_page throughput, and the database's total bytes per model vertex.
//   decode DB    decode_page alone on the real pages of a built database (every --stride-th
//                page, copied out of LMDB first): microseconds per page and nanoseconds per op,
//                the figure page-format work is judged by; --keep holds every page of a pass, so
//                each is decoded into fresh memory as in a first view (not into the last one's);
//                and bytes per model vertex of the leaves, records (by stream) and geometry.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <unordered_set>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "benchmarks/bench_common.h"
#include "benchmarks/bench_db_common.h"
#include "smr/builders/terrain/greedy_tin.h"
#include "smr/db/database.h"
#include "smr/db/page.h"
#include "smr/db/tables.h"
#include "smr/db/writer.h"
#include "smr/extract/extract.h"
#include "smr/query/indexed_source.h"
#include "smr/rcf/spec.h"
#include "storage/checksum.h"
#include "storage/codec.h"
#include "storage/lmdb_env.h"
#include "tools/report_json.h"

namespace {

using nlohmann::json;
using smr::bench::camera_json;
using smr::bench::drop_from_page_cache;
using smr::bench::median;
using smr::bench::named_camera;
using smr::bench::now_ns;
using smr::bench::parse_vec3;
using smr::bench::resident_bytes;
using smr::bench::seconds_since;
using smr::bench::vec3_json;

// ---- recording which ops and pages an extraction fetches -----------------------------------

class AllVisitor final : public smr::index::Visitor {
 public:
  bool enter(const smr::index::Summary&) override { return true; }
  bool accept(const smr::index::Entry&) override { return true; }
};

// Forwards to the database's IndexedSource and records, in order, every op fetched and every
// R-tree leaf the indexed X query reads.
class RecordingSource final : public smr::OpSource, public smr::RcfIndexedSource {
 public:
  explicit RecordingSource(const smr::Database& db) : db_(db) {}
  const smr::CrmrInfo& info() const override { return db_.info(); }
  std::uint64_t op_count() const override { return db_.op_count(); }
  smr::OpRef op(smr::OpId id) const override {
    ops.push_back(id.value);
    return db_.op(id);
  }
  void need_links() const override { db_.need_links(); }
  std::vector<smr::OpId> not_completely_finer(const smr::RcfOracle& rcf) const override {
    for (const smr::index::Hit& h : db_.rcf_hits(rcf)) {
      if (leaves.empty() || leaves.back() != h.leaf) leaves.push_back(h.leaf);
    }
    return db_.not_completely_finer(rcf);
  }
  smr::CandidateOps maybe_not_completely_finer(const smr::RcfOracle& rcf,
                                               bool /*read_ahead*/) const override {
    // Reads no page, and has none read ahead: the pages counted are those the extraction reads.
    return db_.maybe_not_completely_finer(rcf, false);
  }
  mutable std::vector<std::uint64_t> ops;
  mutable std::vector<std::uint64_t> leaves;

 private:
  const smr::IndexedSource db_;
};

// ---- mode: extract --------------------------------------------------------------------------

struct ExtractArgs {
  std::string db, view = "oblique", eye, target;
  double fov = 60.0, far = 0.0;
  int vw = 1024, vh = 768;
  std::vector<double> pixel_errors{1.0, 4.0};
  std::vector<std::string> algorithms{"minimal", "reduced"};
  std::uint64_t cache_mb = 64;
  int repeat = 5;
  bool cold = true, raw = true;
};

struct Timed {
  smr::Extraction e;
  std::size_t mesh_vertices = 0, mesh_triangles = 0;
  double open_seconds = 0, extract_seconds = 0, mesh_seconds = 0;
  smr::DatabaseStats stats;
  std::uint64_t pages_read_to_mesh = 0;  // of stats.pages_read, by to_mesh
};

// One extraction by algorithm `alg`: minimal (advancing front), minimal-pages (its triangles by
// the set formula, ExpansionOptions::fronts false) or reduced.
smr::Extraction extract_by(const smr::OpSource& source, const smr::Rcf& rcf,
                           const std::string& alg) {
  if (alg == "reduced") return smr::extract_reduced(source, rcf);
  return smr::extract_minimal_surface(source, rcf, {.fronts = alg == "minimal"});
}

Timed run_extraction(const smr::Database& db, const smr::Rcf& rcf, const std::string& alg) {
  Timed t;
  std::uint64_t t0 = now_ns();
  const smr::IndexedSource source(db);
  t.e = extract_by(source, rcf, alg);
  t.extract_seconds = seconds_since(t0);
  const std::uint64_t pages_before_mesh = db.stats().pages_read;
  t0 = now_ns();
  const smr::TriangleMesh mesh = smr::to_mesh(db, t.e.triangles);
  t.mesh_seconds = seconds_since(t0);
  t.pages_read_to_mesh = db.stats().pages_read - pages_before_mesh;
  t.mesh_vertices = mesh.positions.size();
  t.mesh_triangles = mesh.triangles.size();
  t.stats = db.stats();
  return t;
}

// One run on a fresh Database (opening it timed); `keep`, when given, receives that Database.
Timed fresh_run(const ExtractArgs& a, const smr::Rcf& rcf, const std::string& alg,
                std::unique_ptr<smr::Database>* keep = nullptr) {
  const std::uint64_t t0 = now_ns();
  auto db = smr::Database::open(a.db, {std::size_t(a.cache_mb) << 20});
  const double open = seconds_since(t0);
  Timed t = run_extraction(*db, rcf, alg);
  t.open_seconds = open;
  if (keep) *keep = std::move(db);
  return t;
}

// Reads the given data pages from LMDB and touches every byte, without decoding. Seconds.
double raw_read(const std::string& path, const std::vector<std::uint64_t>& pages,
                std::uint64_t* bytes) {
  const std::uint64_t t0 = now_ns();
  const smr::storage::Env env = smr::storage::Env::open_read_only(path, smr::kTableNames);
  const smr::storage::ReadTxn txn = env.read();
  std::uint64_t sum = 0, total = 0;
  for (std::uint64_t p : pages) {
    const auto v = txn.get(smr::Table::kPages, p);
    if (!v) smr::throw_internal("raw read: page " + std::to_string(p) + " missing");
    total += v->size();
    for (std::size_t i = 0; i < v->size(); i += 64) sum += (*v)[i];
    sum += (*v)[v->size() - 1];
  }
  const double s = seconds_since(t0);
  if (sum == 1) std::fprintf(stderr, " ");  // keep the reads
  *bytes = total;
  return s;
}

// Where each op lives and how large each page is.
struct PageIndex {
  smr::CrmrInfo info;
  std::vector<std::uint32_t> page_of;    // op id -> page
  std::vector<std::uint64_t> page_size;  // page -> bytes
  std::uint64_t all_page_bytes = 0;
};

PageIndex read_page_index(const smr::Database& db, const std::string& path) {
  PageIndex index;
  index.info = db.info();
  index.page_of.assign(db.op_count(), ~0u);
  AllVisitor all;
  for (const smr::index::Hit& h : db.rtree().query(all)) index.page_of.at(h.id) = h.leaf;
  index.page_size.assign(db.page_count(), 0);
  const smr::storage::Env env = smr::storage::Env::open_read_only(path, smr::kTableNames);
  const smr::storage::ReadTxn txn = env.read();
  for (std::uint64_t p = 0; p < index.page_size.size(); ++p) {
    // The page part of the value (its leaf is the R-tree's: DatabaseStats counts it there).
    index.page_size[p] =
        smr::split_page_value(*txn.get(smr::Table::kPages, p), "pages", std::to_string(p))
            .page.size();
    index.all_page_bytes += index.page_size[p];
  }
  return index;
}

// Per record stream: raw bytes and bytes compressed alone per page (what a field costs).
using StreamBytes = std::map<std::string, std::pair<std::uint64_t, std::uint64_t>>;

void add_streams(StreamBytes& streams, smr::storage::ByteView payload, const std::string& context) {
  for (const auto& [stream, bytes] : smr::page_record_streams(payload, context)) {
    streams[stream].first += bytes.size();
    if (!bytes.empty()) streams[stream].second += smr::storage::zstd_compress(bytes).size();
  }
}

// Per record stream: raw and alone-compressed bytes per model vertex.
json streams_json(const StreamBytes& streams, std::uint64_t vertices) {
  json out = json::object();
  for (const auto& [name, bytes] : streams) {
    out[name] = {{"raw", double(bytes.first) / double(vertices)},
                 {"zstd", double(bytes.second) / double(vertices)}};
  }
  return out;
}

json database_json(const smr::Database& db, const std::string& path, const PageIndex& index) {
  const smr::CrmrInfo& info = index.info;
  const json meta = json::parse(db.meta_json());
  return {{"path", path},
          {"file_bytes", db.file_bytes()},
          {"samples", std::uint64_t(info.grid_width) * std::uint64_t(info.grid_height)},
          {"grid", {info.grid_width, info.grid_height}},
          {"spacing", info.georef.dx},
          {"vertices", info.vertex_count},
          {"ops", db.op_count()},
          {"triangles", meta["counts"]["triangles"]},
          {"pages", db.page_count()},
          {"page_bytes", index.all_page_bytes},
          {"mean_page_bytes", double(index.all_page_bytes) / double(index.page_size.size())},
          {"rtree_height", db.rtree().height()},
          {"codec", meta["codec"]},
          {"err0", info.err0},
          {"err_final", info.err_final},
          {"bounds", {vec3_json(info.bounds.lo), vec3_json(info.bounds.hi)}}};
}

// The op -> page map, page sizes and counts (out["db"]), from a separate instance: its reads do
// not count, and it is closed before any measurement so that it maps nothing the cold runs must
// drop.
PageIndex index_database(const ExtractArgs& a, json& out) {
  const auto db = smr::Database::open(a.db, {std::size_t{256} << 20});
  PageIndex index = read_page_index(*db, a.db);
  out["db"] = database_json(*db, a.db, index);
  return index;
}

// The named view, or the explicit --eye/--target (out["view"], out["camera"]).
smr::Camera view_camera(const ExtractArgs& a, const smr::Box3& bounds, json& out) {
  smr::Camera cam;
  if (!a.eye.empty() || !a.target.empty()) {
    cam.eye = parse_vec3(a.eye, "--eye");
    cam.target = parse_vec3(a.target, "--target");
    out["view"] = "explicit";
  } else {
    cam = named_camera(a.view, bounds);
    out["view"] = a.view;
  }
  cam.fov_y_deg = a.fov;
  cam.viewport_w = a.vw;
  cam.viewport_h = a.vh;
  cam.far_distance = a.far;
  out["camera"] = camera_json(cam);
  return cam;
}

// The timed runs of one case.
struct CaseTimes {
  std::optional<Timed> cold;
  Timed first;  // the first warm run: its statistics are the ones reported
  std::vector<double> warm_extract, warm_total, hot_extract;
};

// Cold (the file dropped from the OS page cache first, then a fresh process-like Database), warm
// (a fresh Database each time, the file in the OS page cache) and hot (the last warm Database
// again: its cache holds what fits of the pages it decoded).
CaseTimes time_case(const ExtractArgs& a, const smr::Rcf& rcf, const std::string& alg, json& c) {
  CaseTimes t;
  if (a.cold) {
    c["resident_bytes_after_drop"] = drop_from_page_cache(a.db);
    t.cold = fresh_run(a, rcf, alg);
    c["resident_bytes_after_cold_run"] = resident_bytes(a.db);
  }
  std::unique_ptr<smr::Database> keep;
  for (int i = 0; i < a.repeat; ++i) {
    Timed run = fresh_run(a, rcf, alg, i + 1 == a.repeat ? &keep : nullptr);
    t.warm_extract.push_back(run.extract_seconds);
    t.warm_total.push_back(run.open_seconds + run.extract_seconds + run.mesh_seconds);
    if (i == 0) t.first = std::move(run);
  }
  for (int i = 0; i < a.repeat; ++i)
    t.hot_extract.push_back(run_extraction(*keep, rcf, alg).extract_seconds);
  return t;
}

// Needed pages (those holding an op of an output triangle) against touched pages (every page the
// extraction fetched, recorded through RecordingSource on a Database with an unbounded cache).
struct PageUse {
  std::set<std::uint64_t> needed;
  std::uint64_t needed_bytes = 0;
  std::vector<std::uint64_t> touched;  // in the order first fetched
  std::uint64_t touched_bytes = 0;
  smr::DatabaseStats unbounded;  // the recorded run's statistics
};

PageUse page_use(const ExtractArgs& a, const PageIndex& index, const smr::Rcf& rcf,
                 const std::string& alg, const smr::Extraction& e) {
  PageUse u;
  for (const smr::TriRef& t : e.triangles) u.needed.insert(index.page_of.at(t.op.value));
  for (std::uint64_t p : u.needed) u.needed_bytes += index.page_size[p];
  const auto big = smr::Database::open(a.db, {std::size_t{1} << 40});
  RecordingSource rec(*big);
  const smr::Extraction re = extract_by(rec, rcf, alg);
  (void)smr::to_mesh(rec, re.triangles);
  std::unordered_set<std::uint64_t> seen;
  auto touch = [&](std::uint64_t p) {
    if (seen.insert(p).second) u.touched.push_back(p);
  };
  // not_completely_finer reads its leaves before any op is fetched through op().
  for (std::uint64_t l : rec.leaves) touch(l);
  for (std::uint64_t id : rec.ops) touch(index.page_of.at(id));
  for (std::uint64_t p : u.touched) u.touched_bytes += index.page_size[p];
  u.unbounded = big->stats();
  return u;
}

std::uint64_t output_triangles(const smr::ExtractStats& s) {
  return s.triangles - s.void_triangles;
}

// The output's size; the extraction's counters as tools/report_json.h writes them.
json output_json(const Timed& first) {
  const json stats = first.e.stats;
  json j = {{"triangles", output_triangles(first.e.stats)},
            {"mesh_vertices", first.mesh_vertices},
            {"mesh_triangles", first.mesh_triangles}};
  for (const char* key :
       {"void_triangles", "x", "x_plus", "ops_visited", "held_ops_peak", "held_bytes_peak"})
    j[key] = stats.at(key);
  return j;
}

json pages_json(const PageUse& u, const Timed& first, const PageIndex& index) {
  return {{"needed", u.needed.size()},
          {"needed_bytes", u.needed_bytes},
          {"touched", u.touched.size()},
          {"touched_bytes", u.touched_bytes},
          {"touched_check_ok", u.touched.size() == u.unbounded.pages_read},
          {"read", first.stats.pages_read},
          {"of_database", index.page_size.size()}};
}

// Every byte read of LMDB's values (pages, R-tree nodes including the leaves at the head of the
// pages values, op locators: DatabaseStats::lmdb_bytes_read) over the bytes of the needed pages.
double lmdb_over_needed(const PageUse& u, const Timed& first) {
  return double(first.stats.lmdb_bytes_read) / double(std::max<std::uint64_t>(1, u.needed_bytes));
}

json amplification_json(const PageUse& u, const Timed& first) {
  const double needed_bytes = double(std::max<std::uint64_t>(1, u.needed_bytes));
  return {{"lmdb_bytes_over_needed", lmdb_over_needed(u, first)},
          {"page_bytes_over_needed", double(first.stats.page_bytes_read) / needed_bytes},
          {"touched_over_needed_pages",
           double(u.touched.size()) / double(std::max<std::size_t>(1, u.needed.size()))},
          {"touched_over_needed_bytes", double(u.touched_bytes) / needed_bytes},
          {"index_and_locator_bytes", first.stats.lmdb_bytes_read - first.stats.page_bytes_read}};
}

json seconds_json(const CaseTimes& t) {
  const smr::ExtractStats& s = t.first.e.stats;
  json j = {{"warm_extract", median(t.warm_extract)}, {"warm_extract_all", t.warm_extract},
            {"warm_total", median(t.warm_total)},     {"open", t.first.open_seconds},
            {"to_mesh", t.first.mesh_seconds},        {"extraction_phase", s.extract_seconds},
            {"expansion_phase", s.expand_seconds},    {"hot_extract", median(t.hot_extract)}};
  if (t.cold) {
    j["cold_extract"] = t.cold->extract_seconds;
    j["cold_total"] = t.cold->open_seconds + t.cold->extract_seconds + t.cold->mesh_seconds;
    j["cold_over_warm"] = t.cold->extract_seconds / median(t.warm_extract);
  }
  return j;
}

// The physical limit: the touched pages read from LMDB without decoding, cold and warm.
json raw_read_json(const ExtractArgs& a, const std::vector<std::uint64_t>& pages,
                   const CaseTimes& t) {
  std::uint64_t bytes = 0;
  json r;
  if (a.cold) {
    r["resident_bytes_after_drop"] = drop_from_page_cache(a.db);
    r["cold_seconds"] = raw_read(a.db, pages, &bytes);
  }
  std::vector<double> warm;
  for (int i = 0; i < a.repeat; ++i) warm.push_back(raw_read(a.db, pages, &bytes));
  r["warm_seconds"] = median(warm);
  r["pages"] = pages.size();
  r["bytes"] = bytes;
  r["warm_mb_per_s"] = double(bytes) / 1e6 / std::max(1e-12, median(warm));
  r["warm_extract_over_raw"] = median(t.warm_extract) / std::max(1e-12, median(warm));
  if (a.cold) {
    const double cold = r["cold_seconds"].get<double>();
    r["cold_mb_per_s"] = double(bytes) / 1e6 / std::max(1e-12, cold);
    r["cold_extract_over_raw"] = t.cold->extract_seconds / std::max(1e-12, cold);
  }
  return r;
}

void print_case(const CaseTimes& t, const PageUse& u) {
  std::fprintf(stderr,
               "    |F| %llu  pages needed %zu touched %zu read %llu  lmdb/needed %.2f  warm "
               "%.3fs%s\n",
               static_cast<unsigned long long>(output_triangles(t.first.e.stats)), u.needed.size(),
               u.touched.size(), static_cast<unsigned long long>(t.first.stats.pages_read),
               lmdb_over_needed(u, t.first), median(t.warm_extract),
               t.cold ? (", cold " + std::to_string(t.cold->extract_seconds) + "s").c_str() : "");
}

// One view x pixel error x algorithm: times, page use, amplification, raw read.
json run_case(const ExtractArgs& a, const PageIndex& index, const smr::Rcf& rcf, double px,
              const std::string& alg, const std::string& view) {
  if (alg != "minimal" && alg != "minimal-pages" && alg != "reduced")
    smr::throw_input("--algorithms: unknown algorithm '" + alg +
                     "' (minimal, minimal-pages, reduced)");
  std::fprintf(stderr, "  %s %gpx %s\n", view.c_str(), px, alg.c_str());
  json c = {{"pixel_error", px}, {"algorithm", alg}};
  const CaseTimes t = time_case(a, rcf, alg, c);
  const PageUse u = page_use(a, index, rcf, alg, t.first.e);
  c["output"] = output_json(t.first);
  c["io"] = json(t.first.stats);
  c["io"]["pages_read_to_mesh"] = t.first.pages_read_to_mesh;
  c["io_unbounded_cache"] = json(u.unbounded);
  c["pages"] = pages_json(u, t.first, index);
  c["amplification"] = amplification_json(u, t.first);
  c["seconds"] = seconds_json(t);
  c["triangles_per_second_warm"] =
      double(output_triangles(t.first.e.stats)) / std::max(1e-12, median(t.warm_extract));
  if (a.raw) c["raw_read"] = raw_read_json(a, u.touched, t);
  print_case(t, u);
  return c;
}

json mode_extract(const ExtractArgs& a) {
  std::fprintf(stderr, "bench_db extract %s\n", a.db.c_str());
  json out = {{"mode", "extract"}, {"cache_mb", a.cache_mb}, {"repeat", a.repeat}};
  const PageIndex index = index_database(a, out);
  out["machine"] = smr::bench::machine_json();
  const smr::Camera cam = view_camera(a, index.info.bounds, out);
  json cases = json::array();
  for (double px : a.pixel_errors) {
    smr::RcfSpec spec;
    spec.camera = cam;
    spec.pixel_error = px;
    smr::validate(spec);
    const smr::Rcf rcf = smr::make_rcf(spec, index.info.kind, nullptr);
    for (const std::string& alg : a.algorithms)
      cases.push_back(run_case(a, index, rcf, px, alg, out["view"].get<std::string>()));
  }
  out["cases"] = cases;
  return out;
}

// ---- mode: codecs ---------------------------------------------------------------------------

struct CodecArgs {
  std::string dem, work_dir = "build/bench-db";
  int fbm = 0;
  std::uint64_t seed = 1;
  double max_error = 0.0, max_error_fraction = 0.0;
  std::vector<std::string> codecs{"raw", "zstd", "draco"};
  double min_seconds = 0.5;
  std::string name;
};

// Runs `pass` (one pass over every page) until `min_seconds` have elapsed; seconds per pass.
template <class F>
double time_passes(double min_seconds, F&& pass) {
  int passes = 0;
  const std::uint64_t t0 = now_ns();
  do {
    pass();
    ++passes;
  } while (seconds_since(t0) < min_seconds);
  return seconds_since(t0) / passes;
}

json mode_codecs(const CodecArgs& a) {
  smr::bench::InputOptions in;
  in.path = a.dem;
  in.fbm_size = a.fbm;
  in.seed = a.seed;
  const smr::bench::Input input = smr::bench::load_input(in);
  const double max_error =
      a.max_error > 0 ? a.max_error : a.max_error_fraction * (input.z_max - input.z_min);
  std::fprintf(stderr, "bench_db codecs %s: building at max error %g\n", a.name.c_str(), max_error);
  smr::GreedyTinOptions bo;
  bo.max_error = max_error;
  std::uint64_t t0 = now_ns();
  smr::Crmr crmr = smr::build_greedy_tin(input.dem, bo);
  const double build_seconds = seconds_since(t0);
  std::uint64_t fragment_triangles = 0, finest = 0;
  for (const smr::Op& op : crmr.ops) {
    fragment_triangles += op.fragment.size();
    for (const auto& t : op.fragment) finest += !t.killer.valid() && !t.is_void();
  }
  const std::uint64_t vertices = crmr.header.vertex_count;
  json out = {{"mode", "codecs"},
              {"name", a.name},
              {"input", input.description},
              {"max_error", max_error},
              {"crmr",
               {{"vertices", vertices},
                {"ops", crmr.ops.size()},
                {"fragment_triangles", fragment_triangles},
                {"finest_triangles", finest},
                {"build_seconds", build_seconds}}},
              {"machine", smr::bench::machine_json()}};
  std::filesystem::create_directories(a.work_dir);
  json codecs = json::object();
  for (const std::string& name : a.codecs) {
    const auto codec = smr::storage::parse_codec(name);
    if (!codec) smr::throw_input("unknown codec " + name);
    const std::string path = a.work_dir + "/" + a.name + "." + name + ".smrdb";
    smr::WriteOptions wo;
    wo.codec = *codec;
    wo.force = true;
    const smr::WriteReport w = smr::write_database(crmr, path, wo);
    const auto db = smr::Database::open(path, {std::size_t{16} << 20});
    // Every page's value, copied out of LMDB, and its geometry blob.
    std::vector<smr::storage::Bytes> pages;
    std::vector<std::pair<std::size_t, std::size_t>> geo_span;  // offset, size within payload
    std::vector<smr::storage::ByteView> payloads, geos;
    std::uint64_t geo_bytes = 0, record_bytes = 0, page_bytes = 0, page_triangles = 0;
    {
      const smr::storage::Env env = smr::storage::Env::open_read_only(path, smr::kTableNames);
      const smr::storage::ReadTxn txn = env.read();
      txn.for_each(smr::Table::kPages, [&](smr::storage::ByteView, smr::storage::ByteView v) {
        pages.emplace_back(v.begin(), v.end());
      });
    }
    StreamBytes streams;
    for (std::size_t i = 0; i < pages.size(); ++i) {
      const smr::PageValue value = smr::split_page_value(pages[i], "pages", std::to_string(i));
      page_bytes += pages[i].size() - value.leaf.size();  // the leaf is the R-tree's
      const smr::storage::ByteView payload =
          smr::storage::unseal(value.page, "pages", std::to_string(i));
      const smr::PageSections parts = smr::page_sections(payload, "pages/" + std::to_string(i));
      add_streams(streams, payload, "pages/" + std::to_string(i));
      record_bytes += parts.records.size();
      page_triangles += parts.totals[2];  // fragment triangles (pages keep them in the records)
      const smr::storage::ByteView geo = parts.geometry;
      geo_bytes += geo.size();
      payloads.push_back(payload);
      geos.push_back(geo);
    }
    std::uint64_t positions = 0;
    const std::uint64_t faces = page_triangles;
    for (const auto& g : geos) {
      const smr::storage::GeometryBlob b = smr::storage::decode_geometry(*codec, g, "geometry");
      positions += b.positions.size();
    }
    std::uint64_t sink = 0;
    const double geo_s = time_passes(a.min_seconds, [&] {
      for (const auto& g : geos)
        sink += smr::storage::decode_geometry(*codec, g, "geometry").positions.size();
    });
    const double page_s = time_passes(a.min_seconds, [&] {
      for (const auto& p : payloads)
        sink += smr::decode_page(p, db->grid(), db->info(), "page")->size();
    });
    const double raw_geo_bytes = 12.0 * double(positions);  // int32 x 3
    codecs[name] = {{"file_bytes", w.file_bytes},
                    {"pages", pages.size()},
                    {"page_bytes", page_bytes},
                    {"geometry_bytes", geo_bytes},
                    {"record_bytes", record_bytes},
                    {"page_vertices", positions},
                    {"page_triangles", faces},
                    {"mean_page_bytes", double(page_bytes) / double(pages.size())},
                    {"mean_page_triangles", double(faces) / double(pages.size())},
                    {"geometry_bytes_per_page_vertex", double(geo_bytes) / double(positions)},
                    {"geometry_bytes_per_triangle", double(geo_bytes) / double(faces)},
                    {"geometry_bytes_per_model_vertex", double(geo_bytes) / double(vertices)},
                    {"record_bytes_per_model_vertex", double(record_bytes) / double(vertices)},
                    {"record_streams_per_model_vertex", streams_json(streams, vertices)},
                    {"page_bytes_per_model_vertex", double(page_bytes) / double(vertices)},
                    {"file_bytes_per_model_vertex", double(w.file_bytes) / double(vertices)},
                    {"geometry_decode",
                     {{"seconds_per_pass", geo_s},
                      {"input_mb_per_s", double(geo_bytes) / 1e6 / geo_s},
                      {"output_mb_per_s", raw_geo_bytes / 1e6 / geo_s},
                      {"triangles_per_s", double(faces) / geo_s},
                      {"us_per_page", 1e6 * geo_s / double(pages.size())}}},
                    {"page_decode",
                     {{"seconds_per_pass", page_s},
                      {"input_mb_per_s", double(page_bytes) / 1e6 / page_s},
                      {"triangles_per_s", double(faces) / page_s},
                      {"us_per_page", 1e6 * page_s / double(pages.size())}}}};
    if (sink == 42) std::fprintf(stderr, " ");
    std::fprintf(stderr,
                 "  %-5s file %.2f MB = %.1f B/vertex; geometry %.2f B/page-vertex, %.2f "
                 "B/triangle; decode %.0f MB/s in, %.2f M tri/s; page decode %.2f M tri/s\n",
                 name.c_str(), double(w.file_bytes) / 1e6, double(w.file_bytes) / double(vertices),
                 double(geo_bytes) / double(positions), double(geo_bytes) / double(faces),
                 double(geo_bytes) / 1e6 / geo_s, double(faces) / geo_s / 1e6,
                 double(faces) / page_s / 1e6);
  }
  out["codecs"] = codecs;
  out["references"] = {{"hoppe_pm_bytes_per_vertex", 24.9}, {"brown_crmr_over_pm", {2.0, 4.0}}};
  return out;
}

// ---- mode: decode ---------------------------------------------------------------------------

struct DecodeArgs {
  std::string db;
  std::uint64_t stride = 1;
  double min_seconds = 1.0;
  bool keep = false;   // every page of a pass held until its end: each decoded into fresh memory
  bool links = false;  // decode the Hypermesh links too (as after OpSource::need_links)
};

json mode_decode(const DecodeArgs& a) {
  const auto db = smr::Database::open(a.db, {std::size_t{16} << 20});
  std::vector<smr::storage::Bytes> pages;
  {
    const smr::storage::Env env = smr::storage::Env::open_read_only(a.db, smr::kTableNames);
    const smr::storage::ReadTxn txn = env.read();
    for (std::uint64_t p = 0; p < db->page_count(); p += a.stride) {
      const auto v = txn.get(smr::Table::kPages, p);
      if (!v) smr::throw_internal("decode: page " + std::to_string(p) + " missing");
      pages.emplace_back(v->begin(), v->end());
    }
  }
  std::vector<smr::storage::ByteView> payloads;
  std::uint64_t ops = 0, bytes = 0, decoded_bytes = 0, leaf_bytes = 0, record_bytes = 0,
                geo_bytes = 0;
  std::array<std::uint64_t, 7> totals{};
  StreamBytes streams;
  for (std::size_t i = 0; i < pages.size(); ++i) {
    const smr::PageValue value = smr::split_page_value(pages[i], "pages", std::to_string(i));
    leaf_bytes += value.leaf.size();
    payloads.push_back(smr::storage::unseal(value.page, "pages", std::to_string(i)));
    add_streams(streams, payloads.back(), "pages/" + std::to_string(i));
    const smr::PageSections parts = smr::page_sections(payloads.back(), "page");
    for (std::size_t k = 0; k < totals.size(); ++k) totals[k] += parts.totals[k];
    record_bytes += parts.records.size();
    geo_bytes += parts.geometry.size();
    const auto page = smr::decode_page(payloads.back(), db->grid(), db->info(), "page", a.links);
    ops += page->size();
    bytes += pages[i].size() - value.leaf.size();  // the leaf is the R-tree's
    decoded_bytes += page->memory_bytes();
  }
  std::uint64_t sink = 0;
  const double s = time_passes(a.min_seconds, [&] {
    std::vector<std::shared_ptr<const smr::DecodedPage>> keep;
    for (const auto& p : payloads) {
      keep.push_back(smr::decode_page(p, db->grid(), db->info(), "page", a.links));
      sink += keep.back()->size();
      if (!a.keep) keep.clear();
    }
  });
  if (sink == 42) std::fprintf(stderr, " ");
  std::fprintf(stderr, "bench_db decode %s: %zu pages, %.1f us/page, %.0f ns/op\n", a.db.c_str(),
               pages.size(), 1e6 * s / double(pages.size()), 1e9 * s / double(ops));
  json per_op = json::object();  // the page header's totals (page.h), per op
  const char* names[] = {"vertices", "list", "triangles", "pre", "links", "parents", "children"};
  for (std::size_t k = 0; k < totals.size(); ++k)
    per_op[names[k]] = double(totals[k]) / double(ops);
  // Bytes per model vertex of the pages read (all of them with --stride 1).
  const double vertices = double(db->info().vertex_count);
  return {{"mode", "decode"},
          {"db", a.db},
          {"per_op", per_op},
          {"per_model_vertex",
           {{"leaves", double(leaf_bytes) / vertices},
            {"records", double(record_bytes) / vertices},
            {"geometry", double(geo_bytes) / vertices},
            {"record_streams", streams_json(streams, db->info().vertex_count)}}},
          {"machine", smr::bench::machine_json()},
          {"pages", pages.size()},
          {"ops", ops},
          {"page_bytes", bytes},
          {"decoded_bytes_per_page", double(decoded_bytes) / double(pages.size())},
          {"seconds_per_pass", s},
          {"us_per_page", 1e6 * s / double(pages.size())},
          {"ns_per_op", 1e9 * s / double(ops)},
          {"pages_kept", a.keep},
          {"links", a.links},
          {"pages_per_mib", double(pages.size()) * 1048576.0 / double(decoded_bytes)},
          {"input_mb_per_s", double(bytes) / 1e6 / s}};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_db: I/O benchmarks of the on-disk database (JSON on stdout)"};
  app.require_subcommand(1);
  ExtractArgs ea;
  CLI::App* ex = app.add_subcommand("extract", "Read amplification and cold/warm/hot timings");
  ex->add_option("db", ea.db, "Database file")->required();
  ex->add_option("--view", ea.view, "oblique or overview (camera relative to the bounds)")
      ->capture_default_str();
  ex->add_option("--eye", ea.eye, "Explicit camera position x,y,z (with --target)");
  ex->add_option("--target", ea.target, "Explicit camera target x,y,z");
  ex->add_option("--fov", ea.fov, "Vertical field of view, degrees")->capture_default_str();
  ex->add_option("--far", ea.far, "Far plane distance (0 = none)")->capture_default_str();
  ex->add_option("--width", ea.vw, "Viewport width")->capture_default_str();
  ex->add_option("--height", ea.vh, "Viewport height")->capture_default_str();
  ex->add_option("--pixel-error", ea.pixel_errors, "Screen-space tolerances (comma list)")
      ->delimiter(',')
      ->capture_default_str();
  ex->add_option("--algorithms", ea.algorithms, "minimal,minimal-pages,reduced")
      ->delimiter(',')
      ->capture_default_str();
  ex->add_option("--cache-mb", ea.cache_mb, "Page cache budget of the measured runs, MiB")
      ->capture_default_str();
  ex->add_option("--repeat", ea.repeat, "Warm and hot runs (median)")->capture_default_str();
  bool no_cold = false, no_raw = false;
  ex->add_flag("--no-cold", no_cold, "Skip the cold runs (posix_fadvise DONTNEED)");
  ex->add_flag("--no-raw", no_raw, "Skip the raw LMDB read of the same pages");

  CodecArgs ca;
  CLI::App* co = app.add_subcommand("codecs", "Codec sizes and decode speeds on real pages");
  co->add_option("dem", ca.dem, "DEM file (or --fbm)");
  co->add_option("--fbm", ca.fbm, "Generate an N x N fBm (range 1600, spacing 1)");
  co->add_option("--seed", ca.seed, "fBm seed")->capture_default_str();
  co->add_option("--max-error", ca.max_error, "Build tolerance (data units)");
  co->add_option("--max-error-fraction", ca.max_error_fraction,
                 "Build tolerance as a fraction of the height range");
  co->add_option("--codecs", ca.codecs, "raw,zstd,draco")->delimiter(',')->capture_default_str();
  co->add_option("--work-dir", ca.work_dir, "Where the databases are written")
      ->capture_default_str();
  co->add_option("--min-seconds", ca.min_seconds, "Minimum time per decode measurement")
      ->capture_default_str();
  co->add_option("--name", ca.name, "Dataset name (file names, JSON)")->required();
  DecodeArgs da;
  CLI::App* de = app.add_subcommand("decode", "decode_page speed on a database's real pages");
  de->add_option("db", da.db, "Database file")->required();
  de->add_option("--stride", da.stride, "Every N-th page")->capture_default_str();
  de->add_option("--min-seconds", da.min_seconds, "Minimum measuring time")->capture_default_str();
  de->add_flag("--keep", da.keep,
               "Hold every decoded page to the end of a pass (fresh memory, as a first view has)");
  de->add_flag("--links", da.links,
               "Decode the Hypermesh links too (a database does once a reader needs them)");
  CLI11_PARSE(app, argc, argv);
  try {
    json out;
    if (*de) {
      da.stride = std::max<std::uint64_t>(1, da.stride);
      out = mode_decode(da);
    } else if (*ex) {
      ea.cold = !no_cold;
      ea.raw = !no_raw;
      ea.repeat = std::max(1, ea.repeat);
      out = mode_extract(ea);
    } else {
      if (ca.dem.empty() == (ca.fbm == 0)) smr::throw_input("codecs: give a DEM or --fbm N");
      if (!(ca.max_error > 0) && !(ca.max_error_fraction > 0))
        smr::throw_input("codecs: give --max-error or --max-error-fraction");
      out = mode_codecs(ca);
    }
    out["peak_rss_mb"] = smr::bench::peak_rss_mb();
    std::cout << out.dump(2) << "\n";
  } catch (const smr::Error& e) {
    std::fprintf(stderr, "bench_db: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
