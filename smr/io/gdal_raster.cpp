// GDAL raster reading and GeoTIFF writing: the one place smrdb talks to GDAL. Built as the module
// libsmrdb_gdal.so, loaded on first use by gdal_loader.cpp (gdal_module.h says why); the
// functions' contracts are in dem_reader.h (read_gdal_raster) and gdal_raster.h (write_geotiff).

#include <cpl_conv.h>
#include <cpl_error.h>
#include <cpl_string.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <mutex>
#include <new>

#include "smr/io/atomic_file.h"
#include "smr/io/gdal_module.h"
#include "storage/error.h"

namespace smr {

namespace {

void ensure_registered() {
  static std::once_flag once;
  std::call_once(once, [] { GDALAllRegister(); });
}

// Keeps GDAL from printing to stderr while alive (GDAL's handler stack is per thread) and records
// its last error message so that ours can quote it.
class GdalErrors {
 public:
  GdalErrors() {
    CPLPushErrorHandlerEx(&GdalErrors::handler, this);
    CPLErrorReset();
  }
  ~GdalErrors() { CPLPopErrorHandler(); }
  GdalErrors(const GdalErrors&) = delete;
  GdalErrors& operator=(const GdalErrors&) = delete;

  bool failed() const { return failed_; }
  std::string suffix() const { return last_.empty() ? std::string() : " (GDAL: " + last_ + ")"; }

 private:
  static void CPL_STDCALL handler(CPLErr cls, CPLErrorNum, const char* msg) {
    auto* self = static_cast<GdalErrors*>(CPLGetErrorHandlerUserData());
    if (self == nullptr || cls < CE_Failure) return;
    self->failed_ = true;
    if (msg != nullptr) self->last_ = msg;
  }
  std::string last_;
  bool failed_ = false;
};

void flip_rows(std::vector<float>& z, std::vector<std::uint8_t>& valid, int width, int height) {
  const auto w = static_cast<std::ptrdiff_t>(width);
  for (std::ptrdiff_t r = 0, s = height - 1; r < s; ++r, --s) {
    std::swap_ranges(z.begin() + r * w, z.begin() + (r + 1) * w, z.begin() + s * w);
    if (!valid.empty()) {
      std::swap_ranges(valid.begin() + r * w, valid.begin() + (r + 1) * w, valid.begin() + s * w);
    }
  }
}

void check_readable_file(const std::string& path) {
  if (path.rfind("/vsi", 0) == 0) return;  // GDAL virtual file systems: let GDAL judge
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (!std::filesystem::exists(status)) throw_io("cannot open '" + path + "': no such file");
  if (std::filesystem::is_directory(status)) {
    throw_input("cannot read '" + path + "': it is a directory, expected a raster file");
  }
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) throw_io("cannot open '" + path + "': " + std::strerror(errno));
  std::fclose(f);
}

constexpr double kNoData = -3.4028234663852886e+38;  // lowest float32

Heightfield read_raster(const std::string& path) {
  check_readable_file(path);
  ensure_registered();
  GdalErrors errors;
  GDALDatasetUniquePtr ds(
      GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY | GDAL_OF_VERBOSE_ERROR));
  if (!ds) {
    throw_input("'" + path + "' is not a raster GDAL can read; expected a single-band DEM" +
                errors.suffix());
  }
  const int width = ds->GetRasterXSize(), height = ds->GetRasterYSize();
  const int bands = ds->GetRasterCount();
  if (bands != 1) {
    throw_input("'" + path + "' has " + std::to_string(bands) +
                " bands; expected exactly one elevation band");
  }
  if (width <= 0 || height <= 0) {
    throw_input("'" + path + "' is empty (" + std::to_string(width) + " x " +
                std::to_string(height) + " pixels); expected at least one pixel");
  }
  GDALRasterBand* band = ds->GetRasterBand(1);
  if (band == nullptr) throw_input("'" + path + "': GDAL cannot access band 1" + errors.suffix());
  if (GDALDataTypeIsComplex(band->GetRasterDataType())) {
    throw_input("'" + path + "' band 1 has the complex type " +
                GDALGetDataTypeName(band->GetRasterDataType()) + "; expected real elevations");
  }

  Heightfield h;
  h.width = width;
  h.height = height;
  h.source = path;

  // Georeferencing.
  double gt[6] = {0, 1, 0, 0, 0, -1};
  bool north_up = true;
  if (ds->GetGeoTransform(gt) == CE_None) {
    for (double v : gt) {
      if (!std::isfinite(v)) throw_input("'" + path + "' has a non-finite geotransform");
    }
    if (gt[2] != 0.0 || gt[4] != 0.0) {
      throw_input("'" + path + "' has a rotated or sheared geotransform (row rotation " +
                  std::to_string(gt[2]) + ", column rotation " + std::to_string(gt[4]) +
                  "); expected a north-up grid (warp it first, e.g. with gdalwarp)");
    }
    if (!(gt[1] > 0.0)) {
      throw_input("'" + path + "' has pixel width " + std::to_string(gt[1]) +
                  "; expected columns running west to east (a positive pixel width)");
    }
    if (gt[5] == 0.0) throw_input("'" + path + "' has a zero pixel height in its geotransform");
    north_up = gt[5] < 0.0;
    h.georef.dx = gt[1];
    h.georef.x0 = gt[0] + 0.5 * gt[1];
    h.georef.dy = std::fabs(gt[5]);
    // Centre of the southern line: the last line when north-up, the first otherwise.
    h.georef.y0 =
        north_up ? gt[3] + (static_cast<double>(height) - 0.5) * gt[5] : gt[3] + 0.5 * gt[5];
  } else {
    CPLErrorReset();  // a missing geotransform is not an error: unit pixels, north-up image
  }
  if (const char* wkt = ds->GetProjectionRef(); wkt != nullptr && *wkt != '\0') {
    h.georef.crs_wkt = wkt;
  }
  if (const OGRSpatialReference* srs = ds->GetSpatialRef(); srs != nullptr) {
    h.georef.geographic = srs->IsGeographic() != 0;
  }

  // Samples and mask, in file order (line 0 first).
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  try {
    h.z.resize(n);
  } catch (const std::bad_alloc&) {
    throw_input("'" + path + "' is too large to read into memory (" + std::to_string(width) +
                " x " + std::to_string(height) + " samples)");
  }
  if (band->RasterIO(GF_Read, 0, 0, width, height, h.z.data(), width, height, GDT_Float32, 0, 0,
                     nullptr) != CE_None) {
    throw_input("cannot read band 1 of '" + path + "'" + errors.suffix());
  }
  const int mask_flags = band->GetMaskFlags();
  if ((mask_flags & GMF_ALL_VALID) == 0) {
    GDALRasterBand* mask = band->GetMaskBand();
    h.valid.resize(n);
    if (mask == nullptr || mask->RasterIO(GF_Read, 0, 0, width, height, h.valid.data(), width,
                                          height, GDT_Byte, 0, 0, nullptr) != CE_None) {
      throw_input("cannot read the no-data mask of band 1 of '" + path + "'" + errors.suffix());
    }
  }
  int has_scale = 0, has_offset = 0;
  double scale = band->GetScale(&has_scale), offset = band->GetOffset(&has_offset);
  if (!has_scale) scale = 1.0;
  if (!has_offset) offset = 0.0;
  const bool rescale = scale != 1.0 || offset != 0.0;

  std::size_t valid_count = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!h.valid.empty() && h.valid[i] == 0) {
      h.z[i] = 0.0f;  // no data: a finite placeholder
      continue;
    }
    if (!h.valid.empty()) h.valid[i] = 1;  // GDAL masks use 255
    ++valid_count;
    if (rescale) h.z[i] = static_cast<float>(h.z[i] * scale + offset);
    if (!std::isfinite(h.z[i])) {
      throw_input("'" + path + "' band 1 has " +
                  (std::isnan(h.z[i]) ? "NaN" : "an infinite value") + " at pixel (col " +
                  std::to_string(i % static_cast<std::size_t>(width)) + ", line " +
                  std::to_string(i / static_cast<std::size_t>(width)) +
                  ") that is not marked as no data; expected finite elevations (set a nodata "
                  "value, e.g. gdal_edit.py -a_nodata nan)");
    }
  }
  if (valid_count == 0) {
    throw_input("'" + path + "' band 1 has no data at all: every sample is masked as no data");
  }
  if (valid_count == n) h.valid.clear();
  if (north_up) flip_rows(h.z, h.valid, width, height);
  return h;
}

void write_tiff(const std::string& path, const Heightfield& h) {
  if (h.width <= 0 || h.height <= 0 ||
      h.z.size() != static_cast<std::size_t>(h.width) * static_cast<std::size_t>(h.height) ||
      (!h.valid.empty() && h.valid.size() != h.z.size())) {
    throw_input("cannot write '" + path + "': the heightfield '" + h.source + "' is " +
                std::to_string(h.width) + " x " + std::to_string(h.height) + " with " +
                std::to_string(h.z.size()) + " samples and " + std::to_string(h.valid.size()) +
                " validity flags; expected a non-empty, consistent grid");
  }
  if (!(h.georef.dx > 0.0) || !(h.georef.dy > 0.0)) {
    throw_input("cannot write '" + path + "': the heightfield '" + h.source +
                "' has non-positive sample spacing");
  }
  if (h.has_nodata()) {
    for (std::size_t i = 0; i < h.z.size(); ++i) {
      if (h.valid[i] != 0 && double(h.z[i]) == kNoData) {
        throw_input("cannot write '" + path + "': sample " + std::to_string(i) +
                    " holds the nodata value -3.4028234663852886e+38 but is marked valid");
      }
    }
  }
  ensure_registered();
  GdalErrors errors;
  GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("GTiff");
  if (driver == nullptr) throw_internal("GDAL has no GTiff driver");

  AtomicFile file(path);
  file.close_stream();  // GDAL writes the temporary file itself
  char** options = nullptr;
  options = CSLSetNameValue(options, "TILED", "YES");
  options = CSLSetNameValue(options, "BLOCKXSIZE", "256");
  options = CSLSetNameValue(options, "BLOCKYSIZE", "256");
  options = CSLSetNameValue(options, "COMPRESS", "DEFLATE");
  options = CSLSetNameValue(options, "PREDICTOR", "3");
  options = CSLSetNameValue(options, "BIGTIFF", "IF_SAFER");
  GDALDatasetUniquePtr ds(
      driver->Create(file.temp_path().c_str(), h.width, h.height, 1, GDT_Float32, options));
  CSLDestroy(options);
  if (!ds) throw_io("cannot write '" + path + "'" + errors.suffix());

  const Georef& g = h.georef;
  double gt[6] = {g.x0 - 0.5 * g.dx,
                  g.dx,
                  0.0,
                  g.y0 + (static_cast<double>(h.height) - 0.5) * g.dy,
                  0.0,
                  -g.dy};
  ds->SetGeoTransform(gt);
  if (!g.crs_wkt.empty() && ds->SetProjection(g.crs_wkt.c_str()) != CE_None) {
    throw_input("cannot write '" + path + "': GDAL rejects the heightfield's CRS" +
                errors.suffix());
  }
  GDALRasterBand* band = ds->GetRasterBand(1);
  if (h.has_nodata()) band->SetNoDataValue(kNoData);

  // Write in strips of lines, line 0 = northern row.
  const int strip = 256;
  const auto w = static_cast<std::size_t>(h.width);
  std::vector<float> buffer(w * static_cast<std::size_t>(std::min(strip, h.height)));
  for (int line0 = 0; line0 < h.height && !errors.failed(); line0 += strip) {
    const int lines = std::min(strip, h.height - line0);
    for (int k = 0; k < lines; ++k) {
      const int row = h.height - 1 - (line0 + k);
      const std::size_t src = h.index(0, row);
      float* dst = buffer.data() + static_cast<std::size_t>(k) * w;
      std::copy_n(h.z.begin() + static_cast<std::ptrdiff_t>(src), w, dst);
      if (h.has_nodata()) {
        for (std::size_t c = 0; c < w; ++c) {
          if (h.valid[src + c] == 0) dst[c] = static_cast<float>(kNoData);
        }
      }
    }
    if (band->RasterIO(GF_Write, 0, line0, h.width, lines, buffer.data(), h.width, lines,
                       GDT_Float32, 0, 0, nullptr) != CE_None) {
      break;
    }
  }
  ds->FlushCache(true);
  ds.reset();  // closes the file; errors are reported through the handler
  if (errors.failed()) throw_io("cannot write '" + path + "'" + errors.suffix());
  file.commit();
}

}  // namespace

}  // namespace smr

extern "C" __attribute__((visibility("default"))) const smr::gdal_module::Api* smrdb_gdal_module() {
  static const smr::gdal_module::Api api{smr::gdal_module::kAbi, &smr::read_raster,
                                         &smr::write_tiff};
  return &api;
}
