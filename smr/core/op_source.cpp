#include "smr/core/op_source.h"

#include <algorithm>
#include <string>
#include <utility>

#include "base/error.h"

namespace smr {

double error_at(const CrmrInfo& info, double res) {
  const double span = info.err0 - info.err_final;
  if (span <= 0.0) return info.err_final;
  return info.err_final + (1.0 - res) * span;
}

double resolution_of(const CrmrInfo& info, double error) {
  const double span = info.err0 - info.err_final;
  if (span <= 0.0) return 1.0;
  return std::clamp(1.0 - (error - info.err_final) / span, 0.0, 1.0);
}

const OpView& batch_op(const OpBatch& batch, std::uint32_t index, OpId id) {
  if (index >= batch.ops.size() || batch.ops[index].id != id) {
    throw Error(ErrorKind::kCorrupt, "op " + std::to_string(id.value) +
                                         " is not where its locator says (index " +
                                         std::to_string(index) + " of a page of " +
                                         std::to_string(batch.ops.size()) + " ops)");
  }
  return batch.ops[index];
}

const OpView& OpReader::read(const PlacedOp& p) {
  if (p.at.index == OpPlace::kNoIndex) {
    ref_ = source_->op(p.id);
    return *ref_;
  }
  if (batch_.keep == nullptr || place_ != p.at.place) {
    batch_ = source_->batch(p.at.place);
    place_ = p.at.place;
  }
  return batch_op(batch_, p.at.index, p.id);
}

PlaceLookahead::PlaceLookahead(const OpSource& source, std::vector<std::uint64_t> places)
    : source_(source), places_(std::move(places)) {
  reached(0);
}

void PlaceLookahead::reached(std::size_t i) {
  if (i + kAhead - kStep < hinted_ || hinted_ >= places_.size()) return;
  const std::size_t from = std::max(i + 1, hinted_), to = std::min(places_.size(), i + 1 + kAhead);
  if (from < to) source_.prefetch(std::span(places_).subspan(from, to - from));
  hinted_ = to;
}

// Database places are page numbers, fewer than the ops of a big X: then a counting pass by place,
// and a sort within each place.
void sort_for_reading(std::vector<PlacedOp>& ops) {
  std::uint64_t top = 0;
  for (const PlacedOp& p : ops) top = std::max(top, p.at.place);
  if (ops.size() < 1024 || top >= ops.size()) {
    std::sort(ops.begin(), ops.end());
    return;
  }
  std::vector<std::size_t> start(std::size_t(top) + 2, 0);
  for (const PlacedOp& p : ops) ++start[std::size_t(p.at.place) + 1];
  for (std::size_t i = 1; i < start.size(); ++i) start[i] += start[i - 1];
  std::vector<PlacedOp> sorted(ops.size());
  std::vector<std::size_t> next(start.begin(), start.end() - 1);
  for (const PlacedOp& p : ops) sorted[next[std::size_t(p.at.place)]++] = p;
  for (std::size_t i = 0; i + 1 < start.size(); ++i)
    std::sort(sorted.begin() + std::ptrdiff_t(start[i]),
              sorted.begin() + std::ptrdiff_t(start[i + 1]));
  ops.swap(sorted);
}

FragmentTriangle OpSource::triangle(TriRef t) const {
  return op(t.op)->triangle(t.index);
}

double OpSource::error_at(double res) const {
  return smr::error_at(info(), res);
}
double OpSource::resolution_of(double error) const {
  return smr::resolution_of(info(), error);
}

}  // namespace smr
