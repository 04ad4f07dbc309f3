// Geometry codecs: the raw and zstd layouts and the dispatch; Draco lives in codec_draco.cpp and
// zstd in codec_zstd.cpp (one file per third-party library).
//
// Every layout starts with varint position count and varint face count. Then:
//   raw:   positions as 3 x int32 LE, faces as 3 x uint32 LE.
//   zstd:  one zstd frame of: per position, 3 svarints (delta to the previous position, per axis);
//          per face corner, 1 svarint (delta to the previous corner's index).
//   draco: see codec_draco.cpp.
#include "storage/codec.h"

#include <cstdint>
#include <string>

#include "base/error.h"
#include "storage/codec_draco.h"

namespace smr::storage {
namespace {

constexpr std::uint64_t kMaxPositions = std::uint64_t{1} << 32;  // face indices are uint32

void validate_for_encoding(CodecId codec, const GeometryBlob& blob) {
  if (blob.positions.size() > kMaxPositions) {
    throw_input(std::string(codec_name(codec)) +
                " codec: " + std::to_string(blob.positions.size()) + " positions (at most 2^32)");
  }
  const std::size_t n = blob.positions.size();
  for (std::size_t f = 0; f < blob.faces.size(); ++f) {
    for (std::uint32_t v : blob.faces[f]) {
      if (v >= n) {
        throw_input(std::string(codec_name(codec)) + " codec: face " + std::to_string(f) +
                    " refers to position " + std::to_string(v) + " of " + std::to_string(n));
      }
    }
  }
}

void encode_raw(const GeometryBlob& blob, Bytes& out) {
  ByteWriter w(out);
  w.varint(blob.positions.size());
  w.varint(blob.faces.size());
  out.reserve(out.size() + 12 * (blob.positions.size() + blob.faces.size()));
  for (const auto& p : blob.positions) {
    for (std::int32_t c : p) w.u32(static_cast<std::uint32_t>(c));
  }
  for (const auto& f : blob.faces) {
    for (std::uint32_t v : f) w.u32(v);
  }
}

GeometryBlob decode_raw(ByteReader& r) {
  const std::uint64_t np = r.varint();
  const std::uint64_t nf = r.varint();
  if (np > r.remaining() / 12 || nf > r.remaining() / 12 || (np + nf) * 12 != r.remaining()) {
    r.fail("raw geometry: " + std::to_string(np) + " positions and " + std::to_string(nf) +
           " faces do not match the " + std::to_string(r.remaining()) + " bytes that follow");
  }
  GeometryBlob blob;
  blob.positions.resize(np);
  for (auto& p : blob.positions) {
    for (std::int32_t& c : p) c = static_cast<std::int32_t>(r.u32());
  }
  blob.faces.resize(nf);
  for (std::size_t f = 0; f < nf; ++f) {
    for (std::uint32_t& v : blob.faces[f]) {
      v = r.u32();
      if (v >= np) {
        r.fail("raw geometry: face " + std::to_string(f) + " refers to position " +
               std::to_string(v) + " of " + std::to_string(np));
      }
    }
  }
  return blob;
}

void encode_zstd(const GeometryBlob& blob, Bytes& out) {
  Bytes stream;
  ByteWriter s(stream);
  std::array<std::int64_t, 3> prev{0, 0, 0};
  for (const auto& p : blob.positions) {
    for (int a = 0; a < 3; ++a) {
      s.svarint(p[a] - prev[a]);
      prev[a] = p[a];
    }
  }
  std::int64_t prev_index = 0;
  for (const auto& f : blob.faces) {
    for (std::uint32_t v : f) {
      s.svarint(static_cast<std::int64_t>(v) - prev_index);
      prev_index = v;
    }
  }
  ByteWriter w(out);
  w.varint(blob.positions.size());
  w.varint(blob.faces.size());
  w.bytes(zstd_compress(stream, 3));
}

GeometryBlob decode_zstd(ByteReader& r) {
  const std::uint64_t np = r.varint();
  const std::uint64_t nf = r.varint();
  if (np > kMaxPositions || nf > kMaxPositions) {
    r.fail("zstd geometry: implausible counts " + std::to_string(np) + " positions, " +
           std::to_string(nf) + " faces");
  }
  // Every coordinate and index delta is a varint of at most 5 bytes.
  const Bytes stream = zstd_decompress(r.bytes(r.remaining()), 15 * (np + nf), r.context());
  ByteReader s(stream, r.context());
  if (3 * (np + nf) > stream.size()) {
    s.fail("zstd geometry: " + std::to_string(stream.size()) + " bytes cannot hold " +
           std::to_string(np) + " positions and " + std::to_string(nf) + " faces");
  }
  GeometryBlob blob;
  blob.positions.resize(np);
  std::array<std::int64_t, 3> prev{0, 0, 0};
  for (auto& p : blob.positions) {
    for (int a = 0; a < 3; ++a) {
      const std::int64_t delta = s.svarint();
      if (delta < -(std::int64_t{1} << 33) || delta > (std::int64_t{1} << 33))
        s.fail("zstd geometry: coordinate out of int32 range");
      const std::int64_t c = prev[a] + delta;
      if (c < INT32_MIN || c > INT32_MAX) s.fail("zstd geometry: coordinate out of int32 range");
      p[a] = static_cast<std::int32_t>(c);
      prev[a] = c;
    }
  }
  blob.faces.resize(nf);
  std::int64_t prev_index = 0;
  for (std::size_t f = 0; f < nf; ++f) {
    for (std::uint32_t& v : blob.faces[f]) {
      const std::int64_t delta = s.svarint();
      if (delta < -(std::int64_t{1} << 33) || delta > (std::int64_t{1} << 33))
        s.fail("zstd geometry: face " + std::to_string(f) + " refers to a position out of range");
      const std::int64_t index = prev_index + delta;
      if (index < 0 || static_cast<std::uint64_t>(index) >= np) {
        s.fail("zstd geometry: face " + std::to_string(f) + " refers to a position out of range");
      }
      v = static_cast<std::uint32_t>(index);
      prev_index = index;
    }
  }
  s.expect_end();
  return blob;
}

}  // namespace

std::string_view codec_name(CodecId codec) {
  switch (codec) {
    case CodecId::kRaw:
      return "raw";
    case CodecId::kZstd:
      return "zstd";
    case CodecId::kDraco:
      return "draco";
  }
  return "?";
}

std::optional<CodecId> parse_codec(std::string_view name) {
  for (CodecId c : {CodecId::kRaw, CodecId::kZstd, CodecId::kDraco}) {
    if (codec_name(c) == name) return c;
  }
  return std::nullopt;
}

void encode_geometry(CodecId codec, const GeometryBlob& blob, Bytes& out) {
  validate_for_encoding(codec, blob);
  switch (codec) {
    case CodecId::kRaw:
      return encode_raw(blob, out);
    case CodecId::kZstd:
      return encode_zstd(blob, out);
    case CodecId::kDraco:
      return detail::draco_encode(blob, out);
  }
  throw_internal("encode_geometry: unknown codec id " + std::to_string(static_cast<int>(codec)));
}

GeometryBlob decode_geometry(CodecId codec, ByteView in, std::string_view context) {
  ByteReader r(in, std::string(context));
  switch (codec) {
    case CodecId::kRaw:
      return decode_raw(r);
    case CodecId::kZstd:
      return decode_zstd(r);
    case CodecId::kDraco:
      return detail::draco_decode(in, context);
  }
  r.fail("unknown geometry codec id " + std::to_string(static_cast<int>(codec)));
}

}  // namespace smr::storage
