// Internal helpers shared by smr/io's readers and writers (smr/io/io_util.h).
#include "smr/io/io_util.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "base/error.h"

namespace smr::io_util {

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

std::string excerpt(std::string_view s, std::size_t max) {
  std::string out;
  for (std::size_t i = 0; i < s.size() && i < max; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02x", c);
      out += hex;
    }
  }
  if (s.size() > max) out += "...";
  return out;
}

void check_is_file(const std::string& path, const char* expected) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (!std::filesystem::exists(status)) throw_io("cannot open '" + path + "': no such file");
  if (std::filesystem::is_directory(status)) {
    throw_input("cannot read '" + path + "': it is a directory, expected " + expected);
  }
}

std::vector<std::uint8_t> read_file_bytes(const std::string& path, const char* expected) {
  check_is_file(path, expected);
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) throw_io("cannot open '" + path + "': " + std::strerror(errno));
  std::vector<std::uint8_t> bytes;
  std::error_code ec;
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (!ec && size < (std::uintmax_t{1} << 40)) bytes.reserve(static_cast<std::size_t>(size));
  std::uint8_t chunk[1 << 16];
  for (;;) {
    const std::size_t got = std::fread(chunk, 1, sizeof chunk, f);
    bytes.insert(bytes.end(), chunk, chunk + got);
    if (got < sizeof chunk) break;
  }
  const bool failed = std::ferror(f) != 0;
  const int err = errno;
  std::fclose(f);
  if (failed) throw_io("cannot read '" + path + "': " + std::strerror(err));
  return bytes;
}

}  // namespace smr::io_util
