// Reading DEMs into a Heightfield (smr/core/heightfield.h conventions: row 0 = south, (x0, y0) =
// centre of sample (0, 0), dx, dy > 0, `valid` empty when every sample has data).
//
// Every reader throws smr::Error (base/error.h): kIo when the operating system refuses
// (missing file, permission), kInvalidInput for anything wrong with the content; the message names
// the file (and the band / array / zip member) and says what was expected. No-data samples hold
// z = 0 (finite, so that code that forgets `valid` cannot be poisoned by NaN).
#pragma once

#include <memory>
#include <string>

#include "smr/core/heightfield.h"

namespace smr {

/// Reads a DEM, choosing the reader by extension (case-insensitive): `.npy` -> read_npy,
/// `.npz` -> read_npz, anything else -> read_gdal_raster.
Heightfield read_dem(const std::string& path);

/// Any single-band raster GDAL can open (GeoTIFF, ASCII grid, VRT, /vsi paths ...).
///  - exactly one band (else an error naming the band count); read as float32, with the band's
///    scale/offset applied when set; complex bands are rejected;
///  - georeferencing from the geotransform: rotated or sheared transforms are rejected; north-up
///    rasters (negative pixel height) are flipped so row 0 is the southern row; pixel-is-area
///    centres (GDAL normalises pixel-is-point files to the same convention); a raster without a
///    geotransform is taken as a north-up image with unit pixels and x0 = y0 = 0;
///  - crs_wkt from the dataset, `geographic` from OGRSpatialReference::IsGeographic;
///  - no data from GDAL's mask band (nodata value, NaN nodata, internal masks); a raster whose
///    every sample is no data is an error; a NaN or infinite sample that is not masked is an
///    error naming its pixel (col, line) as GDAL counts them (line 0 = first line in the file).
Heightfield read_gdal_raster(const std::string& path);

/// The same raster opened for reading by windows (RasterWindows): only the header is read here,
/// and each window is checked as read_gdal_raster checks the whole raster (a raster whose every
/// sample is no data is found only by the reader of the last window).
std::unique_ptr<RasterWindows> open_gdal_raster(const std::string& path);

/// read_dem's choice of reader, by windows: GDAL rasters and .npy files are read window by window;
/// .npz archives (whose members may be deflated) are read whole and served from memory.
std::unique_ptr<RasterWindows> open_dem(const std::string& path);

/// The same .npy opened for reading by windows: the header is read and checked here (shape,
/// dtype, and a file size that fits them), and each window's samples are read and checked (NaN,
/// infinities, integers that are not exact float32s, naming their index) when it is read.
std::unique_ptr<RasterWindows> open_npy(const std::string& path);

/// A NumPy .npy file holding one 2-D array (shape (rows, cols)); see smr/io/npy.h for the dtypes.
/// A plain .npy has no georeferencing: x0 = y0 = 0, dx = dy = 1, and rows are taken as stored
/// (array row 0 = heightfield row 0 = south), so read_npy(write_npy(h)) round-trips exactly.
Heightfield read_npy(const std::string& path);

/// A NumPy .npz archive (stored or deflated zip). The elevation array is the only 2-D array, or,
/// when there are several, the one named `elevation`, `topo` or `z`. Georeferencing, when present,
/// follows the matplotlib sample-data conventions:
///  - scalars xmin, xmax, ymin, ymax, dx, dy (jacksboro_fault_dem.npz): a raster in image order
///    (array row 0 = NORTH, as matplotlib's imshow/LightSource assume); the extent is
///    [min(xmin, xmax), max(...)] x [min(ymin, ymax), max(...)] (the sample file stores
///    ymin > ymax), either cell edges (extent = n * d) or sample centres (extent = (n - 1) * d);
///  - 1-D arrays longitude (length cols) and latitude (length rows) of sample centres
///    (topobathy.npz): rows are flipped when latitude decreases with the row; spacings must be
///    uniform to within half a cell (topobathy's Mercator-spaced latitudes deviate from uniform
///    by up to 0.44 cell, which is accepted: the georef is then approximate to that extent);
///    decreasing longitude is rejected.
/// Both conventions set geographic = true when the coordinates are degrees (longitude/latitude
/// arrays always; xmin.. when they lie within +-360 / +-90 and dx, dy < 0.1). Without these
/// arrays the archive is read like a plain .npy.
Heightfield read_npz(const std::string& path);

}  // namespace smr
