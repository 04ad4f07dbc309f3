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
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <mutex>
#include <new>

#include "base/error.h"
#include "smr/io/atomic_file.h"
#include "smr/io/gdal_module.h"

namespace smr {

namespace {

void ensure_registered() {
  static std::once_flag once;
  std::call_once(once, [] {
    GDALAllRegister();
    // GDAL's block cache defaults to 5 % of the machine's memory (1.2 GiB here), which a reader
    // that copies every window out at once does not need: decoded tiles are read once per
    // window. 64 MiB unless the user chose (GDAL_CACHEMAX).
    if (std::getenv("GDAL_CACHEMAX") == nullptr) {
      GDALSetCacheMax64(std::min<GIntBig>(GDALGetCacheMax64(), GIntBig{64} << 20));
    }
  });
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

// A raster opened once and read by windows (RasterWindows); read_raster reads one window, the
// whole raster.
class GdalWindows final : public RasterWindows {
 public:
  explicit GdalWindows(const std::string& path) : path_(path) {
    check_readable_file(path);
    ensure_registered();
    GdalErrors errors;
    ds_.reset(
        GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY | GDAL_OF_VERBOSE_ERROR));
    if (!ds_) {
      throw_input("'" + path + "' is not a raster GDAL can read; expected a single-band DEM" +
                  errors.suffix());
    }
    width_ = ds_->GetRasterXSize();
    height_ = ds_->GetRasterYSize();
    const int bands = ds_->GetRasterCount();
    if (bands != 1) {
      throw_input("'" + path + "' has " + std::to_string(bands) +
                  " bands; expected exactly one elevation band");
    }
    if (width_ <= 0 || height_ <= 0) {
      throw_input("'" + path + "' is empty (" + std::to_string(width_) + " x " +
                  std::to_string(height_) + " pixels); expected at least one pixel");
    }
    band_ = ds_->GetRasterBand(1);
    if (band_ == nullptr)
      throw_input("'" + path + "': GDAL cannot access band 1" + errors.suffix());
    if (GDALDataTypeIsComplex(band_->GetRasterDataType())) {
      throw_input("'" + path + "' band 1 has the complex type " +
                  GDALGetDataTypeName(band_->GetRasterDataType()) + "; expected real elevations");
    }
    // Georeferencing.
    double gt[6] = {0, 1, 0, 0, 0, -1};
    if (ds_->GetGeoTransform(gt) == CE_None) {
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
      north_up_ = gt[5] < 0.0;
      georef_.dx = gt[1];
      georef_.x0 = gt[0] + 0.5 * gt[1];
      georef_.dy = std::fabs(gt[5]);
      // Centre of the southern line: the last line when north-up, the first otherwise.
      georef_.y0 =
          north_up_ ? gt[3] + (static_cast<double>(height_) - 0.5) * gt[5] : gt[3] + 0.5 * gt[5];
    } else {
      CPLErrorReset();  // a missing geotransform is not an error: unit pixels, north-up image
    }
    if (const char* wkt = ds_->GetProjectionRef(); wkt != nullptr && *wkt != '\0') {
      georef_.crs_wkt = wkt;
    }
    if (const OGRSpatialReference* srs = ds_->GetSpatialRef(); srs != nullptr) {
      georef_.geographic = srs->IsGeographic() != 0;
    }
    masked_ = (band_->GetMaskFlags() & GMF_ALL_VALID) == 0;
    int has_scale = 0, has_offset = 0;
    scale_ = band_->GetScale(&has_scale);
    offset_ = band_->GetOffset(&has_offset);
    if (!has_scale) scale_ = 1.0;
    if (!has_offset) offset_ = 0.0;
  }

  int width() const override { return width_; }
  int height() const override { return height_; }
  const Georef& georef() const override { return georef_; }
  const std::string& source() const override { return path_; }

  std::uint64_t set_cache_bytes(std::uint64_t bytes) const override {
    // GDAL's block cache is the process's; lowering its limit evicts blocks down to it.
    const GIntBig before = GDALGetCacheMax64();
    GDALSetCacheMax64(static_cast<GIntBig>(bytes));
    return static_cast<std::uint64_t>(before);
  }
  Heightfield read(int col0, int row0, int w, int h) const override {
    if (col0 < 0 || row0 < 0 || w <= 0 || h <= 0 || col0 + w > width_ || row0 + h > height_) {
      throw_internal("'" + path_ + "': window outside the raster");
    }
    GdalErrors errors;
    Heightfield out = window_header(georef_, path_, col0, row0, w, h);
    // File lines of the window, the first one first.
    const int line0 = north_up_ ? height_ - row0 - h : row0;
    const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
    try {
      out.z.resize(n);
      if (masked_) out.valid.resize(n);
    } catch (const std::bad_alloc&) {
      throw_input("'" + path_ + "' is too large to read into memory (" + std::to_string(w) + " x " +
                  std::to_string(h) + " samples)");
    }
    if (band_->RasterIO(GF_Read, col0, line0, w, h, out.z.data(), w, h, GDT_Float32, 0, 0,
                        nullptr) != CE_None) {
      throw_input("cannot read band 1 of '" + path_ + "'" + errors.suffix());
    }
    if (masked_) {
      GDALRasterBand* mask = band_->GetMaskBand();
      if (mask == nullptr || mask->RasterIO(GF_Read, col0, line0, w, h, out.valid.data(), w, h,
                                            GDT_Byte, 0, 0, nullptr) != CE_None) {
        throw_input("cannot read the no-data mask of band 1 of '" + path_ + "'" + errors.suffix());
      }
    }
    const bool rescale = scale_ != 1.0 || offset_ != 0.0;
    std::size_t valid_count = 0;
    for (std::size_t i = 0; i < n; ++i) {
      if (masked_ && out.valid[i] == 0) {
        out.z[i] = 0.0f;  // no data: a finite placeholder
        continue;
      }
      if (masked_) out.valid[i] = 1;  // GDAL masks use 255
      ++valid_count;
      if (rescale) out.z[i] = static_cast<float>(out.z[i] * scale_ + offset_);
      if (!std::isfinite(out.z[i])) {
        throw_input("'" + path_ + "' band 1 has " +
                    (std::isnan(out.z[i]) ? "NaN" : "an infinite value") + " at pixel (col " +
                    std::to_string(col0 + int(i % static_cast<std::size_t>(w))) + ", line " +
                    std::to_string(line0 + int(i / static_cast<std::size_t>(w))) +
                    ") that is not marked as no data; expected finite elevations (set a nodata "
                    "value, e.g. gdal_edit.py -a_nodata nan)");
      }
    }
    if (valid_count == n) out.valid.clear();
    if (north_up_) flip_rows(out.z, out.valid, w, h);
    return out;
  }

 private:
  std::string path_;
  GDALDatasetUniquePtr ds_;
  GDALRasterBand* band_ = nullptr;
  int width_ = 0, height_ = 0;
  Georef georef_;
  bool north_up_ = true, masked_ = false;
  double scale_ = 1.0, offset_ = 0.0;
};

std::unique_ptr<RasterWindows> open_raster(const std::string& path) {
  return std::make_unique<GdalWindows>(path);
}

Heightfield read_raster(const std::string& path) {
  const GdalWindows r(path);
  Heightfield h = r.read(0, 0, r.width(), r.height());
  if (h.has_nodata() &&
      std::none_of(h.valid.begin(), h.valid.end(), [](std::uint8_t v) { return v != 0; })) {
    throw_input("'" + path + "' band 1 has no data at all: every sample is masked as no data");
  }
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
                                         &smr::write_tiff, &smr::open_raster};
  return &api;
}
