// A fragment's edges across its triangles (Brown 4.5.1: F's boundary is where the Hypermesh
// links start): the one search for a triangle's neighbours and for the boundary edges, shared by
// the builders' derived neighbours (crmr.h) and the page codec's link codes (smr/db/page.cpp).
// Two triangles are neighbours across edge k of one when the other has that edge reversed; a
// boundary edge is a directed edge whose reverse no triangle of the fragment has. Only the
// triangles' corners `v` are read, so any triangle type with them serves.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <unordered_map>

#include "smr/core/op.h"

namespace smr {

/// set(i, k, j): across edge k of triangle i lies triangle j (kNoNeighbour if none). Small
/// fragments are scanned, large ones hashed.
template <class Tri, class Set>
void for_each_neighbour(std::span<const Tri> fragment, Set&& set) {
  const std::size_t n = fragment.size();
  if (n > 64) {
    std::unordered_map<std::uint64_t, std::int32_t> by_edge;
    by_edge.reserve(n * 3);
    for (std::size_t i = 0; i < n; ++i) {
      const auto& v = fragment[i].v;
      for (int k = 0; k < 3; ++k)
        by_edge[(std::uint64_t(v[k]) << 32) | v[(k + 1) % 3]] = std::int32_t(i);
    }
    for (std::size_t i = 0; i < n; ++i) {
      const auto& v = fragment[i].v;
      for (int k = 0; k < 3; ++k) {
        auto it = by_edge.find((std::uint64_t(v[(k + 1) % 3]) << 32) | v[k]);
        set(i, k, it == by_edge.end() ? FragmentTriangle::kNoNeighbour : it->second);
      }
    }
    return;
  }
  for (std::size_t i = 0; i < n; ++i) {
    const auto& v = fragment[i].v;
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = v[(k + 1) % 3], b = v[k];  // the reversed edge a -> b
      std::int32_t found = FragmentTriangle::kNoNeighbour;
      for (std::size_t j = 0; j < n; ++j) {
        const auto& u = fragment[j].v;
        if ((u[0] == a && u[1] == b) || (u[1] == a && u[2] == b) || (u[2] == a && u[0] == b)) {
          found = std::int32_t(j);
          break;
        }
      }
      set(i, k, found);
    }
  }
}

/// visit(i, k) for each boundary edge k of triangle i, in (triangle, edge) order. With corners
/// below `vertex_count` <= 64 (an op's own vertex indices, as pages decode them) the directed
/// edges are the bits of one word per vertex, a few nanoseconds an edge; else for_each_neighbour.
template <class Tri, class Visit>
void for_each_boundary_edge(std::span<const Tri> fragment, std::size_t vertex_count,
                            Visit&& visit) {
  if (vertex_count > 64) {
    for_each_neighbour(fragment, [&](std::size_t i, int k, std::int32_t j) {
      if (j == FragmentTriangle::kNoNeighbour) visit(std::uint32_t(i), std::uint8_t(k));
    });
    return;
  }
  std::array<std::uint64_t, 64> out;  // out[a] bit b: the directed edge (a, b)
  std::fill_n(out.begin(), vertex_count, 0);
  for (const Tri& t : fragment)
    for (int k = 0; k < 3; ++k) out[t.v[k]] |= std::uint64_t{1} << t.v[(k + 1) % 3];
  for (std::uint32_t i = 0; i < fragment.size(); ++i) {
    const Tri& t = fragment[i];
    for (std::uint8_t k = 0; k < 3; ++k) {
      if (((out[t.v[(k + 1) % 3]] >> t.v[k]) & 1) == 0) visit(i, k);
    }
  }
}

}  // namespace smr
