// Request parameters of smrdb serve, range-checked: every failure is an HttpError (400) whose
// message names the parameter and what was expected. No socket here (api.h, http.h).
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "smr/core/geometry.h"

namespace smr::serve {

/// An answer other than 200: the status and the message of its JSON body {"error": message}.
class HttpError : public std::runtime_error {
 public:
  HttpError(int status, const std::string& message)
      : std::runtime_error(message), status_(status) {}
  int status() const { return status_; }

 private:
  int status_;
};

[[noreturn]] void fail(int status, const std::string& message);

/// The query string's parameters (each name once), checked as they are read.
class Params {
 public:
  /// From the decoded name/value pairs as they came; a name given twice is a 400.
  explicit Params(const std::vector<std::pair<std::string, std::string>>& pairs);

  bool has(const std::string& name) const { return values_.count(name) != 0; }
  /// A finite number in [lo, hi] (lo excluded when `lo_open`); absent: `fallback`, or a 400 when
  /// there is none.
  double number(const std::string& name, double lo, double hi,
                std::optional<double> fallback = std::nullopt, bool lo_open = false) const;
  /// An integer in [lo, hi]; absent: `fallback`, or a 400 when there is none.
  std::int64_t integer(const std::string& name, std::int64_t lo, std::int64_t hi,
                       std::optional<std::int64_t> fallback = std::nullopt) const;
  /// `count` comma-separated finite numbers, each of magnitude at most 1e15 (required).
  std::vector<double> numbers(const std::string& name, std::size_t count,
                              const std::string& form) const;
  Vec3 vec3(const std::string& name) const;
  Vec2 vec2(const std::string& name) const;
  /// "WxH", both in [1, 8192]; absent: `fallback`.
  std::pair<int, int> viewport(const std::string& name, std::pair<int, int> fallback) const;
  /// Names given that are not in `known` (a 400 naming the first).
  void only(const std::vector<std::string>& known) const;

 private:
  const std::string* raw(const std::string& name) const;
  std::map<std::string, std::string> values_;
};

/// A decimal number that is the whole of `text` (no spaces, no hex, finite); nullopt otherwise.
std::optional<double> parse_double(const std::string& text);

}  // namespace smr::serve
