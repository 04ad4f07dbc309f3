// Internal: the interface between smrdb_io and the GDAL module (libsmrdb_gdal.so).
//
// GDAL drags in ~115 shared libraries and ~31 MiB of resident memory at process start, which an
// extraction under a memory budget must not pay for a library it never calls. So GDAL lives in a
// module that smrdb_io loads with dlopen the first time a raster is read or written
// (gdal_loader.cpp); a process that only extracts never maps it. The module exports one C symbol,
// kGdalModuleSymbol, returning this table. Both sides are built from the same tree and the same
// compiler, so C++ types (and smr::Error exceptions) cross the boundary; `abi` guards against a
// stale module from another build.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "smr/core/heightfield.h"

namespace smr::gdal_module {

inline constexpr std::uint32_t kAbi = 2;
inline constexpr const char* kSymbol = "smrdb_gdal_module";
inline constexpr const char* kFileName = "libsmrdb_gdal.so";

struct Api {
  std::uint32_t abi = kAbi;
  Heightfield (*read_raster)(const std::string& path) = nullptr;
  void (*write_geotiff)(const std::string& path, const Heightfield& h) = nullptr;
  std::unique_ptr<RasterWindows> (*open_raster)(const std::string& path) = nullptr;
};

/// The loaded module (loaded on first call; thread-safe). Looks, in order, at $SMRDB_GDAL_MODULE,
/// beside the executable, in <executable>/../lib/smrdb/, and at the build tree's copy. Throws
/// kIo naming every place tried when none loads.
const Api& api();

/// True once api() has loaded the module (for tests: extraction must not load it).
bool loaded();

}  // namespace smr::gdal_module
