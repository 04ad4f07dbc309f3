// Feature preservation by the QEM progressive-mesh builder (smr/builders/mesh/qem_pm.h) on CGAL's
// fandisk.off, the CAD part with sharp creases that Hoppe's progressive meshes were shown on.
// The builder has no crease rule of its own: every collapse waits for the band of its guaranteed
// error bound, so one that would cut a crease comes after the flat collapses around it. The
// property tested is the one a user sees: in a coarse uniform cut (a few percent of the
// triangles), every crease of the source still has a crease of the output next to it, and the
// output has no crease where the source has none. Creases are found the same way on both sides
// (the faces' normals turn by more than 60 degrees), independently of the builder.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include "smr/builders/mesh/qem_pm.h"
#include "smr/extract/extract.h"
#include "smr/io/mesh_reader.h"
#include "smr/rcf/spec.h"
#include "tests/support/mesh_distance.h"
#include "tests/support/test_data.h"

namespace smr {
namespace {

using Segment = std::pair<Vec3, Vec3>;

// The edges of a closed or open triangle mesh whose two faces' normals turn by more than
// `degrees`.
std::vector<Segment> creases(const TriangleMesh& mesh, double degrees) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, std::vector<Vec3>> faces_of;
  for (const auto& t : mesh.triangles) {
    const Vec3 n = glm::cross(mesh.positions[t[1]] - mesh.positions[t[0]],
                              mesh.positions[t[2]] - mesh.positions[t[0]]);
    const double len = glm::length(n);
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = t[k], b = t[(k + 1) % 3];
      faces_of[{std::min(a, b), std::max(a, b)}].push_back(len > 0.0 ? n / len : Vec3(0.0));
    }
  }
  const double c = std::cos(degrees * 3.14159265358979323846 / 180.0);
  std::vector<Segment> out;
  for (const auto& [edge, normals] : faces_of) {
    if (normals.size() == 2 && glm::dot(normals[0], normals[1]) < c) {
      out.push_back({mesh.positions[edge.first], mesh.positions[edge.second]});
    }
  }
  return out;
}

// For points along every segment of `from` (ends, quarters, middle): the largest and the mean
// distance to the nearest segment of `to`.
std::pair<double, double> deviation(const std::vector<Segment>& from,
                                    const std::vector<Segment>& to) {
  double largest = 0.0, sum = 0.0;
  std::size_t n = 0;
  for (const Segment& s : from) {
    for (double t : {0.0, 0.25, 0.5, 0.75, 1.0}) {
      const Vec3 p = s.first + t * (s.second - s.first);
      double d = std::numeric_limits<double>::infinity();
      for (const Segment& o : to)
        d = std::min(d, test::textbook_segment_distance(p, o.first, o.second));
      largest = std::max(largest, d);
      sum += d;
      ++n;
    }
  }
  return {largest, n ? sum / double(n) : 0.0};
}

TEST(MeshFeatures, CoarseCutsKeepTheFandisksCreases) {
  const TriangleMesh source = read_mesh(test::data_path("meshes/fandisk.off"));
  const Crmr crmr = build_qem_pm(source, "fandisk.off");
  const std::vector<Segment> source_creases = creases(source, 60.0);
  ASSERT_GT(source_creases.size(), 600u) << "fandisk has about 700 creases";
  const double diagonal = glm::length(crmr.header.bounds.hi - crmr.header.bounds.lo);
  // Uniform cuts from coarse to fine; the first one with at least 3 % of the source's triangles
  // (and those up to 10 %) must keep the creases.
  std::size_t checked = 0;
  for (double floor = 0.95; floor < 1.0 && checked < 3; floor += 0.0025) {
    RcfSpec spec;
    spec.floor = floor;
    const Extraction e = extract_minimal_surface(crmr, make_rcf(spec, ModelKind::kMesh3d, nullptr));
    const TriangleMesh cut = to_mesh(crmr, e.triangles);
    const double fraction = double(cut.triangles.size()) / double(source.triangles.size());
    if (fraction < 0.03) continue;
    if (fraction > 0.10) break;
    const std::vector<Segment> cut_creases = creases(cut, 60.0);
    const auto [kept_max, kept_mean] = deviation(source_creases, cut_creases);
    const auto [made_max, made_mean] = deviation(cut_creases, source_creases);
    std::printf(
        "floor %.4f: %zu triangles (%.1f %%), %zu creases; source creases to the cut's: max %.3f "
        "%%, mean %.3f %% of the diagonal; the cut's to the source's: max %.3f %%, mean %.3f %%\n",
        floor, cut.triangles.size(), 100.0 * fraction, cut_creases.size(),
        100.0 * kept_max / diagonal, 100.0 * kept_mean / diagonal, 100.0 * made_max / diagonal,
        100.0 * made_mean / diagonal);
    EXPECT_LT(kept_max, 0.01 * diagonal) << "a crease of the source was smoothed away";
    EXPECT_LT(kept_mean, 0.002 * diagonal);
    EXPECT_LT(made_mean, 0.002 * diagonal) << "creases where the source has none";
    ++checked;
  }
  EXPECT_GE(checked, 1u) << "no uniform cut between 3 and 10 % of the triangles";
}

}  // namespace
}  // namespace smr
