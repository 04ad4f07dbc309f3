// Top-down hill-shaded rendering of a 2.5-D mesh and PNG output through libpng's simplified API
// (the one place smrdb talks to libpng). Lambert's cosine law for the shading (as in Horn,
// "Hill shading and the reflectance map", Proc. IEEE 69(1), 1981), hypsometric tints, triangles
// filled by edge functions (Pineda, "A parallel algorithm for polygon rasterization",
// SIGGRAPH 1988). The steps: check the input, fit the view, then per triangle colour, shade and
// fill; the wireframe last.
#include "smr/io/render.h"

#include <png.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>

#include <glm/geometric.hpp>

#include "base/error.h"
#include "smr/io/mesh_writer.h"

namespace smr {

namespace {

constexpr int kMaxSide = 16384;
constexpr double kPi = 3.14159265358979323846;
constexpr double kMetresPerDegree = 6371008.8 * kPi / 180.0;

using Rgb = std::array<double, 3>;

struct Stop {
  double t;
  Rgb c;
};

Rgb ramp(const Stop* stops, int n, double t) {
  t = std::clamp(t, 0.0, 1.0);
  for (int i = 1; i < n; ++i) {
    if (t <= stops[i].t) {
      const double u = (t - stops[i - 1].t) / (stops[i].t - stops[i - 1].t);
      Rgb c;
      for (int k = 0; k < 3; ++k)
        c[k] = stops[i - 1].c[k] + u * (stops[i].c[k] - stops[i - 1].c[k]);
      return c;
    }
  }
  return stops[n - 1].c;
}

constexpr Stop kLand[] = {{0.00, {26, 102, 46}},  {0.20, {94, 160, 72}},   {0.40, {214, 200, 120}},
                          {0.60, {170, 120, 70}}, {0.80, {140, 110, 100}}, {1.00, {250, 250, 250}}};
constexpr Stop kSea[] = {{0.0, {8, 40, 110}}, {1.0, {120, 180, 230}}};
constexpr Stop kValues[] = {{0.00, {68, 1, 84}},
                            {0.25, {59, 82, 139}},
                            {0.50, {33, 145, 140}},
                            {0.75, {94, 201, 98}},
                            {1.00, {253, 231, 37}}};

bool finite(const Vec3& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

std::uint8_t to_byte(double v) {
  return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0, 255.0)));
}

// Checks the options and that every triangle index is in range.
void check_input(const TriangleMesh& mesh, const RenderOptions& options) {
  if (options.width < 1 || options.width > kMaxSide || options.height < 0 ||
      options.height > kMaxSide) {
    throw_input("render: image size " + std::to_string(options.width) + " x " +
                std::to_string(options.height) + " is invalid; expected a width in 1.." +
                std::to_string(kMaxSide) + " and a height in 0.." + std::to_string(kMaxSide));
  }
  if (!std::isfinite(options.z_exaggeration)) {
    throw_input("render: z exaggeration must be a finite number");
  }
  const std::size_t nv = mesh.positions.size();
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    for (std::uint32_t v : mesh.triangles[t]) {
      if (v >= nv) {
        throw_input("render: triangle " + std::to_string(t) + " references vertex " +
                    std::to_string(v) + " but the mesh has " + std::to_string(nv) + " vertices");
      }
    }
  }
}

// Bounds of the finite vertices that triangles use (empty when there are none).
Box3 used_bounds(const TriangleMesh& mesh) {
  Box3 b;
  for (const auto& tri : mesh.triangles) {
    for (std::uint32_t v : tri) {
      if (finite(mesh.positions[v])) b.add(mesh.positions[v]);
    }
  }
  return b;
}

// World -> pixel: centred, aspect-preserving, 2-pixel margin (pixel centres at +0.5); x is
// scaled by sx (the cosine of the mean latitude for geographic meshes, else 1).
struct View {
  int width = 0, height = 0;
  double sx = 1.0, scale = 1.0, cx = 0.0, cy = 0.0;
  Vec2 to_pixel(const Vec3& p) const {
    return Vec2(0.5 * width + (p.x - cx) * sx * scale, 0.5 * height - (p.y - cy) * scale);
  }
};

// The image's height: as asked, else the aspect of the extent (ext_w x ext_h), else square.
int image_height(const RenderOptions& options, double ext_w, double ext_h) {
  if (options.height > 0) return options.height;
  if (ext_w > 0.0 && ext_h > 0.0) {
    const double h = std::round(options.width * ext_h / ext_w);
    return static_cast<int>(std::clamp(h, 1.0, double(kMaxSide)));
  }
  return options.width;
}

View fit_view(const RgbImage& img, const Box3& b, double sx, double ext_w, double ext_h) {
  View view{img.width, img.height, sx, std::numeric_limits<double>::infinity(), 0.0, 0.0};
  const double margin = std::min(img.width, img.height) >= 8 ? 2.0 : 0.0;
  const double avail_w = img.width - 2 * margin, avail_h = img.height - 2 * margin;
  if (ext_w > 0.0) view.scale = std::min(view.scale, avail_w / ext_w);
  if (ext_h > 0.0) view.scale = std::min(view.scale, avail_h / ext_h);
  if (!std::isfinite(view.scale)) view.scale = 1.0;  // a single point
  view.cx = 0.5 * (b.lo.x + b.hi.x);
  view.cy = 0.5 * (b.lo.y + b.hi.y);
  return view;
}

// Triangle colours: by value (viridis-like over the finite values' range) or by mean elevation
// (hypsometric; blues below 0 when the mesh spans sea level).
struct Palette {
  bool by_values = false, sea = false;
  double vlo = std::numeric_limits<double>::infinity(), vhi = -vlo;
  double zlo = 0.0, zhi = 0.0;
};

Palette make_palette(const TriangleMesh& mesh, const RenderOptions& options, const Box3& b) {
  Palette pal;
  pal.by_values = options.colour_by_values && !mesh.triangle_values.empty() &&
                  mesh.triangle_values.size() == mesh.triangles.size();
  if (pal.by_values) {
    for (float v : mesh.triangle_values) {
      if (!std::isfinite(v)) continue;
      pal.vlo = std::min(pal.vlo, double(v));
      pal.vhi = std::max(pal.vhi, double(v));
    }
  }
  pal.sea = !pal.by_values && b.lo.z < 0.0 && b.hi.z > 0.0;
  pal.zlo = b.lo.z;
  pal.zhi = b.hi.z;
  return pal;
}

Rgb triangle_colour(const Palette& pal, const TriangleMesh& mesh, std::size_t t, const Vec3& a,
                    const Vec3& b, const Vec3& c) {
  if (pal.by_values) {
    const double v = mesh.triangle_values[t];
    return ramp(kValues, 5,
                pal.vhi > pal.vlo && std::isfinite(v) ? (v - pal.vlo) / (pal.vhi - pal.vlo) : 0.5);
  }
  const double z = (a.z + b.z + c.z) / 3.0;
  if (pal.sea && z < 0.0) return ramp(kSea, 2, (z - pal.zlo) / -pal.zlo);
  const double base = pal.sea ? 0.0 : pal.zlo;
  return ramp(kLand, 6, pal.zhi > base ? (z - base) / (pal.zhi - base) : 0.0);
}

// Lambert hill-shading in metric units (degrees -> metres for geographic meshes) from the
// north-west (azimuth 315 deg, altitude 45 deg).
struct Lighting {
  double mx = 1.0, my = 1.0, mz = 1.0;
  Vec3 sun{0.0};
};

Lighting make_lighting(const RenderOptions& options, double sx) {
  Lighting l;
  l.mx = options.geographic ? kMetresPerDegree * sx : 1.0;
  l.my = options.geographic ? kMetresPerDegree : 1.0;
  l.mz = options.z_exaggeration;
  const double az = 315.0 * kPi / 180.0, alt = 45.0 * kPi / 180.0;
  l.sun = Vec3(std::cos(alt) * std::sin(az), std::cos(alt) * std::cos(az), std::sin(alt));
  return l;
}

// The brightness factor of triangle abc: flat ground at about 0.9.
double brightness(const Lighting& l, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ma(a.x * l.mx, a.y * l.my, a.z * l.mz), mb(b.x * l.mx, b.y * l.my, b.z * l.mz),
      mc(c.x * l.mx, c.y * l.my, c.z * l.mz);
  Vec3 n = glm::cross(mb - ma, mc - ma);
  const double len = glm::length(n);
  double shade = 0.7071;  // flat
  if (len > 0.0 && std::isfinite(len)) {
    n /= len;
    if (n.z < 0.0) n = -n;
    shade = std::max(0.0, glm::dot(n, l.sun));
  }
  return 0.3 + 0.7 * shade / 0.7071 * 0.85;  // flat ground at ~0.9 brightness
}

// Fill: pixel centres inside or on the triangle (edge functions, either orientation).
void fill_triangle(RgbImage& img, const Vec2& pa, const Vec2& pb, const Vec2& pc,
                   const std::array<std::uint8_t, 3>& rgb) {
  const double area = orient2d(pa, pb, pc);
  if (area == 0.0) return;
  const double s = area > 0.0 ? 1.0 : -1.0;
  const int x0 = std::max(0, static_cast<int>(std::floor(std::min({pa.x, pb.x, pc.x}))));
  const int x1 = std::min(img.width - 1, static_cast<int>(std::ceil(std::max({pa.x, pb.x, pc.x}))));
  const int y0 = std::max(0, static_cast<int>(std::floor(std::min({pa.y, pb.y, pc.y}))));
  const int y1 =
      std::min(img.height - 1, static_cast<int>(std::ceil(std::max({pa.y, pb.y, pc.y}))));
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) {
      const Vec2 p(x + 0.5, y + 0.5);
      if (s * orient2d(pa, pb, p) < 0.0 || s * orient2d(pb, pc, p) < 0.0 ||
          s * orient2d(pc, pa, p) < 0.0) {
        continue;
      }
      std::uint8_t* q = &img.rgb[(static_cast<std::size_t>(y) * img.width + x) * 3];
      q[0] = rgb[0];
      q[1] = rgb[1];
      q[2] = rgb[2];
    }
  }
}

// Edge pixels are set to a darkened copy of the fill, so an edge shared by two triangles looks
// the same as a boundary edge.
void draw_wireframe(RgbImage& img, const TriangleMesh& mesh, const View& view) {
  std::vector<std::uint8_t>& px = img.rgb;
  const std::vector<std::uint8_t> fill = px;
  const auto line = [&](const Vec2& p, const Vec2& q) {
    const double steps = std::ceil(std::max(std::fabs(q.x - p.x), std::fabs(q.y - p.y)));
    const int n = static_cast<int>(std::min(steps, 4.0 * kMaxSide));
    for (int i = 0; i <= n; ++i) {
      const double u = n == 0 ? 0.0 : double(i) / n;
      const int x = static_cast<int>(std::floor(p.x + u * (q.x - p.x)));
      const int y = static_cast<int>(std::floor(p.y + u * (q.y - p.y)));
      if (x < 0 || y < 0 || x >= img.width || y >= img.height) continue;
      const std::size_t o = (static_cast<std::size_t>(y) * img.width + x) * 3;
      for (int k = 0; k < 3; ++k) px[o + k] = static_cast<std::uint8_t>(fill[o + k] * 45 / 100);
    }
  };
  for (const auto& tri : mesh.triangles) {
    const Vec3& a = mesh.positions[tri[0]];
    const Vec3& b = mesh.positions[tri[1]];
    const Vec3& c = mesh.positions[tri[2]];
    if (!finite(a) || !finite(b) || !finite(c)) continue;
    const Vec2 pa = view.to_pixel(a), pb = view.to_pixel(b), pc = view.to_pixel(c);
    line(pa, pb);
    line(pb, pc);
    line(pc, pa);
  }
}

}  // namespace

RgbImage render_image(const TriangleMesh& mesh, const RenderOptions& options) {
  check_input(mesh, options);
  const Box3 bounds = used_bounds(mesh);
  const bool empty = bounds.empty();
  const double lat_mid = empty ? 0.0 : 0.5 * (bounds.lo.y + bounds.hi.y);
  const double sx = options.geographic ? std::max(std::cos(lat_mid * kPi / 180.0), 1e-6) : 1.0;
  const double ext_w = empty ? 0.0 : (bounds.hi.x - bounds.lo.x) * sx;
  const double ext_h = empty ? 0.0 : bounds.hi.y - bounds.lo.y;

  RgbImage img;
  img.width = options.width;
  img.height = image_height(options, ext_w, ext_h);
  const std::size_t npix =
      static_cast<std::size_t>(img.width) * static_cast<std::size_t>(img.height);
  img.rgb.assign(npix * 3, 240);
  if (empty) return img;

  const View view = fit_view(img, bounds, sx, ext_w, ext_h);
  const Lighting lighting = make_lighting(options, sx);
  const Palette palette = make_palette(mesh, options, bounds);
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    const Vec3& a = mesh.positions[tri[0]];
    const Vec3& b = mesh.positions[tri[1]];
    const Vec3& c = mesh.positions[tri[2]];
    if (!finite(a) || !finite(b) || !finite(c)) continue;
    const Rgb colour = triangle_colour(palette, mesh, t, a, b, c);
    const double k = brightness(lighting, a, b, c);
    const std::array<std::uint8_t, 3> rgb = {to_byte(colour[0] * k), to_byte(colour[1] * k),
                                             to_byte(colour[2] * k)};
    fill_triangle(img, view.to_pixel(a), view.to_pixel(b), view.to_pixel(c), rgb);
  }
  if (options.wireframe) draw_wireframe(img, mesh, view);
  return img;
}

void render_png(const std::string& path, const TriangleMesh& mesh, const RenderOptions& options) {
  const RgbImage img = render_image(mesh, options);
  AtomicFile file(path);
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  image.width = static_cast<png_uint_32>(img.width);
  image.height = static_cast<png_uint_32>(img.height);
  image.format = PNG_FORMAT_RGB;
  if (png_image_write_to_stdio(&image, file.stream(), 0, img.rgb.data(), 0, nullptr) == 0) {
    const std::string message = image.message;
    png_image_free(&image);
    throw_io("cannot write '" + path + "': libpng: " + message);
  }
  png_image_free(&image);
  file.commit();
}

}  // namespace smr
