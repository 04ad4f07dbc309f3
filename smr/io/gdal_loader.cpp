// Loading the GDAL module on first use (see gdal_module.h), and the raster functions that
// forward to it.
#include <dlfcn.h>

#include <atomic>
#include <filesystem>
#include <mutex>
#include <vector>

#include "base/error.h"
#include "smr/io/dem_reader.h"
#include "smr/io/gdal_module.h"
#include "smr/io/gdal_raster.h"

namespace smr {

namespace gdal_module {

namespace {

std::atomic<bool> g_loaded{false};

std::vector<std::string> candidates() {
  std::vector<std::string> out;
  if (const char* env = std::getenv("SMRDB_GDAL_MODULE"); env != nullptr && *env != '\0') {
    out.emplace_back(env);
  }
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    out.push_back((exe.parent_path() / kFileName).string());
    out.push_back((exe.parent_path().parent_path() / "lib" / "smrdb" / kFileName).string());
  }
#ifdef SMRDB_GDAL_MODULE_BUILD_PATH
  out.emplace_back(SMRDB_GDAL_MODULE_BUILD_PATH);
#endif
  return out;
}

const Api* load() {
  std::string tried;
  for (const std::string& path : candidates()) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) {
      tried += "\n  " + path + ": no such file";
      continue;
    }
    void* handle = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      const char* why = ::dlerror();
      tried += "\n  " + path + ": " + (why != nullptr ? why : "dlopen failed");
      continue;
    }
    using Entry = const Api* (*)();
    auto entry = reinterpret_cast<Entry>(::dlsym(handle, kSymbol));
    const Api* api = entry != nullptr ? entry() : nullptr;
    if (api == nullptr || api->abi != kAbi || api->read_raster == nullptr ||
        api->write_geotiff == nullptr || api->open_raster == nullptr) {
      tried += "\n  " + path + ": not a GDAL module of this smrdb build";
      ::dlclose(handle);
      continue;
    }
    return api;  // never unloaded: GDAL keeps global state
  }
  throw_io(
      "cannot load smrdb's GDAL module " + std::string(kFileName) +
      " (needed to read and write rasters); set SMRDB_GDAL_MODULE to its path. Tried:" + tried);
}

}  // namespace

const Api& api() {
  static std::once_flag once;
  static const Api* table = nullptr;
  std::call_once(once, [] {
    table = load();
    g_loaded = true;
  });
  return *table;
}

bool loaded() {
  return g_loaded.load();
}

}  // namespace gdal_module

Heightfield read_gdal_raster(const std::string& path) {
  return gdal_module::api().read_raster(path);
}

void write_geotiff(const std::string& path, const Heightfield& h) {
  gdal_module::api().write_geotiff(path, h);
}

std::unique_ptr<RasterWindows> open_gdal_raster(const std::string& path) {
  return gdal_module::api().open_raster(path);
}

}  // namespace smr
