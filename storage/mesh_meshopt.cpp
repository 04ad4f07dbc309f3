// The one place meshoptimizer is used (storage/mesh_compress.h): EXT_meshopt_compression's
// attribute and triangle codecs (the extension's Appendix A bitstreams, versions 0 and 1) and the
// vertex cache / fetch reordering the extension recommends before them.
#include <meshoptimizer.h>

#include <cstring>
#include <numeric>
#include <string>

#include "base/error.h"
#include "storage/mesh_compress.h"

namespace smr::storage {

std::vector<std::uint32_t> meshopt_reorder(std::span<std::array<std::uint32_t, 3>> triangles,
                                           std::size_t vertex_count) {
  const std::size_t n = triangles.size() * 3;
  auto* indices = reinterpret_cast<unsigned int*>(triangles.data());
  static_assert(sizeof(std::array<std::uint32_t, 3>) == 3 * sizeof(unsigned int));
  for (std::size_t i = 0; i < n; ++i) {
    if (indices[i] >= vertex_count)
      throw_input("meshopt: triangle index " + std::to_string(indices[i]) + " out of range (" +
                  std::to_string(vertex_count) + " vertices)");
  }
  std::vector<unsigned int> reordered(n);
  meshopt_optimizeVertexCache(reordered.data(), indices, n, vertex_count);
  // Unused vertices come back as ~0u: they go last, in their old order.
  std::vector<std::uint32_t> remap(vertex_count);
  const std::size_t used =
      meshopt_optimizeVertexFetchRemap(remap.data(), reordered.data(), n, vertex_count);
  std::uint32_t next = static_cast<std::uint32_t>(used);
  for (auto& r : remap) {
    if (r == ~0u) r = next++;
  }
  for (std::size_t i = 0; i < n; ++i) indices[i] = remap[reordered[i]];
  return remap;
}

Bytes meshopt_encode_attributes(ByteView data, std::size_t count, std::size_t stride) {
  if (stride == 0 || stride % 4 != 0 || stride > 256 || data.size() != count * stride)
    throw_internal("meshopt: attribute stride " + std::to_string(stride) + " for " +
                   std::to_string(data.size()) + " bytes of " + std::to_string(count) +
                   " elements");
  Bytes out(meshopt_encodeVertexBufferBound(count, stride));
  out.resize(meshopt_encodeVertexBuffer(out.data(), out.size(), data.data(), count, stride));
  if (out.empty()) throw_internal("meshopt: attribute encoding failed");
  return out;
}

Bytes meshopt_encode_triangles(std::span<const std::uint32_t> indices, std::size_t vertex_count) {
  if (indices.size() % 3 != 0) throw_internal("meshopt: index count not a multiple of 3");
  Bytes out(meshopt_encodeIndexBufferBound(indices.size(), vertex_count));
  out.resize(meshopt_encodeIndexBuffer(out.data(), out.size(), indices.data(), indices.size()));
  if (out.empty()) throw_internal("meshopt: index encoding failed");
  return out;
}

Bytes meshopt_decode_attributes(ByteView in, std::size_t count, std::size_t stride,
                                const char* context) {
  Bytes out(count * stride);
  if (meshopt_decodeVertexBuffer(out.data(), count, stride, in.data(), in.size()) != 0)
    throw_corrupt(std::string(context) + ": not a meshopt attribute stream of " +
                  std::to_string(count) + " x " + std::to_string(stride) + " bytes");
  return out;
}

std::vector<std::uint32_t> meshopt_decode_triangles(ByteView in, std::size_t index_count,
                                                    const char* context) {
  std::vector<std::uint32_t> out(index_count);
  if (meshopt_decodeIndexBuffer(out.data(), index_count, sizeof(std::uint32_t), in.data(),
                                in.size()) != 0)
    throw_corrupt(std::string(context) + ": not a meshopt triangle stream of " +
                  std::to_string(index_count) + " indices");
  return out;
}

}  // namespace smr::storage
