#include "tests/support/datasets.h"

#include <map>
#include <memory>
#include <mutex>

#include "smr/builders/terrain/greedy_tin.h"
#include "smr/io/dem_reader.h"
#include "smr/io/synthetic.h"
#include "tests/support/sanitized.h"
#include "tests/support/test_data.h"

namespace smr::test {

std::vector<std::string> dataset_names() {
  // jacksboro (403 x 344) and fbm257, the largest, were 30 % of the sanitizer run's time; the
  // other real DEMs (topobathy, elev with its no-data) and fbm129 cover the same code there.
  if (kSanitized) return {"topobathy", "elev", "fbm129"};
  return {"jacksboro", "topobathy", "elev", "fbm129", "fbm257"};
}

const Heightfield& dem(const std::string& name) {
  static std::map<std::string, std::unique_ptr<Heightfield>> cache;
  static std::mutex mu;
  std::lock_guard<std::mutex> lock(mu);
  auto& slot = cache[name];
  if (!slot) {
    if (name == "jacksboro") {
      slot = std::make_unique<Heightfield>(read_dem(data_path("jacksboro_fault_dem.npz")));
    } else if (name == "topobathy") {
      slot = std::make_unique<Heightfield>(read_dem(data_path("topobathy.npz")));
    } else if (name == "elev") {
      slot = std::make_unique<Heightfield>(read_dem(data_path("elev.tif")));
    } else if (name == "fbm129") {
      slot = std::make_unique<Heightfield>(make_fbm(129, 129, 7, 1600.0, 0, 0.5, 10.0));
    } else if (name == "fbm257") {
      slot = std::make_unique<Heightfield>(make_fbm(257, 193, 42, 1600.0, 0, 0.5, 10.0));
    } else {
      throw std::runtime_error("unknown dataset " + name);
    }
  }
  return *slot;
}

const Dataset& dataset(const std::string& name) {
  static std::map<std::string, std::unique_ptr<Dataset>> cache;
  static std::mutex mu;
  const Heightfield& h = dem(name);
  std::lock_guard<std::mutex> lock(mu);
  auto& slot = cache[name];
  if (!slot) {
    slot = std::make_unique<Dataset>();
    slot->name = name;
    slot->dem = h;
    // Tolerances that keep the suite fast while leaving thousands of ops: 2 m on the real DEMs
    // (jacksboro is 1 m integer data), 0.1 % of the range on fBm.
    slot->max_error = name.rfind("fbm", 0) == 0 ? 1.6 : 2.0;
    GreedyTinOptions opt;
    opt.max_error = slot->max_error;
    slot->crmr = build_greedy_tin(h, opt);
  }
  return *slot;
}

std::string mesh_path(const std::string& name) {
  return data_path("meshes/" + name);
}

}  // namespace smr::test
