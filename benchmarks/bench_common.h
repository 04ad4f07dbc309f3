// Shared pieces of the benchmark programs: loading or generating the input DEM, machine and
// memory facts for the JSON reports, and an independent exact error-bound checker for any
// triangulation of a DEM whose vertices lie on grid samples (ours, delatin's, martini's).
//
// The checker deliberately does not reuse the builder's rasteriser or the test oracles: it
// rasterises each triangle in exact integer arithmetic (a sample belongs to a triangle iff it lies
// in the closed triangle; orientations are exact 64-bit integers), interpolates the triangle's
// plane at every covered sample with exact integer barycentric weights, and compares with the
// DEM. It also records which samples are covered at all, so "checked on every sample" is itself
// checked.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "smr/core/crmr.h"
#include "smr/core/geometry.h"
#include "smr/core/heightfield.h"

namespace smr::bench {

// ---- input ----------------------------------------------------------------------------------

struct InputOptions {
  std::string path;  // a DEM file (read_dem), or empty for fBm
  int fbm_size = 0;  // > 0: generate a fbm_size x fbm_size fBm instead
  std::uint64_t seed = 1;
  double range = 1600.0;  // fBm height range
  double spacing = 1.0;   // fBm sample spacing
};

struct Input {
  Heightfield dem;
  nlohmann::json description;  // path or generator parameters, size, z range, timing
  double z_min = 0.0, z_max = 0.0;
};

/// Reads or generates the DEM and describes it (read_seconds or generate_seconds included).
Input load_input(const InputOptions& options);

/// min and max z over samples with data.
std::pair<double, double> z_range(const Heightfield& dem);

/// For a geographic DEM (degrees), a copy whose x/y are local metres (equirectangular about the
/// mean latitude, origin at sample (0, 0)), so that cameras and screen-space errors mix metres with
/// metres. Other DEMs are returned unchanged.
Heightfield to_local_metres(const Heightfield& dem);

// ---- machine and process --------------------------------------------------------------------

/// nproc, CPU model, compiler, build type.
nlohmann::json machine_json();
/// Peak resident set size of this process so far (getrusage ru_maxrss), in MiB.
double peak_rss_mb();
/// Current resident set size (/proc/self/statm), in MiB; 0 when unavailable.
double current_rss_mb();

/// The median of `v` (0 when empty).
double median(std::vector<double> v);
double seconds_since(std::uint64_t start_ns);
std::uint64_t now_ns();

// ---- command lines and JSON -----------------------------------------------------------------

/// The items of a `sep`-separated list ("a,b,c"), empty items kept, none for an empty text.
std::vector<std::string> split_list(const std::string& text, char sep = ',');
/// A comma-separated list of numbers ("1,2.5,4"; std::stod each).
std::vector<double> parse_doubles(const std::string& text);
/// [x, y, z].
nlohmann::json vec3_json(const Vec3& v);

// ---- triangulations on the grid -------------------------------------------------------------

/// A triangulation whose vertices are grid samples (col, row). `z`, when not empty, gives the
/// elevation the producer stored at each vertex (checked against the DEM); otherwise the DEM's.
struct GridMesh {
  std::vector<std::array<std::uint32_t, 2>> vertices;
  std::vector<double> z;
  std::vector<std::array<std::uint32_t, 3>> triangles;
};

/// The finest mesh M^m of a terrain CRMR: every fragment triangle no op replaces (killer
/// invalid), void triangles excluded. Vertices are mapped back to grid samples; a vertex that is
/// not exactly at a sample position throws.
GridMesh finest_mesh(const Crmr& crmr, const Heightfield& dem);

/// Binary dump shared with benchmarks/peers/run_peer.mjs (little-endian):
///   8 bytes magic "SMRGRID1", uint32 vertex count V, uint32 triangle count T,
///   V x (uint32 col, uint32 row), T x (uint32 a, uint32 b, uint32 c).
void write_grid_mesh(const std::string& path, const GridMesh& mesh);
GridMesh read_grid_mesh(const std::string& path);

struct ErrorBoundReport {
  double bound = 0.0;      // the max error the mesh must honour
  double tolerance = 0.0;  // float-rounding slack added to the bound
  std::uint64_t triangles = 0;
  std::uint64_t degenerate_triangles = 0;     // zero area: skipped, counted as failures
  std::uint64_t bad_vertices = 0;             // outside the grid, or stored z != DEM sample
  std::uint64_t nodata_vertex_triangles = 0;  // a vertex without data: treated as void, skipped
  std::uint64_t sample_visits = 0;            // (triangle, sample) pairs evaluated
  std::uint64_t samples = 0;                  // samples with data in the DEM
  std::uint64_t samples_covered = 0;          // of those, covered by at least one triangle
  bool dem_has_nodata = false;  // then a valid sample with no valid neighbour may stay uncovered
  std::uint64_t nodata_samples_covered = 0;  // no-data samples inside a non-void triangle
  std::uint64_t violations = 0;              // sample visits deviating more than bound + tolerance
  std::uint64_t over_bound_strict = 0;       // ... more than bound (no tolerance)
  double max_deviation = 0.0;
  double rms_deviation = 0.0;  // over covered samples (each counted once)
  std::string first_violation;
  double seconds = 0.0;

  bool all_samples_covered() const { return samples_covered == samples; }
  /// The bound holds on every covered sample, and every sample is covered (on a DEM without
  /// no-data; with holes, a valid sample surrounded by no-data lies only in void triangles).
  bool ok() const {
    return violations == 0 && degenerate_triangles == 0 && bad_vertices == 0 &&
           (all_samples_covered() || dem_has_nodata);
  }
  nlohmann::json to_json() const;
};

/// Checks `mesh` against every sample of `dem`: |z_mesh(sample) - z_dem(sample)| <= bound for
/// every sample in every closed triangle, and every sample with data covered by some triangle.
ErrorBoundReport check_error_bound(const GridMesh& mesh, const Heightfield& dem, double bound);

}  // namespace smr::bench
