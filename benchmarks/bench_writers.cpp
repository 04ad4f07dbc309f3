// bench_writers: how fast the mesh writers (smr/io/mesh_writer.h) turn a TriangleMesh into a file,
// so that writing keeps up with an extraction producing millions of triangles per second
// (issue 34). The mesh is a real one subdivided (midpoint 1-to-4, smr::midpoint_subdivided):
// bunny00.off (75 408 triangles) 3 times gives 4.83 M triangles and 2.41 M vertices whose
// coordinates are full-precision doubles, like an extraction's. Every triangle gets a value
// (float(t) / 1024, as extraction sets death resolutions), so PLY also writes `property float
// value`.
//
// Formats: binary PLY with values, binary PLY without, ASCII PLY with values, OBJ. Rounds are
// interleaved (each round writes every format once); the time is the whole write_* call (format,
// write, fsync, rename) and the median over --repeat rounds is reported with MB/s (file bytes /
// 1e6 / s) and triangles/s. The file system of --dir is reported (tmpfs or not: on a disk file
// system the fsync is part of the time). Each output's FNV-1a 64 hash is reported so that two
// builds of the writer can be shown to write the same bytes. For scale, "raw_write" times writing
// as many bytes as the binary PLY with values, already in memory, through the same AtomicFile in
// 4 MiB writes (write, fsync, rename): the floor for any writer of that file.
//
//   bench_writers [MESH] [--subdivide 3] [--repeat 5] [--dir DIR]
#include <sys/statfs.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "benchmarks/bench_common.h"
#include "smr/core/mesh.h"
#include "smr/io/atomic_file.h"
#include "smr/io/mesh_reader.h"
#include "smr/io/mesh_writer.h"

namespace {

using nlohmann::json;
using smr::bench::now_ns;
using smr::bench::seconds_since;

struct Format {
  const char* name;
  const char* extension;
  bool values;  // write the mesh with its triangle_values
  void (*write)(const std::string&, const smr::TriangleMesh&);
};

const Format kFormats[] = {
    {"ply_binary_values", ".ply", true,
     [](const std::string& p, const smr::TriangleMesh& m) { smr::write_ply(p, m, true); }},
    {"ply_binary", ".ply", false,
     [](const std::string& p, const smr::TriangleMesh& m) { smr::write_ply(p, m, true); }},
    {"ply_ascii_values", ".ply", true,
     [](const std::string& p, const smr::TriangleMesh& m) { smr::write_ply(p, m, false); }},
    {"obj", ".obj", false,
     [](const std::string& p, const smr::TriangleMesh& m) { smr::write_obj(p, m); }},
};

// FNV-1a 64 of a file's bytes.
std::uint64_t file_hash(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<char> buf(1 << 20);
  std::uint64_t h = 0xcbf29ce484222325ull;
  while (in) {
    in.read(buf.data(), static_cast<std::streamsize>(buf.size()));
    const std::streamsize n = in.gcount();
    for (std::streamsize i = 0; i < n; ++i) {
      h = (h ^ static_cast<unsigned char>(buf[static_cast<std::size_t>(i)])) * 0x100000001b3ull;
    }
  }
  return h;
}

json file_system_json(const std::string& dir) {
  struct statfs fs {};
  if (::statfs(dir.c_str(), &fs) != 0) return {{"dir", dir}};
  constexpr unsigned long kTmpfsMagic = 0x01021994;
  char hex[32];
  std::snprintf(hex, sizeof hex, "0x%lx", static_cast<unsigned long>(fs.f_type));
  return {{"dir", dir},
          {"statfs_type", hex},
          {"tmpfs", static_cast<unsigned long>(fs.f_type) == kTmpfsMagic}};
}

struct Config {
  std::string path;
  int subdivide = 3;
  int repeat = 5;
  std::string dir;
};

// Writes `bytes` bytes of memory through an AtomicFile in 4 MiB writes and commits.
void raw_write(const std::string& path, std::size_t bytes) {
  static const std::vector<char> block(std::size_t{4} << 20, 'x');
  smr::AtomicFile file(path);
  for (std::size_t done = 0; done < bytes; done += block.size()) {
    file.write(block.data(), std::min(block.size(), bytes - done));
  }
  file.commit();
}

int run(const Config& cfg) {
  json report;
  report["benchmark"] = "mesh_writers";
  report["machine"] = smr::bench::machine_json();
  smr::TriangleMesh mesh = smr::read_mesh(cfg.path);
  for (int i = 0; i < cfg.subdivide; ++i) mesh = smr::midpoint_subdivided(mesh);
  const std::size_t triangles = mesh.triangles.size();
  report["input"] = {{"path", cfg.path},
                     {"subdivide", cfg.subdivide},
                     {"vertices", mesh.positions.size()},
                     {"triangles", triangles}};
  smr::TriangleMesh with_values = mesh;
  with_values.triangle_values.resize(triangles);
  for (std::size_t t = 0; t < triangles; ++t) {
    with_values.triangle_values[t] = static_cast<float>(t) / 1024.0f;
  }

  const std::filesystem::path dir =
      std::filesystem::path(cfg.dir) / ("smrdb-bench-writers-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  report["file_system"] = file_system_json(dir.string());
  report["repeat"] = cfg.repeat;

  std::vector<std::vector<double>> times(std::size(kFormats));
  std::vector<double> raw_times;
  const std::string raw_path = (dir / "raw").string();
  for (int round = 0; round < cfg.repeat; ++round) {
    for (std::size_t f = 0; f < std::size(kFormats); ++f) {
      const Format& format = kFormats[f];
      const std::string path = (dir / (std::string(format.name) + format.extension)).string();
      const std::uint64_t t0 = now_ns();
      format.write(path, format.values ? with_values : mesh);
      times[f].push_back(seconds_since(t0));
    }
    const std::uint64_t t0 = now_ns();
    raw_write(raw_path, std::filesystem::file_size(dir / "ply_binary_values.ply"));
    raw_times.push_back(seconds_since(t0));
  }
  json results = json::object();
  for (std::size_t f = 0; f < std::size(kFormats); ++f) {
    const Format& format = kFormats[f];
    const std::string path = (dir / (std::string(format.name) + format.extension)).string();
    const double bytes = static_cast<double>(std::filesystem::file_size(path));
    const double seconds = smr::bench::median(times[f]);
    char hash[24];
    std::snprintf(hash, sizeof hash, "%016llx", static_cast<unsigned long long>(file_hash(path)));
    results[format.name] = {{"seconds", seconds},
                            {"all_seconds", times[f]},
                            {"bytes", bytes},
                            {"mb_per_s", bytes / 1e6 / seconds},
                            {"triangles_per_s", static_cast<double>(triangles) / seconds},
                            {"fnv1a64", hash}};
  }
  const double raw_bytes = static_cast<double>(std::filesystem::file_size(raw_path));
  const double raw_seconds = smr::bench::median(raw_times);
  results["raw_write"] = {{"seconds", raw_seconds},
                          {"all_seconds", raw_times},
                          {"bytes", raw_bytes},
                          {"mb_per_s", raw_bytes / 1e6 / raw_seconds}};
  std::filesystem::remove_all(dir);
  report["results"] = results;
  report["rss_peak_mb"] = smr::bench::peak_rss_mb();
  std::cout << report.dump(2) << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_writers: binary PLY, ASCII PLY and OBJ writing speed on a large mesh"};
  Config cfg;
  cfg.path = std::string(SMRDB_BENCH_DATA_DIR) + "/meshes/bunny00.off";
  cfg.dir = std::filesystem::temp_directory_path().string();
  app.add_option("mesh", cfg.path, "Mesh to subdivide (default: data/meshes/bunny00.off)");
  app.add_option("--subdivide", cfg.subdivide, "Midpoint subdivision levels (default 3)")
      ->check(CLI::Range(0, 6));
  app.add_option("--repeat", cfg.repeat, "Rounds; medians are reported (default 5)")
      ->check(CLI::Range(1, 1000));
  app.add_option("--dir", cfg.dir, "Directory for the files (default: the temp directory)");
  CLI11_PARSE(app, argc, argv);
  try {
    return run(cfg);
  } catch (const std::exception& e) {
    std::cerr << "bench_writers: " << e.what() << "\n";
    return 1;
  }
}
