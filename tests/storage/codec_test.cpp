#include "storage/codec.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

#include "storage/codec_draco.h"
#include "storage_test_helpers.h"

namespace smr::storage {
namespace {

using test::expect_error;

constexpr CodecId kCodecs[] = {CodecId::kRaw, CodecId::kZstd, CodecId::kDraco};

// An n x n grid of points around `origin` (step `step`, random heights), two triangles per cell;
// then positions are permuted, faces shuffled and each face rotated at random, and `isolated`
// positions no face refers to are added.
GeometryBlob grid_mesh(int n, std::array<std::int32_t, 3> origin, std::int32_t step,
                       std::uint64_t seed, int isolated = 0, bool shuffle = true,
                       bool smooth = false) {
  std::mt19937_64 rng(seed);
  GeometryBlob blob;
  for (int y = 0; y < n; ++y) {
    for (int x = 0; x < n; ++x) {
      // Random heights (worst case), or a smooth terrain-like surface with a little noise.
      const auto z =
          smooth ? static_cast<std::int32_t>(400 * std::sin(x / 5.0) + 300 * std::cos(y / 7.0) +
                                             static_cast<double>(rng() % 8))
                 : static_cast<std::int32_t>(rng() % 2000);
      blob.positions.push_back({origin[0] + x * step, origin[1] + y * step, origin[2] + z});
    }
  }
  const auto at = [n](int x, int y) { return static_cast<std::uint32_t>(y * n + x); };
  for (int y = 0; y + 1 < n; ++y) {
    for (int x = 0; x + 1 < n; ++x) {
      blob.faces.push_back({at(x, y), at(x + 1, y), at(x + 1, y + 1)});
      blob.faces.push_back({at(x, y), at(x + 1, y + 1), at(x, y + 1)});
    }
  }
  for (int i = 0; i < isolated; ++i) {
    blob.positions.push_back({origin[0] - 5 - i, origin[1] + i, origin[2]});
  }
  if (shuffle) {
    std::vector<std::uint32_t> perm(blob.positions.size());
    std::iota(perm.begin(), perm.end(), 0u);
    std::shuffle(perm.begin(), perm.end(), rng);
    std::vector<std::array<std::int32_t, 3>> positions(blob.positions.size());
    for (std::size_t i = 0; i < perm.size(); ++i) positions[perm[i]] = blob.positions[i];
    blob.positions = positions;
    for (auto& f : blob.faces) {
      for (auto& v : f) v = perm[v];
      std::rotate(f.begin(), f.begin() + static_cast<std::ptrdiff_t>(rng() % 3), f.end());
    }
    std::shuffle(blob.faces.begin(), blob.faces.end(), rng);
  }
  return blob;
}

Bytes encode(CodecId codec, const GeometryBlob& blob) {
  Bytes out;
  encode_geometry(codec, blob, out);
  return out;
}

TEST(Codec, NamesParse) {
  for (CodecId c : kCodecs) EXPECT_EQ(parse_codec(codec_name(c)), c);
  EXPECT_EQ(codec_name(CodecId::kDraco), "draco");
  EXPECT_FALSE(parse_codec("gzip").has_value());
}

TEST(Codec, RoundTripIsExactOnShuffledRotatedGrids) {
  const std::array<std::int32_t, 3> origins[] = {
      {0, 0, 0}, {1 << 28, 1 << 28, 1 << 28}, {-(1 << 28), -7, -(1 << 29)}, {-3, 5, -1000}};
  std::uint64_t seed = 0;
  for (CodecId codec : kCodecs) {
    for (const auto& origin : origins) {
      for (int n : {2, 3, 12, 23}) {
        for (int isolated : {0, 3}) {
          ++seed;
          const GeometryBlob blob =
              grid_mesh(n, origin, 1 + static_cast<std::int32_t>(seed % 1000), seed, isolated);
          Bytes out = {0xee};  // encode appends
          encode_geometry(codec, blob, out);
          ASSERT_EQ(out[0], 0xee);
          const GeometryBlob back =
              decode_geometry(codec, ByteView(out).subspan(1), "pages/" + std::to_string(seed));
          ASSERT_EQ(back, blob) << codec_name(codec) << " n=" << n << " seed=" << seed;
        }
      }
    }
  }
}

TEST(Codec, EdgeCasesRoundTrip) {
  std::vector<GeometryBlob> blobs;
  blobs.push_back({});                                                        // empty
  blobs.push_back({{{1, 2, 3}}, {}});                                         // one point, no face
  blobs.push_back({{{-1, -2, -3}, {4, 5, 6}, {7, 8, 9}, {10, 11, 12}}, {}});  // points only
  blobs.push_back({{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{1, 2, 0}}});          // one face
  blobs.push_back({{{5, 5, 5}, {5, 5, 5}, {5, 5, 5}}, {{2, 1, 0}, {0, 1, 2}}});  // duplicates
  blobs.push_back({{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 0, 0}, {0, 1, 2}, {0, 1, 2}}});
  blobs.push_back({{{(1 << 30) - 1, -(1 << 29), 0}, {0, (1 << 29) - 1, 0}, {0, 0, 0}},
                   {{0, 1, 2}}});  // wide span
  for (CodecId codec : kCodecs) {
    for (std::size_t i = 0; i < blobs.size(); ++i) {
      const GeometryBlob back = decode_geometry(codec, encode(codec, blobs[i]), "edge");
      EXPECT_EQ(back, blobs[i]) << codec_name(codec) << " case " << i;
    }
  }
}

TEST(Codec, SamePositionDecodesIdenticallyInEveryBlob) {
  // Two blobs sharing a vertex at a large coordinate, with different neighbourhoods.
  const std::array<std::int32_t, 3> shared = {268435457, -268435455, 123456789};
  const GeometryBlob a = {{shared, {shared[0] + 1000, shared[1], shared[2]}, {0, 0, 0}},
                          {{0, 1, 2}}};
  const GeometryBlob b = {{{shared[0] - 7, shared[1] - 9, shared[2] + 3},
                           shared,
                           {shared[0], shared[1] + 1, shared[2] - 500000}},
                          {{2, 1, 0}}};
  for (CodecId codec : kCodecs) {
    EXPECT_EQ(decode_geometry(codec, encode(codec, a), "a").positions[0], shared);
    EXPECT_EQ(decode_geometry(codec, encode(codec, b), "b").positions[1], shared);
  }
}

TEST(Codec, FullInt32RangeRoundTrips) {
  constexpr std::int32_t lo = std::numeric_limits<std::int32_t>::min();
  constexpr std::int32_t hi = std::numeric_limits<std::int32_t>::max();
  const GeometryBlob blob = {{{lo, hi, 0}, {hi, lo, -1}, {0, 0, hi}, {lo + 1, hi - 1, 12345}},
                             {{0, 1, 2}, {3, 2, 1}}};
  // Coarse grids spanning most of the int32 range (Draco splits wide spans into two attributes).
  const GeometryBlob coarse = grid_mesh(20, {-(1 << 30), -(1 << 30), 0}, 1 << 26, 3, 4);
  const GeometryBlob medium = grid_mesh(20, {-(1 << 20), 1 << 20, 0}, (1 << 12) + 1, 4, 4);
  for (CodecId codec : kCodecs) {
    EXPECT_EQ(decode_geometry(codec, encode(codec, blob), "x"), blob) << codec_name(codec);
    EXPECT_EQ(decode_geometry(codec, encode(codec, coarse), "x"), coarse) << codec_name(codec);
    EXPECT_EQ(decode_geometry(codec, encode(codec, medium), "x"), medium) << codec_name(codec);
  }
}

TEST(Codec, FaceIndexOutOfRangeIsInvalidInput) {
  const GeometryBlob blob = {{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}, {0, 3, 1}}};
  for (CodecId codec : kCodecs) {
    expect_error([&] { encode(codec, blob); }, ErrorKind::kInvalidInput,
                 std::string(codec_name(codec)) + " codec: face 1 refers to position 3 of 3");
  }
}

// Decoding must throw smr::Error (kCorrupt) or return a blob; never crash (run under ASan).
bool decodes(CodecId codec, ByteView in) {
  try {
    decode_geometry(codec, in, "pages/99");
    return true;
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kCorrupt) << e.what();
    EXPECT_EQ(std::string(e.what()).rfind("pages/99: ", 0), 0u) << e.what();
    return false;
  }
}

TEST(Codec, GarbageAndTruncationsThrow) {
  std::mt19937_64 rng(11);
  for (CodecId codec : kCodecs) {
    int accepted = 0;
    for (int i = 0; i < 3000; ++i) {
      const Bytes garbage = test::random_bytes(rng, rng() % 300);
      if (decodes(codec, garbage)) ++accepted;
    }
    // Random bytes essentially never form a valid page (a 1-byte {0, 0} prefix can: empty blob).
    EXPECT_LT(accepted, 30) << codec_name(codec);

    const GeometryBlob blob = grid_mesh(9, {100, -100, 1 << 20}, 3, 77, 2);
    const Bytes good = encode(codec, blob);
    for (std::size_t n = 0; n < good.size(); ++n) {
      EXPECT_FALSE(decodes(codec, ByteView(good.data(), n)))
          << codec_name(codec) << ": truncation to " << n << " of " << good.size() << " decoded";
    }
    Bytes longer = good;
    longer.push_back(0);
    if (codec != CodecId::kDraco) {  // Draco ignores bytes after its mesh
      EXPECT_FALSE(decodes(codec, longer)) << codec_name(codec) << ": trailing byte accepted";
    }
    // Bit flips: each must be rejected or decode to something; no crash. (Detection is the
    // checksum's job, see checksum_test.)
    for (std::size_t bit = 0; bit < good.size() * 8; bit += 3) {
      Bytes flipped = good;
      flipped[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
      decodes(codec, flipped);
    }
  }
  expect_error(
      [] {
        decode_geometry(static_cast<CodecId>(7), Bytes{0, 0}, "pages/5");
      },
      ErrorKind::kCorrupt, "pages/5: unknown geometry codec id 7");
}

TEST(Codec, ZstdFramesAreBoundedAndValidated) {
  std::mt19937_64 rng(12);
  Bytes data(100000);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::uint8_t>(i % 251);
  const Bytes z = zstd_compress(data);
  EXPECT_LT(z.size(), data.size() / 10);
  EXPECT_EQ(zstd_decompress(z, data.size(), "z"), data);
  expect_error([&] { zstd_decompress(z, data.size() - 1, "pages/3"); }, ErrorKind::kCorrupt,
               "pages/3: zstd: frame declares 100000 bytes");
  Bytes trailing = z;
  trailing.push_back(1);
  expect_error([&] { zstd_decompress(trailing, data.size(), "pages/3"); }, ErrorKind::kCorrupt,
               "pages/3: zstd");
  for (std::size_t n = 0; n < z.size(); ++n) {
    expect_error([&] { zstd_decompress(ByteView(z.data(), n), data.size(), "pages/4"); },
                 ErrorKind::kCorrupt, "pages/4: zstd");
  }
  expect_error([&] { zstd_decompress(test::random_bytes(rng, 64), 1 << 20, "pages/6"); },
               ErrorKind::kCorrupt, "pages/6: zstd");
  EXPECT_EQ(zstd_decompress(zstd_compress({}), 0, "empty"), Bytes{});
}

// Not an assertion of sizes (they depend on library versions): prints bytes per face so that
// the codec choice can be revisited (docs/design.md section 3: "measure Draco against plain/zstd").
TEST(Codec, CodecSizes) {
  for (int n : {12, 23}) {  // 242 and 968 faces
    for (int variant = 0; variant < 3; ++variant) {
      const bool shuffled = variant == 1, smooth = variant == 2;
      const GeometryBlob blob = grid_mesh(n, {1 << 28, 1 << 28, 0}, 16, 5, 0, shuffled, smooth);
      const double faces = static_cast<double>(blob.faces.size());
      std::printf("%4zu faces, %4zu positions, %-22s:", blob.faces.size(), blob.positions.size(),
                  shuffled ? "random z, shuffled"
                  : smooth ? "smooth z, row order"
                           : "random z, row order");
      for (CodecId codec : kCodecs) {
        std::printf("  %s %.2f B/face", std::string(codec_name(codec)).c_str(),
                    static_cast<double>(encode(codec, blob).size()) / faces);
      }
      std::printf("  (draco edgebreaker without order: %.2f B/face)\n",
                  static_cast<double>(detail::draco_edgebreaker_size(blob)) / faces);
      EXPECT_LT(encode(CodecId::kDraco, blob).size(), encode(CodecId::kRaw, blob).size());
    }
  }
}

}  // namespace
}  // namespace smr::storage
