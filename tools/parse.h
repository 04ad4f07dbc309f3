// Parsing what the user typed, for the commands (each failure is kInvalidInput naming the flag).
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace smr::tools {

/// "256M", "2G", "1.5G", "512K" or a plain number of bytes (binary units: M = 2^20).
std::uint64_t parse_bytes(const std::string& text, const std::string& option);

/// `count` comma-separated finite numbers (0: one or more); `form` names them in the message
/// ("x,y,z").
std::vector<double> parse_numbers(const std::string& text, std::size_t count,
                                  const std::string& option, const std::string& form);

/// "WxH" (e.g. 1920x1080): width and height in pixels (range checks are Camera::validate's).
std::pair<int, int> parse_viewport(const std::string& text, const std::string& option);

/// The extension of `path`, lower case, with its dot (".tif").
std::string extension_of(const std::string& path);

}  // namespace smr::tools
