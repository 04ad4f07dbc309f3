// Out-of-core assembly of a decimation's CRMR; op_assembly.h describes the method.
//
// finish() runs in named steps: join_base (R^0 joins like any star), rank_ops (the op order,
// Brown 4.4.3.3), join_fixups (PreF's owners) and join_links (the Hypermesh links, Brown 4.5.1),
// both by external sorts, then emit_base and emit_ops (OpMaker makes the ops on the workers,
// InOrder hands them to the sink in id order).
#include "smr/builders/op_assembly.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <vector>

#include "base/error.h"
#include "smr/core/clock.h"
#include "smr/core/parallel.h"
#include "storage/external_sort.h"
#include "storage/record_file.h"
#include "storage/spill_array.h"

namespace smr {

namespace {

using storage::ExternalSorter;
using storage::RecordFile;
constexpr std::uint32_t kNone = OpAssembler::kNone;

std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
  return (std::uint64_t(a) << 32) | b;
}

// A removal's record in the spool: this head, its vertices, its star, what it made, then its
// star's vertices' positions (by vertex id; none: finish()'s `position` gives them).
struct SpoolHead {
  std::uint32_t vertices = 0, star = 0, made = 0, positions = 0;
};

// The order: falling err, the later removal first among equals.
struct OrderKey {
  double err = 0.0;
  std::uint32_t k = 0, bytes = 0;
  std::uint64_t offset = 0;
  bool operator<(const OrderKey& o) const { return err > o.err || (err == o.err && k > o.k); }
};
struct OrderEntry {
  std::uint64_t offset = 0;
  std::uint32_t k = 0, bytes = 0;
};

// Raw joins, written as removals come (removal indices), sorted by op id at finish.
struct RawFixup {  // triangle `tri` made by `creator` is triangle `local` of dest's star
  std::uint32_t creator = 0, tri = 0, dest = 0, local = 0;  // dest kNone: R^0
};
// A directed edge of a triangle (an answer: edge `edge` of triangle `local` of dest's star, made
// by `creator`) or a fragment boundary edge asking for the triangle across (edge `edge` of star
// triangle `local` of removal `dest`; its key is the reversed edge b->a). Sorted by key only, so
// each edge's triangles and questions meet in one group; their order in it does not matter (a
// question has one answer at most), so the sort keeps no arrival numbers. 20 bytes: there are
// about four for every triangle ever made.
struct EdgeItem {
  static constexpr std::uint32_t kMaxLocal = (std::uint32_t{1} << 29) - 1;
  std::uint32_t a = 0, b = 0;  // the key, a->b
  std::uint32_t dest = 0, creator = 0;
  std::uint32_t packed = 0;  // local << 3 | question << 2 | edge

  static EdgeItem make(std::uint32_t a, std::uint32_t b, std::uint32_t dest, std::uint32_t creator,
                       std::uint32_t local, std::uint32_t edge, bool question) {
    if (local > kMaxLocal) throw_internal("op assembly: a star or R^0 of more than 2^29 triangles");
    return {a, b, dest, creator, local << 3 | std::uint32_t(question) << 2 | edge};
  }
  std::uint64_t key() const { return edge_key(a, b); }
  std::uint32_t local() const { return packed >> 3; }
  std::uint32_t edge() const { return packed & 3; }
  bool question() const { return (packed & 4) != 0; }
  bool operator<(const EdgeItem& o) const { return a < o.a || (a == o.a && b < o.b); }
};
static_assert(sizeof(EdgeItem) == 20);
using EdgeSorter = ExternalSorter<EdgeItem, std::less<EdgeItem>, storage::Ties::kAny>;
// Fixups, links and the order are each unique under their order: their sorts keep no arrival
// numbers.
// The same, by op ids.
struct Fixup {
  std::uint32_t op = 0, tri = 0, owner = 0, local = 0;
  bool operator<(const Fixup& o) const { return op < o.op || (op == o.op && tri < o.tri); }
};
struct Link {  // the live triangle across a boundary edge: its owner op, index, edge
  std::uint32_t op = 0, tri = 0, edge = 0;
  std::uint32_t owner = 0, local = 0, coarser_edge = 0;
  bool operator<(const Link& o) const {
    if (op != o.op) return op < o.op;
    return tri < o.tri || (tri == o.tri && edge < o.edge);
  }
};

template <class T>
void put(std::vector<std::uint8_t>& out, const T* p, std::size_t n) {
  const auto* b = reinterpret_cast<const std::uint8_t*>(p);
  out.insert(out.end(), b, b + n * sizeof(T));
}

template <class T>
const std::uint8_t* get(const std::uint8_t* in, std::vector<T>& out, std::size_t n) {
  out.resize(n);
  if (n != 0) std::memcpy(out.data(), in, n * sizeof(T));
  return in + n * sizeof(T);
}

// Vertex v's index among an op's vertex ids `vs`: the `lead` introduced ones first, then the
// rest sorted.
std::uint32_t vertex_index(const std::vector<std::uint32_t>& vs, std::size_t lead,
                           std::uint32_t v) {
  for (std::size_t j = 0; j < lead; ++j) {
    if (vs[j] == v) return static_cast<std::uint32_t>(j);
  }
  const auto it = std::lower_bound(vs.begin() + static_cast<std::ptrdiff_t>(lead), vs.end(), v);
  if (it == vs.end() || *it != v) throw_internal("op assembly: a PreF corner is not in F");
  return static_cast<std::uint32_t>(it - vs.begin());
}

int index_of(const std::array<std::uint32_t, 3>& v, std::uint32_t x) {
  for (int k = 0; k < 3; ++k) {
    if (v[k] == x) return k;
  }
  return -1;
}

template <class T>
using UniqueSorter = ExternalSorter<T, std::less<T>, storage::Ties::kAny>;

// Reads a sorter's stream one op at a time.
template <class T>
class Cursor {
 public:
  explicit Cursor(UniqueSorter<T>& s) : s_(s) { more_ = s_.next(head_); }
  // Calls f(record) for each record whose op is `op`; records of earlier ops are an error.
  template <class F>
  void take(std::uint32_t op, F&& f) {
    while (more_ && head_.op <= op) {
      if (head_.op < op) throw_internal("op assembly: a record names an op already made");
      f(head_);
      more_ = s_.next(head_);
    }
  }
  bool done() const { return !more_; }

 private:
  UniqueSorter<T>& s_;
  T head_{};
  bool more_ = false;
};

// A default op that keeps `op`'s vectors' buffers, for the next op made in it.
void clear_keeping_buffers(Op& op) {
  Op fresh;
  auto keep = [](auto& from, auto& to) {
    from.clear();
    to.swap(from);
  };
  keep(op.vertices, fresh.vertices);
  keep(op.fragment, fresh.fragment);
  keep(op.pre, fresh.pre);
  keep(op.pre_tris, fresh.pre_tris);
  keep(op.coarser, fresh.coarser);
  keep(op.parents, fresh.parents);
  keep(op.children, fresh.children);
  op = std::move(fresh);
}

void report(const AssemblyOptions& options, double f) {
  if (options.progress) options.progress(std::clamp(f, 0.0, 1.0));
}

using StarTriangle = OpAssembler::StarTriangle;
using MadeTriangle = OpAssembler::MadeTriangle;
constexpr std::uint32_t kNever = kNone;  // killer of a finest triangle: never replaced

// The per-removal tables (storage::SpillArray: in memory, or in scratch files under a budget).
using ErrTable = storage::SpillArray<double>;        // err(k)
using OpTable = storage::SpillArray<std::uint32_t>;  // op id by removal, DAG depth by op

// ---- the joins (finish's first part) ----

// R^0's triangles join like any star (destroyer kNone = R^0): their fixups into `fixups`, their
// edges into `edges`.
void join_base(std::span<const StarTriangle> base, std::size_t m, RecordFile<RawFixup>& fixups,
               EdgeSorter& edges) {
  for (std::uint32_t j = 0; j < base.size(); ++j) {
    const StarTriangle& t = base[j];
    if (t.creator != kNone) {
      if (t.creator >= m) throw_internal("op assembly: a base triangle made by no removal");
      fixups.push({t.creator, t.id, kNone, j});
    }
    for (std::uint32_t i = 0; i < 3; ++i) {
      edges.add(EdgeItem::make(t.v[i], t.v[(i + 1) % 3], kNone, t.creator, j, i, false));
    }
  }
}

// Op ids: ranks in the order (R^0 is 0), into op_of (per removal); `ops` gets each op's record's
// place in the spool, in id order.
void rank_ops(UniqueSorter<OrderKey>& order, OpTable& op_of, RecordFile<OrderEntry>& ops) {
  OrderKey o;
  std::uint32_t i = 0;
  while (order.next(o)) {
    op_of.set(o.k, ++i);
    ops.push({o.offset, o.k, o.bytes});
  }
  ops.flush();
}

std::uint32_t op_id(const OpTable& op_of, std::uint32_t removal) {
  return removal == kNone ? 0 : op_of[removal];
}

// PreF's references: the raw fixups (by removal) by op ids, sorted by op.
void join_fixups(const RecordFile<RawFixup>& raw, const OpTable& op_of,
                 UniqueSorter<Fixup>& fixups) {
  raw.for_each([&](const RawFixup& f) {
    fixups.add({op_of[f.creator], f.tri, op_id(op_of, f.dest), f.local});
  });
  fixups.seal();
}

// The Hypermesh links, from the edges sorted by edge. Each edge's group: the question of op i is
// answered by the triangle across alive just before i (owner < i < killer; one at most, as
// triangles with one directed edge live one after another).
void join_links(EdgeSorter& edges, const OpTable& op_of, UniqueSorter<Link>& links) {
  std::vector<EdgeItem> group;
  EdgeItem e;
  bool more = edges.next(e);
  while (more) {
    group.clear();
    const std::uint64_t key = e.key();
    for (; more && e.key() == key; more = edges.next(e)) group.push_back(e);
    for (const EdgeItem& q : group) {
      if (!q.question()) continue;
      const std::uint32_t i = op_of[q.dest];
      for (const EdgeItem& r : group) {
        if (r.question()) continue;
        const std::uint32_t owner = op_id(op_of, r.dest);
        const std::uint32_t killer = r.creator == kNone ? kNever : op_of[r.creator];
        if (owner < i && i < killer) {
          links.add({i, q.local(), q.edge(), owner, r.local(), r.edge()});
          break;
        }
      }
    }
  }
  links.seal();
}

// ---- making the ops (finish's second part) ----

struct Raw {  // what op i is made from
  std::uint32_t k = 0;
  std::vector<std::uint32_t> verts;
  std::vector<StarTriangle> star;
  std::vector<MadeTriangle> made;
  std::vector<Vec3> positions;
  std::vector<Fixup> fixups;
  std::vector<Link> links;
};

// The records are read a chunk of ops at a time: ops follow falling error, the spool the
// build's order, so one by one they would be a read each; a chunk's are read in runs of nearby
// records (RecordFile::read_pieces), its bytes held within a share of the budget.
class RecordChunks {
 public:
  RecordChunks(const RecordFile<std::uint8_t>& spool, const RecordFile<OrderEntry>& ops,
               std::uint64_t m, std::uint64_t chunk_bytes)
      : spool_(spool), ops_(ops), m_(m), chunk_bytes_(chunk_bytes) {}

  // Op i's record into r.k, r.verts, r.star and r.made; ops are read in id order from 1.
  void read(std::uint32_t i, Raw& r) {
    if (i - 1 == at_ + chunk_.size()) load(i - 1);
    r.k = chunk_[i - 1 - at_].k;
    SpoolHead head;
    const std::uint8_t* p = bytes_.data() + chunk_at_[i - 1 - at_];
    std::memcpy(&head, p, sizeof head);
    p += sizeof head;
    p = get(p, r.verts, head.vertices);
    p = get(p, r.star, head.star);
    p = get(p, r.made, head.made);
    get(p, r.positions, head.positions);
  }

 private:
  // The chunk of ops from `at` (a 0-based index into the order).
  void load(std::uint64_t at) {
    at_ = at;
    chunk_.resize(
        static_cast<std::size_t>(std::min<std::uint64_t>(std::uint64_t{1} << 16, m_ - at_)));
    ops_.read(at_, chunk_);
    std::size_t n = 0, total = 0;  // the entries whose records fit the chunk's bytes
    for (; n < chunk_.size() && (n == 0 || total + chunk_[n].bytes <= chunk_bytes_); ++n)
      total += chunk_[n].bytes;
    chunk_.resize(n);
    pieces_.resize(n);
    chunk_at_.resize(n);
    for (std::size_t j = 0, to = 0; j < n; to += chunk_[j].bytes, ++j) {
      pieces_[j] = {chunk_[j].offset, chunk_[j].bytes, to};
      chunk_at_[j] = to;
    }
    bytes_.resize(total);
    spool_.read_pieces(pieces_, bytes_.data());
  }

  const RecordFile<std::uint8_t>& spool_;
  const RecordFile<OrderEntry>& ops_;
  const std::uint64_t m_, chunk_bytes_;
  std::vector<OrderEntry> chunk_;
  std::vector<std::size_t> chunk_at_;  // each chunk entry's record in `bytes_`
  std::vector<std::uint8_t> bytes_;
  std::vector<RecordFile<std::uint8_t>::Piece> pieces_;
  std::uint64_t at_ = 0;
};

// Sorted parents and children.
void sort_ids(Op& op) {
  for (std::vector<OpId>* ids : {&op.parents, &op.children}) {
    std::sort(ids->begin(), ids->end());
    ids->erase(std::unique(ids->begin(), ids->end()), ids->end());
  }
}

// Sorted parents and children, bounds: an op as a sink that does not encode takes it.
void finish_op(Op& op) {
  sort_ids(op);
  compute_op_bounds(op);
}

// Makes the ops from their records. Runs on the workers: everything it reads is fixed by then.
class OpMaker {
 public:
  OpMaker(const CrmrInfo& info, const ErrTable& err, const OpTable& op_of,
          const std::function<Vec3(std::uint32_t)>& position)
      : info_(info), err_(err), op_of_(op_of), position_(position) {}

  // Fills the op's vertices (`first` introduced, then the rest of F's by id; R^0 introduces
  // them all) and fragment. `vs` is the caller's scratch: the op's vertex ids, the `first.size()`
  // introduced ones, then the rest sorted. `positions`: the vertices' coordinates by id, or
  // empty (from `position`).
  void fill(Op& op, std::span<const std::uint32_t> first, std::span<const StarTriangle> frag,
            std::vector<std::uint32_t>& vs, std::span<const Vec3> positions = {}) const {
    const bool base_op = op.id == kBaseOp;
    vs.clear();
    for (const StarTriangle& t : frag) vs.insert(vs.end(), t.v.begin(), t.v.end());
    std::sort(vs.begin(), vs.end());
    vs.erase(std::unique(vs.begin(), vs.end()), vs.end());
    if (!positions.empty() && positions.size() != vs.size())
      throw_internal("op assembly: a record's positions do not match its star's vertices");
    thread_local std::vector<std::uint32_t> sorted;
    if (!positions.empty()) sorted = vs;
    auto at = [&](std::uint32_t v) {
      if (positions.empty()) return position_(v);
      return positions[std::lower_bound(sorted.begin(), sorted.end(), v) - sorted.begin()];
    };
    if (!base_op) {
      for (std::uint32_t v : first) {
        const auto it = std::lower_bound(vs.begin(), vs.end(), v);
        if (it == vs.end() || *it != v)
          throw_internal("op assembly: a removed vertex is on none of its star's triangles");
        vs.erase(it);
      }
      vs.insert(vs.begin(), first.begin(), first.end());
    }
    op.new_vertex_count = static_cast<std::uint32_t>(base_op ? vs.size() : first.size());
    op.vertices.reserve(vs.size());
    for (std::uint32_t v : vs) op.vertices.push_back({VertexId(v), at(v)});
    op.fragment.resize(frag.size());
    op.children.reserve(frag.size());
    for (std::size_t i = 0; i < frag.size(); ++i) {
      FragmentTriangle& ft = op.fragment[i];
      for (int k = 0; k < 3; ++k) ft.v[k] = vertex_index(vs, first.size(), frag[i].v[k]);
      if (frag[i].is_void) ft.flags |= FragmentTriangle::kVoid;
      if (frag[i].creator != kNone) {
        ft.killer = OpId(op_of_[frag[i].creator]);
        ft.death_res = birth(frag[i].creator);
        op.children.push_back(ft.killer);
      }
    }
  }

  // Op `id` (not R^0) from its record: F, the error, PreF and its parents, the links. `vs` and
  // `owner` are the caller's scratch. Returns the links made.
  std::uint64_t make(std::uint32_t id, const Raw& r, Op& op, std::vector<std::uint32_t>& vs,
                     std::vector<std::pair<std::uint32_t, std::uint32_t>>& owner) const {
    op.id = OpId(id);
    fill(op, r.verts, r.star, vs, r.positions);
    op.error = err_[r.k];
    op.birth_res = birth(r.k);
    owners(r, owner);
    op.pre.reserve(r.made.size());
    op.pre_tris.reserve(r.made.size());
    op.parents.reserve(r.made.size());
    op.coarser.reserve(r.links.size());
    for (std::size_t j = 0; j < r.made.size(); ++j) {
      if (owner[j].first == kNone)
        throw_internal("op assembly: a made triangle is in no later star nor in R^0");
      op.pre.push_back({OpId(owner[j].first), owner[j].second});
      op.parents.push_back(OpId(owner[j].first));
      PreTriangle pt;
      for (int k = 0; k < 3; ++k) pt.v[k] = vertex_index(vs, r.verts.size(), r.made[j].v[k]);
      if (r.made[j].is_void) pt.flags |= FragmentTriangle::kVoid;
      op.pre_tris.push_back(pt);
    }
    for (const Link& l : r.links) op.coarser.push_back(coarser(r, l, owner));
    return r.links.size();
  }

 private:
  double birth(std::uint32_t removal) const { return resolution_of(info_, err_[removal]); }

  // PreF's owners: per made triangle, the op and index of the fragment that holds it.
  static void owners(const Raw& r, std::vector<std::pair<std::uint32_t, std::uint32_t>>& owner) {
    owner.assign(r.made.size(), {kNone, 0});
    for (const Fixup& f : r.fixups) {
      bool found = false;
      for (std::size_t j = 0; j < r.made.size(); ++j) {
        if (r.made[j].id == f.tri) owner[j] = {f.owner, f.local}, found = true;
      }
      if (!found)
        throw_internal("op assembly: a star triangle names a creator that did not make it");
    }
  }

  // A link: the newer of PreF's triangle with a->b and the live one across.
  static CoarserLink coarser(const Raw& r, const Link& l,
                             const std::vector<std::pair<std::uint32_t, std::uint32_t>>& owner) {
    const std::array<std::uint32_t, 3>& v = r.star[l.tri].v;
    const std::uint32_t a = v[l.edge], b = v[(l.edge + 1) % 3];
    std::size_t inside = r.made.size();
    int inside_edge = -1;
    for (std::size_t j = 0; j < r.made.size(); ++j) {
      const int x = index_of(r.made[j].v, a);
      if (x >= 0 && r.made[j].v[(x + 1) % 3] == b) {
        inside = j;
        inside_edge = x;
      }
    }
    if (inside == r.made.size())
      throw_internal("op assembly: a fragment boundary edge has no PreF triangle");
    EdgeRef target{TriRef{OpId(owner[inside].first), owner[inside].second},
                   static_cast<std::uint8_t>(inside_edge)};
    if (l.owner > owner[inside].first) {
      target = EdgeRef{TriRef{OpId(l.owner), l.local}, static_cast<std::uint8_t>(l.coarser_edge)};
    }
    return {l.tri, static_cast<std::uint8_t>(l.edge), target};
  }

  const CrmrInfo& info_;
  const ErrTable& err_;
  const OpTable& op_of_;
  const std::function<Vec3(std::uint32_t)>& position_;
};

// Hands the ops to the sink in id order (the calling thread), keeping each op's DAG depth.
class InOrder {
 public:
  InOrder(OpSink& sink, std::uint64_t ops, OpTable depth, std::uint64_t& dag_height)
      : sink_(sink), depth_(std::move(depth)), dag_height_(dag_height) {
    depth_.resize(ops);
  }
  void add(Op&& op) {
    deepen(op.id.value, op.parents);
    sink_.add(std::move(op));
  }
  void add_encoded(std::uint64_t id, std::span<const OpId> parents,
                   std::span<const std::uint8_t> bytes) {
    deepen(id, parents);
    sink_.add_encoded(bytes);
  }

 private:
  void deepen(std::uint64_t id, std::span<const OpId> parents) {
    std::uint32_t d = 0;
    for (OpId p : parents) d = std::max(d, depth_[p.value] + 1);
    depth_.set(id, d);
    dag_height_ = std::max<std::uint64_t>(dag_height_, d);
  }
  OpSink& sink_;
  OpTable depth_;
  std::uint64_t& dag_height_;
};

// R^0, op 0: the triangles `base`, of error err0.
void emit_base(const OpMaker& maker, OpSink& sink, InOrder& out, std::span<const StarTriangle> base,
               double err0) {
  Op op;
  op.id = OpId(0);
  std::vector<std::uint32_t> vs;
  maker.fill(op, {}, base, vs);
  op.error = err0;
  if (sink.encodes()) {
    sort_ids(op);
    std::vector<std::uint8_t> bytes;
    sink.encode(op, bytes);
    out.add_encoded(0, op.parents, bytes);
  } else {
    finish_op(op);
    out.add(std::move(op));
  }
}

// A batch of ops as the pipeline makes them.
struct Batch {
  std::uint32_t first = 0;  // op id of raw[0]
  std::vector<Raw> raw;
  std::vector<Op> ops;  // or, encoding, each op's bytes and parents:
  std::vector<std::uint8_t> encoded;
  std::vector<std::size_t> encoded_end;
  std::vector<OpId> parents;
  std::vector<std::size_t> parents_end;
  std::uint64_t links = 0;
};

// What the ops are made from, besides their records: the fixups and links sorted by op.
struct Joined {
  const RecordFile<std::uint8_t>& spool;
  const RecordFile<OrderEntry>& ops;
  UniqueSorter<Fixup>& fixups;
  UniqueSorter<Link>& links;
};

// Ops 1..m in batches through a pipeline: the calling thread reads each batch's records and
// its share of the fixups and links (sequential streams), the workers make the ops, and the
// calling thread hands them to the sink in id order, so the output does not depend on the
// thread count. A sink that encodes (OpSink::encodes) gets each op encoded on the worker that
// made it: the sink's own work on the op runs on the workers, the op's buffers are reused there
// instead of being freed by the sink's thread, and what goes through in id order is a copy of
// bytes. Returns the links made.
std::uint64_t emit_ops(const AssemblyOptions& options, std::uint64_t m, std::uint64_t chunk_bytes,
                       const Joined& joined, const OpMaker& maker, OpSink& sink, InOrder& out) {
  constexpr std::uint32_t kBatchOps = 256;
  const bool encoding = sink.encodes();
  const std::uint64_t batches = (m + kBatchOps - 1) / kBatchOps;
  Cursor<Fixup> fix(joined.fixups);
  Cursor<Link> link(joined.links);
  RecordChunks records(joined.spool, joined.ops, m, chunk_bytes);
  std::uint64_t links = 0;
  // Merged batches, whose buffers the next batches reuse: a batch's encoded bytes (~100 KiB)
  // were fresh mapped memory, faulted in and unmapped every batch (with the sink's work moved
  // to the workers, the reuse took this stage from 1.8 to 1.15 s on the 8193² terrain), and the
  // records' buffers are made and freed on this thread, not made here and freed on a worker.
  std::vector<std::unique_ptr<Batch>> spare;
  auto make = [&](std::size_t b) {
    std::unique_ptr<Batch> batch;
    if (spare.empty()) {
      batch = std::make_unique<Batch>();
    } else {
      batch = std::move(spare.back());
      spare.pop_back();
      batch->ops.clear();
      batch->encoded.clear();
      batch->encoded_end.clear();
      batch->parents.clear();
      batch->parents_end.clear();
      batch->links = 0;
    }
    batch->first = static_cast<std::uint32_t>(b * kBatchOps + 1);
    const std::uint32_t last =
        static_cast<std::uint32_t>(std::min<std::uint64_t>(m, (b + 1) * kBatchOps));
    batch->raw.resize(last - batch->first + 1);
    for (std::uint32_t i = batch->first; i <= last; ++i) {
      Raw& r = batch->raw[i - batch->first];
      records.read(i, r);
      r.fixups.clear();
      r.links.clear();
      fix.take(i, [&](const Fixup& f) { r.fixups.push_back(f); });
      link.take(i, [&](const Link& l) { r.links.push_back(l); });
    }
    return batch;
  };
  auto work = [&](Batch& batch) {
    std::vector<std::uint32_t> vs;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> owner;  // per made triangle: op, index
    // Encoding, one op at a time, its buffers reused from op to op.
    thread_local Op reused;
    if (!encoding) batch.ops.resize(batch.raw.size());
    for (std::size_t n = 0; n < batch.raw.size(); ++n) {
      Op& op = encoding ? reused : batch.ops[n];
      if (encoding) clear_keeping_buffers(op);
      batch.links +=
          maker.make(batch.first + static_cast<std::uint32_t>(n), batch.raw[n], op, vs, owner);
      if (!encoding) {
        finish_op(op);
        continue;
      }
      sort_ids(op);
      sink.encode(op, batch.encoded);
      batch.encoded_end.push_back(batch.encoded.size());
      batch.parents.insert(batch.parents.end(), op.parents.begin(), op.parents.end());
      batch.parents_end.push_back(batch.parents.size());
    }
  };
  auto merge = [&](Batch& batch, std::size_t b) {
    for (Op& op : batch.ops) out.add(std::move(op));
    const std::span<const std::uint8_t> encoded(batch.encoded);
    const std::span<const OpId> parents(batch.parents);
    for (std::size_t n = 0; n < batch.encoded_end.size(); ++n) {
      const std::size_t e0 = n == 0 ? 0 : batch.encoded_end[n - 1];
      const std::size_t p0 = n == 0 ? 0 : batch.parents_end[n - 1];
      out.add_encoded(batch.first + static_cast<std::uint32_t>(n),
                      parents.subspan(p0, batch.parents_end[n] - p0),
                      encoded.subspan(e0, batch.encoded_end[n] - e0));
    }
    links += batch.links;
    spare.push_back(std::make_unique<Batch>(std::move(batch)));
    const std::uint64_t done = std::min<std::uint64_t>(m, (b + 1) * kBatchOps);
    if ((b & 0xff) == 0) report(options, 0.35 + 0.65 * double(done) / double(m));
  };
  const unsigned threads = thread_count(options.threads);
  ordered_pipeline(static_cast<std::size_t>(batches), threads, 2 * std::size_t(threads), make, work,
                   merge);
  if (!fix.done() || !link.done()) throw_internal("op assembly: records name no op");
  return links;
}

}  // namespace

struct OpAssembler::State {
  explicit State(AssemblyOptions o)
      : options(std::move(o)),
        dir(storage::scratch_dir(options.tmp_dir)),
        spool(dir),
        fixups(dir),
        // Both are filled on the builder's thread, whose time is the one that counts: full
        // buffers are sorted and written on threads of their own.
        edges(std::make_unique<EdgeSorter>(dir, budget(4), std::less<EdgeItem>{},
                                           storage::Spill::kBackground)),
        order(std::make_unique<UniqueSorter<OrderKey>>(dir, budget(4), std::less<OrderKey>{},
                                                       storage::Spill::kBackground)),
        err(table<double>()) {}

  // A per-removal (or per-op) table, spilled to a scratch file under options.table_bytes.
  template <class T>
  storage::SpillArray<T> table() const {
    return storage::SpillArray<T>(dir, options.table_bytes / 3);
  }

  AssemblyOptions options;
  std::string dir;
  RecordFile<std::uint8_t> spool;
  RecordFile<RawFixup> fixups;
  std::unique_ptr<EdgeSorter> edges;              // filled as removals come
  std::unique_ptr<UniqueSorter<OrderKey>> order;  // filled as removals come
  ErrTable err;                                   // per removal (err(k))
  std::vector<std::uint8_t> record;
  AssemblyStats stats;
  bool finished = false;

  std::uint64_t budget(int parts) const {
    return std::max<std::uint64_t>(options.sort_bytes / parts, 16 << 10);
  }
};

OpAssembler::OpAssembler(AssemblyOptions options)
    : s_(std::make_unique<State>(std::move(options))) {}
OpAssembler::~OpAssembler() = default;

std::uint64_t OpAssembler::removals() const {
  return s_->err.size();
}
double OpAssembler::error(std::uint32_t k) const {
  if (k >= s_->err.size()) throw_internal("op assembly: error() of a removal not added");
  return s_->err[k];
}
const AssemblyStats& OpAssembler::stats() const {
  return s_->stats;
}

std::uint32_t OpAssembler::add_removal(std::span<const std::uint32_t> vertices,
                                       std::span<const StarTriangle> star,
                                       std::span<const MadeTriangle> made, double error) {
  return add_removal(vertices, star, made, error, {});
}

std::uint32_t OpAssembler::add_removal(std::span<const std::uint32_t> vertices,
                                       std::span<const StarTriangle> star,
                                       std::span<const MadeTriangle> made, double error,
                                       std::span<const Vec3> star_positions) {
  State& s = *s_;
  if (s.finished) throw_internal("op assembly: add_removal() after finish()");
  if (s.err.size() >= kNone - 1) throw_internal("op assembly: more than 2^32 - 2 removals");
  if (vertices.empty() || made.empty()) {
    // An op with no PreF would have no parent to reach it from R^0 (spawned components need
    // an op to hold them, which this assembler does not make).
    throw_internal("op assembly: a removal must remove a vertex and make triangles");
  }
  const auto k = static_cast<std::uint32_t>(s.err.size());
  double e = error;
  for (std::uint32_t j = 0; j < star.size(); ++j) {
    const StarTriangle& t = star[j];
    if (t.creator != kNone) {
      if (t.creator >= k) throw_internal("op assembly: a star triangle made by a later removal");
      e = std::max(e, s.err[t.creator]);
      s.fixups.push({t.creator, t.id, k, j});
    }
    for (std::uint32_t i = 0; i < 3; ++i) {
      s.edges->add(EdgeItem::make(t.v[i], t.v[(i + 1) % 3], k, t.creator, j, i, false));
    }
  }
  // F's boundary edges: a star triangle's edges whose reverse no star triangle has.
  for (std::uint32_t j = 0; j < star.size(); ++j) {
    for (std::uint32_t i = 0; i < 3; ++i) {
      const std::uint32_t a = star[j].v[i], b = star[j].v[(i + 1) % 3];
      bool inner = false;
      for (const StarTriangle& o : star) {
        const int x = index_of(o.v, b);
        inner = inner || (x >= 0 && o.v[(x + 1) % 3] == a);
      }
      if (!inner) s.edges->add(EdgeItem::make(b, a, k, kNone, j, i, true));
    }
  }
  s.err.push_back(e);
  std::vector<std::uint8_t>& r = s.record;
  r.clear();
  const SpoolHead head{
      static_cast<std::uint32_t>(vertices.size()), static_cast<std::uint32_t>(star.size()),
      static_cast<std::uint32_t>(made.size()), static_cast<std::uint32_t>(star_positions.size())};
  put(r, &head, 1);
  put(r, vertices.data(), vertices.size());
  put(r, star.data(), star.size());
  put(r, made.data(), made.size());
  put(r, star_positions.data(), star_positions.size());
  s.order->add({e, k, static_cast<std::uint32_t>(r.size()), s.spool.count()});
  s.spool.append(r.data(), r.size());
  ++s.stats.removals;
  s.stats.triangles_destroyed += star.size();
  s.stats.triangles_made += made.size();
  return k;
}

void OpAssembler::finish(CrmrInfo info, std::span<const StarTriangle> base,
                         const std::function<Vec3(std::uint32_t)>& position, OpSink& sink) {
  State& s = *s_;
  if (s.finished) throw_internal("op assembly: finish() called twice");
  const auto t0 = Clock::now();
  s.finished = true;
  const std::size_t m = s.err.size();

  join_base(base, m, s.fixups, *s.edges);
  s.spool.flush();
  s.fixups.flush();
  OpTable op_of = s.table<std::uint32_t>();
  op_of.resize(m);
  RecordFile<OrderEntry> ops(s.dir);
  rank_ops(*s.order, op_of, ops);
  s.stats.scratch_bytes += s.order->spilled_bytes();
  s.order.reset();
  report(s.options, 0.05);

  // The two joins are independent (both only read op_of): the fixups' on one thread, the
  // links' on another, each sorting its output's full buffers on a third.
  UniqueSorter<Fixup> fixups(s.dir, s.budget(4), std::less<Fixup>{}, storage::Spill::kBackground);
  UniqueSorter<Link> links(s.dir, s.budget(4), std::less<Link>{}, storage::Spill::kBackground);
  parallel_for(2, std::min(2u, thread_count(s.options.threads)), [&](std::size_t job) {
    if (job == 0) {
      join_links(*s.edges, op_of, links);
    } else {
      join_fixups(s.fixups, op_of, fixups);
    }
  });
  s.stats.scratch_bytes += s.edges->spilled_bytes();
  s.edges.reset();
  s.stats.scratch_bytes += s.spool.bytes() + s.fixups.bytes() + ops.bytes();
  report(s.options, 0.35);

  double err0 = info.err0;
  for (std::size_t k = 0; k < m; ++k) err0 = std::max(err0, s.err[k]);
  info.err0 = err0;
  info.err_final = std::min(info.err_final, err0);
  s.stats.seconds_join = seconds_since(t0);
  const auto t1 = Clock::now();
  sink.begin(info, m + 1);

  const OpMaker maker(info, s.err, op_of, position);
  InOrder out(sink, m + 1, s.table<std::uint32_t>(), s.stats.dag_height);
  emit_base(maker, sink, out, base, err0);
  const std::uint64_t chunk_bytes = std::max<std::uint64_t>(s.budget(8), 1 << 16);
  s.stats.links +=
      emit_ops(s.options, m, chunk_bytes, Joined{s.spool, ops, fixups, links}, maker, sink, out);
  s.stats.scratch_bytes += fixups.spilled_bytes() + links.spilled_bytes();
  s.stats.seconds_emit = seconds_since(t1);
  report(s.options, 1.0);
}

}  // namespace smr
