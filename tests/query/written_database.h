// A CRMR written to a database in a scratch directory and opened for queries through the R-tree
// (IndexedSource), for the query tests that check a database answers as its CRMR.
#pragma once

#include <cstddef>
#include <memory>
#include <string>

#include "smr/core/crmr.h"
#include "smr/db/database.h"
#include "smr/db/writer.h"
#include "smr/query/indexed_source.h"
#include "tests/support/files.h"

namespace smr::test {

class WrittenDatabase {
 public:
  explicit WrittenDatabase(const Crmr& crmr, std::size_t cache_bytes = std::size_t{1} << 20) {
    const std::string path = dir_.file("query.smrdb");
    Crmr copy = crmr;  // write_database snaps the CRMR it is given to its grid
    write_database(copy, path, {});
    db_ = Database::open(path, {cache_bytes});
    source_ = std::make_unique<IndexedSource>(*db_);
  }
  const IndexedSource& source() const { return *source_; }
  const Database& database() const { return *db_; }

 private:
  TempDir dir_{"smrdb-query"};
  std::unique_ptr<Database> db_;
  std::unique_ptr<IndexedSource> source_;
};

}  // namespace smr::test
