// read_dem: dispatch on the file extension.
#include "smr/io/dem_reader.h"

#include <algorithm>
#include <cctype>
#include <filesystem>

namespace smr {

Heightfield read_dem(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".npy") return read_npy(path);
  if (ext == ".npz") return read_npz(path);
  return read_gdal_raster(path);
}

}  // namespace smr
