// Parameter parsing for smrdb serve (params.h).
#include "tools/serve/params.h"

#include <charconv>
#include <cmath>
#include <limits>
#include <sstream>

namespace smr::serve {

namespace {

constexpr std::size_t kMaxValue = 256;  // characters of one parameter's value
constexpr double kMaxCoordinate = 1e15;

std::string quoted(const std::string& s) {
  std::string out = "'";
  for (const char c : s.substr(0, 64)) out += (c >= 32 && c < 127 && c != '\'') ? c : '?';
  if (s.size() > 64) out += "...";
  return out + "'";
}

std::string range_text(double lo, double hi, bool lo_open) {
  std::ostringstream os;
  os << (lo_open ? "(" : "[") << lo << ", " << hi << "]";
  return os.str();
}

}  // namespace

void fail(int status, const std::string& message) {
  throw HttpError(status, message);
}

std::optional<double> parse_double(const std::string& text) {
  if (text.empty() || text.size() > kMaxValue) return std::nullopt;
  for (const char c : text)
    if (!((c >= '0' && c <= '9') || c == '.' || c == '-' || c == '+' || c == 'e' || c == 'E'))
      return std::nullopt;  // rejects nan, inf, hex, spaces
  const char* first = text.data() + (text[0] == '+' ? 1 : 0);
  double v = 0.0;
  const auto [end, ec] = std::from_chars(first, text.data() + text.size(), v);
  if (ec != std::errc() || end != text.data() + text.size() || !std::isfinite(v))
    return std::nullopt;
  return v;
}

Params::Params(const std::vector<std::pair<std::string, std::string>>& pairs) {
  for (const auto& [name, value] : pairs) {
    if (name.size() > 64) fail(400, "parameter name " + quoted(name) + " is too long");
    if (value.size() > kMaxValue)
      fail(400, "parameter '" + name + "' is too long (at most 256 characters)");
    if (!values_.emplace(name, value).second)
      fail(400, "parameter '" + name + "' is given more than once");
  }
}

const std::string* Params::raw(const std::string& name) const {
  const auto it = values_.find(name);
  return it == values_.end() ? nullptr : &it->second;
}

double Params::number(const std::string& name, double lo, double hi, std::optional<double> fallback,
                      bool lo_open) const {
  const std::string* text = raw(name);
  if (text == nullptr) {
    if (fallback) return *fallback;
    fail(400, "parameter '" + name + "' is missing: expected a number in " +
                  range_text(lo, hi, lo_open));
  }
  const std::optional<double> v = parse_double(*text);
  if (!v || *v < lo || *v > hi || (lo_open && *v == lo))
    fail(400, "parameter '" + name + "' must be a finite number in " + range_text(lo, hi, lo_open) +
                  ", got " + quoted(*text));
  return *v;
}

std::int64_t Params::integer(const std::string& name, std::int64_t lo, std::int64_t hi,
                             std::optional<std::int64_t> fallback) const {
  const std::string* text = raw(name);
  if (text == nullptr) {
    if (fallback) return *fallback;
    fail(400, "parameter '" + name + "' is missing: expected an integer in [" + std::to_string(lo) +
                  ", " + std::to_string(hi) + "]");
  }
  std::int64_t v = 0;
  const auto [end, ec] = std::from_chars(text->data(), text->data() + text->size(), v);
  if (text->empty() || ec != std::errc() || end != text->data() + text->size() || v < lo || v > hi)
    fail(400, "parameter '" + name + "' must be an integer in [" + std::to_string(lo) + ", " +
                  std::to_string(hi) + "], got " + quoted(*text));
  return v;
}

std::vector<double> Params::numbers(const std::string& name, std::size_t count,
                                    const std::string& form) const {
  const std::string* text = raw(name);
  if (text == nullptr) fail(400, "parameter '" + name + "' is missing: expected " + form);
  std::vector<double> out;
  std::size_t start = 0;
  while (out.size() <= count) {
    const std::size_t comma = text->find(',', start);
    const std::string part =
        text->substr(start, comma == std::string::npos ? comma : comma - start);
    const std::optional<double> v = parse_double(part);
    if (!v || std::abs(*v) > kMaxCoordinate)
      fail(400, "parameter '" + name + "' must be " + form +
                    " (finite numbers of magnitude <= " + "1e15), got " + quoted(*text));
    out.push_back(*v);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  if (out.size() != count)
    fail(400, "parameter '" + name + "' must be " + form + ", got " + quoted(*text));
  return out;
}

Vec3 Params::vec3(const std::string& name) const {
  const auto v = numbers(name, 3, "x,y,z");
  return {v[0], v[1], v[2]};
}

Vec2 Params::vec2(const std::string& name) const {
  const auto v = numbers(name, 2, "x,y");
  return {v[0], v[1]};
}

std::pair<int, int> Params::viewport(const std::string& name, std::pair<int, int> fallback) const {
  const std::string* text = raw(name);
  if (text == nullptr) return fallback;
  const std::size_t x = text->find('x');
  int w = 0, h = 0;
  const char* b = text->data();
  const char* e = b + text->size();
  const bool ok = x != std::string::npos && std::from_chars(b, b + x, w).ptr == b + x &&
                  std::from_chars(b + x + 1, e, h).ptr == e && x > 0 && x + 1 < text->size();
  if (!ok || w < 1 || h < 1 || w > 8192 || h > 8192)
    fail(400,
         "parameter '" + name + "' must be WxH with W and H in [1, 8192], got " + quoted(*text));
  return {w, h};
}

void Params::only(const std::vector<std::string>& known) const {
  for (const auto& [name, value] : values_) {
    bool found = false;
    for (const auto& k : known) found = found || k == name;
    if (!found) {
      std::string list;
      for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
      fail(400, "unknown parameter " + quoted(name) + " (expected: " + list + ")");
    }
  }
}

}  // namespace smr::serve
