// Synthetic terrain for tests and benchmarks: fractional Brownian motion (fBm) over 2-D gradient
// noise (Perlin, "Improving noise", SIGGRAPH 2002: quintic fade; gradients from our own integer
// hash, never std::rand or <random> distributions, whose output differs across library versions).
//
// The writers peers use to save generated terrain live beside their codecs and are re-exported
// here: write_geotiff (smr/io/gdal_raster.h) and write_npy (smr/io/npy.h).
#pragma once

#include <cstdint>

#include "smr/core/heightfield.h"
#include "smr/io/gdal_raster.h"
#include "smr/io/npy.h"

namespace smr {

/// A width x height fBm heightfield, deterministic in (width, height, seed, height_range, octaves,
/// persistence, spacing) whatever the machine's thread count.
///  - octave k (k = 0 .. octaves-1) has wavelength max(width, height) / 2^k samples and amplitude
///    persistence^k; octaves = 0 picks floor(log2(max(width, height))) (wavelengths down to ~2
///    samples);
///  - the result is normalised so that min z = 0 and max z = height_range exactly (float32);
///  - georef: x0 = y0 = 0, dx = dy = spacing, no CRS; every sample valid;
///  - source: "fbm(width=..., height=..., seed=..., ...)".
/// Throws kInvalidInput for width or height < 2 or > 65536, a non-positive or non-finite
/// height_range or spacing, octaves outside 0..30 or persistence outside (0, 4].
/// Multi-threaded (std::thread); 4097 x 4097 takes a few seconds on two cores.
Heightfield make_fbm(int width, int height, std::uint64_t seed, double height_range = 1600.0,
                     int octaves = 0, double persistence = 0.5, double spacing = 1.0);

}  // namespace smr
