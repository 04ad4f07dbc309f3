// smrdb serve's request handling (docs/serve.md): a request (method, decoded path, query pairs,
// a few headers) in, a response (status, type, bytes) out. No socket here: http.h carries
// requests to Api::handle from httplib, and the tests can call it directly.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "smr/core/mesh.h"
#include "smr/db/database.h"
#include "smr/query/indexed_source.h"
#include "tools/serve/sessions.h"
#include "tools/serve/tile_cache.h"

namespace smr::serve {

struct ApiOptions {
  std::uint64_t max_triangles = 2'000'000;  // per response (extract, session frame)
  double timeout_ms = 10'000;               // compute budget of a request
  std::size_t max_sessions = 64;
  std::size_t tile_cache_bytes = std::size_t{64} << 20;  // encoded tiles kept (0: none)
  std::chrono::milliseconds session_idle{60'000};
};

/// Writes a mesh of `db` as the GLB `smrdb extract -o x.glb` writes (tools/serve_cmd.cpp gives
/// the CLI's writer); `extras` go to asset.extras.smrdb.
using GlbWriter = std::function<std::string(const Database& db, const TriangleMesh& mesh,
                                            const nlohmann::json& extras)>;

struct Request {
  std::string method;  // GET, POST, DELETE
  std::string path;    // decoded, without the query
  std::vector<std::pair<std::string, std::string>> params;
  std::string if_none_match;
};

struct Response {
  int status = 200;
  std::string content_type = "application/json";
  std::string body;
  std::string etag;  // quoted; empty: none
  std::vector<std::pair<std::string, std::string>> headers;
};

/// The body of an error answer: {"error": message}.
Response error_response(int status, const std::string& message);

class Api {
 public:
  /// Opens each database (name, path) read-only with a page cache of `cache_bytes`; throws
  /// smr::Error naming a bad name, a duplicate or a file that does not open.
  Api(const std::vector<std::pair<std::string, std::string>>& databases, std::size_t cache_bytes,
      const ApiOptions& options, GlbWriter glb);
  ~Api();
  /// Never throws: errors become 4xx/5xx answers with a JSON body.
  Response handle(const Request& request);
  std::size_t sessions() { return sessions_.size(); }

  struct Db;

 private:
  Response route(const Request& request);
  Response databases() const;
  Response info(const Db& db) const;
  Response extract(const Db& db, const Request& request);
  Response layer(const Db& db, const Request& request) const;
  Response tile(const Db& db, const std::vector<std::string>& parts, const Request& request);
  Response query(const Db& db, const std::string& kind, const Request& request) const;
  Response session_create(Db& db);
  Response session_update(Db& db, const std::string& id, const Request& request);
  Response session_delete(Db& db, const std::string& id);

  std::vector<std::unique_ptr<Db>> dbs_;
  ApiOptions options_;
  GlbWriter glb_;
  SessionTable sessions_;
  TileCache tile_cache_;
};

/// A name for a database path given without one: its file stem.
std::string default_name(const std::string& path);
/// Whether `name` may name a database in a URL: [A-Za-z0-9_-]{1,64}.
bool valid_name(const std::string& name);

}  // namespace smr::serve
