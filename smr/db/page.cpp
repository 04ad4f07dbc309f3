#include "smr/db/page.h"

#include <algorithm>
#include <unordered_map>

#include "base/error.h"
#include "smr/core/crmr.h"

namespace smr {

using storage::ByteReader;
using storage::Bytes;
using storage::ByteView;
using storage::ByteWriter;
using storage::GeometryBlob;

namespace {

constexpr std::size_t kMaxRecordBytes = std::size_t{1} << 31;

template <class T>
std::uint64_t count_of(const std::vector<T>& v) {
  return v.size();
}

}  // namespace

void write_link(ByteWriter& w, const CoarserLink& link, std::uint64_t id) {
  w.varint(link.tri);
  w.u8(link.edge);
  w.svarint(std::int64_t(id - link.coarser.tri.op.value));
  w.varint(link.coarser.tri.index);
  w.u8(link.coarser.edge);
}

CoarserLink read_link(ByteReader& r, std::uint64_t id) {
  CoarserLink l;
  l.tri = std::uint32_t(r.varint());
  l.edge = r.u8();
  l.coarser.tri.op = OpId(id - std::uint64_t(r.svarint()));
  l.coarser.tri.index = std::uint32_t(r.varint());
  l.coarser.edge = r.u8();
  return l;
}

Bytes encode_page(std::span<const Op* const> ops, const QuantGrid& grid, storage::CodecId codec) {
  // The page's vertices, in order of first use, and each op's local -> page index.
  std::unordered_map<std::uint64_t, std::uint32_t> page_index;
  std::vector<std::uint64_t> ids;
  GeometryBlob geometry;
  std::vector<std::vector<std::uint32_t>> to_page(ops.size());
  for (std::size_t o = 0; o < ops.size(); ++o) {
    const Op& op = *ops[o];
    for (const Vertex& v : op.vertices) {
      auto [it, fresh] = page_index.emplace(v.id.value, std::uint32_t(ids.size()));
      if (fresh) {
        ids.push_back(v.id.value);
        const auto q = grid.quantize(v.p);
        if (grid.dequantize(q) != v.p) {
          throw_internal("page encoding: vertex " + std::to_string(v.id.value) +
                         " is not on the quantization grid");
        }
        geometry.positions.push_back(q);
      }
      to_page[o].push_back(it->second);
    }
    for (const FragmentTriangle& t : op.fragment) {
      geometry.faces.push_back({to_page[o][t.v[0]], to_page[o][t.v[1]], to_page[o][t.v[2]]});
    }
  }

  Bytes records;
  ByteWriter w(records);
  w.varint(ids.size());
  std::uint64_t prev = 0;
  for (std::uint64_t id : ids) {
    w.svarint(std::int64_t(id - prev));
    prev = id;
  }
  std::uint64_t prev_op = 0;
  for (std::size_t o = 0; o < ops.size(); ++o) {
    const Op& op = *ops[o];
    const std::uint64_t id = op.id.value;
    w.svarint(std::int64_t(id - prev_op));
    prev_op = id;
    w.f64(op.birth_res);
    w.f64(op.error);
    w.varint(op.vertices.size());
    w.varint(op.new_vertex_count);
    std::int64_t prev_index = 0;
    for (std::uint32_t p : to_page[o]) {
      w.svarint(std::int64_t(p) - prev_index);
      prev_index = p;
    }
    // Children (with their birth_res: the death_res of the triangles they replace).
    w.varint(op.children.size());
    for (OpId c : op.children) w.varint(c.value - id);
    std::vector<double> child_res;  // filled from the triangles below
    child_res.assign(op.children.size(), -1.0);
    w.varint(op.fragment.size());
    Bytes killers;
    ByteWriter kw(killers);
    std::vector<std::uint32_t> voids;
    for (std::uint32_t i = 0; i < op.fragment.size(); ++i) {
      const FragmentTriangle& t = op.fragment[i];
      if (t.flags & FragmentTriangle::kVoid) voids.push_back(i);
      if (t.flags & ~FragmentTriangle::kVoid) throw_internal("page encoding: unknown flags");
      if (!t.killer.valid()) {
        if (t.death_res != 1.0) throw_internal("page encoding: unreplaced triangle below 1");
        kw.varint(0);
        continue;
      }
      auto it = std::lower_bound(op.children.begin(), op.children.end(), t.killer);
      if (it == op.children.end() || *it != t.killer)
        throw_internal("page encoding: a killer is not a child");
      const std::size_t c = std::size_t(it - op.children.begin());
      if (child_res[c] >= 0.0 && child_res[c] != t.death_res)
        throw_internal("page encoding: one killer, two death resolutions");
      child_res[c] = t.death_res;
      kw.varint(c + 1);
    }
    for (double r : child_res) w.f64(r);
    w.bytes(killers);
    w.varint(voids.size());
    for (std::uint32_t v : voids) w.varint(v);
    // Parents and PreF.
    w.varint(op.parents.size());
    for (OpId p : op.parents) w.varint(id - p.value);
    if (op.pre_tris.size() != op.pre.size()) throw_internal("page encoding: pre_tris missing");
    w.varint(op.pre.size());
    std::vector<std::uint32_t> pre_voids;
    for (std::size_t i = 0; i < op.pre.size(); ++i) {
      const TriRef& r = op.pre[i];
      auto it = std::lower_bound(op.parents.begin(), op.parents.end(), r.op);
      if (it == op.parents.end() || *it != r.op)
        throw_internal("page encoding: a PreF triangle's op is not a parent");
      w.varint(std::uint64_t(it - op.parents.begin()));
      w.varint(r.index);
      for (std::uint32_t c : op.pre_tris[i].v) w.varint(c);
      if (op.pre_tris[i].flags & FragmentTriangle::kVoid) pre_voids.push_back(std::uint32_t(i));
    }
    w.varint(pre_voids.size());
    for (std::uint32_t v : pre_voids) w.varint(v);
    // Hypermesh links.
    w.varint(op.coarser.size());
    for (const CoarserLink& l : op.coarser) write_link(w, l, id);
    // ROI, in grid steps outside the op's own box.
    const auto blo = grid.quantize(op.box.lo), bhi = grid.quantize(op.box.hi);
    const auto rlo = grid.quantize(op.roi.lo), rhi = grid.quantize(op.roi.hi);
    for (int k = 0; k < 3; ++k) w.varint(std::uint64_t(std::int64_t(blo[k]) - rlo[k]));
    for (int k = 0; k < 3; ++k) w.varint(std::uint64_t(std::int64_t(rhi[k]) - bhi[k]));
    // Subtree normal cone (canonical: exact in its codes).
    const ConeCode cone = cone_code(op.subtree_cone);
    w.u8(cone.full ? 0 : 1);
    if (!cone.full) {
      for (std::int16_t a : cone.axis) w.svarint(a);
      w.u16(cone.half);
    }
  }

  Bytes out;
  ByteWriter pw(out);
  pw.u8(kPageFormat);
  pw.u8(static_cast<std::uint8_t>(codec));
  pw.varint(ops.size());
  pw.blob(storage::zstd_compress(records));
  Bytes geo;
  storage::encode_geometry(codec, geometry, geo);
  pw.blob(geo);
  return out;
}

std::vector<Op> decode_page(ByteView page, const QuantGrid& grid, const std::string& context) {
  ByteReader pr(page, context);
  if (pr.u8() != kPageFormat) pr.fail("unknown page format");
  const std::uint8_t codec_byte = pr.u8();
  if (codec_byte > static_cast<std::uint8_t>(storage::CodecId::kDraco)) pr.fail("unknown codec");
  const auto codec = static_cast<storage::CodecId>(codec_byte);
  const std::uint64_t op_count = pr.varint();
  const ByteView packed = pr.blob();
  const ByteView geo_bytes = pr.blob();
  pr.expect_end();
  const Bytes records = storage::zstd_decompress(packed, kMaxRecordBytes, context);
  const GeometryBlob geometry = storage::decode_geometry(codec, geo_bytes, context);

  ByteReader r(records, context + " records");
  auto count = [&](std::uint64_t limit, const char* what) {
    const std::uint64_t n = r.varint();
    if (n > limit) r.fail(std::string("implausible ") + what + " count");
    return n;
  };
  const std::uint64_t vcount = count(geometry.positions.size(), "vertex");
  if (vcount != geometry.positions.size()) r.fail("vertex count disagrees with the geometry");
  if (op_count > records.size()) r.fail("implausible op count");
  std::vector<std::uint64_t> ids(vcount);
  std::uint64_t prev = 0;
  for (auto& id : ids) prev = id = prev + std::uint64_t(r.svarint());
  std::vector<Vec3> positions(vcount);
  for (std::size_t i = 0; i < vcount; ++i) positions[i] = grid.dequantize(geometry.positions[i]);

  std::vector<Op> ops(op_count);
  std::size_t face = 0;
  std::uint64_t prev_op = 0;
  constexpr std::uint32_t kNone = ~0u;
  std::vector<std::uint32_t> local_of(vcount, kNone);  // page vertex -> index in the current op
  std::vector<std::uint32_t> mine;                     // the current op's page vertices
  for (Op& op : ops) {
    const std::uint64_t id = prev_op + std::uint64_t(r.svarint());
    prev_op = id;
    op.id = OpId(id);
    op.birth_res = r.f64();
    op.error = r.f64();
    const std::uint64_t nv = count(vcount, "op vertex");
    op.new_vertex_count = std::uint32_t(count(nv, "new vertex"));
    op.vertices.resize(nv);
    std::int64_t prev_index = 0;
    mine.clear();
    for (std::uint32_t i = 0; i < nv; ++i) {
      prev_index += r.svarint();
      if (prev_index < 0 || std::uint64_t(prev_index) >= vcount)
        r.fail("vertex index out of range");
      const auto p = std::uint32_t(prev_index);
      op.vertices[i] = {VertexId(ids[p]), positions[p]};
      if (local_of[p] != kNone) r.fail("an op lists a vertex twice");
      local_of[p] = i;
      mine.push_back(p);
    }
    const std::uint64_t nc = count(r.remaining(), "child");
    op.children.resize(nc);
    for (auto& c : op.children) c = OpId(id + r.varint());
    const std::uint64_t nf = count(geometry.faces.size() - face, "triangle");
    std::vector<double> child_res(nc);
    for (double& cr : child_res) cr = r.f64();
    op.fragment.resize(nf);
    for (FragmentTriangle& t : op.fragment) {
      const auto& f = geometry.faces[face++];
      for (int k = 0; k < 3; ++k) {
        if (f[k] >= vcount || local_of[f[k]] == kNone)
          r.fail("a triangle uses a vertex its op does not list");
        t.v[k] = local_of[f[k]];
      }
      const std::uint64_t killer = r.varint();
      if (killer > nc) r.fail("killer out of range");
      if (killer != 0) {
        t.killer = op.children[killer - 1];
        t.death_res = child_res[killer - 1];
      }
    }
    const std::uint64_t nvoid = count(nf, "void triangle");
    for (std::uint64_t i = 0; i < nvoid; ++i) {
      const std::uint64_t v = r.varint();
      if (v >= nf) r.fail("void triangle out of range");
      op.fragment[v].flags |= FragmentTriangle::kVoid;
    }
    for (std::uint32_t p : mine) local_of[p] = kNone;
    derive_fragment_neighbours(op);
    const std::uint64_t np = count(r.remaining(), "parent");
    op.parents.resize(np);
    for (auto& p : op.parents) {
      const std::uint64_t d = r.varint();
      if (d == 0 || d > id) r.fail("parent id out of range");
      p = OpId(id - d);
    }
    const std::uint64_t npre = count(r.remaining(), "PreF");
    op.pre.resize(npre);
    op.pre_tris.resize(npre);
    for (std::uint64_t i = 0; i < npre; ++i) {
      const std::uint64_t pi = r.varint();
      if (pi >= np) r.fail("PreF parent out of range");
      op.pre[i] = {op.parents[pi], std::uint32_t(r.varint())};
      for (auto& c : op.pre_tris[i].v) {
        const std::uint64_t v = r.varint();
        if (v >= nv) r.fail("PreF corner out of range");
        c = std::uint32_t(v);
      }
    }
    const std::uint64_t npv = count(npre, "void PreF");
    for (std::uint64_t i = 0; i < npv; ++i) {
      const std::uint64_t v = r.varint();
      if (v >= npre) r.fail("void PreF triangle out of range");
      op.pre_tris[v].flags |= FragmentTriangle::kVoid;
    }
    const std::uint64_t nl = count(r.remaining(), "coarser link");
    op.coarser.resize(nl);
    for (CoarserLink& l : op.coarser) {
      l = read_link(r, id);
      if (l.tri >= nf || l.edge > 2 || l.coarser.edge > 2) r.fail("coarser link out of range");
    }
    if (nf == 0 && npre == 0) r.fail("an op without triangles");
    compute_op_bounds(op);
    auto lo = grid.quantize(op.box.lo), hi = grid.quantize(op.box.hi);
    for (int k = 0; k < 3; ++k)
      lo[k] = std::int32_t(std::int64_t(lo[k]) - std::int64_t(r.varint()));
    for (int k = 0; k < 3; ++k)
      hi[k] = std::int32_t(std::int64_t(hi[k]) + std::int64_t(r.varint()));
    op.roi = Box3{grid.dequantize(lo), grid.dequantize(hi)};
    ConeCode cone;
    const std::uint8_t cone_flag = r.u8();
    if (cone_flag > 1) r.fail("bad subtree cone flag");
    cone.full = cone_flag == 0;
    if (!cone.full) {
      for (std::int16_t& a : cone.axis) {
        const std::int64_t v = r.svarint();
        if (v < -32767 || v > 32767) r.fail("subtree cone axis out of range");
        a = static_cast<std::int16_t>(v);
      }
      if (cone.axis == std::array<std::int16_t, 3>{}) r.fail("subtree cone without an axis");
      cone.half = r.u16();
      if (cone.half == 0xffff) r.fail("subtree cone angle out of range");
    }
    op.subtree_cone = decode_cone(cone);
  }
  r.expect_end();
  if (face != geometry.faces.size()) pr.fail("geometry has triangles no op claims");
  return ops;
}

std::size_t heap_block_bytes(std::size_t bytes) {
  return bytes == 0 ? 0 : std::max<std::size_t>(32, (bytes + 8 + 15) & ~std::size_t{15});
}

namespace {
template <class T>
std::size_t heap_of(const std::vector<T>& v) {
  return heap_block_bytes(v.capacity() * sizeof(T));
}
}  // namespace

std::size_t op_memory_bytes(const Op& op) {
  return sizeof(Op) + heap_of(op.vertices) + heap_of(op.fragment) + heap_of(op.pre) +
         heap_of(op.pre_tris) + heap_of(op.coarser) + heap_of(op.parents) + heap_of(op.children);
}

}  // namespace smr
