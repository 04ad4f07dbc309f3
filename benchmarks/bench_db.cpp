// bench_db: I/O benchmarks of the on-disk database (DESIGN.md sections 3, 5, 6, 8.7). Prints one
// JSON object. Modes:
//
//   extract DB   For one view (a named camera placed relative to the database's bounds, or an
//                explicit --eye/--target) and each --pixel-error and algorithm (minimal surface,
//                reduced extraction from the R-tree):
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
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <unordered_set>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "benchmarks/bench_common.h"
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
using smr::bench::median;
using smr::bench::now_ns;
using smr::bench::seconds_since;

// ---- the OS page cache ----------------------------------------------------------------------

// Bytes of `path` resident in the OS page cache (mincore over a mapping that is never touched).
std::uint64_t resident_bytes(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return 0;
  struct stat st {};
  std::uint64_t resident = 0;
  if (::fstat(fd, &st) == 0 && st.st_size > 0) {
    const auto size = static_cast<std::size_t>(st.st_size);
    void* map = ::mmap(nullptr, size, PROT_READ, MAP_SHARED, fd, 0);
    if (map != MAP_FAILED) {
      const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
      std::vector<unsigned char> in((size + page - 1) / page);
      if (::mincore(map, size, in.data()) == 0) {
        for (unsigned char c : in) resident += (c & 1u) ? page : 0;
      }
      ::munmap(map, size);
    }
  }
  ::close(fd);
  return resident;
}

// Drops `path` from the OS page cache (no process may map it at the time). Returns the bytes
// still resident afterwards (0 when the drop worked).
std::uint64_t drop_from_page_cache(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) smr::throw_input(path + ": cannot open");
  (void)::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
  ::close(fd);
  return resident_bytes(path);
}

// ---- views ----------------------------------------------------------------------------------

json camera_json(const smr::Camera& c) {
  return {{"eye", {c.eye.x, c.eye.y, c.eye.z}},
          {"target", {c.target.x, c.target.y, c.target.z}},
          {"fov_y_deg", c.fov_y_deg},
          {"viewport", {c.viewport_w, c.viewport_h}},
          {"far", c.far_distance}};
}

smr::Vec3 parse_vec3(const std::string& text, const char* what) {
  std::vector<double> v;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ',');) v.push_back(std::stod(item));
  if (v.size() != 3) smr::throw_input(std::string(what) + " expects x,y,z, got '" + text + "'");
  return {v[0], v[1], v[2]};
}

// Named cameras relative to the model's bounds (L = the larger horizontal extent):
//   oblique   a low camera inside the south-west quarter, 0.02 L above the highest point,
//             looking north-east across the terrain towards (60 %, 75 %) at 30 % of the relief;
//   overview  a high camera 1.0 L above the highest point, south of the centre, looking at the
//             centre: the whole terrain in view.
smr::Camera named_camera(const std::string& name, const smr::Box3& b) {
  const double lx = b.hi.x - b.lo.x, ly = b.hi.y - b.lo.y, zr = b.hi.z - b.lo.z;
  const double l = std::max(lx, ly);
  smr::Camera cam;
  if (name == "oblique") {
    cam.eye = {b.lo.x + 0.25 * lx, b.lo.y + 0.15 * ly, b.hi.z + 0.02 * l};
    cam.target = {b.lo.x + 0.6 * lx, b.lo.y + 0.75 * ly, b.lo.z + 0.3 * zr};
  } else if (name == "overview") {
    cam.eye = {b.lo.x + 0.5 * lx, b.lo.y + 0.2 * ly, b.hi.z + 1.0 * l};
    cam.target = {b.lo.x + 0.5 * lx, b.lo.y + 0.5 * ly, b.lo.z};
  } else {
    smr::throw_input("--view must be oblique or overview, got '" + name + "'");
  }
  return cam;
}

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
  std::vector<smr::OpId> not_completely_finer(const smr::Rcf& rcf) const override {
    for (const smr::index::Hit& h : db_.rcf_hits(rcf)) {
      if (leaves.empty() || leaves.back() != h.leaf) leaves.push_back(h.leaf);
    }
    return db_.not_completely_finer(rcf);
  }
  std::vector<smr::OpId> maybe_not_completely_finer(const smr::Rcf& rcf) const override {
    return db_.maybe_not_completely_finer(rcf);  // reads no page
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

Timed run_extraction(const smr::Database& db, const smr::Rcf& rcf, bool reduced) {
  Timed t;
  std::uint64_t t0 = now_ns();
  const smr::IndexedSource source(db);
  t.e = reduced ? smr::extract_reduced(source, rcf) : smr::extract_minimal_surface(source, rcf);
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

Timed fresh_run(const ExtractArgs& a, const smr::Rcf& rcf, bool reduced) {
  const std::uint64_t t0 = now_ns();
  const auto db = smr::Database::open(a.db, {std::size_t(a.cache_mb) << 20});
  const double open = seconds_since(t0);
  Timed t = run_extraction(*db, rcf, reduced);
  t.open_seconds = open;
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

json mode_extract(const ExtractArgs& a) {
  std::fprintf(stderr, "bench_db extract %s\n", a.db.c_str());
  // The op -> page map, page sizes and counts, from a separate instance (its reads do not count;
  // it is closed before any measurement so that it maps nothing the cold runs must drop).
  auto index_db = smr::Database::open(a.db, {std::size_t{256} << 20});
  const smr::CrmrInfo info = index_db->info();
  std::vector<std::uint32_t> page_of(index_db->op_count(), ~0u);
  {
    AllVisitor all;
    for (const smr::index::Hit& h : index_db->rtree().query(all)) page_of.at(h.id) = h.leaf;
  }
  std::vector<std::uint64_t> page_size(index_db->page_count(), 0);
  std::uint64_t all_page_bytes = 0;
  {
    const smr::storage::Env env = smr::storage::Env::open_read_only(a.db, smr::kTableNames);
    const smr::storage::ReadTxn txn = env.read();
    for (std::uint64_t p = 0; p < page_size.size(); ++p) {
      page_size[p] = txn.get(smr::Table::kPages, p)->size();
      all_page_bytes += page_size[p];
    }
  }
  const json meta = json::parse(index_db->meta_json());
  json out = {{"mode", "extract"},
              {"db",
               {{"path", a.db},
                {"file_bytes", index_db->file_bytes()},
                {"samples", std::uint64_t(info.grid_width) * std::uint64_t(info.grid_height)},
                {"grid", {info.grid_width, info.grid_height}},
                {"spacing", info.georef.dx},
                {"vertices", info.vertex_count},
                {"ops", index_db->op_count()},
                {"triangles", meta["counts"]["triangles"]},
                {"pages", index_db->page_count()},
                {"page_bytes", all_page_bytes},
                {"mean_page_bytes", double(all_page_bytes) / double(page_size.size())},
                {"rtree_height", index_db->rtree().height()},
                {"codec", meta["codec"]},
                {"err0", info.err0},
                {"err_final", info.err_final},
                {"bounds",
                 {{info.bounds.lo.x, info.bounds.lo.y, info.bounds.lo.z},
                  {info.bounds.hi.x, info.bounds.hi.y, info.bounds.hi.z}}}}},
              {"cache_mb", a.cache_mb},
              {"repeat", a.repeat},
              {"machine", smr::bench::machine_json()}};
  index_db.reset();

  smr::Camera cam;
  if (!a.eye.empty() || !a.target.empty()) {
    cam.eye = parse_vec3(a.eye, "--eye");
    cam.target = parse_vec3(a.target, "--target");
    out["view"] = "explicit";
  } else {
    cam = named_camera(a.view, info.bounds);
    out["view"] = a.view;
  }
  cam.fov_y_deg = a.fov;
  cam.viewport_w = a.vw;
  cam.viewport_h = a.vh;
  cam.far_distance = a.far;
  out["camera"] = camera_json(cam);

  json cases = json::array();
  for (double px : a.pixel_errors) {
    smr::RcfSpec spec;
    spec.camera = cam;
    spec.pixel_error = px;
    smr::validate(spec);
    const smr::Rcf rcf = smr::make_rcf(spec, info.kind, nullptr);
    for (const std::string& alg : a.algorithms) {
      const bool reduced = alg == "reduced";
      std::fprintf(stderr, "  %s %gpx %s\n", out["view"].get<std::string>().c_str(), px,
                   alg.c_str());
      json c = {{"pixel_error", px}, {"algorithm", alg}};
      // Cold: the file dropped from the OS page cache first, then a fresh process-like Database.
      std::optional<Timed> cold;
      if (a.cold) {
        c["resident_bytes_after_drop"] = drop_from_page_cache(a.db);
        cold = fresh_run(a, rcf, reduced);
        c["resident_bytes_after_cold_run"] = resident_bytes(a.db);
      }
      // Warm: fresh Database each time, file in the OS page cache.
      std::vector<double> warm_extract, warm_total;
      std::optional<Timed> first;
      std::unique_ptr<smr::Database> keep;
      for (int i = 0; i < a.repeat; ++i) {
        const std::uint64_t t0 = now_ns();
        auto db = smr::Database::open(a.db, {std::size_t(a.cache_mb) << 20});
        const double open = seconds_since(t0);
        Timed t = run_extraction(*db, rcf, reduced);
        t.open_seconds = open;
        warm_extract.push_back(t.extract_seconds);
        warm_total.push_back(open + t.extract_seconds + t.mesh_seconds);
        if (!first) first = std::move(t);
        if (i + 1 == a.repeat) keep = std::move(db);
      }
      // Hot: the same Database again (its cache holds what fits of the pages it decoded).
      std::vector<double> hot_extract;
      for (int i = 0; i < a.repeat; ++i)
        hot_extract.push_back(run_extraction(*keep, rcf, reduced).extract_seconds);
      keep.reset();

      const smr::Extraction& e = first->e;
      const smr::ExtractStats& s = e.stats;
      // Needed pages: those holding an op of an output triangle.
      std::set<std::uint64_t> needed;
      for (const smr::TriRef& t : e.triangles) needed.insert(page_of.at(t.op.value));
      std::uint64_t needed_bytes = 0;
      for (std::uint64_t p : needed) needed_bytes += page_size[p];
      // Touched pages: every page the extraction fetched (recorded; unbounded cache).
      auto big = smr::Database::open(a.db, {std::size_t{1} << 40});
      RecordingSource rec(*big);
      const smr::Extraction re =
          reduced ? smr::extract_reduced(rec, rcf) : smr::extract_minimal_surface(rec, rcf);
      (void)smr::to_mesh(rec, re.triangles);
      std::vector<std::uint64_t> touched_order;
      std::unordered_set<std::uint64_t> touched;
      auto touch = [&](std::uint64_t p) {
        if (touched.insert(p).second) touched_order.push_back(p);
      };
      // not_completely_finer reads its leaves before any op is fetched through op().
      for (std::uint64_t l : rec.leaves) touch(l);
      for (std::uint64_t id : rec.ops) touch(page_of.at(id));
      std::uint64_t touched_bytes = 0;
      for (std::uint64_t p : touched_order) touched_bytes += page_size[p];
      const smr::DatabaseStats unbounded = big->stats();
      big.reset();
      const double lmdb = double(first->stats.lmdb_bytes_read);

      c["output"] = {{"triangles", s.triangles - s.void_triangles},
                     {"void_triangles", s.void_triangles},
                     {"mesh_vertices", first->mesh_vertices},
                     {"mesh_triangles", first->mesh_triangles},
                     {"x", s.x},
                     {"x_plus", s.x_plus},
                     {"ops_visited", s.ops_visited},
                     {"held_ops_peak", s.held_ops_peak},
                     {"held_bytes_peak", s.held_bytes_peak}};
      c["io"] = json(first->stats);
      c["io"]["pages_read_to_mesh"] = first->pages_read_to_mesh;
      c["io_unbounded_cache"] = json(unbounded);
      c["pages"] = {{"needed", needed.size()},
                    {"needed_bytes", needed_bytes},
                    {"touched", touched_order.size()},
                    {"touched_bytes", touched_bytes},
                    {"touched_check_ok", touched_order.size() == unbounded.pages_read},
                    {"read", first->stats.pages_read},
                    {"of_database", page_size.size()}};
      c["amplification"] = {
          // The target: every byte fetched from LMDB over the bytes of the needed pages.
          {"lmdb_bytes_over_needed", lmdb / double(std::max<std::uint64_t>(1, needed_bytes))},
          {"page_bytes_over_needed",
           double(first->stats.page_bytes_read) / double(std::max<std::uint64_t>(1, needed_bytes))},
          {"touched_over_needed_pages",
           double(touched_order.size()) / double(std::max<std::size_t>(1, needed.size()))},
          {"touched_over_needed_bytes",
           double(touched_bytes) / double(std::max<std::uint64_t>(1, needed_bytes))},
          {"index_and_locator_bytes", first->stats.lmdb_bytes_read - first->stats.page_bytes_read}};
      c["seconds"] = {
          {"warm_extract", median(warm_extract)}, {"warm_extract_all", warm_extract},
          {"warm_total", median(warm_total)},     {"open", first->open_seconds},
          {"to_mesh", first->mesh_seconds},       {"extraction_phase", s.extract_seconds},
          {"expansion_phase", s.expand_seconds},  {"hot_extract", median(hot_extract)}};
      if (cold) {
        c["seconds"]["cold_extract"] = cold->extract_seconds;
        c["seconds"]["cold_total"] =
            cold->open_seconds + cold->extract_seconds + cold->mesh_seconds;
        c["seconds"]["cold_over_warm"] = cold->extract_seconds / median(warm_extract);
      }
      const double out_tris = double(s.triangles - s.void_triangles);
      c["triangles_per_second_warm"] = out_tris / std::max(1e-12, median(warm_extract));
      if (a.raw) {
        std::uint64_t bytes = 0;
        json r;
        if (a.cold) {
          r["resident_bytes_after_drop"] = drop_from_page_cache(a.db);
          r["cold_seconds"] = raw_read(a.db, touched_order, &bytes);
        }
        std::vector<double> warm;
        for (int i = 0; i < a.repeat; ++i) warm.push_back(raw_read(a.db, touched_order, &bytes));
        r["warm_seconds"] = median(warm);
        r["pages"] = touched_order.size();
        r["bytes"] = bytes;
        r["warm_mb_per_s"] = double(bytes) / 1e6 / std::max(1e-12, median(warm));
        r["warm_extract_over_raw"] = median(warm_extract) / std::max(1e-12, median(warm));
        if (a.cold) {
          r["cold_mb_per_s"] =
              double(bytes) / 1e6 / std::max(1e-12, r["cold_seconds"].get<double>());
          r["cold_extract_over_raw"] =
              cold->extract_seconds / std::max(1e-12, r["cold_seconds"].get<double>());
        }
        c["raw_read"] = r;
      }
      std::fprintf(stderr,
                   "    |F| %llu  pages needed %zu touched %zu read %llu  lmdb/needed %.2f  warm "
                   "%.3fs%s\n",
                   static_cast<unsigned long long>(s.triangles - s.void_triangles), needed.size(),
                   touched_order.size(), static_cast<unsigned long long>(first->stats.pages_read),
                   lmdb / double(std::max<std::uint64_t>(1, needed_bytes)), median(warm_extract),
                   cold ? (", cold " + std::to_string(cold->extract_seconds) + "s").c_str() : "");
      cases.push_back(c);
    }
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
    std::uint64_t geo_bytes = 0, record_bytes = 0, page_bytes = 0;
    {
      const smr::storage::Env env = smr::storage::Env::open_read_only(path, smr::kTableNames);
      const smr::storage::ReadTxn txn = env.read();
      txn.for_each(smr::Table::kPages, [&](smr::storage::ByteView, smr::storage::ByteView v) {
        pages.emplace_back(v.begin(), v.end());
      });
    }
    for (std::size_t i = 0; i < pages.size(); ++i) {
      page_bytes += pages[i].size();
      const smr::storage::ByteView payload =
          smr::storage::unseal(pages[i], "pages", std::to_string(i));
      smr::storage::ByteReader r(payload, "pages/" + std::to_string(i));
      r.u8();
      r.u8();
      r.varint();
      record_bytes += r.blob().size();
      const smr::storage::ByteView geo = r.blob();
      geo_bytes += geo.size();
      payloads.push_back(payload);
      geos.push_back(geo);
    }
    std::uint64_t positions = 0, faces = 0;
    for (const auto& g : geos) {
      const smr::storage::GeometryBlob b = smr::storage::decode_geometry(*codec, g, "geometry");
      positions += b.positions.size();
      faces += b.faces.size();
    }
    std::uint64_t sink = 0;
    const double geo_s = time_passes(a.min_seconds, [&] {
      for (const auto& g : geos)
        sink += smr::storage::decode_geometry(*codec, g, "geometry").faces.size();
    });
    const double page_s = time_passes(a.min_seconds, [&] {
      for (const auto& p : payloads) sink += smr::decode_page(p, db->grid(), "page").size();
    });
    const double raw_geo_bytes = 12.0 * double(positions + faces);  // int32 x 3, uint32 x 3
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
  ex->add_option("--algorithms", ea.algorithms, "minimal,reduced")
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
  CLI11_PARSE(app, argc, argv);
  try {
    json out;
    if (*ex) {
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
