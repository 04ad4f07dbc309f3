// smrdb tiles: a static quantized-mesh-1.0 pyramid of a terrain database (smr/tiles/pyramid.h).
#include <cstdio>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/db/database.h"
#include "smr/tiles/pyramid.h"
#include "tools/commands.h"
#include "tools/progress.h"
#include "tools/report_json.h"

namespace smr::tools {

void TilesArgs::add_to(CLI::App& app) {
  app.add_option("-o,--output", out, "Output directory ({z}/{x}/{y}.terrain and layer.json)")
      ->required();
  app.add_option(
      "--max-zoom", max_zoom,
      "Deepest zoom level, 0..24 (default: tiles at most 64 samples across, or as accurate "
      "as the database)");
  app.add_option("--cache-mb", cache_mb, "Page cache budget in MiB")->capture_default_str();
  app.add_flag("--force", force, "Replace the output directory if it exists");
}

int cmd_tiles(const std::string& db_path, const TilesArgs& a, const CommonFlags& f) {
  if (a.max_zoom && (*a.max_zoom < 0 || *a.max_zoom > tiles::kMaxZoom))
    throw_input("--max-zoom must be in [0, " + std::to_string(tiles::kMaxZoom) + "], got " +
                std::to_string(*a.max_zoom));
  if (a.cache_mb < 1 || a.cache_mb > (std::uint64_t{1} << 20))
    throw_input("--cache-mb must be in [1, 1048576]");
  const auto db = Database::open(db_path, {std::size_t(a.cache_mb) << 20});
  ProgressBar bar(f.quiet || f.json ? nullptr : stderr);
  tiles::PyramidOptions options;
  options.max_zoom = a.max_zoom.value_or(-1);
  options.force = a.force;
  options.progress = [&](std::uint64_t done, std::uint64_t total) {
    bar.update(double(done) / double(total));
  };
  const tiles::PyramidReport r = tiles::write_pyramid(*db, a.out, options);
  bar.done();
  const nlohmann::json report = {{"output", a.out},
                                 {"projection", r.projection},
                                 {"max_zoom", r.max_zoom},
                                 {"tiles", r.tiles},
                                 {"level_tiles", r.level_tiles},
                                 {"level_errors", r.level_errors},
                                 {"vertices", r.vertices},
                                 {"triangles", r.triangles},
                                 {"bytes", r.bytes},
                                 {"height_step", r.height_step},
                                 {"pages_read", r.pages_read},
                                 {"seconds", r.seconds}};
  print_report(report, f.json);
  if (!f.json && !f.quiet)
    std::fprintf(stderr, "%s: %llu tiles, zoom 0..%d (%s), %llu triangles -> %s\n", db_path.c_str(),
                 static_cast<unsigned long long>(r.tiles), r.max_zoom, r.projection.c_str(),
                 static_cast<unsigned long long>(r.triangles), a.out.c_str());
  return 0;
}

}  // namespace smr::tools
