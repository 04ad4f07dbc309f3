// Selective mesh refinement (Brown ch. 5): the minimal surface algorithm (5.1: AddToList, then
// surface expansion by Infill/PerformExpansion as an advancing front, highest resolution first)
// and reduced extraction for 2.5-D (5.2: X from Eq. 5.5, coarser ops pulled in by the expansion,
// starting points confirmed by a domain test).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "smr/core/crmr.h"
#include "smr/core/mesh.h"
#include "smr/rcf/rcf.h"

namespace smr {

struct ExtractStats {
  std::uint64_t x = 0;       // |X| after refinement operation extraction
  std::uint64_t x_plus = 0;  // |X+| after surface expansion (reduced extraction; = |X| otherwise)
  std::uint64_t ops_visited = 0;
  std::uint64_t triangles = 0;  // expanded triangles, void ones included
  std::uint64_t void_triangles = 0;
  std::uint64_t fans = 0;
  std::uint64_t starting_points = 0;
  std::uint64_t domain_tests = 0;     // reduced extraction's geometric starting-point tests
  std::uint64_t held_ops_peak = 0;    // most ops of X held between their page's read and infill
  std::uint64_t held_bytes_peak = 0;  // the decoded pages they hold, in bytes
  double triangles_per_fan() const { return fans == 0 ? 0.0 : double(triangles) / double(fans); }
  double extract_seconds = 0.0;  // refinement operation extraction
  double expand_seconds = 0.0;   // surface expansion
};

struct Extraction {
  std::vector<OpId> x;                    // the extracted ops (X, or X+), descending
  std::vector<TriRef> triangles;          // in expansion order
  std::vector<std::uint32_t> fan_starts;  // index in `triangles` where each triangle fan begins
  ExtractStats stats;
};

struct ExpansionOptions {
  /// Stop the expansion after this many triangles (0 = no limit). The part expanded first is the
  /// highest-resolution part (Brown 5.1.2); a stopped expansion does not tile the domain.
  std::uint64_t max_triangles = 0;
  /// The decoded pages that ops of X hold while they wait for their turn (expansion.cpp,
  /// HeldOps): beyond this, pages are no longer read whole for X and ops come through the
  /// source's cache.
  std::uint64_t max_held_bytes = std::uint64_t{512} << 20;
  /// Minimal surface only: false outputs the same triangles (Lemma 5.1.1: for an ancestor-closed
  /// X the set formula is the minimal surface) from one pass over X's ops, page by page, with no
  /// advancing front: no fans, in page order, several times faster. Ignored (the front runs) when
  /// max_triangles is set or for reduced extraction, whose X+ grows during the expansion.
  bool fronts = true;
  /// Whether the advancing front runs (it reads the ops' links: OpSource::need_links).
  bool runs_front() const { return fronts || max_triangles != 0; }
};

/// An index's conservative answer to "which ops may be not completely finer than the RCF".
struct CandidateOps {
  std::vector<OpId> ids;
  std::vector<std::uint64_t> places;  // the ids' places (OpSource::locality), each once
};

/// A source that answers "which ops are not completely finer than the RCF" from an index instead
/// of a scan of every op (smr/query/indexed_source.h: a database's R-tree over ROI boxes,
/// Maheshwari 4.4).
class RcfIndexedSource {
 public:
  virtual ~RcfIndexedSource() = default;
  /// Exactly the ops that are not completely finer than `rcf` (R^0 may be omitted; it is always
  /// added): reduced extraction's X.
  virtual std::vector<OpId> not_completely_finer(const RcfOracle& rcf) const = 0;
  /// A superset of not_completely_finer() found without reading ops (a conservative test on
  /// index entries), so that AddToList can rule out children without fetching them, and the
  /// places they lie on. `read_ahead`: the caller reads those places next, starting at R^0's,
  /// and the source may start reading them (OpSource::prefetch) before it returns.
  virtual CandidateOps maybe_not_completely_finer(const RcfOracle& rcf, bool read_ahead) const = 0;
  /// Whether maybe_not_completely_finer may run on another thread while the source is read (a
  /// session then looks ahead on a second core).
  virtual bool concurrent_queries() const { return false; }
};

/// Brown 5.1.1 (Fig. 5.2): the smallest X containing R^0, the children of its non-finer members
/// that are not completely finer, and all ancestors of its members. Sorted descending.
std::vector<OpId> add_to_list(const OpSource& source, const RcfOracle& rcf);

/// Reduced extraction's X (Brown Eq. 5.5 in the form of Lemma 5.2.1): R^0 and every op that is
/// not completely finer than the RCF. Scans every op, unless the source is an RcfIndexedSource.
std::vector<OpId> add_to_list_reduced(const OpSource& source, const RcfOracle& rcf);

/// Minimal surface SMR (Brown 5.1).
Extraction extract_minimal_surface(const OpSource& source, const RcfOracle& rcf,
                                   const ExpansionOptions& options = {});

/// The surface expansion of Brown 5.1 for an X that AddToList (or a session) made, as
/// `options` asks (advancing front or set formula); `extract_seconds` is reported as the time X
/// took.
Extraction expand_minimal(const OpSource& source, std::span<const OpId> x,
                          const ExpansionOptions& options, double extract_seconds);

/// Reduced extraction SMR (Brown 5.2), 2.5-D only: a 3-D mesh source is kInvalidInput.
Extraction extract_reduced(const OpSource& source, const RcfOracle& rcf,
                           const ExpansionOptions& options = {});

/// Surface expansion of an ancestor-closed X (Brown 5.1.2). `x` in any order.
Extraction expand(const OpSource& source, std::span<const OpId> x,
                  const ExpansionOptions& options = {});

/// The set formula of Lemma 5.1.1: union of F(R) minus union of PreF(R) over R in X. Sorted.
std::vector<TriRef> set_formula(const OpSource& source, std::span<const OpId> x);

/// The set formula of an ancestor-closed X as an extraction (ExpansionOptions::fronts false): a
/// triangle of F(R), R in X, is in the mesh when its killer is not in X (its PreF membership is
/// the killer's). Ops visited page by page (OpSource::locality), triangles in that order.
Extraction extract_set_formula(const OpSource& source, std::span<const OpId> x);

/// An indexed mesh of the given triangles, vertices shared by id; void triangles are dropped
/// unless keep_void. triangle_values holds each triangle's death_res.
TriangleMesh to_mesh(const OpSource& source, std::span<const TriRef> triangles,
                     bool keep_void = false);

}  // namespace smr
