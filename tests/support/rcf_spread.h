// A spread of RCFs covering every component: constant floors 0..1, AOIs, discs, critical lines,
// cameras with and without culling, screen-space tolerances 0.5-8 px, a screen AOI.
#pragma once

#include <string>
#include <vector>

#include "smr/core/crmr.h"
#include "smr/rcf/spec.h"

namespace smr::test {

struct NamedSpec {
  std::string name;
  RcfSpec spec;
};

/// The tests' camera: from `eye` to `target`, a 50 degree field of view over 800x600 pixels.
Camera test_camera(const Vec3& eye, const Vec3& target);

/// RCFs placed relative to the model's bounds, so they mean the same on every DEM.
std::vector<NamedSpec> rcf_spread(const CrmrInfo& info);

}  // namespace smr::test
