// Tests of the top-down renderer (smr/io/render.h): PNG structure and size, pixels decoded back
// with libpng equal render_image, shading and wireframe effects, options and errors.
#include "smr/io/render.h"

#include <png.h>

#include <cmath>
#include <cstring>

#include <gtest/gtest.h>

#include "smr/io/dem_reader.h"
#include "smr/io/synthetic.h"
#include "tests/io/io_test_helpers.h"
#include "tests/support/test_data.h"

namespace smr {
namespace {

using test::expect_error;
using test::TempDir;

/// A regular triangulation of a heightfield (2 triangles per cell), in world coordinates.
TriangleMesh grid_mesh(const Heightfield& h, int step = 1) {
  TriangleMesh m;
  const int cols = (h.width - 1) / step + 1, rows = (h.height - 1) / step + 1;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) m.positions.push_back(h.world(c * step, r * step));
  const auto id = [&](int c, int r) { return static_cast<std::uint32_t>(r * cols + c); };
  for (int r = 0; r + 1 < rows; ++r) {
    for (int c = 0; c + 1 < cols; ++c) {
      m.triangles.push_back({id(c, r), id(c + 1, r), id(c + 1, r + 1)});
      m.triangles.push_back({id(c, r), id(c + 1, r + 1), id(c, r + 1)});
    }
  }
  return m;
}

struct PngInfo {
  bool signature_ok = false;
  std::uint32_t width = 0, height = 0;
  int bit_depth = 0, colour_type = 0;
};

PngInfo png_info(const std::string& path) {
  const std::vector<std::uint8_t> b = test::read_bytes(path);
  PngInfo info;
  static const std::uint8_t kSig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (b.size() < 33) return info;
  info.signature_ok =
      std::memcmp(b.data(), kSig, 8) == 0 && std::memcmp(b.data() + 12, "IHDR", 4) == 0;
  const auto be32 = [&](std::size_t o) {
    return (std::uint32_t{b[o]} << 24) | (std::uint32_t{b[o + 1]} << 16) |
           (std::uint32_t{b[o + 2]} << 8) | std::uint32_t{b[o + 3]};
  };
  info.width = be32(16);
  info.height = be32(20);
  info.bit_depth = b[24];
  info.colour_type = b[25];
  return info;
}

std::vector<std::uint8_t> decode_png(const std::string& path, int& w, int& h) {
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  EXPECT_NE(png_image_begin_read_from_file(&image, path.c_str()), 0) << image.message;
  image.format = PNG_FORMAT_RGB;
  std::vector<std::uint8_t> rgb(PNG_IMAGE_SIZE(image));
  EXPECT_NE(png_image_finish_read(&image, nullptr, rgb.data(), 0, nullptr), 0) << image.message;
  w = static_cast<int>(image.width);
  h = static_cast<int>(image.height);
  return rgb;
}

TEST(Render, PngHasRequestedSizeAndDecodesToTheImage) {
  TempDir dir;
  Heightfield h = make_fbm(65, 33, 4, 500.0, 0, 0.5, 30.0);
  const TriangleMesh mesh = grid_mesh(h);
  RenderOptions opt;
  opt.width = 200;  // height 0: aspect of the xy bounds, 64 x 32 cells -> 100
  const std::string path = dir.file("fbm.png");
  render_png(path, mesh, opt);
  const PngInfo info = png_info(path);
  EXPECT_TRUE(info.signature_ok);
  EXPECT_EQ(info.width, 200u);
  EXPECT_EQ(info.height, 100u);
  EXPECT_EQ(info.bit_depth, 8);
  EXPECT_EQ(info.colour_type, PNG_COLOR_TYPE_RGB);
  int w = 0, hh = 0;
  const std::vector<std::uint8_t> decoded = decode_png(path, w, hh);
  const RgbImage img = render_image(mesh, opt);
  EXPECT_EQ(w, img.width);
  EXPECT_EQ(hh, img.height);
  EXPECT_EQ(decoded, img.rgb);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"fbm.png"});

  opt.height = 77;
  render_png(path, mesh, opt);
  EXPECT_EQ(png_info(path).height, 77u);
  EXPECT_EQ(png_info(path).width, 200u);
}

TEST(Render, GeographicScalesLongitudeByCosLatitude) {
  TriangleMesh m;
  // 1 x 1 degree at 60 N: shown twice as tall as wide.
  m.positions = {{10, 60, 0}, {11, 60, 0}, {11, 61, 100}, {10, 61, 50}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}};
  RenderOptions opt;
  opt.width = 100;
  EXPECT_EQ(render_image(m, opt).height, 100);
  opt.geographic = true;
  const int h = render_image(m, opt).height;
  EXPECT_NEAR(h, 100 / std::cos(60.5 * 3.14159265358979 / 180), 1.0);
}

TEST(Render, ShadingWireframeAndValueColouring) {
  // Two triangles: the western one slopes up to the east (faces west, lit from the NW), the
  // eastern one slopes down to the east (faces east, in shadow). Same mean elevation.
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {10, 0, 10}, {10, 10, 10}, {0, 10, 0}, {20, 0, 0}, {20, 10, 0}};
  m.triangles = {{0, 1, 2}, {0, 2, 3}, {1, 4, 5}, {1, 5, 2}};
  RenderOptions opt;
  opt.width = 204;
  opt.height = 104;
  opt.wireframe = false;
  const RgbImage img = render_image(m, opt);
  const auto pixel = [&](const RgbImage& im, int x, int y) {
    const std::size_t o = (static_cast<std::size_t>(y) * im.width + x) * 3;
    return im.rgb[o] + im.rgb[o + 1] + im.rgb[o + 2];
  };
  // The ramp colours differ between the halves only through elevation; both halves have
  // triangles with the same mean z (20/3 and 10/3 pairs), so compare matching triangles:
  // west lower triangle (0,1,2) mean 20/3 vs east upper triangle (1,5,2) mean 20/3.
  const int west = pixel(img, 80, 60);   // in triangle (0, 1, 2)
  const int east = pixel(img, 110, 40);  // in triangle (1, 5, 2)
  EXPECT_GT(west, east + 60) << "west-facing slope should be brighter under a NW sun";
  // Background outside the mesh stays light grey.
  EXPECT_EQ(pixel(img, 0, 0), 3 * 240);

  opt.wireframe = true;
  const RgbImage wire = render_image(m, opt);
  // The diagonal edge of the western cell passes through its centre (52, 52).
  EXPECT_LT(pixel(wire, 52, 52), pixel(img, 52, 52));
  EXPECT_EQ(pixel(wire, 80, 60), pixel(img, 80, 60));  // away from edges: unchanged

  // Colour by values: different triangle values give different colours on a flat mesh.
  TriangleMesh flat = m;
  for (Vec3& p : flat.positions) p.z = 0;
  flat.triangle_values = {0, 0, 1, 1};
  opt.wireframe = false;
  opt.colour_by_values = true;
  const RgbImage by_value = render_image(flat, opt);
  EXPECT_NE(pixel(by_value, 30, 52), pixel(by_value, 170, 52));
  opt.colour_by_values = false;
  const RgbImage by_height = render_image(flat, opt);
  EXPECT_EQ(pixel(by_height, 30, 52), pixel(by_height, 170, 52));
}

TEST(Render, RealDemRendersWithGeographicShading) {
  TempDir dir;
  const Heightfield h = read_dem(test::data_path("jacksboro_fault_dem.npz"));
  const TriangleMesh mesh = grid_mesh(h, 8);
  RenderOptions opt;
  opt.width = 256;
  opt.geographic = h.georef.geographic;
  const std::string path = dir.file("jacksboro.png");
  render_png(path, mesh, opt);
  const PngInfo info = png_info(path);
  EXPECT_TRUE(info.signature_ok);
  EXPECT_EQ(info.width, 256u);
  // 50 x 42 cells of 1/150 deg at ~36.6 N: aspect 42 / (50 cos 36.6 deg).
  EXPECT_NEAR(info.height, 256 * 42 / (50 * std::cos(36.59 * 3.14159265358979 / 180)), 1.0);
  // Hill-shading in metres gives a range of brightness (not all black, not flat).
  const RgbImage img = render_image(mesh, opt);
  int lo = 765, hi = 0;
  for (std::size_t i = 0; i < img.rgb.size(); i += 3) {
    const int v = img.rgb[i] + img.rgb[i + 1] + img.rgb[i + 2];
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  EXPECT_GT(hi - lo, 200);
}

TEST(Render, EmptyMeshAndErrors) {
  TempDir dir;
  RenderOptions opt;
  opt.width = 16;
  const RgbImage blank = render_image(TriangleMesh{}, opt);
  EXPECT_EQ(blank.width, 16);
  EXPECT_EQ(blank.height, 16);
  EXPECT_EQ(blank.rgb, std::vector<std::uint8_t>(16 * 16 * 3, 240));

  TriangleMesh bad;
  bad.positions = {{0, 0, 0}};
  bad.triangles = {{0, 0, 1}};
  expect_error([&] { (void)render_image(bad, opt); }, ErrorKind::kInvalidInput, {"vertex 1"});
  opt.width = 0;
  expect_error([&] { (void)render_image(TriangleMesh{}, opt); }, ErrorKind::kInvalidInput,
               {"image size"});
  opt.width = 16;
  expect_error([&] { render_png("/nonexistent-smrdb-dir/x.png", TriangleMesh{}, opt); },
               ErrorKind::kIo, {"/nonexistent-smrdb-dir/x.png"});
  EXPECT_TRUE(dir.entries().empty());
}

}  // namespace
}  // namespace smr
