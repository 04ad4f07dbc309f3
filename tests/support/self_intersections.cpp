#include "tests/support/self_intersections.h"

#include <map>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Surface_mesh.h>

namespace smr::test {

std::size_t crossing_pairs(const std::vector<std::array<Vec3, 3>>& triangles) {
  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Mesh = CGAL::Surface_mesh<K::Point_3>;
  std::vector<K::Point_3> points;
  std::vector<std::array<std::size_t, 3>> faces;
  std::map<std::array<double, 3>, std::size_t> index;
  for (const auto& t : triangles) {
    std::array<std::size_t, 3> f{};
    for (std::size_t k = 0; k < 3; ++k) {
      const auto [it, fresh] = index.emplace(std::array{t[k].x, t[k].y, t[k].z}, points.size());
      if (fresh) points.emplace_back(t[k].x, t[k].y, t[k].z);
      f[k] = it->second;
    }
    faces.push_back(f);
  }
  Mesh mesh;
  CGAL::Polygon_mesh_processing::polygon_soup_to_polygon_mesh(points, faces, mesh);
  std::vector<std::pair<Mesh::Face_index, Mesh::Face_index>> pairs;
  CGAL::Polygon_mesh_processing::self_intersections(mesh, std::back_inserter(pairs));
  return pairs.size();
}

}  // namespace smr::test
