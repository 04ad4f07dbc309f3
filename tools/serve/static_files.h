// The viewer's files, read into memory once at startup: a request path is looked up in this map,
// never handed to the file system.
#pragma once

#include <map>
#include <string>

namespace smr::serve {

struct StaticFile {
  std::string bytes;
  std::string type;  // Content-Type
};

/// URL path ("/index.html", "/assets/x.js") -> file.
using StaticFiles = std::map<std::string, StaticFile>;

/// Every regular file under `dir` (symbolic links are not followed, hidden names skipped), at
/// most 4096 files and 256 MiB; throws smr::Error naming the directory when it is not one or is
/// too big.
StaticFiles read_static_files(const std::string& dir);
/// The file at `path`, or nullptr; "/dir/" means "/dir/index.html".
const StaticFile* find_static_file(const StaticFiles& files, const std::string& path);
/// The Content-Type for a file name's extension.
std::string content_type_of(const std::string& name);

}  // namespace smr::serve
