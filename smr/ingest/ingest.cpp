#include "smr/ingest/ingest.h"

#include <atomic>
#include <charconv>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <span>
#include <utility>
#include <vector>

#include "base/error.h"
#include "smr/builders/terrain/greedy_tin.h"
#include "smr/core/clock.h"
#include "smr/core/invariants.h"
#include "smr/db/verify.h"
#include "smr/io/dem_reader.h"

namespace smr {

static_assert(std::is_same_v<std::variant_alternative_t<std::size_t(IngestPath::kBlockTin),
                                                        decltype(IngestReport::build)>,
                             BlockTinReport>,
              "IngestReport::path() maps the variant's index to IngestPath");

namespace {

// The database names its source by file name only, like describe(): where the input sits must
// not change the bytes.
std::string file_name(const std::string& path) {
  return std::filesystem::path(path).filename().string();
}

// Counts what CrmrSummary shows of the ops; add() may run on several threads at once (a sink's
// encode()).
struct CrmrCounts {
  std::atomic<std::uint64_t> ops = 0, triangles = 0, finest = 0, base = 0;
  CrmrSummary summary;
  void header(const CrmrInfo& h) {
    summary.vertices = h.vertex_count;
    summary.err0 = h.err0;
    summary.err_final = h.err_final;
  }
  void add(const Op& op) {
    std::uint64_t f = 0;
    for (const auto& t : op.fragment) f += !t.killer.valid() && !t.is_void();
    finest.fetch_add(f, std::memory_order_relaxed);
    if (op.id.value == 0) base = op.fragment.size();
    triangles.fetch_add(op.fragment.size(), std::memory_order_relaxed);
    ops.fetch_add(1, std::memory_order_relaxed);
  }
  CrmrSummary get() const {
    CrmrSummary s = summary;
    s.ops = ops.load();
    s.fragment_triangles = triangles.load();
    s.finest_triangles = finest.load();
    s.base_triangles = base.load();
    return s;
  }
};

// Between a block builder and the database writer: names the source by file name only (as the
// in-memory paths do) and counts the ops as they stream by.
class IngestTap final : public OpSink {
 public:
  IngestTap(OpSink& inner, std::string source) : inner_(inner), source_(std::move(source)) {}
  void begin(const CrmrInfo& header, std::uint64_t op_count) override {
    CrmrInfo h = header;
    h.source = source_;
    counts.header(h);
    inner_.begin(h, op_count);
  }
  void add(Op&& op) override {
    counts.add(op);
    inner_.add(std::move(op));
  }
  bool encodes() const override { return inner_.encodes(); }
  void encode(Op& op, std::vector<std::uint8_t>& out) const override {
    counts.add(op);
    inner_.encode(op, out);
  }
  void add_encoded(std::span<const std::uint8_t> op) override { inner_.add_encoded(op); }
  mutable CrmrCounts counts;

 private:
  OpSink& inner_;
  std::string source_;
};

// Every height of `dem` is a multiple of `step` (a power of two; the grid's z values are, since
// choose_grid puts its origin on one), so snapping to it moves none (false for step 0).
bool on_z_grid(const Heightfield& dem, double step) {
  if (!(step > 0.0)) return false;
  for (std::size_t i = 0; i < dem.z.size(); ++i) {
    if (!dem.valid.empty() && dem.valid[i] == 0) continue;
    const double units = double(dem.z[i]) / step;  // exact: step is a power of two
    if (units != std::nearbyint(units)) return false;
  }
  return true;
}

// One call's state: the input, its options, the shares of the budget, the report so far.
struct Run {
  const std::string& input;
  const std::string& db_path;
  const IngestOptions& options;
  const IngestProgress& progress;
  MemoryShares shares;
  IngestReport report;

  void fraction(double f) const {
    if (progress.fraction) progress.fraction(f);
  }
  std::function<void(double)> build_progress() const {
    return [this](double f) { fraction(0.8 * f); };
  }
  void phase(IngestPhase p) const {
    if (progress.phase) progress.phase(p, report);
  }

  // A DEM built to a max error takes, unless told otherwise, a z step of error_z_quantum of it,
  // and its builder aims half a step below the error asked for unless its heights all lie on the
  // step (smr/db/quantize.h; only a DEM in memory is checked).
  TerrainErrorSplit error_split(bool heights_on_step = false) const {
    return split_terrain_error(options.max_error, options.z_quantum, heights_on_step);
  }

  WriteOptions write_options() const {
    WriteOptions wo;
    wo.codec = options.codec;
    wo.force = options.force;
    wo.z_quantum = options.z_quantum;
    wo.error_quantum = error_split().error_quantum;
    wo.page_bytes = options.page_kb * 1024 - 16;
    wo.parameters = describe(input, options);
    wo.progress = [this](double f) { fraction(0.8 + 0.2 * f); };
    wo.batch_bytes = shares.writer_batch_bytes;
    wo.sort_bytes = shares.writer_sort_bytes;
    return wo;
  }

  // The in-memory paths' end: counts, the optional check, the database written whole.
  void write_whole(Crmr& crmr, Clock::time_point build_start) {
    crmr.header.source = file_name(input);
    CrmrCounts counts;
    counts.header(crmr.header);
    for (const Op& op : crmr.ops) counts.add(op);
    report.crmr = counts.get();
    report.build_seconds = seconds_since(build_start);
    phase(IngestPhase::kBuilt);
    if (options.verify) {
      const InvariantReport r = check_crmr(crmr);
      if (!r.ok()) throw_internal("CRMR invariants violated: " + r.summary());
    }
    report.database = write_database(crmr, db_path, write_options());
    phase(IngestPhase::kWritten);
  }

  // What both block builders take alike.
  template <class BlockOptions>
  BlockOptions block_options() const {
    BlockOptions opt;
    opt.tmp_dir = options.tmp_dir;
    opt.assembly_sort_bytes = shares.assembly_sort_bytes;
    opt.assembly_table_bytes = shares.assembly_table_bytes;
    opt.threads = options.threads;
    opt.progress = build_progress();
    return opt;
  }

  // The block paths: `build(sink, stats)` streams the ops into the database writer through a
  // tap, which spools them to tmp_dir; then the writer's finish() and, with options.verify, a
  // check of what was written (the CRMR never exists in memory: checksums, DAG, links, index).
  template <class Part, class Build>
  void stream(Clock::time_point build_start, Part part, const Build& build) {
    DatabaseStreamWriter writer(db_path, write_options(), options.tmp_dir);
    IngestTap tap(writer, file_name(input));
    build(tap, part.stats);
    const std::uint64_t builder_temp_bytes = part.stats.temp_bytes;
    report.build = std::move(part);
    report.crmr = tap.counts.get();
    report.build_seconds = seconds_since(build_start);
    phase(IngestPhase::kBuilt);
    report.database = writer.finish();
    report.temp_bytes =
        builder_temp_bytes + report.database.spool_bytes + report.database.scratch_bytes;
    phase(IngestPhase::kWritten);
    if (options.verify) {
      const VerifyReport r = verify_database(db_path, nullptr);
      if (!r.ok()) throw_internal("database invariants violated: " + r.faults.front());
    }
  }

  void qem_pm() {
    auto t0 = Clock::now();
    Crmr crmr;
    {
      QemPmReport part;
      const TriangleMesh mesh =
          read_mesh(input, options.repair ? MeshRepair::all() : MeshRepair{}, &part.input);
      part.read_seconds = seconds_since(t0);
      QemPmOptions opt;
      opt.base_vertices = options.base_vertices;
      opt.max_fragment_triangles = options.coalesce;
      opt.coalesce_error_ratio = options.coalesce_ratio;
      opt.allow_self_intersections = options.allow_self_intersections;
      opt.threads = options.threads;
      opt.progress = build_progress();
      t0 = Clock::now();
      crmr = build_qem_pm(mesh, input, opt, &part.stats);
      report.build = std::move(part);
    }
    write_whole(crmr, t0);
  }

  void greedy_tin() {
    auto t0 = Clock::now();
    Crmr crmr;
    {
      const Heightfield dem = read_dem(input);
      report.build = GreedyTinReport{
          dem.width,        dem.height, dem.sample_count(), dem.has_nodata(), dem.georef.geographic,
          seconds_since(t0)};
      GreedyTinOptions opt;
      opt.max_error = error_split(on_z_grid(dem, error_split().error_quantum)).build_error;
      opt.max_vertices = options.max_vertices;
      opt.base_vertices = options.base_vertices;
      opt.progress = build_progress();
      t0 = Clock::now();
      crmr = build_greedy_tin(dem, opt);
    }
    write_whole(crmr, t0);
  }

  // A DEM read one leaf block at a time: neither the raster nor the CRMR is ever whole in memory.
  void block_tin() {
    const auto t0 = Clock::now();
    const std::unique_ptr<RasterWindows> dem = open_dem(input);
    const BlockTinReport part{dem->width(), dem->height(), dem->georef().geographic, {}};
    auto opt = block_options<BlockTinOptions>();
    opt.max_error = error_split().build_error;
    opt.block_cells = options.block_cells;
    opt.exact_window_samples = shares.exact_window_samples;
    opt.raster_cache_bytes = shares.raster_cache_bytes;
    stream(t0, part, [&](OpSink& sink, BlockTinStats& st) {
      build_block_tin(*dem, sink, opt, &st);
      report.records_over_budget =
          shares.record_bytes != 0 && st.record_bytes > shares.record_bytes;
    });
  }

  // A PLY streamed (two passes), its triangles sorted by octree cell on disk, blocks simplified
  // and merged, ops assembled on disk.
  void block_pm() {
    const auto t0 = Clock::now();
    const std::unique_ptr<MeshStream> mesh = open_mesh_stream(input);
    auto opt = block_options<BlockPmOptions>();
    opt.allow_self_intersections = options.allow_self_intersections;
    opt.face_sort_bytes = shares.face_sort_bytes;
    opt.leaf_triangles = shares.leaf_triangles;
    stream(t0, BlockPmReport{},
           [&](OpSink& sink, BlockPmStats& st) { build_block_pm(*mesh, sink, opt, &st); });
  }
};

// Shortest text that reads back as v.
std::string number(double v) {
  char buf[32];
  return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
}

}  // namespace

IngestPath choose_path(const std::string& input, const IngestOptions& options) {
  const bool blocks = options.builder == IngestBuilder::kBlocks ||
                      (options.builder == IngestBuilder::kAuto && options.memory.total_bytes != 0);
  if (is_mesh_path(input)) return blocks ? IngestPath::kBlockPm : IngestPath::kQemPm;
  return blocks ? IngestPath::kBlockTin : IngestPath::kGreedyTin;
}

std::string describe(const std::string& input, const IngestOptions& o) {
  const IngestPath path = choose_path(input, o);
  const bool mesh = path == IngestPath::kQemPm || path == IngestPath::kBlockPm;
  const std::string memory =
      o.memory.total_bytes == 0 ? std::string() : " memory=" + std::to_string(o.memory.total_bytes);
  std::string s = "input=" + file_name(input) + " max-error=" + number(o.max_error) +
                  " max-vertices=" + std::to_string(o.max_vertices) +
                  " base-vertices=" + std::to_string(o.base_vertices) +
                  " codec=" + std::string(storage::codec_name(o.codec)) +
                  " z-quantum=" + number(o.z_quantum) + " page-kb=" + std::to_string(o.page_kb);
  if (mesh && o.allow_self_intersections) s += " self-intersections=allowed";
  switch (path) {
    case IngestPath::kBlockPm:
      return s + " builder=blocks" + memory;
    case IngestPath::kQemPm:
      return s + " repair=" + (o.repair ? "yes" : "no") +
             " coalesce=" + std::to_string(o.coalesce) +
             " coalesce-ratio=" + number(o.coalesce_ratio);
    case IngestPath::kBlockTin:
      return s + " builder=blocks block-cells=" + std::to_string(o.block_cells) + memory;
    case IngestPath::kGreedyTin:
      break;
  }
  return s;
}

IngestReport ingest(const std::string& input, const std::string& db_path,
                    const IngestOptions& options, const IngestProgress& progress) {
  const IngestPath path = choose_path(input, options);
  if (options.memory.total_bytes != 0 &&
      (path == IngestPath::kQemPm || path == IngestPath::kGreedyTin)) {
    throw_input(
        "a memory budget needs a block builder: the in-memory builders hold the whole "
        "input");
  }
  if (options.page_kb < 1 || options.page_kb > 4096)
    throw_input("the page size must be 1 to 4096 KiB");
  Run run{input, db_path, options, progress, divide(options.memory, path), {}};
  switch (path) {
    case IngestPath::kQemPm:
      run.qem_pm();
      break;
    case IngestPath::kBlockPm:
      run.block_pm();
      break;
    case IngestPath::kGreedyTin:
      run.greedy_tin();
      break;
    case IngestPath::kBlockTin:
      run.block_tin();
      break;
  }
  return std::move(run.report);
}

}  // namespace smr
