// GDAL-style progress on a terminal: "0...10...20...30...40...50...60...70...80...90...100 - done."
// A dot every 2.5 %, the percentage every 10 %, printed as the fraction crosses each tick.
#pragma once

#include <algorithm>
#include <cstdio>

namespace smr::tools {

class GdalProgress {
 public:
  explicit GdalProgress(std::FILE* out) : out_(out) {}
  void update(double fraction) {
    if (out_ == nullptr) return;
    if (!started_) {
      std::fputc('0', out_);
      started_ = true;
    }
    const int target = static_cast<int>(std::clamp(fraction, 0.0, 1.0) * 40.0);
    while (ticks_ < target) {
      ++ticks_;
      if (ticks_ % 4 == 0) {
        std::fprintf(out_, "%d", ticks_ * 10 / 4);
      } else {
        std::fputc('.', out_);
      }
    }
    std::fflush(out_);
  }
  void done() {
    if (out_ == nullptr || finished_) return;
    update(1.0);
    std::fputs(" - done.\n", out_);
    finished_ = true;
  }

 private:
  std::FILE* out_;
  int ticks_ = 0;
  bool started_ = false;
  bool finished_ = false;
};

}  // namespace smr::tools
