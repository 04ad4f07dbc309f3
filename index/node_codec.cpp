// R-tree node codec: conservative 16-bit quantisation of boxes (see node_codec.h).
#include "index/node_codec.h"

#include <cmath>
#include <limits>

#include "storage/error.h"

namespace smr::index::detail {
namespace {

constexpr std::uint32_t kMaxQ = 65535;

void encode_box(const Frame& frame, const Box& box, storage::ByteWriter& w, Box& stored) {
  for (int a = 0; a < 3; ++a) {
    const std::uint16_t q = frame.quantize_lo(a, box.lo[a]);
    w.u16(q);
    stored.lo[a] = frame.decode(a, q);
  }
  for (int a = 0; a < 3; ++a) {
    const std::uint16_t q = frame.quantize_hi(a, box.hi[a]);
    w.u16(q);
    stored.hi[a] = frame.decode(a, q);
  }
}

Box decode_box(const Frame& frame, storage::ByteReader& r) {
  Box box;
  for (int a = 0; a < 3; ++a) box.lo[a] = frame.decode(a, r.u16());
  for (int a = 0; a < 3; ++a) box.hi[a] = frame.decode(a, r.u16());
  return box;
}

}  // namespace

Frame Frame::around(const Box& bounds) {
  Frame f;
  for (int a = 0; a < 3; ++a) {
    const double lo = bounds.lo[a];
    const double hi = bounds.hi[a];
    const double extent = hi - lo;
    if (!std::isfinite(lo) || !std::isfinite(hi) || !std::isfinite(extent) || extent < 0) {
      throw_input("R-tree: box coordinates must be finite, with lo <= hi and hi - lo finite");
    }
    f.origin[a] = lo;
    double step = extent / kMaxQ;
    // Make sure the top of the grid reaches `hi`, so every value in [lo, hi] has a q above it.
    while (f.origin[a] + static_cast<double>(kMaxQ) * step < hi) {
      step = std::nextafter(step, std::numeric_limits<double>::infinity());
    }
    f.step[a] = step;
  }
  return f;
}

double Frame::decode(int axis, std::uint16_t q) const {
  // Two statements: no contraction into a fused multiply-add, so writer and reader agree.
  const double offset = static_cast<double>(q) * step[axis];
  return origin[axis] + offset;
}

std::uint16_t Frame::quantize_lo(int axis, double v) const {
  if (step[axis] == 0) return 0;
  double guess = std::floor((v - origin[axis]) / step[axis]);
  guess = std::fmin(std::fmax(guess, 0.0), static_cast<double>(kMaxQ));
  auto q = static_cast<std::uint32_t>(guess);
  while (q > 0 && decode(axis, static_cast<std::uint16_t>(q)) > v) --q;
  // Tighten (bounded: on a degenerate frame many q decode to the same value).
  for (int i = 0; i < 4 && q < kMaxQ && decode(axis, static_cast<std::uint16_t>(q + 1)) <= v; ++i) {
    ++q;
  }
  return static_cast<std::uint16_t>(q);
}

std::uint16_t Frame::quantize_hi(int axis, double v) const {
  if (step[axis] == 0) return 0;
  double guess = std::ceil((v - origin[axis]) / step[axis]);
  guess = std::fmin(std::fmax(guess, 0.0), static_cast<double>(kMaxQ));
  auto q = static_cast<std::uint32_t>(guess);
  while (q < kMaxQ && decode(axis, static_cast<std::uint16_t>(q)) < v) ++q;
  for (int i = 0; i < 4 && q > 0 && decode(axis, static_cast<std::uint16_t>(q - 1)) >= v; ++i) {
    --q;
  }
  return static_cast<std::uint16_t>(q);
}

double round_res_down(double res) {
  constexpr double kMaxFloat = std::numeric_limits<float>::max();
  if (res > kMaxFloat && !std::isinf(res)) return kMaxFloat;
  if (res < -kMaxFloat) return -std::numeric_limits<double>::infinity();
  float f = static_cast<float>(res);
  if (static_cast<double>(f) > res) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
  return static_cast<double>(f);
}

Node encode_node(const Node& node, storage::Bytes& out) {
  if (node.items.empty()) throw_internal("R-tree: encoding an empty node");
  Box bounds;
  for (const NodeItem& item : node.items) bounds.add(item.roi);
  const Frame frame = Frame::around(bounds);

  storage::ByteWriter w(out);
  w.varint(node.level);
  w.varint(node.items.size());
  for (int a = 0; a < 3; ++a) w.f64(frame.origin[a]);
  for (int a = 0; a < 3; ++a) w.f64(frame.step[a]);
  if (node.level > 0) w.varint(node.first_child);

  Node stored{node.level, node.first_child, {}};
  stored.items.reserve(node.items.size());
  for (const NodeItem& item : node.items) {
    NodeItem s;
    encode_box(frame, item.roi, w, s.roi);
    encode_box(frame, item.box, w, s.box);
    s.res = round_res_down(item.res);
    s.value = item.value;
    if (node.level == 0) {
      w.varint(item.value);
      w.f32(static_cast<float>(s.res));
    } else {
      w.f32(static_cast<float>(s.res));
      w.varint(item.value);
    }
    stored.items.push_back(s);
  }
  return stored;
}

Node decode_node(storage::ByteView payload, const std::string& context) {
  storage::ByteReader r(payload, context);
  Node node;
  node.level = r.varint();
  if (node.level > 64) r.fail("level " + std::to_string(node.level) + " out of range");
  const std::uint64_t count = r.varint();
  if (count == 0) r.fail("node has no items");
  // Each item takes at least 24 + 4 + 1 bytes: reject absurd counts before reading on.
  if (count > r.remaining() / 29) r.fail("item count " + std::to_string(count) + " exceeds node");
  Frame frame;
  for (int a = 0; a < 3; ++a) frame.origin[a] = r.f64();
  for (int a = 0; a < 3; ++a) frame.step[a] = r.f64();
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(frame.origin[a]) || !(frame.step[a] >= 0) ||
        !std::isfinite(frame.decode(a, static_cast<std::uint16_t>(kMaxQ)))) {
      r.fail("bad quantisation frame");
    }
  }
  if (node.level > 0) node.first_child = r.varint();
  node.items.reserve(count);
  for (std::uint64_t i = 0; i < count; ++i) {
    NodeItem item;
    item.roi = decode_box(frame, r);
    item.box = decode_box(frame, r);
    if (node.level == 0) {
      item.value = r.varint();
      item.res = static_cast<double>(r.f32());
    } else {
      item.res = static_cast<double>(r.f32());
      item.value = r.varint();
      if (item.value == 0) r.fail("child " + std::to_string(i) + " has no entries");
    }
    if (item.roi.empty() || item.box.empty() || !item.roi.contains(item.box)) {
      r.fail("item " + std::to_string(i) + " has an empty box or a box outside its roi");
    }
    if (std::isnan(item.res)) r.fail("item " + std::to_string(i) + " has a NaN res");
    node.items.push_back(item);
  }
  r.expect_end();
  return node;
}

}  // namespace smr::index::detail
