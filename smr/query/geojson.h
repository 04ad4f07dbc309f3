// GeoJSON output (RFC 7946) for query answers: a FeatureCollection streamed feature by feature, so
// that a whole DEM's contours (millions of points) never sit in memory as one document.
//
// Coordinates are written as the database holds them, in the raster's own CRS as ingest recorded
// it (Georef), not reprojected to WGS 84. The CRS is recorded as GDAL's GeoJSON driver records it
// for such data, plus the WKT itself:
//  - "crs": {"type": "name", "properties": {"name": URN}} (the GeoJSON 2008 member GDAL writes)
//    when the WKT names an EPSG code at its root (WKT1 AUTHORITY["EPSG","n"], WKT2 ID["EPSG",n]):
//    "urn:ogc:def:crs:OGC:1.3:CRS84" for EPSG:4326 (x = longitude, as GDAL writes it), else
//    "urn:ogc:def:crs:EPSG::n". GDAL's OSR, which could also identify a WKT that names no code,
//    is not reachable from here (GDAL is a module smr/io loads for rasters only, gdal_module.h),
//    so such a CRS gets no "crs" member;
//  - "crs_wkt": the WKT, a foreign member (RFC 7946 6.1, ignored by GDAL and other readers), so
//    no CRS is lost, with or without an EPSG code;
//  - neither when the database records no CRS.
// Numbers are written in the shortest form that reads back as the same double, integral ones with
// a ".0" as GDAL writes them (so readers type the field as real).
#pragma once

#include <cstdint>
#include <ostream>
#include <span>
#include <string>
#include <string_view>
#include <variant>

#include "smr/core/geometry.h"
#include "smr/core/heightfield.h"

namespace smr::query {

/// A feature's property: a number, an integer, a flag or a string.
using PropertyValue = std::variant<double, std::int64_t, bool, std::string>;
struct Property {
  std::string_view name;
  PropertyValue value;
};

/// Writes one FeatureCollection to a stream, one feature per call. Not thread-safe.
class GeoJsonWriter {
 public:
  /// Writes the collection's opening: "name" (GDAL's layer name; omitted when empty) and the CRS
  /// members described above.
  GeoJsonWriter(std::ostream& out, const Georef& georef, std::string_view name = {});
  GeoJsonWriter(const GeoJsonWriter&) = delete;
  GeoJsonWriter& operator=(const GeoJsonWriter&) = delete;

  /// A LineString feature (at least 2 points; fewer is kInvalidInput).
  void line_string(std::span<const Vec2> points, std::span<const Property> properties);
  /// A Point feature.
  void point(const Vec2& p, std::span<const Property> properties);
  /// Closes the collection and flushes the stream; kIo when the stream failed at any point.
  /// Without it the output is not a complete document.
  void finish();
  std::uint64_t features() const { return features_; }

 private:
  void begin_feature(std::span<const Property> properties, std::string_view type);
  void end_feature();
  void coordinates(const Vec2& p);
  void number(double v);
  void string(std::string_view s);

  std::ostream& out_;
  std::uint64_t features_ = 0;
  bool finished_ = false;
};

/// The "crs" member's name for a WKT, as described above ("" when the WKT names no EPSG code).
std::string geojson_crs_name(std::string_view wkt);

}  // namespace smr::query
