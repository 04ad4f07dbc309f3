// Elevation grids from .npy arrays and .npz archives (read_npy, read_npz, heightfield_from_npy /
// _npz; formats in npy_format.cpp and npz_zip.cpp): a 2-D array becomes the heightfield's samples
// (any supported dtype, C or Fortran order, converted to float32 only when exact), and an .npz
// may georeference it with the scalars xmin, xmax, ymin, ymax, dx, dy or with the coordinate
// vectors longitude and latitude (the GMT / xarray export conventions).
#include <algorithm>
#include <bit>
#include <climits>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <string_view>

#include "base/error.h"
#include "smr/io/dem_reader.h"
#include "smr/io/io_util.h"
#include "smr/io/npy.h"
#include "smr/io/npy/npy_internal.h"

namespace smr {

namespace npy_io {

namespace {

[[noreturn]] void bad_sample(const std::string& what, std::size_t r, std::size_t c,
                             const std::string& why) {
  throw_input("'" + what + "' has " + why + " at index [" + std::to_string(r) + ", " +
              std::to_string(c) + "]; expected finite elevations");
}

bool integer_fits_float(std::uint64_t magnitude) {
  if (magnitude <= (std::uint64_t{1} << 24)) return true;
  magnitude >>= std::countr_zero(magnitude);
  return magnitude < (std::uint64_t{1} << 24);
}

}  // namespace

// The (rows, cols) of a 2-D array that fits a heightfield.
std::pair<std::size_t, std::size_t> grid_shape(const NpyArray& a, const std::string& what) {
  if (a.shape.size() != 2) {
    throw_input("'" + what + "' has shape " + shape_text(a.shape) +
                "; expected a 2-D array (rows, cols) of elevations");
  }
  const std::size_t rows = a.shape[0], cols = a.shape[1];
  if (rows == 0 || cols == 0) {
    throw_input("'" + what + "' is empty (shape " + shape_text(a.shape) +
                "); expected at least one row and one column");
  }
  if (rows > static_cast<std::size_t>(INT_MAX) || cols > static_cast<std::size_t>(INT_MAX)) {
    throw_input("'" + what + "' has shape " + shape_text(a.shape) +
                ", too large for a heightfield");
  }
  return {rows, cols};
}

// True when the elements are native float32s, which are copied as they are.
bool native_float32(const NpyArray& a) {
  return a.kind == NpyKind::kFloat && a.item_size == 4 &&
         a.big_endian == (std::endian::native == std::endian::big);
}

// Checks that float32 samples are finite: z[i] is elevation [r0 + i / w, c0 + i % w].
void check_finite(std::span<const float> z, std::size_t r0, std::size_t c0, std::size_t w,
                  const std::string& what) {
  for (std::size_t i = 0; i < z.size(); ++i) {
    if (!std::isfinite(z[i])) {
      bad_sample(what, r0 + i / w, c0 + i % w, std::isnan(z[i]) ? "NaN" : "an infinite value");
    }
  }
}

// The element at `p` of array `a` as a float32 elevation; (r, c) name it in errors.
float element(const NpyArray& a, const std::uint8_t* p, const std::string& what, std::size_t r,
              std::size_t c) {
  const int n = a.item_size;
  const std::uint64_t bits = a.big_endian ? load_be(p, n) : load_le(p, n);
  switch (a.kind) {
    case NpyKind::kFloat: {
      const double v = n == 4 ? double(std::bit_cast<float>(static_cast<std::uint32_t>(bits)))
                              : std::bit_cast<double>(bits);
      if (std::isnan(v)) bad_sample(what, r, c, "NaN");
      if (std::isinf(v)) bad_sample(what, r, c, "an infinite value");
      if (std::fabs(v) > double(std::numeric_limits<float>::max())) {
        bad_sample(what, r, c, "a value outside the float32 range");
      }
      return static_cast<float>(v);
    }
    case NpyKind::kBool:
      return bits != 0 ? 1.0f : 0.0f;
    case NpyKind::kUInt:
      if (!integer_fits_float(bits)) {
        bad_sample(what, r, c, "the integer " + std::to_string(bits) + ", not exactly a float32");
      }
      return static_cast<float>(bits);
    case NpyKind::kInt: {
      const int shift = 64 - 8 * n;
      const std::int64_t v = static_cast<std::int64_t>(bits << shift) >> shift;  // sign-extend
      const std::uint64_t magnitude =
          v < 0 ? static_cast<std::uint64_t>(-(v + 1)) + 1 : static_cast<std::uint64_t>(v);
      if (!integer_fits_float(magnitude)) {
        bad_sample(what, r, c, "the integer " + std::to_string(v) + ", not exactly a float32");
      }
      return static_cast<float>(v);
    }
  }
  return 0.0f;  // unreachable: every kind is handled above
}

}  // namespace npy_io

namespace {

using io_util::excerpt;
using npy_io::check_finite;
using npy_io::element;
using npy_io::grid_shape;
using npy_io::native_float32;
using npy_io::shape_text;

// ---------------------------------------------------------------------------------------------
// Conversion of a 2-D array to heightfield samples (array order: z row r = array row r).

struct Grid {
  int width = 0, height = 0;
  std::vector<float> z;
};

Grid to_grid(const NpyArray& a, const std::string& what) {
  const auto [rows, cols] = grid_shape(a, what);
  Grid g;
  g.width = static_cast<int>(cols);
  g.height = static_cast<int>(rows);
  g.z.resize(rows * cols);
  const std::uint8_t* base = a.data.data();
  if (native_float32(a) && !a.fortran_order) {
    std::memcpy(g.z.data(), base, g.z.size() * sizeof(float));  // the common case
    check_finite(g.z, 0, 0, cols, what);
    return g;
  }
  const auto n = static_cast<std::size_t>(a.item_size);
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t c = 0; c < cols; ++c) {
      const std::size_t i = a.fortran_order ? c * rows + r : r * cols + c;
      g.z[r * cols + c] = element(a, base + i * n, what, r, c);
    }
  }
  return g;
}

void flip_rows(Grid& g) {
  const auto w = static_cast<std::size_t>(g.width);
  for (int r = 0, s = g.height - 1; r < s; ++r, --s) {
    std::swap_ranges(g.z.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(r) * w),
                     g.z.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(r + 1) * w),
                     g.z.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(s) * w));
  }
}

Heightfield to_heightfield(Grid g, const std::string& source) {
  Heightfield h;
  h.width = g.width;
  h.height = g.height;
  h.z = std::move(g.z);
  h.source = source;
  return h;
}

// ---------------------------------------------------------------------------------------------
// .npz georeferencing

const NpyArray* find(const std::map<std::string, NpyArray>& arrays, const std::string& name) {
  const auto it = arrays.find(name);
  return it == arrays.end() ? nullptr : &it->second;
}

double scalar(const NpyArray& a, const std::string& what) {
  if (a.count() != 1 || a.shape.size() > 1) {
    throw_input("'" + what + "' has shape " + shape_text(a.shape) + "; expected a scalar");
  }
  const double v = a.value(0);
  if (!std::isfinite(v)) throw_input("'" + what + "' is not finite; expected a number");
  return v;
}

// Origin and spacing of one axis given by an extent [lo, hi] and a spacing d for n samples.
void axis_from_extent(double a, double b, double d, std::size_t n, const std::string& what,
                      double& origin) {
  const double lo = std::min(a, b), span = std::fabs(b - a);
  const double nd = static_cast<double>(n);
  if (!(d > 0.0)) throw_input(what + ": the spacing must be positive");
  if (std::fabs(span - nd * d) <= 0.01 * d) {
    origin = lo + 0.5 * d;  // extent = cell edges
  } else if (n > 1 && std::fabs(span - (nd - 1.0) * d) <= 0.01 * d) {
    origin = lo;  // extent = sample centres
  } else {
    throw_input(what + ": the extent " + std::to_string(span) + " does not match " +
                std::to_string(n) + " samples at spacing " + std::to_string(d) +
                " (expected n * d for cell edges or (n - 1) * d for sample centres)");
  }
}

struct AxisFit {
  double first = 0.0, step = 0.0;
};

AxisFit fit_axis(const NpyArray& a, std::size_t n, const std::string& what, bool allow_decreasing) {
  if (a.shape.size() != 1 || a.shape[0] != n) {
    throw_input("'" + what + "' has shape " + shape_text(a.shape) + "; expected (" +
                std::to_string(n) + ",) to match the elevation array");
  }
  std::vector<double> v(n);
  for (std::size_t i = 0; i < n; ++i) {
    v[i] = a.value(i);
    if (!std::isfinite(v[i])) {
      throw_input("'" + what + "' has a non-finite value at index " + std::to_string(i));
    }
  }
  AxisFit fit{v[0], 0.0};
  if (n == 1) return fit;
  fit.step = (v[n - 1] - v[0]) / static_cast<double>(n - 1);
  if (fit.step == 0.0 || (!allow_decreasing && fit.step < 0.0)) {
    throw_input("'" + what + "' must be strictly " +
                std::string(allow_decreasing ? "monotonic" : "increasing"));
  }
  for (std::size_t i = 1; i < n; ++i) {
    if ((v[i] - v[i - 1]) * fit.step <= 0.0) {
      throw_input("'" + what + "' is not strictly monotonic at index " + std::to_string(i));
    }
  }
  for (std::size_t i = 0; i < n; ++i) {
    const double dev = std::fabs(v[i] - (v[0] + static_cast<double>(i) * fit.step));
    if (dev > 0.5 * std::fabs(fit.step)) {
      throw_input("'" + what + "' is not uniformly spaced: value " + std::to_string(i) + " is " +
                  std::to_string(dev / std::fabs(fit.step)) +
                  " cells from a uniform grid (expected at most 0.5)");
    }
  }
  return fit;
}

// ---------------------------------------------------------------------------------------------
// .npz: the elevation array and its georeferencing

// The 2-D array that holds the elevations: the only one, or the one named elevation, topo or z.
std::string choose_elevation(const std::map<std::string, NpyArray>& arrays,
                             const std::string& what) {
  std::vector<std::string> grids;
  for (const auto& [name, a] : arrays) {
    if (a.shape.size() == 2) grids.push_back(name);
  }
  std::string elevation;
  if (grids.size() == 1) {
    elevation = grids[0];
  } else {
    for (const char* preferred : {"elevation", "topo", "z"}) {
      if (std::find(grids.begin(), grids.end(), preferred) != grids.end()) {
        elevation = preferred;
        break;
      }
    }
  }
  if (elevation.empty()) {
    std::string list;
    for (const auto& [name, a] : arrays) {
      list += (list.empty() ? "" : ", ") + excerpt(name, 40) + shape_text(a.shape);
    }
    throw_input("'" + what + "' has " + (grids.empty() ? "no" : std::to_string(grids.size())) +
                " 2-D arrays; expected exactly one, or one named 'elevation', 'topo' or 'z' "
                "(arrays: " +
                (list.empty() ? "none" : list) + ")");
  }
  return elevation;
}

constexpr const char* kExtent[] = {"xmin", "xmax", "ymin", "ymax", "dx", "dy"};

// Georeferencing by the scalars xmin, xmax, ymin, ymax, dx, dy (all six); rows are flipped to
// put the northern row first.
Georef georef_from_extent(const std::map<std::string, NpyArray>& arrays, const std::string& what,
                          Grid& g) {
  const auto cols = static_cast<std::size_t>(g.width), rows = static_cast<std::size_t>(g.height);
  Georef geo;
  double v[6];
  for (int k = 0; k < 6; ++k) {
    const NpyArray* a = find(arrays, kExtent[k]);
    if (a == nullptr) {
      throw_input("'" + what + "' has some of the arrays xmin, xmax, ymin, ymax, dx, dy but not '" +
                  kExtent[k] + "'; expected all six for georeferencing");
    }
    v[k] = scalar(*a, what + ":" + kExtent[k]);
  }
  geo.dx = v[4];
  geo.dy = v[5];
  axis_from_extent(v[0], v[1], geo.dx, cols, "'" + what + "' xmin/xmax/dx", geo.x0);
  axis_from_extent(v[2], v[3], geo.dy, rows, "'" + what + "' ymin/ymax/dy", geo.y0);
  const double xlo = std::min(v[0], v[1]), xhi = std::max(v[0], v[1]);
  const double ylo = std::min(v[2], v[3]), yhi = std::max(v[2], v[3]);
  geo.geographic =
      xlo >= -360.0 && xhi <= 360.0 && ylo >= -90.0 && yhi <= 90.0 && geo.dx < 0.1 && geo.dy < 0.1;
  flip_rows(g);  // image order: array row 0 is the northern row
  return geo;
}

// Georeferencing by the coordinate vectors longitude and latitude (both; uniformly spaced, latitude
// may decrease, which flips the rows).
Georef georef_from_axes(const NpyArray* lon, const NpyArray* lat, const std::string& what,
                        Grid& g) {
  if (lon == nullptr || lat == nullptr) {
    throw_input("'" + what + "' has only one of the arrays 'longitude' and 'latitude'; " +
                "expected both for georeferencing");
  }
  const auto cols = static_cast<std::size_t>(g.width), rows = static_cast<std::size_t>(g.height);
  Georef geo;
  const AxisFit fx = fit_axis(*lon, cols, what + ":longitude", false);
  const AxisFit fy = fit_axis(*lat, rows, what + ":latitude", true);
  geo.dx = fx.step != 0.0 ? fx.step : (fy.step != 0.0 ? std::fabs(fy.step) : 1.0);
  geo.dy = fy.step != 0.0 ? std::fabs(fy.step) : geo.dx;
  geo.x0 = fx.first;
  if (fy.step < 0.0) {
    geo.y0 = fy.first + fy.step * static_cast<double>(rows - 1);
    flip_rows(g);
  } else {
    geo.y0 = fy.first;
  }
  geo.geographic = true;
  return geo;
}

}  // namespace

Heightfield heightfield_from_npy(std::span<const std::uint8_t> bytes, const std::string& what) {
  const NpyArray a = parse_npy(bytes, what);
  return to_heightfield(to_grid(a, what), what);
}

Heightfield heightfield_from_npz(std::span<const std::uint8_t> bytes, const std::string& what) {
  const std::vector<NpzMember> members = unpack_npz(bytes, what);
  std::map<std::string, NpyArray> arrays;
  for (const NpzMember& m : members) arrays[m.name] = parse_npy(m.bytes, what + ":" + m.name);
  const std::string elevation = choose_elevation(arrays, what);
  Grid g = to_grid(arrays.at(elevation), what + ":" + elevation);
  Georef geo;
  bool extent = false;  // any of the six extent scalars
  for (const char* name : kExtent) extent = extent || find(arrays, name) != nullptr;
  const NpyArray* lon = find(arrays, "longitude");
  const NpyArray* lat = find(arrays, "latitude");
  if (extent) {
    geo = georef_from_extent(arrays, what, g);
  } else if (lon != nullptr || lat != nullptr) {
    geo = georef_from_axes(lon, lat, what, g);
  }
  Heightfield h = to_heightfield(std::move(g), what);
  h.georef = geo;
  return h;
}

Heightfield read_npy(const std::string& path) {
  const std::vector<std::uint8_t> bytes = io_util::read_file_bytes(path, "a file");
  return heightfield_from_npy(bytes, path);
}

Heightfield read_npz(const std::string& path) {
  const std::vector<std::uint8_t> bytes = io_util::read_file_bytes(path, "a file");
  return heightfield_from_npz(bytes, path);
}

}  // namespace smr
