// fBm terrain (Perlin 2002 gradient noise, quintic fade; octaves summed as in Musgrave's fBm,
// "Texturing and Modeling" ch. 16) with a splitmix64 lattice hash, computed row-parallel.
#include "smr/io/synthetic.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <thread>
#include <vector>

#include "base/error.h"
#include "smr/core/ids.h"

namespace smr {

namespace {

// Eight unit gradients (literals, not cos/sin, so no libm difference can change the output).
constexpr double kS = 0.70710678118654752440;
constexpr double kGrad[8][2] = {{1, 0},   {-1, 0},   {0, 1},    {0, -1},
                                {kS, kS}, {-kS, kS}, {kS, -kS}, {-kS, -kS}};

struct Octave {
  double freq, amp, ox, oy;
  std::uint64_t key;
};

inline const double* gradient(std::uint64_t key, std::int64_t ix, std::int64_t iy) {
  // Lattice coordinates are < 2^31, so (ix, iy) packs into 64 bits without collisions.
  const std::uint64_t packed =
      (static_cast<std::uint64_t>(ix) << 32) | (static_cast<std::uint64_t>(iy) & 0xffffffffULL);
  return kGrad[mix64(key + packed) >> 61];
}

inline double fade(double t) {
  return t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
}

double unit(std::uint64_t h) {
  return static_cast<double>(h >> 11) * 0x1p-53;
}

void fbm_row(int y, int width, const std::vector<Octave>& octaves, std::vector<double>& acc,
             float* out) {
  std::fill(acc.begin(), acc.end(), 0.0);
  for (const Octave& o : octaves) {
    const double fy = y * o.freq + o.oy;
    const double fly = std::floor(fy);
    const auto iy = static_cast<std::int64_t>(fly);
    const double ty = fy - fly, wy = fade(ty);
    std::int64_t cached = std::numeric_limits<std::int64_t>::min();
    const double *g00 = nullptr, *g10 = nullptr, *g01 = nullptr, *g11 = nullptr;
    for (int x = 0; x < width; ++x) {
      const double fx = x * o.freq + o.ox;
      const double flx = std::floor(fx);
      const auto ix = static_cast<std::int64_t>(flx);
      const double tx = fx - flx;
      if (ix != cached) {
        g00 = gradient(o.key, ix, iy);
        g10 = gradient(o.key, ix + 1, iy);
        g01 = gradient(o.key, ix, iy + 1);
        g11 = gradient(o.key, ix + 1, iy + 1);
        cached = ix;
      }
      const double n00 = g00[0] * tx + g00[1] * ty;
      const double n10 = g10[0] * (tx - 1.0) + g10[1] * ty;
      const double n01 = g01[0] * tx + g01[1] * (ty - 1.0);
      const double n11 = g11[0] * (tx - 1.0) + g11[1] * (ty - 1.0);
      const double wx = fade(tx);
      const double a = n00 + wx * (n10 - n00);
      const double b = n01 + wx * (n11 - n01);
      acc[static_cast<std::size_t>(x)] += o.amp * (a + wy * (b - a));
    }
  }
  for (int x = 0; x < width; ++x) out[x] = static_cast<float>(acc[static_cast<std::size_t>(x)]);
}

}  // namespace

Heightfield make_fbm(int width, int height, std::uint64_t seed, double height_range, int octaves,
                     double persistence, double spacing) {
  const auto bad = [&](const std::string& why) {
    throw_input("make_fbm(" + std::to_string(width) + " x " + std::to_string(height) + "): " + why);
  };
  if (width < 2 || height < 2 || width > 65536 || height > 65536) {
    bad("width and height must be in 2..65536");
  }
  if (!(height_range > 0.0) || !std::isfinite(height_range)) bad("height_range must be > 0");
  if (!(spacing > 0.0) || !std::isfinite(spacing)) bad("spacing must be > 0");
  if (octaves < 0 || octaves > 30) bad("octaves must be in 0..30 (0 = automatic)");
  if (!(persistence > 0.0) || persistence > 4.0) bad("persistence must be in (0, 4]");

  const int side = std::max(width, height);
  if (octaves == 0) octaves = std::max(1, static_cast<int>(std::floor(std::log2(double(side)))));
  std::vector<Octave> oct;
  double amp = 1.0;
  for (int k = 0; k < octaves; ++k) {
    const std::uint64_t key = mix64(seed ^ mix64(0x5eed0000ULL + static_cast<std::uint64_t>(k)));
    // Offsets in [0, 256) so that octaves do not share lattice points (and noise is not 0 at
    // every sample of a coarse octave).
    oct.push_back({std::ldexp(1.0, k) / side, amp, 256.0 * unit(mix64(key ^ 1)),
                   256.0 * unit(mix64(key ^ 2)), key});
    amp *= persistence;
  }

  Heightfield h;
  h.width = width;
  h.height = height;
  const auto w = static_cast<std::size_t>(width);
  h.z.resize(w * static_cast<std::size_t>(height));
  h.georef.dx = h.georef.dy = spacing;

  // Rows are independent, so the result does not depend on the thread count.
  const unsigned hw = std::max(1u, std::thread::hardware_concurrency());
  const unsigned threads = std::min<unsigned>(hw, static_cast<unsigned>(std::max(1, height / 16)));
  std::vector<std::vector<double>> acc(threads, std::vector<double>(w));
  std::atomic<int> next_row{0};
  const auto work = [&](unsigned t) {
    for (int y; (y = next_row.fetch_add(1)) < height;) {
      fbm_row(y, width, oct, acc[t], h.z.data() + static_cast<std::size_t>(y) * w);
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work, t);
  work(0);
  for (std::thread& t : pool) t.join();

  const auto [lo_it, hi_it] = std::minmax_element(h.z.begin(), h.z.end());
  const double lo = *lo_it, hi = *hi_it;
  if (!(hi > lo)) bad("the noise is constant; use a larger grid");
  // (v - lo) / (hi - lo) is exactly 0 at the minimum and exactly 1 at the maximum.
  const double inv = 1.0 / (hi - lo);
  for (float& v : h.z) {
    const double t = (double(v) == hi) ? 1.0 : (double(v) - lo) * inv;
    v = static_cast<float>(std::min(t, 1.0) * height_range);
  }

  char source[256];
  std::snprintf(source, sizeof source,
                "fbm(width=%d, height=%d, seed=%llu, range=%g, octaves=%d, persistence=%g, "
                "spacing=%g)",
                width, height, static_cast<unsigned long long>(seed), height_range, octaves,
                persistence, spacing);
  h.source = source;
  return h;
}

}  // namespace smr
