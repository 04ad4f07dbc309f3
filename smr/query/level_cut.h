// The minimal mesh of a constant object-space RCF (`--floor L` alone: the whole model at one
// resolution, what a user asks for as "the model at error e" and what martini's getMesh(maxError)
// gives), straight from the data pages, without AddToList's traversal or the ops' decoding.
//
// With a constant level L (no culling), IsFiner and IsCompletelyFiner (Rcf) depend on
// resolutions alone: a triangle meets the RCF at resolution r iff meets_level(r, L). The CRMR's
// invariants (DESIGN.md section 4; check_crmr) give: birth_res is non-decreasing from parent to
// child; every op but R^0 has a non-empty PreF, and each of its parents gives it a PreF triangle;
// a triangle's death_res is its killer's (a child's) birth_res. So, with no void triangle,
// AddToList's fixed point (Brown 5.1.1, Fig. 5.2) is X = R^0 and the ops that do not meet L; by
// induction on the ids: a parent of such an op does not meet L either, is in X, and is not finer
// (the PreF triangle it gives dies below L), so the op is reached and is not completely finer;
// and neither rule adds an op that meets L. The set formula (Lemma 5.1.1)
// then keeps the fragment triangles of X whose killer is not in X: one pass over the pages that
// hold an op of X, each read alone, on every core, merged in page order.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "smr/core/mesh.h"
#include "smr/db/database.h"
#include "smr/extract/extract.h"
#include "smr/rcf/rcf.h"
#include "smr/rcf/spec.h"

namespace smr {

struct LevelCutOptions {
  unsigned threads = 0;             // reading and cutting pages (0: one per core)
  std::uint64_t max_triangles = 0;  // stop once the mesh has more (0: no limit)
};

struct LevelCutStats {
  std::uint64_t x = 0;          // |X| (of the pages merged)
  std::uint64_t pages = 0;      // data pages merged: those the R-tree says may hold an op of X
  std::uint64_t triangles = 0;  // output triangles
  bool voids = false;           // stopped at a page with a void triangle
  bool over_budget = false;     // stopped past max_triangles
};

/// The level of a spec that is a constant object-space level and nothing else, or nullopt.
std::optional<double> constant_level(const RcfSpec& spec);

/// The minimal mesh meeting the constant level `level` (in [0, 1]): the triangles of the set
/// formula in page order (each op's in fragment order), vertices numbered by first use, per
/// triangle its death_res as triangle_values: the mesh to_mesh makes of extract_minimal_surface's
/// triangles, up to their order. nullopt if a page the cut reads holds a void triangle (the
/// closed form of X does not hold there; extract_minimal_surface does) or if the mesh passes
/// options.max_triangles (the stats say which). Reads pages past the cache on options.threads
/// threads; the result does not depend on their number.
std::optional<TriangleMesh> extract_level_cut(const Database& db, double level,
                                              const LevelCutOptions& options = {},
                                              LevelCutStats* stats = nullptr);

/// The check behind --verify: the general path (AddToList and the set formula through the
/// R-tree, extract_minimal_surface, then to_mesh) gives `mesh`'s triangles and `stats.x` ops for
/// `rcf`, the cut's constant level. Returns what differs, or "" if nothing; `general` (if given)
/// receives the general path's extraction.
std::string check_level_cut(const Database& db, const Rcf& rcf, const TriangleMesh& mesh,
                            const LevelCutStats& stats, Extraction* general = nullptr);

}  // namespace smr
