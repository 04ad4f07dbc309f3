// Streaming GeoJSON writer (geojson.h; RFC 7946).
#include "smr/query/geojson.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <optional>
#include <utility>

#include "base/error.h"

namespace smr::query {

namespace {

bool same_word(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::toupper(static_cast<unsigned char>(a[i])) !=
        std::toupper(static_cast<unsigned char>(b[i])))
      return false;
  }
  return true;
}

// The keyword ending just before position `end` of `wkt` (letters, digits, underscores).
std::string_view keyword_before(std::string_view wkt, std::size_t end) {
  std::size_t begin = end;
  while (begin > 0 &&
         (std::isalnum(static_cast<unsigned char>(wkt[begin - 1])) != 0 || wkt[begin - 1] == '_'))
    --begin;
  return wkt.substr(begin, end - begin);
}

// One argument of a WKT node starting at `i` (after blanks): a quoted string or a bare token.
std::string_view argument_at(std::string_view wkt, std::size_t& i) {
  while (i < wkt.size() && (std::isspace(static_cast<unsigned char>(wkt[i])) != 0 || wkt[i] == ','))
    ++i;
  if (i < wkt.size() && wkt[i] == '"') {
    const std::size_t close = wkt.find('"', i + 1);
    if (close == std::string_view::npos) return {};
    const std::string_view s = wkt.substr(i + 1, close - i - 1);
    i = close + 1;
    return s;
  }
  const std::size_t begin = i;
  while (i < wkt.size() && wkt[i] != ',' && wkt[i] != ']' && wkt[i] != ')') ++i;
  return wkt.substr(begin, i - begin);
}

// (authority, code) of the last AUTHORITY[...] (WKT1) or ID[...] (WKT2) child of the root node.
std::optional<std::pair<std::string_view, std::string_view>> root_authority(std::string_view wkt) {
  std::optional<std::pair<std::string_view, std::string_view>> found;
  int depth = 0;
  bool quoted = false;
  for (std::size_t i = 0; i < wkt.size(); ++i) {
    const char c = wkt[i];
    if (c == '"') quoted = !quoted;  // a doubled quote inside a string toggles twice
    if (quoted || c == '"') continue;
    if (c == ']' || c == ')') --depth;
    if (c != '[' && c != '(') continue;
    const std::string_view word = keyword_before(wkt, i);
    if (depth++ == 1 && (same_word(word, "AUTHORITY") || same_word(word, "ID"))) {
      std::size_t j = i + 1;
      const std::string_view name = argument_at(wkt, j);
      const std::string_view code = argument_at(wkt, j);
      found = std::pair{name, code};
    }
  }
  return found;
}

}  // namespace

std::string geojson_crs_name(std::string_view wkt) {
  const auto authority = root_authority(wkt);
  if (!authority || !same_word(authority->first, "EPSG") || authority->second.empty()) return {};
  if (authority->second == "4326") return "urn:ogc:def:crs:OGC:1.3:CRS84";
  return "urn:ogc:def:crs:EPSG::" + std::string(authority->second);
}

GeoJsonWriter::GeoJsonWriter(std::ostream& out, const Georef& georef, std::string_view name)
    : out_(out) {
  out_ << "{\n\"type\": \"FeatureCollection\",\n";
  if (!name.empty()) {
    out_ << "\"name\": ";
    string(name);
    out_ << ",\n";
  }
  if (const std::string crs = geojson_crs_name(georef.crs_wkt); !crs.empty()) {
    out_ << "\"crs\": {\"type\": \"name\", \"properties\": {\"name\": ";
    string(crs);
    out_ << "}},\n";
  }
  if (!georef.crs_wkt.empty()) {
    out_ << "\"crs_wkt\": ";
    string(georef.crs_wkt);
    out_ << ",\n";
  }
  out_ << "\"features\": [";
}

void GeoJsonWriter::line_string(std::span<const Vec2> points,
                                std::span<const Property> properties) {
  if (points.size() < 2)
    throw Error(ErrorKind::kInvalidInput, "GeoJSON: a LineString needs at least 2 points, got " +
                                              std::to_string(points.size()));
  begin_feature(properties, "LineString");
  out_ << '[';
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (i > 0) out_ << ',';
    coordinates(points[i]);
  }
  out_ << ']';
  end_feature();
}

void GeoJsonWriter::point(const Vec2& p, std::span<const Property> properties) {
  begin_feature(properties, "Point");
  coordinates(p);
  end_feature();
}

void GeoJsonWriter::finish() {
  if (!finished_) {
    out_ << (features_ == 0 ? "]\n}\n" : "\n]\n}\n");
    out_.flush();
    finished_ = true;
  }
  if (!out_) throw Error(ErrorKind::kIo, "GeoJSON: writing the output failed");
}

void GeoJsonWriter::begin_feature(std::span<const Property> properties, std::string_view type) {
  if (finished_) throw Error(ErrorKind::kInternal, "GeoJSON: a feature after finish()");
  out_ << (features_++ == 0 ? "\n" : ",\n") << "{\"type\": \"Feature\", \"properties\": {";
  for (std::size_t i = 0; i < properties.size(); ++i) {
    if (i > 0) out_ << ", ";
    string(properties[i].name);
    out_ << ": ";
    std::visit(
        [this](const auto& v) {
          using T = std::decay_t<decltype(v)>;
          if constexpr (std::is_same_v<T, double>) {
            number(v);
          } else if constexpr (std::is_same_v<T, bool>) {
            out_ << (v ? "true" : "false");
          } else if constexpr (std::is_same_v<T, std::string>) {
            string(v);
          } else {
            out_ << v;
          }
        },
        properties[i].value);
  }
  out_ << "}, \"geometry\": {\"type\": \"" << type << "\", \"coordinates\": ";
}

void GeoJsonWriter::end_feature() {
  out_ << "}}";
}

void GeoJsonWriter::coordinates(const Vec2& p) {
  out_ << '[';
  number(p.x);
  out_ << ',';
  number(p.y);
  out_ << ']';
}

void GeoJsonWriter::number(double v) {
  if (!std::isfinite(v)) {  // JSON has no NaN or infinity
    out_ << "null";
    return;
  }
  std::array<char, 32> buf{};
  std::to_chars_result r = std::to_chars(buf.data(), buf.data() + buf.size(), v);
  // An integral value keeps a ".0", as GDAL writes it, so readers type the field as real.
  if (std::find_if(buf.data(), r.ptr, [](char c) { return c == '.' || c == 'e'; }) == r.ptr) {
    *r.ptr++ = '.';
    *r.ptr++ = '0';
  }
  out_.write(buf.data(), r.ptr - buf.data());
}

void GeoJsonWriter::string(std::string_view s) {
  out_ << '"';
  for (const char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out_ << '\\' << c;
    } else if (c == '\n') {
      out_ << "\\n";
    } else if (u < 0x20) {
      constexpr char kHex[] = "0123456789abcdef";
      out_ << "\\u00" << kHex[u >> 4] << kHex[u & 15];
    } else {
      out_ << c;
    }
  }
  out_ << '"';
}

}  // namespace smr::query
