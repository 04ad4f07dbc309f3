// Malformed R-tree nodes and headers must fail with smr::Error (kCorrupt) naming the node —
// never crash, hang or allocate without bound (run under ASan/UBSan). Covers checksum damage
// (bit flips, every truncation) and well-sealed but wrong content (wrong child ids, levels,
// counts, truncated or random payloads).
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "index/node_codec.h"
#include "index/rtree.h"
#include "index/visitors.h"
#include "storage/checksum.h"
#include "tests/index/index_test_util.h"

namespace smr::index {
namespace {

using test::build;
using test::MemoryStore;
using test::random_entries;

class All : public Visitor {
 public:
  bool enter(const Summary&) override { return true; }
  bool accept(const Entry&) override { return true; }
};

// Runs a full query; returns "" on success, else the error (kCorrupt expected).
std::string query_error(const MemoryStore& store) {
  try {
    const RTree tree = store.tree();
    All all;
    const auto hits = tree.query(all);
    for (std::uint32_t leaf = 0; leaf < tree.leaf_count(); ++leaf) tree.leaf_entries(leaf);
    EXPECT_EQ(hits.size(), tree.entry_count());
    return "";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kCorrupt) << e.what();
    return e.what();
  }
}

MemoryStore small_tree() {
  BuildOptions options;
  options.max_leaf_entries = 5;
  options.fanout = 3;
  return build(random_entries(60, 11), options).store;  // 12 leaves, 4 levels
}

Bytes payload_of(const Bytes& sealed) {
  const ByteView p = storage::unseal(sealed, "rtree", "test");
  return Bytes(p.begin(), p.end());
}

TEST(RTreeCorruption, IntactTreeReadsBack) {
  const MemoryStore store = small_tree();
  ASSERT_EQ(store.tree().height(), 4);
  EXPECT_EQ(query_error(store), "");
}

TEST(RTreeCorruption, EveryTruncationOfEveryNodeAndHeader) {
  const MemoryStore good = small_tree();
  for (const auto& [id, bytes] : good.nodes) {
    for (std::size_t len = 0; len < bytes.size(); ++len) {
      MemoryStore bad = good;
      bad.nodes[id].resize(len);
      const std::string err = query_error(bad);
      EXPECT_NE(err.find(std::to_string(id)), std::string::npos)
          << "node " << id << " len " << len << ": " << err;
    }
  }
  for (std::size_t len = 0; len < good.header.size(); ++len) {
    MemoryStore bad = good;
    bad.header.resize(len);
    EXPECT_NE(query_error(bad), "") << "header len " << len;
  }
}

TEST(RTreeCorruption, BitFlips) {
  const MemoryStore good = small_tree();
  for (const auto& [id, bytes] : good.nodes) {
    for (std::size_t bit = 0; bit < bytes.size() * 8; bit += 3) {
      MemoryStore bad = good;
      bad.nodes[id][bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
      EXPECT_NE(query_error(bad).find("rtree"), std::string::npos)
          << "node " << id << " bit " << bit;
    }
  }
  for (std::size_t bit = 0; bit < good.header.size() * 8; ++bit) {
    MemoryStore bad = good;
    bad.header[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
    EXPECT_NE(query_error(bad), "") << "header bit " << bit;
  }
}

// Re-seals a modified node so the checksum passes and the structural checks must catch it.
void reseal(MemoryStore& store, std::uint64_t id, const detail::Node& node) {
  Bytes payload;
  detail::encode_node(node, payload);
  store.nodes[id] = storage::seal(payload);
}

TEST(RTreeCorruption, WrongChildIdsLevelsAndCounts) {
  const MemoryStore good = small_tree();
  const RTree tree = good.tree();
  const std::uint64_t root = tree.node_count() - 1;
  const detail::Node root_node = detail::decode_node(payload_of(good.nodes.at(root)), "root");
  ASSERT_EQ(root_node.level, 3u);

  auto expect_corrupt = [&](const MemoryStore& bad, std::uint64_t id, const char* what) {
    const std::string err = query_error(bad);
    EXPECT_NE(err.find("rtree/" + std::to_string(id)), std::string::npos) << what << ": " << err;
  };
  {  // children pointing at the root itself (a cycle), at leaves, beyond the end, or wrapping
    for (std::uint64_t first : {root, std::uint64_t{0}, root + 5, ~std::uint64_t{0} - 1}) {
      MemoryStore bad = good;
      detail::Node n = root_node;
      n.first_child = first;
      reseal(bad, root, n);
      expect_corrupt(bad, root, "child ids");
    }
  }
  {  // a child range shifted by one inside the right level: counts then disagree
    MemoryStore bad = good;
    detail::Node n = root_node;
    n.items.pop_back();
    n.first_child += 1;
    reseal(bad, root, n);
    EXPECT_NE(query_error(bad), "");
  }
  {  // wrong level
    MemoryStore bad = good;
    detail::Node n = root_node;
    n.level = 2;
    reseal(bad, root, n);
    expect_corrupt(bad, root, "level");
  }
  {  // a child claiming more entries than it holds
    MemoryStore bad = good;
    detail::Node n = root_node;
    n.items[0].value += 1;
    reseal(bad, root, n);
    EXPECT_NE(query_error(bad), "");
  }
  {  // a leaf with an entry too many
    MemoryStore bad = good;
    detail::Node leaf = detail::decode_node(payload_of(good.nodes.at(3)), "leaf");
    leaf.items.push_back(leaf.items.front());
    reseal(bad, 3, leaf);
    expect_corrupt(bad, 3, "leaf count");
  }
  {  // a leaf stored where an internal node belongs
    MemoryStore bad = good;
    bad.nodes[root] = good.nodes.at(0);
    expect_corrupt(bad, root, "leaf as root");
  }
}

TEST(RTreeCorruption, ResealedTruncationsAndGarbage) {
  const MemoryStore good = small_tree();
  std::mt19937 rng(5);
  for (const auto& [id, bytes] : good.nodes) {
    const Bytes payload = payload_of(bytes);
    for (std::size_t len = 0; len < payload.size(); ++len) {
      MemoryStore bad = good;
      bad.nodes[id] = storage::seal(ByteView(payload.data(), len));
      EXPECT_NE(query_error(bad), "") << "node " << id << " payload len " << len;
    }
    // Random byte changes behind a valid checksum: any outcome but a crash is fine (a changed
    // coordinate can still be a valid box), yet errors must be kCorrupt (checked inside).
    for (int trial = 0; trial < 200; ++trial) {
      Bytes p = payload;
      p[rng() % p.size()] = static_cast<std::uint8_t>(rng());
      MemoryStore bad = good;
      bad.nodes[id] = storage::seal(p);
      query_error(bad);
    }
  }
  // A leaf claiming 2^40 entries must not allocate for them.
  Bytes huge;
  storage::ByteWriter w(huge);
  w.varint(0);
  w.varint(std::uint64_t{1} << 40);
  for (int i = 0; i < 6; ++i) w.f64(0);
  MemoryStore bad = good;
  bad.nodes[0] = storage::seal(huge);
  EXPECT_NE(query_error(bad).find("rtree/0"), std::string::npos);
}

TEST(RTreeCorruption, ResealedHeaders) {
  const MemoryStore good = small_tree();
  const Bytes payload = payload_of(good.header);
  for (std::size_t len = 0; len < payload.size(); ++len) {
    MemoryStore bad = good;
    bad.header = storage::seal(ByteView(payload.data(), len));
    EXPECT_NE(query_error(bad), "") << "header payload len " << len;
  }
  auto header = [](std::uint64_t entries, std::vector<std::uint64_t> levels) {
    Bytes h;
    storage::ByteWriter w(h);
    w.u32(0x54524D53);
    w.varint(1);
    w.varint(entries);
    w.varint(levels.size());
    for (std::uint64_t s : levels) w.varint(s);
    if (!levels.empty()) {
      for (int i = 0; i < 6; ++i) w.f64(0);
      for (int i = 0; i < 6; ++i) w.f64(0);
      w.f64(0);
    }
    return storage::seal(h);
  };
  MemoryStore bad = good;
  bad.header = header(60, {12, 4, 1});  // a level-2 node taken for the root: counts differ
  EXPECT_NE(query_error(bad), "");
  bad.header = header(60, {12, 4, 4, 1});  // not decreasing
  EXPECT_NE(query_error(bad), "");
  bad.header = header(60, {12, 4, 2});  // no single root
  EXPECT_NE(query_error(bad), "");
  bad.header = header(~std::uint64_t{0}, {~std::uint64_t{0}, ~std::uint64_t{0} - 1, 1});
  EXPECT_NE(query_error(bad), "");
  bad.header = header(0, {1});
  EXPECT_NE(query_error(bad), "");
  bad.header = header(5, std::vector<std::uint64_t>(100, 1));
  EXPECT_NE(query_error(bad), "");
}

TEST(RTreeCorruption, FetchErrorsPropagate) {
  MemoryStore store = small_tree();
  store.nodes.erase(2);
  try {
    All all;
    store.tree().query(all);
    ADD_FAILURE() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kIo);
  }
}

}  // namespace
}  // namespace smr::index
