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
#include <string>

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

  /// Triangle `t`; throws smr::Error if it does not exist.
  FragmentTriangle triangle(TriRef t) const;
  double error_at(double res) const;
  double resolution_of(double error) const;
};

double error_at(const CrmrInfo& info, double res);
double resolution_of(const CrmrInfo& info, double error);

}  // namespace smr
