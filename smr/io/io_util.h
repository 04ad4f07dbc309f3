// Internal helpers shared by smr/io's readers and writers (not part of the public API): the
// extension of a path, a printable excerpt of untrusted bytes for messages, and whole-file reads
// that name the path in their errors.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace smr::io_util {

/// The extension of `path` in lower case, with its dot (".ply"); empty when it has none.
std::string lower_extension(const std::string& path);

/// Printable excerpt of untrusted text for error messages: at most `max` bytes, each byte outside
/// printable ASCII written as \xNN, "..." appended when cut.
std::string excerpt(std::string_view s, std::size_t max = 40);

/// A missing path is kIo ("cannot open '<path>': no such file"), a directory kInvalidInput
/// ("cannot read '<path>': it is a directory, expected <expected>").
void check_is_file(const std::string& path, const char* expected);

/// The whole file at `path` (check_is_file first); kIo naming the path when it cannot be opened
/// or read.
std::vector<std::uint8_t> read_file_bytes(const std::string& path, const char* expected);

}  // namespace smr::io_util
