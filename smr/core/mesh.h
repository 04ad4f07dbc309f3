// A plain indexed triangle mesh: what extraction hands to writers and renderers.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "smr/core/geometry.h"

namespace smr {

struct TriangleMesh {
  std::vector<Vec3> positions;
  std::vector<std::array<std::uint32_t, 3>> triangles;  // counter-clockwise seen from +z / outside
  /// Optional per-triangle scalar (e.g. death resolution) for colouring; empty or one per triangle.
  std::vector<float> triangle_values;
};

}  // namespace smr
