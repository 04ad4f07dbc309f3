// Reading triangle meshes (smr/io/mesh_reader.h): the public entry points. Each format has its
// reader in smr/io/mesh/ (ply_reader.cpp, obj_reader.cpp, off_reader.cpp, stl_reader.cpp; the
// streamed PLY path in ply_stream.cpp), followed by the validator (mesh/validator.cpp).
// Formats: PLY (Turk 1994, as documented at paulbourke.net/dataformats/ply), Wavefront OBJ
// (Wavefront Advanced Visualizer manual, appendix B1), OFF (Geomview manual, OFF(5)), STL
// (3D Systems, StereoLithography Interface Specification, 1989).
#include "smr/io/mesh_reader.h"

#include <string>
#include <string_view>
#include <vector>

#include "base/error.h"
#include "smr/io/io_util.h"
#include "smr/io/mesh/source.h"
#include "smr/io/mesh/text.h"

namespace smr {

using mesh_io::num;

std::string MeshReport::summary() const {
  std::string s =
      num(std::uint64_t{vertices}) + " vertices, " + num(std::uint64_t{faces}) + " faces, " +
      num(std::uint64_t{components}) + (components == 1 ? " component, " : " components, ") +
      (closed ? std::string("closed") : num(std::uint64_t{boundary_edges}) + " boundary edges");
  std::string r;
  const auto add = [&](std::size_t count, const char* text) {
    if (count == 0) return;
    r += (r.empty() ? "" : ", ") + num(std::uint64_t{count}) + " " + text;
  };
  add(welded_vertices, "vertices welded");
  add(degenerate_faces_dropped, "degenerate faces dropped");
  add(duplicate_faces_dropped, "duplicate faces dropped");
  add(nonmanifold_edges_cut, "non-manifold edges cut");
  add(vertices_split, "vertices split");
  add(faces_flipped, "faces flipped");
  if (!r.empty()) s += "; repaired: " + r;
  std::string notes;
  const auto note = [&](std::size_t count, const char* text) {
    if (count == 0) return;
    notes += (notes.empty() ? "" : ", ") + num(std::uint64_t{count}) + " " + text;
  };
  note(unused_vertices_dropped, "unused vertices dropped");
  note(polygons_triangulated, "polygons triangulated");
  note(zero_area_faces, "zero-area faces");
  if (!notes.empty()) s += "; " + notes;
  return s;
}

bool is_mesh_path(const std::string& path) {
  const std::string ext = io_util::lower_extension(path);
  return ext == ".ply" || ext == ".obj" || ext == ".off" || ext == ".stl";
}

MeshFormat mesh_format_for_path(const std::string& path) {
  const std::string ext = io_util::lower_extension(path);
  if (ext == ".ply") return MeshFormat::kPly;
  if (ext == ".obj") return MeshFormat::kObj;
  if (ext == ".off") return MeshFormat::kOff;
  if (ext == ".stl") return MeshFormat::kStl;
  throw_input("cannot read mesh '" + path + "': " +
              (ext.empty() ? std::string("it has no extension")
                           : "unknown extension '" + io_util::excerpt(ext) + "'") +
              " (supported: .ply, .obj, .off, .stl)");
}

namespace {

TriangleMesh parse_only(std::string_view bytes, MeshFormat format, mesh_io::Source& src,
                        const MeshRepair& repair, MeshReport& rep) {
  TriangleMesh mesh;
  switch (format) {
    case MeshFormat::kPly:
      mesh_io::parse_ply(bytes, src, mesh, repair, rep);
      break;
    case MeshFormat::kObj:
      mesh_io::parse_obj(bytes, src, mesh, repair, rep);
      break;
    case MeshFormat::kOff:
      mesh_io::parse_off(bytes, src, mesh, repair, rep);
      break;
    case MeshFormat::kStl:
      mesh_io::parse_stl(bytes, src, mesh, repair, rep);
      break;
  }
  return mesh;
}

}  // namespace

TriangleMesh parse_mesh(std::string_view bytes, MeshFormat format, const std::string& name,
                        const MeshRepair& repair, MeshReport* report) {
  MeshReport local;
  MeshReport& rep = report != nullptr ? *report : local;
  rep = MeshReport{};
  mesh_io::Source src;
  src.what = name;
  TriangleMesh mesh = parse_only(bytes, format, src, repair, rep);
  mesh_io::validate_faces(mesh, src, repair, rep);
  return mesh;
}

TriangleMesh read_mesh(const std::string& path, const MeshRepair& repair, MeshReport* report) {
  const MeshFormat format = mesh_format_for_path(path);
  MeshReport local;
  MeshReport& rep = report != nullptr ? *report : local;
  rep = MeshReport{};
  mesh_io::Source src;
  src.what = path;
  TriangleMesh mesh;
  {
    // Freed before validation.
    const std::vector<std::uint8_t> bytes = io_util::read_file_bytes(path, "a mesh file");
    const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    mesh = parse_only(text, format, src, repair, rep);
  }
  mesh_io::validate_faces(mesh, src, repair, rep);
  return mesh;
}

void validate_mesh(TriangleMesh& mesh, const std::string& what, const MeshRepair& repair,
                   MeshReport* report) {
  MeshReport local;
  MeshReport& rep = report != nullptr ? *report : local;
  rep = MeshReport{};
  mesh_io::Source src;
  src.what = what;
  mesh_io::validate_faces(mesh, src, repair, rep);
}

}  // namespace smr
