// README.md's library example (open -> RCF -> extract -> mesh), run as it is printed there: the
// demo's database (scripts/demo.sh: jacksboro_fault_dem.npz at max error 1) is ingested through
// the library into out/jacksboro.smrdb under a scratch directory, the example extracts from it a
// view with the demo's resolution floor and area of interest, and its output is checked against the
// definitions (Brown Theorems 5.1.1 and 5.2.1, the stored error bound). A second test checks that
// README.md shows this code verbatim.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "smr/builders/terrain/greedy_tin.h"
#include "smr/core/invariants.h"
#include "smr/db/writer.h"
#include "smr/io/dem_reader.h"
#include "smr/io/mesh_reader.h"
#include "tests/support/files.h"
#include "tests/support/oracles.h"
#include "tests/support/test_data.h"

// [readme-includes]
#include "smr/db/database.h"
#include "smr/extract/extract.h"
#include "smr/io/mesh_writer.h"
#include "smr/query/indexed_source.h"
#include "smr/rcf/spec.h"
// [readme-includes-end]

namespace smr {
namespace {

// Runs in `dir` while it lives, so that the example's relative paths land there.
class WorkingDirectory {
 public:
  explicit WorkingDirectory(const std::filesystem::path& dir)
      : before_(std::filesystem::current_path()) {
    std::filesystem::current_path(dir);
  }
  ~WorkingDirectory() { std::filesystem::current_path(before_); }
  WorkingDirectory(const WorkingDirectory&) = delete;
  WorkingDirectory& operator=(const WorkingDirectory&) = delete;

 private:
  std::filesystem::path before_;
};

TEST(ReadmeExample, ExtractsAViewThatTilesAndMeetsItsRcf) {
  const Heightfield dem = read_dem(test::data_path("jacksboro_fault_dem.npz"));
  const test::TempDir dir("smrdb-readme-example");
  const WorkingDirectory cwd(dir.path());
  std::filesystem::create_directory("out");
  {
    // What `smrdb ingest data/jacksboro_fault_dem.npz --max-error 1` does, through the library.
    const TerrainErrorSplit split = split_terrain_error(1.0, 0.0);
    GreedyTinOptions options;
    options.max_error = split.build_error;
    Crmr crmr = build_greedy_tin(dem, options);
    WriteOptions write;
    write.error_quantum = split.error_quantum;
    write_database(crmr, "out/jacksboro.smrdb", write);
  }

  // [readme-example]
  // Open the database read-only, its pages read through a 16 MiB cache.
  const auto db = smr::Database::open("out/jacksboro.smrdb", {.cache_bytes = 16 << 20});
  // Extraction reads it with its R-tree answering RCF queries (Maheshwari 4.4).
  const smr::IndexedSource source(*db);
  // The RCF (Brown 4.6): resolution 0.2 everywhere, up to 0.98 around a point of interest.
  smr::RcfSpec spec;
  spec.floor = 0.2;
  spec.aois.push_back({.x = -84.20, .y = 36.50, .radius = 0.03, .level = 0.98});
  const smr::Rcf rcf = smr::make_rcf(spec, db->info().kind, nullptr);
  // The smallest mesh that satisfies it (Brown 5.1), as vertices and triangles.
  const smr::Extraction e = smr::extract_minimal_surface(source, rcf);
  const smr::TriangleMesh mesh = smr::to_mesh(source, e.triangles);
  smr::write_mesh("out/view.obj", mesh);
  // [readme-example-end]

  // A selective mesh: finer than the base mesh R^0, coarser than the finest mesh (an RCF of
  // g = 1 everywhere).
  const std::size_t base = db->op(kBaseOp)->fragment.size();
  const Extraction finest =
      extract_minimal_surface(*db, make_rcf({}, ModelKind::kTerrain, nullptr));
  EXPECT_GT(mesh.triangles.size(), base);
  EXPECT_LT(mesh.triangles.size(), to_mesh(*db, finest.triangles).triangles.size());
  // Selective: within 0.03 degrees of the point of interest, over ten times the vertices of a
  // disc of the same size on the north-western plateau.
  const auto vertices_near = [&](double x, double y) {
    return std::count_if(mesh.positions.begin(), mesh.positions.end(),
                         [&](const Vec3& p) { return std::hypot(p.x - x, p.y - y) <= 0.03; });
  };
  EXPECT_GT(vertices_near(-84.20, 36.50), 10 * vertices_near(-84.35, 36.67));

  // Brown Theorem 5.2.1: the output tiles the DEM's domain (no gap, overlap or T-junction).
  const InvariantReport tiling = check_tiling(*db, e.triangles);
  EXPECT_TRUE(tiling.ok()) << tiling.summary();
  // Theorem 5.1.1, from the ops and independently at points of every triangle.
  const test::OracleResult opwise = test::check_rcf_opwise(*db, e.triangles, rcf);
  EXPECT_TRUE(opwise.ok()) << opwise.first_failure;
  const test::OracleResult pointwise = test::check_rcf_pointwise(*db, e.triangles, spec, dem);
  EXPECT_TRUE(pointwise.ok()) << pointwise.failures
                              << " failures; first: " << pointwise.first_failure;
  // The stored error of every output triangle bounds its deviation from every DEM sample under it.
  const test::OracleResult bound = test::check_error_bound(*db, e.triangles, dem);
  EXPECT_TRUE(bound.ok()) << bound.first_failure;

  // The file holds the mesh.
  const TriangleMesh written = read_mesh("out/view.obj");
  EXPECT_EQ(written.positions, mesh.positions);
  EXPECT_EQ(written.triangles, mesh.triangles);
}

// The lines between "// [marker]" and "// [marker-end]" in `text`, less their common indentation.
std::string marked(const std::string& text, const std::string& marker) {
  const std::string begin = "// [" + marker + "]\n", end = "// [" + marker + "-end]";
  const std::size_t from = text.find(begin);
  if (from == std::string::npos) return {};
  const std::size_t to = text.find(end, from);
  if (to == std::string::npos) return {};
  std::istringstream lines(text.substr(from + begin.size(), to - from - begin.size()));
  std::string out, line;
  std::size_t indent = std::string::npos;
  std::vector<std::string> all;
  while (std::getline(lines, line)) {
    all.push_back(line);
    if (line.find_first_not_of(' ') != std::string::npos)
      indent = std::min(indent, line.find_first_not_of(' '));
  }
  while (!all.empty() && all.back().find_first_not_of(' ') == std::string::npos) all.pop_back();
  for (const std::string& l : all) out += (l.size() > indent ? l.substr(indent) : "") + "\n";
  return out;
}

TEST(ReadmeExample, ReadmeShowsThisCode) {
  const std::string readme = test::read_file(SMRDB_README);
  const std::string source = test::read_file(SMRDB_README_EXAMPLE_TEST);
  const std::string includes = marked(source, "readme-includes");
  const std::string example = marked(source, "readme-example");
  ASSERT_FALSE(includes.empty());
  ASSERT_FALSE(example.empty());
  const std::string block = "```cpp\n" + includes + "\n" + example + "```\n";
  EXPECT_NE(readme.find(block), std::string::npos)
      << "README.md's library example differs from " << SMRDB_README_EXAMPLE_TEST
      << "; it should read:\n"
      << block;
}

}  // namespace
}  // namespace smr
