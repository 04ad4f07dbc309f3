// R-tree node codec (index/node_codec.h): the stored res never exceeds the true one and stays
// within a bfloat16 step of its error 1 - res; boxes are rounded outwards by at most two steps of
// the node's 8-bit frame.
#include "index/node_codec.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace smr::index::detail {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(NodeCodec, ResIsRoundedDownWithinABfloat16StepOfItsError) {
  std::vector<double> values = {0.0,
                                1.0,
                                0.5,
                                -0.0,
                                1e-300,
                                -1e-300,
                                0.999999999,
                                1 - 1e-16,
                                1 + 1e-9,
                                2.0,
                                -3.5,
                                1e30,
                                -1e30,
                                3.4e38,
                                -3.4e38,
                                kInf,
                                -kInf,
                                std::nextafter(1.0, 0.0),
                                std::nextafter(1.0, 2.0)};
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int i = 0; i < 100000; ++i) {
    values.push_back(unit(rng));
    values.push_back(1.0 - std::ldexp(unit(rng), -int(rng() % 60)));  // near 1: fine errors
    values.push_back(std::ldexp(unit(rng) - 0.5, int(rng() % 200) - 100));
  }
  for (double res : values) {
    const double stored = decode_res(encode_res(res));
    ASSERT_LE(stored, res) << res;  // conservative: never finer than the truth
    const double e = 1.0 - res, es = 1.0 - stored;
    if (std::isfinite(e) && std::fabs(e) > 1e-30 && std::fabs(e) < 1e38) {
      // Rounded up by less than one bfloat16 step (2^-7 relative), plus the rounding of 1 - res.
      ASSERT_LE(es - e, std::fabs(e) / 128 + 1e-16) << res;
    }
  }
  EXPECT_EQ(decode_res(encode_res(1.0)), 1.0);  // an exact model keeps its exact resolution
  EXPECT_EQ(decode_res(encode_res(0.0)), 0.0);
  EXPECT_EQ(decode_res(encode_res(-kInf)), -kInf);
}

TEST(NodeCodec, BoxesAreConservativeWithinTwoFrameSteps) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1000.0, 1000.0);
  for (int trial = 0; trial < 200; ++trial) {
    Node node{0, 0, {}};
    const int n = 1 + int(rng() % 300);
    for (int i = 0; i < n; ++i) {
      NodeItem it;
      for (int a = 0; a < 3; ++a) {
        const double c = u(rng), r = std::fabs(u(rng)) * 0.01, extra = std::fabs(u(rng)) * 0.01;
        it.box.lo[a] = c - r;
        it.box.hi[a] = c + r;
        it.roi.lo[a] = c - r - extra;
        it.roi.hi[a] = c + r + extra;
      }
      it.res = std::ldexp(1.0, -int(rng() % 20));
      it.value = rng() % 1000000;
      node.items.push_back(it);
    }
    storage::Bytes bytes;
    const Node stored = encode_node(node, bytes);
    const Node decoded = decode_node(bytes, "test");
    ASSERT_EQ(decoded.items.size(), node.items.size());
    Box bounds;
    for (const NodeItem& it : node.items) bounds.add(it.roi);
    for (int i = 0; i < n; ++i) {
      const NodeItem &t = node.items[i], &d = decoded.items[i], &s = stored.items[i];
      ASSERT_EQ(d.value, t.value);
      ASSERT_EQ(d.res, s.res);
      ASSERT_LE(d.res, t.res);
      for (int a = 0; a < 3; ++a) {
        ASSERT_EQ(d.roi.lo[a], s.roi.lo[a]);
        ASSERT_EQ(d.box.hi[a], s.box.hi[a]);
        ASSERT_TRUE(d.roi.contains(t.roi) && d.box.contains(t.box));
        const double step = (bounds.hi[a] - bounds.lo[a]) / 255.0;
        ASSERT_LE(t.box.lo[a] - d.box.lo[a], 2 * step);
        ASSERT_LE(d.roi.hi[a] - t.roi.hi[a], 2 * step);
      }
    }
  }
}

}  // namespace
}  // namespace smr::index::detail
