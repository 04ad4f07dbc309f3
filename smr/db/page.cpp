#include "smr/db/page.h"

#include <algorithm>
#include <array>
#include <bit>
#include <climits>
#include <cmath>
#include <limits>

#include <glm/geometric.hpp>
#include <memory>
#include <optional>
#include <type_traits>
#include <unordered_map>

#include "base/error.h"
#include "smr/core/crmr.h"
#include "smr/core/fragment_edges.h"
#include "storage/checksum.h"

namespace smr {

using storage::ByteReader;
using storage::Bytes;
using storage::ByteView;
using storage::ByteWriter;
using storage::GeometryBlob;

namespace {

constexpr std::size_t kMaxRecordBytes = std::size_t{1} << 31;
constexpr int kRecordLevel = 3;  // zstd level of the records

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

// The records' streams (page.h): each field of every op in one stream, so that zstd sees like
// next to like.
enum Stream : std::size_t {
  kOpHeads,      // per op: svarint id delta, varint vertices, new vertices, triangles, children,
                 // parents, PreF triangles
  kResolutions,  // per op: svarint birth_res as f32 bits, less the previous op's
  kVertexIds,    // per page vertex, in table order: svarint id delta
  kLists,        // per vertex-list entry: 0 = the next new table vertex, else (new so far - index)
  kCorners,      // per fragment triangle: 3 varint corners, as indices into the op's list
  kChildren,     // per child: varint id delta, increasing from the op
  kChildRes,     // per child on another page: svarint its birth_res as f32 bits, less the op's
                 //   (a page's own children give theirs)
  kKillers,      // per fragment triangle: varint 0 (never replaced) or 1 + its killer's child index
  kVoids,        // per op: varint count and indices of void fragment, then PreF, triangles
  kParents,      // per parent: varint id delta, decreasing from the op
  kPre,          // per PreF triangle: varint parent index, varint triangle index
  kPreCorners,   // per PreF triangle: 3 varint corners, as indices into the op's list
  kEdges,        // per boundary edge of F: u8 0 model boundary, 1 its PreF triangle's, 2 stored
  kLinks,        // per stored link: svarint op delta, varint triangle, u8 edge
  kRois,         // per op: 6 varint units of 2^roi_shift grid steps outside the op's box
  kCones,        // per op: u8 0 full | 1, then 3 x i8 axis, u8 half angle (ConeCode)
  kStreamCount
};
constexpr std::array<const char*, kStreamCount> kStreamNames = {
    "op_heads",  "resolutions", "vertex_ids", "lists",   "corners", "children",
    "child_res", "killers",     "voids",      "parents", "pre",     "pre_corners",
    "edges",     "links",       "rois",       "cones"};

enum EdgeCode : std::uint8_t { kModelBoundary = 0, kInside = 1, kStored = 2 };
enum IdCode : std::uint8_t { kStoredIds = 0, kGridKeys = 1 };
constexpr std::uint64_t kMaxKeyWidth = std::uint64_t{1} << 32;

// A terrain vertex's id from its grid coordinates (smr/db/quantize.h, snap_vertices).
std::uint64_t grid_key(const std::array<std::int32_t, 3>& q, std::uint64_t width) {
  return std::uint64_t(q[1]) * width + std::uint64_t(q[0]);
}

// A fragment triangle's corners as indices into its op's vertex list.
struct LocalTri {
  std::array<std::uint32_t, 3> v;
};

// The directed edges of PreF's triangles: edge k of triangle i, (a, b), as a << 32 | b at 3i + k.
template <class Pre>
void pre_edge_keys(std::span<const Pre> pre_tris, std::vector<std::uint64_t>& keys) {
  keys.resize(3 * pre_tris.size());
  for (std::size_t i = 0; i < pre_tris.size(); ++i) {
    const auto& v = pre_tris[i].v;
    keys[3 * i] = std::uint64_t{v[0]} << 32 | v[1];
    keys[3 * i + 1] = std::uint64_t{v[1]} << 32 | v[2];
    keys[3 * i + 2] = std::uint64_t{v[2]} << 32 | v[0];
  }
}

// The link a boundary edge (a, b) of F gets from PreF (Hypermesh, Brown 4.5.1): the first PreF
// triangle with the same directed edge (it lies on the inside of F's boundary, which is PreF's)
// and that edge; nullopt when none has it. `keys`: pre_edge_keys of PreF.
std::optional<EdgeRef> inside_link(std::span<const TriRef> pre, std::span<const std::uint64_t> keys,
                                   std::uint32_t a, std::uint32_t b) {
  const std::uint64_t key = std::uint64_t{a} << 32 | b;
  for (std::size_t j = 0; j < keys.size(); ++j) {
    if (keys[j] == key) return EdgeRef{pre[j / 3], std::uint8_t(j % 3)};
  }
  return std::nullopt;
}

// A resolution in [0, 1] as its 32-bit float's bits: increasing with it, so that nearby
// resolutions differ by small numbers.
std::int64_t res_bits(double res) {
  return std::bit_cast<std::uint32_t>(float(res));
}
constexpr std::int64_t kOneBits = 0x3f800000;  // res_bits(1.0)

void require_float(double v, const char* what, const Op& op) {
  if (double(float(v)) != v)
    throw_internal("page encoding: op " + std::to_string(op.id.value) + " has a " + what +
                   " that is not a 32-bit float (round_for_storage was not applied)");
}

class PageEncoder {
 public:
  PageEncoder(std::span<const Op* const> ops, const QuantGrid& grid) : ops_(ops), grid_(grid) {
    for (const Op* op : ops) res_of_.emplace_back(op->id.value, op->birth_res);
    std::sort(res_of_.begin(), res_of_.end());
  }

  // The records (streams) and the geometry's positions.
  Bytes run(GeometryBlob& geometry, Totals& totals) {
    std::unordered_map<std::uint64_t, std::uint32_t> page_index;
    std::uint64_t prev_op = 0;
    std::int64_t prev_res = 0;
    for (const Op* op : ops_) {
      const auto id = op->id.value;
      w(kOpHeads).svarint(std::int64_t(id - prev_op));
      prev_op = id;
      for (std::uint64_t n :
           {op->vertices.size(), std::size_t(op->new_vertex_count), op->fragment.size(),
            op->children.size(), op->parents.size(), op->pre.size()})
        w(kOpHeads).varint(n);
      require_float(op->birth_res, "birth resolution", *op);
      w(kResolutions).svarint(res_bits(op->birth_res) - prev_res);
      prev_res = res_bits(op->birth_res);
      for (const Vertex& v : op->vertices) {
        const auto [it, fresh] = page_index.emplace(v.id.value, std::uint32_t(page_index.size()));
        if (!fresh) {
          w(kLists).varint(page_index.size() - it->second);
          continue;
        }
        w(kLists).varint(0);
        fresh_ids_.push_back(v.id.value);
        const auto q = grid_.quantize(v.p);
        if (grid_.dequantize(q) != v.p) {
          throw_internal("page encoding: vertex " + std::to_string(v.id.value) +
                         " is not on the quantization grid");
        }
        geometry.positions.push_back(q);
      }
      for (const FragmentTriangle& t : op->fragment)
        for (std::uint32_t c : t.v) w(kCorners).varint(c);
      write_children_and_killers(*op);
      write_parents_and_pre(*op);
      write_links(*op);
      write_roi_and_cone(*op);
      totals.list += op->vertices.size();
      totals.triangles += op->fragment.size();
      totals.pre += op->pre.size();
      totals.links += op->coarser.size();
      totals.parents += op->parents.size();
      totals.children += op->children.size();
    }
    totals.vertices = geometry.positions.size();
    write_vertex_ids(geometry);
    Bytes records;
    ByteWriter out(records);
    for (const Bytes& s : streams_) out.varint(s.size());
    for (const Bytes& s : streams_) out.bytes(s);
    return records;
  }

 private:
  ByteWriter w(Stream s) { return ByteWriter(streams_[s]); }

  // The page's vertex ids: a terrain's are its DEM sample indices, row * width + col
  // (snap_vertices), from the positions given the width; others are stored.
  void write_vertex_ids(const GeometryBlob& geometry) {
    const auto& q = geometry.positions;
    std::uint64_t width = 0;  // from the first vertex off row 0
    for (std::size_t i = 0; i < q.size() && width == 0; ++i) {
      if (q[i][1] > 0 && q[i][0] >= 0 && fresh_ids_[i] >= std::uint64_t(q[i][0]))
        width = (fresh_ids_[i] - std::uint64_t(q[i][0])) / std::uint64_t(q[i][1]);
    }
    bool keys = width <= kMaxKeyWidth;
    for (std::size_t i = 0; i < q.size() && keys; ++i) {
      keys = q[i][0] >= 0 && q[i][1] >= 0 &&
             (width == 0 ? q[i][1] == 0 : std::uint64_t(q[i][0]) < width) &&
             fresh_ids_[i] == grid_key(q[i], width);
    }
    if (keys) {
      w(kVertexIds).u8(kGridKeys);
      w(kVertexIds).varint(width);
      return;
    }
    w(kVertexIds).u8(kStoredIds);
    std::uint64_t prev = 0;
    for (std::uint64_t id : fresh_ids_) {
      w(kVertexIds).svarint(std::int64_t(id - prev));
      prev = id;
    }
  }

  void write_children_and_killers(const Op& op) {
    const std::uint64_t id = op.id.value;
    std::uint64_t prev = id;
    for (OpId c : op.children) {
      if (c.value <= prev) throw_internal("page encoding: children not increasing");
      w(kChildren).varint(c.value - prev);
      prev = c.value;
    }
    child_res_.assign(op.children.size(), -1.0);
    std::vector<std::uint32_t> voids;
    for (std::uint32_t i = 0; i < op.fragment.size(); ++i) {
      const FragmentTriangle& t = op.fragment[i];
      if (t.flags & FragmentTriangle::kVoid) voids.push_back(i);
      if (t.flags & ~FragmentTriangle::kVoid) throw_internal("page encoding: unknown flags");
      if (!t.killer.valid()) {
        if (t.death_res != 1.0) throw_internal("page encoding: unreplaced triangle below 1");
        w(kKillers).varint(0);
        continue;
      }
      auto it = std::lower_bound(op.children.begin(), op.children.end(), t.killer);
      if (it == op.children.end() || *it != t.killer)
        throw_internal("page encoding: a killer is not a child");
      const std::size_t c = std::size_t(it - op.children.begin());
      if (child_res_[c] >= 0.0 && child_res_[c] != t.death_res)
        throw_internal("page encoding: one killer, two death resolutions");
      child_res_[c] = t.death_res;
      w(kKillers).varint(c + 1);
    }
    for (std::size_t c = 0; c < op.children.size(); ++c) {
      const auto on_page =
          std::lower_bound(res_of_.begin(), res_of_.end(), std::pair{op.children[c].value, -1.0});
      if (on_page != res_of_.end() && on_page->first == op.children[c].value) {
        if (child_res_[c] >= 0.0 && child_res_[c] != on_page->second)
          throw_internal("page encoding: a triangle's death_res is not its killer's birth_res");
        continue;
      }
      if (child_res_[c] < 0.0) child_res_[c] = 1.0;  // kills nothing here: never read
      require_float(child_res_[c], "death resolution", op);
      w(kChildRes).svarint(res_bits(child_res_[c]) - res_bits(op.birth_res));
    }
    w(kVoids).varint(voids.size());
    for (std::uint32_t v : voids) w(kVoids).varint(v);
  }

  void write_parents_and_pre(const Op& op) {
    std::uint64_t prev = op.id.value;
    for (auto p = op.parents.rbegin(); p != op.parents.rend(); ++p) {
      if (p->value >= prev) throw_internal("page encoding: parents not increasing");
      w(kParents).varint(prev - p->value);
      prev = p->value;
    }
    if (op.pre_tris.size() != op.pre.size()) throw_internal("page encoding: pre_tris missing");
    std::vector<std::uint32_t> pre_voids;
    for (std::size_t i = 0; i < op.pre.size(); ++i) {
      const TriRef& r = op.pre[i];
      auto it = std::lower_bound(op.parents.begin(), op.parents.end(), r.op);
      if (it == op.parents.end() || *it != r.op)
        throw_internal("page encoding: a PreF triangle's op is not a parent");
      w(kPre).varint(std::uint64_t(it - op.parents.begin()));
      w(kPre).varint(r.index);
      for (std::uint32_t c : op.pre_tris[i].v) w(kPreCorners).varint(c);
      if (op.pre_tris[i].flags & FragmentTriangle::kVoid) pre_voids.push_back(std::uint32_t(i));
    }
    w(kVoids).varint(pre_voids.size());
    for (std::uint32_t v : pre_voids) w(kVoids).varint(v);
  }

  // Hypermesh links: one code per boundary edge of F; a link the PreF triangle inside the edge
  // gives is not stored.
  void write_links(const Op& op) {
    std::size_t next = 0;
    std::vector<std::uint64_t> pre_keys;
    pre_edge_keys(std::span<const PreTriangle>(op.pre_tris), pre_keys);
    for_each_boundary_edge(std::span<const FragmentTriangle>(op.fragment), op.vertices.size(),
                           [&](std::uint32_t tri, std::uint8_t edge) {
                             if (next == op.coarser.size() || op.coarser[next].tri != tri ||
                                 op.coarser[next].edge != edge) {
                               w(kEdges).u8(kModelBoundary);
                               return;
                             }
                             const CoarserLink& l = op.coarser[next++];
                             const auto& t = op.fragment[tri];
                             const auto in =
                                 inside_link(op.pre, pre_keys, t.v[edge], t.v[(edge + 1) % 3]);
                             if (in && *in == l.coarser) {
                               w(kEdges).u8(kInside);
                               return;
                             }
                             w(kEdges).u8(kStored);
                             w(kLinks).svarint(std::int64_t(op.id.value - l.coarser.tri.op.value));
                             w(kLinks).varint(l.coarser.tri.index);
                             w(kLinks).u8(l.coarser.edge);
                           });
    if (next != op.coarser.size())
      throw_internal("page encoding: op " + std::to_string(op.id.value) +
                     " has a coarser link off its fragment's boundary, or links out of order");
  }

  // ROI, in grid steps outside the op's own box; subtree normal cone (canonical: exact in its
  // codes).
  void write_roi_and_cone(const Op& op) {
    const auto blo = grid_.quantize(op.box.lo), bhi = grid_.quantize(op.box.hi);
    const auto rlo = grid_.quantize(op.roi.lo), rhi = grid_.quantize(op.roi.hi);
    std::array<int, 3> shift{};
    for (int k = 0; k < 3; ++k) shift[k] = roi_shift(op.error, grid_.step[k]);
    auto units = [&](std::int64_t d, int k) {  // d grid steps, a multiple of 2^shift (stored_roi)
      if (d < 0 || (d & ((std::int64_t{1} << shift[k]) - 1)) != 0)
        throw_internal("page encoding: op " + std::to_string(op.id.value) +
                       "'s ROI is not as stored_roi gives it");
      return std::uint64_t(d >> shift[k]);
    };
    for (int k = 0; k < 3; ++k) w(kRois).varint(units(std::int64_t(blo[k]) - rlo[k], k));
    for (int k = 0; k < 3; ++k) w(kRois).varint(units(std::int64_t(rhi[k]) - bhi[k], k));
    const ConeCode cone = cone_code(op.subtree_cone);
    w(kCones).u8(cone.full ? 0 : 1);
    if (!cone.full) {
      for (std::int8_t a : cone.axis) w(kCones).u8(static_cast<std::uint8_t>(a));
      w(kCones).u8(cone.half);
    }
  }

  std::span<const Op* const> ops_;
  const QuantGrid& grid_;
  std::array<Bytes, kStreamCount> streams_;
  std::vector<std::pair<std::uint64_t, double>> res_of_;  // the page's ops: id, birth_res
  std::vector<double> child_res_;
  std::vector<std::uint64_t> fresh_ids_;  // the page's vertex ids, in table order
};

}  // namespace

Bytes encode_page(std::span<const Op* const> ops, const QuantGrid& grid, storage::CodecId codec) {
  GeometryBlob geometry;
  Totals totals;
  const Bytes records = PageEncoder(ops, grid).run(geometry, totals);
  Bytes out;
  ByteWriter pw(out);
  pw.u8(kPageFormat);
  pw.u8(static_cast<std::uint8_t>(codec));
  pw.varint(ops.size());
  for (std::uint64_t* n : totals.fields()) pw.varint(*n);
  pw.blob(storage::zstd_compress(records, kRecordLevel));
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
              const std::string& context, bool links = true)
      : grid_(grid), info_(info), context_(context), links_(links) {
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
    unpack();
    auto page = std::shared_ptr<DecodedPage>(new DecodedPage());
    allocate(*page);
    read_vertices();
    read_heads();
    for (std::size_t o = 0; o < op_count_; ++o) read_op(ops_[o], heads_[o]);
    for (std::size_t i = 0; i < kStreamCount; ++i) {
      if ((links_ || (i != kEdges && i != kLinks)) && !in_[i].at_end())
        in_[i].fail("bytes no op reads");
    }
    if (fresh_ != totals_.vertices) fail("vertices no op lists");
    for (const auto& [n, used] : {std::pair{totals_.list, list_used_},
                                  {totals_.triangles, face_},
                                  {totals_.pre, pre_used_},
                                  {links_kept(), links_used_},
                                  {totals_.parents + totals_.children, ids_used_}}) {
      if (n != used) fail("the page's totals disagree with its records");
    }
    return page;
  }

  // The cut of the page below `below` (page.h, cut_page); false if it has a void triangle.
  bool cut(double below, PageCut& out) {
    unpack();
    out.vertex_ids.clear();
    out.positions.clear();
    out.triangles.clear();
    out.values.clear();
    out.ops_in_x = 0;
    const auto n = std::size_t(totals_.vertices);
    page_ids_.resize(n);
    read_vertex_ids([&](std::size_t i, std::uint64_t id, const auto&) {
      if (id == ~std::uint64_t{0}) fail("vertex id out of range");  // a map's empty key
      page_ids_[i] = id;
    });
    // `below` above 1: every op is in X (level_cut.h), no killer's resolution is needed nor read.
    const bool every_op = below > 1.0;
    read_heads(!every_op);
    stamp_.assign(n, 0);
    used_.assign(n, 0);
    std::size_t parents = 0, pre = 0;  // counted, not read
    for (const Head& h : heads_) {
      if (h.vertices == 0) fail("an op without vertices");
      if (h.triangles == 0 && h.pre == 0) fail("an op without triangles");
      const bool in_x = h.id == kBaseOp.value || h.res < below;
      out.ops_in_x += in_x ? 1 : 0;
      take(h.vertices, list_used_, totals_.list, "vertex-list entries");  // before any resize
      cut_list_.resize(h.vertices);
      read_list(h.vertices, cut_list_.data());
      take(h.children, ids_used_, totals_.children, "children");
      cut_children_.resize(h.children);
      read_children(h, cut_children_.data());
      child_res_.assign(h.children, 1.0);
      for (std::size_t i = 0; i < h.children && !every_op; ++i)
        child_res_[i] = child_res(cut_children_[i].value, h.res);
      take(h.triangles, face_, totals_.triangles, "triangles");
      ByteReader& kr = in_[kKillers];
      for (std::size_t i = 0; i < h.triangles; ++i) {
        std::array<std::uint32_t, 3> c{};
        for (std::uint32_t& k : c) k = cut_list_[local_corner(in_[kCorners], h.vertices)];
        const std::uint64_t killer = kr.varint();
        if (killer > h.children) kr.fail("killer out of range");
        if (!in_x || (killer != 0 && child_res_[killer - 1] < below)) continue;
        for (std::uint32_t& k : c) {
          std::uint32_t& u = used_[k];
          if (u == 0) {
            out.vertex_ids.push_back(page_ids_[k]);
            out.positions.push_back(grid_.dequantize(geometry_.positions[k]));
            u = std::uint32_t(out.vertex_ids.size());
          }
          k = u - 1;
        }
        out.triangles.push_back(c);
        out.values.push_back(killer == 0 ? 1.0f : float(child_res_[killer - 1]));
      }
      // Fragment voids, then PreF voids (the order encode_page writes them in).
      if (in_[kVoids].varint() != 0 || in_[kVoids].varint() != 0) return false;
      take(h.parents, parents, totals_.parents, "parents");
      take(h.pre, pre, totals_.pre, "PreF triangles");
    }
    for (Stream s :
         {kOpHeads, kResolutions, kVertexIds, kLists, kCorners, kChildren, kKillers, kVoids}) {
      if (!in_[s].at_end()) in_[s].fail("bytes no op reads");
    }
    if (!every_op && !in_[kChildRes].at_end()) in_[kChildRes].fail("bytes no op reads");
    if (fresh_ != totals_.vertices) fail("vertices no op lists");
    if (list_used_ != totals_.list || face_ != totals_.triangles || ids_used_ != totals_.children ||
        parents != totals_.parents || pre != totals_.pre)
      fail("the page's totals disagree with its records");
    return true;
  }

  std::vector<std::pair<std::string, Bytes>> streams() {
    records_ = storage::zstd_decompress(packed_, kMaxRecordBytes, context_);
    open_streams();
    std::vector<std::pair<std::string, Bytes>> out;
    for (std::size_t i = 0; i < kStreamCount; ++i) {
      const ByteView b = in_[i].bytes(in_[i].remaining());
      out.emplace_back(kStreamNames[i], Bytes(b.begin(), b.end()));
    }
    return out;
  }

 private:
  [[noreturn]] void fail(const std::string& what) const {
    ByteReader(ByteView{}, context_).fail(what);
  }

  // The records and the geometry decompressed, the streams opened, the totals checked.
  void unpack() {
    records_ = storage::zstd_decompress(packed_, kMaxRecordBytes, context_);
    geometry_ = storage::decode_geometry(codec_, geo_bytes_, context_);
    open_streams();
    check_totals();
  }

  void open_streams() {
    ByteReader r(records_, context_ + " records");
    std::array<std::uint64_t, kStreamCount> sizes{};
    for (std::uint64_t& n : sizes) n = r.varint();
    for (std::size_t i = 0; i < kStreamCount; ++i) {
      if (sizes[i] > r.remaining()) r.fail(std::string("stream ") + kStreamNames[i] + " cut short");
      in_.emplace_back(r.bytes(std::size_t(sizes[i])),
                       context_ + " records (" + kStreamNames[i] + ")");
    }
    r.expect_end();
  }

  void check_totals() const {
    // Every op, list entry, triangle, PreF triangle, parent and child takes a byte of its stream
    // at least, every link a byte of the edges'; vertices are the geometry's.
    if (op_count_ == 0) fail("a page without ops");
    if (op_count_ > in_[kOpHeads].remaining()) fail("implausible op count");
    if (totals_.vertices != geometry_.positions.size())
      fail("vertex count disagrees with the geometry");
    if (!geometry_.faces.empty()) fail("geometry with faces (pages keep them in the records)");
    for (const auto& [n, s] : {std::pair{totals_.list, kLists},
                               {totals_.triangles, kKillers},
                               {totals_.pre, kPre},
                               {totals_.links, kEdges},
                               {totals_.parents, kParents},
                               {totals_.children, kChildren}}) {
      if (n > in_[s].remaining()) fail("implausible count in the page header");
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

  // The links the page's block holds: none when decode_page was asked for none.
  std::uint64_t links_kept() const { return links_ ? totals_.links : 0; }

  // One block for every array of the page (the first pass sizes it, the second places them).
  void allocate(DecodedPage& page) {
    std::size_t size = 0;
    for (int pass = 0; pass < 2; ++pass) {
      std::size_t at = 0;
      ops_ = carve<OpView>(at, op_count_);
      vertices_ = carve<Vertex>(at, totals_.vertices);
      triangles_ = carve<FragmentTriangle>(at, totals_.triangles);
      pre_ = carve<TriRef>(at, totals_.pre);
      links_block_ = carve<CoarserLink>(at, links_kept());
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
    std::uninitialized_default_construct_n(links_block_, links_kept());
    std::uninitialized_default_construct_n(ids_, totals_.parents + totals_.children);
    std::uninitialized_default_construct_n(pre_tris_, totals_.pre);
    page.ops_ = ops_;
    page.op_count_ = op_count_;
    stamp_.assign(totals_.vertices, 0);
  }

  // The counts of one op, read before any op so that a child on the page gives its birth_res.
  struct Head {
    std::uint64_t id = 0, vertices = 0, fresh = 0, triangles = 0, children = 0, parents = 0,
                  pre = 0;
    double res = 0.0;
  };

  // `by_id`: keeps the ops' resolutions by id too (res_of_), for their parents on the page.
  void read_heads(bool by_id = true) {
    heads_.resize(op_count_);  // op_count_ <= the heads' bytes (check_totals)
    ByteReader& r = in_[kOpHeads];
    std::uint64_t prev = 0;
    std::int64_t prev_res = 0;
    for (Head& h : heads_) {
      h.id = prev + std::uint64_t(r.svarint());
      if (h.id == OpId::kInvalidValue) r.fail("op id out of range");
      prev = h.id;
      for (std::uint64_t* n :
           {&h.vertices, &h.fresh, &h.triangles, &h.children, &h.parents, &h.pre})
        *n = r.varint();
      if (h.fresh > h.vertices) r.fail("implausible new vertex count");
      h.res = read_res(in_[kResolutions], prev_res);
      prev_res = res_bits(h.res);
      if (by_id) res_of_.emplace_back(h.id, h.res);
    }
    if (!std::is_sorted(res_of_.begin(), res_of_.end())) std::sort(res_of_.begin(), res_of_.end());
  }

  // A resolution stored as the difference of its bits from `base`'s (res_bits).
  static double read_res(ByteReader& r, std::int64_t base) {
    const std::int64_t d = r.svarint();
    if (d < -kOneBits || d > kOneBits || base + d < 0 || base + d > kOneBits)
      r.fail("resolution out of range");
    return double(std::bit_cast<float>(std::uint32_t(base + d)));
  }

  void read_vertices() {
    read_vertex_ids([&](std::size_t i, std::uint64_t id, const std::array<std::int32_t, 3>& q) {
      vertices_[i] = {VertexId(id), grid_.dequantize(q)};
    });
  }

  // f(i, id, quantized position) for each page vertex i, in table order.
  template <class F>
  void read_vertex_ids(F&& f) {
    ByteReader& r = in_[kVertexIds];
    const std::uint8_t mode = r.u8();
    if (mode > kGridKeys) r.fail("unknown vertex id code");
    const std::uint64_t width = mode == kGridKeys ? r.varint() : 0;
    if (width > kMaxKeyWidth) r.fail("implausible grid width");
    std::uint64_t prev = 0;
    for (std::size_t i = 0; i < totals_.vertices; ++i) {
      const auto& q = geometry_.positions[i];
      for (std::int32_t c : q)  // the writer's grid is +-INT32_MAX
        if (c == std::numeric_limits<std::int32_t>::min()) r.fail("vertex outside the grid");
      if (mode == kGridKeys) {
        if (q[0] < 0 || q[1] < 0 || (width != 0 && std::uint64_t(q[0]) >= width) ||
            (width == 0 && q[1] != 0))
          r.fail("a terrain vertex off its grid");
        prev = grid_key(q, width);
      } else {
        prev += std::uint64_t(r.svarint());
      }
      f(i, prev, q);
    }
  }

  // n more entries of an array holding `total`, `used` so far.
  std::size_t take(std::uint64_t n, std::size_t& used, std::uint64_t total,
                   const char* what) const {
    if (n > total - used) fail(std::string("more ") + what + " than the page's total");
    const std::size_t at = used;
    used += std::size_t(n);
    return at;
  }

  void read_op(OpView& op, const Head& h) {
    op.id = OpId(h.id);
    op.birth_res = h.res;
    op.error = stored_op_error(info_, op.birth_res);
    const std::size_t list_at = take(h.vertices, list_used_, totals_.list, "vertex-list entries");
    read_list(h.vertices, list_ + list_at);
    op.vertices = {vertices_, std::size_t(totals_.vertices)};
    op.vertex_list = {list_ + list_at, std::size_t(h.vertices)};
    op.new_vertex_count = std::uint32_t(h.fresh);
    read_children_and_fragment(op, h);
    read_parents_and_pre(op, h);
    if (links_)
      read_links(op);
    else
      op.links = false;
    if (op.fragment.empty() && op.pre.empty()) fail("an op without triangles");
    if (op.vertex_list.empty()) fail("an op without vertices");
    read_roi_and_cone(op, set_box_and_sphere(op));
  }

  // An op's vertex list: n page vertex indices into `list`.
  void read_list(std::uint64_t n, std::uint32_t* list) {
    const std::uint32_t stamp = ++op_stamp_;
    ByteReader& r = in_[kLists];
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint64_t code = r.varint();
      if (code == 0 && fresh_ == totals_.vertices) r.fail("more vertices than the page's total");
      if (code > fresh_) r.fail("vertex index out of range");
      const auto p = std::uint32_t(code == 0 ? fresh_++ : fresh_ - code);
      if (stamp_[p] == stamp) r.fail("an op lists a vertex twice");
      stamp_[p] = stamp;
      list[i] = p;
    }
  }

  // An op's children, increasing from the op, into `children`.
  void read_children(const Head& h, OpId* children) {
    ByteReader& cr = in_[kChildren];
    std::uint64_t prev = h.id;
    for (std::size_t i = 0; i < h.children; ++i) {
      const std::uint64_t d = cr.varint();
      if (d == 0 || d >= ~prev) cr.fail("child id out of range");  // the sum stays below ~0
      prev += d;
      children[i] = OpId(prev);
    }
  }

  // A corner as stored: an index into the op's vertex list (op.vertex_list[it] is the page's).
  static std::uint32_t local_corner(ByteReader& r, std::size_t list_size) {
    const std::uint64_t c = r.varint();
    if (c >= list_size) r.fail("a corner out of its op's vertex list");
    return std::uint32_t(c);
  }

  // The birth_res of child `id` of an op of resolution `res`: the page's op's, or the next
  // stored one.
  double child_res(std::uint64_t id, double res) {
    const auto on_page = std::lower_bound(res_of_.begin(), res_of_.end(), std::pair{id, -1.0});
    if (on_page != res_of_.end() && on_page->first == id) return on_page->second;
    return read_res(in_[kChildRes], res_bits(res));
  }

  void read_children_and_fragment(OpView& op, const Head& h) {
    OpId* children =
        ids_ + take(h.children, ids_used_, totals_.parents + totals_.children, "DAG links");
    read_children(h, children);
    op.children = {children, std::size_t(h.children)};
    child_res_.resize(h.children);
    for (std::size_t i = 0; i < h.children; ++i)
      child_res_[i] = child_res(children[i].value, h.res);
    FragmentTriangle* tris = triangles_ + take(h.triangles, face_, totals_.triangles, "triangles");
    ByteReader& kr = in_[kKillers];
    local_tris_.resize(h.triangles);
    for (std::size_t i = 0; i < h.triangles; ++i) {
      FragmentTriangle& t = tris[i];
      for (int k = 0; k < 3; ++k) {
        local_tris_[i].v[k] = local_corner(in_[kCorners], h.vertices);
        t.v[k] = op.vertex_list[local_tris_[i].v[k]];
      }
      const std::uint64_t killer = kr.varint();
      if (killer > h.children) kr.fail("killer out of range");
      if (killer != 0) {
        t.killer = children[killer - 1];
        t.death_res = child_res_[killer - 1];
      }
    }
    op.fragment = {tris, std::size_t(h.triangles)};  // neighbours are derived on demand
    read_voids(std::span<FragmentTriangle>(tris, std::size_t(h.triangles)));
  }

  template <class Tri>
  void read_voids(std::span<Tri> tris) {
    ByteReader& r = in_[kVoids];
    const std::uint64_t n = r.varint();
    if (n > tris.size()) r.fail("implausible void triangle count");
    for (std::uint64_t i = 0; i < n; ++i) {
      const std::uint64_t v = r.varint();
      if (v >= tris.size()) r.fail("void triangle out of range");
      tris[v].flags |= FragmentTriangle::kVoid;
    }
  }

  void read_parents_and_pre(OpView& op, const Head& h) {
    OpId* parents =
        ids_ + take(h.parents, ids_used_, totals_.parents + totals_.children, "DAG links");
    ByteReader& r = in_[kParents];
    std::uint64_t prev = h.id;
    for (std::size_t i = h.parents; i-- > 0;) {  // stored decreasing
      const std::uint64_t d = r.varint();
      if (d == 0 || d > prev) r.fail("parent id out of range");
      prev -= d;
      parents[i] = OpId(prev);
    }
    op.parents = {parents, std::size_t(h.parents)};
    const std::size_t at = take(h.pre, pre_used_, totals_.pre, "PreF triangles");
    TriRef* pre = pre_ + at;
    PreTriangle* pre_tris = pre_tris_ + at;
    ByteReader& pr = in_[kPre];
    for (std::size_t i = 0; i < h.pre; ++i) {
      const std::uint64_t pi = pr.varint();
      if (pi >= h.parents) pr.fail("PreF parent out of range");
      pre[i] = {parents[pi], std::uint32_t(pr.varint())};
      for (auto& c : pre_tris[i].v) c = op.vertex_list[local_corner(in_[kPreCorners], h.vertices)];
    }
    op.pre = {pre, std::size_t(h.pre)};
    op.pre_tris = {pre_tris, std::size_t(h.pre)};
    read_voids(std::span<PreTriangle>(pre_tris, std::size_t(h.pre)));
  }

  // Hypermesh links, one code per boundary edge of F (page.h).
  void read_links(OpView& op) {
    CoarserLink* links = links_block_ + links_used_;
    ByteReader& er = in_[kEdges];
    ByteReader& lr = in_[kLinks];
    pre_edge_keys(op.pre_tris, pre_keys_);
    for_each_boundary_edge(std::span<const LocalTri>(local_tris_), op.vertex_list.size(),
                           [&](std::uint32_t tri, std::uint8_t edge) {
                             const std::uint8_t code = er.u8();
                             if (code == kModelBoundary) return;
                             if (links_used_ == totals_.links)
                               er.fail("more coarser links than the page's total");
                             CoarserLink& l = links_block_[links_used_++];
                             l.tri = tri;
                             l.edge = edge;
                             if (code == kInside) {
                               const auto& t = op.fragment[tri];
                               const auto in =
                                   inside_link(op.pre, pre_keys_, t.v[edge], t.v[(edge + 1) % 3]);
                               if (!in)
                                 er.fail("a boundary edge without a PreF triangle inside it");
                               l.coarser = *in;
                               return;
                             }
                             if (code != kStored) er.fail("unknown boundary edge code");
                             l.coarser.tri.op = OpId(op.id.value - std::uint64_t(lr.svarint()));
                             l.coarser.tri.index = std::uint32_t(lr.varint());
                             l.coarser.edge = lr.u8();
                             if (l.coarser.edge > 2) lr.fail("coarser link out of range");
                           });
    op.coarser = {links, std::size_t(links_block_ + links_used_ - links)};
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

  void read_roi_and_cone(OpView& op, std::array<std::array<std::int32_t, 3>, 2> box) {
    auto [lo, hi] = box;
    ByteReader& r = in_[kRois];
    constexpr std::int64_t kMax = std::numeric_limits<std::int32_t>::max();
    // A margin: units of 2^roi_shift grid steps (stored_roi), from the op's stored error.
    std::array<int, 3> shift{};
    for (int k = 0; k < 3; ++k) shift[k] = roi_shift(op.error, grid_.step[k]);
    const auto margin = [&](int k) {
      const std::uint64_t u = r.varint();
      if (u > std::uint64_t(2 * kMax) >> shift[k]) r.fail("ROI outside the grid");
      return std::int64_t(u << shift[k]);
    };
    for (int k = 0; k < 3; ++k) {
      const std::int64_t v = std::int64_t(lo[k]) - margin(k);
      if (v < -kMax) r.fail("ROI outside the grid");
      lo[k] = std::int32_t(v);
    }
    for (int k = 0; k < 3; ++k) {
      const std::int64_t v = std::int64_t(hi[k]) + margin(k);
      if (v > kMax) r.fail("ROI outside the grid");
      hi[k] = std::int32_t(v);
    }
    op.roi = Box3{grid_.dequantize(lo), grid_.dequantize(hi)};
    ConeCode cone;
    ByteReader& c = in_[kCones];
    const std::uint8_t cone_flag = c.u8();
    if (cone_flag > 1) c.fail("bad subtree cone flag");
    cone.full = cone_flag == 0;
    if (!cone.full) {
      for (std::int8_t& a : cone.axis) {
        a = static_cast<std::int8_t>(c.u8());
        if (a < -kConeAxisMax) c.fail("subtree cone axis out of range");
      }
      if (cone.axis == std::array<std::int8_t, 3>{}) c.fail("subtree cone without an axis");
      cone.half = c.u8();
      if (cone.half >= kConeHalfSteps) c.fail("subtree cone angle out of range");
    }
    op.subtree_cone = decode_cone(cone);
  }

  const QuantGrid& grid_;
  const CrmrInfo& info_;
  const std::string& context_;
  bool links_ = true;  // decode the Hypermesh links (decode_page)
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
  CoarserLink* links_block_ = nullptr;
  OpId* ids_ = nullptr;  // parents and children
  PreTriangle* pre_tris_ = nullptr;
  std::uint32_t* list_ = nullptr;
  std::size_t face_ = 0, list_used_ = 0, pre_used_ = 0, links_used_ = 0, ids_used_ = 0;
  std::size_t fresh_ = 0;             // page vertices listed so far
  std::vector<std::uint32_t> stamp_;  // per page vertex: the last op (its stamp) listing it
  std::uint32_t op_stamp_ = 0;
  std::vector<ByteReader> in_;  // the streams, by Stream
  std::vector<Head> heads_;
  std::vector<LocalTri> local_tris_;  // the current op's fragment, in its list's indices
  std::vector<std::pair<std::uint64_t, double>> res_of_;  // the page's ops: id, birth_res
  std::vector<double> child_res_;
  std::vector<std::uint64_t> pre_keys_;  // the current op's pre_edge_keys
  // cut(): the page's vertex ids, per page vertex 1 + its index in the cut (0: unused), and the
  // current op's list and children.
  std::vector<std::uint64_t> page_ids_;
  std::vector<std::uint32_t> used_, cut_list_;
  std::vector<OpId> cut_children_;
};

std::shared_ptr<const DecodedPage> decode_page(ByteView page, const QuantGrid& grid,
                                               const CrmrInfo& info, const std::string& context,
                                               bool links) {
  return PageDecoder(page, grid, info, context, links).run();
}

bool cut_page(ByteView page, const QuantGrid& grid, double below, PageCut& out,
              const std::string& context) {
  const CrmrInfo info;  // the cut derives no error
  return PageDecoder(page, grid, info, context).cut(below, out);
}

std::vector<std::pair<std::string, Bytes>> page_record_streams(ByteView page,
                                                               const std::string& context) {
  const QuantGrid grid;
  const CrmrInfo info;
  return PageDecoder(page, grid, info, context).streams();
}

PageValue split_page_value(ByteView value, std::string_view table, const std::string& key) {
  ByteReader r(value, "table '" + std::string(table) + "', key " + key);
  const std::uint64_t n = r.varint();
  if (n > r.remaining()) r.fail("R-tree leaf of " + std::to_string(n) + " bytes past the value");
  PageValue v;
  v.leaf = r.bytes(std::size_t(n));
  v.page = r.bytes(r.remaining());
  return v;
}

Bytes join_page_value(ByteView leaf, ByteView page) {
  Bytes out;
  out.reserve(page_value_overhead(leaf.size()) + page.size());
  ByteWriter w(out);
  w.varint(leaf.size());
  w.bytes(leaf);
  w.bytes(page);
  return out;
}

std::size_t page_value_overhead(std::size_t leaf_bytes) {
  std::size_t varint = 1;
  for (std::size_t n = leaf_bytes; n >= 0x80; n >>= 7) ++varint;
  return varint + leaf_bytes;
}

ByteView page_payload(ByteView value, std::string_view table, const std::string& key) {
  return storage::unseal(split_page_value(value, table, key).page, table, key);
}

DecodedPage::~DecodedPage() = default;

std::size_t DecodedPage::memory_bytes() const {
  return heap_block_bytes(block_bytes_) + heap_block_bytes(sizeof(DecodedPage) + 16);
}

std::size_t heap_block_bytes(std::size_t bytes) {
  return bytes == 0 ? 0 : std::max<std::size_t>(32, (bytes + 8 + 15) & ~std::size_t{15});
}

}  // namespace smr
