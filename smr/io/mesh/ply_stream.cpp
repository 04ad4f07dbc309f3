// A PLY file as a MeshStream (open_mesh_stream, smr/io/mesh_reader.h): each pass maps the file
// and runs the PLY reader (ply_reader.cpp) front to back, handing vertices and triangles over in
// batches, its pages dropped from the resident set as it goes (storage::PageTrimmer).
#include <algorithm>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <utility>

#include "smr/io/mesh/source.h"
#include "smr/io/mesh/text.h"
#include "smr/io/mesh_reader.h"
#include "storage/mapped_file.h"

namespace smr {

namespace {

class PlyStream final : public MeshStream {
 public:
  explicit PlyStream(std::string path) : path_(std::move(path)) {
    // The counts the header declares (the parse checks them against the data), so the
    // builder can size its arrays before the first pass.
    const storage::MappedFile file(path_);
    const std::string_view b = file.bytes();
    const std::string_view head = b.substr(0, std::min<std::size_t>(b.size(), 1 << 20));
    std::size_t at = 0;
    while (at < head.size()) {
      const std::size_t nl = head.find('\n', at);
      const std::string_view line =
          head.substr(at, (nl == std::string_view::npos ? head.size() : nl) - at);
      at = nl == std::string_view::npos ? head.size() : nl + 1;
      if (line.starts_with("end_header")) break;
      std::uint64_t n = 0;
      for (const auto& [prefix, out] :
           {std::pair{std::string_view("element vertex "), &vertices_},
            std::pair{std::string_view("element face "), &triangles_}}) {
        if (!line.starts_with(prefix)) continue;
        std::string_view rest = line.substr(prefix.size());
        while (!rest.empty() && (rest.back() == '\r' || rest.back() == ' ')) rest.remove_suffix(1);
        if (mesh_io::parse_uint(rest, n)) *out = n;
      }
    }
  }
  std::string name() const override { return path_; }
  std::uint64_t vertex_count() const override { return vertices_; }
  std::uint64_t triangle_count() const override { return triangles_; }
  void vertices(const std::function<void(std::span<const Vec3>)>& f) const override {
    std::uint64_t nv = 0, nt = 0;
    pass([&](std::span<const Vec3> b) { nv += b.size(), f(b); },
         [&](std::span<const std::array<std::uint32_t, 3>> b) { nt += b.size(); });
    vertices_ = nv;
    triangles_ = nt;
  }
  void triangles(
      const std::function<void(std::span<const std::array<std::uint32_t, 3>>)>& f) const override {
    pass([](std::span<const Vec3>) {}, f);
  }

 private:
  void pass(const std::function<void(std::span<const Vec3>)>& v,
            const std::function<void(std::span<const std::array<std::uint32_t, 3>>)>& t) const {
    const storage::MappedFile file(path_);
    const storage::PageTrimmer trimmer(file.bytes().data(), file.bytes().size());
    mesh_io::Source src;
    src.what = path_;
    src.vertex_batch = v;
    src.triangle_batch = t;
    MeshReport report;
    TriangleMesh mesh;
    mesh_io::parse_ply(file.bytes(), src, mesh, MeshRepair{}, report);
  }

  std::string path_;
  mutable std::uint64_t vertices_ = 0, triangles_ = 0;
};

}  // namespace

std::unique_ptr<MeshStream> open_mesh_stream(const std::string& path) {
  if (mesh_format_for_path(path) != MeshFormat::kPly) {
    throw_input("'" + path +
                "': only PLY meshes can be streamed (out-of-core ingest with --memory); "
                "convert it to PLY or ingest it in memory");
  }
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw_io("cannot open '" + path + "': no such file");
  return std::make_unique<PlyStream>(path);
}

}  // namespace smr
