// The one place Draco is used (docs/design.md section 3, "Geometry codec").
//
// Layout: varint position count, varint face count; if there are positions, the per-axis minimum
// (3 svarints), a shift s (u8) and a Draco geometry with the "DRACO" magic stripped: a mesh, or a
// point cloud when there are no faces (Draco cannot decode a mesh without faces). Draco also
// cannot decode a mesh with points no face uses: those ride in extra faces after the real ones.
//
// Positions are stored relative to the minimum, v = p - min in [0, 2^32), as integer attributes,
// so the coding is lossless: the same integer position decodes identically in every blob (no
// cracks). Draco's entropy coder sizes a histogram by the largest symbol (ComputeShannonEntropy:
// 2^28-unit spans cost seconds and gigabytes), so a span wider than 2^16 is split: the POSITION
// attribute holds v >> s (below 2^16) and a GENERIC attribute the low s bits (no prediction; at
// such spacing they are noise anyway). Draco's sequential mesh coding keeps point order and face
// order and rotation; connectivity is entropy-coded index deltas ("compress_connectivity") and
// positions are delta-predicted and entropy-coded. Edgebreaker would reorder points and faces:
// restoring the order would cost log2(np!) + log2(nf!) + nf log2(3) bits per blob, ~1.8 B/face on
// a 968-face grid chunk, more than edgebreaker saves (tests/storage/codec_test.cpp, CodecSizes).
#include <algorithm>
#include <bit>
#include <cstring>
#include <limits>
#include <memory>
#include <string>

#include <draco/compression/decode.h>
#include <draco/compression/expert_encode.h>
#include <draco/mesh/mesh.h>

#include "base/error.h"
#include "storage/codec_draco.h"

namespace smr::storage::detail {
namespace {

constexpr char kMagic[] = {'D', 'R', 'A', 'C', 'O'};
constexpr int kHighBits = 16;  // largest span stored in one attribute: 2^16 - 1
constexpr int kMaxShift = 32 - kHighBits;

struct Frame {
  std::array<std::int64_t, 3> min{};
  int shift = 0;
};

Frame frame_of(const GeometryBlob& blob) {
  Frame frame;
  std::array<std::int64_t, 3> hi{};
  for (int a = 0; a < 3; ++a) frame.min[a] = hi[a] = blob.positions.front()[a];
  for (const auto& p : blob.positions) {
    for (int a = 0; a < 3; ++a) {
      frame.min[a] = std::min<std::int64_t>(frame.min[a], p[a]);
      hi[a] = std::max<std::int64_t>(hi[a], p[a]);
    }
  }
  std::uint64_t span = 0;
  for (int a = 0; a < 3; ++a)
    span = std::max(span, static_cast<std::uint64_t>(hi[a] - frame.min[a]));
  const int bits = static_cast<int>(std::bit_width(span));
  frame.shift = bits > kHighBits ? bits - kHighBits : 0;
  return frame;
}

int add_attribute(draco::PointCloud& pc, draco::GeometryAttribute::Type type) {
  draco::GeometryAttribute ga;
  ga.Init(type, nullptr, 3, draco::DT_INT32, false, 3 * sizeof(std::int32_t), 0);
  return pc.AddAttribute(ga, true, pc.num_points());
}

std::unique_ptr<draco::Mesh> to_draco(const GeometryBlob& blob, const Frame& frame) {
  auto mesh = std::make_unique<draco::Mesh>();
  const auto np = static_cast<draco::PointIndex::ValueType>(blob.positions.size());
  mesh->set_num_points(np);
  draco::PointAttribute* high =
      mesh->attribute(add_attribute(*mesh, draco::GeometryAttribute::POSITION));
  draco::PointAttribute* low =
      frame.shift > 0 ? mesh->attribute(add_attribute(*mesh, draco::GeometryAttribute::GENERIC))
                      : nullptr;
  const std::uint32_t mask = (std::uint32_t{1} << frame.shift) - 1;
  for (std::uint32_t i = 0; i < np; ++i) {
    std::int32_t h[3], l[3];
    for (int a = 0; a < 3; ++a) {
      const auto v = static_cast<std::uint32_t>(blob.positions[i][a] - frame.min[a]);
      h[a] = static_cast<std::int32_t>(v >> frame.shift);
      l[a] = static_cast<std::int32_t>(v & mask);
    }
    high->SetAttributeValue(draco::AttributeValueIndex(i), h);
    if (low != nullptr) low->SetAttributeValue(draco::AttributeValueIndex(i), l);
  }
  mesh->SetNumFaces(blob.faces.size());
  for (std::uint32_t f = 0; f < blob.faces.size(); ++f) {
    const auto& face = blob.faces[f];
    mesh->SetFace(draco::FaceIndex(f), {draco::PointIndex(face[0]), draco::PointIndex(face[1]),
                                        draco::PointIndex(face[2])});
  }
  if (blob.faces.empty()) return mesh;
  // Draco cannot decode a mesh with points no face refers to: carry them in extra faces after
  // the real ones (three per face, the last one padded), which decoding drops.
  std::vector<bool> used(np, false);
  for (const auto& face : blob.faces) {
    for (std::uint32_t v : face) used[v] = true;
  }
  std::vector<draco::PointIndex> unused;
  for (std::uint32_t i = 0; i < np; ++i) {
    if (!used[i]) unused.emplace_back(i);
  }
  for (std::size_t k = 0; k < unused.size(); k += 3) {
    const draco::PointIndex a = unused[k];
    const draco::PointIndex b = k + 1 < unused.size() ? unused[k + 1] : a;
    const draco::PointIndex c = k + 2 < unused.size() ? unused[k + 2] : b;
    mesh->AddFace({a, b, c});
  }
  return mesh;
}

draco::EncoderBuffer encode_mesh(const draco::Mesh& mesh, int method) {
  // A mesh without faces goes as a point cloud: Draco fails to decode a mesh with no faces.
  draco::ExpertEncoder encoder =
      mesh.num_faces() == 0 ? draco::ExpertEncoder(static_cast<const draco::PointCloud&>(mesh))
                            : draco::ExpertEncoder(mesh);
  encoder.SetEncodingMethod(mesh.num_faces() == 0 ? draco::POINT_CLOUD_SEQUENTIAL_ENCODING
                                                  : method);
  for (int att = 1; att < mesh.num_attributes(); ++att) {  // the low bits: no prediction
    const draco::Status status = encoder.SetAttributePredictionScheme(att, draco::PREDICTION_NONE);
    if (!status.ok()) throw_internal("draco codec: " + status.error_msg_string());
  }
  encoder.options().SetGlobalBool("compress_connectivity", true);
  encoder.SetSpeedOptions(0, 0);  // best compression of the entropy coder
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodeToBuffer(&buffer);
  if (!status.ok()) throw_internal("draco codec: encoding failed: " + status.error_msg_string());
  return buffer;
}

}  // namespace

void draco_encode(const GeometryBlob& blob, Bytes& out) {
  ByteWriter w(out);
  w.varint(blob.positions.size());
  w.varint(blob.faces.size());
  if (blob.positions.empty()) return;
  const Frame frame = frame_of(blob);
  for (std::int64_t c : frame.min) w.svarint(c);
  w.u8(static_cast<std::uint8_t>(frame.shift));
  const draco::EncoderBuffer buffer =
      encode_mesh(*to_draco(blob, frame), draco::MESH_SEQUENTIAL_ENCODING);
  const auto* data = reinterpret_cast<const std::uint8_t*>(buffer.data());
  if (buffer.size() < sizeof kMagic || std::memcmp(data, kMagic, sizeof kMagic) != 0) {
    throw_internal("draco codec: encoder output does not start with the DRACO magic");
  }
  w.bytes(ByteView(data, buffer.size()).subspan(sizeof kMagic));
}

GeometryBlob draco_decode(ByteView in, std::string_view context) {
  ByteReader r(in, std::string(context));
  const std::uint64_t np = r.varint();
  const std::uint64_t nf = r.varint();
  if (np == 0) {
    if (nf != 0) r.fail("draco geometry: " + std::to_string(nf) + " faces but no positions");
    r.expect_end();
    return {};
  }
  if (np > std::numeric_limits<std::uint32_t>::max() ||
      nf > std::numeric_limits<std::uint32_t>::max()) {
    r.fail("draco geometry: implausible counts " + std::to_string(np) + " positions, " +
           std::to_string(nf) + " faces");
  }
  Frame frame;
  for (std::int64_t& c : frame.min) {
    c = r.svarint();
    if (c < std::numeric_limits<std::int32_t>::min() ||
        c > std::numeric_limits<std::int32_t>::max()) {
      r.fail("draco geometry: minimum coordinate out of int32 range");
    }
  }
  frame.shift = r.u8();
  if (frame.shift > kMaxShift) r.fail("draco geometry: bad shift " + std::to_string(frame.shift));
  const ByteView payload = r.bytes(r.remaining());
  std::vector<char> buffer(sizeof kMagic + payload.size());
  std::memcpy(buffer.data(), kMagic, sizeof kMagic);
  if (!payload.empty()) std::memcpy(buffer.data() + sizeof kMagic, payload.data(), payload.size());

  draco::DecoderBuffer in_buffer;
  in_buffer.Init(buffer.data(), buffer.size());
  draco::Decoder decoder;
  std::unique_ptr<draco::PointCloud> pc;
  const draco::Mesh* mesh = nullptr;
  if (nf == 0) {
    // Draco sizes a point cloud's attributes from the int32 point count in its header (after the
    // version, encoder type and method, and u16 flags) before reading any of them: a damaged
    // count would allocate gigabytes. It must be the blob's own.
    std::int32_t header_points = 0;
    if (payload.size() >= 10) std::memcpy(&header_points, payload.data() + 6, 4);
    if (payload.size() < 10 || std::uint64_t(header_points) != np || header_points < 0)
      r.fail("draco geometry: the point cloud's header does not hold its " + std::to_string(np) +
             " points");
    auto decoded = decoder.DecodePointCloudFromBuffer(&in_buffer);
    if (!decoded.ok()) r.fail("draco geometry: " + decoded.status().error_msg_string());
    pc = std::move(decoded).value();
  } else {
    auto decoded = decoder.DecodeMeshFromBuffer(&in_buffer);
    if (!decoded.ok()) r.fail("draco geometry: " + decoded.status().error_msg_string());
    std::unique_ptr<draco::Mesh> m = std::move(decoded).value();
    mesh = m.get();
    pc = std::move(m);
  }
  // A mesh may carry extra faces after the real ones (see to_draco), at most one per 3 points.
  if (pc == nullptr || pc->num_points() != np ||
      (mesh != nullptr && (mesh->num_faces() < nf || mesh->num_faces() - nf > (np + 2) / 3))) {
    r.fail("draco geometry: decoded geometry does not have the " + std::to_string(np) +
           " positions and " + std::to_string(nf) + " faces recorded");
  }
  const auto attribute = [&](draco::GeometryAttribute::Type type) {
    const draco::PointAttribute* att = pc->GetNamedAttribute(type);
    if (att == nullptr || att->num_components() != 3 || att->data_type() != draco::DT_INT32 ||
        att->byte_stride() != 3 * sizeof(std::int32_t)) {
      r.fail("draco geometry: missing 3 x int32 attribute");
    }
    return att;
  };
  const draco::PointAttribute* high = attribute(draco::GeometryAttribute::POSITION);
  const draco::PointAttribute* low =
      frame.shift > 0 ? attribute(draco::GeometryAttribute::GENERIC) : nullptr;
  const auto value = [&](const draco::PointAttribute* att, std::uint32_t i, std::int32_t* out) {
    const draco::AttributeValueIndex index = att->mapped_index(draco::PointIndex(i));
    if (index.value() >= att->size()) r.fail("draco geometry: bad attribute mapping");
    att->GetValue(index, out);
  };

  GeometryBlob blob;
  blob.positions.resize(np);
  const std::int64_t high_limit = std::int64_t{1} << (32 - frame.shift);
  const std::int64_t low_limit = std::int64_t{1} << frame.shift;
  for (std::uint32_t i = 0; i < np; ++i) {
    std::int32_t h[3] = {0, 0, 0}, l[3] = {0, 0, 0};
    value(high, i, h);
    if (low != nullptr) value(low, i, l);
    for (int a = 0; a < 3; ++a) {
      if (h[a] < 0 || h[a] >= high_limit || l[a] < 0 || l[a] >= low_limit) {
        r.fail("draco geometry: position " + std::to_string(i) + " out of range");
      }
      const std::int64_t c = frame.min[a] + ((std::int64_t{h[a]} << frame.shift) | l[a]);
      if (c > std::numeric_limits<std::int32_t>::max()) {
        r.fail("draco geometry: position " + std::to_string(i) + " out of range");
      }
      blob.positions[i][a] = static_cast<std::int32_t>(c);
    }
  }
  if (nf == 0) return blob;
  blob.faces.resize(nf);
  for (std::uint32_t f = 0; f < nf; ++f) {
    const draco::Mesh::Face& face = mesh->face(draco::FaceIndex(f));
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t v = face[k].value();
      if (v >= np) {
        r.fail("draco geometry: face " + std::to_string(f) + " refers to position " +
               std::to_string(v) + " of " + std::to_string(np));
      }
      blob.faces[f][k] = v;
    }
  }
  return blob;
}

std::size_t draco_edgebreaker_size(const GeometryBlob& blob) {
  if (blob.positions.empty() || blob.faces.empty()) return 0;
  const draco::EncoderBuffer buffer =
      encode_mesh(*to_draco(blob, frame_of(blob)), draco::MESH_EDGEBREAKER_ENCODING);
  return buffer.size() - sizeof kMagic;
}

}  // namespace smr::storage::detail
