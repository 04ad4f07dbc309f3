// `smrdb verify` (verify.h): a pass over the data pages gathers what every op says of itself and
// of the others, then each check below follows one kind of cross-reference: ids, op locators,
// the DAG (Brown 4.4: parents <-> children, subtree normal cones), PreF <-> killers and
// Hypermesh links (Brown 4.5), and the R-tree (Maheshwari 4.4).
#include "smr/db/verify.h"

#include <algorithm>
#include <optional>
#include <utility>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/db/database.h"
#include "smr/db/index_box.h"
#include "smr/db/page.h"
#include "smr/db/tables.h"

namespace smr {

namespace {

constexpr std::size_t kMaxFaults = 100;

// Collects faults, each naming the file, up to kMaxFaults.
class Faults {
 public:
  Faults(const std::string& path, std::vector<std::string>& out) : path_(path), out_(out) {}
  void operator()(const std::string& what) {
    if (out_.size() >= kMaxFaults) return;
    out_.push_back(what.rfind(path_, 0) == 0 ? what : path_ + ": " + what);
  }

 private:
  const std::string& path_;
  std::vector<std::string>& out_;
};

struct OpFacts {
  std::uint64_t page = ~0ull;
  std::uint32_t slot = 0;
  double birth_res = 0.0;
  Box3 box, roi;
  NormalCone subtree_cone;
  std::vector<OpId> killers;  // per fragment triangle
  std::uint32_t seen = 0;
};

// What the page pass gathers for the checks: the facts of every op (by id) and the references
// between ops, each kind in one list.
struct Gathered {
  explicit Gathered(std::uint64_t n) : facts(n) {}
  std::vector<OpFacts> facts;
  std::vector<std::pair<std::uint64_t, std::uint64_t>> down, up;  // (parent, child) both ways
  std::vector<std::pair<TriRef, OpId>> pre;                       // (triangle, op replacing it)
  std::vector<std::pair<OpId, EdgeRef>> links;
  std::uint64_t n() const { return facts.size(); }
};

bool contains(const Box3& outer, const Box3& inner) {
  for (int k = 0; k < 3; ++k) {
    if (!(outer.lo[k] <= inner.lo[k] && inner.hi[k] <= outer.hi[k])) return false;
  }
  return true;
}

// Every data page, read once: each op's id is in range and stored once, its ROI holds its box
// and its subtree normal cone its own cone. Gathers the facts and references of every op.
void read_pages(const Database& db, Gathered& g, VerifyReport& rep, Faults& fault,
                const std::function<void(double)>& progress) {
  const std::uint64_t n = g.n();
  for (std::uint64_t p = 0; p < db.page_count(); ++p) {
    if (progress && p % 64 == 0) progress(0.8 * double(p) / double(db.page_count()));
    std::shared_ptr<const DecodedPage> ops;
    try {
      ops = db.page(p);
    } catch (const Error& e) {
      fault(e.what());
      continue;
    }
    ++rep.pages;
    db.clear_cache();  // keep memory flat: every page is read once
    for (std::uint32_t s = 0; s < ops->size(); ++s) {
      const OpView& op = (*ops)[s];
      const std::string name = std::string(table_name(Table::kPages)) + "/" + std::to_string(p) +
                               " op " + std::to_string(op.id.value);
      if (op.id.value >= n) {
        fault(name + ": id beyond the op count " + std::to_string(n));
        continue;
      }
      OpFacts& f = g.facts[op.id.value];
      if (f.seen++ != 0) fault(name + ": the op is stored twice");
      f.page = p;
      f.slot = s;
      f.birth_res = op.birth_res;
      f.box = op.box;
      f.roi = op.roi;
      f.subtree_cone = op.subtree_cone;
      f.killers.clear();
      for (const FragmentTriangle& t : op.fragment) f.killers.push_back(t.killer);
      ++rep.ops;
      rep.triangles += op.fragment.size();
      rep.links += op.coarser.size();
      for (OpId c : op.children) g.down.push_back({op.id.value, c.value});
      for (OpId q : op.parents) g.up.push_back({q.value, op.id.value});
      for (const TriRef& t : op.pre) g.pre.push_back({t, op.id});
      op.require_links();  // verify_database asked for them
      for (const CoarserLink& l : op.coarser) g.links.push_back({op.id, l.coarser});
      if (!contains(op.roi, op.box)) fault(name + ": its ROI does not contain its box");
      if (!cone_contains(op.subtree_cone, op_bounds(op).cone))
        fault(name + ": its subtree normal cone does not hold its own");
    }
  }
}

// Ids: birth_res does not decrease with the id, and every op was found in a page. Ops missing
// because their page could not be read were reported with the page: the checks skip them rather
// than report every consequence.
void check_ids(const Gathered& g, bool every_page, Faults& fault) {
  std::uint64_t unseen = 0, first_unseen = 0;
  std::optional<double> last_res;
  for (std::uint64_t i = 0; i < g.n(); ++i) {
    if (g.facts[i].seen == 0) {
      if (unseen++ == 0) first_unseen = i;
      continue;
    }
    if (last_res && g.facts[i].birth_res < *last_res)
      fault("op " + std::to_string(i) + ": birth_res decreases");
    last_res = g.facts[i].birth_res;
  }
  if (unseen > 0) {
    fault(std::to_string(unseen) + " ops (the first: op " + std::to_string(first_unseen) +
          ") are " + (every_page ? "in no page" : "in no readable page"));
  }
}

// Op locators: each must give the page and slot the op was found in (no page is decoded again).
void check_locators(const Database& db, const Gathered& g, Faults& fault) {
  for (std::uint64_t i = 0; i < g.n(); ++i) {
    const OpFacts& f = g.facts[i];
    if (f.seen == 0) continue;
    try {
      const auto [page, slot] = db.locator(OpId{i});
      if (page != f.page || slot != f.slot) {
        fault(std::string(table_name(Table::kOpLocators)) + "/" +
              std::to_string(i / kOpsPerLocatorBlock) + ": op " + std::to_string(i) +
              " is located at page " + std::to_string(page) + " slot " + std::to_string(slot) +
              ", it is in page " + std::to_string(f.page) + " slot " + std::to_string(f.slot));
      }
    } catch (const Error& e) {
      fault(e.what());
      i = (i / kOpsPerLocatorBlock + 1) * kOpsPerLocatorBlock - 1;  // one fault per block
    }
    if (i % 65536 == 0) db.clear_cache();
  }
}

// The DAG both ways: parents' and children's lists agree (sorts both), every edge goes from a
// smaller id to a larger one, and a parent's subtree normal cone holds its child's. Returns
// whether the edges are ordered so (the depth below needs it).
bool check_dag(Gathered& g, Faults& fault) {
  std::sort(g.down.begin(), g.down.end());
  std::sort(g.up.begin(), g.up.end());
  if (g.down != g.up) fault("DAG: parents and children lists disagree");
  for (const auto& [parent, child] : g.down) {
    if (parent >= child || child >= g.n()) {
      fault("DAG: op " + std::to_string(parent) + " has child " + std::to_string(child));
      return false;
    }
    if (!cone_contains(g.facts[parent].subtree_cone, g.facts[child].subtree_cone))
      fault("DAG: the subtree normal cone of op " + std::to_string(parent) +
            " does not hold its child " + std::to_string(child) + "'s");
  }
  return true;
}

// The DAG depth meta records (the longest parent chain), from the edges check_dag checked.
void check_dag_depth(const Database& db, Gathered& g, Faults& fault) {
  std::sort(g.down.begin(), g.down.end(),
            [](const auto& a, const auto& b) { return a.second < b.second; });
  std::vector<std::uint32_t> depth(g.n(), 0);
  std::uint32_t dag_depth = 0;
  for (const auto& [parent, child] : g.down) {
    depth[child] = std::max(depth[child], depth[parent] + 1);
    dag_depth = std::max(dag_depth, depth[child]);
  }
  const auto meta = nlohmann::json::parse(db.meta_json());
  const auto recorded = meta["counts"].find("dag_depth");
  if (recorded == meta["counts"].end() || *recorded != dag_depth)
    fault("meta: DAG depth " +
          (recorded == meta["counts"].end() ? std::string("missing") : recorded->dump()) +
          ", the DAG's is " + std::to_string(dag_depth));
}

// PreF against the killers: as many replaced triangles as PreF entries, each naming its op as
// killer; and every Hypermesh link names an existing triangle.
void check_pref_and_links(const Gathered& g, bool every_page, Faults& fault) {
  std::uint64_t killed = 0;
  for (const OpFacts& f : g.facts) {
    for (OpId k : f.killers) killed += k.valid();
  }
  if (every_page && killed != g.pre.size())
    fault("DAG: replaced triangles and PreF entries differ in number");
  for (const auto& [t, by] : g.pre) {
    if (t.op.value >= g.n() || t.index >= g.facts[t.op.value].killers.size() ||
        g.facts[t.op.value].killers[t.index] != by) {
      fault("op " + std::to_string(by.value) + ": its PreF triangle (" +
            std::to_string(t.op.value) + ", " + std::to_string(t.index) +
            ") does not name it as killer");
      break;
    }
  }
  for (const auto& [from, e] : g.links) {
    if (e.tri.op.value >= g.n() || e.tri.index >= g.facts[e.tri.op.value].killers.size()) {
      fault("op " + std::to_string(from.value) + ": a coarser link names a missing triangle");
      break;
    }
  }
}

// The R-tree: leaf i lists exactly the ops of page i, in their slots, with conservative boxes,
// ROIs and resolutions; a full query returns every op once.
void check_rtree(const Database& db, const Gathered& g, VerifyReport& rep, Faults& fault) {
  const std::uint64_t n = g.n();
  const index::RTree& tree = db.rtree();
  for (std::uint64_t leaf = 0; leaf < tree.leaf_count(); ++leaf) {
    std::vector<index::Entry> entries;
    try {
      entries = tree.leaf_entries(static_cast<std::uint32_t>(leaf));
    } catch (const Error& e) {
      fault(e.what());
      continue;
    }
    ++rep.rtree_nodes;
    for (std::uint32_t s = 0; s < entries.size(); ++s) {
      const index::Entry& e = entries[s];
      const std::string name = "rtree leaf " + std::to_string(leaf) + " entry " + std::to_string(s);
      if (e.id < n && g.facts[e.id].seen == 0) continue;  // its page was reported
      if (e.id >= n || g.facts[e.id].page != leaf || g.facts[e.id].slot != s) {
        fault(name + ": op " + std::to_string(e.id) + " is not in slot " + std::to_string(s) +
              " of page " + std::to_string(leaf));
        continue;
      }
      const OpFacts& f = g.facts[e.id];
      if (!contains(from_index(e.box), f.box) || !contains(from_index(e.roi), f.roi) ||
          e.res > f.birth_res)
        fault(name + ": box, ROI or resolution is not conservative for op " + std::to_string(e.id));
    }
    if (leaf % 4096 == 0) db.clear_cache();
  }
  try {
    struct All final : index::Visitor {
      bool enter(const index::Summary&) override { return true; }
      bool accept(const index::Entry&) override { return true; }
    } all;
    if (tree.query(all).size() != n) fault("rtree: a full query does not return every op once");
  } catch (const Error& e) {
    fault(e.what());
  }
}

}  // namespace

VerifyReport verify_database(const std::string& path, const std::function<void(double)>& progress) {
  VerifyReport rep;
  Faults fault(path, rep.faults);
  std::unique_ptr<Database> db;
  try {
    db = Database::open(path, {std::size_t{16} << 20});
  } catch (const Error& e) {
    fault(e.what());
    return rep;
  }
  db->need_links();  // the links are checked too (each names an existing coarser triangle)
  Gathered g(db->op_count());
  read_pages(*db, g, rep, fault, progress);
  const bool every_page = rep.pages == db->page_count();
  check_ids(g, every_page, fault);
  check_locators(*db, g, fault);
  if (progress) progress(0.85);
  // The DAG both ways, and PreF against the killers (only when every op was read).
  if (!every_page) {
    g.down.clear();
    g.up.clear();
    g.pre.clear();
    g.links.clear();
  }
  const bool ordered = check_dag(g, fault);
  if (every_page && ordered) check_dag_depth(*db, g, fault);
  check_pref_and_links(g, every_page, fault);
  if (progress) progress(0.9);
  check_rtree(*db, g, rep, fault);
  if (progress) progress(1.0);
  return rep;
}

}  // namespace smr
