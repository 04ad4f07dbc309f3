// Peucker & Douglas' critical line detector (Brown 2.2.3): a 2x2 window passes over the DEM; in
// each position its lowest sample(s) cannot be on a ridge and its highest cannot be on a channel.
// Samples never marked lowest are ridge candidates, never marked highest channel candidates.
// Brown thresholds the output (4.6.2); we keep candidates whose 3x3 local relief >= min_relief.
#pragma once

#include <cstdint>
#include <vector>

#include "smr/core/heightfield.h"

namespace smr {

struct CriticalLineOptions {
  double min_relief = 0.0;  // data units; 0 keeps every Peucker-Douglas candidate
};

class CriticalLines {
 public:
  static CriticalLines detect(const Heightfield& dem, const CriticalLineOptions& options = {});

  int width() const { return width_; }
  int height() const { return height_; }
  const Georef& georef() const { return georef_; }
  std::uint64_t count() const { return count_; }
  bool flagged(int col, int row) const { return flags_[std::size_t(row) * width_ + col] != 0; }
  /// Number of flagged samples with col in [c0, c1] on `row` (clamped to the grid).
  std::uint32_t count_in_row(int row, int c0, int c1) const;
  /// Number of flagged samples in the grid rectangle [c0, c1] x [r0, r1] (clamped).
  std::uint64_t count_in_rect(int c0, int r0, int c1, int r1) const;

 private:
  int width_ = 0, height_ = 0;
  Georef georef_;
  std::uint64_t count_ = 0;
  std::vector<std::uint8_t> flags_;
  std::vector<std::uint32_t> row_prefix_;  // (width + 1) per row
  std::vector<std::uint64_t> block_sat_;   // summed-area table over 16x16 blocks
  int bw_ = 0, bh_ = 0;
};

}  // namespace smr
