// A top-down picture of a 2.5-D mesh: how users see selective refinement (small triangles where
// the mesh was refined). Orthographic view from +z, north up; each triangle is filled with a
// hypsometric colour ramp by its mean elevation (blues below 0 when the mesh spans sea level),
// modulated by Lambert hill-shading from the north-west (sun azimuth 315 deg, altitude 45 deg)
// computed from the triangle normal in metric units; triangle edges are drawn as thin dark lines.
// Painter's algorithm without a z-buffer: a 2.5-D mesh does not overlap itself seen from above.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "smr/core/mesh.h"

namespace smr {

struct RenderOptions {
  int width = 1024;  // pixels, 1..16384
  int height = 0;    // pixels, 0 = keep the aspect of the mesh's xy bounds (capped at 16384)
  bool wireframe = true;
  double z_exaggeration = 1.0;
  /// When true, x and y are degrees of longitude and latitude: x is scaled by the cosine of the
  /// mean latitude for display, and degrees are converted to metres (6371008.8 m Earth radius)
  /// for the hill-shading.
  bool geographic = false;
  /// Colour by TriangleMesh::triangle_values (low = purple .. high = yellow, viridis-like)
  /// instead of elevation; ignored when the mesh has no triangle values.
  bool colour_by_values = false;
};

/// An 8-bit RGB image, row 0 at the top (north), 3 bytes per pixel.
struct RgbImage {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;
};

/// Renders `mesh` into an image (the work behind render_png). The mesh's xy bounds are fitted into
/// the image with a 2-pixel margin, preserving the aspect ratio. An empty mesh gives a blank image
/// (height = width when height is 0). Throws kInvalidInput for bad options or triangle indices.
RgbImage render_image(const TriangleMesh& mesh, const RenderOptions& options);

/// Renders `mesh` and writes it as a PNG (via a temporary file renamed into place: a failed write
/// leaves no partial file; kIo naming the path).
void render_png(const std::string& path, const TriangleMesh& mesh, const RenderOptions& options);

}  // namespace smr
