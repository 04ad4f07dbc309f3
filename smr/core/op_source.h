// Read access to a CRMR (Brown 4.4, 4.5), whatever holds it: the header of the model and its ops
// by id. The in-memory Crmr (crmr.h) and the on-disk store (smr/db) implement it; extraction
// (smr/extract) and the checks (invariants.h) read through it.
//
// Resolution. Brown defines r(M^m) = 1 for the finest mesh. We keep that and tie resolution to
// absolute error against the SOURCE data: r = 1 - (err - err_final) / (err0 - err_final), where
// err0 is the base mesh's error and err_final the finest mesh's (0 for a lossless build, in which
// case r = 1 - err/err0 as in docs/design.md). So error_at(death_res(t)) bounds t's true deviation.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "smr/core/geometry.h"
#include "smr/core/heightfield.h"
#include "smr/core/op.h"

namespace smr {

enum class ModelKind : std::uint8_t { kTerrain = 0, kMesh3d = 1 };

struct CrmrInfo {
  ModelKind kind = ModelKind::kTerrain;
  Georef georef;
  int grid_width = 0, grid_height = 0;  // terrain: the source grid
  double err0 = 0.0;                    // max error of the base mesh M^0
  double err_final = 0.0;               // max error of the finest mesh M^m
  Box3 bounds;                          // of every vertex
  std::string source;
  std::string builder;  // builder name and parameters, for `info`
  std::uint64_t vertex_count = 0;
  friend bool operator==(const CrmrInfo&, const CrmrInfo&) = default;
};

/// A handle on an op that keeps it alive: an op paged in from disk stays in memory, with its whole
/// decoded page, while a handle on it exists, even if the page cache evicts the page.
using OpRef = std::shared_ptr<const OpView>;

/// Where an op is stored: its place (OpSource::locality) and its index among the ops of that place
/// as OpSource::batch returns them; kNoIndex for sources that do not read ops in batches.
struct OpPlace {
  static constexpr std::uint32_t kNoIndex = ~std::uint32_t{0};
  std::uint64_t place = 0;
  std::uint32_t index = kNoIndex;
};

/// The ops stored at one place, read together (smr/db: one decoded page): `ops` stay valid while
/// `keep` is held. Reading a place's ops this way costs one lookup, not one per op.
struct OpBatch {
  std::shared_ptr<const void> keep;
  std::span<const OpView> ops;
};

/// Op `index` of `batch`, which must be op `id` (as place_of said); throws smr::Error (kCorrupt)
/// otherwise.
const OpView& batch_op(const OpBatch& batch, std::uint32_t index, OpId id);

class OpSource;

/// An op with where it is stored; sorting orders ops for reading (place, then index).
struct PlacedOp {
  OpPlace at;
  OpId id;
  friend bool operator<(const PlacedOp& a, const PlacedOp& b) {
    if (a.at.place != b.at.place) return a.at.place < b.at.place;
    if (a.at.index != b.at.index) return a.at.index < b.at.index;
    return a.id < b.id;
  }
};

/// Sorts ops into reading order (PlacedOp's <).
void sort_for_reading(std::vector<PlacedOp>& ops);

/// Reads ops one after another through their places, holding the last place's batch: ops read in
/// place order cost one lookup per place. A returned view stays valid until the reader reads an
/// op of another place (or is reset); the previous one is still held while the next is fetched.
class OpReader {
 public:
  explicit OpReader(const OpSource& source) : source_(&source) {}
  const OpView& read(const PlacedOp& p);

 private:
  const OpSource* source_;
  OpBatch batch_;
  std::uint64_t place_ = 0;
  OpRef ref_;  // an op of a source without batches
};

/// Keeps a source's prefetch (OpSource::prefetch) a few places ahead of a reader going through
/// `places` in order: reached(i) says the reader is at places[i].
class PlaceLookahead {
 public:
  static constexpr std::size_t kAhead = 16, kStep = 8;
  PlaceLookahead(const OpSource& source, std::vector<std::uint64_t> places);
  void reached(std::size_t i);

 private:
  const OpSource& source_;
  std::vector<std::uint64_t> places_;
  std::size_t hinted_ = 0;  // places_[0, hinted_) were hinted
};

/// Read access to a CRMR, in memory (Crmr) or paged from disk (smr/db's Database).
class OpSource {
 public:
  virtual ~OpSource() = default;
  virtual const CrmrInfo& info() const = 0;
  virtual std::uint64_t op_count() const = 0;
  /// The op; throws smr::Error if `id` is out of range or its record cannot be read.
  virtual OpRef op(OpId id) const = 0;
  /// Where the op is stored, as a number: ops with equal values are read together and reading in
  /// increasing order is cheapest (smr/db: the op's data page). Reads no op. Traversals whose
  /// result does not depend on the visiting order use it to visit ops page by page.
  virtual std::uint64_t locality(OpId) const { return 0; }
  /// The memory an OpRef into place `locality` holds beyond the source's own (smr/db: the
  /// decoded page, which a handle keeps alive); 0 for in-memory sources.
  virtual std::uint64_t locality_bytes(std::uint64_t /*locality*/) const { return 0; }
  /// The op's place and index (reads no op); index OpPlace::kNoIndex: read it with op().
  virtual OpPlace place_of(OpId id) const { return {locality(id), OpPlace::kNoIndex}; }
  /// Every op of a place that place_of gave an index in; throws smr::Error like op().
  virtual OpBatch batch(std::uint64_t /*place*/) const { return {}; }
  /// A hint: these places (in the order given) are read soon, the first of them next by the reader
  /// itself. smr/db decodes the others on a thread of its own meanwhile, as many as a quarter of
  /// its cache holds; replaces the previous hint. Returns how many of `places` the hint took (0:
  /// the source reads nothing ahead). Never needed for correctness.
  virtual std::size_t prefetch(std::span<const std::uint64_t> /*places*/) const { return 0; }
  /// The reader will read ops' Hypermesh links (OpView::coarser: the advancing front does): from
  /// now on every op read has them. smr/db decodes pages without them until asked, since the
  /// set formula, the level cut and every query do without (a sixth of a decoded page).
  virtual void need_links() const {}

  /// Triangle `t`; throws smr::Error if it does not exist.
  FragmentTriangle triangle(TriRef t) const;
  double error_at(double res) const;
  double resolution_of(double error) const;
};

double error_at(const CrmrInfo& info, double res);
double resolution_of(const CrmrInfo& info, double error);

}  // namespace smr
