// The progress bar every smrdb command draws on stderr, in GDAL's style:
// "0...10...20...30...40...50...60...70...80...90...100 - done."
// A dot every 2.5 %, the percentage every 10 %, printed as the fraction crosses each tick. Once a
// run has taken 5 s, each percentage is followed by an estimate of the time left, from the rate
// so far: "0...10...20 (eta 1:05)...30 (eta 0:52)...".
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdio>

namespace smr::tools {

class ProgressBar {
 public:
  /// Draws on `out`; nullptr draws nothing (-q, --json).
  explicit ProgressBar(std::FILE* out) : out_(out) {}
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
        const double elapsed =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
        if (ticks_ < 40 && elapsed >= 5.0) {
          const auto left = static_cast<long>(elapsed * double(40 - ticks_) / double(ticks_) + 0.5);
          std::fprintf(out_, " (eta %ld:%02ld)", left / 60, left % 60);
        }
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
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  int ticks_ = 0;
  bool started_ = false;
  bool finished_ = false;
};

}  // namespace smr::tools
