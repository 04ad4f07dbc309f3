// The block TIN builder's copy of the DEM's samples (block_tin.h), kept so the passes after the
// leaf pass bound their triangles exactly from the samples (the Delaunay repair, level 0, the
// exact upper levels) without decoding the source again: out-of-core terrain simplification by
// blocks re-reads each block's window (Hoppe 1998, "Smooth view-dependent level-of-detail
// control and its application to terrain rendering", section 4).
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "smr/core/heightfield.h"
#include "storage/temp_file.h"

namespace smr::block_tin {

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
              const RasterWindows* direct);

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
  void warm(Cache& cache, int tx, int ty, const Heightfield& w, int c0, int r0) const;

  /// Stores tile (tx, ty) from window w, whose sample (0, 0) is grid (c0, r0). One thread at a
  /// time stores tiles; others may read the tiles stored before meanwhile.
  void put(int tx, int ty, const Heightfield& w, int c0, int r0);

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
                 Cache* cache = nullptr) const;

  /// Tile (tx, ty)'s window (its leaf block's) into `out`, reusing its buffers, if `cache`
  /// holds it; false if not.
  bool read_cached(const Cache& cache, int tx, int ty, const RasterWindows& source,
                   Heightfield& out) const;

  std::uint64_t bytes() const { return file_ ? file_->bytes_written() : 0; }

 private:
  bool stored(int tx, int ty) const {
    return stored_[std::size_t(ty) * std::size_t(nx_) + std::size_t(tx)] != 0;
  }
  bool all_stored(int tx0, int tx1, int ty0, int ty1) const;

  /// Sample (c, r) of stored tile (tx, ty), which holds it.
  void sample(int tx, int ty, int c, int r, Cache* cache, float& z, std::uint8_t& v) const;

  /// Samples [c0, c0 + n) x [r0, r0 + rows) of stored tile (tx, ty), which holds them, into z and
  /// v (n to a row).
  void load(int tx, int ty, int c0, int r0, std::size_t n, std::size_t rows, float* z,
            std::uint8_t* v) const;

  const Cache::Tile& cached(Cache& cache, int tx, int ty) const;
  /// Tile (tx, ty) of `cache`; if it is not there, a new one sized for it (`fresh`, its samples
  /// to be filled) in the oldest one's place when the cache is full.
  Cache::Tile& entry(Cache& cache, int tx, int ty, bool& fresh) const;

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

}  // namespace smr::block_tin
