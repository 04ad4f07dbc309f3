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
class RcfVisitor final : public index::Visitor {
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

}  // namespace

std::vector<index::Hit> IndexedSource::rcf_hits(const RcfOracle& rcf) const {
  RcfVisitor visitor(rcf, db_.info());
  return db_.rtree_query(visitor);
}

std::vector<OpId> IndexedSource::maybe_not_completely_finer(const RcfOracle& rcf) const {
  std::vector<OpId> ids;
  std::vector<std::uint64_t> pages;
  for (const index::Hit& h : rcf_hits(rcf)) {
    ids.push_back(OpId{h.id});
    if (pages.empty() || pages.back() != h.leaf) pages.push_back(h.leaf);
  }
  db_.will_need(pages);  // the pages the candidates are on, read ahead if not in the cache
  return ids;
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
