// read_dem: dispatch on the file extension.
#include "smr/io/dem_reader.h"

#include <memory>
#include <utility>

#include "smr/io/io_util.h"

namespace smr {

namespace {

using io_util::lower_extension;

/// A Heightfield read whole, served by windows.
class OwnedWindows final : public RasterWindows {
 public:
  explicit OwnedWindows(Heightfield h) : h_(std::move(h)), windows_(h_) {}
  int width() const override { return h_.width; }
  int height() const override { return h_.height; }
  const Georef& georef() const override { return h_.georef; }
  const std::string& source() const override { return h_.source; }
  Heightfield read(int col0, int row0, int w, int h) const override {
    return windows_.read(col0, row0, w, h);
  }
  bool random_access() const override { return true; }

 private:
  Heightfield h_;
  HeightfieldWindows windows_;
};

}  // namespace

Heightfield read_dem(const std::string& path) {
  const std::string ext = lower_extension(path);
  if (ext == ".npy") return read_npy(path);
  if (ext == ".npz") return read_npz(path);
  return read_gdal_raster(path);
}

std::unique_ptr<RasterWindows> open_dem(const std::string& path) {
  const std::string ext = lower_extension(path);
  if (ext == ".npy") return open_npy(path);
  if (ext == ".npz") return std::make_unique<OwnedWindows>(read_npz(path));
  return open_gdal_raster(path);
}

}  // namespace smr
