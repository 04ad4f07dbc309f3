// What the database tests compare between a clean and a damaged or concurrently read database:
// both extraction algorithms for one RCF and the mesh of the minimal surface.
#pragma once

#include <span>
#include <vector>

#include "smr/core/mesh.h"
#include "smr/extract/extract.h"
#include "smr/rcf/spec.h"

namespace smr::test {

struct Result {
  Extraction minimal, reduced;
  TriangleMesh mesh;
};

/// Minimal-surface and reduced extraction of `spec` (a terrain RCF without a DEM) from `source`.
Result extract_all(const OpSource& source, const RcfSpec& spec);

/// Same X, triangles and mesh.
bool same(const Result& a, const Result& b);

/// The triangles in ascending order (sets of triangles compared as such).
std::vector<TriRef> sorted(std::span<const TriRef> triangles);

}  // namespace smr::test
