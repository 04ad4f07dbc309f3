// Fuzz target for the streamed PLY path (smr::open_mesh_stream, smr/io/mesh_reader.h), which the
// out-of-core block builder reads: each input is written to a file and streamed, two passes of
// vertices and one of triangles. The stream must either throw smr::Error of a user kind naming
// the file, or hand over batches that agree with its counts and with each other from pass to
// pass, with finite coordinates, indices in range and no vertex twice in a triangle (what one
// record can show; the whole-mesh checks are not made on a stream). And it must agree with the
// in-memory reader on the same bytes: a file parse_mesh accepts (without repair, no vertex
// dropped as unused) streams to exactly its vertices and triangles, and a file the stream
// rejects parse_mesh rejects too. Seeds, mutator and smoke mode: the driver (mesh_fuzz.h).
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "tests/fuzz/mesh_fuzz.h"

namespace {

using smr::fuzz::fail;

// The file each input is written to: in /dev/shm when there is one (memory, so a busy disk does
// not set the pace), else in the temporary directory; removed when the process ends.
struct StreamFile {
  std::string path;
  StreamFile() {
    std::error_code ec;
    const std::filesystem::path dir = std::filesystem::is_directory("/dev/shm", ec)
                                          ? std::filesystem::path("/dev/shm")
                                          : std::filesystem::temp_directory_path();
    path = (dir / ("smrdb-mesh-stream-fuzz-" + std::to_string(::getpid()) + ".ply")).string();
  }
  ~StreamFile() {
    std::error_code ec;
    std::filesystem::remove(path, ec);
  }
};

const std::string& stream_path() {
  static const StreamFile file;
  return file.path;
}

struct Streamed {
  std::vector<smr::Vec3> positions;
  std::vector<std::array<std::uint32_t, 3>> triangles;
};

Streamed stream(const std::string& path, std::string_view input) {
  const auto s = smr::open_mesh_stream(path);
  Streamed out;
  s->vertices([&](std::span<const smr::Vec3> b) {
    out.positions.insert(out.positions.end(), b.begin(), b.end());
  });
  s->triangles([&](std::span<const std::array<std::uint32_t, 3>> b) {
    out.triangles.insert(out.triangles.end(), b.begin(), b.end());
  });
  if (s->vertex_count() != out.positions.size() || s->triangle_count() != out.triangles.size()) {
    fail("the stream's counts differ from what it handed over", input);
  }
  std::vector<smr::Vec3> again;
  s->vertices([&](std::span<const smr::Vec3> b) { again.insert(again.end(), b.begin(), b.end()); });
  if (again != out.positions) fail("two passes of the stream differ", input);
  for (const smr::Vec3& p : out.positions) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
      fail("the stream handed over a non-finite coordinate", input);
    }
  }
  for (const auto& t : out.triangles) {
    for (std::uint32_t v : t) {
      if (v >= out.positions.size()) fail("the stream handed over an index out of range", input);
    }
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
      fail("the stream handed over a triangle with a vertex twice", input);
    }
  }
  return out;
}

void run(std::string_view bytes, smr::fuzz::Stats& stats) {
  ++stats.inputs;
  const std::string& path = stream_path();
  {
    std::ofstream f(path, std::ios::binary | std::ios::trunc);
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!f) fail("cannot write " + path, bytes);
  }
  ++stats.parses;
  bool streamed = false;
  Streamed s;
  try {
    s = stream(path, bytes);
    streamed = true;
    ++stats.valid;
  } catch (const smr::Error& e) {
    smr::fuzz::expect_user_error(e, path, bytes, "streaming");
    ++stats.errors;
  } catch (const std::exception& e) {
    fail(std::string("a non-smr exception streaming: ") + e.what(), bytes);
  }
  // The in-memory reader on the same bytes.
  try {
    smr::MeshReport rep;
    const smr::TriangleMesh m =
        smr::parse_mesh(bytes, smr::MeshFormat::kPly, smr::fuzz::kName, {}, &rep);
    if (!streamed) fail("the stream rejects a file the in-memory reader accepts", bytes);
    if (rep.unused_vertices_dropped == 0 &&
        (s.positions != m.positions || s.triangles != m.triangles)) {
      fail("the stream and the in-memory reader give different meshes", bytes);
    }
  } catch (const smr::Error& e) {
    smr::fuzz::expect_user_error(e, smr::fuzz::kName, bytes, "in memory");
  } catch (const std::exception& e) {
    fail(std::string("a non-smr exception in memory: ") + e.what(), bytes);
  }
}

}  // namespace

namespace smr::fuzz {

// 3000 inputs a smoke run: each is written to a file and read four times.
const Target& target() {
  static const Target t{"mesh_stream_fuzz", MeshFormat::kPly, run, 3000};
  return t;
}

}  // namespace smr::fuzz
