// Tokenizing and number parsing shared by the mesh readers (internal to smr/io/mesh): the
// whitespace-separated token scanner of the text formats (PLY ascii, OBJ, OFF, ASCII STL), strict
// number parsing of one token, and the number formatting of messages.
#pragma once

#include <charconv>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <system_error>

#include "smr/core/mesh.h"
#include "smr/io/io_util.h"

namespace smr::mesh_io {

using io_util::excerpt;

/// A whole token as a double ("+" allowed; out-of-range values become +-HUGE_VAL or the nearest
/// denormal / zero, like strtod). False when the token is not exactly one number.
inline bool parse_double(std::string_view tok, double& out) {
  if (tok.size() > 1 && tok[0] == '+') tok.remove_prefix(1);
  if (tok.empty()) return false;
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), out);
  if (r.ptr != tok.data() + tok.size()) return false;
  if (r.ec == std::errc::result_out_of_range) {
    // from_chars leaves `out` alone on overflow and underflow; strtod (on a copy, so it cannot
    // read past the token) gives +-HUGE_VAL or the nearest denormal / zero.
    const std::string copy(tok);
    out = std::strtod(copy.c_str(), nullptr);
    return true;
  }
  return r.ec == std::errc();
}

/// A whole token as a signed / unsigned integer ("+" allowed; "-" never for unsigned).
inline bool parse_int(std::string_view tok, std::int64_t& out) {
  if (tok.size() > 1 && tok[0] == '+') tok.remove_prefix(1);
  if (tok.empty()) return false;
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), out);
  return r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

inline bool parse_uint(std::string_view tok, std::uint64_t& out) {
  if (tok.size() > 1 && tok[0] == '+') tok.remove_prefix(1);
  if (tok.empty() || tok[0] == '-') return false;
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), out);
  return r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

/// Numbers and positions as messages print them (shortest round-trip form for doubles).
std::string num(double v);
std::string num(std::uint64_t v);
std::string pos_text(const Vec3& p);
/// "line <n>".
std::string at_line(std::size_t line);

/// Scans text token by token, counting lines (1-based). Blanks are space, \t, \r, \v and \f;
/// with `hash_comments`, '#' starts a comment to the end of the line; with `continuations`, a
/// backslash at the end of a line (before (\r) \n) joins it to the next (OBJ).
class Text {
 public:
  Text(std::string_view s, bool hash_comments, bool continuations = false)
      : p_(s.data()),
        end_(s.data() + s.size()),
        comments_(hash_comments),
        continuations_(continuations) {}

  bool at_end() const { return p_ == end_; }
  std::size_t line() const { return line_; }
  std::size_t remaining() const { return static_cast<std::size_t>(end_ - p_); }

  /// Skips blanks within the line (and comments up to the newline).
  void skip_blanks();
  /// Skips blanks, comments and newlines.
  void skip_space();
  bool at_eol() {
    skip_blanks();
    return p_ == end_ || *p_ == '\n';
  }
  /// Moves to the start of the next line.
  void skip_line();
  /// The next token within the current line; empty at the end of the line.
  std::string_view token_in_line() {
    skip_blanks();
    return raw_token();
  }
  /// The next token, on this line or a later one; empty at the end of the input.
  std::string_view token() {
    skip_space();
    return raw_token();
  }
  /// The rest of the current line (for names after `solid`).
  void rest_of_line() { skip_line(); }

 private:
  bool continues() const;  // at a backslash: is it followed by (\r) \n ?
  std::string_view raw_token();

  const char* p_;
  const char* end_;
  bool comments_;
  bool continuations_;
  std::size_t line_ = 1;
};

inline void Text::skip_blanks() {
  while (p_ != end_) {
    const char c = *p_;
    if (c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f') {
      ++p_;
    } else if (comments_ && c == '#') {
      while (p_ != end_ && *p_ != '\n') ++p_;
    } else if (continuations_ && c == '\\' && continues()) {
      while (*p_ != '\n') ++p_;
      ++p_;
      ++line_;
    } else {
      break;
    }
  }
}

inline void Text::skip_space() {
  for (;;) {
    skip_blanks();
    if (p_ != end_ && *p_ == '\n') {
      ++p_;
      ++line_;
    } else {
      return;
    }
  }
}

inline void Text::skip_line() {
  while (p_ != end_ && *p_ != '\n') {
    if (continuations_ && *p_ == '\\' && continues()) {
      while (*p_ != '\n') ++p_;
      ++line_;
    }
    ++p_;
  }
  if (p_ != end_) {
    ++p_;
    ++line_;
  }
}

inline bool Text::continues() const {
  const char* q = p_ + 1;
  while (q != end_ && *q == '\r') ++q;
  return q != end_ && *q == '\n';
}

inline std::string_view Text::raw_token() {
  const char* b = p_;
  while (p_ != end_) {
    const char c = *p_;
    if (c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f') break;
    if (comments_ && c == '#') break;
    ++p_;
  }
  return {b, static_cast<std::size_t>(p_ - b)};
}

}  // namespace smr::mesh_io
