// smrdb synth: a deterministic fractional Brownian motion DEM (smr/io/synthetic.h).
#include <cmath>
#include <cstdio>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "smr/io/synthetic.h"
#include "tools/commands.h"
#include "tools/parse.h"

namespace smr::tools {

void SynthArgs::add_to(CLI::App& app) {
  app.add_option("--size", width, "Width in samples")->capture_default_str();
  app.add_option("--height", height, "Height in samples (default: = size)");
  app.add_option("--seed", seed, "Random seed")->capture_default_str();
  app.add_option("--range", range, "Height range (max - min)")->capture_default_str();
  app.add_option("--spacing", spacing, "Sample spacing")->capture_default_str();
  app.add_option("-o,--output", out, "Output DEM (.tif or .npy)")->required();
}

int cmd_synth(const SynthArgs& a, bool quiet) {
  const int width = a.width, height = a.height == 0 ? a.width : a.height;
  if (width < 2 || height < 2 || width > 65536 || height > 65536) {
    throw_input("--size/--height must be in [2, 65536], got " + std::to_string(width) + "x" +
                std::to_string(height));
  }
  if (!(a.range > 0.0) || !std::isfinite(a.range))
    throw_input("--range must be a positive height range");
  if (!(a.spacing > 0.0) || !std::isfinite(a.spacing)) throw_input("--spacing must be positive");
  const std::string ext = extension_of(a.out);
  if (ext != ".tif" && ext != ".tiff" && ext != ".npy")
    throw_input("-o " + a.out + ": must end in .tif or .npy");
  const Heightfield h = make_fbm(width, height, a.seed, a.range, 0, 0.5, a.spacing);
  if (ext == ".npy") {
    write_npy(a.out, h);
  } else {
    write_geotiff(a.out, h);
  }
  if (!quiet)
    std::fprintf(stderr, "%s: %dx%d fBm, seed %llu, range %g\n", a.out.c_str(), width, height,
                 static_cast<unsigned long long>(a.seed), a.range);
  return 0;
}

}  // namespace smr::tools
