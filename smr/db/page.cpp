#include "smr/db/page.h"

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <limits>

#include <glm/geometric.hpp>
#include <memory>
#include <type_traits>
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

namespace {

// The counts a decoder sizes its block from, in the order the page stores them.
struct Totals {
  std::uint64_t vertices = 0, list = 0, triangles = 0, pre = 0, links = 0, parents = 0,
                children = 0;
  std::array<std::uint64_t*, 7> fields() {
    return {&vertices, &list, &triangles, &pre, &links, &parents, &children};
  }
};

void require_float(double v, const char* what, const Op& op) {
  if (double(float(v)) != v)
    throw_internal("page encoding: op " + std::to_string(op.id.value) + " has a " + what +
                   " that is not a 32-bit float (round_for_storage was not applied)");
}

// The record of one op (page.h's layout), given its vertices' page indices.
void write_record(ByteWriter& w, const Op& op, std::span<const std::uint32_t> to_page,
                  std::uint64_t prev_op, const QuantGrid& grid) {
  const std::uint64_t id = op.id.value;
  w.svarint(std::int64_t(id - prev_op));
  require_float(op.birth_res, "birth resolution", op);
  w.f32(float(op.birth_res));
  w.varint(op.vertices.size());
  w.varint(op.new_vertex_count);
  std::int64_t prev_index = 0;
  for (std::uint32_t p : to_page) {
    w.svarint(std::int64_t(p) - prev_index);
    prev_index = p;
  }
  // Children (increasing), with their birth_res: the death_res of the triangles they replace.
  w.varint(op.children.size());
  std::uint64_t prev = id;
  for (OpId c : op.children) {
    if (c.value <= prev) throw_internal("page encoding: children not increasing");
    w.varint(c.value - prev);
    prev = c.value;
  }
  std::vector<double> child_res(op.children.size(), -1.0);
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
  for (double r : child_res) {
    require_float(r, "death resolution", op);
    w.f32(float(r));
  }
  w.varint(op.fragment.size());
  w.bytes(killers);
  w.varint(voids.size());
  for (std::uint32_t v : voids) w.varint(v);
  // Parents (decreasing from the op) and PreF.
  w.varint(op.parents.size());
  prev = id;
  for (auto p = op.parents.rbegin(); p != op.parents.rend(); ++p) {
    if (p->value >= prev) throw_internal("page encoding: parents not increasing");
    w.varint(prev - p->value);
    prev = p->value;
  }
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

}  // namespace

Bytes encode_page(std::span<const Op* const> ops, const QuantGrid& grid, storage::CodecId codec) {
  // The page's vertices, in order of first use, and each op's local -> page index.
  std::unordered_map<std::uint64_t, std::uint32_t> page_index;
  std::vector<std::uint64_t> ids;
  GeometryBlob geometry;
  std::vector<std::vector<std::uint32_t>> to_page(ops.size());
  Totals totals;
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
    totals.list += op.vertices.size();
    totals.pre += op.pre.size();
    totals.links += op.coarser.size();
    totals.parents += op.parents.size();
    totals.children += op.children.size();
  }
  totals.vertices = ids.size();
  totals.triangles = geometry.faces.size();

  Bytes records;
  ByteWriter w(records);
  std::uint64_t prev = 0;
  for (std::uint64_t id : ids) {
    w.svarint(std::int64_t(id - prev));
    prev = id;
  }
  std::uint64_t prev_op = 0;
  for (std::size_t o = 0; o < ops.size(); ++o) {
    write_record(w, *ops[o], to_page[o], prev_op, grid);
    prev_op = ops[o]->id.value;
  }

  Bytes out;
  ByteWriter pw(out);
  pw.u8(kPageFormat);
  pw.u8(static_cast<std::uint8_t>(codec));
  pw.varint(ops.size());
  for (std::uint64_t* n : totals.fields()) pw.varint(*n);
  pw.blob(storage::zstd_compress(records));
  Bytes geo;
  storage::encode_geometry(codec, geometry, geo);
  pw.blob(geo);
  return out;
}

PageSections page_sections(ByteView page, const std::string& context) {
  ByteReader r(page, context);
  PageSections s;
  s.format = r.u8();
  if (s.format != kPageFormat) return s;  // the rest is another format's
  s.codec = r.u8();
  s.ops = r.varint();
  for (std::uint64_t& n : s.totals) n = r.varint();
  s.records = r.blob();
  s.geometry = r.blob();
  r.expect_end();
  return s;
}

// Decodes a page into one block (page.h). Every count is checked against the page's totals and
// every index against what it indexes before it is used: bytes that encode_page did not write
// throw kCorrupt naming the page.
class PageDecoder {
 public:
  PageDecoder(ByteView page, const QuantGrid& grid, const CrmrInfo& info,
              const std::string& context)
      : grid_(grid), info_(info), context_(context) {
    const PageSections s = page_sections(page, context);
    if (s.format != kPageFormat)
      ByteReader(page, context)
          .fail("page format " + std::to_string(s.format) + " (this smrdb reads format " +
                std::to_string(kPageFormat) + ")");
    if (s.codec > static_cast<std::uint8_t>(storage::CodecId::kDraco))
      ByteReader(page, context).fail("unknown codec");
    codec_ = static_cast<storage::CodecId>(s.codec);
    op_count_ = s.ops;
    const auto fields = totals_.fields();
    for (std::size_t i = 0; i < fields.size(); ++i) *fields[i] = s.totals[i];
    packed_ = s.records;
    geo_bytes_ = s.geometry;
  }

  std::shared_ptr<const DecodedPage> run() {
    records_ = storage::zstd_decompress(packed_, kMaxRecordBytes, context_);
    geometry_ = storage::decode_geometry(codec_, geo_bytes_, context_);
    ByteReader r(records_, context_ + " records");
    check_totals(r);
    auto page = std::shared_ptr<DecodedPage>(new DecodedPage());
    allocate(*page);
    read_vertices(r);
    std::uint64_t prev_op = 0;
    for (std::size_t o = 0; o < op_count_; ++o) {
      OpView& op = ops_[o];
      read_op(r, op, prev_op);
      prev_op = op.id.value;
    }
    r.expect_end();
    if (face_ != geometry_.faces.size()) r.fail("geometry has triangles no op claims");
    for (const auto& [n, used] : {std::pair{totals_.list, list_used_},
                                  {totals_.pre, pre_used_},
                                  {totals_.links, links_used_},
                                  {totals_.parents + totals_.children, ids_used_}}) {
      if (n != used) r.fail("the page's totals disagree with its records");
    }
    return page;
  }

 private:
  void check_totals(const ByteReader& r) {
    // Every op and every list entry, PreF triangle, link, parent and child takes a byte of the
    // records at least; vertices and triangles are the geometry's.
    const std::uint64_t bytes = records_.size();
    if (op_count_ == 0) r.fail("a page without ops");
    if (op_count_ > bytes) r.fail("implausible op count");
    if (totals_.vertices != geometry_.positions.size())
      r.fail("vertex count disagrees with the geometry");
    if (totals_.triangles != geometry_.faces.size())
      r.fail("triangle count disagrees with the geometry");
    for (std::uint64_t n :
         {totals_.list, totals_.pre, totals_.links, totals_.parents, totals_.children}) {
      if (n > bytes) r.fail("implausible count in the page header");
    }
  }

  template <class T>
  T* carve(std::size_t& at, std::uint64_t n) {
    static_assert(std::is_trivially_destructible_v<T> && alignof(T) <= 16);
    at = (at + alignof(T) - 1) & ~(alignof(T) - 1);
    T* p = block_ == nullptr ? nullptr : reinterpret_cast<T*>(block_ + at);  // sizing pass
    at += std::size_t(n) * sizeof(T);
    return p;
  }

  // One block for every array of the page (the first pass sizes it, the second places them).
  void allocate(DecodedPage& page) {
    std::size_t size = 0;
    for (int pass = 0; pass < 2; ++pass) {
      std::size_t at = 0;
      ops_ = carve<OpView>(at, op_count_);
      vertices_ = carve<Vertex>(at, totals_.vertices);
      triangles_ = carve<FragmentTriangle>(at, totals_.triangles);
      pre_ = carve<TriRef>(at, totals_.pre);
      links_ = carve<CoarserLink>(at, totals_.links);
      ids_ = carve<OpId>(at, totals_.parents + totals_.children);
      pre_tris_ = carve<PreTriangle>(at, totals_.pre);
      list_ = carve<std::uint32_t>(at, totals_.list);
      size = at;
      if (pass == 0) {
        page.block_.reset(new std::byte[size]);  // not zeroed: every element is constructed
        page.block_bytes_ = size;
        block_ = page.block_.get();
      }
    }
    std::uninitialized_default_construct_n(ops_, op_count_);
    std::uninitialized_default_construct_n(vertices_, totals_.vertices);
    std::uninitialized_default_construct_n(triangles_, totals_.triangles);
    std::uninitialized_default_construct_n(pre_, totals_.pre);
    std::uninitialized_default_construct_n(links_, totals_.links);
    std::uninitialized_default_construct_n(ids_, totals_.parents + totals_.children);
    std::uninitialized_default_construct_n(pre_tris_, totals_.pre);
    page.ops_ = ops_;
    page.op_count_ = op_count_;
    stamp_.assign(totals_.vertices, 0);
  }

  void read_vertices(ByteReader& r) {
    std::uint64_t prev = 0;
    for (std::size_t i = 0; i < totals_.vertices; ++i) {
      prev += std::uint64_t(r.svarint());
      for (std::int32_t c : geometry_.positions[i])  // the writer's grid is +-INT32_MAX
        if (c == std::numeric_limits<std::int32_t>::min()) r.fail("vertex outside the grid");
      vertices_[i] = {VertexId(prev), grid_.dequantize(geometry_.positions[i])};
    }
  }

  // n more entries of an array holding `total`, `used` so far.
  static std::size_t take(ByteReader& r, std::uint64_t n, std::size_t& used, std::uint64_t total,
                          const char* what) {
    if (n > total - used) r.fail(std::string("more ") + what + " than the page's total");
    const std::size_t at = used;
    used += std::size_t(n);
    return at;
  }

  void read_op(ByteReader& r, OpView& op, std::uint64_t prev_op) {
    const std::uint64_t id = prev_op + std::uint64_t(r.svarint());
    if (id == OpId::kInvalidValue) r.fail("op id out of range");
    op.id = OpId(id);
    op.birth_res = r.f32();
    if (!(op.birth_res >= 0.0 && op.birth_res <= 1.0)) r.fail("resolution out of range");
    op.error = stored_op_error(info_, op.birth_res);
    const std::uint32_t stamp = ++op_stamp_;
    const std::uint64_t nv = r.varint();
    const std::uint64_t nnew = r.varint();
    if (nnew > nv) r.fail("implausible new vertex count");
    const std::size_t list_at = take(r, nv, list_used_, totals_.list, "vertex-list entries");
    std::int64_t prev_index = 0;
    for (std::size_t i = 0; i < nv; ++i) {
      prev_index += r.svarint();
      if (prev_index < 0 || std::uint64_t(prev_index) >= totals_.vertices)
        r.fail("vertex index out of range");
      const auto p = std::uint32_t(prev_index);
      if (stamp_[p] == stamp) r.fail("an op lists a vertex twice");
      stamp_[p] = stamp;
      list_[list_at + i] = p;
    }
    op.vertices = {vertices_, std::size_t(totals_.vertices)};
    op.vertex_list = {list_ + list_at, std::size_t(nv)};
    op.new_vertex_count = std::uint32_t(nnew);
    read_children_and_fragment(r, op, stamp);
    read_parents_and_pre(r, op);
    const std::uint64_t nl = r.varint();
    CoarserLink* links = links_ + take(r, nl, links_used_, totals_.links, "coarser links");
    for (std::size_t i = 0; i < nl; ++i) {
      links[i] = read_link(r, id);
      if (links[i].tri >= op.fragment.size() || links[i].edge > 2 || links[i].coarser.edge > 2)
        r.fail("coarser link out of range");
    }
    op.coarser = {links, std::size_t(nl)};
    if (op.fragment.empty() && op.pre.empty()) r.fail("an op without triangles");
    if (op.vertex_list.empty()) r.fail("an op without vertices");
    read_roi_and_cone(r, op, set_box_and_sphere(op));
  }

  // op_bounds' box and sphere, from the op's own vertices: they are exactly the corners of F
  // and PreF (every listed vertex is used; PreF's corners are F's), so the values are the same.
  // The box is found on the grid (dequantizing is monotone on each axis); returns it there.
  std::array<std::array<std::int32_t, 3>, 2> set_box_and_sphere(OpView& op) const {
    std::array<std::int32_t, 3> lo{INT32_MAX, INT32_MAX, INT32_MAX};
    std::array<std::int32_t, 3> hi{INT32_MIN, INT32_MIN, INT32_MIN};
    for (std::uint32_t v : op.vertex_list) {
      const auto& q = geometry_.positions[v];
      for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], q[k]), hi[k] = std::max(hi[k], q[k]);
    }
    op.box = Box3{grid_.dequantize(lo), grid_.dequantize(hi)};
    op.sphere.center = op.box.center();
    double r2 = 0.0;
    for (std::uint32_t v : op.vertex_list) {
      const Vec3 d = op.vertices[v].p - op.sphere.center;
      r2 = std::max(r2, glm::dot(d, d));
    }
    op.sphere.radius = std::sqrt(r2);
    return {lo, hi};
  }

  void read_children_and_fragment(ByteReader& r, OpView& op, std::uint32_t stamp) {
    const std::uint64_t id = op.id.value;
    const std::uint64_t nc = r.varint();
    OpId* children = ids_ + take(r, nc, ids_used_, totals_.parents + totals_.children, "DAG links");
    std::uint64_t prev = id;
    for (std::size_t i = 0; i < nc; ++i) {
      const std::uint64_t d = r.varint();
      if (d == 0 || d >= ~prev) r.fail("child id out of range");  // the sum stays below ~0
      prev += d;
      children[i] = OpId(prev);
    }
    op.children = {children, std::size_t(nc)};
    child_res_.resize(nc);
    for (double& c : child_res_) {
      c = r.f32();
      if (!(c >= 0.0 && c <= 1.0)) r.fail("resolution out of range");
    }
    const std::uint64_t nf = r.varint();
    if (nf > geometry_.faces.size() - face_) r.fail("more triangles than the geometry holds");
    FragmentTriangle* tris = triangles_ + face_;
    for (std::size_t i = 0; i < nf; ++i) {
      FragmentTriangle& t = tris[i];
      const auto& f = geometry_.faces[face_ + i];
      for (int k = 0; k < 3; ++k) {
        if (f[k] >= totals_.vertices || stamp_[f[k]] != stamp)
          r.fail("a triangle uses a vertex its op does not list");
        t.v[k] = f[k];
      }
      const std::uint64_t killer = r.varint();
      if (killer > nc) r.fail("killer out of range");
      if (killer != 0) {
        t.killer = children[killer - 1];
        t.death_res = child_res_[killer - 1];
      }
    }
    face_ += std::size_t(nf);
    const std::uint64_t nvoid = r.varint();
    if (nvoid > nf) r.fail("implausible void triangle count");
    for (std::uint64_t i = 0; i < nvoid; ++i) {
      const std::uint64_t v = r.varint();
      if (v >= nf) r.fail("void triangle out of range");
      tris[v].flags |= FragmentTriangle::kVoid;
    }
    op.fragment = {tris, std::size_t(nf)};  // neighbours are derived on demand
  }

  void read_parents_and_pre(ByteReader& r, OpView& op) {
    const std::uint64_t id = op.id.value;
    const std::uint64_t np = r.varint();
    OpId* parents = ids_ + take(r, np, ids_used_, totals_.parents + totals_.children, "DAG links");
    std::uint64_t prev = id;
    for (std::size_t i = np; i-- > 0;) {  // stored decreasing
      const std::uint64_t d = r.varint();
      if (d == 0 || d > prev) r.fail("parent id out of range");
      prev -= d;
      parents[i] = OpId(prev);
    }
    op.parents = {parents, std::size_t(np)};
    const std::uint64_t npre = r.varint();
    const std::size_t at = take(r, npre, pre_used_, totals_.pre, "PreF triangles");
    TriRef* pre = pre_ + at;
    PreTriangle* pre_tris = pre_tris_ + at;
    for (std::size_t i = 0; i < npre; ++i) {
      const std::uint64_t pi = r.varint();
      if (pi >= np) r.fail("PreF parent out of range");
      pre[i] = {parents[pi], std::uint32_t(r.varint())};
      for (auto& c : pre_tris[i].v) {
        const std::uint64_t v = r.varint();
        if (v >= op.vertex_list.size()) r.fail("PreF corner out of range");
        c = op.vertex_list[v];
      }
    }
    const std::uint64_t npv = r.varint();
    if (npv > npre) r.fail("implausible void PreF count");
    for (std::uint64_t i = 0; i < npv; ++i) {
      const std::uint64_t v = r.varint();
      if (v >= npre) r.fail("void PreF triangle out of range");
      pre_tris[v].flags |= FragmentTriangle::kVoid;
    }
    op.pre = {pre, std::size_t(npre)};
    op.pre_tris = {pre_tris, std::size_t(npre)};
  }

  void read_roi_and_cone(ByteReader& r, OpView& op,
                         std::array<std::array<std::int32_t, 3>, 2> box) {
    auto [lo, hi] = box;
    constexpr std::int64_t kMax = std::numeric_limits<std::int32_t>::max();
    for (int k = 0; k < 3; ++k) {
      const std::uint64_t d = r.varint();
      if (d > std::uint64_t(2 * kMax) || std::int64_t(lo[k]) - std::int64_t(d) < -kMax)
        r.fail("ROI outside the grid");
      lo[k] = std::int32_t(std::int64_t(lo[k]) - std::int64_t(d));
    }
    for (int k = 0; k < 3; ++k) {
      const std::uint64_t d = r.varint();
      if (d > std::uint64_t(2 * kMax) || std::int64_t(hi[k]) + std::int64_t(d) > kMax)
        r.fail("ROI outside the grid");
      hi[k] = std::int32_t(std::int64_t(hi[k]) + std::int64_t(d));
    }
    op.roi = Box3{grid_.dequantize(lo), grid_.dequantize(hi)};
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

  const QuantGrid& grid_;
  const CrmrInfo& info_;
  const std::string& context_;
  storage::CodecId codec_ = storage::CodecId::kRaw;
  std::uint64_t op_count_ = 0;
  Totals totals_;
  ByteView packed_, geo_bytes_;
  Bytes records_;
  GeometryBlob geometry_;
  std::byte* block_ = nullptr;
  OpView* ops_ = nullptr;
  Vertex* vertices_ = nullptr;
  FragmentTriangle* triangles_ = nullptr;
  TriRef* pre_ = nullptr;
  CoarserLink* links_ = nullptr;
  OpId* ids_ = nullptr;  // parents and children
  PreTriangle* pre_tris_ = nullptr;
  std::uint32_t* list_ = nullptr;
  std::size_t face_ = 0, list_used_ = 0, pre_used_ = 0, links_used_ = 0, ids_used_ = 0;
  std::vector<std::uint32_t> stamp_;  // per page vertex: the last op (its stamp) listing it
  std::uint32_t op_stamp_ = 0;
  std::vector<double> child_res_;
};

std::shared_ptr<const DecodedPage> decode_page(ByteView page, const QuantGrid& grid,
                                               const CrmrInfo& info, const std::string& context) {
  return PageDecoder(page, grid, info, context).run();
}

DecodedPage::~DecodedPage() = default;

std::size_t DecodedPage::memory_bytes() const {
  return heap_block_bytes(block_bytes_) + heap_block_bytes(sizeof(DecodedPage) + 16);
}

std::size_t heap_block_bytes(std::size_t bytes) {
  return bytes == 0 ? 0 : std::max<std::size_t>(32, (bytes + 8 + 15) & ~std::size_t{15});
}

}  // namespace smr
