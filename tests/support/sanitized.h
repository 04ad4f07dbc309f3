// Under AddressSanitizer/UndefinedBehaviorSanitizer (the asan preset) every run is 3-10x slower.
// Sweeps that repeat one code path many times (damage at every page, kills at many moments, the
// same invariants on every dataset) run a sample there: the release run does them in full, and
// the sample still puts each code path under the sanitizers.
#pragma once

#include <cstddef>

namespace smr::test {

#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kSanitized = true;
#else
inline constexpr bool kSanitized = false;
#endif

/// Whether item i of a sweep runs: all of them in a plain build, every `every`-th under the
/// sanitizers.
constexpr bool in_sample(std::size_t i, std::size_t every) {
  return !kSanitized || i % every == 0;
}

}  // namespace smr::test
