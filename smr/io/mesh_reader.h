// Reading triangle meshes (PLY, OBJ, OFF, STL) with hand-written, bounds-checked parsers (no
// third-party reader: every byte of an untrusted file is checked here; this is a fuzz target,
// tests/fuzz/mesh_reader_fuzz.cpp), followed by a validation that either rejects a mesh a
// simplifier cannot work on or, when asked, repairs it.
//
// Formats (https://paulbourke.net/dataformats/ply/, .../obj/, Geomview's OFF(5), 3D Systems' STL):
//  - PLY: ascii, binary_little_endian, binary_big_endian. The `vertex` element must have scalar
//    properties x, y, z of any PLY type (char .. double, int8 .. float64); other vertex
//    properties are ignored. The `face` element must have a list property `vertex_indices` or
//    `vertex_index` with integer count and index types; other face properties and all other
//    elements (edge, material, ...) are skipped.
//  - OBJ: `v x y z [w | r g b]` and `f` with references `i`, `i/t`, `i//n`, `i/t/n`; negative
//    indices count back from the last vertex read; positive indices may refer to vertices defined
//    later in the file; every other statement (vt, vn, g, o, s, usemtl, mtllib, l, p, ...) is
//    ignored; `\` at the end of a line continues it.
//  - OFF: `OFF` (also COFF, NOFF, CNOFF, STOFF, ... : per-vertex normals, colours and texture
//    coordinates are ignored), the counts `V F [E]` (E ignored), then V vertices and F faces
//    `n i1 .. in [colour]`; `#` comments anywhere.
//  - STL: binary when the size is exactly 84 + 50 * (the triangle count at byte 80), else ASCII
//    (`solid` .. `facet normal` .. `outer loop` .. `vertex` x3 .. `endsolid`, several solids
//    allowed). STL stores every triangle with its own three corners, so the STL reader always
//    merges corners with equal positions (x == y == z compared as numbers: -0 equals +0) into
//    shared vertices, in order of first appearance. That is how STL encodes connectivity, not a
//    repair, and is not counted in MeshReport::welded_vertices.
// Faces with more than three vertices (OBJ, OFF, PLY) are fan-triangulated (v0, vi, vi+1); a face
// with fewer than three vertices is degenerate.
//
// Counts are never trusted: a count the rest of the file cannot hold ("the header says 4000000000
// vertices, the file has room for at most N") is rejected before anything is allocated, and no
// read goes past the buffer. Every problem throws smr::Error (base/error.h): kIo when the file
// cannot be opened or read, kInvalidInput for anything wrong with its content. Messages name the
// file, the element (vertex / face number, 0-based in file order except for OBJ's 1-based
// vertex numbers, plus the line for text formats) and what was expected, and say which repair, if
// any, would fix it.
//
// Implementation: smr/io/mesh/ holds one reader per format (ply_reader.cpp with the streamed path
// in ply_stream.cpp, obj_reader.cpp, off_reader.cpp, stl_reader.cpp), their shared tokenizer
// (text.h) and face sink (source.h), and the validator's steps (validator.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "smr/core/mesh.h"

namespace smr {

enum class MeshFormat { kPly, kObj, kOff, kStl };

/// Optional repairs (validate_mesh). Without them, each problem is an error; the CLI's `--repair`
/// means MeshRepair::all().
struct MeshRepair {
  /// Merge vertices whose positions are equal (compared as numbers: -0 == +0; NaN never gets
  /// this far). The lowest-numbered vertex survives.
  bool weld = false;
  /// Drop faces that use a vertex twice (after welding) or have fewer than three vertices.
  bool drop_degenerate = false;
  /// Drop faces with the same vertex set as an earlier face (whatever their orientation).
  bool drop_duplicates = false;
  /// Edges with more than two faces: keep one pair of faces glued (preferring two that traverse
  /// the edge in opposite directions, else the first two in file order) and detach the others,
  /// which gives them their own copies of the edge's vertices (and, in the rare case where a
  /// detached face still reaches the kept pair around both end vertices, their own copies of all
  /// three vertices). Vertices whose faces form several edge-connected fans ("bowties") are split
  /// into one copy per fan; the first fan in file order keeps the original vertex.
  bool split_nonmanifold = false;
  /// Flip faces so that neighbours traverse their shared edge in opposite directions, per
  /// connected component, flipping the fewer faces (ties: keep the component's first face).
  /// A non-orientable component (a Moebius strip) is an error even with this repair.
  bool orient = false;

  static MeshRepair all() { return {true, true, true, true, true}; }
  bool any() const {
    return weld || drop_degenerate || drop_duplicates || split_nonmanifold || orient;
  }
};

/// What reading and validating a mesh found and changed.
struct MeshReport {
  // Repairs (each only non-zero when the matching MeshRepair flag was set).
  std::size_t welded_vertices = 0;           // vertices merged into an equal earlier one
  std::size_t degenerate_faces_dropped = 0;  // repeated vertex or fewer than 3 vertices
  std::size_t duplicate_faces_dropped = 0;
  std::size_t nonmanifold_edges_cut = 0;  // edges with > 2 faces whose extra faces were detached
  std::size_t vertices_split = 0;         // vertex copies added by split_nonmanifold
  std::size_t faces_flipped = 0;
  // Always done, never an error (documented, not repairs).
  std::size_t unused_vertices_dropped = 0;  // vertices no face references (silently dropped)
  std::size_t polygons_triangulated = 0;    // faces with more than 3 vertices, fan-triangulated
  /// Faces with three distinct vertices whose cross product is exactly zero (collinear or
  /// coincident corners). They are kept: a simplifier survives zero-area triangles (they collapse
  /// first), while a repeated index breaks its connectivity, which is why only the latter is
  /// "degenerate".
  std::size_t zero_area_faces = 0;
  // The resulting mesh.
  std::size_t vertices = 0;
  std::size_t faces = 0;
  std::size_t components = 0;      // edge-connected components
  std::size_t boundary_edges = 0;  // edges with exactly one face
  bool closed = false;             // no boundary edges (and at least one face)

  /// Number of repairs made (the sum of the repair counters above).
  std::size_t repairs() const {
    return welded_vertices + degenerate_faces_dropped + duplicate_faces_dropped +
           nonmanifold_edges_cut + vertices_split + faces_flipped;
  }
  /// One line for a log, e.g. "37706 vertices, 75408 faces, 1 component, closed; repaired: ...".
  std::string summary() const;
};

/// True when `path` ends in .ply, .obj, .off or .stl (case-insensitive).
bool is_mesh_path(const std::string& path);

/// The format for `path`'s extension (case-insensitive); any other extension -> kInvalidInput
/// naming it and listing the supported ones.
MeshFormat mesh_format_for_path(const std::string& path);

/// Reads, validates and (optionally) repairs a mesh; the format is chosen by extension. The
/// result satisfies the invariants listed at validate_mesh. `report`, when given, is overwritten.
TriangleMesh read_mesh(const std::string& path, const MeshRepair& repair = {},
                       MeshReport* report = nullptr);

/// read_mesh on bytes already in memory; `name` is used in messages in place of the path.
TriangleMesh parse_mesh(std::string_view bytes, MeshFormat format, const std::string& name,
                        const MeshRepair& repair = {}, MeshReport* report = nullptr);

/// A PLY file as a MeshStream for the out-of-core builder: each pass maps the file and parses it
/// front to back with the reader above, handing vertices and triangles over in batches, so
/// neither the file nor the mesh is held (the map's pages are dropped from the resident set as
/// the parse goes). Counts are known after the first vertices() pass. Checks what one record
/// can show (finite coordinates, indices in range, no vertex twice in a face, truncation); the
/// whole-mesh checks of validate_mesh (manifold edges and fans, orientation) are not made, and
/// nothing is repaired. Other formats: kInvalidInput.
std::unique_ptr<MeshStream> open_mesh_stream(const std::string& path);

/// Validates `mesh` in place, applying the repairs asked for; `what` names it in messages. Checks,
/// in this order (each an error unless the repair in brackets is set):
///  1. every coordinate is finite (never repairable);
///  2. every index is < positions.size() (never repairable);
///  3. [weld] vertices with equal positions are merged (optional; no error without it);
///  4. no face repeats a vertex [drop_degenerate]; exactly-zero-area faces are counted, kept;
///  5. no two faces have the same vertex set [drop_duplicates];
///  6. no edge has more than two faces [split_nonmanifold];
///  7. the faces around each vertex form one edge-connected fan [split_nonmanifold];
///  8. every component is orientable (never repairable), and faces sharing an edge traverse it in
///     opposite directions [orient];
///  9. at least one face is left.
/// Vertices no face references are then dropped (counted, never an error); the order of the
/// remaining vertices and faces is kept, vertex copies made by split_nonmanifold are appended.
/// Afterwards: every index is in range, no face repeats a vertex, no two faces share a vertex
/// set, every edge has one or two faces and two faces traverse it in opposite directions, every
/// vertex is referenced and its faces form a single fan. triangle_values, when it has one value
/// per triangle, follows the faces; any other non-empty size is an error.
/// Cost: O(V + F) time on flat arrays (edges grouped by a counting sort on their lower vertex,
/// fans by a union-find over face corners, weld by hashing); about 55 bytes of scratch per face
/// at the peak. 5 M triangles validate in about 1 s.
void validate_mesh(TriangleMesh& mesh, const std::string& what, const MeshRepair& repair = {},
                   MeshReport* report = nullptr);

}  // namespace smr
