// smrdb serve's HTTP transport: the one place that knows cpp-httplib. httplib parses requests
// and writes responses (Server::process_request); the connections are ours, so that limits hold
// whatever a client does:
//  - a bounded pool: `threads` workers and at most `queue` accepted connections waiting for one;
//    beyond that a connection gets a canned 503 at once and is closed;
//  - a deadline per request: its headers must arrive within timeout_ms of its first byte, and its
//    answer must be taken within timeout_ms (a client trickling bytes, slowloris, is cut off);
//  - keep-alive: at most 5 requests per connection, at most 2 s idle between them.
// Static files of the viewer are read into memory at startup (no request path ever reaches the
// file system). Every answer carries Access-Control-Allow-Origin: *.
#pragma once

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <string>

#include "tools/serve/api.h"

namespace smr::serve {

struct HttpOptions {
  std::string bind = "127.0.0.1";
  int port = 8080;  // 0: any free port
  unsigned threads = 8;
  std::size_t queue = 64;
  int timeout_ms = 10'000;
  std::string viewer_dir;  // empty: no viewer
  bool log = false;        // a line per request on stderr
};

class HttpServer {
 public:
  /// Reads the viewer's files; throws smr::Error for a bad viewer directory.
  HttpServer(Api& api, const HttpOptions& options);
  ~HttpServer();
  /// Binds and listens; returns the port (throws smr::Error naming the address on failure).
  int bind();
  /// Serves until stop() (from another thread or a signal handler's thread).
  void run();
  void stop();
  std::size_t viewer_files() const;

  class Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace smr::serve
