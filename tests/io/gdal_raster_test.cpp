// Tests of read_gdal_raster and write_geotiff (smr/io/gdal_raster.h, smr/io/dem_reader.h):
// terra's elev.tif (values checked against gdalinfo / an AAIGrid export), round trips, and broken
// rasters made here with GDAL.
#include "smr/io/gdal_raster.h"

#include <cpl_string.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <cmath>
#include <limits>
#include <optional>

#include <gtest/gtest.h>

#include "smr/io/dem_reader.h"
#include "smr/io/synthetic.h"
#include "tests/io/io_test_helpers.h"
#include "tests/support/test_data.h"

namespace smr {
namespace {

using test::expect_error;
using test::TempDir;

struct RasterSpec {
  int width = 4, height = 3, bands = 1;
  GDALDataType type = GDT_Float32;
  std::optional<std::vector<double>> geotransform = std::vector<double>{100, 10, 0, 530, 0, -10};
  std::optional<double> nodata;
  std::optional<double> scale, offset;
  std::vector<double> values;  // file order (line 0 first); default: 10 * line + col
  std::string driver = "GTiff";
};

void make_raster(const std::string& path, RasterSpec spec) {
  GDALAllRegister();
  GDALDriver* driver = GetGDALDriverManager()->GetDriverByName(spec.driver.c_str());
  ASSERT_NE(driver, nullptr);
  GDALDatasetUniquePtr ds(
      driver->Create(path.c_str(), spec.width, spec.height, spec.bands, spec.type, nullptr));
  ASSERT_TRUE(ds);
  if (spec.geotransform) ds->SetGeoTransform(spec.geotransform->data());
  OGRSpatialReference srs;
  srs.importFromEPSG(4326);
  ds->SetSpatialRef(&srs);
  if (spec.values.empty()) {
    for (int l = 0; l < spec.height; ++l)
      for (int c = 0; c < spec.width; ++c) spec.values.push_back(10.0 * l + c);
  }
  for (int b = 1; b <= spec.bands; ++b) {
    GDALRasterBand* band = ds->GetRasterBand(b);
    if (spec.nodata) band->SetNoDataValue(*spec.nodata);
    if (spec.scale) band->SetScale(*spec.scale);
    if (spec.offset) band->SetOffset(*spec.offset);
    ASSERT_EQ(band->RasterIO(GF_Write, 0, 0, spec.width, spec.height, spec.values.data(),
                             spec.width, spec.height, GDT_Float64, 0, 0, nullptr),
              CE_None);
  }
}

// ---------------------------------------------------------------------------------------------
// terra's elev.tif: 95 x 90 Int16, WGS 84, origin (5.741666666666666, 50.19166666666666),
// pixel 0.0083333333333333 deg, nodata -32768; 4608 valid samples (3942 no data), min 141 at
// pixel (74, 81) and (74, 84), max 547 at pixel (33, 1) (col, line from the top).

TEST(GdalRaster, ElevTif) {
  const std::string path = test::data_path("elev.tif");
  const Heightfield h = read_gdal_raster(path);
  ASSERT_EQ(h.width, 95);
  ASSERT_EQ(h.height, 90);
  EXPECT_EQ(h.source, path);
  const double px = 0.0083333333333333;
  EXPECT_NEAR(h.georef.dx, px, 1e-15);  // gdalinfo rounds; the file holds 1/120 to ~1e-17
  EXPECT_NEAR(h.georef.dy, px, 1e-15);
  EXPECT_NEAR(h.georef.x0, 5.741666666666666 + px / 2, 1e-12);
  EXPECT_NEAR(h.georef.y0, 50.19166666666666 - 89.5 * px, 1e-12);  // centre of the southern line
  EXPECT_NEAR(h.georef.y0 - px / 2, 49.4416666666667, 1e-9);       // gdalinfo's lower-left
  EXPECT_TRUE(h.georef.geographic);
  EXPECT_NE(h.georef.crs_wkt.find("WGS 84"), std::string::npos);

  ASSERT_TRUE(h.has_nodata());
  ASSERT_EQ(h.valid.size(), h.z.size());
  std::size_t valid = 0;
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (std::size_t i = 0; i < h.z.size(); ++i) {
    if (h.valid[i] == 0) {
      EXPECT_EQ(h.z[i], 0.0f) << "no-data samples hold 0";
      continue;
    }
    ++valid;
    lo = std::min(lo, h.z[i]);
    hi = std::max(hi, h.z[i]);
  }
  EXPECT_EQ(valid, 4608u);
  EXPECT_EQ(h.z.size() - valid, 3942u);
  EXPECT_EQ(lo, 141.0f);
  EXPECT_EQ(hi, 547.0f);
  // Line L of the file is row 89 - L.
  EXPECT_EQ(h.at(33, 88), 547.0f);
  EXPECT_EQ(h.at(74, 8), 141.0f);
  EXPECT_EQ(h.at(74, 5), 141.0f);
  EXPECT_FALSE(h.has_data(0, 0));
  EXPECT_FALSE(h.has_data(0, 89));

  const Heightfield d = read_dem(path);
  EXPECT_EQ(d.z, h.z);
  EXPECT_EQ(d.valid, h.valid);
  EXPECT_EQ(d.georef, h.georef);
}

// ---------------------------------------------------------------------------------------------
// Orientation and georeferencing of made-up rasters

TEST(GdalRaster, NorthUpIsFlippedAndCentred) {
  TempDir dir;
  const std::string path = dir.file("north-up.tif");
  make_raster(path, {});
  const Heightfield h = read_gdal_raster(path);
  ASSERT_EQ(h.width, 4);
  ASSERT_EQ(h.height, 3);
  EXPECT_DOUBLE_EQ(h.georef.x0, 105);
  EXPECT_DOUBLE_EQ(h.georef.y0, 505);
  EXPECT_DOUBLE_EQ(h.georef.dx, 10);
  EXPECT_DOUBLE_EQ(h.georef.dy, 10);
  EXPECT_TRUE(h.valid.empty());
  EXPECT_EQ(h.at(0, 2), 0.0f);   // file line 0 is the northern row
  EXPECT_EQ(h.at(3, 0), 23.0f);  // file line 2 is row 0
  EXPECT_EQ(h.world(3, 0), Vec3(135, 505, 23));
}

TEST(GdalRaster, SouthUpIsNotFlipped) {
  TempDir dir;
  const std::string path = dir.file("south-up.tif");
  RasterSpec spec;
  spec.geotransform = std::vector<double>{100, 10, 0, 500, 0, 10};
  make_raster(path, spec);
  const Heightfield h = read_gdal_raster(path);
  EXPECT_DOUBLE_EQ(h.georef.y0, 505);
  EXPECT_DOUBLE_EQ(h.georef.dy, 10);
  EXPECT_EQ(h.at(0, 0), 0.0f);
  EXPECT_EQ(h.at(3, 2), 23.0f);
}

TEST(GdalRaster, NoGeotransformIsAUnitNorthUpImage) {
  TempDir dir;
  const std::string path = dir.file("plain.tif");
  RasterSpec spec;
  spec.geotransform.reset();
  make_raster(path, spec);
  const Heightfield h = read_gdal_raster(path);
  EXPECT_DOUBLE_EQ(h.georef.x0, 0);
  EXPECT_DOUBLE_EQ(h.georef.y0, 0);
  EXPECT_DOUBLE_EQ(h.georef.dx, 1);
  EXPECT_DOUBLE_EQ(h.georef.dy, 1);
  EXPECT_EQ(h.at(0, 2), 0.0f);
}

TEST(GdalRaster, ScaleAndOffsetAreApplied) {
  TempDir dir;
  const std::string path = dir.file("scaled.tif");
  RasterSpec spec;
  spec.type = GDT_Int16;
  spec.scale = 0.5;
  spec.offset = 100;
  make_raster(path, spec);
  const Heightfield h = read_gdal_raster(path);
  EXPECT_EQ(h.at(3, 0), 23 * 0.5f + 100);
}

TEST(GdalRaster, NoDataMaskAndNanNoData) {
  TempDir dir;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const double nodata : {-9999.0, nan}) {
    const std::string path = dir.file("masked.tif");
    RasterSpec spec;
    spec.nodata = nodata;
    spec.values = {0, 1, 2, 3, 10, 11, nodata, 13, 20, 21, 22, 23};
    make_raster(path, spec);
    const Heightfield h = read_gdal_raster(path);
    ASSERT_TRUE(h.has_nodata());
    EXPECT_FALSE(h.has_data(2, 1));  // line 1 -> row 1
    EXPECT_EQ(h.at(2, 1), 0.0f);
    EXPECT_TRUE(h.has_data(3, 1));
    EXPECT_EQ(h.valid[h.index(3, 1)], 1);
    EXPECT_EQ(std::count(h.valid.begin(), h.valid.end(), 0), 1);
  }
}

// ---------------------------------------------------------------------------------------------
// Bad rasters

TEST(GdalRaster, UnmaskedNanOrInfinityIsAnErrorNamingThePixel) {
  TempDir dir;
  const std::string path = dir.file("nan.tif");
  RasterSpec spec;
  spec.values = {0, 1, 2, 3, 10, 11, std::numeric_limits<double>::quiet_NaN(), 13, 20, 21, 22, 23};
  make_raster(path, spec);
  expect_error([&] { (void)read_dem(path); }, ErrorKind::kInvalidInput,
               {path, "NaN", "col 2, line 1", "no data"});
  spec.values[6] = 0;
  spec.values[9] = -std::numeric_limits<double>::infinity();
  make_raster(path, spec);
  expect_error([&] { (void)read_dem(path); }, ErrorKind::kInvalidInput,
               {path, "infinite", "col 1, line 2"});
}

TEST(GdalRaster, MultiBandIsAnError) {
  TempDir dir;
  const std::string path = dir.file("rgb.tif");
  RasterSpec spec;
  spec.bands = 3;
  make_raster(path, spec);
  expect_error([&] { (void)read_dem(path); }, ErrorKind::kInvalidInput,
               {path, "3 bands", "exactly one"});
}

TEST(GdalRaster, AllNoDataIsAnError) {
  TempDir dir;
  const std::string path = dir.file("void.tif");
  RasterSpec spec;
  spec.nodata = -1;
  spec.values.assign(12, -1);
  make_raster(path, spec);
  expect_error([&] { (void)read_dem(path); }, ErrorKind::kInvalidInput, {path, "no data at all"});
}

TEST(GdalRaster, RotatedOrMirroredGeotransformIsAnError) {
  TempDir dir;
  const std::string path = dir.file("rotated.tif");
  RasterSpec spec;
  spec.geotransform = std::vector<double>{100, 10, 1, 530, 0.5, -10};
  make_raster(path, spec);
  expect_error([&] { (void)read_dem(path); }, ErrorKind::kInvalidInput, {path, "rotated"});
  const std::string mirrored = dir.file("mirrored.tif");
  spec.geotransform = std::vector<double>{100, -10, 0, 530, 0, -10};
  make_raster(mirrored, spec);
  expect_error([&] { (void)read_dem(mirrored); }, ErrorKind::kInvalidInput,
               {mirrored, "pixel width"});
}

TEST(GdalRaster, MissingTextAndDirectoryInputs) {
  TempDir dir;
  const std::string missing = dir.file("missing.tif");
  expect_error([&] { (void)read_dem(missing); }, ErrorKind::kIo, {missing, "no such file"});
  for (const char* name : {"notes.txt", "fake.tif"}) {
    const std::string text = dir.file(name);
    test::write_text(text, "this is a text file, not a raster\n1 2 3\n");
    expect_error([&] { (void)read_dem(text); }, ErrorKind::kInvalidInput,
                 {text, "not a raster GDAL can read"});
  }
  expect_error([&] { (void)read_gdal_raster(dir.path().string()); }, ErrorKind::kInvalidInput,
               {dir.path().string(), "directory"});
}

// ---------------------------------------------------------------------------------------------
// write_geotiff

TEST(GeoTiff, RoundTripWithNoDataAndCrs) {
  TempDir dir;
  Heightfield h = make_fbm(300, 270, 11, 900.0, 0, 0.5, 30.0);
  h.georef.x0 = 500015;
  h.georef.y0 = 4100015;
  OGRSpatialReference utm;
  utm.importFromEPSG(32633);
  char* wkt = nullptr;
  utm.exportToWkt(&wkt);
  h.georef.crs_wkt = wkt;
  CPLFree(wkt);
  h.valid.assign(h.z.size(), 1);
  for (std::size_t i = 0; i < h.z.size(); i += 7) {
    h.valid[i] = 0;
    h.z[i] = 0;
  }
  const std::string path = dir.file("fbm.tif");
  write_geotiff(path, h);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"fbm.tif"});

  const Heightfield r = read_dem(path);
  ASSERT_EQ(r.width, h.width);
  ASSERT_EQ(r.height, h.height);
  EXPECT_EQ(r.z, h.z);
  EXPECT_EQ(r.valid, h.valid);
  EXPECT_DOUBLE_EQ(r.georef.x0, h.georef.x0);
  EXPECT_DOUBLE_EQ(r.georef.y0, h.georef.y0);
  EXPECT_DOUBLE_EQ(r.georef.dx, 30.0);
  EXPECT_DOUBLE_EQ(r.georef.dy, 30.0);
  EXPECT_FALSE(r.georef.geographic);
  EXPECT_NE(r.georef.crs_wkt.find("UTM zone 33N"), std::string::npos);

  // The file itself: tiled, DEFLATE, float32, north-up geotransform.
  GDALDatasetUniquePtr ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
  ASSERT_TRUE(ds);
  EXPECT_STREQ(ds->GetMetadataItem("COMPRESSION", "IMAGE_STRUCTURE"), "DEFLATE");
  int bx = 0, by = 0;
  ds->GetRasterBand(1)->GetBlockSize(&bx, &by);
  EXPECT_EQ(bx, 256);
  EXPECT_EQ(by, 256);
  EXPECT_EQ(ds->GetRasterBand(1)->GetRasterDataType(), GDT_Float32);
  double gt[6];
  ASSERT_EQ(ds->GetGeoTransform(gt), CE_None);
  EXPECT_DOUBLE_EQ(gt[0], 500000);
  EXPECT_DOUBLE_EQ(gt[3], 4100000 + 270 * 30.0);
  EXPECT_DOUBLE_EQ(gt[5], -30.0);
}

TEST(GeoTiff, RoundTripGeographicWithoutNoData) {
  TempDir dir;
  Heightfield h = make_fbm(40, 20, 3);
  h.georef = Georef{6.0, 49.5, 1.0 / 1200, 1.0 / 1200, "", true};
  OGRSpatialReference wgs84;
  wgs84.importFromEPSG(4326);
  char* wkt = nullptr;
  wgs84.exportToWkt(&wkt);
  h.georef.crs_wkt = wkt;
  CPLFree(wkt);
  const std::string path = dir.file("geo.tif");
  write_geotiff(path, h);
  const Heightfield r = read_gdal_raster(path);
  EXPECT_EQ(r.z, h.z);
  EXPECT_TRUE(r.valid.empty());
  EXPECT_NEAR(r.georef.x0, 6.0, 1e-12);
  EXPECT_NEAR(r.georef.y0, 49.5, 1e-12);
  EXPECT_TRUE(r.georef.geographic);
}

TEST(GeoTiff, WriteErrors) {
  TempDir dir;
  Heightfield h = make_fbm(8, 8, 1);
  expect_error([&] { write_geotiff("/nonexistent-smrdb-dir/x.tif", h); }, ErrorKind::kIo,
               {"/nonexistent-smrdb-dir/x.tif"});
  h.valid.assign(h.z.size(), 1);
  h.valid[0] = 0;
  h.z[5] = -3.4028234663852886e+38f;
  expect_error([&] { write_geotiff(dir.file("x.tif"), h); }, ErrorKind::kInvalidInput,
               {"x.tif", "nodata value"});
  h.z.pop_back();
  expect_error([&] { write_geotiff(dir.file("x.tif"), h); }, ErrorKind::kInvalidInput,
               {"x.tif", "consistent"});
  EXPECT_TRUE(dir.entries().empty());
}

}  // namespace
}  // namespace smr
