// Independent oracles for the invariants of docs/design.md section 8. They re-derive each property
// from first principles (grid samples, point evaluations of the RCF's definitions) instead of
// calling the code under test's own decision functions.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "smr/core/crmr.h"
#include "smr/core/heightfield.h"
#include "smr/extract/extract.h"
#include "smr/rcf/spec.h"

namespace smr::test {

struct OracleResult {
  std::uint64_t checked = 0;
  std::uint64_t failures = 0;
  std::string first_failure;
  double worst = 0.0;  // largest excess found (error bound: metres over the bound)
  void fail(const std::string& what) {
    if (failures++ == 0) first_failure = what;
  }
  bool ok() const { return failures == 0; }
};

/// The finest mesh M^m: every fragment triangle no op replaces.
std::vector<TriRef> finest_mesh(const Crmr& m);

/// Every grid sample in the closed (non-void) triangle deviates from the triangle's plane by no
/// more than error_at(death_res) (+ a float-rounding tolerance). No-data samples are skipped.
OracleResult check_error_bound(const OpSource& source, std::span<const TriRef> triangles,
                               const Heightfield& dem);

/// Per triangle, from the RCF spec's definitions evaluated at points (vertices, edge points,
/// centroid, grid samples inside, the point nearest each AOI centre): either the triangle is
/// culled (all vertices outside one frustum plane, or its normal faces away from the eye at every
/// vertex) or g(p) <= death_res and the projected error at p <= tau(p) pixels, or it is final
/// (no op replaces it: the finest the model offers, Brown 4.6.2).
OracleResult check_rcf_pointwise(const OpSource& source, std::span<const TriRef> triangles,
                                 const RcfSpec& spec, const Heightfield& dem);

/// Theorem 5.1.1: t is in F(R) with R finer, or in PreF(R') with R' completely finer, or no op
/// replaces t (it is the finest the model has: Brown 4.6.2, "or if its fragment has no children").
OracleResult check_rcf_opwise(const OpSource& source, std::span<const TriRef> triangles,
                              const Rcf& rcf);

/// X is exactly the set of Brown 5.1.1 (minimal: R^0, closure conditions, every member justified)
/// or of Lemma 5.2.1 (reduced: R^0 and every op not completely finer).
OracleResult check_x_definition(const OpSource& source, std::span<const OpId> x, const Rcf& rcf,
                                bool ancestors);

/// Brute force for the Hypermesh links (Brown 4.5.1): replays the ops in id order from R^0 with
/// every live triangle's directed edges in a map, as an in-memory builder does, and expects each
/// op's coarser links to be the newer (larger op) of PreF's triangle with a->b and the live one
/// with b->a across each fragment boundary edge a->b (none on the model boundary).
void expect_links_of_a_replay(const Crmr& crmr);

/// The invariants every terrain cut is held to (docs/design.md section 8): it tiles the domain
/// (8.1), the advancing front equals the set formula triangle for triangle (Brown
/// Lemma 5.1.1, 8.3), every triangle meets the RCF op-wise and, independently, point-wise (Brown
/// Theorem 5.1.1, 8.2), and its stored error bounds its deviation from every DEM sample under it
/// (8.5). Failures are reported through EXPECT_*.
void expect_terrain_cut_invariants(const OpSource& source, const Extraction& e, const Rcf& rcf,
                                   const RcfSpec& spec, const Heightfield& dem);

}  // namespace smr::test
