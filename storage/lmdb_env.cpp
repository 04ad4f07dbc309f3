// The one place LMDB is used (docs/design.md section 3). Bulk loads use sorted keys with
// MDB_APPEND; every status code goes through one mapping to smr::Error.
#include "storage/lmdb_env.h"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <thread>
#include <utility>
#include <vector>

#include <fcntl.h>
#include <lmdb.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/error.h"

namespace smr::storage {
namespace {

constexpr unsigned kMaxDbs = kMaxTables;

[[noreturn]] void throw_mdb(int rc, const std::string& where) {
  const std::string message = where + ": " + mdb_strerror(rc);
  switch (rc) {
    case MDB_CORRUPTED:
    case MDB_INVALID:
    case MDB_PAGE_NOTFOUND:
    case MDB_VERSION_MISMATCH:
    case MDB_INCOMPATIBLE:
    case MDB_BAD_VALSIZE:
    case MDB_CURSOR_FULL:  // a tree deeper than LMDB's cursor stack: a damaged branch page
      throw_corrupt(message);
    default:
      if (rc > 0) throw_io(message);  // an errno value (LMDB's own codes are negative)
      throw_internal(message);
  }
}

void check(int rc, const std::string& where) {
  if (rc != MDB_SUCCESS) throw_mdb(rc, where);
}

MDB_val to_val(ByteView v) {
  return MDB_val{v.size(), const_cast<std::uint8_t*>(v.data())};
}

ByteView from_val(const MDB_val& v) {
  return {static_cast<const std::uint8_t*>(v.mv_data), v.mv_size};
}

std::string errno_text(int err) {
  return std::strerror(err);
}

// Built piecewise: GCC 12 reports a false -Wrestrict on "'" + std::string(...) + "'".
std::string quoted(std::string_view text) {
  std::string out;
  out.reserve(text.size() + 2);
  out.push_back('\'');
  out.append(text);
  out.push_back('\'');
  return out;
}

// ---------------------------------------------------------------------------------------------
// LMDB's file format, checked before LMDB trusts it
//
// LMDB 0.9 trusts the file it maps: a damaged meta page or B-tree page makes it divide by zero,
// read past the end of the mapping, or follow a null pointer (a leaf node flagged F_DUPDATA in a
// table without MDB_DUPSORT) — a crash, not an error. Database files never change, so every page
// LMDB is about to read is checked here once, the first time: the meta pages and the table of
// tables (LMDB's main table, which names the others) when the file is opened, the pages on the way
// to a key before each get, every page of a table before a cursor walks it. LMDB then reads only
// checked pages, and what it returns is compared with what the check found. Layout: mdb.c's
// MDB_meta, MDB_page, MDB_node and MDB_db of 64-bit builds, little-endian.

static_assert(sizeof(void*) == 8 && sizeof(std::size_t) == 8, "LMDB layout of 64-bit builds");
static_assert(MDB_VERSION_MAJOR == 0 && MDB_VERSION_MINOR == 9, "LMDB 0.9 file format");

constexpr std::uint16_t kBranchPage = 0x01, kLeafPage = 0x02, kOverflowPage = 0x04;  // P_*
constexpr std::uint16_t kMetaPage = 0x08;
constexpr std::uint16_t kBigData = 0x01, kSubData = 0x02;  // F_BIGDATA, F_SUBDATA
constexpr std::size_t kPageHeader = 16, kNodeHeader = 8;   // PAGEHDRSZ, NODESIZE
constexpr std::size_t kDbRecord = 48;                      // sizeof(MDB_db)
constexpr std::size_t kDbFlags = 4, kDbDepth = 6, kDbRoot = 40;
constexpr std::uint64_t kNoPage = ~std::uint64_t{0};  // P_INVALID: an empty tree
constexpr std::uint64_t kMaxDepth = 32;               // CURSOR_STACK
constexpr std::uint64_t kMinPageSize = 512, kMaxPageSize = 65536;
constexpr std::uint32_t kMagic = 0xBEEFC0DE, kDataVersion = 1;
// In a meta page: MDB_meta after the page header; the free table's md_pad is the page size.
constexpr std::size_t kMetaMagic = 16, kMetaVersion = 20, kMetaPageSize = 40;
constexpr std::size_t kMetaMainDb = 88, kMetaLastPgno = 136, kMetaTxnId = 144, kMetaBytes = 152;

std::uint64_t read_le(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = bytes - 1; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
std::uint16_t u16(const std::uint8_t* p) {
  return static_cast<std::uint16_t>(read_le(p, 2));
}

// LMDB's default key order (mdb_cmp_memn): bytewise, a prefix first.
int compare_keys(ByteView a, ByteView b) {
  const std::size_t common = std::min(a.size(), b.size());
  const int c = common == 0 ? 0 : std::memcmp(a.data(), b.data(), common);
  if (c != 0 || a.size() == b.size()) return c;
  return a.size() < b.size() ? -1 : 1;
}

// One node of a checked page.
struct Node {
  ByteView key;
  std::uint16_t flags = 0;
  std::uint64_t size = 0;   // leaf: the value's size
  std::uint64_t child = 0;  // branch: the child page
  const std::uint8_t* data = nullptr;
};

std::size_t node_count(const std::uint8_t* page) {
  return (u16(page + 12) - kPageHeader) / 2;
}

Node node_at(const std::uint8_t* page, std::size_t i) {
  const std::uint8_t* n = page + u16(page + kPageHeader + 2 * i);
  Node node;
  node.key = ByteView(n + kNodeHeader, u16(n + 6));
  node.flags = u16(n + 4);
  node.size = read_le(n, 4);   // mn_lo | mn_hi << 16
  node.child = read_le(n, 6);  // mn_lo | mn_hi << 16 | mn_flags << 32
  node.data = n + kNodeHeader + node.key.size();
  return node;
}

bool is_branch(const std::uint8_t* page) {
  return u16(page + 10) == kBranchPage;
}

// LMDB's way down a branch page (mdb_page_search_root): the last child whose key, from the
// second on, is not greater than `key`.
std::size_t child_index(const std::uint8_t* page, ByteView key) {
  std::size_t lo = 1, hi = node_count(page);  // the answer is in [lo - 1, hi - 1]
  while (lo < hi) {
    const std::size_t mid = (lo + hi) / 2;
    if (compare_keys(node_at(page, mid).key, key) <= 0) {
      lo = mid + 1;
    } else {
      hi = mid;
    }
  }
  return lo - 1;
}

// Page `pgno` of a file of `pages` pages of `page_size` bytes as a B-tree page LMDB may read:
// flags, bounds, every node inside the page, values inside the file, child pages that exist,
// keys in order and inside the range [lo, hi) its parent gives it (nullptr: open). `tables`:
// the table of tables, whose records must be MDB_db records. Returns what is wrong, or "".
std::string check_tree_page(const std::uint8_t* page, std::uint64_t pgno, std::uint64_t page_size,
                            std::uint64_t pages, bool tables, const ByteView* lo,
                            const ByteView* hi) {
  if (read_le(page, 8) != pgno) return "it says it is page " + std::to_string(read_le(page, 8));
  const std::uint16_t flags = u16(page + 10);
  if (flags != kBranchPage && flags != kLeafPage) {
    return "flags " + std::to_string(flags) + ", not a branch or leaf page";
  }
  const bool branch = flags == kBranchPage;
  const std::size_t lower = u16(page + 12), upper = u16(page + 14);
  if (lower < kPageHeader || (lower - kPageHeader) % 2 != 0 || lower > upper || upper > page_size) {
    return "free space from " + std::to_string(lower) + " to " + std::to_string(upper);
  }
  const std::size_t n = node_count(page);
  if (n < (branch ? 2u : 1u)) return std::to_string(n) + " nodes";
  ByteView previous;
  for (std::size_t i = 0; i < n; ++i) {
    auto bad = [i](const std::string& what) { return "node " + std::to_string(i) + what; };
    const std::size_t at = u16(page + kPageHeader + 2 * i);
    if (at < upper || at % 2 != 0 || at + kNodeHeader > page_size) {
      return bad(" at offset " + std::to_string(at));
    }
    const Node node = node_at(page, i);
    const std::size_t data_at = at + kNodeHeader + node.key.size();
    if (data_at > page_size) return bad(": a key of " + std::to_string(node.key.size()) + " bytes");
    if (branch) {
      if (node.child < 2 || node.child >= pages || node.child == pgno) {
        return bad(": child page " + std::to_string(node.child));
      }
      if (i == 0) continue;  // LMDB never reads the first key of a branch page
    } else if (node.flags == kBigData) {
      if (data_at + 8 > page_size) return bad(": no room for its overflow page number");
      const std::uint64_t first = read_le(node.data, 8);
      if (first < 2 || first >= pages || node.size > (pages - first) * page_size - kPageHeader) {
        return bad(": a value of " + std::to_string(node.size) + " bytes at page " +
                   std::to_string(first));
      }
    } else if (node.flags == kSubData && tables) {
      if (node.size != kDbRecord || data_at + kDbRecord > page_size) {
        return bad(": a table record of " + std::to_string(node.size) + " bytes");
      }
    } else if (node.flags != 0 || data_at + node.size > page_size) {
      return bad(": flags " + std::to_string(node.flags) + ", a value of " +
                 std::to_string(node.size) + " bytes");
    }
    if ((lo != nullptr && compare_keys(node.key, *lo) < 0) ||
        (hi != nullptr && compare_keys(node.key, *hi) >= 0)) {
      return bad(": its key is outside the range of the parent page");
    }
    if (i > (branch ? 1u : 0u) && compare_keys(previous, node.key) >= 0) {
      return bad(": keys out of order");
    }
    previous = node.key;
  }
  return {};
}

// A meta page as mdb_env_open reads it.
struct MetaPage {
  bool valid = false;  // flagged P_META, with LMDB's magic and data version
  std::uint64_t page_size = 0, last_pgno = 0, txnid = 0;
  std::uint8_t main[kDbRecord] = {};  // the MDB_db record of the table of tables
};

MetaPage read_meta(int fd, std::uint64_t offset) {
  std::uint8_t b[kMetaBytes];
  MetaPage m;
  if (::pread(fd, b, sizeof b, static_cast<off_t>(offset)) != static_cast<ssize_t>(sizeof b)) {
    return m;
  }
  m.valid = (u16(b + 10) & kMetaPage) != 0 && read_le(b + kMetaMagic, 4) == kMagic &&
            read_le(b + kMetaVersion, 4) == kDataVersion;
  m.page_size = read_le(b + kMetaPageSize, 4);
  m.last_pgno = read_le(b + kMetaLastPgno, 8);
  m.txnid = read_le(b + kMetaTxnId, 8);
  std::memcpy(m.main, b + kMetaMainDb, kDbRecord);
  return m;
}

bool good_page_size(std::uint64_t size) {
  return size >= kMinPageSize && size <= kMaxPageSize && (size & (size - 1)) == 0;
}

// The root page and depth of a tree, from its MDB_db record.
struct Tree {
  std::uint64_t root = kNoPage;
  std::uint64_t depth = 0;
};

std::string check_tree_record(const std::uint8_t* db, std::uint64_t pages, Tree& tree) {
  tree.root = read_le(db + kDbRoot, 8);
  tree.depth = u16(db + kDbDepth);
  if (u16(db + kDbFlags) != 0) {
    // The tables DatabaseWriter makes are plain ones: with MDB_DUPSORT, MDB_INTEGERKEY... LMDB
    // would read the pages another way.
    return "flags " + std::to_string(u16(db + kDbFlags));
  }
  if (tree.root == kNoPage
          ? tree.depth != 0
          : tree.root < 2 || tree.root >= pages || tree.depth < 1 || tree.depth > kMaxDepth) {
    return "root page " + std::to_string(tree.root) + ", depth " + std::to_string(tree.depth);
  }
  return {};
}

// What mdb_env_open will trust, read as it reads it: meta page 0 at offset 0, meta page 1 at
// meta 0's page size, the newer one (meta 0 on a tie) giving the page size, the last page and
// the table of tables; then that table's root page, which mdb_dbi_open reads. A file LMDB itself
// rejects (no meta page, a wrong magic or version) is left to it: page_size stays 0.
struct OpenCheck {
  std::uint64_t page_size = 0, pages = 0;  // pages: last page + 1
  std::uint64_t main_root = kNoPage;
  std::vector<std::uint8_t> main_page;  // the table of tables (a leaf), when not empty
  std::vector<Tree> trees;              // per Table
};

// The caller's table names, checked: at most kMaxTables, no two alike.
std::vector<std::string> table_names(std::span<const std::string_view> tables,
                                     const std::string& path) {
  if (tables.size() > kMaxTables) {
    throw_internal(path + ": " + std::to_string(tables.size()) + " tables, LMDB is set up for " +
                   std::to_string(kMaxTables));
  }
  std::vector<std::string> names(tables.begin(), tables.end());
  for (std::size_t a = 0; a < names.size(); ++a) {
    for (std::size_t b = a + 1; b < names.size(); ++b) {
      if (names[a] == names[b]) throw_internal(path + ": table '" + names[a] + "' named twice");
    }
  }
  return names;
}

// The index of `table` in a list of `count` tables; kInternal when out of range.
std::size_t index_of(Table table, std::size_t count, const std::string& path) {
  if (table.index() >= count) {
    throw_internal(path + ": table " + std::to_string(table.index()) + " of " +
                   std::to_string(count));
  }
  return table.index();
}

OpenCheck check_before_open(const std::string& path, std::uint64_t file_bytes,
                            const std::vector<std::string>& tables) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw_io(path + ": cannot open database: " + errno_text(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  OpenCheck out;
  out.trees.resize(tables.size());
  const MetaPage m0 = read_meta(fd, 0);
  if (!m0.valid) return out;
  if (!good_page_size(m0.page_size)) {
    throw_corrupt(path + ": damaged LMDB meta page 0: page size " + std::to_string(m0.page_size));
  }
  const MetaPage m1 = read_meta(fd, m0.page_size);
  if (!m1.valid) return out;
  const MetaPage& m = m1.txnid > m0.txnid ? m1 : m0;
  const std::string meta = path + ": damaged LMDB meta page " + (&m == &m1 ? "1" : "0");
  if (m1.page_size != m0.page_size) {
    throw_corrupt(path + ": damaged LMDB meta page: pages 0 and 1 disagree on the page size (" +
                  std::to_string(m0.page_size) + ", " + std::to_string(m1.page_size) + ")");
  }
  if (m.last_pgno >= file_bytes / m.page_size) {
    throw_corrupt(path + ": truncated database or damaged LMDB meta page: " +
                  std::to_string(file_bytes) + " bytes, the meta page names page " +
                  std::to_string(m.last_pgno) + " of " + std::to_string(m.page_size) + " bytes");
  }
  out.page_size = m.page_size;
  out.pages = m.last_pgno + 1;
  Tree main;
  if (const std::string bad = check_tree_record(m.main, out.pages, main); !bad.empty()) {
    throw_corrupt(meta + ": the table of tables has " + bad);
  }
  out.main_root = main.root;
  if (main.root == kNoPage) return out;  // no tables: mdb_dbi_open reports the first missing one
  const std::string page =
      path + ": damaged LMDB page " + std::to_string(main.root) + " (the table of tables)";
  out.main_page.resize(out.page_size);
  if (::pread(fd, out.main_page.data(), out.page_size,
              static_cast<off_t>(main.root * out.page_size)) !=
      static_cast<ssize_t>(out.page_size)) {
    throw_io(path + ": cannot read page " + std::to_string(main.root) + ": " + errno_text(errno));
  }
  const std::uint8_t* p = out.main_page.data();
  if (const std::string bad =
          check_tree_page(p, main.root, out.page_size, out.pages, true, nullptr, nullptr);
      !bad.empty()) {
    throw_corrupt(page + ": " + bad);
  }
  if (is_branch(p) || main.depth != 1) {
    throw_corrupt(page + ": more than one page, not an smrdb database");
  }
  for (std::size_t i = 0; i < node_count(p); ++i) {
    const Node node = node_at(p, i);
    for (std::size_t t = 0; t < tables.size(); ++t) {
      const std::string& name = tables[t];
      if (node.flags != kSubData || node.key.size() != name.size() ||
          std::memcmp(node.key.data(), name.data(), name.size()) != 0) {
        continue;
      }
      if (const std::string bad = check_tree_record(node.data, out.pages, out.trees[t]);
          !bad.empty()) {
        throw_corrupt(page + ": table '" + name + "' has " + bad);
      }
    }
  }
  for (std::size_t a = 0; a < tables.size(); ++a) {
    for (std::size_t b = a + 1; b < tables.size(); ++b) {
      if (out.trees[a].root != kNoPage && out.trees[a].root == out.trees[b].root) {
        throw_corrupt(page + ": tables '" + tables[a] + "' and '" + tables[b] +
                      "' have the same root page");
      }
    }
  }
  return out;
}

}  // namespace

namespace detail {

struct EnvState {
  std::string path;
  std::vector<std::string> tables;  // the names, by Table index
  MDB_env* env = nullptr;
  std::vector<MDB_dbi> dbis;  // per Table
  std::uint64_t file_bytes = 0;
  mutable std::atomic<std::uint64_t> bytes_read{0};
  // The file as LMDB mapped it, and what has been checked of it.
  const std::uint8_t* map = nullptr;  // page 0; the mapping is file_bytes long
  std::uint64_t page_size = 0, pages = 0;
  std::vector<Tree> trees;  // per Table
  // Per page: 0 until it passed check_page, then 1 + the table whose tree holds it.
  std::unique_ptr<std::atomic<std::uint8_t>[]> owner;

  ~EnvState() {
    if (env != nullptr) mdb_env_close(env);
  }
  std::size_t index(Table table) const { return index_of(table, tables.size(), path); }
  MDB_dbi dbi(Table table) const { return dbis[index(table)]; }
  std::string where(Table table) const { return path + ", table '" + tables[index(table)] + "'"; }
  const std::uint8_t* page(std::uint64_t pgno) const { return map + pgno * page_size; }

  // Throws kCorrupt naming the table and page unless `pgno` is a sound page of `table`'s tree
  // (and of no other table's).
  void check_page(Table table, std::uint64_t pgno, const ByteView* lo, const ByteView* hi) const {
    const auto mine = static_cast<std::uint8_t>(index(table) + 1);
    const std::uint8_t seen = owner[pgno].load(std::memory_order_acquire);
    if (seen == mine) return;
    std::string bad = seen != 0
                          ? "it is a page of table '" + tables[seen - 1] + "'"
                          : check_tree_page(page(pgno), pgno, page_size, pages, false, lo, hi);
    if (!bad.empty()) {
      throw_corrupt(where(table) + ": damaged LMDB page " + std::to_string(pgno) + ": " + bad);
    }
    owner[pgno].store(mine, std::memory_order_release);
  }

  // Where LMDB's search for a key ends: the leaf page that would hold it, and the keys bounding
  // that page in its parent (for check_page). The bounds point into the mapped file.
  struct LeafAt {
    std::uint64_t pgno = kNoPage;
    ByteView lo, hi;
    bool has_lo = false, has_hi = false;
  };

  // Follows LMDB's search for `key` down `table`'s branch pages, checking each, to the leaf that
  // would hold it (not read); pgno kNoPage for an empty tree.
  LeafAt descend(Table table, ByteView key, const std::string& key_text) const {
    const Tree& tree = trees[index(table)];
    LeafAt at;
    if (tree.root == kNoPage) return at;
    at.pgno = tree.root;
    for (std::uint64_t depth = 1; depth < tree.depth; ++depth) {
      check_page(table, at.pgno, at.has_lo ? &at.lo : nullptr, at.has_hi ? &at.hi : nullptr);
      const std::uint8_t* p = page(at.pgno);
      if (!is_branch(p)) not_deep(table, key_text, at.pgno);
      const std::size_t i = child_index(p, key);
      if (i > 0) at.lo = node_at(p, i).key, at.has_lo = true;
      if (i + 1 < node_count(p)) at.hi = node_at(p, i + 1).key, at.has_hi = true;
      at.pgno = node_at(p, i).child;
    }
    return at;
  }

  // The key's node in the leaf `at` (descend's), checking the leaf, if there is one.
  std::optional<Node> find_in(Table table, const LeafAt& at, ByteView key,
                              const std::string& key_text) const {
    if (at.pgno == kNoPage) return std::nullopt;
    check_page(table, at.pgno, at.has_lo ? &at.lo : nullptr, at.has_hi ? &at.hi : nullptr);
    const std::uint8_t* p = page(at.pgno);
    if (is_branch(p)) not_deep(table, key_text, at.pgno);
    std::size_t a = 0, b = node_count(p);
    while (a < b) {
      const std::size_t mid = (a + b) / 2;
      const Node node = node_at(p, mid);
      const int c = compare_keys(node.key, key);
      if (c == 0) return node;
      if (c < 0) {
        a = mid + 1;
      } else {
        b = mid;
      }
    }
    return std::nullopt;
  }

  // Follows LMDB's search for `key` down `table`'s tree, checking each page on the way, and
  // returns the key's node, if there is one.
  std::optional<Node> find(Table table, ByteView key, const std::string& key_text) const {
    return find_in(table, descend(table, key, key_text), key, key_text);
  }

  [[noreturn]] void not_deep(Table table, const std::string& key_text, std::uint64_t pgno) const {
    throw_corrupt(where(table) + ", key " + key_text + ": damaged LMDB page " +
                  std::to_string(pgno) + ": the tree is not " +
                  std::to_string(trees[index(table)].depth) + " pages deep there");
  }

  // Checks every page of `table`'s tree (before a cursor walks it).
  void check_tree(Table table) const {
    const Tree& tree = trees[index(table)];
    if (tree.root != kNoPage) check_subtree(table, tree.root, 1, nullptr, nullptr);
  }
  void check_subtree(Table table, std::uint64_t pgno, std::uint64_t depth, const ByteView* lo,
                     const ByteView* hi) const {
    check_page(table, pgno, lo, hi);
    const std::uint8_t* p = page(pgno);
    if (is_branch(p) != (depth < trees[index(table)].depth)) {
      throw_corrupt(where(table) + ": damaged LMDB page " + std::to_string(pgno) +
                    ": the tree is not " + std::to_string(trees[index(table)].depth) +
                    " pages deep there");
    }
    if (!is_branch(p)) return;
    const std::size_t n = node_count(p);
    for (std::size_t i = 0; i < n; ++i) {
      const ByteView first = node_at(p, i).key;
      const ByteView next = i + 1 < n ? node_at(p, i + 1).key : ByteView();
      check_subtree(table, node_at(p, i).child, depth + 1, i > 0 ? &first : lo,
                    i + 1 < n ? &next : hi);
    }
  }

  // The value LMDB returned for `node` is the one the check found, and lies in the file; an
  // overflow value's first page says so. `what()` names the entry.
  template <class What>
  void check_value(const Node& node, const MDB_val& v, const What& what) const {
    const std::uint8_t* expected = node.data;
    if (node.flags == kBigData) {
      const std::uint64_t first = read_le(node.data, 8);
      const std::uint8_t* p = page(first);
      const std::uint64_t count = (kPageHeader - 1 + node.size) / page_size + 1;  // OVPAGES
      if (read_le(p, 8) != first || u16(p + 10) != kOverflowPage || read_le(p + 12, 4) != count) {
        throw_corrupt(what() + ": damaged LMDB overflow page " + std::to_string(first));
      }
      expected = p + kPageHeader;
    }
    if (v.mv_data != expected || v.mv_size != node.size) {
      throw_internal(what() + ": LMDB returned another value than its page holds");
    }
  }
};

}  // namespace detail

// ---------------------------------------------------------------------------------------------
// Env

Env::Env(std::unique_ptr<detail::EnvState> state) : state_(std::move(state)) {}
Env::Env(Env&&) noexcept = default;
Env& Env::operator=(Env&&) noexcept = default;
Env::~Env() = default;

namespace {

// Where LMDB mapped the file. mdb_env_info's me_mapaddr is not it (that is the address stored in
// the meta page, 0 unless MDB_FIXEDMAP) and LMDB has no call for it, so it is found from a key
// whose place in the file is known: the first key of the table of tables (node 0 of its root
// page, a checked leaf), which LMDB returns as a pointer into the mapping.
const std::uint8_t* find_mapping(MDB_txn* txn, const OpenCheck& c, const std::string& path) {
  MDB_dbi main = 0;
  check(mdb_dbi_open(txn, nullptr, 0, &main), path + ": the table of tables");
  MDB_cursor* cursor = nullptr;
  check(mdb_cursor_open(txn, main, &cursor), path + ": the table of tables");
  MDB_val k{}, v{};
  const int rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST);
  mdb_cursor_close(cursor);
  check(rc, path + ": the table of tables");
  const std::uint8_t* page = c.main_page.data();
  const std::uint64_t offset =
      c.main_root * c.page_size + u16(page + kPageHeader) + kNodeHeader;  // node 0's key
  const auto at = reinterpret_cast<std::uintptr_t>(k.mv_data);
  const auto os_page = static_cast<std::uintptr_t>(::sysconf(_SC_PAGESIZE));
  if (at < offset || (at - offset) % os_page != 0 || k.mv_size != node_at(page, 0).key.size() ||
      std::memcmp(k.mv_data, node_at(page, 0).key.data(), k.mv_size) != 0) {
    throw_internal(path + ": LMDB's mapping of the file is not where its first key says");
  }
  return reinterpret_cast<const std::uint8_t*>(at - offset);
}

}  // namespace

Env Env::open_read_only(const std::string& path, std::span<const std::string_view> tables) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    throw_io(path + ": cannot open database: " + errno_text(errno));
  }
  if (!S_ISREG(st.st_mode)) throw_input(path + ": not a regular file");
  if (st.st_size == 0) throw_corrupt(path + ": empty file, not an smrdb database");

  auto state = std::make_unique<detail::EnvState>();
  state->path = path;
  state->tables = table_names(tables, path);
  state->dbis.assign(state->tables.size(), 0);
  state->file_bytes = static_cast<std::uint64_t>(st.st_size);
  const OpenCheck checked = check_before_open(path, state->file_bytes, state->tables);
  check(mdb_env_create(&state->env), path + ": mdb_env_create");
  check(mdb_env_set_maxdbs(state->env, kMaxDbs), path + ": mdb_env_set_maxdbs");
  // Map exactly the file, whatever map size the meta page records (LMDB maps at least up to its
  // last page, checked to be in the file).
  if (checked.page_size != 0) {
    check(mdb_env_set_mapsize(state->env, state->file_bytes), path + ": mdb_env_set_mapsize");
  }
  const int rc =
      mdb_env_open(state->env, path.c_str(),
                   MDB_RDONLY | MDB_NOSUBDIR | MDB_NOTLS | MDB_NOLOCK | MDB_NORDAHEAD, 0);
  if (rc == MDB_INVALID || rc == MDB_VERSION_MISMATCH || rc == ENOENT || rc == EINVAL) {
    throw_corrupt(path + ": not an LMDB database (" + mdb_strerror(rc) + ")");
  }
  check(rc, path + ": cannot open database");

  // LMDB opened what was checked (it read the meta pages itself).
  MDB_envinfo info{};
  MDB_stat stat{};
  check(mdb_env_info(state->env, &info), path + ": mdb_env_info");
  check(mdb_env_stat(state->env, &stat), path + ": mdb_env_stat");
  if (checked.page_size == 0 || stat.ms_psize != checked.page_size ||
      info.me_last_pgno + 1 != checked.pages || info.me_mapsize != state->file_bytes) {
    throw_internal(path + ": LMDB opened another file than the one checked");
  }
  state->page_size = checked.page_size;
  state->pages = checked.pages;
  state->trees = checked.trees;
  state->owner = std::make_unique<std::atomic<std::uint8_t>[]>(state->pages);

  MDB_txn* txn = nullptr;
  check(mdb_txn_begin(state->env, nullptr, MDB_RDONLY, &txn), path + ": mdb_txn_begin");
  try {
    for (std::size_t t = 0; t < state->tables.size(); ++t) {
      const std::string& name = state->tables[t];
      const int open_rc = mdb_dbi_open(txn, name.c_str(), 0, &state->dbis[t]);
      if (open_rc == MDB_NOTFOUND) {
        throw_corrupt(path + ": missing table '" + name + "', not an smrdb database");
      }
      if (open_rc == MDB_INCOMPATIBLE) {
        throw_corrupt(path + ": '" + name + "' is not a table, not an smrdb database");
      }
      check(open_rc, state->where(Table(t)));
    }
    state->map = find_mapping(txn, checked, path);
  } catch (...) {
    mdb_txn_abort(txn);
    throw;
  }
  // Committing a read-only txn keeps the opened DBI handles for the environment.
  check(mdb_txn_commit(txn), path + ": mdb_txn_commit");
  return Env(std::move(state));
}

const std::string& Env::path() const {
  return state_->path;
}
std::uint64_t Env::file_bytes() const {
  return state_->file_bytes;
}
const std::string& Env::table_name(Table table) const {
  return state_->tables[state_->index(table)];
}
std::uint64_t Env::bytes_read() const {
  return state_->bytes_read.load();
}

ReadTxn Env::read() const {
  MDB_txn* txn = nullptr;
  check(mdb_txn_begin(state_->env, nullptr, MDB_RDONLY, &txn),
        state_->path + ": cannot begin a read transaction");
  return ReadTxn(state_.get(), txn);
}

void Env::release_mapped_pages() const {
  // Advisory: failure only means the pages stay resident.
  (void)::madvise(const_cast<std::uint8_t*>(state_->map), state_->file_bytes, MADV_DONTNEED);
}

// ---------------------------------------------------------------------------------------------
// ReadTxn

ReadTxn::ReadTxn(ReadTxn&& other) noexcept
    : env_(std::exchange(other.env_, nullptr)), txn_(std::exchange(other.txn_, nullptr)) {}

ReadTxn& ReadTxn::operator=(ReadTxn&& other) noexcept {
  if (this != &other) {
    if (txn_ != nullptr) mdb_txn_abort(static_cast<MDB_txn*>(txn_));
    env_ = std::exchange(other.env_, nullptr);
    txn_ = std::exchange(other.txn_, nullptr);
  }
  return *this;
}

ReadTxn::~ReadTxn() {
  if (txn_ != nullptr) mdb_txn_abort(static_cast<MDB_txn*>(txn_));
}

std::optional<ByteView> ReadTxn::get_bytes(Table table, ByteView key, const std::string& key_text,
                                           std::size_t head) const {
  const std::optional<Node> node = env_->find(table, key, key_text);  // checks LMDB's way there
  MDB_val k = to_val(key);
  MDB_val v{};
  const int rc = mdb_get(static_cast<MDB_txn*>(txn_), env_->dbi(table), &k, &v);
  if (rc == MDB_NOTFOUND && !node) return std::nullopt;
  if (rc != MDB_SUCCESS && rc != MDB_NOTFOUND) {
    throw_mdb(rc, env_->where(table) + ", key " + key_text);
  }
  if (!node) {
    throw_internal(env_->where(table) + ", key " + key_text +
                   ": LMDB found a key its pages do not hold");
  }
  if (rc == MDB_NOTFOUND) {
    throw_internal(env_->where(table) + ", key " + key_text + ": LMDB missed a key of its pages");
  }
  if (v.mv_size > 4096) {
    // The file is opened MDB_NORDAHEAD, so a value over several pages would be read a page per
    // fault, each waiting on the disk: asked for whole, its pages are read together.
    const auto start = reinterpret_cast<std::uintptr_t>(v.mv_data) & ~std::uintptr_t{4095};
    const auto end = reinterpret_cast<std::uintptr_t>(v.mv_data) + std::min(v.mv_size, head);
    (void)::madvise(reinterpret_cast<void*>(start), end - start, MADV_WILLNEED);  // advisory
  }
  env_->check_value(*node, v, [&] { return env_->where(table) + ", key " + key_text; });
  env_->bytes_read.fetch_add(v.mv_size, std::memory_order_relaxed);
  return from_val(v);
}

namespace {

// Finds the leaf of every key through the branch pages and asks for the leaves all at once:
// finding a key reads its leaf, and with the file opened MDB_NORDAHEAD each would otherwise wait on
// the disk after the one before. Returns the keys' leaves, in the keys' order.
std::vector<detail::EnvState::LeafAt> advise_leaves(const detail::EnvState& env, Table table,
                                                    std::span<const std::uint64_t> keys) {
  std::vector<detail::EnvState::LeafAt> at;
  at.reserve(keys.size());
  std::vector<std::uint64_t> leaves;
  leaves.reserve(keys.size());
  for (std::uint64_t key : keys) {
    at.push_back(env.descend(table, key_u64(key), std::to_string(key)));
    if (at.back().pgno != kNoPage) leaves.push_back(at.back().pgno);
  }
  std::sort(leaves.begin(), leaves.end());
  leaves.erase(std::unique(leaves.begin(), leaves.end()), leaves.end());
  for (std::uint64_t leaf : leaves) {
    (void)::madvise(const_cast<std::uint8_t*>(env.page(leaf)), env.page_size,
                    MADV_WILLNEED);  // advisory
  }
  return at;
}

}  // namespace

void ReadTxn::will_need_leaves(Table table, std::span<const std::uint64_t> keys) const {
  advise_leaves(*env_, table, keys);
}

void ReadTxn::will_need(Table table, std::span<const std::uint64_t> keys, std::size_t head) const {
  const std::vector<detail::EnvState::LeafAt> at = advise_leaves(*env_, table, keys);
  for (std::size_t i = 0; i < keys.size(); ++i) {
    const std::optional<Node> node =
        env_->find_in(table, at[i], key_u64(keys[i]), std::to_string(keys[i]));
    if (!node || node->flags != kBigData) continue;  // absent, or in the leaf page just read
    const std::uint64_t first = read_le(node->data, 8);
    const std::uint64_t count = (kPageHeader - 1 + node->size) / env_->page_size + 1;
    const std::uint64_t asked =
        head >= node->size ? count : (kPageHeader - 1 + head) / env_->page_size + 1;
    if (first + count > env_->pages) continue;  // get() will say why
    (void)::madvise(const_cast<std::uint8_t*>(env_->page(first)), asked * env_->page_size,
                    MADV_WILLNEED);  // advisory
  }
}

std::optional<ByteView> ReadTxn::get(Table table, std::uint64_t key, std::size_t head) const {
  const Bytes k = key_u64(key);
  return get_bytes(table, k, std::to_string(key), head);
}

std::optional<ByteView> ReadTxn::get(Table table, std::string_view key) const {
  return get_bytes(table, as_bytes(key), quoted(key), kWhole);
}

void ReadTxn::for_each(Table table,
                       const std::function<void(ByteView key, ByteView value)>& visit) const {
  env_->check_tree(table);  // every page the cursor will read
  MDB_cursor* cursor = nullptr;
  check(mdb_cursor_open(static_cast<MDB_txn*>(txn_), env_->dbi(table), &cursor),
        env_->where(table) + ": mdb_cursor_open");
  struct Closer {
    MDB_cursor* c;
    ~Closer() { mdb_cursor_close(c); }
  } closer{cursor};
  MDB_val k{}, v{};
  int rc = mdb_cursor_get(cursor, &k, &v, MDB_FIRST);
  while (rc == MDB_SUCCESS) {
    const std::optional<Node> node =
        env_->find(table, from_val(k), "the cursor visits");  // checked: finds the same node
    if (!node) throw_internal(env_->where(table) + ": the cursor reads a key its pages lack");
    env_->check_value(*node, v,
                      [&] { return env_->where(table) + ", an entry the cursor visits"; });
    visit(from_val(k), from_val(v));
    rc = mdb_cursor_get(cursor, &k, &v, MDB_NEXT);
  }
  if (rc != MDB_NOTFOUND) throw_mdb(rc, env_->where(table) + ": cursor");
}

std::uint64_t ReadTxn::count(Table table) const {
  MDB_stat st{};
  check(mdb_stat(static_cast<MDB_txn*>(txn_), env_->dbi(table), &st),
        env_->where(table) + ": mdb_stat");
  return st.ms_entries;
}

// ---------------------------------------------------------------------------------------------
// DatabaseWriter

namespace {

void remove_quietly(const std::string& path) {
  std::error_code ec;
  std::filesystem::remove(path, ec);
  std::filesystem::remove(path + "-lock", ec);
}

void fsync_path(const std::string& path, bool directory) {
  const int fd = ::open(path.c_str(), (directory ? O_RDONLY | O_DIRECTORY : O_RDONLY) | O_CLOEXEC);
  if (fd < 0) throw_io(path + ": cannot open for fsync: " + errno_text(errno));
  const int rc = ::fsync(fd);
  const int err = errno;
  ::close(fd);
  if (rc != 0) throw_io(path + ": fsync failed: " + errno_text(err));
}

std::string parent_dir(const std::string& path) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  return parent.empty() ? std::string(".") : parent.string();
}

}  // namespace

DatabaseWriter::DatabaseWriter(std::string path, std::span<const std::string_view> tables,
                               bool force, std::uint64_t batch_bytes,
                               std::uint64_t initial_map_bytes)
    : path_(std::move(path)),
      tables_(table_names(tables, path_)),
      batch_bytes_(batch_bytes == 0 ? 1 : batch_bytes),
      map_bytes_(initial_map_bytes < (1u << 16) ? (1u << 16) : initial_map_bytes) {
  std::error_code ec;
  if (std::filesystem::exists(path_, ec) && !force) {
    throw_input(path_ + ": exists; pass --force to replace it");
  }
  if (std::filesystem::is_directory(path_, ec)) throw_input(path_ + ": is a directory");
  tmp_path_ = path_ + ".tmp-" + std::to_string(::getpid());
  compact_path_ = tmp_path_ + ".compact";
  dbis_.assign(tables_.size(), 0);
  last_key_.assign(tables_.size(), std::nullopt);
  remove_quietly(tmp_path_);
  remove_quietly(compact_path_);

  MDB_env* env = nullptr;
  check(mdb_env_create(&env), tmp_path_ + ": mdb_env_create");
  env_ = env;
  try {
    check(mdb_env_set_maxdbs(env, kMaxDbs), tmp_path_ + ": mdb_env_set_maxdbs");
    check(mdb_env_set_mapsize(env, map_bytes_), tmp_path_ + ": mdb_env_set_mapsize");
    // Single writer, temporary file: no lock file, no syncs (finish() fsyncs the compact copy).
    check(mdb_env_open(env, tmp_path_.c_str(), MDB_NOSUBDIR | MDB_NOLOCK | MDB_NOSYNC, 0644),
          tmp_path_ + ": cannot create database");
    MDB_txn* txn = nullptr;
    check(mdb_txn_begin(env, nullptr, 0, &txn), tmp_path_ + ": mdb_txn_begin");
    for (std::size_t t = 0; t < tables_.size(); ++t) {  // in the caller's order
      const std::string& name = tables_[t];
      const int rc = mdb_dbi_open(txn, name.c_str(), MDB_CREATE, &dbis_[t]);
      if (rc != MDB_SUCCESS) {
        mdb_txn_abort(txn);
        throw_mdb(rc, tmp_path_ + ", table '" + name + "'");
      }
    }
    check(mdb_txn_commit(txn), tmp_path_ + ": mdb_txn_commit");
  } catch (...) {
    cleanup();
    throw;
  }
}

DatabaseWriter::~DatabaseWriter() {
  cleanup();
}

void DatabaseWriter::cleanup() noexcept {
  if (env_ != nullptr) {
    mdb_env_close(static_cast<MDB_env*>(env_));
    env_ = nullptr;
  }
  if (!tmp_path_.empty()) {
    remove_quietly(tmp_path_);
    remove_quietly(compact_path_);
  }
}

void DatabaseWriter::append(Table table, std::uint64_t key, ByteView value) {
  std::optional<std::uint64_t>& last = last_key_[index_of(table, tables_.size(), path_)];
  if (last && key <= *last) {
    throw_internal(path_ + ", table '" + table_name(table) + "': key " + std::to_string(key) +
                   " appended after key " + std::to_string(*last) +
                   " (keys must be strictly increasing)");
  }
  last = key;
  const Bytes k = key_u64(key);
  add(table, k, value, true);
}

const std::string& DatabaseWriter::table_name(Table table) const {
  return tables_[index_of(table, tables_.size(), path_)];
}

void DatabaseWriter::put(Table table, std::string_view key, ByteView value) {
  add(table, as_bytes(key), value, false);
}

void DatabaseWriter::add(Table table, ByteView key, ByteView value, bool append) {
  if (finished_ || env_ == nullptr) throw_internal(path_ + ": write after finish()");
  (void)index_of(table, tables_.size(), path_);
  if (key.empty() || key.size() > 511) {
    throw_internal(path_ + ", table '" + table_name(table) + "': key of " +
                   std::to_string(key.size()) + " bytes (LMDB keys are 1..511 bytes)");
  }
  Op op{table, append, arena_.size(), key.size(), 0, value.size()};
  arena_.insert(arena_.end(), key.begin(), key.end());
  op.value_offset = arena_.size();
  arena_.insert(arena_.end(), value.begin(), value.end());
  ops_.push_back(op);
  bytes_written_ += value.size();
  if (arena_.size() >= batch_bytes_) flush();
}

void DatabaseWriter::flush() {
  if (ops_.empty()) return;
  auto* env = static_cast<MDB_env*>(env_);
  for (;;) {
    MDB_txn* txn = nullptr;
    check(mdb_txn_begin(env, nullptr, 0, &txn), tmp_path_ + ": mdb_txn_begin");
    int rc = MDB_SUCCESS;
    const Op* failed = nullptr;
    for (const Op& op : ops_) {
      MDB_val k{op.key_size, arena_.data() + op.key_offset};
      MDB_val v{op.value_size, arena_.data() + op.value_offset};
      rc = mdb_put(txn, dbis_[op.table.index()], &k, &v, op.append ? MDB_APPEND : 0);
      if (rc != MDB_SUCCESS) {
        failed = &op;
        break;
      }
    }
    if (rc == MDB_SUCCESS) {
      rc = mdb_txn_commit(txn);  // frees the txn whatever the outcome
    } else {
      mdb_txn_abort(txn);
    }
    if (rc == MDB_SUCCESS) break;
    if (rc == MDB_MAP_FULL) {
      // Grow and redo the whole batch (the aborted txn left nothing behind).
      map_bytes_ *= 2;
      check(mdb_env_set_mapsize(env, map_bytes_), tmp_path_ + ": mdb_env_set_mapsize");
      continue;
    }
    std::string where = path_;
    if (failed != nullptr) {
      where += ", table '" + table_name(failed->table) + "', key ";
      const ByteView key(arena_.data() + failed->key_offset, failed->key_size);
      where +=
          failed->append
              ? std::to_string(parse_key_u64(key, where))
              : quoted(std::string_view(reinterpret_cast<const char*>(key.data()), key.size()));
    } else {
      where += ": commit";
    }
    throw_mdb(rc, where);
  }
  ++commits_;
  ops_.clear();
  arena_.clear();
  drop_mapped_pages();
}

// Each batch reads the path to each table's last page through LMDB's map (the pages it writes go
// out by pwrite): mapped pages count in the resident set, and one batch's path after another they
// would pile up with the file (tens of MiB for a GB database). So they are dropped after every
// commit: clean file pages, faulted back in from the page cache when read again. The map moves
// when it grows, so its place is found again then.
void DatabaseWriter::drop_mapped_pages() {
  if (map_found_bytes_ != map_bytes_) {
    map_ = mapping_of_written();
    map_found_bytes_ = map_bytes_;
  }
  if (map_ != nullptr) (void)::madvise(const_cast<std::uint8_t*>(map_), map_bytes_, MADV_DONTNEED);
}

const std::uint8_t* DatabaseWriter::mapping_of_written() const {
  // Advisory (only the trimming depends on it): any failure means no trimming.
  struct stat st {};
  if (::stat(tmp_path_.c_str(), &st) != 0) return nullptr;
  MDB_txn* txn = nullptr;
  if (mdb_txn_begin(static_cast<MDB_env*>(env_), nullptr, MDB_RDONLY, &txn) != MDB_SUCCESS)
    return nullptr;
  const std::uint8_t* map = nullptr;
  try {
    map = find_mapping(
        txn, check_before_open(tmp_path_, static_cast<std::uint64_t>(st.st_size), tables_),
        tmp_path_);
  } catch (const Error&) {
    map = nullptr;
  }
  mdb_txn_abort(txn);
  return map;
}

namespace {

// Small: the kernel maps the cached pages around each page faulted in (64 KiB: "fault-around"),
// and the copy reads the small tables' leaves a page here and there between the data pages'
// runs, so each page read may bring 16 in; 2 MiB held up to ~30 MiB of them.
constexpr std::size_t kTrimBytes = std::size_t{256} << 10;

// Moves everything read from `in` to `out` until end of file, dropping `map`'s pages every
// kTrimBytes moved. After a write error it keeps draining `in` (so the writer never blocks on a
// full pipe) and returns the error; 0 on success.
int pump_bytes(int in, int out, const std::uint8_t* map, std::size_t map_bytes) {
  std::vector<std::uint8_t> buffer(std::size_t{1} << 20);
  int error = 0;
  std::size_t since_trim = 0;
  for (;;) {
    const ssize_t got = ::read(in, buffer.data(), buffer.size());
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) return errno;
    if (got == 0) break;
    for (std::size_t done = 0; error == 0 && done < static_cast<std::size_t>(got);) {
      const ssize_t put = ::write(out, buffer.data() + done, static_cast<std::size_t>(got) - done);
      if (put < 0 && errno == EINTR) continue;
      if (put < 0) error = errno;
      if (put > 0) done += static_cast<std::size_t>(put);
    }
    since_trim += static_cast<std::size_t>(got);
    if (map != nullptr && since_trim >= kTrimBytes) {
      (void)::madvise(const_cast<std::uint8_t*>(map), map_bytes, MADV_DONTNEED);  // advisory
      since_trim = 0;
    }
  }
  return error;
}

// pump_bytes, then closes `in`: a writer still writing then fails (EPIPE) instead of blocking.
int pump(int in, int out, const std::uint8_t* map, std::size_t map_bytes) {
  const int rc = pump_bytes(in, out, map, map_bytes);
  ::close(in);
  return rc;
}

}  // namespace

int DatabaseWriter::copy_through_pump(void* env, int fd, const std::uint8_t* map) const {
  int ends[2];
  if (::pipe2(ends, O_CLOEXEC) != 0) return errno;
  int pumped = 0;
  std::thread mover([&] { pumped = pump(ends[0], fd, map, map_bytes_); });
  int rc = mdb_env_copyfd2(static_cast<MDB_env*>(env), ends[1], MDB_CP_COMPACT);
  ::close(ends[1]);  // the pump sees the end of the copy
  mover.join();
  if (rc == MDB_SUCCESS) rc = pumped;
  return rc;
}

void DatabaseWriter::finish() {
  if (finished_ || env_ == nullptr) throw_internal(path_ + ": finish() called twice");
  flush();
  auto* env = static_cast<MDB_env*>(env_);
  const int fd = ::open(compact_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw_io(compact_path_ + ": cannot create: " + errno_text(errno));
  // The compacting copy reads every page through LMDB's map, and mapped pages count in the
  // process's resident set: a 2.6 GB database would show as 2.6 GB of RSS. So the copy writes
  // into a pipe, and a pump moves the pipe's bytes to the file, dropping the map's pages (clean
  // file pages, faulted back in from the page cache if read again) every kTrimBytes it moves:
  // the copy cannot read further ahead than LMDB's two write buffers and the pipe, so the
  // mapped pages resident stay under kTrimBytes plus those (times the kernel's fault-around, at
  // worst) whatever the machine's load.
  int rc = copy_through_pump(env, fd, mapping_of_written());
  if (rc == MDB_SUCCESS && ::fsync(fd) != 0) rc = errno;
  if (::close(fd) != 0 && rc == MDB_SUCCESS) rc = errno;
  check(rc, compact_path_ + ": writing the compacted database");
  mdb_env_close(env);
  env_ = nullptr;
  if (::rename(compact_path_.c_str(), path_.c_str()) != 0) {
    throw_io(path_ + ": cannot rename " + compact_path_ + " over it: " + errno_text(errno));
  }
  finished_ = true;
  remove_quietly(tmp_path_);
  fsync_path(parent_dir(path_), true);
}

}  // namespace smr::storage
