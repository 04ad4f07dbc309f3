// The test datasets: three real DEMs no one here made (fetched by scripts/fetch-data.sh) and
// deterministic synthetic fBm terrains. Loaded and built once per test process.
#pragma once

#include <string>
#include <vector>

#include "smr/core/crmr.h"
#include "smr/core/heightfield.h"

namespace smr::test {

struct Dataset {
  std::string name;
  Heightfield dem;
  double max_error = 0.0;  // the build tolerance used by the shared CRMR
  Crmr crmr;
};

/// Names: "jacksboro", "topobathy", "elev", "fbm129", "fbm257".
std::vector<std::string> dataset_names();
/// The DEM alone (cached).
const Heightfield& dem(const std::string& name);
/// The DEM with a CRMR built at the dataset's standard tolerance (cached).
const Dataset& dataset(const std::string& name);

/// Full path of a real mesh in <data dir>/meshes (bunny00.off, pig.stl, ...); like data_path, a
/// missing file fails the current test.
std::string mesh_path(const std::string& name);

}  // namespace smr::test
