// Shared pieces of the benchmarks that read an on-disk database (bench_db, bench_extract_speed):
// the OS page cache (what of a file is resident, dropping it, warming it) and the named cameras
// placed relative to a model's bounds.
#pragma once

#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include "smr/core/geometry.h"
#include "smr/rcf/camera.h"

namespace smr::bench {

// ---- the OS page cache ----------------------------------------------------------------------

/// Bytes of `path` resident in the OS page cache (mincore over a mapping that is never touched).
std::uint64_t resident_bytes(const std::string& path);

/// Drops `path` from the OS page cache (no process may map it at the time). Returns the bytes
/// still resident afterwards (0 when the drop worked).
std::uint64_t drop_from_page_cache(const std::string& path);

/// Reads `path` once from start to end, so that it is in the OS page cache. Returns its bytes.
std::uint64_t warm_page_cache(const std::string& path);

// ---- views ----------------------------------------------------------------------------------

/// Named cameras relative to the model's bounds (L = the larger horizontal extent):
///   oblique   a low camera inside the south-west quarter, 0.02 L above the highest point,
///             looking north-east across the terrain towards (60 %, 75 %) at 30 % of the relief;
///   overview  a high camera 1.0 L above the highest point, south of the centre, looking at the
///             centre: the whole terrain in view.
/// Any other name throws smr::Error (kInvalidInput). The viewport and field of view are Camera's
/// defaults.
Camera named_camera(const std::string& name, const Box3& bounds);

/// "x,y,z" -> Vec3; anything else throws smr::Error (kInvalidInput) naming `what`.
Vec3 parse_vec3(const std::string& text, const char* what);

/// {eye, target, fov_y_deg, viewport, far}.
nlohmann::json camera_json(const Camera& c);

}  // namespace smr::bench
