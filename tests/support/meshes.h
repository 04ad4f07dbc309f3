// The 3-D test meshes (CGAL's demo data, fetched by scripts/fetch-data.sh), each read and built
// into a QEM progressive-mesh CRMR once per process, and a spread of 3-D RCFs placed relative to
// a model's bounds.
#pragma once

#include <string>
#include <vector>

#include "smr/builders/mesh/qem_pm.h"
#include "smr/core/invariants.h"
#include "smr/core/mesh.h"
#include "tests/support/rcf_spread.h"

namespace smr::test {

struct BuiltMesh {
  TriangleMesh source;
  Crmr crmr;
  QemPmStats stats;
};

/// `name` is a file of <data>/meshes (e.g. "bunny00.off"); pig.stl is read with MeshRepair::all().
const BuiltMesh& built_mesh(const std::string& name);

/// A cut of a 3-D CRMR has the source's topology, except for components not spawned yet: at most
/// the source's components and boundary loops, and exactly its components, loops and Euler
/// characteristic when every component is there.
void expect_same_topology_or_unspawned(const SurfaceReport& cut, const SurfaceReport& source);

/// Object-space levels 0..1, volumes of significance (Gaussian, ball, Gaussian over a floor) and
/// cameras from three directions at 3 and 1.2 model radii with 0.5, 2 and 8 px tolerances
/// (frustum and back-face culling on).
std::vector<NamedSpec> mesh_rcf_spread(const CrmrInfo& info);

}  // namespace smr::test
