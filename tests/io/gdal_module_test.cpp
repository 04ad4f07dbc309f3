// The GDAL module (smr/io/gdal_module.h) is loaded on first use only: a process that reads .npy
// DEMs and writes meshes never maps GDAL (~31 MiB of resident memory at start-up), and one that
// reads a GeoTIFF loads it and gets the same raster as before. This binary does not link GDAL.
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "io_test_helpers.h"
#include "smr/io/dem_reader.h"
#include "smr/io/gdal_module.h"
#include "smr/io/gdal_raster.h"
#include "smr/io/mesh_writer.h"
#include "smr/io/npy.h"

namespace smr {
namespace {

bool gdal_mapped() {
  std::ifstream maps("/proc/self/maps");
  std::string line;
  while (std::getline(maps, line)) {
    if (line.find("libgdal.so") != std::string::npos) return true;
  }
  return false;
}

Heightfield small_dem() {
  Heightfield h;
  h.width = 5;
  h.height = 4;
  h.georef.x0 = 10;
  h.georef.y0 = 20;
  h.georef.dx = h.georef.dy = 2;
  for (int i = 0; i < h.width * h.height; ++i) h.z.push_back(float(i % 7) * 1.5f);
  return h;
}

// One test: the order matters (the module stays loaded once loaded).
TEST(GdalModule, LoadedOnlyWhenARasterIsReadOrWritten) {
  test::TempDir dir;
  const Heightfield h = small_dem();
  ASSERT_FALSE(gdal_mapped()) << "GDAL is mapped before any raster was touched";

  write_npy(dir.file("a.npy"), h);
  const Heightfield from_npy = read_dem(dir.file("a.npy"));
  EXPECT_EQ(from_npy.z, h.z);
  TriangleMesh mesh;
  mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 2}};
  write_mesh(dir.file("m.ply"), mesh);
  EXPECT_FALSE(gdal_module::loaded());
  EXPECT_FALSE(gdal_mapped()) << ".npy reading and mesh writing loaded GDAL";

  write_geotiff(dir.file("a.tif"), h);
  EXPECT_TRUE(gdal_module::loaded());
  EXPECT_TRUE(gdal_mapped());
  const Heightfield from_tif = read_dem(dir.file("a.tif"));
  EXPECT_EQ(from_tif.z, h.z);
  EXPECT_EQ(from_tif.georef.x0, h.georef.x0);
  EXPECT_EQ(from_tif.georef.dy, h.georef.dy);

  // Errors raised inside the module reach the caller as smr::Error with their kind.
  test::expect_error([&] { (void)read_gdal_raster(dir.file("missing.tif")); }, ErrorKind::kIo,
                     {"missing.tif"});
}

}  // namespace
}  // namespace smr
