// Spawned components (Brown 4.4.1, Fig. 4.9d): once simplification has run to its end, every
// component but one is removed whole, as one more "collapse" with no replacement; reversed, its
// op spawns the component.
#pragma once

#include "smr/builders/mesh/pm_mesh.h"
#include "smr/builders/mesh/qem_pm.h"

namespace smr::qem {

/// Removes every live component but the one whose removal would cost most, each logged as a
/// collapse with kept == kNone (QemPmStats::spawned_components counts them). The bound: a
/// source point assigned to a triangle T of the component is within e(T) of a point q of T, and
/// q within (distance from a corner of T to the rest of the mesh) + (T's longest edge) of the
/// rest. Nothing when no collapse was made (a spawn needs an op to hold it).
void remove_components(PmMesh& m, CollapseLog& log, QemPmStats& stats);

}  // namespace smr::qem
