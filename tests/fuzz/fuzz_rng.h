// The fuzz targets' random numbers: splitmix64 (smr::mix64 over a Weyl sequence), so a seed gives
// the same mutations with every standard library.
#pragma once

#include <cstddef>
#include <cstdint>

#include "smr/core/ids.h"

namespace smr::fuzz {

class Rng {
 public:
  explicit Rng(std::uint64_t seed) : s_(seed) {}
  std::uint64_t next() { return mix64(s_ += 0x9e3779b97f4a7c15ULL); }
  /// In [0, n); 0 when n is 0.
  std::size_t below(std::size_t n) { return n == 0 ? 0 : static_cast<std::size_t>(next() % n); }

 private:
  std::uint64_t s_;
};

}  // namespace smr::fuzz
