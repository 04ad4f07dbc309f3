// A database as smrdb serve holds it (api.h): opened once, shared by every request thread, with
// what its answers need precomputed (the info JSON, the tiling, layer.json).
#pragma once

#include <memory>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "smr/db/database.h"
#include "smr/query/indexed_source.h"
#include "smr/tiles/tiling.h"
#include "tools/serve/api.h"

namespace smr::serve {

struct Api::Db {
  Db(std::string name, const std::string& path, std::size_t cache_bytes);

  std::string name;
  std::unique_ptr<Database> db;
  std::unique_ptr<IndexedSource> source;  // extraction and queries go through the R-tree
  bool terrain = true;
  Vec3 origin{0.0};     // the centre of the bounds: frames' positions are relative to it
  nlohmann::json info;  // /info
  // Terrain only:
  std::optional<tiles::TilingScheme> scheme;
  int max_zoom = 0;
  double height_step = 0.0;
  std::string layer_json, layer_etag;
};

/// A strong ETag (quoted) of the bytes.
std::string strong_etag(const std::string& bytes);

}  // namespace smr::serve
