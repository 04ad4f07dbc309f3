// IndexedSource (indexed_source.h): the RCF query over a database's R-tree.
#include "smr/query/indexed_source.h"

#include <memory>
#include <string>

#include "base/error.h"
#include "smr/db/index_box.h"
#include "smr/db/tables.h"

namespace smr {

namespace {

// Brown Lemma 5.2.1 through the R-tree: a subtree is skipped when every op in it is completely
// finer (Rcf::region_completely_finer on the union of the ops' own boxes, at the subtree's least
// birth_res: conservative and monotone); an entry passing its box test is then judged exactly.
class RcfVisitor : public index::Visitor {
 public:
  RcfVisitor(const RcfOracle& rcf, const CrmrInfo& info) : rcf_(rcf), info_(info) {}
  bool enter(const index::Summary& s) override {
    return !rcf_.region_completely_finer(from_index(s.box), from_index(s.roi), s.min_res, info_);
  }
  bool accept(const index::Entry& e) override {
    return !rcf_.region_completely_finer(from_index(e.box), from_index(e.roi), e.res, info_);
  }

 private:
  const RcfOracle& rcf_;
  const CrmrInfo& info_;
};

// The query with its pages hinted to the database's prefetcher as their leaves are found, so that
// decoding starts while the query runs (about 2 ms of a warm 1 px view of the 16385^2 database),
// every 4 leaves, until a hint no longer takes them all (a quarter of the cache).
class ReadAheadVisitor final : public RcfVisitor {
 public:
  ReadAheadVisitor(const RcfOracle& rcf, const Database& db, std::uint64_t first)
      : RcfVisitor(rcf, db.info()), db_(db), pages_{first} {}
  void leaf_done(std::uint32_t leaf, std::size_t accepted) override {
    if (accepted == 0 || stopped_ || leaf == pages_[0]) return;
    pages_.push_back(leaf);
    if (pages_.size() % 4 == 1) stopped_ = db_.prefetch(pages_) < pages_.size();
  }

 private:
  const Database& db_;
  std::vector<std::uint64_t> pages_;  // the reader's first page, then those found
  bool stopped_ = false;
};

}  // namespace

std::vector<index::Hit> IndexedSource::rcf_hits(const RcfOracle& rcf) const {
  RcfVisitor visitor(rcf, db_.info());
  return db_.rtree_query(visitor);
}

CandidateOps IndexedSource::maybe_not_completely_finer(const RcfOracle& rcf,
                                                       bool read_ahead) const {
  CandidateOps c;
  std::vector<index::Hit> hits;
  if (read_ahead) {
    ReadAheadVisitor visitor(rcf, db_, db_.place_of(kBaseOp).place);
    hits = db_.rtree_query(visitor);
  } else {
    hits = rcf_hits(rcf);
  }
  for (const index::Hit& h : hits) {  // grouped by leaf: a leaf's page is its number
    c.ids.push_back(OpId{h.id});
    if (c.places.empty() || c.places.back() != h.leaf) c.places.push_back(h.leaf);
  }
  db_.will_need(c.places);        // the pages the candidates are on, read ahead if not in the cache
  db_.will_need_locators(c.ids);  // and where they are (the traversal locates what it visits)
  return c;
}

std::vector<OpId> IndexedSource::not_completely_finer(const RcfOracle& rcf) const {
  std::vector<OpId> x;
  std::shared_ptr<const DecodedPage> ops;
  std::uint64_t current = ~0ull;
  std::size_t slot = 0;  // hits come in slot order within a leaf: one pass over each page
  for (const index::Hit& h : rcf_hits(rcf)) {
    if (h.leaf != current) {
      current = h.leaf;
      ops = db_.page(h.leaf);
      slot = 0;
    }
    while (slot < ops->size() && (*ops)[slot].id.value != h.id) ++slot;
    const OpView* found = slot < ops->size() ? &(*ops)[slot] : nullptr;
    if (found == nullptr)
      throw Error(ErrorKind::kCorrupt, db_.path() + ": " + std::string(table_name(Table::kPages)) +
                                           "/" + std::to_string(h.leaf) + " lacks op " +
                                           std::to_string(h.id) + " of its R-tree leaf");
    if (found->id == kBaseOp || !rcf.is_completely_finer(*found, *this)) x.push_back(found->id);
  }
  return x;
}

}  // namespace smr
