#include "tests/support/meshes.h"

#include <cmath>
#include <map>
#include <mutex>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include "smr/io/mesh_reader.h"
#include "tests/support/test_data.h"

namespace smr::test {

const BuiltMesh& built_mesh(const std::string& name) {
  static std::mutex mutex;
  static std::map<std::string, BuiltMesh> cache;
  std::lock_guard lock(mutex);
  auto it = cache.find(name);
  if (it != cache.end()) return it->second;
  BuiltMesh b;
  // pig.stl pinches itself at vertices shared by separate parts (bowties): it is read with the
  // repairs (MeshRepair::all(), the CLI's --repair), which split them. The others read as they are.
  const MeshRepair repair = name == "pig.stl" ? MeshRepair::all() : MeshRepair{};
  b.source = read_mesh(data_path("meshes/" + name), repair);
  b.crmr = build_qem_pm(b.source, name, {}, &b.stats);
  return cache.emplace(name, std::move(b)).first->second;
}

void expect_same_topology_or_unspawned(const SurfaceReport& cut, const SurfaceReport& source) {
  EXPECT_LE(cut.components, source.components);
  EXPECT_LE(cut.boundary_loops, source.boundary_loops);
  if (cut.components == source.components) {
    EXPECT_EQ(cut.boundary_loops, source.boundary_loops);
    EXPECT_EQ(cut.euler, source.euler);
  }
}

std::vector<NamedSpec> mesh_rcf_spread(const CrmrInfo& info) {
  std::vector<NamedSpec> out;
  for (double g : {0.0, 0.3, 0.6, 0.9, 1.0}) {
    RcfSpec s;
    s.floor = g;
    out.push_back({"floor " + std::to_string(g), s});
  }
  const Vec3 c = 0.5 * (info.bounds.lo + info.bounds.hi);
  const double radius = 0.5 * glm::length(info.bounds.hi - info.bounds.lo);
  // Volumes of significance around a corner region of the box: Gaussian, thresholded, and a
  // Gaussian over a floor.
  const Vec3 corner = info.bounds.lo + 0.3 * (info.bounds.hi - info.bounds.lo);
  for (int kind = 0; kind < 3; ++kind) {
    RcfSpec s;
    s.volumes.push_back({corner.x, corner.y, corner.z, 0.25 * radius, 0.95, kind != 1});
    if (kind == 2) s.floor = 0.4;
    out.push_back(
        {std::string(kind == 1 ? "ball" : "gaussian volume") + (kind == 2 ? " over floor 0.4" : ""),
         s});
  }
  const std::array<Vec3, 3> dirs{Vec3{1, 0.3, 0.2}, Vec3{-0.4, 1, -0.5}, Vec3{0.2, -0.6, 1}};
  for (std::size_t d = 0; d < dirs.size(); ++d) {
    for (double distance : {3.0, 1.2}) {
      for (double px : {0.5, 2.0, 8.0}) {
        RcfSpec s;
        Camera cam;
        cam.eye = c + glm::normalize(dirs[d]) * (distance * radius);
        cam.target = c;
        cam.up = std::abs(dirs[d].z) > 0.9 ? Vec3{0, 1, 0} : Vec3{0, 0, 1};
        s.camera = cam;
        s.pixel_error = px;
        out.push_back({"camera " + std::to_string(d) + " at " + std::to_string(distance) +
                           " radii, " + std::to_string(px) + " px",
                       s});
      }
    }
  }
  return out;
}

}  // namespace smr::test
