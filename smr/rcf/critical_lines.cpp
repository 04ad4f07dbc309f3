#include "smr/rcf/critical_lines.h"

#include <algorithm>

namespace smr {

namespace {
constexpr int kBlock = 16;
}

CriticalLines CriticalLines::detect(const Heightfield& dem, const CriticalLineOptions& options) {
  CriticalLines cl;
  cl.width_ = dem.width;
  cl.height_ = dem.height;
  cl.georef_ = dem.georef;
  const std::size_t n = dem.z.size();
  // bit 1: marked lowest somewhere (not a ridge); bit 2: marked highest (not a channel);
  // bit 4: in at least one complete window.
  std::vector<std::uint8_t> marks(n, 0);
  for (int r = 0; r + 1 < dem.height; ++r) {
    for (int c = 0; c + 1 < dem.width; ++c) {
      const std::size_t idx[4] = {dem.index(c, r), dem.index(c + 1, r), dem.index(c, r + 1),
                                  dem.index(c + 1, r + 1)};
      bool all_valid = true;
      for (std::size_t i : idx) all_valid &= dem.valid.empty() || dem.valid[i] != 0;
      if (!all_valid) continue;
      float lo = dem.z[idx[0]], hi = lo;
      for (std::size_t i : idx) {
        lo = std::min(lo, dem.z[i]);
        hi = std::max(hi, dem.z[i]);
      }
      for (std::size_t i : idx) {
        marks[i] |= 4;
        if (dem.z[i] == lo) marks[i] |= 1;
        if (dem.z[i] == hi) marks[i] |= 2;
      }
    }
  }
  cl.flags_.assign(n, 0);
  for (int r = 0; r < dem.height; ++r) {
    for (int c = 0; c < dem.width; ++c) {
      const std::size_t i = dem.index(c, r);
      if ((marks[i] & 4) == 0 || (marks[i] & 3) == 3) continue;
      if (options.min_relief > 0.0) {
        float lo = dem.z[i], hi = lo;
        for (int dr = -1; dr <= 1; ++dr) {
          for (int dc = -1; dc <= 1; ++dc) {
            const int cc = c + dc, rr = r + dr;
            if (cc < 0 || rr < 0 || cc >= dem.width || rr >= dem.height || !dem.has_data(cc, rr))
              continue;
            lo = std::min(lo, dem.at(cc, rr));
            hi = std::max(hi, dem.at(cc, rr));
          }
        }
        if (double(hi) - double(lo) < options.min_relief) continue;
      }
      cl.flags_[i] = 1;
      ++cl.count_;
    }
  }
  cl.row_prefix_.assign(std::size_t(dem.width + 1) * dem.height, 0);
  for (int r = 0; r < dem.height; ++r) {
    std::uint32_t* p = &cl.row_prefix_[std::size_t(r) * (dem.width + 1)];
    for (int c = 0; c < dem.width; ++c) p[c + 1] = p[c] + cl.flags_[dem.index(c, r)];
  }
  cl.bw_ = (dem.width + kBlock - 1) / kBlock;
  cl.bh_ = (dem.height + kBlock - 1) / kBlock;
  cl.block_sat_.assign(std::size_t(cl.bw_ + 1) * (cl.bh_ + 1), 0);
  for (int br = 0; br < cl.bh_; ++br) {
    for (int bc = 0; bc < cl.bw_; ++bc) {
      std::uint64_t s = 0;
      for (int r = br * kBlock; r < std::min(dem.height, (br + 1) * kBlock); ++r) {
        s += cl.count_in_row(r, bc * kBlock, (bc + 1) * kBlock - 1);
      }
      const std::size_t w = cl.bw_ + 1;
      cl.block_sat_[(br + 1) * w + bc + 1] = s + cl.block_sat_[br * w + bc + 1] +
                                             cl.block_sat_[(br + 1) * w + bc] -
                                             cl.block_sat_[br * w + bc];
    }
  }
  return cl;
}

std::uint32_t CriticalLines::count_in_row(int row, int c0, int c1) const {
  if (row < 0 || row >= height_) return 0;
  c0 = std::max(c0, 0);
  c1 = std::min(c1, width_ - 1);
  if (c0 > c1) return 0;
  const std::uint32_t* p = &row_prefix_[std::size_t(row) * (width_ + 1)];
  return p[c1 + 1] - p[c0];
}

std::uint64_t CriticalLines::count_in_rect(int c0, int r0, int c1, int r1) const {
  c0 = std::max(c0, 0);
  r0 = std::max(r0, 0);
  c1 = std::min(c1, width_ - 1);
  r1 = std::min(r1, height_ - 1);
  if (c0 > c1 || r0 > r1) return 0;
  // Blocks fully inside via the SAT; partial rows at the edges via row prefixes.
  const int bc0 = (c0 + kBlock - 1) / kBlock, bc1 = (c1 + 1) / kBlock;  // full blocks [bc0, bc1)
  const int br0 = (r0 + kBlock - 1) / kBlock, br1 = (r1 + 1) / kBlock;
  if (bc0 >= bc1 || br0 >= br1) {
    std::uint64_t s = 0;
    for (int r = r0; r <= r1; ++r) s += count_in_row(r, c0, c1);
    return s;
  }
  const std::size_t w = bw_ + 1;
  std::uint64_t s = block_sat_[br1 * w + bc1] - block_sat_[br0 * w + bc1] -
                    block_sat_[br1 * w + bc0] + block_sat_[br0 * w + bc0];
  for (int r = r0; r <= r1; ++r) {
    if (r >= br0 * kBlock && r < br1 * kBlock) {
      s += count_in_row(r, c0, bc0 * kBlock - 1) + count_in_row(r, bc1 * kBlock, c1);
    } else {
      s += count_in_row(r, c0, c1);
    }
  }
  return s;
}

}  // namespace smr
