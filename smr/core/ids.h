// Typed 64-bit ids (STYLE.md, after OpenMesh's handles): an OpId cannot be passed where a
// VertexId is expected. The values double as storage keys in the on-disk store.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>

namespace smr {

template <class Tag>
struct Id {
  static constexpr std::uint64_t kInvalidValue = std::numeric_limits<std::uint64_t>::max();
  std::uint64_t value = kInvalidValue;

  constexpr Id() = default;
  constexpr explicit Id(std::uint64_t v) : value(v) {}
  constexpr bool valid() const { return value != kInvalidValue; }
  friend constexpr auto operator<=>(Id, Id) = default;
};

using OpId = Id<struct OpTag>;
using VertexId = Id<struct VertexTag>;

/// R^0, the pseudo refinement operation holding the base mesh (Brown 4.4.1).
inline constexpr OpId kBaseOp{0};

/// A triangle of the CRMR: triangle `index` of the fragment F(op). Every triangle belongs to
/// exactly one fragment, so this is its identity for set comparisons (Brown 4.4.1).
struct TriRef {
  OpId op;
  std::uint32_t index = 0;
  friend constexpr auto operator<=>(const TriRef&, const TriRef&) = default;
};

/// splitmix64 finaliser (Steele et al. 2014): the project's one integer hash.
constexpr std::uint64_t mix64(std::uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return x;
}

}  // namespace smr

template <class Tag>
struct std::hash<smr::Id<Tag>> {
  std::size_t operator()(smr::Id<Tag> id) const noexcept { return smr::mix64(id.value); }
};
template <>
struct std::hash<smr::TriRef> {
  std::size_t operator()(const smr::TriRef& t) const noexcept {
    return smr::mix64(t.op.value * 0x9E3779B97F4A7C15ULL + t.index);
  }
};
