// A plain indexed triangle mesh: what extraction hands to writers and renderers.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "smr/core/geometry.h"

namespace smr {

struct TriangleMesh {
  std::vector<Vec3> positions;
  std::vector<std::array<std::uint32_t, 3>> triangles;  // counter-clockwise seen from +z / outside
  /// Optional per-triangle scalar (e.g. death resolution) for colouring; empty or one per triangle.
  std::vector<float> triangle_values;
};

/// One level of 1-to-4 midpoint subdivision: every edge gets its midpoint (shared by both faces;
/// numbered in order of first appearance in face order, so the output is deterministic), and each
/// triangle (a, b, c) becomes (a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca): the same
/// surface and orientation with 4 times the triangles (the benchmarks' and tests' large meshes).
/// triangle_values are not carried over.
TriangleMesh midpoint_subdivided(const TriangleMesh& in);

/// Whether two meshes have the same triangles, each with its triangle_value when both meshes have
/// values: the same corner positions in the same winding, in any order and vertex numbering.
bool same_triangles(const TriangleMesh& a, const TriangleMesh& b);

/// A triangle mesh read in passes, never held whole: the out-of-core builder's input
/// (smr::build_block_pm). Indices are into the vertex order; the mesh must be manifold and
/// consistently oriented (what read_mesh validates in memory). A file stream may know its counts
/// only after its first vertices() pass.
class MeshStream {
 public:
  virtual ~MeshStream() = default;
  virtual std::string name() const = 0;
  virtual std::uint64_t vertex_count() const = 0;
  virtual std::uint64_t triangle_count() const = 0;
  /// Calls f with consecutive batches of the vertices' positions, in order.
  virtual void vertices(const std::function<void(std::span<const Vec3>)>& f) const = 0;
  /// Calls f with consecutive batches of the triangles, in order.
  virtual void triangles(
      const std::function<void(std::span<const std::array<std::uint32_t, 3>>)>& f) const = 0;
};

/// A mesh in memory as a MeshStream.
class MemoryMeshStream final : public MeshStream {
 public:
  MemoryMeshStream(const TriangleMesh& mesh, std::string name)
      : mesh_(mesh), name_(std::move(name)) {}
  std::string name() const override { return name_; }
  std::uint64_t vertex_count() const override { return mesh_.positions.size(); }
  std::uint64_t triangle_count() const override { return mesh_.triangles.size(); }
  void vertices(const std::function<void(std::span<const Vec3>)>& f) const override {
    f(mesh_.positions);
  }
  void triangles(
      const std::function<void(std::span<const std::array<std::uint32_t, 3>>)>& f) const override {
    f(mesh_.triangles);
  }

 private:
  const TriangleMesh& mesh_;
  std::string name_;
};

}  // namespace smr
