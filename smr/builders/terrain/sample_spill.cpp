// The samples' scratch copy of the block TIN builder; sample_spill.h describes it.
#include "smr/builders/terrain/sample_spill.h"

#include <algorithm>
#include <cstring>

namespace smr::block_tin {

SampleSpill::SampleSpill(const std::string& dir, int width, int height, int b, int nx, int ny,
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

void SampleSpill::warm(Cache& cache, int tx, int ty, const Heightfield& w, int c0, int r0) const {
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

void SampleSpill::put(int tx, int ty, const Heightfield& w, int c0, int r0) {
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

void SampleSpill::read_into(Heightfield& out, int col0, int row0, int w, int h,
                            const RasterWindows& source, Cache* cache) const {
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
        const std::size_t first = std::size_t(r_lo - ty * B_) * pitch + std::size_t(c_lo - tx * B_);
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

bool SampleSpill::all_stored(int tx0, int tx1, int ty0, int ty1) const {
  for (int ty = ty0; ty <= ty1; ++ty) {
    for (int tx = tx0; tx <= tx1; ++tx) {
      if (!stored(tx, ty)) return false;
    }
  }
  return true;
}

void SampleSpill::sample(int tx, int ty, int c, int r, Cache* cache, float& z,
                         std::uint8_t& v) const {
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

void SampleSpill::load(int tx, int ty, int c0, int r0, std::size_t n, std::size_t rows, float* z,
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

const SampleSpill::Cache::Tile& SampleSpill::cached(Cache& cache, int tx, int ty) const {
  bool fresh = false;
  Cache::Tile& t = entry(cache, tx, ty, fresh);
  if (fresh) {
    const auto [cw, rh] = extent(tx, ty);
    load(tx, ty, tx * B_, ty * B_, std::size_t(cw), std::size_t(rh), t.z.data(), t.v.data());
  }
  return t;
}

SampleSpill::Cache::Tile& SampleSpill::entry(Cache& cache, int tx, int ty, bool& fresh) const {
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

bool SampleSpill::read_cached(const Cache& cache, int tx, int ty, const RasterWindows& source,
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
}  // namespace smr::block_tin
