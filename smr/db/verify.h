// `smrdb verify`: every value of a database read, every checksum checked, every cross-reference
// followed (tables.h).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace smr {

/// What verify_database found: the data pages and the op locators, the DAG (parents <-> children,
/// PreF <-> killers), Hypermesh links, and that the R-tree holds every op exactly once with a
/// conservative box, in the page of its leaf.
struct VerifyReport {
  std::vector<std::string> faults;  // empty = clean
  std::uint64_t pages = 0, ops = 0, triangles = 0, links = 0, rtree_nodes = 0;
  bool ok() const { return faults.empty(); }
};

/// Reads every value of the database at `path` and checks it (VerifyReport). Faults name the
/// file; at most 100 are kept. `progress` (may be empty) gets the fraction done.
VerifyReport verify_database(const std::string& path, const std::function<void(double)>& progress);

}  // namespace smr
