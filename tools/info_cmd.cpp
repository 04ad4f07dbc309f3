// smrdb info and smrdb verify: what a database holds, and whether every byte of it checks out.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/db/database.h"
#include "tools/commands.h"
#include "tools/progress.h"
#include "tools/report_json.h"

namespace smr::tools {

int cmd_info(const std::string& db_path, bool json) {
  const auto db = Database::open(db_path, {std::size_t{16} << 20});
  nlohmann::json meta = nlohmann::json::parse(db->meta_json());
  const std::uint64_t max_depth = meta["counts"]["dag_depth"].get<std::uint64_t>();
  const std::uint64_t vertices = meta["model"]["vertex_count"].get<std::uint64_t>();
  nlohmann::json out = {
      {"path", db_path},
      {"file_bytes", db->file_bytes()},
      {"bytes_per_vertex", double(db->file_bytes()) / double(std::max<std::uint64_t>(1, vertices))},
      {"dag_depth", max_depth},
      {"rtree_height", db->rtree().height()},
      {"meta", meta}};
  if (json) {
    std::cout << out.dump(2) << "\n";
    return 0;
  }
  const auto& m = meta["model"];
  std::printf("database        %s (format %d, %s pages, checksum %s)\n", db_path.c_str(),
              meta["version"].get<int>(), meta["codec"].get<std::string>().c_str(),
              meta["checksum"].get<std::string>().c_str());
  if (m["kind"].get<std::string>() == "terrain") {
    std::printf("source          %s (%dx%d samples)\n", m["source"].get<std::string>().c_str(),
                m["grid_width"].get<int>(), m["grid_height"].get<int>());
  } else {
    std::printf("source          %s (3-D mesh)\n", m["source"].get<std::string>().c_str());
  }
  std::printf("builder         %s\n", m["builder"].get<std::string>().c_str());
  std::printf("ops             %llu (DAG depth %llu), %llu triangles, %llu vertices\n",
              static_cast<unsigned long long>(meta["counts"]["ops"].get<std::uint64_t>()),
              static_cast<unsigned long long>(max_depth),
              static_cast<unsigned long long>(meta["counts"]["triangles"].get<std::uint64_t>()),
              static_cast<unsigned long long>(vertices));
  std::printf("pages           %llu data pages, R-tree of %llu nodes (height %d)\n",
              static_cast<unsigned long long>(meta["counts"]["pages"].get<std::uint64_t>()),
              static_cast<unsigned long long>(meta["counts"]["rtree_nodes"].get<std::uint64_t>()),
              db->rtree().height());
  std::printf(
      "size            %.3f MB, %.2f bytes/vertex (pages %.3f MB, locators %.3f MB, R-tree %.3f "
      "MB)\n",
      double(db->file_bytes()) / 1e6, out["bytes_per_vertex"].get<double>(),
      double(meta["bytes"]["pages"].get<std::uint64_t>()) / 1e6,
      double(meta["bytes"]["locators"].get<std::uint64_t>()) / 1e6,
      double(meta["bytes"]["rtree"].get<std::uint64_t>()) / 1e6);
  std::printf("error           err0 %g, err_final %g (includes the z quantization shift %g)\n",
              m["err0"].get<double>(), m["err_final"].get<double>(), meta["z_shift"].get<double>());
  std::printf("quantization    origin %s, step %s\n", meta["grid"]["origin"].dump().c_str(),
              meta["grid"]["step"].dump().c_str());
  std::printf("parameters      %s\n", meta["parameters"].get<std::string>().c_str());
  return 0;
}

int cmd_verify(const std::string& db_path, const CommonFlags& f) {
  if (!std::filesystem::exists(db_path)) throw_input(db_path + ": no such file");
  ProgressBar bar(f.quiet || f.json ? nullptr : stderr);
  const VerifyReport r = verify_database(db_path, [&](double x) { bar.update(x); });
  bar.done();
  if (f.json) {
    nlohmann::json j = r;
    j["path"] = db_path;
    std::cout << j.dump(2) << "\n";
  }
  for (const std::string& fault : r.faults)
    std::fprintf(stderr, "smrdb: verify: %s\n", fault.c_str());
  if (!f.json && !f.quiet)
    std::fprintf(stderr, "%s: %s (%llu pages, %llu ops, %llu triangles)\n", db_path.c_str(),
                 r.ok() ? "ok" : "FAULTY", static_cast<unsigned long long>(r.pages),
                 static_cast<unsigned long long>(r.ops),
                 static_cast<unsigned long long>(r.triangles));
  return r.ok() ? 0 : 1;
}

}  // namespace smr::tools
