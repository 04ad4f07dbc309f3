// Hierarchical block decimation into a CRMR; block_tin.h describes the method.
//
// Geometry is exact where it decides topology: vertices sit on integer grid positions, so the
// orientation and in-circle tests of the hole re-triangulation are evaluated exactly in 64- and
// 128-bit integers. Errors are doubles, rounded outward by the DEM's exact tolerance.
#include "smr/builders/block_tin.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <deque>
#include <filesystem>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "base/error.h"
#include "smr/builders/greedy_tin.h"
#include "smr/builders/op_assembly.h"
#include "smr/builders/triangle_rows.h"
#include "smr/core/chunked.h"
#include "smr/core/id_map.h"
#include "smr/core/parallel.h"
#include "storage/temp_file.h"

namespace smr {
namespace {

constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
constexpr double kInfeasible = std::numeric_limits<double>::infinity();
/// Items between a level-0 block's copy and its merge in the interleaved leaf pass (and the most
/// the pass holds in flight).
constexpr std::size_t kLevel0Lag = 8;

/// Thrown by the Delaunay repair of an interleaved leaf pass when it reaches a triangle already
/// handed to a level-0 block: the build starts again without interleaving.
struct LeafConflict {};

struct MVert {
  std::int32_t col = 0, row = 0;
  float z = 0.0f;
  std::uint32_t tri = kNone;  // a live triangle having this vertex
  bool sticky = false;        // a corner of a void triangle: never removed
};

/// One-sided bounds of the source against a triangle's plane: source - plane <= up and
/// plane - source <= down over the triangle; zlo <= source <= zhi there. Signed bounds combine
/// across an overlay much more tightly than |source - plane|: the largest plane difference in
/// one direction adds to one side only.
struct TriBound {
  double up = 0.0, down = 0.0;
  float zlo = 0.0f, zhi = 0.0f;
  double err() const { return std::max(up, down); }
};

struct MTri {
  std::array<std::uint32_t, 3> v{};                       // counter-clockwise in grid space
  std::array<std::uint32_t, 3> nbr{kNone, kNone, kNone};  // across edge k = (v[k], v[k+1])
  TriBound bound;                   // of the source against the triangle's plane
  std::uint32_t creator = kNone;    // removal whose hole it fills; kNone = M^m
  std::uint32_t destroyer = kNone;  // removal whose star it is in; kNone = alive
  bool is_void = false;
  bool copied = false;  // handed to a level-0 block while leaves were still being merged
};

struct Removal {
  std::uint32_t vertex = 0;
  std::uint32_t star_begin = 0, star_end = 0;  // into Builder::star_ids_, counter-clockwise
  std::uint32_t new_begin = 0, new_end = 0;    // triangle ids (consecutive)
  double err = 0.0;                            // the largest error of the hole's triangles
};

std::int64_t orient(const MVert& a, const MVert& b, const MVert& c) {
  return std::int64_t(b.col - a.col) * (c.row - a.row) -
         std::int64_t(b.row - a.row) * (c.col - a.col);
}

__extension__ using Int128 = __int128;  // exact in-circle on grid coordinates up to 2^30

/// > 0 iff d lies strictly inside the circle through the counter-clockwise a, b, c.
bool in_circle(const MVert& a, const MVert& b, const MVert& c, const MVert& d) {
  const Int128 adx = a.col - d.col, ady = a.row - d.row, bdx = b.col - d.col, bdy = b.row - d.row,
               cdx = c.col - d.col, cdy = c.row - d.row;
  const Int128 det = (adx * adx + ady * ady) * (bdx * cdy - cdx * bdy) +
                     (bdx * bdx + bdy * bdy) * (cdx * ady - adx * cdy) +
                     (cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady);
  return det > 0;
}

/// z = a * col + b * row + c through three grid points.
struct Plane {
  double a = 0.0, b = 0.0, c = 0.0;
  Plane(const MVert& p, const MVert& q, const MVert& r) {
    const double x1 = q.col - p.col, y1 = q.row - p.row, x2 = r.col - p.col, y2 = r.row - p.row;
    const double z1 = double(q.z) - p.z, z2 = double(r.z) - p.z;
    const double det = x1 * y2 - x2 * y1;
    a = (z1 * y2 - z2 * y1) / det;
    b = (z2 * x1 - z1 * x2) / det;
    c = double(p.z) - a * p.col - b * p.row;
  }
  double at(double col, double row) const { return a * col + b * row + c; }
};

/// The vertices of 1-D line samples z[0..n) kept so that linear interpolation between kept
/// neighbours is within `tol` of every sample (Douglas-Peucker with vertical error), plus every
/// sample with valid[i] == 0 (no data on or next to it) and its neighbours. Deterministic in the
/// samples alone, so the two blocks that share a border line keep the same vertices.
std::vector<int> simplify_line(const std::vector<float>& z, const std::vector<std::uint8_t>& valid,
                               double tol) {
  const int n = static_cast<int>(z.size());
  std::vector<std::uint8_t> keep(n, 0);
  keep[0] = keep[n - 1] = 1;
  if (!valid.empty()) {
    for (int i = 0; i < n; ++i) {
      if (valid[i] != 0) continue;
      for (int j = std::max(0, i - 1); j <= std::min(n - 1, i + 1); ++j) keep[j] = 1;
    }
  }
  std::vector<std::pair<int, int>> pending;
  int prev = 0;
  for (int i = 1; i < n; ++i) {
    if (keep[i]) {
      if (i - prev > 1) pending.push_back({prev, i});
      prev = i;
    }
  }
  while (!pending.empty()) {
    auto [lo, hi] = pending.back();
    pending.pop_back();
    double worst = tol;
    int at = -1;
    for (int i = lo + 1; i < hi; ++i) {
      const double t = double(i - lo) / double(hi - lo);
      const double e = std::abs(double(z[i]) - (double(z[lo]) + t * (double(z[hi]) - z[lo])));
      if (e > worst) {
        worst = e;
        at = i;
      }
    }
    if (at < 0) continue;
    keep[at] = 1;
    if (at - lo > 1) pending.push_back({lo, at});
    if (hi - at > 1) pending.push_back({at, hi});
  }
  std::vector<int> out;
  for (int i = 0; i < n; ++i) {
    if (keep[i]) out.push_back(i);
  }
  return out;
}

/// The DEM's samples, copied block by block to a scratch file as the leaf pass reads them, so the
/// later passes re-read their windows from it (page cache, plain floats) instead of decoding the
/// source again. Tile (tx, ty) holds the leaf block (tx, ty)'s whole window: columns
/// [tx * B, min(tx * B + B, W - 1)], rows likewise, so its closing column and row (shared with
/// the next tiles) are there too and a window inside the blocks stored so far reads no other.
/// A source that reads in place from several threads at once (RasterWindows::random_access: a
/// .npy, memory) is not copied: `put` only records that the tile is stored, and the tiles are
/// read from the source itself, with the same samples and the same "not stored yet" rule.
class SampleSpill {
 public:
  SampleSpill(const std::string& dir, int width, int height, int b, int nx, int ny,
              const RasterWindows* direct)
      : W_(width),
        H_(height),
        B_(b),
        nx_(nx),
        ny_(ny),
        stride_(std::uint64_t(b + 1) * std::uint64_t(b + 1)),
        stored_(std::size_t(nx) * std::size_t(ny), 0),
        direct_(direct),
        file_(direct != nullptr ? nullptr
                                : std::make_unique<storage::TempFile>(
                                      dir, std::uint64_t(nx) * std::uint64_t(ny) * stride_ * 5)) {}

  /// Whole tiles kept by one caller (not shared between threads), the oldest dropped first: many
  /// small windows in one area cost one read of each tile.
  struct Cache {
    struct Tile {
      int tx = -1, ty = -1;
      std::vector<float> z;
      std::vector<std::uint8_t> v;
    };
    explicit Cache(std::size_t tiles_kept) : capacity(tiles_kept) {}
    std::size_t capacity;
    std::deque<Tile> tiles;
  };

  /// Puts tile (tx, ty), stored already, in `cache` from window w, whose sample (0, 0) is grid
  /// (c0, r0): its samples are at hand, no read brings them back.
  void warm(Cache& cache, int tx, int ty, const Heightfield& w, int c0, int r0) const {
    const auto [cw, rh] = extent(tx, ty);
    bool fresh = false;
    Cache::Tile& t = entry(cache, tx, ty, fresh);
    for (int r = 0; r < rh; ++r) {
      const std::size_t from = w.index(tx * B_ - c0, ty * B_ - r0 + r);
      const std::size_t to = std::size_t(r) * std::size_t(cw);
      std::memcpy(t.z.data() + to, w.z.data() + from, std::size_t(cw) * sizeof(float));
      if (w.valid.empty()) {
        std::fill_n(t.v.begin() + std::ptrdiff_t(to), cw, std::uint8_t{1});
      } else {
        std::memcpy(t.v.data() + to, w.valid.data() + from, std::size_t(cw));
      }
    }
  }

  /// Stores tile (tx, ty) from window w, whose sample (0, 0) is grid (c0, r0). One thread at a
  /// time stores tiles; others may read the tiles stored before meanwhile.
  void put(int tx, int ty, const Heightfield& w, int c0, int r0) {
    const auto [cw, rh] = extent(tx, ty);
    if (direct_ != nullptr) {
      stored_[std::size_t(ty) * std::size_t(nx_) + std::size_t(tx)] = 1;
      return;
    }
    // Buffers kept across tiles (one caller, the reading thread): no fresh pages per tile.
    std::vector<float>& z = put_z_;
    std::vector<std::uint8_t>& v = put_v_;
    z.resize(static_cast<std::size_t>(cw) * static_cast<std::size_t>(rh));
    v.assign(z.size(), 1);
    for (int r = 0; r < rh; ++r) {
      const std::size_t from = w.index(tx * B_ - c0, ty * B_ - r0 + r);
      const std::size_t to = std::size_t(r) * std::size_t(cw);
      std::memcpy(z.data() + to, w.z.data() + from, std::size_t(cw) * sizeof(float));
      if (!w.valid.empty()) std::memcpy(v.data() + to, w.valid.data() + from, std::size_t(cw));
    }
    const std::uint64_t at = offset(tx, ty);
    file_->write(at, z.data(), z.size() * sizeof(float));
    file_->write(at + stride_ * sizeof(float), v.data(), v.size());
    stored_[std::size_t(ty) * std::size_t(nx_) + std::size_t(tx)] = 1;
  }

  /// Samples [col0, col0 + w) x [row0, row0 + h), as RasterWindows::read, from the tiles that
  /// hold them (a window's last column and row come from the tile before, where it has one); a
  /// tile not stored yet reads as no data. With a cache, whole tiles are read into it; without,
  /// only the window's bytes are read.
  Heightfield read(int col0, int row0, int w, int h, const RasterWindows& source,
                   Cache* cache = nullptr) const {
    Heightfield out;
    read_into(out, col0, row0, w, h, source, cache);
    return out;
  }

  /// The same into `out`, reusing its buffers (a thread's windows one after another fault in no
  /// fresh pages; every sample is written).
  void read_into(Heightfield& out, int col0, int row0, int w, int h, const RasterWindows& source,
                 Cache* cache = nullptr) const {
    const int tx0 = tile_of(col0, nx_), tx1 = tile_of(std::max(col0, col0 + w - 2), nx_);
    const int ty0 = tile_of(row0, ny_), ty1 = tile_of(std::max(row0, row0 + h - 2), ny_);
    if (direct_ != nullptr && cache == nullptr && all_stored(tx0, tx1, ty0, ty1)) {
      direct_->read_into(out, col0, row0, w, h);  // the whole window in one read, no copies
      return;
    }
    set_window_header(out, source.georef(), source.source(), col0, row0, w, h);
    out.z.resize(std::size_t(w) * std::size_t(h));
    out.valid.resize(out.z.size());
    for (int ty = ty0; ty <= ty1; ++ty) {
      for (int tx = tx0; tx <= tx1; ++tx) {
        const auto [cw, rh] = extent(tx, ty);
        const int c_lo = std::max(col0, tx * B_);
        const int c_hi = tx == tx1 ? col0 + w : std::min(col0 + w, tx * B_ + B_);
        const int r_lo = std::max(row0, ty * B_);
        const int r_hi = ty == ty1 ? row0 + h : std::min(row0 + h, ty * B_ + B_);
        const std::size_t n = std::size_t(c_hi - c_lo);
        const std::size_t rows = std::size_t(r_hi - r_lo);
        if (!stored(tx, ty)) {
          for (std::size_t r = 0; r < rows; ++r) {
            const std::size_t o = out.index(c_lo - col0, r_lo - row0 + int(r));
            std::fill_n(out.valid.begin() + std::ptrdiff_t(o), n, std::uint8_t{0});
          }
          // Its first column and row are also the closing ones of the tiles before it: take them
          // from there (a corner of the blocks read so far, whichever tile the window's range
          // gave it to).
          for (int r = r_lo; r < r_hi; ++r) {
            for (int c = c_lo; c < c_hi; ++c) {
              if (c != tx * B_ && r != ty * B_) continue;
              const int sx = c == tx * B_ && tx > 0 ? tx - 1 : tx;
              const int sy = r == ty * B_ && ty > 0 ? ty - 1 : ty;
              if ((sx == tx && sy == ty) || !stored(sx, sy)) continue;
              const std::size_t o = out.index(c - col0, r - row0);
              sample(sx, sy, c, r, cache, out.z[o], out.valid[o]);
            }
          }
          continue;
        }
        if (cache != nullptr) {
          const Cache::Tile& tile = cached(*cache, tx, ty);
          const std::size_t pitch = std::size_t(cw);
          const std::size_t first =
              std::size_t(r_lo - ty * B_) * pitch + std::size_t(c_lo - tx * B_);
          for (std::size_t r = 0; r < rows; ++r) {
            const std::size_t o = out.index(c_lo - col0, r_lo - row0 + int(r));
            std::memcpy(out.z.data() + o, tile.z.data() + first + r * pitch, n * sizeof(float));
            std::memcpy(out.valid.data() + o, tile.v.data() + first + r * pitch, n);
          }
        } else {
          // Through buffers each thread keeps (no fresh pages to fault in per window).
          thread_local std::vector<float> z;
          thread_local std::vector<std::uint8_t> v;
          if (z.size() < n * rows) {
            z.resize(n * rows);
            v.resize(n * rows);
          }
          load(tx, ty, c_lo, r_lo, n, rows, z.data(), v.data());
          for (std::size_t r = 0; r < rows; ++r) {
            const std::size_t o = out.index(c_lo - col0, r_lo - row0 + int(r));
            std::memcpy(out.z.data() + o, z.data() + r * n, n * sizeof(float));
            std::memcpy(out.valid.data() + o, v.data() + r * n, n);
          }
        }
      }
    }
    const bool any_invalid =
        std::find(out.valid.begin(), out.valid.end(), std::uint8_t{0}) != out.valid.end();
    if (!any_invalid) out.valid.clear();
  }
  std::uint64_t bytes() const { return file_ ? file_->bytes_written() : 0; }

 private:
  bool stored(int tx, int ty) const {
    return stored_[std::size_t(ty) * std::size_t(nx_) + std::size_t(tx)] != 0;
  }
  bool all_stored(int tx0, int tx1, int ty0, int ty1) const {
    for (int ty = ty0; ty <= ty1; ++ty) {
      for (int tx = tx0; tx <= tx1; ++tx) {
        if (!stored(tx, ty)) return false;
      }
    }
    return true;
  }

  /// Sample (c, r) of stored tile (tx, ty), which holds it.
  void sample(int tx, int ty, int c, int r, Cache* cache, float& z, std::uint8_t& v) const {
    const std::size_t i =
        std::size_t(r - ty * B_) * std::size_t(extent(tx, ty).first) + std::size_t(c - tx * B_);
    if (cache != nullptr) {
      const Cache::Tile& tile = cached(*cache, tx, ty);
      z = tile.z[i];
      v = tile.v[i];
      return;
    }
    load(tx, ty, c, r, 1, 1, &z, &v);
  }

  /// Samples [c0, c0 + n) x [r0, r0 + rows) of stored tile (tx, ty), which holds them, into z and
  /// v (n to a row).
  void load(int tx, int ty, int c0, int r0, std::size_t n, std::size_t rows, float* z,
            std::uint8_t* v) const {
    if (direct_ != nullptr) {
      thread_local Heightfield window;  // its pages stay with the thread
      direct_->read_into(window, c0, r0, int(n), int(rows));
      std::memcpy(z, window.z.data(), n * rows * sizeof(float));
      if (window.valid.empty()) {
        std::fill_n(v, n * rows, std::uint8_t{1});
      } else {
        std::memcpy(v, window.valid.data(), n * rows);
      }
      return;
    }
    const int cw = extent(tx, ty).first;
    // Whole rows in one read when the piece spans the tile's width, else row by row.
    const bool whole_rows = c0 == tx * B_ && n == std::size_t(cw);
    const std::uint64_t at = offset(tx, ty);
    for (std::size_t r = 0; r < rows; r += whole_rows ? rows : 1) {
      const std::uint64_t first =
          std::uint64_t(r0 - ty * B_ + int(r)) * std::uint64_t(cw) + std::uint64_t(c0 - tx * B_);
      const std::size_t count = whole_rows ? n * rows : n;
      file_->read(at + first * sizeof(float), z + r * n, count * sizeof(float));
      file_->read(at + stride_ * sizeof(float) + first, v + r * n, count);
    }
  }

  const Cache::Tile& cached(Cache& cache, int tx, int ty) const {
    bool fresh = false;
    Cache::Tile& t = entry(cache, tx, ty, fresh);
    if (fresh) {
      const auto [cw, rh] = extent(tx, ty);
      load(tx, ty, tx * B_, ty * B_, std::size_t(cw), std::size_t(rh), t.z.data(), t.v.data());
    }
    return t;
  }
  /// Tile (tx, ty) of `cache`; if it is not there, a new one sized for it (`fresh`, its samples
  /// to be filled) in the oldest one's place when the cache is full.
  Cache::Tile& entry(Cache& cache, int tx, int ty, bool& fresh) const {
    fresh = false;
    for (auto& t : cache.tiles) {
      if (t.tx == tx && t.ty == ty) return t;
    }
    fresh = true;
    Cache::Tile reused;  // the oldest tile's buffers: no new pages to fault in and clear
    if (cache.tiles.size() >= cache.capacity) {
      reused = std::move(cache.tiles.front());
      cache.tiles.pop_front();
    }
    auto& t = cache.tiles.emplace_back(std::move(reused));
    t.tx = tx;
    t.ty = ty;
    const auto [cw, rh] = extent(tx, ty);
    t.z.resize(std::size_t(cw) * std::size_t(rh));
    t.v.resize(t.z.size());
    return t;
  }

 public:
  /// Tile (tx, ty)'s window (its leaf block's) into `out`, reusing its buffers, if `cache`
  /// holds it; false if not.
  bool read_cached(const Cache& cache, int tx, int ty, const RasterWindows& source,
                   Heightfield& out) const {
    for (const auto& t : cache.tiles) {
      if (t.tx != tx || t.ty != ty) continue;
      const auto [cw, rh] = extent(tx, ty);
      set_window_header(out, source.georef(), source.source(), tx * B_, ty * B_, cw, rh);
      out.z.assign(t.z.begin(), t.z.end());
      if (std::find(t.v.begin(), t.v.end(), std::uint8_t{0}) != t.v.end()) {
        out.valid.assign(t.v.begin(), t.v.end());
      } else {
        out.valid.clear();
      }
      return true;
    }
    return false;
  }

 private:
  /// Columns and rows of tile (tx, ty): its leaf block's window.
  std::pair<int, int> extent(int tx, int ty) const {
    return {std::min(tx * B_ + B_, W_ - 1) - tx * B_ + 1,
            std::min(ty * B_ + B_, H_ - 1) - ty * B_ + 1};
  }
  int tile_of(int x, int n) const { return std::min(x / B_, n - 1); }
  std::uint64_t offset(int tx, int ty) const {
    return (std::uint64_t(ty) * std::uint64_t(nx_) + std::uint64_t(tx)) * stride_ * 5;
  }
  int W_, H_, B_, nx_, ny_;
  std::uint64_t stride_;
  std::vector<std::uint8_t> stored_;  // tile -> put yet
  std::vector<float> put_z_;          // put's buffers
  std::vector<std::uint8_t> put_v_;
  const RasterWindows* direct_;  // the source, read in place; or
  std::unique_ptr<storage::TempFile> file_;
};

class Builder {
  struct EdgeTask;
  struct UpperBlock;

 public:
  Builder(const RasterWindows& dem, const BlockTinOptions& opt, BlockTinStats& stats)
      : dem_(dem), opt_(opt), stats_(stats), W_(dem.width()), H_(dem.height()) {
    if (W_ < 2 || H_ < 2) {
      throw_input(dem.source() + ": a DEM needs at least 2x2 samples, got " + std::to_string(W_) +
                  "x" + std::to_string(H_));
    }
    if (opt.block_cells < 8 || (opt.block_cells & (opt.block_cells - 1)) != 0) {
      throw_input("block size " + std::to_string(opt.block_cells) +
                  " cells: expected a power of two, at least 8");
    }
    if (opt.max_degree < 3) throw_input("max_degree must be at least 3");
    if (!(opt.max_error >= 0.0) || !std::isfinite(opt.max_error)) {
      throw_input("max_error must be a finite number >= 0");
    }
    B_ = opt.block_cells;
    exact_window_samples_ = opt.exact_window_samples;
    bw_ = (W_ - 2) / B_ + 1;
    bh_ = (H_ - 2) / B_ + 1;
    int span = 1;
    levels_ = 0;
    while (span < std::max(bw_, bh_)) {
      span *= 2;
      ++levels_;
    }
  }

  void run(OpSink& sink) {
    make_assembler();
    Clock::time_point t = Clock::now();
    auto lap = [&](double& into) {
      const Clock::time_point now = Clock::now();
      into += std::chrono::duration<double>(now - t).count();
      t = now;
    };
    // A lossless build needs the DEM's largest |z| before any block (its tolerance decides which
    // errors are zero, on both sides of every border): one pass reads it. With a max error, the
    // tolerance only rounds bounds outward, and each block's own samples raise it as they come.
    // The samples' scratch copy serves the Delaunay repair of M^m, level 0 (always exact) and
    // the exact upper levels.
    {
      const std::string dir = storage::scratch_dir(opt_.tmp_dir);
      spill_ = std::make_unique<SampleSpill>(dir, W_, H_, B_, bw_, bh_,
                                             dem_.random_access() ? &dem_ : nullptr);
    }
    if (opt_.max_error == 0.0) {
      survey();
    } else {
      stop_error_ = eps0_ = opt_.max_error;
    }
    lap(stats_.seconds_survey);
    // The reader's cache serves the leaf pass only: the upper levels re-read the scratch file.
    // A block's window with its halo spans three rows of the source's tiles; a cache that holds
    // them decodes each tile once (a 64 MiB cache re-decoded them up to 9 times on a 32769-wide
    // raster: reads took 116 s of a 193 s ingest).
    const std::uint64_t cache_before =
        opt_.raster_cache_bytes != 0 ? dem_.set_cache_bytes(opt_.raster_cache_bytes) : 0;
    repair_tiles_.capacity = std::min<std::size_t>(2 * std::size_t(bw_) + 4, 64);
    leaf_pass();
    lap(stats_.seconds_leaves);
    if (valid_samples_ == 0) throw_input(dem_.source() + ": every sample is no data");
    // Nothing reads the source from here on: hand its cache back, and the leaf pass's maps.
    const std::uint64_t cap = dem_.set_cache_bytes(0);
    dem_.set_cache_bytes(opt_.raster_cache_bytes != 0 ? cache_before : cap);
    shared_ = IdMap<std::uint32_t>();
    if (!level0_done_) {
      make_borders_delaunay();
      lap(stats_.seconds_delaunay);
      decimate_blocks(0);
      lap(stats_.seconds_level0);
    }
    finest_vertices_ = verts_.size();
    report(0.7);
    for (int level = 1; level <= levels_; ++level) {
      decimate_blocks(level);
      report(0.7 + 0.2 * double(level) / double(std::max(1, levels_)));
    }
    lap(stats_.seconds_upper);
    // The build records at their largest: every triangle ever made is still in memory.
    stats_.triangles_made = tris_.size();
    stats_.record_bytes = tris_.size() * sizeof(MTri) + verts_.size() * sizeof(MVert) +
                          removals_.size() * sizeof(Removal) +
                          star_ids_.size() * sizeof(std::uint32_t);
    assemble(sink);
    lap(stats_.seconds_assemble);
  }

 private:
  // ---- the survey: global tolerance and range, read one block at a time ----
  void survey() {
    float zmin = std::numeric_limits<float>::infinity(), zmax = -zmin, zabs = 0.0f;
    std::uint64_t valid = 0;
    for (int by = 0; by < bh_; ++by) {
      for (int bx = 0; bx < bw_; ++bx) {
        const Heightfield w = window(bx, by);
        for (std::size_t i = 0; i < w.z.size(); ++i) {
          if (!w.valid.empty() && w.valid[i] == 0) continue;
          zmin = std::min(zmin, w.z[i]);
          zmax = std::max(zmax, w.z[i]);
          zabs = std::max(zabs, std::abs(w.z[i]));
          ++valid;
        }
      }
    }
    if (valid == 0) throw_input(dem_.source() + ": every sample is no data");
    tol_ = 1e-9 * std::max(1.0, double(zabs));  // exact_tolerance of the whole DEM
    range_ = double(zmax) - double(zmin);
    stop_error_ = std::max(opt_.max_error, tol_);
    // Levels' tolerances grow 4x per level from here (a block's mesh keeps its size as blocks
    // merge 2x2 when the vertex density falls with the error); one stage per factor sqrt(2).
    eps0_ = std::max({stop_error_, range_ * std::ldexp(1.0, -14), tol_});
  }

  int block_col0(int bx) const { return bx * B_; }
  int block_col1(int bx) const { return std::min(bx * B_ + B_, W_ - 1); }
  int block_row0(int by) const { return by * B_; }
  int block_row1(int by) const { return std::min(by * B_ + B_, H_ - 1); }
  Heightfield window(int bx, int by) const {
    const int c0 = block_col0(bx), r0 = block_row0(by);
    Heightfield w = dem_.read(c0, r0, block_col1(bx) - c0 + 1, block_row1(by) - r0 + 1);
    stats_.max_block_samples = std::max<std::uint64_t>(stats_.max_block_samples, w.z.size());
    return w;
  }

  // ---- phase 1: a leaf block's greedy TIN, then its level-0 decimation with exact errors ----
  using Clock = std::chrono::steady_clock;
  static double since(Clock::time_point& t) {
    const Clock::time_point now = Clock::now();
    const double s = std::chrono::duration<double>(now - t).count();
    t = now;
    return s;
  }

  /// A leaf block's samples and the tolerance it is built with, read in block order.
  struct LeafInput {
    int bx = 0, by = 0;
    Heightfield halo, w;  // the block's window with one sample around it, and the window
    double tol = 0.0;     // the tolerance so far: the largest |z| of this and earlier blocks
  };

  /// Reads leaf k = (bx, by), copies it to the scratch file, counts its samples. The workers
  /// read the leaves one at a time in block order (read_turns_: the reader is not shared between
  /// threads and the tolerance is a running maximum), so the calling thread, which merges the
  /// leaves in order, is left the merges.
  LeafInput read_leaf(std::size_t k) {
    return read_turns_.run(k, [&] { return read_leaf_now(k); });
  }
  LeafInput read_leaf_now(std::size_t k) {
    const int bx = int(k % std::size_t(bw_)), by = int(k / std::size_t(bw_));
    const Clock::time_point t0 = Clock::now();
    LeafInput in;
    in.halo = spare_window();
    in.w = spare_window();
    in.bx = bx;
    in.by = by;
    // The block's window and a halo of one sample around it, which the border rule below reads:
    // both blocks that share a border line see the same samples on either side of it.
    const int c0 = block_col0(bx), r0 = block_row0(by);
    const int hc0 = std::max(0, c0 - 1), hr0 = std::max(0, r0 - 1);
    const int hc1 = std::min(W_ - 1, block_col1(bx) + 1),
              hr1 = std::min(H_ - 1, block_row1(by) + 1);
    dem_.read_into(in.halo, hc0, hr0, hc1 - hc0 + 1, hr1 - hr0 + 1);
    HeightfieldWindows(in.halo).read_into(in.w, c0 - hc0, r0 - hr0, block_col1(bx) - c0 + 1,
                                          block_row1(by) - r0 + 1);
    const Heightfield& w = in.w;
    // Not stats_.max_block_samples: this thread merges level-0 blocks into it meanwhile.
    read_max_samples_ = std::max<std::uint64_t>(read_max_samples_, in.halo.z.size());
    if (spill_) spill_->put(bx, by, w, c0, r0);
    for (std::size_t i = 0; i < w.z.size(); ++i) {
      if (!w.valid.empty() && w.valid[i] == 0) continue;
      ++valid_samples_;
      if (opt_.max_error != 0.0) read_tol_ = std::max(read_tol_, 1e-9 * std::abs(double(w.z[i])));
    }
    if (opt_.max_error != 0.0) read_tol_ = std::max(read_tol_, 1e-9);
    in.tol = read_tol_;
    leaf_tol_[k] = read_tol_;
    ++stats_.leaf_blocks;
    stats_.samples += w.z.size();
    stats_.seconds_read += std::chrono::duration<double>(Clock::now() - t0).count();
    return in;
  }

  /// A window whose buffers a worker handed back (or a new one): the leaf pass's windows reuse
  /// pages already faulted in instead of fresh ones. They are taken on the calling thread and
  /// handed back by the workers, so at most the pipeline's items' windows are ever out.
  Heightfield spare_window() {
    std::lock_guard lock(spare_mu_);
    if (spare_windows_.empty()) return {};
    Heightfield w = std::move(spare_windows_.back());
    spare_windows_.pop_back();
    return w;
  }
  void give_back(Heightfield&& w) {
    std::lock_guard lock(spare_mu_);
    spare_windows_.push_back(std::move(w));
  }

  /// Builds a read leaf block into this (empty) builder's records: its greedy TIN from the shared
  /// border vertices and their exact bounds. Runs on a worker thread; merge_leaf then appends the
  /// records to the whole mesh's.
  void build_leaf(const LeafInput& in) {
    Clock::time_point clock = Clock::now();
    tol_ = in.tol;
    const int bx = in.bx, by = in.by;
    const Heightfield& halo = in.halo;
    const Heightfield& w = in.w;
    const int c0 = block_col0(bx), r0 = block_row0(by);
    const int hc0 = std::max(0, c0 - 1), hr0 = std::max(0, r0 - 1);
    const int ww = w.width, wh = w.height;
    const double line_tol = stop_error_ * 0.999;  // below the 2-D test, whatever its rounding
    GreedyTinOptions g;
    g.max_error = opt_.max_error;
    g.tolerance = tol_;
    g.allow_no_data_only = true;
    g.freeze_border = true;
    // A border line's vertices: its 1-D simplification, plus every sample of it next to a no-data
    // sample (on the line or either side of it), so that the holes' edges need no other border
    // vertex.
    auto no_data_near = [&](int c, int r) {  // grid coordinates
      if (!halo.has_nodata()) return false;
      for (int dr = -1; dr <= 1; ++dr) {
        for (int dc = -1; dc <= 1; ++dc) {
          const int hc = c + dc - hc0, hr = r + dr - hr0;
          if (hc < 0 || hr < 0 || hc >= halo.width || hr >= halo.height) continue;
          if (!halo.has_data(hc, hr)) return true;
        }
      }
      return false;
    };
    auto border = [&](bool horizontal, int fixed) {
      const int n = horizontal ? ww : wh;
      std::vector<float> z(n);
      std::vector<std::uint8_t> valid;
      if (halo.has_nodata()) valid.resize(n);
      for (int i = 0; i < n; ++i) {
        const int c = horizontal ? i : fixed, r = horizontal ? fixed : i;
        z[i] = w.at(c, r);
        if (halo.has_nodata()) valid[i] = no_data_near(c0 + c, r0 + r) ? 0 : 1;
      }
      for (int i : simplify_line(z, valid, line_tol)) {
        g.initial_vertices.push_back(horizontal
                                         ? std::pair(std::uint32_t(i), std::uint32_t(fixed))
                                         : std::pair(std::uint32_t(fixed), std::uint32_t(i)));
      }
    };
    border(true, 0);
    border(true, wh - 1);
    border(false, 0);
    border(false, ww - 1);
    std::vector<std::pair<std::uint32_t, std::uint32_t>> prescribed = g.initial_vertices;
    std::sort(prescribed.begin(), prescribed.end());
    prescribed.erase(std::unique(prescribed.begin(), prescribed.end()), prescribed.end());

    const GreedyMesh tin = build_greedy_mesh(w, g);
    stats_.seconds_greedy += since(clock);

    // The final triangles, into the global mesh.
    const std::uint32_t first_tri = static_cast<std::uint32_t>(tris_.size());
    std::vector<std::uint32_t> local(tin.vertices.size(), kNone);  // greedy vertex id -> ours
    for (const GreedyMesh::Triangle& t : tin.triangles) {
      MTri m;
      for (int k = 0; k < 3; ++k) {
        const GreedyMesh::Vertex& gv = tin.vertices.at(t.v[k]);
        std::uint32_t& ours = local[t.v[k]];
        if (ours == kNone) {
          const int col = static_cast<int>(gv.col), row = static_cast<int>(gv.row);
          const bool on_border = col == 0 || row == 0 || col == ww - 1 || row == wh - 1;
          if (on_border && !std::binary_search(prescribed.begin(), prescribed.end(),
                                               std::pair(std::uint32_t(col), std::uint32_t(row)))) {
            throw_internal(dem_.source() + ": block (" + std::to_string(bx) + ", " +
                           std::to_string(by) + ") put a vertex on its border at (" +
                           std::to_string(c0 + col) + ", " + std::to_string(r0 + row) +
                           ") that its neighbour does not have");
          }
          ours = global_vertex(c0 + col, r0 + row, gv.z);
        }
        m.v[k] = ours;
      }
      m.is_void = t.is_void;
      tris_.push_back(m);
    }
    // Adjacency: within the block, and across its borders to earlier blocks.
    for (std::uint32_t t = first_tri; t < tris_.size(); ++t) {
      MTri& m = tris_[t];
      for (int k = 0; k < 3; ++k) {
        verts_[m.v[k]].tri = t;
        if (m.is_void) verts_[m.v[k]].sticky = true;
        const std::uint64_t back = edge_key(m.v[(k + 1) % 3], m.v[k]);
        if (const std::uint32_t* o = open_edges_.find(back); o != nullptr) {
          const std::uint32_t other = *o >> 2, oe = *o & 3;
          m.nbr[k] = other;
          tris_[other].nbr[oe] = t;
          open_edges_.erase(back);
        } else if (!boundary_edge(verts_[m.v[k]], verts_[m.v[(k + 1) % 3]])) {
          open_edges_[edge_key(m.v[k], m.v[(k + 1) % 3])] = (t << 2) | std::uint32_t(k);
        }
      }
    }
    // Exact errors of M^m from the window's samples.
    for (std::uint32_t t = first_tri; t < tris_.size(); ++t) {
      if (tris_[t].is_void) continue;
      TriBound& b = tris_[t].bound;
      b = exact_bound(tris_[t].v, w, c0, r0, false);
      if (b.err() > stop_error_ + tol_) {
        throw_internal(dem_.source() + ": a greedy TIN triangle exceeds the error it was built to");
      }
      b.up = std::min(b.up, stop_error_);  // within float rounding of the greedy's own test
      b.down = std::min(b.down, stop_error_);
      err_final_ = std::max(err_final_, b.err());
    }
    finest_triangles_ += tris_.size() - first_tri;
    stats_.seconds_greedy += since(clock);
    // Edges on the block's outer border wait for the neighbour.
  }

  /// Appends a leaf builder's records (built by build_leaf) to this one's, renumbered: vertices
  /// through global_vertex in the leaf's own order (so border vertices are shared and the ids
  /// are those a single pass would give), triangles after this one's, and the leaf's open border
  /// edges glued to the earlier blocks' or left open for later ones.
  /// With `glued`, the edges glued to earlier leaves are listed there and the leaf's vertices
  /// kept as leaf_vertices_[leaf_index] (the interleaved pass).
  void merge_leaf(Builder& leaf, std::vector<EdgeTask>* glued, std::size_t leaf_index) {
    const std::uint32_t tri_base = static_cast<std::uint32_t>(tris_.size());
    auto tri = [&](std::uint32_t t) { return t == kNone ? kNone : t + tri_base; };
    std::vector<std::uint32_t> vmap(leaf.verts_.size());
    for (std::size_t v = 0; v < leaf.verts_.size(); ++v) {
      const MVert& lv = leaf.verts_[v];
      const std::uint32_t g = global_vertex(lv.col, lv.row, lv.z);
      vmap[v] = g;
      verts_[g].tri = tri(lv.tri);  // the leaf wrote it last, as a single pass would
      verts_[g].sticky = verts_[g].sticky || lv.sticky;
    }
    if (glued != nullptr) leaf_vertices_[leaf_index] = vmap;
    leaf.tris_.drain([&](std::size_t, const MTri& lt) {
      MTri m = lt;
      for (int k = 0; k < 3; ++k) {
        m.v[k] = vmap[lt.v[k]];
        m.nbr[k] = tri(lt.nbr[k]);
      }
      tris_.push_back(m);
    });
    leaf.open_edges_.for_each([&](std::uint64_t key, std::uint32_t value) {
      const std::uint32_t a = vmap[key >> 32], b = vmap[key & 0xffffffffu];
      const std::uint32_t t = (value >> 2) + tri_base, e = value & 3;
      const std::uint64_t back = edge_key(b, a);
      if (const std::uint32_t* o = open_edges_.find(back); o != nullptr) {
        const std::uint32_t other = *o >> 2, oe = *o & 3;
        tris_[t].nbr[e] = other;
        tris_[other].nbr[oe] = t;
        open_edges_.erase(back);
        if (glued != nullptr) glued->push_back({t, a, b});
      } else {
        open_edges_[edge_key(a, b)] = (t << 2) | e;
      }
    });
    if (glued != nullptr)  // last first: repair pops them in triangle order
      std::sort(glued->begin(), glued->end(), [](const EdgeTask& x, const EdgeTask& y) {
        return std::tie(x.t, x.a, x.b) > std::tie(y.t, y.a, y.b);
      });
    err_final_ = std::max(err_final_, leaf.err_final_);
    finest_triangles_ += leaf.finest_triangles_;
    scanned_ += leaf.scanned_;
    stats_.seconds_greedy += leaf.stats_.seconds_greedy;
  }

  /// Every leaf block: read in order on this thread, built on `threads` workers, merged in
  /// order, so the records (and the database) do not depend on the number of threads.
  ///
  /// Interleaved (options.interleave_level0), each merge also repairs the Delaunay property
  /// across the borders the new leaf shares with earlier ones, and a leaf's level-0 block is
  /// copied out as soon as its last neighbour (the one below and to the right) is merged and
  /// repaired; it is decimated by the workers alongside later leaves and merged back kLevel0Lag
  /// items later. A later repair that would touch a triangle handed out so throws LeafConflict,
  /// and the build starts again in the plain order (every leaf, the whole repair, level 0). Every
  /// step is on the merge sequence, so the output does not depend on the thread count.
  void leaf_pass() {
    const std::size_t n = std::size_t(bw_) * std::size_t(bh_);
    struct Item {
      std::size_t k = 0;
      LeafInput in;
      BlockTinStats stats;
      std::unique_ptr<Builder> builder;   // the leaf's TIN
      std::unique_ptr<UpperBlock> block;  // a level-0 block
    };
    const unsigned threads = thread_count(opt_.threads);
    const bool interleave = opt_.interleave_level0 && levels_ > 0;
    // Item k + kLevel0Lag carries the block copied when leaf k was merged, so the pipeline holds
    // at most kLevel0Lag items (whatever the thread count) and item k + kLevel0Lag is made after
    // merge k.
    const std::size_t in_flight = std::min<std::size_t>(2 * std::size_t(threads), kLevel0Lag);
    const std::size_t items = interleave ? n + std::size_t(bw_) + 1 + kLevel0Lag : n;
    std::deque<std::unique_ptr<UpperBlock>> ready;  // copied at merges, waiting for their item
    if (interleave) leaf_vertices_.assign(n, {});
    leaf_tol_.assign(n, 0.0);
    read_turns_.reset();
    read_tol_ = tol_;
    ordered_pipeline(
        items, threads, in_flight,
        [&](std::size_t k) {
          auto item = std::make_unique<Item>();
          item->k = k;
          if (k < n) item->builder = make_worker(item->stats);
          if (interleave && k >= kLevel0Lag) {
            item->block = std::move(ready.front());
            ready.pop_front();
          }
          return item;
        },
        [this](Item& item) {
          if (item.builder) {
            item.in = read_leaf(item.k);
            item.builder->build_leaf(item.in);
            give_back(std::move(item.in.halo));  // the halo is done with: its buffers serve the
          }                                      // next leaves (the window's, after the merge)
          if (item.block) decimate_block(*item.block);
        },
        [&](Item& item, std::size_t k) {
          if (item.builder) {
            // The repair's tiles get the leaf's window, which is at hand, in merge order.
            if (spill_) {
              spill_->warm(repair_tiles_, item.in.bx, item.in.by, item.in.w, block_col0(item.in.bx),
                           block_row0(item.in.by));
            }
            give_back(std::move(item.in.w));
            std::vector<EdgeTask> glued;
            merge_leaf(*item.builder, interleave ? &glued : nullptr, k);
            if (interleave) repair(glued);
          }
          if (item.block) merge_block(*item.block);
          if (interleave) {
            // Leaf k - bw - 1's last neighbour is merged: its block goes out (none before).
            const std::size_t j = k - std::size_t(bw_) - 1;
            ready.push_back(k >= std::size_t(bw_) + 1 && j < n ? level0_block(j) : nullptr);
          }
          report(0.7 * double(std::min(k + 1, n)) / double(n));
        });
    tol_ = read_tol_;
    stats_.max_block_samples = std::max(stats_.max_block_samples, read_max_samples_);
    leaf_vertices_ = {};
    spare_windows_ = {};
    window_buffer() = Heightfield{};
    level0_done_ = interleave;
    stats_.level0_interleaved = interleave;
  }

  /// Leaf j's level-0 block, copied out (the interleaved leaf pass): the live triangles around
  /// its vertices whose centroid is in it and that no other block has, its unlocked vertices.
  std::unique_ptr<UpperBlock> level0_block(std::size_t j) {
    const int bx = int(j % std::size_t(bw_)), by = int(j / std::size_t(bw_));
    const int c0 = block_col0(bx), r0 = block_row0(by);
    const int c1 = block_col1(bx), r1 = block_row1(by);
    auto in_leaf = [&](double col, double row) {
      return std::min(int(col) / B_, bw_ - 1) == bx && std::min(int(row) / B_, bh_ - 1) == by;
    };
    std::vector<std::uint32_t> tris, cand;
    for (std::uint32_t v : leaf_vertices_[j]) {
      const MVert& m = verts_[v];
      if (m.tri == kNone || m.col < c0 || m.col > c1 || m.row < r0 || m.row > r1) continue;
      if (in_leaf(m.col, m.row) && !locked(m, 0)) cand.push_back(v);
      for_each_incident(v, [&](std::uint32_t t) {
        const MTri& tm = tris_[t];
        if (handed_out(t)) return;
        const MVert &a = verts_[tm.v[0]], &b = verts_[tm.v[1]], &c = verts_[tm.v[2]];
        if (in_leaf((a.col + b.col + c.col) / 3.0, (a.row + b.row + c.row) / 3.0))
          tris.push_back(t);
      });
    }
    std::vector<std::uint32_t>().swap(leaf_vertices_[j]);
    if (cand.empty()) return nullptr;
    std::sort(tris.begin(), tris.end());
    tris.erase(std::unique(tris.begin(), tris.end()), tris.end());
    std::sort(cand.begin(), cand.end());
    cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
    for (std::uint32_t t : tris) tris_[t].copied = true;
    auto block = setup_block(0, c0, r0, B_, std::move(tris), cand);
    // The running tolerance as of the leaf whose merge copies this block (not of however many
    // leaves the reader is ahead by): it covers this block's samples, and does not depend on
    // the thread count.
    block->builder->tol_ = leaf_tol_[std::min(j + std::size_t(bw_) + 1, leaf_tol_.size() - 1)];
    // Its window is leaf j's, most likely still among the repair's tiles: a copy, not a read.
    Heightfield w = spare_window();
    if (spill_ && spill_->read_cached(repair_tiles_, bx, by, dem_, w)) {
      block->samples = std::move(w);
    } else {
      give_back(std::move(w));
    }
    return block;
  }

  /// f(t) for every live triangle having vertex v (each once).
  template <class F>
  void for_each_incident(std::uint32_t v, F&& f) const {
    const std::uint32_t start = verts_[v].tri;
    auto at = [&](std::uint32_t t) {
      const int i = index_of(tris_[t], v);
      if (i < 0) throw_internal("block TIN: a vertex's fan is broken");
      return i;
    };
    std::uint32_t t = start;
    for (;;) {  // counter-clockwise, across (b, v), until back or open
      f(t);
      t = tris_[t].nbr[(at(t) + 2) % 3];
      if (t == start) return;
      if (t == kNone) break;
    }
    for (t = start;;) {  // then clockwise from the start, across (v, a)
      t = tris_[t].nbr[at(t)];
      if (t == kNone) return;
      f(t);
    }
  }

  /// An empty builder for one block's work on a worker thread, with this one's settings.
  std::unique_ptr<Builder> make_worker(BlockTinStats& stats) const {
    auto b = std::make_unique<Builder>(dem_, opt_, stats);
    b->stop_error_ = stop_error_;
    b->eps0_ = eps0_;
    b->tol_ = tol_;
    return b;
  }

  std::uint32_t global_vertex(int col, int row, float z) {
    const std::uint64_t key = std::uint64_t(row) * std::uint64_t(W_) + std::uint64_t(col);
    const bool on_block_border =
        (col % B_ == 0) || (row % B_ == 0) || col == W_ - 1 || row == H_ - 1;
    if (on_block_border) {
      std::uint32_t& id = shared_[key];  // stored + 1: 0 = new
      if (id != 0) return id - 1;
      id = static_cast<std::uint32_t>(verts_.size()) + 1;
    }
    MVert v;
    v.col = col;
    v.row = row;
    v.z = z;
    verts_.push_back(v);
    return static_cast<std::uint32_t>(verts_.size() - 1);
  }

  static std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
    return (std::uint64_t(a) << 32) | b;
  }

  /// The bound of the samples in the closed triangle (window coordinates) against its plane;
  /// up = kInfeasible when it covers a no-data sample. With `outward`, rounded up by the exact
  /// tolerance (a bound on new triangles). The scan stops after the first row that takes up or
  /// down past `limit`: the bound is then only a lower bound of the triangle's, above `limit`.
  TriBound exact_bound(const std::array<std::uint32_t, 3>& v, const Heightfield& w, int c0, int r0,
                       bool outward, double limit = kInfeasible) const {
    const MVert &a = verts_[v[0]], &b = verts_[v[1]], &c = verts_[v[2]];
    const Plane pl(a, b, c);
    TriBound tb;
    tb.zlo = std::min({a.z, b.z, c.z});
    tb.zhi = std::max({a.z, b.z, c.z});
    const std::int64_t x[3] = {a.col - c0, b.col - c0, c.col - c0};
    const std::int64_t y[3] = {a.row - r0, b.row - r0, c.row - r0};
    build::TriangleRows rows(x, y);
    const double pa = pl.a, pc = pl.c + pl.a * c0 + pl.b * r0;  // the plane in window coordinates
    double up = 0.0, down = 0.0;
    float lo = tb.zlo, hi = tb.zhi;
    for (std::int64_t row = rows.ymin(); row <= rows.ymax(); ++row) {
      std::int64_t xl, xr;
      rows.next(xl, xr);
      if (xl > xr) continue;
      const std::size_t base = static_cast<std::size_t>(row) * static_cast<std::size_t>(w.width);
      if (w.has_nodata()) {
        for (std::int64_t col = xl; col <= xr; ++col) {
          if (w.valid[base + static_cast<std::size_t>(col)] == 0) {
            tb.up = kInfeasible;
            return tb;
          }
        }
      }
      scanned_ += static_cast<std::uint64_t>(xr - xl + 1);
      const float* z = w.z.data() + base;
      scan_row(z, xl, xr, pa, pl.b * double(row) + pc, up, down, lo, hi);
      if (up > limit || down > limit) break;
    }
    tb.up = up;
    tb.down = down;
    tb.zlo = lo;
    tb.zhi = hi;
    if (outward) {
      tb.up = tb.up <= tol_ ? 0.0 : tb.up + tol_;
      tb.down = tb.down <= tol_ ? 0.0 : tb.down + tol_;
    }
    return tb;
  }

  /// The samples z[xl..xr] of one row against the plane pa * col + zrow: the largest
  /// z - plane into up, plane - z into down, the range into lo, hi. Four columns a step in SSE
  /// lanes (GCC vector extensions), so the max chains do not wait on each other. Each lane does
  /// the scalar loop's arithmetic (column numbers are exact doubles), and max and min are exact
  /// in any order, so the result is the scalar loop's to the bit.
  static void scan_row(const float* z, std::int64_t xl, std::int64_t xr, double pa, double zrow,
                       double& up, double& down, float& lo, float& hi) {
    using V2d = double __attribute__((vector_size(16)));
    using V4f = float __attribute__((vector_size(16)));
    V2d u01 = {up, up}, u23 = u01, d01 = {down, down}, d23 = d01;
    V4f l4 = {lo, lo, lo, lo}, h4 = {hi, hi, hi, hi};
    const V2d slope = {pa, pa}, base = {zrow, zrow}, step = {4.0, 4.0};
    V2d c01 = {double(xl), double(xl + 1)}, c23 = {double(xl + 2), double(xl + 3)};
    std::int64_t col = xl;
    for (; col + 3 <= xr; col += 4) {
      V4f zf;
      std::memcpy(&zf, z + col, sizeof zf);
      l4 = zf < l4 ? zf : l4;
      h4 = zf > h4 ? zf : h4;
      const V2d z01 = {double(zf[0]), double(zf[1])}, z23 = {double(zf[2]), double(zf[3])};
      const V2d e01 = z01 - (slope * c01 + base), e23 = z23 - (slope * c23 + base);
      u01 = e01 > u01 ? e01 : u01;
      u23 = e23 > u23 ? e23 : u23;
      d01 = -e01 > d01 ? -e01 : d01;
      d23 = -e23 > d23 ? -e23 : d23;
      c01 += step;
      c23 += step;
    }
    up = std::max({up, u01[0], u01[1], u23[0], u23[1]});
    down = std::max({down, d01[0], d01[1], d23[0], d23[1]});
    lo = std::min({lo, l4[0], l4[1], l4[2], l4[3]});
    hi = std::max({hi, h4[0], h4[1], h4[2], h4[3]});
    for (; col <= xr; ++col) {
      const double e = double(z[col]) - (pa * double(col) + zrow);
      up = std::max(up, e);
      down = std::max(down, -e);
      lo = std::min(lo, z[col]);
      hi = std::max(hi, z[col]);
    }
  }

  // ---- Delaunay across the leaf blocks' borders ----
  /// Each leaf's greedy TIN is Delaunay, but their union need not be across the border lines
  /// (each leaf saw only its own vertices). Lawson flips (edges between two data triangles, so the
  /// voids keep their shape) make M^m Delaunay; a flipped triangle whose exact bound exceeds the
  /// error gets its worst sample inserted, greedy-insertion style (Brown 7.1.1), and the
  /// triangles around it are legalised again. The samples on an edge that existed before are
  /// within the error (its interpolation is unchanged), so that sample lies inside the triangle
  /// or on a new edge between two data triangles. Vertex removal with Delaunay holes then keeps
  /// every mesh of the hierarchy Delaunay, so every fragment meets the Delaunay criterion and so
  /// does every extracted mesh (Brown Theorem 5.1.4).
  void make_borders_delaunay() {
    std::vector<EdgeTask> stack;
    for (std::uint32_t t = 0; t < tris_.size(); ++t) {
      const MTri& m = tris_[t];
      for (int k = 0; k < 3; ++k) {
        const MVert &a = verts_[m.v[k]], &b = verts_[m.v[(k + 1) % 3]];
        const bool on_line = (a.col == b.col && a.col % B_ == 0 && a.col > 0 && a.col < W_ - 1) ||
                             (a.row == b.row && a.row % B_ == 0 && a.row > 0 && a.row < H_ - 1);
        if (on_line && m.nbr[k] != kNone && m.nbr[k] > t)
          stack.push_back({t, m.v[k], m.v[(k + 1) % 3]});
      }
    }
    std::reverse(stack.begin(), stack.end());  // popped in triangle order
    repair(stack);
  }

  /// Legalises the edges of `stack` and bounds the flipped triangles, inserting samples where
  /// they exceed the error. Triangles whose bound is to be computed go in waves sorted by place
  /// (so the tile cache reads each tile about once): a triangle changed after its turn goes to
  /// the next wave, so the last computation of each is of its final shape.
  void repair(std::vector<EdgeTask>& stack) {
    std::vector<std::uint32_t> stale, wave;
    legalise(stack, stale);
    SampleSpill::Cache& tiles = repair_tiles_;
    while (!stale.empty()) {
      wave.swap(stale);
      stale.clear();
      std::vector<std::pair<std::uint64_t, std::uint32_t>> order;
      for (std::uint32_t t : wave) {
        const MTri& m = tris_[t];
        const int col = std::min({verts_[m.v[0]].col, verts_[m.v[1]].col, verts_[m.v[2]].col});
        const int row = std::min({verts_[m.v[0]].row, verts_[m.v[1]].row, verts_[m.v[2]].row});
        order.push_back(
            {(std::uint64_t(row / B_) * std::uint64_t(bw_) + std::uint64_t(col / B_)) << 32 | t,
             t});
      }
      std::sort(order.begin(), order.end());
      order.erase(std::unique(order.begin(), order.end()), order.end());
      for (const auto& [key, t] : order) {
        const auto [c0, r0, w] = window_of(tris_[t].v, tiles);
        TriBound& b = tris_[t].bound;
        b = exact_bound(tris_[t].v, w, c0, r0, false);
        if (b.err() <= stop_error_) {
          err_final_ = std::max(err_final_, b.err());
          continue;
        }
        const auto [col, row] = worst_sample(tris_[t].v, w, c0, r0);
        insert_sample(t, col, row, w.at(col - c0, row - r0), stack, stale);
        legalise(stack, stale);
      }
    }
  }

  /// A triangle the Delaunay repair of an interleaved leaf pass may no longer look at: given to
  /// a level-0 block, or made or replaced by one.
  bool handed_out(std::uint32_t t) const {
    const MTri& m = tris_[t];
    return m.copied || m.creator != kNone || m.destroyer != kNone;
  }

  /// An edge to legalise: (a, b) of triangle t, if t still has it (either way round).
  struct EdgeTask {
    std::uint32_t t, a, b;
  };

  /// Lawson's flips until every edge of the stack is locally Delaunay; flipped triangles go to
  /// `stale`.
  void legalise(std::vector<EdgeTask>& stack, std::vector<std::uint32_t>& stale) {
    while (!stack.empty()) {
      const EdgeTask e = stack.back();
      stack.pop_back();
      const std::uint32_t t1 = e.t;
      int k = -1;
      for (int i = 0; i < 3; ++i) {
        const std::uint32_t x = tris_[t1].v[i], y = tris_[t1].v[(i + 1) % 3];
        if ((x == e.a && y == e.b) || (x == e.b && y == e.a)) k = i;
      }
      if (k < 0) continue;  // flipped away since
      const std::uint32_t t2 = tris_[t1].nbr[k];
      if (t2 == kNone || tris_[t1].is_void || tris_[t2].is_void) continue;
      if (handed_out(t1) || handed_out(t2)) throw LeafConflict{};
      const std::uint32_t a = tris_[t1].v[k], b = tris_[t1].v[(k + 1) % 3],
                          c = tris_[t1].v[(k + 2) % 3];
      const int j = index_of(tris_[t2], b);
      const std::uint32_t d = tris_[t2].v[(j + 2) % 3];
      if (!in_circle(verts_[a], verts_[b], verts_[c], verts_[d])) continue;
      // (a, b, c) and (b, a, d) become (c, a, d) and (d, b, c): the quad a, d, b, c is convex.
      const std::uint32_t n_bc = tris_[t1].nbr[(k + 1) % 3], n_ca = tris_[t1].nbr[(k + 2) % 3];
      const std::uint32_t n_ad = tris_[t2].nbr[(j + 1) % 3], n_db = tris_[t2].nbr[(j + 2) % 3];
      set_triangle(t1, {c, a, d}, {n_ca, n_ad, t2});
      set_triangle(t2, {d, b, c}, {n_db, n_bc, t1});
      relink(n_ad, d, a, t1);
      relink(n_bc, c, b, t2);
      ++stats_.delaunay_flips;
      stale.push_back(t1);
      stale.push_back(t2);
      stack.push_back({t1, c, a});
      stack.push_back({t1, a, d});
      stack.push_back({t2, d, b});
      stack.push_back({t2, b, c});
    }
  }

  /// Inserts grid sample (col, row) of height z, which lies in triangle t (inside, or on an edge
  /// shared with another data triangle), splitting t (and that neighbour); the new triangles go to
  /// `stale` and their outer edges to `stack`.
  void insert_sample(std::uint32_t t, int col, int row, float z, std::vector<EdgeTask>& stack,
                     std::vector<std::uint32_t>& stale) {
    MVert pv;
    pv.col = col;
    pv.row = row;
    pv.z = z;
    const auto p = static_cast<std::uint32_t>(verts_.size());
    verts_.push_back(pv);
    if (!leaf_vertices_.empty()) {  // the interleaved leaf pass: a candidate of its leaf's block
      leaf_vertices_[std::size_t(std::min(row / B_, bh_ - 1)) * std::size_t(bw_) +
                     std::size_t(std::min(col / B_, bw_ - 1))]
          .push_back(p);
    }
    ++stats_.delaunay_insertions;
    int k = -1;
    for (int i = 0; i < 3; ++i) {
      if (orient(verts_[tris_[t].v[i]], verts_[tris_[t].v[(i + 1) % 3]], pv) == 0) k = i;
    }
    const std::uint32_t a = tris_[t].v[k < 0 ? 0 : k], b = tris_[t].v[k < 0 ? 1 : (k + 1) % 3],
                        c = tris_[t].v[k < 0 ? 2 : (k + 2) % 3];
    const std::uint32_t n_ab = tris_[t].nbr[k < 0 ? 0 : k],
                        n_bc = tris_[t].nbr[k < 0 ? 1 : (k + 1) % 3],
                        n_ca = tris_[t].nbr[k < 0 ? 2 : (k + 2) % 3];
    const auto n1 = static_cast<std::uint32_t>(tris_.size());
    tris_.push_back(MTri{});
    if (k < 0) {  // inside: (a, b, p), (b, c, p), (c, a, p)
      const std::uint32_t n2 = n1 + 1;
      tris_.push_back(MTri{});
      set_triangle(t, {a, b, p}, {n_ab, n1, n2});
      set_triangle(n1, {b, c, p}, {n_bc, n2, t});
      set_triangle(n2, {c, a, p}, {n_ca, t, n1});
      relink(n_bc, c, b, n1);
      relink(n_ca, a, c, n2);
      stale.insert(stale.end(), {t, n1, n2});
      stack.insert(stack.end(), {{t, a, b}, {n1, b, c}, {n2, c, a}});
      finest_triangles_ += 2;
      return;
    }
    // On edge (a, b), shared with u = (b, a, d): (a, p, c), (p, b, c), (b, p, d), (p, a, d).
    const std::uint32_t u = n_ab;
    if (u == kNone || tris_[u].is_void)
      throw_internal("block TIN: a sample over the error lies on an old edge");
    const int j = index_of(tris_[u], b);
    const std::uint32_t d = tris_[u].v[(j + 2) % 3];
    const std::uint32_t n_ad = tris_[u].nbr[(j + 1) % 3], n_db = tris_[u].nbr[(j + 2) % 3];
    const std::uint32_t n2 = n1 + 1;
    tris_.push_back(MTri{});
    set_triangle(t, {a, p, c}, {n2, n1, n_ca});
    set_triangle(n1, {p, b, c}, {u, n_bc, t});
    set_triangle(u, {b, p, d}, {n1, n2, n_db});
    set_triangle(n2, {p, a, d}, {t, n_ad, u});
    relink(n_bc, c, b, n1);
    relink(n_ad, d, a, n2);
    stale.insert(stale.end(), {t, n1, u, n2});
    stack.insert(stack.end(), {{t, c, a}, {n1, b, c}, {u, d, b}, {n2, a, d}});
    finest_triangles_ += 2;
  }

  /// Triangle t of M^m becomes (v, nbr), counter-clockwise; its vertices point at it.
  void set_triangle(std::uint32_t t, const std::array<std::uint32_t, 3>& v,
                    const std::array<std::uint32_t, 3>& nbr) {
    MTri& m = tris_[t];
    m.v = v;
    m.nbr = nbr;
    if (orient(verts_[v[0]], verts_[v[1]], verts_[v[2]]) <= 0)
      throw_internal("block TIN: a Delaunay repair made a degenerate triangle");
    for (int k = 0; k < 3; ++k) {
      verts_[v[k]].tri = t;
      // An edge waiting for a later leaf (the interleaved pass) may have moved to this slot.
      if (nbr[k] == kNone && !boundary_edge(verts_[v[k]], verts_[v[(k + 1) % 3]]))
        open_edges_[edge_key(v[k], v[(k + 1) % 3])] = (t << 2) | std::uint32_t(k);
    }
  }
  /// The neighbour o's edge (a, b), if o exists, now borders triangle t.
  void relink(std::uint32_t o, std::uint32_t a, std::uint32_t b, std::uint32_t t) {
    if (o == kNone) return;
    MTri& m = tris_[o];
    for (int j = 0; j < 3; ++j) {
      if (m.v[j] == a && m.v[(j + 1) % 3] == b) m.nbr[j] = t;
    }
  }

  struct SampleWindow {
    int c0, r0;
    Heightfield w;
  };
  /// The samples of a triangle's bounding box, from the scratch copy through a tile cache.
  SampleWindow window_of(const std::array<std::uint32_t, 3>& v, SampleSpill::Cache& tiles) const {
    const MVert &a = verts_[v[0]], &b = verts_[v[1]], &c = verts_[v[2]];
    const int c0 = std::min({a.col, b.col, c.col}), r0 = std::min({a.row, b.row, c.row});
    const int c1 = std::max({a.col, b.col, c.col}), r1 = std::max({a.row, b.row, c.row});
    return {c0, r0, spill_->read(c0, r0, c1 - c0 + 1, r1 - r0 + 1, dem_, &tiles)};
  }

  /// The sample of the closed triangle farthest from its plane (the first in row order).
  std::pair<int, int> worst_sample(const std::array<std::uint32_t, 3>& v, const Heightfield& w,
                                   int c0, int r0) const {
    const MVert &a = verts_[v[0]], &b = verts_[v[1]], &c = verts_[v[2]];
    const Plane pl(a, b, c);
    const std::int64_t x[3] = {a.col - c0, b.col - c0, c.col - c0};
    const std::int64_t y[3] = {a.row - r0, b.row - r0, c.row - r0};
    build::TriangleRows rows(x, y);
    double best = -1.0;
    std::pair<int, int> at{a.col, a.row};
    for (std::int64_t row = rows.ymin(); row <= rows.ymax(); ++row) {
      std::int64_t xl, xr;
      rows.next(xl, xr);
      for (std::int64_t col = xl; col <= xr; ++col) {
        const double e =
            std::abs(double(w.at(int(col), int(row))) - pl.at(double(col + c0), double(row + r0)));
        if (e > best) {
          best = e;
          at = {int(col + c0), int(row + r0)};
        }
      }
    }
    return at;
  }

  // ---- locks ----
  bool is_corner(const MVert& v) const {
    return (v.col == 0 || v.col == W_ - 1) && (v.row == 0 || v.row == H_ - 1);
  }
  /// Locked at `level`: on the border line of a level-`level` block (the domain's own boundary
  /// is not a block border: its vertices are removed along it).
  bool locked(const MVert& v, int level) const {
    if (v.sticky || is_corner(v)) return true;
    if (level >= levels_) return false;
    const int span = B_ << level;
    return (v.col % span == 0 && v.col > 0 && v.col < W_ - 1) ||
           (v.row % span == 0 && v.row > 0 && v.row < H_ - 1);
  }
  bool on_domain_boundary(const MVert& v) const {
    return v.col == 0 || v.row == 0 || v.col == W_ - 1 || v.row == H_ - 1;
  }

  // ---- one removal ----
  struct Plan {
    std::vector<std::uint32_t> star;  // triangles, counter-clockwise around the vertex
    std::vector<std::uint32_t> poly;  // the hole's boundary, counter-clockwise
    bool open = false;                // the vertex is on the domain boundary
    std::vector<std::array<std::uint32_t, 3>> tris;  // the hole's new triangles (vertex ids)
    std::vector<TriBound> bounds;                    // of each new triangle
    double err = kInfeasible;
    bool lower_bound = false;  // err is only a lower bound (plan's gate)
    bool delaunay = true;
  };

  template <class Tri>
  static int index_of(const Tri& t, std::uint32_t v) {
    for (int k = 0; k < 3; ++k) {
      if (t.v[k] == v) return k;
    }
    return -1;
  }

  /// The star and hole polygon of `v`; false if it cannot be removed (degree too high).
  bool gather(std::uint32_t v, Plan& p) const {
    p.star.clear();
    p.poly.clear();
    std::uint32_t t = verts_[v].tri, start = t;
    if (t == kNone) return false;  // its triangles are in another block's copy
    // Clockwise to the first triangle of an open fan (or all the way round).
    std::uint32_t steps = 0;
    for (;;) {
      const int i = index_of(tris_[t], v);
      const std::uint32_t prev = tris_[t].nbr[i];  // across (v, a): the triangle before
      if (prev == kNone) {
        // A fan is open only at the domain's boundary: elsewhere its star goes on in another
        // block's copy, and v is not this block's to remove.
        if (!boundary_edge(verts_[v], verts_[tris_[t].v[(i + 1) % 3]])) return false;
        start = t;
        p.open = true;
        break;
      }
      t = prev;
      if (t == start) {
        p.open = false;
        break;
      }
      if (++steps > opt_.max_degree + 1) return false;
    }
    t = start;
    for (;;) {
      const MTri& m = tris_[t];
      const int i = index_of(m, v);
      p.star.push_back(t);
      p.poly.push_back(m.v[(i + 1) % 3]);
      if (p.star.size() > opt_.max_degree) return false;
      const std::uint32_t next = m.nbr[(i + 2) % 3];  // across (b, v)
      if (next == kNone) {
        if (!boundary_edge(verts_[m.v[(i + 2) % 3]], verts_[v])) return false;
        p.poly.push_back(m.v[(i + 2) % 3]);
        break;
      }
      if (next == start) break;
      t = next;
    }
    return p.poly.size() <= opt_.max_degree && p.poly.size() >= 3;
  }

  /// Delaunay ears over the hole polygon; false if no triangulation was found.
  bool triangulate(Plan& p) const {
    p.tris.clear();
    p.delaunay = true;
    std::vector<std::uint32_t> poly = p.poly;
    while (poly.size() > 3) {
      const std::size_t n = poly.size();
      std::size_t ear = n, plain = n;
      for (std::size_t i = 0; i < n && ear == n; ++i) {
        const MVert &a = verts_[poly[(i + n - 1) % n]], &b = verts_[poly[i]],
                    &c = verts_[poly[(i + 1) % n]];
        if (orient(a, b, c) <= 0) continue;
        bool empty = true, circle = true;
        for (std::size_t j = 0; j < n && empty; ++j) {
          if (j == i || j == (i + 1) % n || j == (i + n - 1) % n) continue;
          const MVert& d = verts_[poly[j]];
          if (orient(a, b, d) >= 0 && orient(b, c, d) >= 0 && orient(c, a, d) >= 0) empty = false;
          if (circle && in_circle(a, b, c, d)) circle = false;
        }
        if (!empty) continue;
        if (circle) ear = i;
        if (plain == n) plain = i;
      }
      if (ear == n) {
        if (plain == n) return false;
        ear = plain;
        p.delaunay = false;
      }
      p.tris.push_back({poly[(ear + n - 1) % n], poly[ear], poly[(ear + 1) % n]});
      poly.erase(poly.begin() + static_cast<std::ptrdiff_t>(ear));
    }
    if (orient(verts_[poly[0]], verts_[poly[1]], verts_[poly[2]]) <= 0) return false;
    p.tris.push_back({poly[0], poly[1], poly[2]});
    return true;
  }

  /// Conservative bound of new triangle `nt` over the old star: for every old triangle o it
  /// overlaps, source - new = (source - o) + (o - new), so up <= o.up + the largest o - new over
  /// the overlap (at its corners: both planes are linear there), and likewise down; and never
  /// more than the source's range allows: the plane lies between its corners' heights and the
  /// source between the overlapped triangles' zlo and zhi.
  TriBound overlay_bound(const std::array<std::uint32_t, 3>& nt, const Plan& p) const {
    const MVert &a = verts_[nt[0]], &b = verts_[nt[1]], &c = verts_[nt[2]];
    const Plane pn(a, b, c);
    TriBound tb;
    const float vlo = std::min({a.z, b.z, c.z}), vhi = std::max({a.z, b.z, c.z});
    tb.zlo = vlo;
    tb.zhi = vhi;
    std::vector<std::array<double, 2>>& poly = clip_a_;
    std::vector<std::array<double, 2>>& next = clip_b_;
    for (std::uint32_t ot : p.star) {
      const MTri& o = tris_[ot];
      poly = {{double(a.col), double(a.row)},
              {double(b.col), double(b.row)},
              {double(c.col), double(c.row)}};
      for (int k = 0; k < 3 && !poly.empty(); ++k) {  // clip by o's edge k (keep its left side)
        const MVert &e0 = verts_[o.v[k]], &e1 = verts_[o.v[(k + 1) % 3]];
        const double ex = e1.col - e0.col, ey = e1.row - e0.row;
        auto side = [&](const std::array<double, 2>& q) {
          return ex * (q[1] - e0.row) - ey * (q[0] - e0.col);
        };
        next.clear();
        for (std::size_t i = 0; i < poly.size(); ++i) {
          const auto& q0 = poly[i];
          const auto& q1 = poly[(i + 1) % poly.size()];
          const double s0 = side(q0), s1 = side(q1);
          if (s0 >= 0) next.push_back(q0);
          if ((s0 > 0 && s1 < 0) || (s0 < 0 && s1 > 0)) {
            const double t = s0 / (s0 - s1);
            next.push_back({q0[0] + t * (q1[0] - q0[0]), q0[1] + t * (q1[1] - q0[1])});
          }
        }
        poly.swap(next);
      }
      if (poly.size() < 3) continue;
      const Plane po(verts_[o.v[0]], verts_[o.v[1]], verts_[o.v[2]]);
      double above = 0.0, below = 0.0;  // largest o - new and new - o over the overlap
      for (const auto& q : poly) {
        const double d = po.at(q[0], q[1]) - pn.at(q[0], q[1]);
        above = std::max(above, d);
        below = std::max(below, -d);
      }
      tb.up = std::max(tb.up, o.bound.up + above);
      tb.down = std::max(tb.down, o.bound.down + below);
      tb.zlo = std::min(tb.zlo, o.bound.zlo);
      tb.zhi = std::max(tb.zhi, o.bound.zhi);
    }
    tb.up = std::min(tb.up, double(tb.zhi) - double(vlo)) + tol_;
    tb.down = std::min(tb.down, double(vhi) - double(tb.zlo)) + tol_;
    return tb;
  }

  /// Plans the removal of `v`: its hole's triangulation and error (kInfeasible if impossible).
  /// With a window w and `estimate`, no sample is scanned: the error is the removed vertex's
  /// own deviation from the new triangles, a lower bound of the exact one (p.lower_bound).
  /// Exact errors are scanned only until they pass `limit` (a removal that would not be made):
  /// p.err is then a lower bound above it (p.lower_bound) and p.bounds incomplete.
  void plan(std::uint32_t v, Plan& p, const Heightfield* w, int c0, int r0, bool estimate,
            double limit = kInfeasible) const {
    p.err = kInfeasible;
    p.lower_bound = false;
    ++plans_;
    if (!gather(v, p)) return;
    for (std::uint32_t t : p.star) {
      if (tris_[t].is_void) return;
    }
    if (w != nullptr) {  // the hole must lie in the block's window (a Delaunay edge may cross)
      for (std::uint32_t u : p.poly) {
        const MVert& m = verts_[u];
        if (m.col < c0 || m.row < r0 || m.col >= c0 + w->width || m.row >= r0 + w->height) return;
      }
    }
    if (p.open && !on_domain_boundary(verts_[v])) return;
    if (!triangulate(p)) return;
    p.bounds.clear();
    double err = 0.0;
    if (w != nullptr && estimate) {
      const MVert& m = verts_[v];
      double lb = 0.0;
      for (const auto& nt : p.tris) {
        const MVert &a = verts_[nt[0]], &b = verts_[nt[1]], &c = verts_[nt[2]];
        if (orient(a, b, m) < 0 || orient(b, c, m) < 0 || orient(c, a, m) < 0) continue;
        lb = std::max(lb, std::abs(double(m.z) - Plane(a, b, c).at(m.col, m.row)));
      }
      p.err = lb;
      p.lower_bound = true;
      return;
    }
    for (const auto& nt : p.tris) {
      p.bounds.push_back(w != nullptr ? exact_bound(nt, *w, c0, r0, true, limit)
                                      : overlay_bound(nt, p));
      err = std::max(err, p.bounds.back().err());
      if (err > limit) {
        p.err = err;
        p.lower_bound = true;
        return;
      }
    }
    p.err = err;
  }

  void apply(std::uint32_t v, const Plan& p) {
    const auto rid = static_cast<std::uint32_t>(removals_.size());
    Removal r;
    r.vertex = v;
    r.star_begin = static_cast<std::uint32_t>(star_ids_.size());
    for (std::uint32_t t : p.star) star_ids_.push_back(t);
    r.star_end = static_cast<std::uint32_t>(star_ids_.size());
    r.new_begin = static_cast<std::uint32_t>(tris_.size());
    r.err = p.err;
    // The outer neighbour of each hole edge (poly[j], poly[j+1]): across star triangle j's edge
    // opposite v; the closing edge of an open fan has none.
    std::vector<std::pair<std::uint64_t, std::uint32_t>>& outer = scratch_outer_;
    outer.clear();
    for (std::uint32_t t : p.star) {
      const MTri& m = tris_[t];
      const int i = index_of(m, v);
      const std::uint32_t a = m.v[(i + 1) % 3], b = m.v[(i + 2) % 3];
      outer.push_back({edge_key(a, b), m.nbr[(i + 1) % 3]});
      if (m.nbr[(i + 1) % 3] == kNone) {
        open_edges_.erase(edge_key(a, b));  // a block border edge waiting for its neighbour
      }
    }
    for (std::uint32_t t : p.star) tris_[t].destroyer = rid;
    for (std::size_t j = 0; j < p.tris.size(); ++j) {
      MTri m;
      m.v = p.tris[j];
      m.bound = p.bounds[j];
      m.creator = rid;
      tris_.push_back(m);
    }
    r.new_end = static_cast<std::uint32_t>(tris_.size());
    for (std::uint32_t t = r.new_begin; t < r.new_end; ++t) {
      for (int k = 0; k < 3; ++k) {
        const std::uint32_t a = tris_[t].v[k], b = tris_[t].v[(k + 1) % 3];
        verts_[a].tri = t;
        const std::uint64_t key = edge_key(a, b);
        auto it =
            std::find_if(outer.begin(), outer.end(), [&](const auto& e) { return e.first == key; });
        if (it != outer.end()) {  // a hole edge: glue to the outside
          const std::uint32_t o = it->second;
          tris_[t].nbr[k] = o;
          if (o != kNone) {
            relink(o, b, a, t);
          } else if (!boundary_edge(verts_[a], verts_[b])) {
            open_edges_[edge_key(a, b)] = (t << 2) | std::uint32_t(k);
          }
          continue;
        }
        for (std::uint32_t u = r.new_begin; u < r.new_end; ++u) {  // an inner edge
          if (u == t) continue;
          const int j = index_of(tris_[u], b);
          if (j >= 0 && tris_[u].v[(j + 1) % 3] == a) tris_[t].nbr[k] = u;
        }
      }
    }
    verts_[v].tri = kNone;
    removals_.push_back(r);
    if (!p.delaunay) ++stats_.non_delaunay_holes;
  }

  /// Both ends on the same side of the domain: an edge of the domain's boundary.
  bool boundary_edge(const MVert& a, const MVert& b) const {
    return (a.col == 0 && b.col == 0) || (a.row == 0 && b.row == 0) ||
           (a.col == W_ - 1 && b.col == W_ - 1) || (a.row == H_ - 1 && b.row == H_ - 1);
  }

  // ---- decimation of one level: stages of growing tolerance, independent-set rounds ----
  /// Block by block with exact bounds from each block's window: always at level 0 (the leaf
  /// blocks), above it while a window fits options.exact_window_samples, else over the whole mesh
  /// with overlay bounds.
  void decimate_blocks(int level) {
    const int span = B_ << level;
    const int nx = (W_ - 2) / span + 1, ny = (H_ - 2) / span + 1;
    const std::uint64_t window =
        std::uint64_t(std::min(span, W_ - 1) + 1) * std::uint64_t(std::min(span, H_ - 1) + 1);
    if (level > 0 && window > exact_window_samples_) {
      decimate_level(level, nullptr, 0, 0, nullptr);
      return;
    }
    if (level > 0) ++stats_.exact_levels;
    // Blocks are independent: each is copied out for a worker, decimated there with exact bounds
    // from its window, and merged back in block order, so the records are the ones a single pass
    // over the blocks makes. A triangle goes to the block of its centroid; a vertex is removed
    // only where its whole star and hole lie in its block's copy and window (a Delaunay edge may
    // cross a border line), and the border lines' vertices are locked, so no triangle is changed
    // by two blocks.
    const std::size_t blocks = std::size_t(nx) * std::size_t(ny);
    auto block_of = [&](double col, double row) {
      const int bx = std::min(int(col) / span, nx - 1), by = std::min(int(row) / span, ny - 1);
      return std::size_t(by) * std::size_t(nx) + std::size_t(bx);
    };
    std::vector<std::vector<std::uint32_t>> cand(blocks), tris(blocks);
    for (std::uint32_t v = 0; v < verts_.size(); ++v) {
      const MVert& m = verts_[v];
      if (m.tri == kNone || locked(m, level)) continue;
      cand[block_of(m.col, m.row)].push_back(v);
    }
    for (std::uint32_t t = 0; t < tris_.size(); ++t) {
      const MTri& m = tris_[t];
      if (m.destroyer != kNone) continue;
      const MVert &a = verts_[m.v[0]], &b = verts_[m.v[1]], &c = verts_[m.v[2]];
      tris[block_of((a.col + b.col + c.col) / 3.0, (a.row + b.row + c.row) / 3.0)].push_back(t);
    }
    std::vector<std::size_t> with_candidates;
    for (std::size_t k = 0; k < blocks; ++k) {
      if (!cand[k].empty()) with_candidates.push_back(k);
    }
    if (!spill_) throw_internal("block TIN: an exact level without the samples' scratch copy");
    const unsigned threads = thread_count(opt_.threads);
    // Several blocks per worker in flight: the copies are small (the live mesh shrinks level by
    // level; windows are the workers' own), and the workers go on while this thread copies and
    // merges, and past a slow block (one in flight per worker left them idle for a tenth of the
    // upper levels on the 8193² terrain).
    ordered_pipeline(
        with_candidates.size(), threads, 4 * std::size_t(threads),
        [&](std::size_t i) {
          const std::size_t k = with_candidates[i];
          const int c0 = int(k % std::size_t(nx)) * span, r0 = int(k / std::size_t(nx)) * span;
          auto block = setup_block(level, c0, r0, span, std::move(tris[k]), cand[k]);
          std::vector<std::uint32_t>().swap(cand[k]);
          return block;
        },
        [&](UpperBlock& block) { decimate_block(block); },
        [&](UpperBlock& block, std::size_t) { merge_block(block); });
    window_buffer() = Heightfield{};
  }

  /// The block of `level` whose window starts at grid (c0, r0), copied out: `tris` and the
  /// candidates `cand` (whole-mesh ids).
  std::unique_ptr<UpperBlock> setup_block(int level, int c0, int r0, int span,
                                          std::vector<std::uint32_t>&& tris,
                                          const std::vector<std::uint32_t>& cand) {
    auto block = copy_block(level, std::move(tris), cand);
    block->c0 = c0;
    block->r0 = r0;
    block->w = std::min(c0 + span, W_ - 1) - c0 + 1;
    block->h = std::min(r0 + span, H_ - 1) - r0 + 1;
    stats_.max_block_samples =
        std::max<std::uint64_t>(stats_.max_block_samples, std::uint64_t(block->w) * block->h);
    if (level > 0) stats_.samples_rescanned += std::uint64_t(block->w) * std::uint64_t(block->h);
    return block;
  }

  /// A copied block's decimation (a worker thread), exact bounds from its window.
  void decimate_block(UpperBlock& block) {
    if (block.samples.width != 0) {
      block.builder->decimate_level(block.level, &block.samples, block.c0, block.r0, &block.cand);
      give_back(std::move(block.samples));
      return;
    }
    Heightfield& w = window_buffer();
    spill_->read_into(w, block.c0, block.r0, block.w, block.h, dem_);
    block.builder->decimate_level(block.level, &w, block.c0, block.r0, &block.cand);
  }

  /// This thread's last block window, whose buffers the next one reuses. A worker's goes with its
  /// thread; the calling thread's (it works inline with one thread) is freed after each pass.
  static Heightfield& window_buffer() {
    thread_local Heightfield w;
    return w;
  }

  /// A block of an exact upper level copied out of the whole mesh for a worker: its live
  /// triangles and their vertices, numbered in increasing whole-mesh id (so candidates and ties
  /// order as in the whole mesh), and what merge_block needs to put the result back.
  struct UpperBlock {
    int level = 0, c0 = 0, r0 = 0, w = 0, h = 0;
    BlockTinStats stats;
    std::unique_ptr<Builder> builder;
    std::vector<std::uint32_t> gverts, gtris;  // local id -> whole-mesh id, both increasing
    std::vector<std::uint32_t> first_tri;      // each local vertex's `tri` as copied
    std::vector<std::uint32_t> cand;           // local ids of the removal candidates
    IdMap<std::uint32_t> border_owner;  // edge on the block's border -> its whole-mesh triangle
    Heightfield samples;  // the block's window when it was at hand as the block was copied
  };

  std::unique_ptr<UpperBlock> copy_block(int level, std::vector<std::uint32_t>&& tris,
                                         const std::vector<std::uint32_t>& cand) {
    auto block = std::make_unique<UpperBlock>();
    UpperBlock& u = *block;
    u.level = level;
    u.builder = make_worker(u.stats);
    Builder& b = *u.builder;
    u.gtris = std::move(tris);
    for (std::uint32_t t : u.gtris)
      u.gverts.insert(u.gverts.end(), tris_[t].v.begin(), tris_[t].v.end());
    std::sort(u.gverts.begin(), u.gverts.end());
    u.gverts.erase(std::unique(u.gverts.begin(), u.gverts.end()), u.gverts.end());
    auto local_of = [](const std::vector<std::uint32_t>& ids, std::uint32_t g) {
      const auto it = std::lower_bound(ids.begin(), ids.end(), g);
      return it != ids.end() && *it == g ? std::uint32_t(it - ids.begin()) : kNone;
    };
    b.verts_.reserve(u.gverts.size());
    u.first_tri.reserve(u.gverts.size());
    for (std::uint32_t g : u.gverts) {
      MVert v = verts_[g];
      v.tri = v.tri == kNone ? kNone : local_of(u.gtris, v.tri);
      u.first_tri.push_back(v.tri);
      b.verts_.push_back(v);
    }
    for (std::uint32_t t : u.gtris) {
      const MTri& g = tris_[t];
      MTri m;
      for (int k = 0; k < 3; ++k) {
        m.v[k] = local_of(u.gverts, g.v[k]);
        m.nbr[k] = g.nbr[k] == kNone ? kNone : local_of(u.gtris, g.nbr[k]);
        if (g.nbr[k] != kNone && m.nbr[k] == kNone) {
          u.border_owner[edge_key(g.v[k], g.v[(k + 1) % 3])] = t;
        }
      }
      m.bound = g.bound;
      m.is_void = g.is_void;
      b.tris_.push_back(m);
    }
    u.cand.reserve(cand.size());
    for (std::uint32_t g : cand) {
      const std::uint32_t l = local_of(u.gverts, g);
      if (l != kNone) u.cand.push_back(l);  // none of its triangles is in this copy
    }
    return block;
  }

  /// Puts a decimated block back: its removals, stars and new triangles after the whole mesh's
  /// (the ids a single pass gives), the copied triangles' deaths and new neighbours, the new
  /// triangles on the block's border glued to the current triangles outside, and the vertices'
  /// `tri` where the block changed it.
  void merge_block(UpperBlock& u) {
    Builder& b = *u.builder;
    const auto ncopy = static_cast<std::uint32_t>(u.gtris.size());
    const auto tri_base = static_cast<std::uint32_t>(tris_.size());
    const auto rem_base = static_cast<std::uint32_t>(removals_.size());
    const auto star_base = static_cast<std::uint32_t>(star_ids_.size());
    auto tri = [&](std::uint32_t t) {
      return t == kNone ? kNone : t < ncopy ? u.gtris[t] : tri_base + (t - ncopy);
    };
    auto rem = [&](std::uint32_t r) { return r == kNone ? kNone : r + rem_base; };
    for (std::uint32_t t = 0; t < ncopy; ++t) {
      const MTri& l = b.tris_[t];
      MTri& g = tris_[u.gtris[t]];
      if (l.destroyer != kNone) {
        g.destroyer = rem(l.destroyer);
        continue;
      }
      for (int k = 0; k < 3; ++k) {
        if (l.nbr[k] != kNone) g.nbr[k] = tri(l.nbr[k]);
      }
    }
    for (std::uint32_t t = ncopy; t < b.tris_.size(); ++t) {
      MTri m = b.tris_[t];
      for (int k = 0; k < 3; ++k) {
        m.v[k] = u.gverts[m.v[k]];
        m.nbr[k] = tri(m.nbr[k]);
      }
      m.creator = rem(m.creator);
      m.destroyer = rem(m.destroyer);
      tris_.push_back(m);
    }
    for (Removal r : b.removals_) {
      r.vertex = u.gverts[r.vertex];
      r.star_begin += star_base;
      r.star_end += star_base;
      r.new_begin = tri(r.new_begin);
      r.new_end = tri_base + (r.new_end - ncopy);
      removals_.push_back(r);
    }
    for (std::size_t i = 0; i < b.star_ids_.size(); ++i) star_ids_.push_back(tri(b.star_ids_[i]));
    b.open_edges_.for_each([&](std::uint64_t key, std::uint32_t value) {
      const std::uint32_t a = u.gverts[key >> 32], c = u.gverts[key & 0xffffffffu];
      const std::uint32_t t = tri(value >> 2), e = value & 3;
      const std::uint32_t* owner = u.border_owner.find(edge_key(a, c));
      if (owner == nullptr) throw_internal("block TIN: a block's new border edge had no owner");
      const MTri& s = tris_[*owner];
      const std::uint32_t o = s.nbr[index_of(s, a)];
      tris_[t].nbr[e] = o;
      relink(o, c, a, t);
    });
    for (std::size_t v = 0; v < b.verts_.size(); ++v) {
      if (b.verts_[v].tri != u.first_tri[v]) verts_[u.gverts[v]].tri = tri(b.verts_[v].tri);
    }
    scanned_ += b.scanned_;
    plans_ += b.plans_;
    stats_.rounds += u.stats.rounds;
    stats_.non_delaunay_holes += u.stats.non_delaunay_holes;
    feed();
  }

  // With a window w (level 0, or an exact upper level) errors are exact from the block's window w,
  // whose sample (0, 0) is grid (c0, r0), and the candidates are `only`, the block's vertices.
  void decimate_level(int level, const Heightfield* w, int c0, int r0,
                      const std::vector<std::uint32_t>* only) {
    std::vector<std::uint32_t> cand;
    if (only != nullptr) {
      for (std::uint32_t v : *only) {
        if (verts_[v].tri != kNone && !locked(verts_[v], level)) cand.push_back(v);
      }
    } else {
      for (std::uint32_t v = 0; v < verts_.size(); ++v) {
        if (verts_[v].tri != kNone && !locked(verts_[v], level)) cand.push_back(v);
      }
    }
    std::sort(cand.begin(), cand.end());
    cost_.resize(verts_.size());
    dirty_.resize(verts_.size());
    stamp_.resize(verts_.size(), 0);
    for (std::uint32_t v : cand) dirty_[v] = 1;
    const bool root = level >= levels_;
    const double top = eps0_ * std::ldexp(1.0, 2 * (level + 1));
    double eps = level == 0 ? eps0_ : eps0_ * std::ldexp(1.0, 2 * level);
    Plan p;
    std::vector<std::pair<double, std::uint32_t>> order;
    std::vector<std::pair<std::uint32_t, Plan>> chosen;
    std::vector<std::uint32_t> active, next;
    ++cand_stamp_;
    cand_mark_.resize(verts_.size(), 0);
    seen_.resize(verts_.size(), 0);
    for (std::uint32_t v : cand) cand_mark_[v] = cand_stamp_;
    for (;;) {
      eps = root ? eps * std::sqrt(2.0) : std::min(top, eps * std::sqrt(2.0));
      std::uint64_t removed_in_stage = 0;
      // A round looks only at vertices that may be removed: those within eps or whose star
      // changed in the last round; the others cannot change until a neighbour goes.
      active.clear();
      for (std::uint32_t v : cand) {
        if (verts_[v].tri != kNone) active.push_back(v);
      }
      for (;;) {  // rounds
        order.clear();
        for (std::uint32_t v : active) {
          if (verts_[v].tri == kNone) continue;
          // dirty_: 1 = the star changed; 2 = cost_ is only a lower bound (an estimate: with
          // exact bounds a removal's samples are scanned only when it is about to be chosen).
          if (dirty_[v] == 1) {
            plan(v, p, w, c0, r0, true);
            cost_[v] = p.err;
            dirty_[v] = p.lower_bound ? 2 : 0;
          }
          if (cost_[v] <= eps) order.push_back({cost_[v], v});
        }
        if (order.empty()) break;
        std::sort(order.begin(), order.end());
        ++round_stamp_;
        // An independent set, cheapest first: no two removed vertices are adjacent, so each
        // star is untouched by the others' removals and its plan stays valid.
        std::size_t n = 0;
        for (const auto& [c, v] : order) {
          if (stamp_[v] == round_stamp_) continue;
          if (n == chosen.size()) chosen.emplace_back();
          Plan& q = chosen[n].second;
          plan(v, q, w, c0, r0, false, eps);
          cost_[v] = q.err;
          dirty_[v] = q.lower_bound ? 2 : 0;
          if (q.err > eps) continue;
          chosen[n++].first = v;
          stamp_[v] = round_stamp_;
          for (std::uint32_t u : q.poly) stamp_[u] = round_stamp_;
        }
        ++seen_stamp_;
        next.clear();
        for (std::size_t i = 0; i < n; ++i) {
          const Plan& q = chosen[i].second;
          apply(chosen[i].first, q);
          for (std::uint32_t u : q.poly) {
            dirty_[u] = 1;
            if (cand_mark_[u] == cand_stamp_ && seen_[u] != seen_stamp_) {
              seen_[u] = seen_stamp_;
              next.push_back(u);
            }
          }
        }
        for (const auto& [c, v] : order) {
          if (verts_[v].tri != kNone && cost_[v] <= eps && seen_[v] != seen_stamp_) {
            seen_[v] = seen_stamp_;
            next.push_back(v);
          }
        }
        std::sort(next.begin(), next.end());
        active.swap(next);
        if (n == 0) continue;
        removed_in_stage += n;
        ++stats_.rounds;
      }
      cand.erase(std::remove_if(cand.begin(), cand.end(),
                                [&](std::uint32_t v) { return verts_[v].tri == kNone; }),
                 cand.end());
      double cheapest_left = kInfeasible;
      if (root && removed_in_stage == 0) {
        for (std::uint32_t v : cand) {
          if (dirty_[v] == 1) {
            plan(v, p, w, c0, r0, true);
            cost_[v] = p.err;
            dirty_[v] = p.lower_bound ? 2 : 0;
          }
          cheapest_left = std::min(cheapest_left, cost_[v]);
        }
      }
      if (!root && eps >= top) break;
      if (root && removed_in_stage == 0) {
        if (cheapest_left == kInfeasible) break;
        eps = std::max(eps, cheapest_left / std::sqrt(2.0));
      }
    }
  }

  // ---- the CRMR: the removals, in the order they were made, go to the out-of-core assembler
  // as they are merged (feed()), which orders them by falling error, links them and hands each
  // op to the sink (assemble()).
  using StarTriangle = OpAssembler::StarTriangle;
  StarTriangle star_triangle(std::uint32_t t) const {
    const MTri& x = tris_[t];
    return StarTriangle{x.v, t, x.creator, x.is_void};
  }

  void make_assembler() {
    AssemblyOptions ao;
    ao.tmp_dir = opt_.tmp_dir;
    ao.sort_bytes = opt_.assembly_sort_bytes;
    ao.threads = opt_.threads;
    ao.progress = [this](double f) { report(0.9 + 0.1 * f); };
    assembler_ = std::make_unique<OpAssembler>(ao);
  }

  /// Hands the removals merged since the last call to the assembler (their triangles are final).
  void feed() {
    if (!assembler_) return;
    Clock::time_point t0 = Clock::now();
    for (; fed_ < removals_.size(); ++fed_) {
      const Removal& r = removals_[fed_];
      feed_star_.clear();
      for (std::uint32_t i = r.star_begin; i < r.star_end; ++i) {
        feed_star_.push_back(star_triangle(star_ids_[i]));
      }
      feed_made_.clear();
      for (std::uint32_t t = r.new_begin; t < r.new_end; ++t) {
        feed_made_.push_back({tris_[t].v, t, tris_[t].is_void});
      }
      assembler_->add_removal(std::span(&r.vertex, 1), feed_star_, feed_made_, r.err);
    }
    t_fed_ += since(t0);
  }

  // ----
  // (op_assembly.h), which orders them by falling error, links them and hands each op to the sink.
  void assemble(OpSink& sink) {
    const std::size_t m = removals_.size();
    CrmrInfo info;
    info.kind = ModelKind::kTerrain;
    info.georef = dem_.georef();
    info.grid_width = W_;
    info.grid_height = H_;
    info.source = dem_.source();
    info.builder = "block-decimation max_error=" + std::to_string(opt_.max_error) +
                   " block_cells=" + std::to_string(B_) +
                   " max_degree=" + std::to_string(opt_.max_degree);
    info.vertex_count = verts_.size();
    for (const MVert& v : verts_) info.bounds.add(world(v));

    feed();
    OpAssembler& assembler = *assembler_;
    std::vector<StarTriangle> base;
    double err0 = 0.0;
    for (std::uint32_t t = 0; t < tris_.size(); ++t) {
      if (tris_[t].destroyer == kNone) {
        base.push_back(star_triangle(t));
        err0 = std::max(err0, tris_[t].bound.err());
      }
    }
    info.err0 = err0;
    info.err_final = err_final_;
    stats_.finest_vertices = finest_vertices_;
    stats_.samples_scanned = scanned_;
    stats_.temp_bytes = spill_ ? spill_->bytes() : 0;
    stats_.plans = plans_;
    stats_.finest_triangles = finest_triangles_;
    stats_.base_triangles = base.size();
    stats_.removals = m;
    stats_.levels = levels_;
    {
      std::vector<std::uint8_t> seen(verts_.size(), 0);
      for (const StarTriangle& t : base) {
        for (std::uint32_t v : t.v) seen[v] = 1;
      }
      stats_.base_vertices = static_cast<std::uint64_t>(std::count(seen.begin(), seen.end(), 1));
    }
    // The build records are done with (the assembler has its own): the sink and the assembly
    // may use their memory. The vertices stay for their positions.
    tris_.release();
    star_ids_.release();
    std::vector<Removal>().swap(removals_);
    std::vector<double>().swap(cost_);
    std::vector<std::uint8_t>().swap(dirty_);
    for (auto* v : {&stamp_, &cand_mark_, &seen_}) std::vector<std::uint32_t>().swap(*v);
    open_edges_ = IdMap<std::uint32_t>();
    assembler.finish(
        info, base, [this](std::uint32_t v) { return world(verts_[v]); }, sink);
    stats_.seconds_feed = t_fed_;
    stats_.seconds_join = assembler.stats().seconds_join;
    stats_.seconds_emit = assembler.stats().seconds_emit;
    stats_.dag_height = assembler.stats().dag_height;
    stats_.temp_bytes += assembler.stats().scratch_bytes;
    assembler_.reset();
    std::vector<MVert>().swap(verts_);
    report(1.0);
  }

  Vec3 world(const MVert& v) const {
    const Georef& g = dem_.georef();
    return {g.x0 + v.col * g.dx, g.y0 + v.row * g.dy, double(v.z)};
  }

  void report(double f) const {
    if (opt_.progress) opt_.progress(std::clamp(f, 0.0, 1.0));
  }

  const RasterWindows& dem_;
  const BlockTinOptions& opt_;
  BlockTinStats& stats_;
  const int W_, H_;
  int B_ = 256, bw_ = 1, bh_ = 1, levels_ = 0;
  std::uint64_t exact_window_samples_ = 0;
  std::uint64_t valid_samples_ = 0;
  std::unique_ptr<SampleSpill> spill_;
  SampleSpill::Cache repair_tiles_{1};  // the Delaunay repair's tiles (it works along borders)
  std::vector<std::vector<std::uint32_t>> leaf_vertices_;  // interleaved pass: per leaf block
  bool level0_done_ = false;                               // by the interleaved leaf pass
  std::vector<double> leaf_tol_;  // the running tolerance after each leaf's read
  Turnstile read_turns_;          // the leaf pass's reads: one at a time, in block order
  double read_tol_ = 0.0;         // the running tolerance of the reads (tol_ once they are done)
  std::uint64_t read_max_samples_ = 0;  // the reads' largest window (with its halo)
  double tol_ = 0.0, range_ = 0.0, stop_error_ = 0.0, eps0_ = 0.0, err_final_ = 0.0;
  std::uint64_t finest_vertices_ = 0, finest_triangles_ = 0;
  std::vector<MVert> verts_;
  Chunked<MTri> tris_;
  std::vector<Removal> removals_;
  Chunked<std::uint32_t> star_ids_;
  IdMap<std::uint32_t> shared_;      // grid index -> border vertex + 1
  IdMap<std::uint32_t> open_edges_;  // edge -> (tri << 2 | edge)
  std::vector<std::pair<std::uint64_t, std::uint32_t>> scratch_outer_;
  std::mutex spare_mu_;                     // guards spare_windows_
  std::vector<Heightfield> spare_windows_;  // windows whose buffers are free (spare_window)
  mutable std::uint64_t scanned_ = 0, plans_ = 0;
  mutable std::vector<std::array<double, 2>> clip_a_, clip_b_;  // overlay_bound's scratch
  std::vector<double> cost_;
  std::vector<std::uint8_t> dirty_;
  std::vector<std::uint32_t> stamp_;
  std::uint32_t round_stamp_ = 0;
  std::vector<std::uint32_t> cand_mark_, seen_;  // candidates of this level; in the next round
  std::unique_ptr<OpAssembler> assembler_;       // the calling builder's (workers have none)
  std::size_t fed_ = 0;                          // removals handed to it
  std::vector<StarTriangle> feed_star_;
  std::vector<OpAssembler::MadeTriangle> feed_made_;
  double t_fed_ = 0.0;
  std::uint32_t cand_stamp_ = 0, seen_stamp_ = 0;
};

}  // namespace

void build_block_tin(const RasterWindows& dem, OpSink& sink, const BlockTinOptions& options,
                     BlockTinStats* stats) {
  BlockTinStats local;
  BlockTinStats& st = stats != nullptr ? *stats : local;
  try {
    Builder(dem, options, st).run(sink);
  } catch (const LeafConflict&) {
    // Nothing reached the sink (ops are made after every level): start again, plain order.
    BlockTinOptions plain = options;
    plain.interleave_level0 = false;
    st = BlockTinStats{};
    st.level0_restarts = 1;
    Builder(dem, plain, st).run(sink);
  }
}

Crmr build_block_tin(const RasterWindows& dem, const BlockTinOptions& options,
                     BlockTinStats* stats) {
  CrmrCollector collector;
  build_block_tin(dem, collector, options, stats);
  return collector.take();
}

}  // namespace smr
