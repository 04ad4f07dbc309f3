// smrdb serve: databases over HTTP (tools/serve/, docs/serve.md).
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/io/gltf_writer.h"
#include "tools/commands.h"
#include "tools/serve/api.h"
#include "tools/serve/http.h"

namespace smr::tools {

namespace {

// The GLB `smrdb extract -o x.glb` writes (extract_cmd.cpp, write_output), as bytes: written to a
// scratch file by the same writer and read back.
std::string glb_bytes(const Database& db, const TriangleMesh& mesh, const nlohmann::json& extras) {
  static std::atomic<std::uint64_t> counter{0};
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() /
      ("smrdb-serve-" + std::to_string(::getpid()) + "-" + std::to_string(counter++) + ".glb");
  struct Remove {
    std::filesystem::path p;
    ~Remove() {
      std::error_code ec;
      std::filesystem::remove(p, ec);
    }
  } remove{path};
  write_gltf(path.string(), mesh, gltf_options(db, "", extras));
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  if (!in) throw_io("serve: cannot read back " + path.string());
  return bytes.str();
}

std::string default_viewer() {
#ifdef SMRDB_SOURCE_DIR
  const std::string dir = std::string(SMRDB_SOURCE_DIR) + "/tools/viewer/dist";
  std::error_code ec;
  if (std::filesystem::exists(dir + "/index.html", ec)) return dir;
#endif
  return {};
}

}  // namespace

void ServeArgs::add_to(CLI::App& app) {
  app.add_option("databases", databases, "NAME=PATH (or PATH: named by its file stem)")->required();
  app.add_option("--port", port, "TCP port (0: any free one, printed)")->capture_default_str();
  app.add_option("--bind", bind, "Address to listen on")->capture_default_str();
  app.add_option("--threads", threads, "Request threads")->capture_default_str();
  app.add_option("--queue", queue, "Connections waiting for a thread before 503")
      ->capture_default_str();
  app.add_option("--cache-mb", cache_mb, "Page cache of each database, MiB")->capture_default_str();
  app.add_option("--max-sessions", max_sessions, "Open progressive sessions (then 503)")
      ->capture_default_str();
  app.add_option("--session-idle-s", session_idle_s, "A session idle this long is dropped")
      ->capture_default_str();
  app.add_option("--max-triangles", max_triangles, "Most triangles in one answer")
      ->capture_default_str();
  app.add_option("--tile-cache-mb", tile_cache_mb, "Encoded tiles kept in memory, MiB (0: none)")
      ->capture_default_str();
  app.add_option("--timeout-ms", timeout_ms,
                 "Socket timeout, request-header deadline and compute budget, ms")
      ->capture_default_str();
  app.add_option("--viewer", viewer,
                 "Directory of the browser viewer, served at / (default: tools/viewer/dist of "
                 "the source tree when built; 'none': no viewer)");
  app.add_flag("--log", log, "A line per request on stderr");
}

int cmd_serve(const ServeArgs& a) {
  if (a.port < 0 || a.port > 65535) throw_input("--port must be in [0, 65535]");
  if (a.threads < 1 || a.threads > 1024) throw_input("--threads must be in [1, 1024]");
  if (a.queue > 100000) throw_input("--queue must be in [0, 100000]");
  if (a.cache_mb < 1 || a.cache_mb > (std::uint64_t{1} << 20))
    throw_input("--cache-mb must be in [1, 1048576]");
  if (a.max_sessions < 1 || a.max_sessions > 100000)
    throw_input("--max-sessions must be in [1, 100000]");
  if (a.max_triangles < 1 || a.max_triangles > (std::uint64_t{1} << 32))
    throw_input("--max-triangles must be in [1, 2^32]");
  if (a.session_idle_s < 1 || a.session_idle_s > 86400)
    throw_input("--session-idle-s must be in [1, 86400]");
  if (a.tile_cache_mb > (std::uint64_t{1} << 20))
    throw_input("--tile-cache-mb must be in [0, 1048576]");
  if (a.timeout_ms < 100 || a.timeout_ms > 3'600'000)
    throw_input("--timeout-ms must be in [100, 3600000]");
  std::vector<std::pair<std::string, std::string>> named;
  for (const std::string& d : a.databases) {
    const std::size_t eq = d.find('=');
    if (eq == std::string::npos)
      named.emplace_back(serve::default_name(d), d);
    else
      named.emplace_back(d.substr(0, eq), d.substr(eq + 1));
  }
  // SIGINT and SIGTERM stop the server from a thread of their own.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  std::signal(SIGPIPE, SIG_IGN);

  serve::ApiOptions ao;
  ao.max_triangles = a.max_triangles;
  ao.timeout_ms = double(a.timeout_ms);
  ao.max_sessions = a.max_sessions;
  ao.session_idle = std::chrono::seconds(a.session_idle_s);
  ao.tile_cache_bytes = std::size_t(a.tile_cache_mb) << 20;
  serve::Api api(named, std::size_t(a.cache_mb) << 20, ao, glb_bytes);
  serve::HttpOptions ho;
  ho.bind = a.bind;
  ho.port = a.port;
  ho.threads = a.threads;
  ho.queue = a.queue;
  ho.timeout_ms = a.timeout_ms;
  ho.viewer_dir = a.viewer == "none" ? "" : a.viewer.empty() ? default_viewer() : a.viewer;
  ho.log = a.log;
  serve::HttpServer server(api, ho);
  const int port = server.bind();
  const std::string host = a.bind.find(':') != std::string::npos ? "[" + a.bind + "]" : a.bind;
  std::printf("smrdb serve: listening on http://%s:%d/\n", host.c_str(), port);
  if (!ho.viewer_dir.empty())
    std::printf("smrdb serve: viewer (%zu files from %s) at http://%s:%d/index.html\n",
                server.viewer_files(), ho.viewer_dir.c_str(), host.c_str(), port);
  std::fflush(stdout);
  std::thread waiter([&] {
    int sig = 0;
    sigwait(&signals, &sig);
    server.stop();
  });
  server.run();
  pthread_kill(waiter.native_handle(), SIGTERM);  // if run() ended otherwise
  waiter.join();
  return 0;
}

}  // namespace smr::tools
