// Wall-clock time of a phase, as the stats structs report it (seconds, steady clock).
#pragma once

#include <chrono>

namespace smr {

using Clock = std::chrono::steady_clock;

/// Seconds from `t0` to now.
inline double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

}  // namespace smr
