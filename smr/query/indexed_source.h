// Queries over a database (smr/db) that need more than the store: here, RCF questions answered
// from the R-tree over ROI boxes (Maheshwari 4.4), which reduced extraction's X (Brown Lemma
// 5.2.1) and AddToList's candidate children (Brown 5.1.1) take instead of a scan of every op.
// Data flows store -> index -> extract: the store knows no RCF, extraction no R-tree.
#pragma once

#include <cstdint>
#include <vector>

#include "index/rtree.h"
#include "smr/db/database.h"
#include "smr/extract/extract.h"
#include "smr/rcf/rcf.h"

namespace smr {

/// A Database as extraction reads it: its ops (every OpSource call forwards to it) and the
/// R-tree's answers to "which ops are not completely finer than the RCF". Pass this, not the
/// Database, to the extraction algorithms: given a bare Database they scan every op. Holds a
/// reference to the database, which must outlive it; as thread-safe as the database.
class IndexedSource final : public OpSource, public RcfIndexedSource {
 public:
  explicit IndexedSource(const Database& db) : db_(db) {}

  const CrmrInfo& info() const override { return db_.info(); }
  std::uint64_t op_count() const override { return db_.op_count(); }
  OpRef op(OpId id) const override { return db_.op(id); }
  std::uint64_t locality(OpId id) const override { return db_.locality(id); }
  std::uint64_t locality_bytes(std::uint64_t page) const override {
    return db_.locality_bytes(page);
  }
  OpPlace place_of(OpId id) const override { return db_.place_of(id); }
  OpBatch batch(std::uint64_t page) const override { return db_.batch(page); }
  std::size_t prefetch(std::span<const std::uint64_t> pages) const override {
    return db_.prefetch(pages);
  }
  void need_links() const override { db_.need_links(); }

  /// Reduced extraction's X from the R-tree: every op not completely finer than `rcf`. Reads
  /// the R-tree nodes the query enters and the data pages of the entries it accepts.
  std::vector<OpId> not_completely_finer(const RcfOracle& rcf) const override;
  /// The entries the R-tree query accepts (a superset of not_completely_finer), reading no page
  /// (it asks the OS to read ahead those of theirs the cache lacks: Database::will_need; with
  /// `read_ahead`, the database's prefetcher too, as the query finds them).
  CandidateOps maybe_not_completely_finer(const RcfOracle& rcf, bool read_ahead) const override;
  /// The database is safe to read from several threads.
  bool concurrent_queries() const override { return true; }
  /// The R-tree query behind both: accepted entries, grouped by leaf (= data page).
  std::vector<index::Hit> rcf_hits(const RcfOracle& rcf) const;

  const Database& database() const { return db_; }

 private:
  const Database& db_;
};

}  // namespace smr
