// GDAL-backed raster I/O. This file and gdal_raster.cpp are the only places that know GDAL;
// read_gdal_raster is declared in smr/io/dem_reader.h.
#pragma once

#include <string>

#include "smr/core/heightfield.h"

namespace smr {

/// Writes `h` as a single-band float32 GeoTIFF: north-up (heightfield row height-1 is the first
/// line), geotransform (x0 - dx/2, dx, 0, y0 + (height - 1/2) dy, 0, -dy) so that pixel centres
/// are the sample positions, h.georef.crs_wkt as the CRS when set, tiled 256 x 256, DEFLATE with
/// the floating-point predictor. When h has no-data samples they are written as the nodata value
/// -3.4028234663852886e+38 (the lowest float32; a valid sample equal to it is kInvalidInput), so
/// read_gdal_raster(path) returns h again (z, valid and georef; the WKT may be normalised).
/// Written to a temporary file then renamed; failures throw kIo naming the path.
void write_geotiff(const std::string& path, const Heightfield& h);

}  // namespace smr
