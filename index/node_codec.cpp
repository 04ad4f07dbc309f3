// R-tree node codec: conservative 8-bit quantisation of boxes, 16-bit res (see node_codec.h).
#include "index/node_codec.h"

#include <bit>
#include <cmath>
#include <limits>

#include "base/error.h"

namespace smr::index::detail {
namespace {

constexpr std::uint32_t kMaxQ = 255;
// Smallest item: two boxes, a res and a one-byte varint.
constexpr std::size_t kMinItemBytes = 12 + 2 + 1;

void encode_box(const Frame& frame, const Box& box, storage::ByteWriter& w, Box& stored) {
  for (int a = 0; a < 3; ++a) {
    const std::uint8_t q = frame.quantize_lo(a, box.lo[a]);
    w.u8(q);
    stored.lo[a] = frame.decode(a, q);
  }
  for (int a = 0; a < 3; ++a) {
    const std::uint8_t q = frame.quantize_hi(a, box.hi[a]);
    w.u8(q);
    stored.hi[a] = frame.decode(a, q);
  }
}

Box decode_box(const Frame& frame, storage::ByteReader& r) {
  Box box;
  for (int a = 0; a < 3; ++a) box.lo[a] = frame.decode(a, r.u8());
  for (int a = 0; a < 3; ++a) box.hi[a] = frame.decode(a, r.u8());
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

double Frame::decode(int axis, std::uint8_t q) const {
  // Two statements: no contraction into a fused multiply-add, so writer and reader agree.
  const double offset = static_cast<double>(q) * step[axis];
  return origin[axis] + offset;
}

std::uint8_t Frame::quantize_lo(int axis, double v) const {
  if (step[axis] == 0) return 0;
  double guess = std::floor((v - origin[axis]) / step[axis]);
  guess = std::fmin(std::fmax(guess, 0.0), static_cast<double>(kMaxQ));
  auto q = static_cast<std::uint32_t>(guess);
  while (q > 0 && decode(axis, static_cast<std::uint8_t>(q)) > v) --q;
  // Tighten (bounded: on a degenerate frame many q decode to the same value).
  for (int i = 0; i < 4 && q < kMaxQ && decode(axis, static_cast<std::uint8_t>(q + 1)) <= v; ++i) {
    ++q;
  }
  return static_cast<std::uint8_t>(q);
}

std::uint8_t Frame::quantize_hi(int axis, double v) const {
  if (step[axis] == 0) return 0;
  double guess = std::ceil((v - origin[axis]) / step[axis]);
  guess = std::fmin(std::fmax(guess, 0.0), static_cast<double>(kMaxQ));
  auto q = static_cast<std::uint32_t>(guess);
  while (q < kMaxQ && decode(axis, static_cast<std::uint8_t>(q)) < v) ++q;
  for (int i = 0; i < 4 && q > 0 && decode(axis, static_cast<std::uint8_t>(q - 1)) >= v; ++i) {
    --q;
  }
  return static_cast<std::uint8_t>(q);
}

namespace {
// bfloat16 <-> float: the high 16 bits of an IEEE-754 binary32.
double from_bf16(std::uint16_t q) {
  return static_cast<double>(std::bit_cast<float>(static_cast<std::uint32_t>(q) << 16));
}
// The next bfloat16 towards +infinity (q is not +infinity or NaN).
std::uint16_t bf16_up(std::uint16_t q) {
  if (q == 0x8000) return 0x0001;  // -0 -> the least positive
  return (q & 0x8000) ? static_cast<std::uint16_t>(q - 1) : static_cast<std::uint16_t>(q + 1);
}
}  // namespace

std::uint16_t encode_res(double res) {
  const double e = 1.0 - res;  // may round; fixed below
  constexpr float kInf = std::numeric_limits<float>::infinity();
  float f = static_cast<float>(e);
  if (static_cast<double>(f) < e) f = std::nextafter(f, kInf);
  std::uint32_t bits = std::bit_cast<std::uint32_t>(f);
  const bool negative = (bits & 0x80000000u) != 0;
  // Towards +infinity: a positive value with dropped bits goes up one step (carrying into the
  // exponent, possibly to infinity), a negative one is truncated (towards zero).
  std::uint16_t q = static_cast<std::uint16_t>(bits >> 16);
  if (!negative && (bits & 0xFFFFu) != 0) q = static_cast<std::uint16_t>(q + 1);
  while (1.0 - from_bf16(q) > res) q = bf16_up(q);
  return q;
}

double decode_res(std::uint16_t q) {
  return 1.0 - from_bf16(q);
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
  std::uint64_t previous_id = 0;
  for (const NodeItem& item : node.items) {
    NodeItem s;
    encode_box(frame, item.roi, w, s.roi);
    encode_box(frame, item.box, w, s.box);
    const std::uint16_t res = encode_res(item.res);
    s.res = decode_res(res);
    s.value = item.value;
    w.u16(res);
    if (node.level == 0) {
      w.svarint(static_cast<std::int64_t>(item.value - previous_id));  // ids in slot order
      previous_id = item.value;
    } else {
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
  // Reject absurd counts before reading on.
  if (count > r.remaining() / kMinItemBytes)
    r.fail("item count " + std::to_string(count) + " exceeds node");
  Frame frame;
  for (int a = 0; a < 3; ++a) frame.origin[a] = r.f64();
  for (int a = 0; a < 3; ++a) frame.step[a] = r.f64();
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(frame.origin[a]) || !(frame.step[a] >= 0) ||
        !std::isfinite(frame.decode(a, static_cast<std::uint8_t>(kMaxQ)))) {
      r.fail("bad quantisation frame");
    }
  }
  if (node.level > 0) node.first_child = r.varint();
  node.items.reserve(count);
  std::uint64_t previous_id = 0;
  for (std::uint64_t i = 0; i < count; ++i) {
    NodeItem item;
    item.roi = decode_box(frame, r);
    item.box = decode_box(frame, r);
    item.res = decode_res(r.u16());
    if (node.level == 0) {
      item.value = previous_id + static_cast<std::uint64_t>(r.svarint());
      previous_id = item.value;
    } else {
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
