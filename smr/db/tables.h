// The tables of a database file (docs/design.md sections 3, 5, 6): a CRMR in one LMDB file.
//
//   meta         "meta" -> JSON (format, model info, grid, counts, build parameters), sealed
//   pages        u64 leaf -> R-tree leaf `leaf` and its data page (smr/db/page.h, PageValue): the
//                leaf's entries and the page's ops, slot for slot, each sealed
//   locators     u64 block -> where ops 256*block .. 256*block+255 are: varint page, varint slot
//                per op (differences of pages as svarints), sealed
//   rtree        u64 node -> R-tree node above the leaves (index/rtree.h); key 2^64-1 -> the
//                tree's header
//   aux          unused so far
// Every value carries an xxhash checksum (storage/checksum.h); a mismatch names the table and key.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <string_view>

namespace smr {

// 5: R-tree leaves in the pages' values (page.h, PageValue), page format 5; 4: page format 4;
// 3: table "locators".
inline constexpr int kDatabaseFormat = 5;
inline constexpr std::uint64_t kOpsPerLocatorBlock = 256;
inline constexpr std::uint64_t kRtreeHeaderKey = std::numeric_limits<std::uint64_t>::max();

/// A table of a database: its index in kTableNames (storage::Table converts from it).
enum class Table : std::uint8_t { kMeta, kOpLocators, kPages, kRtree, kAux };

/// The LMDB sub-database names, by Table, in the order the writer creates them (names and order
/// are part of the file's bytes). Format 2 named the op locators' table "nodes".
inline constexpr std::array<std::string_view, 5> kTableNames = {"meta", "locators", "pages",
                                                                "rtree", "aux"};
inline constexpr std::array<Table, 5> kAllTables = {Table::kMeta, Table::kOpLocators, Table::kPages,
                                                    Table::kRtree, Table::kAux};

/// The table's on-disk name, as error messages spell it ("locators/12: ...").
constexpr std::string_view table_name(Table table) {
  return kTableNames[static_cast<std::size_t>(table)];
}

}  // namespace smr
