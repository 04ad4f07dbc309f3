// `smrdb verify`: every value read, every checksum checked, every cross-reference followed.
#include <algorithm>
#include <map>
#include <optional>

#include <nlohmann/json.hpp>

#include "base/error.h"
#include "smr/db/database.h"
#include "smr/db/page.h"
#include "storage/checksum.h"

namespace smr {

namespace {

constexpr std::size_t kMaxFaults = 100;

struct OpFacts {
  std::uint64_t page = ~0ull;
  std::uint32_t slot = 0;
  double birth_res = 0.0;
  Box3 box, roi;
  NormalCone subtree_cone;
  std::vector<OpId> killers;  // per fragment triangle
  std::uint32_t seen = 0;
};

bool contains(const Box3& outer, const Box3& inner) {
  for (int k = 0; k < 3; ++k) {
    if (!(outer.lo[k] <= inner.lo[k] && inner.hi[k] <= outer.hi[k])) return false;
  }
  return true;
}

}  // namespace

VerifyReport verify_database(const std::string& path, const std::function<void(double)>& progress) {
  VerifyReport rep;
  auto fault = [&](const std::string& what) {  // every fault names the file
    if (rep.faults.size() >= kMaxFaults) return;
    rep.faults.push_back(what.rfind(path, 0) == 0 ? what : path + ": " + what);
  };
  std::unique_ptr<Database> db;
  try {
    db = Database::open(path, {std::size_t{16} << 20});
  } catch (const Error& e) {
    fault(e.what());
    return rep;
  }
  const std::uint64_t n = db->op_count();
  std::vector<OpFacts> facts(n);
  std::vector<std::pair<std::uint64_t, std::uint64_t>> down, up;  // (parent, child) both ways
  std::vector<std::pair<TriRef, OpId>> pre;                       // (triangle, op replacing it)
  std::vector<std::pair<OpId, EdgeRef>> links;
  for (std::uint64_t p = 0; p < db->page_count(); ++p) {
    if (progress && p % 64 == 0) progress(0.8 * double(p) / double(db->page_count()));
    std::shared_ptr<const std::vector<Op>> ops;
    try {
      ops = db->page(p);
    } catch (const Error& e) {
      fault(e.what());
      continue;
    }
    ++rep.pages;
    db->clear_cache();  // keep memory flat: every page is read once
    for (std::uint32_t s = 0; s < ops->size(); ++s) {
      const Op& op = (*ops)[s];
      const std::string name = "pages/" + std::to_string(p) + " op " + std::to_string(op.id.value);
      if (op.id.value >= n) {
        fault(name + ": id beyond the op count " + std::to_string(n));
        continue;
      }
      OpFacts& f = facts[op.id.value];
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
      for (OpId c : op.children) down.push_back({op.id.value, c.value});
      for (OpId q : op.parents) up.push_back({q.value, op.id.value});
      for (const TriRef& t : op.pre) pre.push_back({t, op.id});
      for (const CoarserLink& l : op.coarser) links.push_back({op.id, l.coarser});
      if (!contains(op.roi, op.box)) fault(name + ": its ROI does not contain its box");
      if (!cone_contains(op.subtree_cone, op.cone))
        fault(name + ": its subtree normal cone does not hold its own");
    }
  }
  // Ops missing because their page could not be read were reported with the page: the checks
  // below skip them rather than report every consequence.
  const bool every_page = rep.pages == db->page_count();
  std::uint64_t unseen = 0, first_unseen = 0;
  std::optional<double> last_res;
  for (std::uint64_t i = 0; i < n; ++i) {
    if (facts[i].seen == 0) {
      if (unseen++ == 0) first_unseen = i;
      continue;
    }
    if (last_res && facts[i].birth_res < *last_res)
      fault("op " + std::to_string(i) + ": birth_res decreases");
    last_res = facts[i].birth_res;
  }
  if (unseen > 0) {
    fault(std::to_string(unseen) + " ops (the first: op " + std::to_string(first_unseen) +
          ") are " + (every_page ? "in no page" : "in no readable page"));
  }
  // Locators: each must give the page and slot the op was found in (no page is decoded again).
  for (std::uint64_t i = 0; i < n; ++i) {
    if (facts[i].seen == 0) continue;
    try {
      const auto [page, slot] = db->locator(OpId{i});
      if (page != facts[i].page || slot != facts[i].slot) {
        fault("nodes/" + std::to_string(i / kOpsPerLocatorBlock) + ": op " + std::to_string(i) +
              " is located at page " + std::to_string(page) + " slot " + std::to_string(slot) +
              ", it is in page " + std::to_string(facts[i].page) + " slot " +
              std::to_string(facts[i].slot));
      }
    } catch (const Error& e) {
      fault(e.what());
      i = (i / kOpsPerLocatorBlock + 1) * kOpsPerLocatorBlock - 1;  // one fault per block
    }
    if (i % 65536 == 0) db->clear_cache();
  }
  if (progress) progress(0.85);
  // The DAG both ways, and PreF against the killers (only when every op was read).
  if (!every_page) {
    down.clear();
    up.clear();
    pre.clear();
    links.clear();
  }
  std::sort(down.begin(), down.end());
  std::sort(up.begin(), up.end());
  if (down != up) fault("DAG: parents and children lists disagree");
  bool ordered = true;
  for (const auto& [parent, child] : down) {
    if (parent >= child || child >= n) {
      fault("DAG: op " + std::to_string(parent) + " has child " + std::to_string(child));
      ordered = false;
      break;
    }
    if (!cone_contains(facts[parent].subtree_cone, facts[child].subtree_cone))
      fault("DAG: the subtree normal cone of op " + std::to_string(parent) +
            " does not hold its child " + std::to_string(child) + "'s");
  }
  // The DAG depth meta records (the longest parent chain), from the edges just checked.
  if (every_page && ordered) {
    std::sort(down.begin(), down.end(),
              [](const auto& a, const auto& b) { return a.second < b.second; });
    std::vector<std::uint32_t> depth(n, 0);
    std::uint32_t dag_depth = 0;
    for (const auto& [parent, child] : down) {
      depth[child] = std::max(depth[child], depth[parent] + 1);
      dag_depth = std::max(dag_depth, depth[child]);
    }
    const auto meta = nlohmann::json::parse(db->meta_json());
    const auto recorded = meta["counts"].find("dag_depth");
    if (recorded == meta["counts"].end() || *recorded != dag_depth)
      fault("meta: DAG depth " +
            (recorded == meta["counts"].end() ? std::string("missing") : recorded->dump()) +
            ", the DAG's is " + std::to_string(dag_depth));
  }
  std::uint64_t killed = 0;
  for (const OpFacts& f : facts) {
    for (OpId k : f.killers) killed += k.valid();
  }
  if (every_page && killed != pre.size())
    fault("DAG: replaced triangles and PreF entries differ in number");
  for (const auto& [t, by] : pre) {
    if (t.op.value >= n || t.index >= facts[t.op.value].killers.size() ||
        facts[t.op.value].killers[t.index] != by) {
      fault("op " + std::to_string(by.value) + ": its PreF triangle (" +
            std::to_string(t.op.value) + ", " + std::to_string(t.index) +
            ") does not name it as killer");
      break;
    }
  }
  for (const auto& [from, e] : links) {
    if (e.tri.op.value >= n || e.tri.index >= facts[e.tri.op.value].killers.size()) {
      fault("op " + std::to_string(from.value) + ": a coarser link names a missing triangle");
      break;
    }
  }
  if (progress) progress(0.9);
  // The R-tree: leaf i lists exactly the ops of page i, with conservative boxes.
  const index::RTree& tree = db->rtree();
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
      if (e.id < n && facts[e.id].seen == 0) continue;  // its page was reported
      if (e.id >= n || facts[e.id].page != leaf || facts[e.id].slot != s) {
        fault(name + ": op " + std::to_string(e.id) + " is not in slot " + std::to_string(s) +
              " of page " + std::to_string(leaf));
        continue;
      }
      const OpFacts& f = facts[e.id];
      Box3 box, roi;
      for (int k = 0; k < 3; ++k) {
        box.lo[k] = e.box.lo[k], box.hi[k] = e.box.hi[k];
        roi.lo[k] = e.roi.lo[k], roi.hi[k] = e.roi.hi[k];
      }
      if (!contains(box, f.box) || !contains(roi, f.roi) || e.res > f.birth_res)
        fault(name + ": box, ROI or resolution is not conservative for op " + std::to_string(e.id));
    }
    if (leaf % 4096 == 0) db->clear_cache();
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
  if (progress) progress(1.0);
  return rep;
}

}  // namespace smr
