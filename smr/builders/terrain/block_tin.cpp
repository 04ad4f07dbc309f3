// Hierarchical block decimation into a CRMR; block_tin.h describes the method (Hoppe 1998,
// "Smooth view-dependent level-of-detail control and its application to terrain rendering",
// section 4; De Floriani et al., LOD part two: independent-set decimation; Brown 4.4.3.3).
//
// The driver: the survey, then the passes, each in a file of its own, over state passed to them
// explicitly:
//  - sample_spill.h: the scratch copy of the samples the later passes re-read;
//  - block_tin_leaves.h: the leaf pass (greedy TIN per leaf block from shared border vertices),
//    with block_tin_lawson.h, the Lawson repair across the leaves' borders;
//  - block_tin_levels.h: the level decimation (2x2 block merges, independent sets of vertex
//    removals, block_tin_removal.h, with exact or overlay bounds, block_tin_bounds.h);
//  - here: handing the removals to the out-of-core assembler (op_assembly.h) as they are merged,
//    and the CRMR's header and R^0 at the end.
// The records they share (the mesh, the grid, the settings) are in block_tin_mesh.h.
#include "smr/builders/terrain/block_tin.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "base/error.h"
#include "smr/builders/op_assembly.h"
#include "smr/builders/terrain/block_tin_lawson.h"
#include "smr/builders/terrain/block_tin_leaves.h"
#include "smr/builders/terrain/block_tin_levels.h"
#include "smr/builders/terrain/block_tin_mesh.h"
#include "smr/builders/terrain/sample_spill.h"
#include "storage/temp_file.h"

namespace smr {
namespace {

using block_tin::decimate_blocks;
using block_tin::DecimationScratch;
using block_tin::Grid;
using block_tin::kNone;
using block_tin::LawsonRepair;
using block_tin::LeafConflict;
using block_tin::LeafPass;
using block_tin::Mesh;
using block_tin::MTri;
using block_tin::MVert;
using block_tin::Removal;
using block_tin::report;
using block_tin::SampleSpill;
using block_tin::Setup;
using block_tin::since;

/// The settings of a build of `dem`, checked; stop_error and eps0 are the survey's to set.
Setup make_setup(const RasterWindows& dem, const BlockTinOptions& opt) {
  Setup s{dem, opt, Grid{}};
  Grid& g = s.grid;
  g.W = dem.width();
  g.H = dem.height();
  if (g.W < 2 || g.H < 2) {
    throw_input(dem.source() + ": a DEM needs at least 2x2 samples, got " + std::to_string(g.W) +
                "x" + std::to_string(g.H));
  }
  if (opt.block_cells < 8 || (opt.block_cells & (opt.block_cells - 1)) != 0) {
    throw_input("block size " + std::to_string(opt.block_cells) +
                " cells: expected a power of two, at least 8");
  }
  if (opt.max_degree < 3) throw_input("max_degree must be at least 3");
  if (!(opt.max_error >= 0.0) || !std::isfinite(opt.max_error)) {
    throw_input("max_error must be a finite number >= 0");
  }
  g.B = opt.block_cells;
  s.exact_window_samples = opt.exact_window_samples;
  g.bw = (g.W - 2) / g.B + 1;
  g.bh = (g.H - 2) / g.B + 1;
  int span = 1;
  g.levels = 0;
  while (span < std::max(g.bw, g.bh)) {
    span *= 2;
    ++g.levels;
  }
  return s;
}

/// The survey: the DEM's global tolerance (into `tol`) and range, read one block at a time; sets
/// the error M^m is built to and the first stage's tolerance.
void survey(Setup& setup, BlockTinStats& stats, double& tol) {
  const Grid& g = setup.grid;
  float zmin = std::numeric_limits<float>::infinity(), zmax = -zmin, zabs = 0.0f;
  std::uint64_t valid = 0;
  for (int by = 0; by < g.bh; ++by) {
    for (int bx = 0; bx < g.bw; ++bx) {
      const int c0 = g.block_col0(bx), r0 = g.block_row0(by);
      const Heightfield w =
          setup.dem.read(c0, r0, g.block_col1(bx) - c0 + 1, g.block_row1(by) - r0 + 1);
      stats.max_block_samples = std::max<std::uint64_t>(stats.max_block_samples, w.z.size());
      for (std::size_t i = 0; i < w.z.size(); ++i) {
        if (!w.valid.empty() && w.valid[i] == 0) continue;
        zmin = std::min(zmin, w.z[i]);
        zmax = std::max(zmax, w.z[i]);
        zabs = std::max(zabs, std::abs(w.z[i]));
        ++valid;
      }
    }
  }
  if (valid == 0) throw_input(setup.dem.source() + ": every sample is no data");
  tol = 1e-9 * std::max(1.0, double(zabs));  // exact_tolerance of the whole DEM
  const double range = double(zmax) - double(zmin);
  setup.stop_error = std::max(setup.opt.max_error, tol);
  // Levels' tolerances grow 4x per level from here (a block's mesh keeps its size as blocks
  // merge 2x2 when the vertex density falls with the error); one stage per factor sqrt(2).
  setup.eps0 = std::max({setup.stop_error, range * std::ldexp(1.0, -14), tol});
}

using StarTriangle = OpAssembler::StarTriangle;
StarTriangle star_triangle(const Mesh& mesh, std::uint32_t t) {
  const MTri& x = mesh.tris[t];
  return StarTriangle{x.v, t, x.creator, x.is_void};
}

/// The removals, in the order they were made, go to the out-of-core assembler as they are
/// merged (feed()), which orders them by falling error, links them and hands each op to the
/// sink (assemble()).
class Feeder {
 public:
  explicit Feeder(const BlockTinOptions& opt) {
    AssemblyOptions ao;
    ao.tmp_dir = opt.tmp_dir;
    ao.sort_bytes = opt.assembly_sort_bytes;
    ao.table_bytes = opt.assembly_table_bytes;
    ao.threads = opt.threads;
    ao.progress = [&opt](double f) { report(opt, 0.9 + 0.1 * f); };
    assembler_ = std::make_unique<OpAssembler>(ao);
  }

  /// Hands the removals merged since the last call to the assembler (their triangles are final).
  void feed(const Mesh& mesh) {
    Clock::time_point t0 = Clock::now();
    for (; fed_ < mesh.removals.size(); ++fed_) {
      const Removal& r = mesh.removals[fed_];
      star_.clear();
      for (std::uint32_t i = r.star_begin; i < r.star_end; ++i) {
        star_.push_back(star_triangle(mesh, mesh.star_ids[i]));
      }
      made_.clear();
      for (std::uint32_t t = r.new_begin; t < r.new_end; ++t) {
        made_.push_back({mesh.tris[t].v, t, mesh.tris[t].is_void});
      }
      assembler_->add_removal(std::span(&r.vertex, 1), star_, made_, r.err);
    }
    seconds_ += since(t0);
  }

  OpAssembler& assembler() { return *assembler_; }
  /// Seconds spent handing removals over.
  double seconds() const { return seconds_; }

 private:
  std::unique_ptr<OpAssembler> assembler_;
  std::size_t fed_ = 0;  // removals handed over
  std::vector<StarTriangle> star_;
  std::vector<OpAssembler::MadeTriangle> made_;
  double seconds_ = 0.0;
};

/// The CRMR: the last removals to the assembler, then R^0 (the live triangles) and the header,
/// and the assembly, which hands every op to `sink`. Frees the build records as it goes.
void assemble(const Setup& setup, Mesh& mesh, DecimationScratch& scratch, Feeder& feeder,
              const SampleSpill& spill, std::uint64_t finest_vertices, BlockTinStats& stats,
              OpSink& sink) {
  const RasterWindows& dem = setup.dem;
  const BlockTinOptions& opt = setup.opt;
  auto world = [&dem](const MVert& v) {
    const Georef& g = dem.georef();
    return Vec3{g.x0 + v.col * g.dx, g.y0 + v.row * g.dy, double(v.z)};
  };
  const std::size_t m = mesh.removals.size();
  CrmrInfo info;
  info.kind = ModelKind::kTerrain;
  info.georef = dem.georef();
  info.grid_width = setup.grid.W;
  info.grid_height = setup.grid.H;
  info.source = dem.source();
  info.builder = "block-decimation max_error=" + std::to_string(opt.max_error) +
                 " block_cells=" + std::to_string(setup.grid.B) +
                 " max_degree=" + std::to_string(opt.max_degree);
  info.vertex_count = mesh.verts.size();
  for (const MVert& v : mesh.verts) info.bounds.add(world(v));

  feeder.feed(mesh);
  OpAssembler& assembler = feeder.assembler();
  std::vector<StarTriangle> base;
  double err0 = 0.0;
  for (std::uint32_t t = 0; t < mesh.tris.size(); ++t) {
    if (mesh.tris[t].destroyer == kNone) {
      base.push_back(star_triangle(mesh, t));
      err0 = std::max(err0, mesh.tris[t].bound.err());
    }
  }
  info.err0 = err0;
  info.err_final = mesh.err_final;
  stats.finest_vertices = finest_vertices;
  stats.samples_scanned = mesh.scanned;
  stats.temp_bytes = spill.bytes();
  stats.plans = mesh.plans;
  stats.finest_triangles = mesh.finest_triangles;
  stats.base_triangles = base.size();
  stats.removals = m;
  stats.levels = setup.grid.levels;
  {
    std::vector<std::uint8_t> seen(mesh.verts.size(), 0);
    for (const StarTriangle& t : base) {
      for (std::uint32_t v : t.v) seen[v] = 1;
    }
    stats.base_vertices = static_cast<std::uint64_t>(std::count(seen.begin(), seen.end(), 1));
  }
  // The build records are done with (the assembler has its own): the sink and the assembly
  // may use their memory. The vertices stay for their positions.
  mesh.tris.release();
  mesh.star_ids.release();
  std::vector<Removal>().swap(mesh.removals);
  scratch = DecimationScratch{};
  mesh.open_edges = IdMap<std::uint32_t>();
  assembler.finish(
      info, base, [&](std::uint32_t v) { return world(mesh.verts[v]); }, sink);
  stats.seconds_feed = feeder.seconds();
  stats.seconds_join = assembler.stats().seconds_join;
  stats.seconds_emit = assembler.stats().seconds_emit;
  stats.dag_height = assembler.stats().dag_height;
  stats.temp_bytes += assembler.stats().scratch_bytes;
}

void build(const RasterWindows& dem, const BlockTinOptions& opt, BlockTinStats& stats,
           OpSink& sink) {
  Setup setup = make_setup(dem, opt);
  const Grid& grid = setup.grid;
  auto feeder = std::make_unique<Feeder>(opt);
  Clock::time_point t = Clock::now();
  auto lap = [&](double& into) { into += since(t); };
  // A lossless build needs the DEM's largest |z| before any block (its tolerance decides which
  // errors are zero, on both sides of every border): one pass reads it. With a max error, the
  // tolerance only rounds bounds outward, and each block's own samples raise it as they come.
  // The samples' scratch copy serves the Delaunay repair of M^m, level 0 (always exact) and
  // the exact upper levels.
  SampleSpill spill(storage::scratch_dir(opt.tmp_dir), grid.W, grid.H, grid.B, grid.bw, grid.bh,
                    dem.random_access() ? &dem : nullptr);
  Mesh mesh;
  if (opt.max_error == 0.0) {
    survey(setup, stats, mesh.tol);
  } else {
    setup.stop_error = setup.eps0 = opt.max_error;
  }
  lap(stats.seconds_survey);
  // The reader's cache serves the leaf pass only: the upper levels re-read the scratch file.
  // A block's window with its halo spans three rows of the source's tiles; a cache that holds
  // them decodes each tile once (a 64 MiB cache re-decoded them up to 9 times on a 32769-wide
  // raster: reads took 116 s of a 193 s ingest).
  const std::uint64_t cache_before =
      opt.raster_cache_bytes != 0 ? dem.set_cache_bytes(opt.raster_cache_bytes) : 0;
  SampleSpill::Cache repair_tiles(std::min<std::size_t>(2 * std::size_t(grid.bw) + 4, 64));
  auto feed = [&] { feeder->feed(mesh); };
  bool level0_done = false;
  std::uint64_t valid_samples = 0;
  {
    LeafPass leaves(setup, mesh, spill, repair_tiles, stats);
    level0_done = leaves.run(feed);
    valid_samples = leaves.valid_samples();
  }
  lap(stats.seconds_leaves);
  if (valid_samples == 0) throw_input(dem.source() + ": every sample is no data");
  // Nothing reads the source from here on: hand its cache back.
  const std::uint64_t cap = dem.set_cache_bytes(0);
  dem.set_cache_bytes(opt.raster_cache_bytes != 0 ? cache_before : cap);
  DecimationScratch scratch;  // the overlay levels', on the whole mesh
  if (!level0_done) {
    LawsonRepair(setup, mesh, spill, repair_tiles, nullptr, stats).make_borders_delaunay();
    lap(stats.seconds_delaunay);
    decimate_blocks(setup, mesh, scratch, spill, stats, 0, feed);
    lap(stats.seconds_level0);
  }
  const std::uint64_t finest_vertices = mesh.verts.size();
  report(opt, 0.7);
  for (int level = 1; level <= grid.levels; ++level) {
    decimate_blocks(setup, mesh, scratch, spill, stats, level, feed);
    report(opt, 0.7 + 0.2 * double(level) / double(std::max(1, grid.levels)));
  }
  lap(stats.seconds_upper);
  // The build records at their largest: every triangle ever made is still in memory.
  stats.triangles_made = mesh.tris.size();
  stats.record_bytes = mesh.tris.size() * sizeof(MTri) + mesh.verts.size() * sizeof(MVert) +
                       mesh.removals.size() * sizeof(Removal) +
                       mesh.star_ids.size() * sizeof(std::uint32_t);
  assemble(setup, mesh, scratch, *feeder, spill, finest_vertices, stats, sink);
  feeder.reset();
  std::vector<MVert>().swap(mesh.verts);
  report(opt, 1.0);
  lap(stats.seconds_assemble);
}

}  // namespace

void build_block_tin(const RasterWindows& dem, OpSink& sink, const BlockTinOptions& options,
                     BlockTinStats* stats) {
  BlockTinStats local;
  BlockTinStats& st = stats != nullptr ? *stats : local;
  try {
    build(dem, options, st, sink);
  } catch (const LeafConflict&) {
    // Nothing reached the sink (ops are made after every level): start again, plain order.
    BlockTinOptions plain = options;
    plain.interleave_level0 = false;
    st = BlockTinStats{};
    st.level0_restarts = 1;
    build(dem, plain, st, sink);
  }
}

Crmr build_block_tin(const RasterWindows& dem, const BlockTinOptions& options,
                     BlockTinStats* stats) {
  CrmrCollector collector;
  build_block_tin(dem, collector, options, stats);
  return collector.take();
}

}  // namespace smr
