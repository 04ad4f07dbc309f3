// DatabaseStreamWriter (writer.h): ops streamed from a builder in id order are snapped and
// spooled to scratch files on a thread of the writer's own; finish() derives ROIs and subtree
// cones by a backward sweep over the records (time-forward processing through an external queue,
// Chiang et al. 1995) and ends in write_tables, as write_database does.
#include <algorithm>
#include <array>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <exception>
#include <mutex>
#include <span>
#include <thread>

#include "base/error.h"
#include "smr/db/index_box.h"
#include "smr/db/page.h"
#include "smr/db/write_tables.h"
#include "smr/db/writer.h"
#include "storage/record_file.h"
#include "storage/temp_file.h"

namespace smr {

using storage::ByteReader;
using storage::Bytes;
using storage::ByteView;
using storage::ByteWriter;
using storage::RecordFile;

namespace {

// An op as add() leaves it for finish(): its own box and cone, and where its parents are.
struct OpRecord {
  OpEntry entry;                 // roi == box and cone == the op's own until the backward sweep
  std::uint64_t parents_at = 0;  // first of its parents' ids in the parents file
  std::uint32_t parent_count = 0;
};

// The spool's copy of an op, for this process only (no version, no byte order): positions as
// their grid coordinates (the op is snapped before it is spooled), ids and indices as varints of
// their differences from the op's id or the previous one, resolutions, errors and bounds as
// doubles; no vertex table shared between ops, no geometry codec, no compression (on the 8193²
// terrain: 108 MB for 372 576 ops, against 377 MB for a raw copy of the fields). roi and
// subtree_cone are not kept: finish() derives them.
void spool_op(const Op& op, const QuantGrid& grid, Bytes& out) {
  ByteWriter w(out);  // appends
  const std::uint64_t id = op.id.value;
  w.varint(id);
  w.f64(op.birth_res);
  w.f64(op.error);
  w.varint(op.new_vertex_count);
  for (const Vec3& p : {op.box.lo, op.box.hi, op.sphere.center, op.cone.axis}) {
    for (int k = 0; k < 3; ++k) w.f64(p[k]);
  }
  w.f64(op.sphere.radius);
  w.f64(op.cone.half_angle);
  w.varint(op.vertices.size());
  std::uint64_t prev_id = id;
  std::array<std::int32_t, 3> prev_q{};
  for (const Vertex& v : op.vertices) {
    w.svarint(std::int64_t(v.id.value - prev_id));
    prev_id = v.id.value;
    const std::array<std::int32_t, 3> q = grid.quantize(v.p);
    if (grid.dequantize(q) != v.p)
      throw_internal("database writer: op " + std::to_string(id) + " has vertex " +
                     std::to_string(v.id.value) + " off the quantization grid");
    for (int k = 0; k < 3; ++k) w.svarint(std::int64_t(q[k]) - prev_q[k]);
    prev_q = q;
  }
  w.varint(op.fragment.size());
  for (const FragmentTriangle& t : op.fragment) {
    for (std::uint32_t v : t.v) w.varint(v);
    w.svarint(t.killer.valid() ? std::int64_t(t.killer.value - id) : 0);
    w.f64(t.death_res);
    w.u8(t.flags);
  }
  w.varint(op.pre.size());
  for (const TriRef& r : op.pre) {
    w.svarint(std::int64_t(id - r.op.value));
    w.varint(r.index);
  }
  w.varint(op.pre_tris.size());
  for (const PreTriangle& t : op.pre_tris) {
    for (std::uint32_t v : t.v) w.varint(v);
    w.u8(t.flags);
  }
  w.varint(op.coarser.size());
  for (const CoarserLink& c : op.coarser) write_link(w, c, id);
  w.varint(op.parents.size());
  for (OpId p : op.parents) w.svarint(std::int64_t(id - p.value));
  w.varint(op.children.size());
  for (OpId c : op.children) w.svarint(std::int64_t(c.value - id));
}

Op unspool_op(ByteView in, std::uint64_t id, const QuantGrid& grid) {
  ByteReader r(in, "scratch op " + std::to_string(id));
  Op op;
  op.id = OpId(r.varint());
  if (op.id.value != id)
    throw_internal("database writer: the scratch file lost op " + std::to_string(id));
  op.birth_res = r.f64();
  op.error = r.f64();
  op.new_vertex_count = static_cast<std::uint32_t>(r.varint());
  for (Vec3* p : {&op.box.lo, &op.box.hi, &op.sphere.center, &op.cone.axis}) {
    for (int k = 0; k < 3; ++k) (*p)[k] = r.f64();
  }
  op.sphere.radius = r.f64();
  op.cone.half_angle = r.f64();
  // Counts are checked against the bytes left (each element takes at least one) before sizing.
  auto count = [&](std::size_t least) {
    const std::uint64_t n = r.varint();
    if (n > r.remaining() / least)
      throw_internal("database writer: the scratch copy of op " + std::to_string(id) +
                     " is truncated");
    return static_cast<std::size_t>(n);
  };
  op.vertices.resize(count(4));
  std::uint64_t prev_id = id;
  std::array<std::int32_t, 3> q{};
  for (Vertex& v : op.vertices) {
    prev_id += static_cast<std::uint64_t>(r.svarint());
    v.id = VertexId(prev_id);
    for (int k = 0; k < 3; ++k) q[k] = static_cast<std::int32_t>(q[k] + r.svarint());
    v.p = grid.dequantize(q);
  }
  op.fragment.resize(count(13));  // 3 corners, killer, f64 death_res, flags
  for (FragmentTriangle& t : op.fragment) {
    for (std::uint32_t& v : t.v) v = static_cast<std::uint32_t>(r.varint());
    const std::int64_t killer = r.svarint();
    if (killer != 0) t.killer = OpId(id + static_cast<std::uint64_t>(killer));
    t.death_res = r.f64();
    t.flags = r.u8();
  }
  op.pre.resize(count(2));
  for (TriRef& t : op.pre) {
    t.op = OpId(id - static_cast<std::uint64_t>(r.svarint()));
    t.index = static_cast<std::uint32_t>(r.varint());
  }
  op.pre_tris.resize(count(4));
  for (PreTriangle& t : op.pre_tris) {
    for (std::uint32_t& v : t.v) v = static_cast<std::uint32_t>(r.varint());
    t.flags = r.u8();
  }
  op.coarser.resize(count(5));
  for (CoarserLink& c : op.coarser) c = read_link(r, id);
  op.parents.resize(count(1));
  for (OpId& p : op.parents) p = OpId(id - static_cast<std::uint64_t>(r.svarint()));
  op.children.resize(count(1));
  for (OpId& c : op.children) c = OpId(id + static_cast<std::uint64_t>(r.svarint()));
  if (r.remaining() != 0)
    throw_internal("database writer: the scratch copy of op " + std::to_string(id) +
                   " has trailing bytes");
  return op;
}

// An op made ready for the spool (DatabaseStreamWriter::encode): this head, its parents' ids,
// then its spool_op bytes. Only this process reads it, right away.
struct EncodedHead {
  OpEntry entry;  // spool_at and spool_size not set yet
  Box3 vertices;  // of its (snapped) vertices
  double moved = 0.0;
  std::uint32_t parent_count = 0;
  std::uint32_t triangles = 0;
};

// Snaps the op and encodes it (quantize()'s snap and bounds). The bounds are recomputed unless
// `bounds_set` says the builder computed them and nothing moved.
void encode_op(Op& op, const CrmrInfo& header, const QuantGrid& grid, bool bounds_set, Bytes& out) {
  const ModelKind kind = header.kind;
  EncodedHead h;
  h.moved = snap_vertices(op, grid, header);
  round_for_storage(op);  // before the index entry: its resolutions are the stored ones
  for (const Vertex& v : op.vertices) h.vertices.add(v.p);
  if (h.moved != 0.0 || !bounds_set) compute_op_bounds(op);
  h.entry = entry_of(op, kind, op.box, op.cone);
  h.parent_count = static_cast<std::uint32_t>(op.parents.size());
  h.triangles = static_cast<std::uint32_t>(op.fragment.size());
  const std::size_t at = out.size();
  out.resize(at + sizeof h + op.parents.size() * sizeof(std::uint64_t));
  std::memcpy(out.data() + at, &h, sizeof h);
  for (std::size_t i = 0; i < op.parents.size(); ++i) {
    const std::uint64_t p = op.parents[i].value;
    std::memcpy(out.data() + at + sizeof h + i * sizeof p, &p, sizeof p);
  }
  spool_op(op, grid, out);  // without ROI and subtree cone: finish() derives them
}

// A child's ROI, subtree cone and height, on its way to a parent (the backward sweep).
struct Message {
  std::uint64_t to = 0, from = 0;
  index::Box roi;
  NormalCone cone;
  std::uint64_t height = 0;
  bool operator<(const Message& o) const { return to < o.to; }
};

}  // namespace

struct DatabaseStreamWriter::State {
  State(const std::string& path, const WriteOptions& o, const std::string& tmp)
      : options(o),
        writer(open_writer(path, o)),
        tmp_dir(storage::scratch_dir(tmp)),
        spool(tmp_dir),
        records(tmp_dir),
        parents(tmp_dir) {}
  WriteOptions options;
  storage::DatabaseWriter writer;
  std::string tmp_dir;
  RecordFile<std::uint8_t> spool;     // the ops (spool_op), in id order
  Bytes spooled;                      // the spooler's buffer for one op
  RecordFile<OpRecord> records;       // one per op, in id order
  RecordFile<std::uint64_t> parents;  // every op's parents, in id order
  std::unique_ptr<index::EntryOrder> order;
  CrmrInfo header;
  QuantGrid grid;
  double shift = 0.0;
  std::uint64_t triangles = 0;
  bool begun = false, finished = false;
  std::uint64_t next_id = 0;        // add()'s next op (checked as it comes, on its thread)
  std::uint64_t next_appended = 0;  // append()'s, whichever way the op came
  enum class Input { kNone, kOps, kEncoded } input = Input::kNone;

  // Spooling runs on its own thread, in id order, while the builder makes the next ops. Ops are
  // handed over in batches (one lock and one wake-up per batch, not per op) and the scratch file
  // is written in large pieces.
  static constexpr std::size_t kBatch = 256, kBatches = 8;
  struct Handover {
    std::mutex mu;
    std::condition_variable cv;
    std::vector<Op> filling;  // the builder's side, not shared
    std::deque<std::vector<Op>> queue;
    bool closing = false;
    std::exception_ptr error;
    std::thread spooler;
  } hand;

  void spool_one(Op& op) {
    spooled.clear();
    encode_op(op, header, grid, true, spooled);
    append(spooled);
  }
  // The ordered half: an encoded op (encode_op) into the spool, its record and its parents.
  void append(ByteView encoded) {
    EncodedHead h;
    if (encoded.size() < sizeof h) throw_internal("database writer: a truncated encoded op");
    std::memcpy(&h, encoded.data(), sizeof h);
    const std::size_t head = sizeof h + std::size_t(h.parent_count) * sizeof(std::uint64_t);
    if (encoded.size() < head) throw_internal("database writer: a truncated encoded op");
    if (h.entry.id != next_appended)
      throw_internal("database writer: op " + std::to_string(h.entry.id) +
                     " arrived out of id order");
    ++next_appended;
    shift = std::max(shift, h.moved);
    header.bounds.add(h.vertices);
    OpRecord r;
    r.entry = h.entry;
    r.entry.spool_at = spool.count();
    r.entry.spool_size = static_cast<std::uint32_t>(encoded.size() - head);
    r.parents_at = parents.count();
    r.parent_count = h.parent_count;
    for (std::uint32_t i = 0; i < h.parent_count; ++i) {
      std::uint64_t p = 0;
      std::memcpy(&p, encoded.data() + sizeof h + i * sizeof p, sizeof p);
      parents.push(p);
    }
    records.push(r);
    order->observe(r.entry.index_entry());
    triangles += h.triangles;
    spool.append(encoded.data() + head, encoded.size() - head);
  }
  void run() {
    for (;;) {
      std::vector<Op> batch;
      {
        std::unique_lock lock(hand.mu);
        hand.cv.wait(lock, [&] { return hand.closing || !hand.queue.empty(); });
        if (hand.queue.empty()) return;
        batch = std::move(hand.queue.front());
        hand.queue.pop_front();
      }
      hand.cv.notify_all();
      try {
        if (!hand.error) {
          for (Op& op : batch) spool_one(op);
        }
      } catch (...) {
        std::lock_guard lock(hand.mu);
        hand.error = std::current_exception();
      }
    }
  }
  // Hands the builder's current batch to the spooler, waiting while kBatches are queued.
  void hand_over() {
    if (hand.filling.empty()) return;
    std::unique_lock lock(hand.mu);
    hand.cv.wait(lock, [&] { return hand.queue.size() < kBatches || hand.error; });
    if (hand.error) {
      lock.unlock();
      drain();
    }
    hand.queue.push_back(std::move(hand.filling));
    lock.unlock();
    hand.cv.notify_all();
    hand.filling = std::vector<Op>();
    hand.filling.reserve(kBatch);
  }
  // Stops the spooler once the queue is empty; rethrows what it threw.
  void drain() {
    if (hand.spooler.joinable()) {
      {
        std::lock_guard lock(hand.mu);
        hand.closing = true;
      }
      hand.cv.notify_all();
      hand.spooler.join();
    }
    if (hand.error) std::rethrow_exception(hand.error);
    spool.flush();
    records.flush();
    parents.flush();
  }
  // The backward sweep: ROI = own box united with the children's ROIs, subtree cone likewise
  // (compute_rois' rule, children folded in id order), height = the longest path down. Children
  // have larger ids, so going from the last op to the first finishes every child before its
  // parents; each op's finished entry goes to `sorted` under its R-tree key. Returns the DAG
  // depth (the longest path from an op without parents: R^0 in a valid CRMR).
  std::uint64_t sweep(EntrySorter& sorted, std::uint64_t* scratch_bytes) {
    storage::ExternalQueue<Message> messages(tmp_dir, side_sort_bytes(options));
    constexpr std::uint64_t kChunk = 4096;
    const std::uint64_t n = records.count();
    std::vector<OpRecord> chunk;
    std::vector<std::uint64_t> parent_ids;
    std::vector<Message> inbox;
    std::uint64_t dag_depth = 0;
    for (std::uint64_t end = n; end > 0;) {
      const std::uint64_t first = end > kChunk ? end - kChunk : 0;
      chunk.resize(end - first);
      records.read(first, chunk);
      const std::uint64_t p0 = chunk.front().parents_at;
      parent_ids.resize(chunk.back().parents_at + chunk.back().parent_count - p0);
      parents.read(p0, parent_ids);
      for (std::size_t k = chunk.size(); k-- > 0;) {
        OpRecord& r = chunk[k];
        const std::uint64_t id = first + k;
        inbox.clear();
        while (!messages.empty() && messages.top().to >= id) {
          if (messages.top().to != id)
            throw_internal("database writer: a message for op " +
                           std::to_string(messages.top().to) + " was left behind");
          inbox.push_back(messages.top());
          messages.pop();
        }
        std::sort(inbox.begin(), inbox.end(),
                  [](const Message& a, const Message& b) { return a.from < b.from; });
        NormalCone cone = r.entry.cone;
        std::uint64_t height = 0;
        for (const Message& m : inbox) {
          r.entry.roi.add(m.roi);
          cone = cone_union(cone, m.cone);
          height = std::max(height, m.height + 1);
        }
        // As pages store it, before the parents take it in (quantize's rule; header's errors
        // already include the snapping's shift).
        r.entry.roi = to_index(stored_roi(from_index(r.entry.roi), from_index(r.entry.box),
                                          stored_op_error(header, r.entry.res), grid));
        r.entry.cone = canonical_cone(cone);
        if (r.parent_count == 0) dag_depth = std::max(dag_depth, height);
        for (std::uint32_t j = 0; j < r.parent_count; ++j) {
          const std::uint64_t p = parent_ids[r.parents_at - p0 + j];
          if (p >= id)
            throw_internal("database writer: op " + std::to_string(id) + " has parent " +
                           std::to_string(p) + ", not an earlier op");
          messages.push({p, id, r.entry.roi, r.entry.cone, height});
        }
        sorted.add({order->key(r.entry.index_entry()), r.entry});
      }
      end = first;
    }
    *scratch_bytes += messages.spilled_bytes();
    return dag_depth;
  }
  ~State() {
    if (hand.spooler.joinable()) {
      {
        std::lock_guard lock(hand.mu);
        hand.closing = true;
        hand.queue.clear();
      }
      hand.cv.notify_all();
      hand.spooler.join();
    }
  }
};

DatabaseStreamWriter::DatabaseStreamWriter(const std::string& path, const WriteOptions& options,
                                           const std::string& tmp_dir)
    : s_(std::make_unique<State>(path, options, tmp_dir)) {}

DatabaseStreamWriter::~DatabaseStreamWriter() = default;

void DatabaseStreamWriter::begin(const CrmrInfo& header, std::uint64_t /*op_count*/) {
  if (s_->begun) throw_internal("database writer: begin() called twice");
  s_->begun = true;
  s_->header = header;
  s_->grid = choose_grid(header, s_->options.z_quantum, s_->options.error_quantum);
  s_->header.bounds = Box3{};  // of the snapped vertices, as quantize() does
  s_->order = std::make_unique<index::EntryOrder>(rtree_options(header, s_->options));
  s_->hand.spooler = std::thread([s = s_.get()] { s->run(); });
}

void DatabaseStreamWriter::encode(Op& op, std::vector<std::uint8_t>& out) const {
  const State& s = *s_;
  if (!s.begun || s.finished) throw_internal("database writer: encode() outside begin/finish");
  encode_op(op, s.header, s.grid, false, out);
}

void DatabaseStreamWriter::add_encoded(std::span<const std::uint8_t> op) {
  State& s = *s_;
  if (!s.begun || s.finished) throw_internal("database writer: add_encoded() outside begin/finish");
  if (s.input == State::Input::kOps)
    throw_internal("database writer: add_encoded() after add(): one or the other");
  s.input = State::Input::kEncoded;
  s.append(op);  // on this thread (the op's own work was done by encode()); checks the id order
}

void DatabaseStreamWriter::add(Op&& op) {
  State& s = *s_;
  if (!s.begun || s.finished) throw_internal("database writer: add() outside begin/finish");
  if (s.input == State::Input::kEncoded)
    throw_internal("database writer: add() after add_encoded(): one or the other");
  s.input = State::Input::kOps;
  if (op.id.value != s.next_id)
    throw_internal("database writer: op " + std::to_string(op.id.value) +
                   " arrived out of id order");
  ++s.next_id;
  s.hand.filling.push_back(std::move(op));
  if (s.hand.filling.size() >= State::kBatch) s.hand_over();
}

WriteReport DatabaseStreamWriter::finish() {
  if (!s_->begun || s_->finished) throw_internal("database writer: finish() without begin()");
  s_->finished = true;
  State& s = *s_;
  const auto t0 = Clock::now();
  s.hand_over();
  s.drain();
  std::uint64_t scratch = 0;
  // The sweep is one thread's work: full buffers of entries are sorted on another.
  EntrySorter sorted(s.tmp_dir, entry_sort_bytes(s.options), {}, storage::Spill::kBackground);
  TableCounts counts;
  counts.ops = s.records.count();
  counts.triangles = s.triangles;
  s.header.err0 += s.shift;  // before the sweep: stored ROIs follow the stored errors
  s.header.err_final += s.shift;
  counts.dag_depth = s.sweep(sorted, &scratch);
  const double seconds_sweep = seconds_since(t0);
  WriteReport report = write_tables(
      s.writer, s.header, s.grid, s.shift, sorted, counts,
      [&](std::span<const OpEntry> page, std::vector<Op>& held) {
        // A page's ops lie near one another in the spool (pages and the build's blocks both
        // follow space): they are read a run of nearby records at a time, not one by one.
        std::vector<RecordFile<std::uint8_t>::Piece> pieces(page.size());
        std::size_t total = 0;
        for (std::size_t i = 0; i < page.size(); ++i) {
          pieces[i] = {page[i].spool_at, page[i].spool_size, total};
          total += page[i].spool_size;
        }
        // Each thread reads its pages into one buffer it keeps (a page's ops are ~100 KiB: a
        // fresh buffer would be mapped, faulted in and unmapped for every page).
        thread_local Bytes bytes;
        bytes.resize(total);
        s.spool.read_pieces(pieces, bytes.data());
        std::vector<const Op*> ops(page.size());
        for (std::size_t i = 0, at = 0; i < page.size(); at += page[i].spool_size, ++i) {
          const OpEntry& e = page[i];
          Op& op = held.emplace_back(
              unspool_op(ByteView(bytes).subspan(at, e.spool_size), e.id, s.grid));
          op.roi = from_index(e.roi);
          op.subtree_cone = e.cone;
          op.error = stored_op_error(s.header, op.birth_res);
          ops[i] = &op;
        }
        return ops;
      },
      s.options, s.tmp_dir);
  report.spool_bytes = s.spool.bytes();
  report.scratch_bytes += scratch + s.records.bytes() + s.parents.bytes();
  report.seconds_sweep = seconds_sweep;
  report.seconds = seconds_since(t0);
  return report;
}

const CrmrInfo& DatabaseStreamWriter::header() const {
  return s_->header;
}

}  // namespace smr
