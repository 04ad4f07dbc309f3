// The viewer's files for smrdb serve (static_files.h).
#include "tools/serve/static_files.h"

#include <filesystem>
#include <fstream>
#include <sstream>

#include "base/error.h"

namespace smr::serve {

namespace fs = std::filesystem;

std::string content_type_of(const std::string& name) {
  static const std::map<std::string, std::string> types = {{".html", "text/html; charset=utf-8"},
                                                           {".js", "application/javascript"},
                                                           {".mjs", "application/javascript"},
                                                           {".css", "text/css"},
                                                           {".json", "application/json"},
                                                           {".map", "application/json"},
                                                           {".svg", "image/svg+xml"},
                                                           {".png", "image/png"},
                                                           {".jpg", "image/jpeg"},
                                                           {".ico", "image/x-icon"},
                                                           {".wasm", "application/wasm"},
                                                           {".txt", "text/plain; charset=utf-8"},
                                                           {".glb", "model/gltf-binary"},
                                                           {".woff2", "font/woff2"}};
  const std::string ext = fs::path(name).extension().string();
  const auto it = types.find(ext);
  return it == types.end() ? "application/octet-stream" : it->second;
}

StaticFiles read_static_files(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw_input("serve: --viewer " + dir + " is not a directory");
  StaticFiles files;
  std::uint64_t total = 0;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    const std::string leaf = it->path().filename().string();
    if (!leaf.empty() && leaf[0] == '.') {
      if (it->is_directory()) it.disable_recursion_pending();
      continue;
    }
    if (it->is_symlink() || !it->is_regular_file()) continue;
    std::ifstream in(it->path(), std::ios::binary);
    std::ostringstream bytes;
    bytes << in.rdbuf();
    if (!in) throw_io("serve: cannot read " + it->path().string());
    std::string url = fs::relative(it->path(), dir).generic_string();
    url.insert(url.begin(), '/');
    total += bytes.str().size();
    if (files.size() >= 4096 || total > (std::uint64_t{256} << 20))
      throw_input("serve: --viewer " + dir + " holds more than 4096 files or 256 MiB");
    files[url] = {bytes.str(), content_type_of(url)};
  }
  if (ec) throw_io("serve: cannot list --viewer " + dir + ": " + ec.message());
  return files;
}

const StaticFile* find_static_file(const StaticFiles& files, const std::string& path) {
  std::string key = path;
  if (!key.empty() && key.back() == '/') key += "index.html";
  const auto it = files.find(key);
  return it == files.end() ? nullptr : &it->second;
}

}  // namespace smr::serve
