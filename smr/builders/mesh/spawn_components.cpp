// Spawned components (Brown 4.4.1, Fig. 4.9d; spawn_components.h).
#include "smr/builders/mesh/spawn_components.h"

#include <algorithm>
#include <limits>
#include <utility>
#include <vector>

namespace smr::qem {
namespace {

// Distance from p to the live triangles of every component but `comp`.
double distance_to_others(const PmMesh& m, const Vec3& p, std::uint32_t comp,
                          const std::vector<std::vector<std::uint32_t>>& tris_of) {
  double best = std::numeric_limits<double>::infinity();
  for (std::uint32_t other = 0; other < tris_of.size(); ++other) {
    if (other == comp) continue;
    for (std::uint32_t id : tris_of[other]) {
      const Tri& t = m.tris[id];
      best =
          std::min(best, point_triangle_distance3d(p, m.pos[t.v[0]], m.pos[t.v[1]], m.pos[t.v[2]]));
    }
  }
  return best;
}

struct Removal {
  double error;
  std::uint32_t comp;
};

// Each component's removal and its bound, least first (ties: the smaller component id).
std::vector<Removal> removals_of(const PmMesh& m,
                                 const std::vector<std::vector<std::uint32_t>>& tris_of) {
  std::vector<Removal> removals;
  for (std::uint32_t comp = 0; comp < tris_of.size(); ++comp) {
    if (tris_of[comp].empty()) continue;
    double e = 0.0;
    for (std::uint32_t id : tris_of[comp]) {
      const Tri& t = m.tris[id];
      double nearest = 0.0, longest = 0.0;
      for (int k = 0; k < 3; ++k) {
        nearest = std::max(nearest, distance_to_others(m, m.pos[t.v[k]], comp, tris_of));
        longest = std::max(longest, glm::length(m.pos[t.v[k]] - m.pos[t.v[(k + 1) % 3]]));
      }
      e = std::max(e, t.e + nearest + longest);
    }
    removals.push_back({e, comp});
  }
  std::sort(removals.begin(), removals.end(), [](const Removal& a, const Removal& b) {
    return a.error != b.error ? a.error < b.error : a.comp < b.comp;
  });
  return removals;
}

}  // namespace

void remove_components(PmMesh& m, CollapseLog& log, QemPmStats& stats) {
  if (log.collapses.empty()) return;  // a spawn needs an op to hold it
  std::vector<std::vector<std::uint32_t>> tris_of(m.comp_vertices.size());
  for (std::uint32_t id = 0; id < m.tris.size(); ++id) {
    if (m.tris[id].destroyer == kNone) tris_of[m.comp[m.tris[id].v[0]]].push_back(id);
  }
  std::vector<Removal> removals = removals_of(m, tris_of);
  if (removals.size() < 2) return;
  removals.pop_back();  // the coarsest mesh keeps one component
  for (const Removal& r : removals) {
    Collapse col;
    col.removed = kNone;
    col.kept = kNone;
    col.error = r.error;
    col.old_begin = static_cast<std::uint32_t>(log.old_tris.size());
    const auto c = static_cast<std::uint32_t>(log.collapses.size());
    for (std::uint32_t id : tris_of[r.comp]) {
      log.old_tris.push_back(id);
      m.tris[id].destroyer = c;
      for (std::uint32_t v : m.tris[id].v) col.spawn_vertices.push_back(v);
    }
    std::sort(col.spawn_vertices.begin(), col.spawn_vertices.end());
    col.spawn_vertices.erase(std::unique(col.spawn_vertices.begin(), col.spawn_vertices.end()),
                             col.spawn_vertices.end());
    col.old_end = static_cast<std::uint32_t>(log.old_tris.size());
    col.new_begin = col.new_end = static_cast<std::uint32_t>(log.new_tris.size());
    log.collapses.push_back(std::move(col));
    ++stats.spawned_components;
  }
}

}  // namespace smr::qem
