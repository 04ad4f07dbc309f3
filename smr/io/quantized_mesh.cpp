// quantized-mesh-1.0 encoder (quantized_mesh.h), after the format's specification
// (CesiumGS/quantized-mesh README): header, VertexData with zig-zag deltas, IndexData16/32 with
// high-water-mark codes after alignment padding, EdgeIndices16/32, extensions with a 1-byte id and
// a 4-byte length.
#include "smr/io/quantized_mesh.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

#include "base/error.h"

namespace smr {

namespace {

constexpr std::uint16_t kMaxCoordinate = 32767;
constexpr std::uint8_t kExtensionOctNormals = 1, kExtensionMetadata = 4;

class Out {
 public:
  template <typename T>
  void put(T v) {
    std::uint8_t b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if constexpr (std::endian::native == std::endian::big) std::reverse(b, b + sizeof(T));
    bytes.insert(bytes.end(), b, b + sizeof(T));
  }
  void put(const Vec3& p) {
    put(p.x);
    put(p.y);
    put(p.z);
  }
  void align(std::size_t n) {
    while (bytes.size() % n != 0) bytes.push_back(0);
  }
  std::vector<std::uint8_t> bytes;
};

std::uint16_t zig_zag(int delta) {
  return static_cast<std::uint16_t>((delta << 1) ^ (delta >> 31));
}

void put_deltas(Out& out, const std::vector<std::uint16_t>& values) {
  int previous = 0;
  for (std::uint16_t v : values) {
    if (v > kMaxCoordinate) throw_internal("quantized-mesh: coordinate above 32767");
    out.put(zig_zag(int(v) - previous));
    previous = v;
  }
}

template <typename Index>
void put_indices(Out& out, const QuantizedMeshTile& t) {
  out.align(sizeof(Index));
  out.put(static_cast<std::uint32_t>(t.triangles.size()));
  std::uint32_t highest = 0;
  for (const auto& tri : t.triangles) {
    for (std::uint32_t i : tri) {
      if (i > highest || i >= t.u.size())
        throw_internal("quantized-mesh: vertex " + std::to_string(i) +
                       " used before the vertices numbered below it");
      out.put(static_cast<Index>(highest - i));
      if (i == highest) ++highest;
    }
  }
  for (const auto* edge : {&t.west, &t.south, &t.east, &t.north}) {
    out.put(static_cast<std::uint32_t>(edge->size()));
    for (std::uint32_t i : *edge) {
      if (i >= t.u.size()) throw_internal("quantized-mesh: edge vertex out of range");
      out.put(static_cast<Index>(i));
    }
  }
}

std::uint8_t to_snorm(double v) {
  return static_cast<std::uint8_t>(std::round((std::clamp(v, -1.0, 1.0) * 0.5 + 0.5) * 255.0));
}

}  // namespace

std::array<std::uint8_t, 2> oct_encode(const Vec3& n) {
  const double l1 = std::abs(n.x) + std::abs(n.y) + std::abs(n.z);
  double x = n.x / l1, y = n.y / l1;
  if (n.z < 0) {  // fold the lower hemisphere over the diagonals
    const double fx = (1.0 - std::abs(y)) * (x >= 0 ? 1.0 : -1.0);
    const double fy = (1.0 - std::abs(x)) * (y >= 0 ? 1.0 : -1.0);
    x = fx;
    y = fy;
  }
  return {to_snorm(x), to_snorm(y)};
}

std::vector<std::uint8_t> encode_quantized_mesh(const QuantizedMeshTile& t) {
  const std::size_t n = t.u.size();
  if (t.v.size() != n || t.height.size() != n || (!t.normals.empty() && t.normals.size() != n))
    throw_internal("quantized-mesh: per-vertex arrays of different lengths");
  Out out;
  out.bytes.reserve(88 + n * 8 + t.triangles.size() * 6 + 64 + t.metadata.size());
  out.put(t.center);
  out.put(t.min_height);
  out.put(t.max_height);
  out.put(t.sphere_center);
  out.put(t.sphere_radius);
  out.put(t.horizon_occlusion);
  out.put(static_cast<std::uint32_t>(n));
  put_deltas(out, t.u);
  put_deltas(out, t.v);
  put_deltas(out, t.height);
  if (n > 65536) {
    put_indices<std::uint32_t>(out, t);
  } else {
    put_indices<std::uint16_t>(out, t);
  }
  if (!t.normals.empty()) {
    out.put(kExtensionOctNormals);
    out.put(static_cast<std::uint32_t>(2 * n));
    for (const Vec3& nrm : t.normals) {
      const auto e = oct_encode(nrm);
      out.put(e[0]);
      out.put(e[1]);
    }
  }
  if (!t.metadata.empty()) {
    out.put(kExtensionMetadata);
    out.put(static_cast<std::uint32_t>(4 + t.metadata.size()));
    out.put(static_cast<std::uint32_t>(t.metadata.size()));
    out.bytes.insert(out.bytes.end(), t.metadata.begin(), t.metadata.end());
  }
  return std::move(out.bytes);
}

}  // namespace smr
