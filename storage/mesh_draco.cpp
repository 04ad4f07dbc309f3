// Draco for glTF's KHR_draco_mesh_compression (storage/mesh_compress.h): a mesh with an integer
// POSITION attribute (3 x uint16) and, optionally, a normalized integer NORMAL (3 x int8 or
// int16), edgebreaker connectivity. Integer attributes are not quantized by Draco, so the codec
// is lossless: a loader decodes exactly the integers the glTF accessors declare
// (KHR_mesh_quantization types). The storage codec (codec_draco.cpp) is the other file that
// includes Draco; both stay inside storage/.
#include <draco/compression/decode.h>
#include <draco/compression/expert_encode.h>
#include <draco/mesh/mesh.h>

#include <memory>
#include <string>

#include "base/error.h"
#include "storage/mesh_compress.h"

namespace smr::storage {
namespace {

int add_attribute(draco::Mesh& mesh, draco::GeometryAttribute::Type type, draco::DataType dt,
                  bool normalized, int component_bytes) {
  draco::GeometryAttribute ga;
  ga.Init(type, nullptr, 3, dt, normalized, 3 * component_bytes, 0);
  return mesh.AddAttribute(ga, true, mesh.num_points());
}

std::unique_ptr<draco::Mesh> to_draco(const QuantizedMesh& in, int& position_id, int& normal_id) {
  auto mesh = std::make_unique<draco::Mesh>();
  const auto n = static_cast<std::uint32_t>(in.positions.size());
  mesh->set_num_points(n);
  position_id = add_attribute(*mesh, draco::GeometryAttribute::POSITION, draco::DT_UINT16, false,
                              sizeof(std::uint16_t));
  draco::PointAttribute* pos = mesh->attribute(position_id);
  for (std::uint32_t i = 0; i < n; ++i)
    pos->SetAttributeValue(draco::AttributeValueIndex(i), in.positions[i].data());
  normal_id = -1;
  if (!in.normals.empty()) {
    const bool bytes8 = in.normal_bits == 8;
    normal_id = add_attribute(*mesh, draco::GeometryAttribute::NORMAL,
                              bytes8 ? draco::DT_INT8 : draco::DT_INT16, true, bytes8 ? 1 : 2);
    draco::PointAttribute* nor = mesh->attribute(normal_id);
    for (std::uint32_t i = 0; i < n; ++i) {
      if (bytes8) {
        std::int8_t v[3];
        for (int k = 0; k < 3; ++k) v[k] = static_cast<std::int8_t>(in.normals[i][k]);
        nor->SetAttributeValue(draco::AttributeValueIndex(i), v);
      } else {
        nor->SetAttributeValue(draco::AttributeValueIndex(i), in.normals[i].data());
      }
    }
  }
  mesh->SetNumFaces(in.triangles.size());
  for (std::uint32_t f = 0; f < in.triangles.size(); ++f) {
    const auto& t = in.triangles[f];
    for (std::uint32_t v : t) {
      if (v >= n)
        throw_input("draco: triangle " + std::to_string(f) + " references vertex " +
                    std::to_string(v) + " of " + std::to_string(n));
    }
    mesh->SetFace(draco::FaceIndex(f),
                  {draco::PointIndex(t[0]), draco::PointIndex(t[1]), draco::PointIndex(t[2])});
  }
  return mesh;
}

}  // namespace

DracoMesh draco_encode_mesh(const QuantizedMesh& mesh) {
  DracoMesh out;
  const std::unique_ptr<draco::Mesh> dm = to_draco(mesh, out.position_id, out.normal_id);
  draco::ExpertEncoder encoder(*dm);
  encoder.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
  // Integer positions: parallelogram prediction; integer normals: plain differences (Draco's
  // geometric normal prediction needs float normals it quantizes itself).
  auto set = [&](int att, draco::PredictionSchemeMethod method) {
    const draco::Status s = encoder.SetAttributePredictionScheme(att, method);
    if (!s.ok()) throw_internal("draco: " + s.error_msg_string());
  };
  set(out.position_id, draco::MESH_PREDICTION_PARALLELOGRAM);
  if (out.normal_id >= 0) set(out.normal_id, draco::PREDICTION_DIFFERENCE);
  encoder.SetSpeedOptions(3, 3);
  draco::EncoderBuffer buffer;
  const draco::Status s = encoder.EncodeToBuffer(&buffer);
  if (!s.ok()) throw_internal("draco: encoding failed: " + s.error_msg_string());
  const auto* data = reinterpret_cast<const std::uint8_t*>(buffer.data());
  out.bytes.assign(data, data + buffer.size());
  return out;
}

QuantizedMesh draco_decode_mesh(ByteView in, const DracoMesh& ids, int normal_bits,
                                const char* context) {
  const std::string where(context);
  draco::DecoderBuffer buffer;
  buffer.Init(reinterpret_cast<const char*>(in.data()), in.size());
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  if (!decoded.ok()) throw_corrupt(where + ": draco: " + decoded.status().error_msg_string());
  const std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();
  const auto attribute = [&](int id, const char* what) {
    const draco::PointAttribute* att = mesh->GetAttributeByUniqueId(static_cast<std::uint32_t>(id));
    if (att == nullptr || att->num_components() != 3)
      throw_corrupt(where + ": draco: no 3-component " + what + " attribute with id " +
                    std::to_string(id));
    return att;
  };
  QuantizedMesh out;
  out.normal_bits = normal_bits;
  const std::uint32_t n = mesh->num_points();
  const draco::PointAttribute* pos = attribute(ids.position_id, "POSITION");
  out.positions.resize(n);
  for (std::uint32_t i = 0; i < n; ++i)
    pos->ConvertValue<std::uint16_t, 3>(pos->mapped_index(draco::PointIndex(i)),
                                        out.positions[i].data());
  if (ids.normal_id >= 0) {
    const draco::PointAttribute* nor = attribute(ids.normal_id, "NORMAL");
    out.normals.resize(n);
    for (std::uint32_t i = 0; i < n; ++i) {
      // Read the stored integers, not the normalized floats ConvertValue would make of them.
      if (normal_bits == 8) {
        std::int8_t v[3];
        nor->GetMappedValue(draco::PointIndex(i), v);
        for (int k = 0; k < 3; ++k) out.normals[i][k] = v[k];
      } else {
        nor->GetMappedValue(draco::PointIndex(i), out.normals[i].data());
      }
    }
  }
  out.triangles.resize(mesh->num_faces());
  for (std::uint32_t f = 0; f < mesh->num_faces(); ++f) {
    const auto& face = mesh->face(draco::FaceIndex(f));
    for (int k = 0; k < 3; ++k) out.triangles[f][k] = face[k].value();
  }
  return out;
}

}  // namespace smr::storage
