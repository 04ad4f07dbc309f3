// Fuzz target for the data page decoder (smr/db/page.h, decode_page): damaged pages must give an
// error naming the page, never a crash, a hang or a wrong answer.
//
// Seeds are real pages: small databases built in a temporary directory from the real data
// ($SMRDB_DATA_DIR), with 1 KiB pages so that a sweep over every byte of a page stays short:
// jacksboro_fault_dem.npz's greedy TIN written with each codec (zstd, raw, Draco; write_database)
// and blobby_3cc.off ingested as a mesh (ingest, zstd). Each page value is read from the file's
// "pages" table through storage::Env and unsealed as smr::Database does, and every one must decode
// to exactly what Database::page returns (to_op, op for op). Five regression cases are made from
// R^0's page (regressions()). Then, for a sample of pages (R^0's, the largest, the smallest, then
// seeded others), every one of these inputs is decoded:
//   prefix    every truncated prefix of the page (each must be rejected);
//   byte      every single-byte change: at each position x^0x01, x^0x80, 0x00, 0xff and a seeded
//             random byte;
//   multi     seeded multi-byte mutations (random bytes, runs, insertions, deletions, copies);
//   header    each of the page header's counts (op count, the seven totals) off by one, zero or
//             huge, the page re-assembled;
//   records   the decompressed records changed at every byte (x^0x01, x^0x80, 0x00, 0xff) and
//             cut at every length, then seeded multi-byte changes, re-compressed: the zstd layer
//             no longer hides the record parser;
//   geometry  the decoded geometry changed (every face corner moved to the previous and next
//             vertex, every coordinate set to the int32 extremes and moved far), re-encoded with
//             the page's codec.
// Each input is also cut (cut_page, smr/query/level_cut.h) below 0.5 and below infinity: the cut
// must reject a truncated page, throw only kCorrupt errors naming the page, and, where decode_page
// accepts the input, equal the cut computed from the decoded ops.
// Each decode either gives a page that passes check_page (spans inside the page's block, every
// index in range, killers among the children, resolutions in [0, 1], boxes holding their corners,
// ROIs their boxes, ...) or throws smr::Error of kind kCorrupt whose message names the page
// ("<database>: pages/<n>"). Anything else fails: another exception type or kind, a message not
// naming the page, a truncated page that decodes, an inconsistent page, a crash or sanitizer
// report, or one decode running over 30 s (a hang). The smoke run goes on after a failure and
// lists every kind of failure at the end, with its first case (database, page, mutation), whose
// input it saves to ./page_fuzz-failure-<k>.page; a crash or hang prints the case and saves the
// input to ./page_fuzz-failure.page.
//
//   page_fuzz [--pages N]       smoke mode: N pages of each database (default 10 in a plain
//                               build, 6 under the sanitizers; or $SMRDB_FUZZ_PAGES);
//                               $SMRDB_FUZZ_SEED changes the sample and the random bytes
//   page_fuzz --corpus DIR      writes the seed pages to DIR (a libFuzzer corpus)
//   page_fuzz FILE...           decodes the given pages (each as a page of every database)
// Built with -DSMRDB_LIBFUZZER=ON (clang) it is a libFuzzer target: LLVMFuzzerTestOneInput decodes
// the input as a page of every database (their grids and models; $SMRDB_DATA_DIR must be set).
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <tuple>
#include <vector>

#include "base/error.h"
#include "smr/builders/terrain/greedy_tin.h"
#include "smr/core/clock.h"
#include "smr/core/crmr.h"
#include "smr/db/database.h"
#include "smr/db/page.h"
#include "smr/db/tables.h"
#include "smr/db/writer.h"
#include "smr/ingest/ingest.h"
#include "smr/io/dem_reader.h"
#include "storage/bytes.h"
#include "storage/checksum.h"
#include "storage/codec.h"
#include "storage/lmdb_env.h"
#include "tests/fuzz/fuzz_rng.h"
#include "tests/support/files.h"
#include "tests/support/sanitized.h"

#if defined(__SANITIZE_ADDRESS__)
#include <sanitizer/common_interface_defs.h>
#endif

namespace smr::fuzz {
namespace {

namespace fs = std::filesystem;
using storage::ByteReader;
using storage::Bytes;
using storage::ByteView;
using storage::ByteWriter;
using storage::CodecId;

// jacksboro at 10 m: 18 k ops in 2.8 k pages of 1 KiB (a few ops each; page_bytes is the payload),
// built in 1 s (5 s under the sanitizers).
constexpr double kTerrainError = 10.0;
constexpr std::uint32_t kPageBytes = 1024 - 16;
constexpr const char* kMesh = "blobby_3cc.off";
constexpr unsigned kCaseSeconds = 30;  // one decode over this is a hang

// ---------------------------------------------------------------------------------------------
// What is being decoded, for a failure, a crash or a hang.

struct Case {
  std::string page;         // "jacksboro-zstd.smrdb: pages/3"
  const char* kind = "";    // "byte", ...
  std::size_t at = 0;       // position or count
  std::uint64_t value = 0;  // the new value
  ByteView input;           // the bytes decoded
};
Case g_case;
bool g_watchdog = false;  // an alarm stops a decode that hangs (not under libFuzzer: its -timeout)

std::string describe(const Case& c) {
  char tail[96];
  std::snprintf(tail, sizeof tail, " [%zu bytes]: %s at %zu, value %#llx", c.input.size(), c.kind,
                c.at, static_cast<unsigned long long>(c.value));
  return c.page + tail;
}

// Writes the input to `path` with async-signal-safe calls only.
void save_input(const char* path) {
  const int fd = ::open(path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0) return;
  std::size_t done = 0;
  while (done < g_case.input.size()) {
    const ssize_t n = ::write(fd, g_case.input.data() + done, g_case.input.size() - done);
    if (n <= 0) break;
    done += static_cast<std::size_t>(n);
  }
  ::close(fd);
}

// The smoke mode goes on after a failure (CaseFailed ends the case) to report every kind of
// failure at once: the first case of each (by `why` without its numbers) and how many.
struct Failure {
  std::string key, why, first_case;
  std::size_t count = 0;
};
struct CaseFailed {};
bool g_keep_going = false;
std::vector<Failure> g_failures;
bool g_reported = false;  // the failure or crash at hand is printed

[[noreturn]] void fail(const std::string& why) {
  if (!g_keep_going) {
    std::fprintf(stderr,
                 "page fuzz: FAILURE: %s\n  case: %s\n  input saved to page_fuzz-failure.page\n",
                 why.c_str(), describe(g_case).c_str());
    save_input("page_fuzz-failure.page");
    g_reported = true;
    std::abort();
  }
  std::string k = why;
  std::erase_if(k, [](char c) { return (c >= '0' && c <= '9') || c == '.' || c == '-'; });
  auto it = std::find_if(g_failures.begin(), g_failures.end(),
                         [&](const Failure& f) { return f.key == k; });
  if (it == g_failures.end()) {
    const std::string file = "page_fuzz-failure-" + std::to_string(g_failures.size()) + ".page";
    save_input(file.c_str());
    std::fprintf(stderr, "page fuzz: FAILURE: %s\n  case: %s\n  input saved to %s\n", why.c_str(),
                 describe(g_case).c_str(), file.c_str());
    g_failures.push_back({k, why, describe(g_case) + " (" + file + ")", 0});
    it = g_failures.end() - 1;
  }
  ++it->count;
  throw CaseFailed{};
}

// ---------------------------------------------------------------------------------------------
// The independent check of a decoded page.

// The address range spans cover (empty spans lie nowhere).
struct Extent {
  std::uintptr_t lo = std::numeric_limits<std::uintptr_t>::max(), hi = 0;
  template <class T>
  void add(std::span<const T> s) {
    if (s.empty()) return;
    const auto b = reinterpret_cast<std::uintptr_t>(s.data());
    lo = std::min(lo, b);
    hi = std::max(hi, b + s.size_bytes());
  }
};

bool in_unit(double r) {
  return r >= 0.0 && r <= 1.0;  // false for NaN
}

bool holds(const Box3& b, const Vec3& p) {
  return b.lo.x <= p.x && p.x <= b.hi.x && b.lo.y <= p.y && p.y <= b.hi.y && b.lo.z <= p.z &&
         p.z <= b.hi.z;
}

// Corners in range and among the op's own vertices (`own`, sorted), in the op's box.
std::string check_corners(const OpView& op, const std::array<std::uint32_t, 3>& v,
                          const std::vector<std::uint32_t>& own) {
  for (std::uint32_t c : v) {
    if (c >= op.vertices.size()) return "a corner out of the vertex table";
    if (!std::binary_search(own.begin(), own.end(), c)) return "a corner the op does not list";
    if (!holds(op.box, op.vertices[c].p)) return "a corner outside the op's box";
  }
  return {};
}

bool has_directed_edge(const FragmentTriangle& t, std::uint32_t a, std::uint32_t b) {
  for (int k = 0; k < 3; ++k) {
    if (t.v[std::size_t(k)] == a && t.v[std::size_t((k + 1) % 3)] == b) return true;
  }
  return false;
}

// What decoded pages hold that no writer makes but the decoder cannot see as wrong from the page
// alone, or is not asked to refuse: counted for the summary, not failures.
struct Oddities {
  std::size_t repeated_corner = 0;   // a triangle with a corner twice
  std::size_t dies_before_born = 0;  // a triangle whose death_res is below its op's birth_res
};
Oddities g_odd;

std::string check_fragment(const OpView& op, const std::vector<std::uint32_t>& own) {
  std::vector<double> child_death(op.children.size(), -1.0);
  std::vector<std::array<std::int32_t, 3>> nbr;  // views carry none: derived as readers do
  fragment_neighbours(op.fragment, nbr);
  for (std::size_t i = 0; i < op.fragment.size(); ++i) {
    const FragmentTriangle& t = op.fragment[i];
    if (auto bad = check_corners(op, t.v, own); !bad.empty()) return "fragment: " + bad;
    if (t.v[0] == t.v[1] || t.v[1] == t.v[2] || t.v[0] == t.v[2]) ++g_odd.repeated_corner;
    if ((t.flags & ~FragmentTriangle::kVoid) != 0) return "a triangle with unknown flags";
    for (int k = 0; k < 3; ++k) {
      const std::int32_t n = nbr[i][std::size_t(k)];
      if (n == FragmentTriangle::kNoNeighbour) continue;
      if (n < 0 || std::size_t(n) >= op.fragment.size()) return "a neighbour out of the fragment";
      if (!has_directed_edge(op.fragment[std::size_t(n)], t.v[std::size_t((k + 1) % 3)],
                             t.v[std::size_t(k)]))
        return "a neighbour without the shared edge";
    }
    if (!in_unit(t.death_res)) return "a death_res out of [0, 1]";
    if (t.death_res < op.birth_res) ++g_odd.dies_before_born;
    if (!t.killer.valid()) {
      if (t.death_res != 1.0) return "a triangle never replaced with death_res below 1";
      continue;
    }
    const auto it = std::lower_bound(op.children.begin(), op.children.end(), t.killer);
    if (it == op.children.end() || *it != t.killer) return "a killer that is not a child";
    double& d = child_death[std::size_t(it - op.children.begin())];
    if (d >= 0.0 && d != t.death_res) return "one killer, two death resolutions";
    d = t.death_res;
  }
  return {};
}

std::string check_links(const OpView& op, const std::vector<std::uint32_t>& own) {
  if (!op.id.valid() || (!op.children.empty() && !op.children.back().valid()))
    return "the invalid id as the op's or a child's";
  for (std::size_t i = 0; i < op.children.size(); ++i) {
    if (op.children[i] <= (i == 0 ? op.id : op.children[i - 1]))
      return "children not increasing from the op";
  }
  for (std::size_t i = 0; i < op.parents.size(); ++i) {
    if (op.parents[i] >= (i + 1 == op.parents.size() ? op.id : op.parents[i + 1]))
      return "parents not increasing up to the op";
  }
  if (op.pre.size() != op.pre_tris.size()) return "PreF and its triangles differ in size";
  for (std::size_t i = 0; i < op.pre.size(); ++i) {
    if (!std::binary_search(op.parents.begin(), op.parents.end(), op.pre[i].op))
      return "a PreF triangle whose op is not a parent";
    if (auto bad = check_corners(op, op.pre_tris[i].v, own); !bad.empty()) return "PreF: " + bad;
    if ((op.pre_tris[i].flags & ~FragmentTriangle::kVoid) != 0)
      return "a PreF triangle with unknown flags";
  }
  for (const CoarserLink& l : op.coarser) {
    if (l.tri >= op.fragment.size()) return "a coarser link's triangle out of the fragment";
    if (l.edge > 2 || l.coarser.edge > 2) return "a coarser link's edge out of range";
  }
  return {};
}

std::string check_op(const OpView& op, const CrmrInfo& info) {
  if (!in_unit(op.birth_res)) return "birth_res out of [0, 1]";
  if (!(op.error >= 0.0 && op.error <= info.err0)) return "error out of [0, err0]";
  if (op.fragment.empty() && op.pre.empty()) return "no triangles";
  if (op.vertex_list.empty()) return "an empty vertex list";
  if (op.new_vertex_count > op.vertex_list.size()) return "more new vertices than vertices";
  std::vector<std::uint32_t> own(op.vertex_list.begin(), op.vertex_list.end());
  std::sort(own.begin(), own.end());
  if (own.back() >= op.vertices.size()) return "a listed vertex out of the vertex table";
  if (std::adjacent_find(own.begin(), own.end()) != own.end()) return "a vertex listed twice";
  if (auto bad = check_fragment(op, own); !bad.empty()) return bad;
  if (auto bad = check_links(op, own); !bad.empty()) return bad;
  if (op.box.empty() || !op.roi.contains(op.box)) return "an ROI that does not hold the box";
  if (!(op.sphere.radius >= 0.0) || !(op_bounds(op).cone.half_angle >= 0.0) ||
      !(op.subtree_cone.half_angle >= 0.0))
    return "a bad sphere or normal cone";
  return {};
}

// Empty when the page is one a reader can use, else what is wrong with it.
std::string check_page(const DecodedPage& page, const CrmrInfo& info) {
  if (page.size() == 0 || page.ops().size() != page.size()) return "a page without ops";
  const std::span<const Vertex> table = page[0].vertices;
  Extent e;
  e.add(page.ops());
  e.add(table);
  for (const OpView& op : page.ops()) {
    if (op.vertices.data() != table.data() || op.vertices.size() != table.size())
      return "ops over different vertex tables";
    e.add(op.vertex_list);
    e.add(op.fragment);
    e.add(op.pre);
    e.add(op.pre_tris);
    e.add(op.coarser);
    e.add(op.parents);
    e.add(op.children);
    if (auto bad = check_op(op, info); !bad.empty())
      return "op " + std::to_string(op.id.value) + ": " + bad;
  }
  // memory_bytes() counts the block and the DecodedPage itself.
  if (e.hi - e.lo > page.memory_bytes() - sizeof(DecodedPage))
    return "spans reach outside the page's block";
  for (const Vertex& v : table) {
    if (!std::isfinite(v.p.x) || !std::isfinite(v.p.y) || !std::isfinite(v.p.z))
      return "a vertex that is not finite";
  }
  return {};
}

// ---------------------------------------------------------------------------------------------
// Decoding one input.

struct Model {
  std::string name;  // the database's file name
  QuantGrid grid;
  CrmrInfo info;
};

struct Tally {
  std::size_t decodes = 0, decoded = 0, rejected = 0;
};

// Runs f(), a decoder of g_case's input, under the watchdog: true if it returned, false if it
// threw an smr::Error of kind kCorrupt naming the page; anything else fails.
template <class F>
bool accepted(const char* who, F&& f) {
  if (g_watchdog) ::alarm(kCaseSeconds);
  try {
    f();
  } catch (const Error& e) {
    if (g_watchdog) ::alarm(0);
    if (e.kind() != ErrorKind::kCorrupt)
      fail(std::string(who) + ": an smr::Error of kind " + std::to_string(int(e.kind())) +
           ", not kCorrupt: " + e.what());
    if (std::string_view(e.what()).find(g_case.page) == std::string_view::npos)
      fail(std::string(who) + ": an error that does not name the page: " + e.what());
    return false;
  } catch (const std::exception& e) {
    fail(std::string(who) + ": a non-smr exception: " + e.what());
  } catch (...) {
    fail(std::string(who) + ": an exception of unknown type");
  }
  if (g_watchdog) ::alarm(0);
  return true;
}

// What the cut of `page` below `below` must be (level_cut.h, cut_page), from the decoded ops:
// every triangle of an op in X whose killer is not, as its corners' positions and its death_res;
// nullopt if the page has a void triangle.
using CutTriangle = std::tuple<Vec3, Vec3, Vec3, float>;
std::optional<std::vector<CutTriangle>> expected_cut(const DecodedPage& page, double below) {
  std::vector<CutTriangle> out;
  for (const OpView& op : page.ops()) {
    for (const auto& t : op.pre_tris)
      if (t.is_void()) return std::nullopt;
    for (const FragmentTriangle& t : op.fragment) {
      if (t.is_void()) return std::nullopt;
      const bool in_x = op.id == kBaseOp || op.birth_res < below;
      if (in_x && (!t.killer.valid() || !(t.death_res < below)))
        out.emplace_back(op.position(t, 0), op.position(t, 1), op.position(t, 2),
                         float(t.death_res));
    }
  }
  return out;
}

// Cuts `bytes` (cut_page) at two levels: an smr::Error must be kCorrupt and name the page; a
// truncated page must be rejected; when `page` (decode_page's answer) is given, the cut must be
// its expected_cut. The cut reads fewer streams than decode_page, so it may accept a page whose
// damage lies in the others.
void cut(ByteView bytes, const Model& model, const DecodedPage* page) {
  for (double below : {std::numeric_limits<double>::infinity(), 0.5}) {
    PageCut c;
    bool whole = false;
    if (!accepted("cut_page", [&] { whole = cut_page(bytes, model.grid, below, c, g_case.page); }))
      continue;
    if (std::strcmp(g_case.kind, "prefix") == 0) fail("cut_page accepted a truncated page");
    for (const auto& t : c.triangles) {
      for (std::uint32_t v : t)
        if (v >= c.positions.size()) fail("cut_page: a corner out of its vertices");
    }
    if (c.values.size() != c.triangles.size() || c.vertex_ids.size() != c.positions.size())
      fail("cut_page: arrays of different lengths");
    if (page == nullptr) continue;
    const auto want = expected_cut(*page, below);
    if (whole != want.has_value()) fail("cut_page and decode_page disagree on void triangles");
    if (!whole) continue;
    std::vector<CutTriangle> got;
    for (std::size_t i = 0; i < c.triangles.size(); ++i) {
      const auto& t = c.triangles[i];
      got.emplace_back(c.positions[t[0]], c.positions[t[1]], c.positions[t[2]], c.values[i]);
    }
    if (got != *want) fail("cut_page differs from the cut of decode_page's ops");
  }
}

// Decodes `bytes` as a page of `model`: an smr::Error must be kCorrupt and name the page; a page
// must pass check_page. Returns the page, or nullptr when rejected.
std::shared_ptr<const DecodedPage> decode_page_checked(ByteView bytes, const Model& model,
                                                       Tally& tally) {
  g_case.input = bytes;
  ++tally.decodes;
  std::shared_ptr<const DecodedPage> page;
  if (!accepted("decode_page",
                [&] { page = decode_page(bytes, model.grid, model.info, g_case.page); })) {
    ++tally.rejected;
    return nullptr;
  }
  if (auto bad = check_page(*page, model.info); !bad.empty()) fail("an inconsistent page: " + bad);
  ++tally.decoded;
  return page;
}

// Empty when `lean` (decoded without links) is `full` but for the links, else what differs.
std::string same_but_links(const DecodedPage& full, const DecodedPage& lean) {
  if (full.size() != lean.size()) return "op counts";
  const auto same = [](auto a, auto b) { return std::ranges::equal(a, b); };
  for (std::size_t i = 0; i < full.size(); ++i) {
    const OpView& f = full[i];
    const OpView& l = lean[i];
    if (!f.links || l.links || !l.coarser.empty()) return "the links flag";
    if (f.id != l.id || f.birth_res != l.birth_res || f.error != l.error ||
        f.new_vertex_count != l.new_vertex_count || !same(f.vertices, l.vertices) ||
        !same(f.vertex_list, l.vertex_list) || !same(f.fragment, l.fragment) ||
        !same(f.pre, l.pre) || !same(f.pre_tris, l.pre_tris) || !same(f.parents, l.parents) ||
        !same(f.children, l.children) || f.box != l.box || f.sphere != l.sphere || f.roi != l.roi ||
        !(f.subtree_cone == l.subtree_cone))
      return "op " + std::to_string(i);
  }
  if (lean.memory_bytes() >= full.memory_bytes() && full.size() > 0 &&
      std::ranges::any_of(full.ops(), [](const OpView& o) { return !o.coarser.empty(); }))
    return "memory: the page without links is not smaller";
  return {};
}

// Decodes `bytes` as a page of `model`: an smr::Error must be kCorrupt and name the page; a page
// must pass check_page. Returns the page, or nullptr when rejected. Decodes it without its links
// too (Database's default until need_links): accepted whenever the whole page is, and equal to
// it but for the links. Cuts it too (cut()).
std::shared_ptr<const DecodedPage> decode(ByteView bytes, const Model& model, Tally& tally) {
  const auto page = decode_page_checked(bytes, model, tally);
  std::shared_ptr<const DecodedPage> lean;
  if (accepted("decode_page without links",
               [&] { lean = decode_page(bytes, model.grid, model.info, g_case.page, false); })) {
    if (auto bad = check_page(*lean, model.info); !bad.empty())
      fail("an inconsistent page without links: " + bad);
    if (page != nullptr) {
      if (auto bad = same_but_links(*page, *lean); !bad.empty())
        fail("decoded without links, the page differs: " + bad);
    }
  } else if (page != nullptr) {
    fail("a page decoded with its links but not without");
  }
  cut(bytes, model, page.get());
  return page;
}

// ---------------------------------------------------------------------------------------------
// The seeds: real pages of real databases.

struct Source {
  Model model;
  std::unique_ptr<Database> db;
  fs::path path;
};

std::string data_dir() {
  const char* dir = std::getenv("SMRDB_DATA_DIR");
  if (dir == nullptr || *dir == '\0') {
    std::fprintf(stderr,
                 "page fuzz: set SMRDB_DATA_DIR to the fetched datasets (scripts/fetch-data.sh)\n");
    std::exit(1);
  }
  return dir;
}

std::vector<Source> build_sources(const fs::path& dir) {
  const std::string data = data_dir();
  std::vector<fs::path> paths;
  GreedyTinOptions tin;
  tin.max_error = kTerrainError;
  const Crmr terrain = build_greedy_tin(read_dem(data + "/jacksboro_fault_dem.npz"), tin);
  for (CodecId codec : {CodecId::kZstd, CodecId::kRaw, CodecId::kDraco}) {
    Crmr copy = terrain;
    WriteOptions w;
    w.codec = codec;
    w.page_bytes = kPageBytes;
    paths.push_back(dir / ("jacksboro-" + std::string(storage::codec_name(codec)) + ".smrdb"));
    write_database(copy, paths.back().string(), w);
  }
  IngestOptions mesh;
  mesh.page_kb = 1;
  paths.push_back(dir / "blobby-zstd.smrdb");
  ingest(data + "/meshes/" + kMesh, paths.back().string(), mesh);
  std::vector<Source> sources;
  for (const fs::path& p : paths) {
    Source s;
    s.db = Database::open(p.string(), {});
    s.db->need_links();  // its pages are compared with decode_page's, links and all
    s.model = {p.filename().string(), s.db->grid(), s.db->info()};
    s.path = p;
    sources.push_back(std::move(s));
  }
  return sources;
}

// The grid and model of each seed database (built once, in a directory removed afterwards).
const std::vector<Model>& models() {
  static const std::vector<Model> m = [] {
    const test::TempDir dir("smrdb-page-fuzz");
    std::vector<Model> out;
    for (const Source& s : build_sources(dir.path())) out.push_back(s.model);
    return out;
  }();
  return m;
}

// Decodes `bytes` as a page of every model.
void decode_input(ByteView bytes, const std::string& name, Tally& tally) {
  for (const Model& m : models()) {
    g_case = {name + " as a page of " + m.name, "input", 0, 0, bytes};
    decode(bytes, m, tally);
  }
}

#ifndef SMRDB_LIBFUZZER
// ---------------------------------------------------------------------------------------------
// The smoke mode.

void on_crash() {
  if (g_reported) return;
  g_reported = true;
  std::fprintf(stderr, "page fuzz: crashed on %s\n", describe(g_case).c_str());
  save_input("page_fuzz-failure.page");
}

void on_signal(int sig) {
  if (sig == SIGALRM) std::fprintf(stderr, "page fuzz: one decode ran over %u s\n", kCaseSeconds);
  on_crash();
  std::signal(sig, SIG_DFL);
  std::raise(sig == SIGALRM ? SIGABRT : sig);
}

// Hooks printing the case on a crash (a sanitizer report: the death callback, or SIGABRT with
// abort_on_error; a signal) and the watchdog's alarm.
void install_crash_hooks() {
#if defined(__SANITIZE_ADDRESS__)
  __sanitizer_set_death_callback(on_crash);
#endif
  for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGALRM}) std::signal(sig, on_signal);
}

struct Seed {
  const Source* source;
  std::uint64_t number;
  Bytes bytes;  // the unsealed value
};

std::string page_name(const Source& s, std::uint64_t page) {
  return s.model.name + ": pages/" + std::to_string(page);
}

// Every page value of the source's file, unsealed as Database does.
std::vector<Seed> read_pages(const Source& s) {
  const storage::Env env = storage::Env::open_read_only(s.path.string(), kTableNames);
  const storage::ReadTxn txn = env.read();
  std::vector<Seed> seeds;
  txn.for_each(Table::kPages, [&](ByteView key, ByteView value) {
    const std::uint64_t n = storage::parse_key_u64(key, "pages");
    const ByteView payload = page_payload(value, table_name(Table::kPages), std::to_string(n));
    seeds.push_back({&s, n, Bytes(payload.begin(), payload.end())});
  });
  if (seeds.size() != s.db->page_count())
    fail(s.model.name + ": the pages table and meta disagree");
  return seeds;
}

// The unmutated page decodes to what Database::page gives, op for op.
void check_seed(const Seed& seed, Tally& tally) {
  g_case = {page_name(*seed.source, seed.number), "unmutated", 0, 0, seed.bytes};
  const auto mine = decode(seed.bytes, seed.source->model, tally);
  if (!mine) fail("a real page was rejected");
  const auto theirs = seed.source->db->page(seed.number);
  if (mine->size() != theirs->size()) fail("the page and Database::page differ in op count");
  for (std::size_t i = 0; i < mine->size(); ++i) {
    if (!(to_op((*mine)[i]) == to_op((*theirs)[i])))
      fail("op " + std::to_string(i) + " of the page differs from Database::page's");
  }
}

// A sample of `count` pages: R^0's, the largest, the smallest, then seeded others.
std::vector<const Seed*> sample(const std::vector<Seed>& seeds, const Source& s, std::size_t count,
                                Rng& rng) {
  std::vector<const Seed*> order;
  const auto by_size = [](const Seed& a, const Seed& b) { return a.bytes.size() < b.bytes.size(); };
  order.push_back(&seeds.at(s.db->locator(OpId(0)).first));
  order.push_back(&*std::max_element(seeds.begin(), seeds.end(), by_size));
  order.push_back(&*std::min_element(seeds.begin(), seeds.end(), by_size));
  for (std::size_t tries = 0; tries < 4 * count; ++tries)
    order.push_back(&seeds[rng.below(seeds.size())]);
  std::vector<const Seed*> out;
  for (const Seed* p : order) {
    if (out.size() == count) break;
    if (std::find(out.begin(), out.end(), p) == out.end()) out.push_back(p);
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Mutations.

constexpr std::size_t kMultiMutations = 48;  // per page, on its bytes and on its records

// A page cut into its parts (page.h's layout), to change one and re-assemble it.
struct Parts {
  std::uint8_t format = 0, codec = 0;
  std::array<std::uint64_t, 8> counts{};  // op count, then the seven totals
  ByteView packed, geo;                   // the records (zstd) and the geometry, as stored
  Bytes records;                          // decompressed
  storage::GeometryBlob geometry;
};

Parts split(ByteView page) {
  ByteReader r(page, "seed page");
  Parts p;
  p.format = r.u8();
  p.codec = r.u8();
  for (std::uint64_t& c : p.counts) c = r.varint();
  p.packed = r.blob();
  p.geo = r.blob();
  r.expect_end();
  p.records = storage::zstd_decompress(p.packed, std::size_t{1} << 31, "seed page");
  p.geometry = storage::decode_geometry(CodecId(p.codec), p.geo, "seed page");
  return p;
}

Bytes join(const Parts& p, ByteView packed, ByteView geo) {
  Bytes out;
  ByteWriter w(out);
  w.u8(p.format);
  w.u8(p.codec);
  for (std::uint64_t c : p.counts) w.varint(c);
  w.blob(packed);
  w.blob(geo);
  return out;
}

struct Tallies {
  std::array<Tally, 8> kinds;  // by kKinds
  std::chrono::duration<double> slowest{0};
  std::string slowest_case;
};
constexpr std::array<const char*, 8> kKinds = {"unmutated", "regression", "prefix",  "byte",
                                               "multi",     "header",     "records", "geometry"};

Tally& tally_of(Tallies& t, const char* kind) {
  for (std::size_t i = 0; i < kKinds.size(); ++i) {
    if (std::strcmp(kKinds[i], kind) == 0) return t.kinds[i];
  }
  fail(std::string("unknown kind ") + kind);
}

// Decodes one mutated input of the current seed, timing it. A truncated page, and the damage of
// the regression cases, must be rejected.
void run_case(ByteView bytes, const Model& model, const char* kind, std::size_t at,
              std::uint64_t value, Tallies& t) {
  g_case.kind = kind;
  g_case.at = at;
  g_case.value = value;
  const auto t0 = Clock::now();
  try {
    if (decode(bytes, model, tally_of(t, kind)) &&
        (std::strcmp(kind, "prefix") == 0 || std::strcmp(kind, "regression") == 0))
      fail(std::string("a damaged page decoded: ") + kind);
  } catch (const CaseFailed&) {
  }
  const auto took = Clock::now() - t0;
  if (took > t.slowest) {
    t.slowest = took;
    t.slowest_case = describe(g_case);
  }
}

// x^0x01, x^0x80, 0x00, 0xff and (with `rng`) a random byte, each once and none equal to x.
std::vector<std::uint8_t> replacements(std::uint8_t x, Rng* rng) {
  std::vector<std::uint8_t> out;
  std::vector<std::uint8_t> wanted = {std::uint8_t(x ^ 0x01), std::uint8_t(x ^ 0x80), 0x00, 0xff};
  if (rng != nullptr) wanted.push_back(std::uint8_t(x ^ (1 + rng->below(255))));
  for (std::uint8_t v : wanted) {
    if (v != x && std::find(out.begin(), out.end(), v) == out.end()) out.push_back(v);
  }
  return out;
}

// One seeded multi-byte mutation of `b`; `at` is set to where it starts.
void mutate(Bytes& b, Rng& rng, std::size_t& at) {
  at = rng.below(b.size());
  switch (rng.below(6)) {
    case 0:  // 2 to 8 random bytes anywhere
      for (std::size_t n = 2 + rng.below(7); n-- > 0;)
        b[rng.below(b.size())] = std::uint8_t(rng.next());
      break;
    case 1: {  // a run of 2 to 16 equal bytes
      const auto v = std::uint8_t(rng.below(2) == 0 ? 0x00 : 0xff);
      for (std::size_t i = at; i < std::min(b.size(), at + 2 + rng.below(15)); ++i) b[i] = v;
      break;
    }
    case 2:  // insert 1 to 8 random bytes
      for (std::size_t n = 1 + rng.below(8); n-- > 0;)
        b.insert(b.begin() + std::ptrdiff_t(at), std::uint8_t(rng.next()));
      break;
    case 3:  // delete 1 to 8 bytes
      b.erase(b.begin() + std::ptrdiff_t(at),
              b.begin() + std::ptrdiff_t(std::min(b.size(), at + 1 + rng.below(8))));
      break;
    case 4: {  // copy 2 to 32 bytes over another place
      const std::size_t from = rng.below(b.size());
      const std::size_t n = std::min({b.size() - from, b.size() - at, 2 + rng.below(31)});
      std::memmove(b.data() + at, b.data() + from, n);
      break;
    }
    default:  // append 1 to 8 bytes
      at = b.size();
      for (std::size_t n = 1 + rng.below(8); n-- > 0;) b.push_back(std::uint8_t(rng.next()));
  }
}

// The raw bytes: every prefix, every single-byte change, seeded multi-byte mutations.
void mutate_bytes(const Seed& seed, Rng& rng, Tallies& t) {
  const Model& model = seed.source->model;
  const Bytes& page = seed.bytes;
  for (std::size_t n = 0; n < page.size(); ++n) {
    run_case(ByteView(page).first(n), model, "prefix", n, 0, t);
  }
  Bytes b = page;
  for (std::size_t i = 0; i < b.size(); ++i) {
    for (std::uint8_t v : replacements(page[i], &rng)) {
      b[i] = v;
      run_case(b, model, "byte", i, v, t);
    }
    b[i] = page[i];
  }
  for (std::size_t k = 0; k < kMultiMutations; ++k) {
    Bytes m = page;
    std::size_t at = 0;
    for (std::size_t rounds = 1 + rng.below(3); rounds-- > 0;) mutate(m, rng, at);
    run_case(m, model, "multi", at, k, t);
  }
}

// Every face corner moved to the neighbouring vertices, every coordinate to the extremes of the
// grid and far off, re-encoded with the page's codec.
void mutate_geometry(Parts& p, const Model& model, Tallies& t) {
  storage::GeometryBlob& g = p.geometry;
  const auto with_geometry = [&](std::size_t at, std::uint64_t v) {
    Bytes geo;
    storage::encode_geometry(CodecId(p.codec), g, geo);
    run_case(join(p, p.packed, geo), model, "geometry", at, v, t);
  };
  const auto nv = std::uint32_t(g.positions.size());
  for (std::size_t f = 0; f < g.faces.size(); ++f) {
    for (std::size_t k = 0; k < 3; ++k) {
      const std::uint32_t c = g.faces[f][k];
      for (std::uint32_t v : {(c + 1) % nv, (c + nv - 1) % nv}) {
        g.faces[f][k] = v;
        with_geometry(3 * f + k, v);
      }
      g.faces[f][k] = c;
    }
  }
  constexpr std::int32_t kMin = std::numeric_limits<std::int32_t>::min();
  constexpr std::int32_t kMax = std::numeric_limits<std::int32_t>::max();
  for (std::size_t i = 0; i < g.positions.size(); ++i) {
    for (std::size_t a = 0; a < 3; ++a) {
      const std::int32_t c = g.positions[i][a];
      for (std::int32_t v : {kMin, kMax, kMin + 1, kMax - 1, c ^ (1 << 24)}) {
        g.positions[i][a] = v;
        with_geometry(3 * i + a, std::uint64_t(std::uint32_t(v)));
      }
      g.positions[i][a] = c;
    }
  }
}

// The header's counts, the decompressed records and the decoded geometry (page.h's layout).
void mutate_parts(const Seed& seed, Rng& rng, Tallies& t) {
  const Model& model = seed.source->model;
  Parts p = split(seed.bytes);
  for (std::size_t i = 0; i < p.counts.size(); ++i) {
    const std::uint64_t c = p.counts[i];
    for (std::uint64_t v :
         {c + 1, c - 1, std::uint64_t{0}, c + (std::uint64_t{1} << 32), std::uint64_t{1} << 63}) {
      if (v == c) continue;
      p.counts[i] = v;
      run_case(join(p, p.packed, p.geo), model, "header", i, v, t);
    }
    p.counts[i] = c;
  }
  Bytes& r = p.records;
  const auto with_records = [&](ByteView records, std::size_t at, std::uint64_t v) {
    run_case(join(p, storage::zstd_compress(records, 1), p.geo), model, "records", at, v, t);
  };
  for (std::size_t i = 0; i < r.size(); ++i) {
    const std::uint8_t x = r[i];
    for (std::uint8_t v : replacements(x, nullptr)) {
      r[i] = v;
      with_records(r, i, v);
    }
    r[i] = x;
    with_records(ByteView(r).first(i), i, 0);  // records cut short
  }
  for (std::size_t k = 0; k < kMultiMutations; ++k) {
    Bytes m = r;
    std::size_t at = 0;
    mutate(m, rng, at);
    with_records(m, at, k);
  }
  mutate_geometry(p, model, t);
}

// The damage the sweeps found in page format 3's first decoder, made directly from the ops of
// `seed` (R^0's page): each must be rejected, naming the page.
void regressions(const Seed& seed, Tallies& t) {
  const Model& model = seed.source->model;
  const auto codec = CodecId(seed.bytes.at(1));
  std::vector<Op> ops;
  for (const OpView& v : seed.source->db->page(seed.number)->ops()) ops.push_back(to_op(v));
  const auto encoded = [&] {
    std::vector<const Op*> page;
    for (const Op& o : ops) page.push_back(&o);
    return encode_page(page, model.grid, codec);
  };
  // 1. A death_res of 2: the records' child resolutions were read without a range check. (Only
  // a killer on another page has its birth_res stored with the triangle's op.)
  const auto off_page = [&](OpId killer) {
    return killer.valid() &&
           std::none_of(ops.begin(), ops.end(), [&](const Op& o) { return o.id == killer; });
  };
  const auto killed = std::find_if(ops.begin(), ops.end(), [&](const Op& o) {
    return std::any_of(o.fragment.begin(), o.fragment.end(),
                       [&](const FragmentTriangle& f) { return off_page(f.killer); });
  });
  if (killed == ops.end()) fail("R^0's page has no triangle replaced by another page's op");
  const Op saved = *killed;
  for (FragmentTriangle& f : killed->fragment) {
    if (off_page(f.killer)) f.death_res = 2.0;
  }
  run_case(encoded(), model, "regression", 1, 0, t);
  *killed = saved;
  // 2. A coordinate of INT32_MIN, on no grid: QuantGrid::quantize, called on the op's box, threw
  // kInvalidInput without the page's name.
  Parts p = split(seed.bytes);
  p.geometry.positions.at(0)[0] = std::numeric_limits<std::int32_t>::min();
  Bytes geo;
  storage::encode_geometry(codec, p.geometry, geo);
  run_case(join(p, p.packed, geo), model, "regression", 2, 0, t);
  // 3. An ROI past the grid's last step (the writer's box made smaller than its corners' so that
  // the stored margin is): the decoder's int32 sum wrapped and the ROI did not hold the box.
  Op& first = ops.front();
  first.box.hi.x = first.box.lo.x;
  first.roi.hi.x = model.grid.dequantize({std::numeric_limits<std::int32_t>::max(), 0, 0}).x;
  first.error = 0.0;  // the margin in single grid steps (roi_shift 0): the reader scales it up

  run_case(encoded(), model, "regression", 3, 0, t);
  // 4, 5. zstd geometry (codec.cpp's layout: the positions' and then the corners' deltas) of
  // two positions and one face, whose second x, then second corner, is 2^63 - 1 past the one
  // before: the decoder added the delta before its range check, a signed overflow (UBSan).
  for (std::size_t huge : {3, 7}) {
    std::array<std::int64_t, 9> deltas = {1000, 0, 0, 5, 0, 0, 1, -1, 1};
    deltas[huge] = std::numeric_limits<std::int64_t>::max();
    Bytes stream;
    ByteWriter s(stream);
    for (std::int64_t d : deltas) s.svarint(d);
    Bytes zstd;
    ByteWriter z(zstd);
    z.varint(2);
    z.varint(1);
    z.bytes(storage::zstd_compress(stream));
    p.codec = static_cast<std::uint8_t>(CodecId::kZstd);
    run_case(join(p, p.packed, zstd), model, "regression", huge == 3 ? 4 : 5, 0, t);
  }
}

// ---------------------------------------------------------------------------------------------
// The modes.

std::size_t pages_per_source(int argc, char** argv) {
  std::size_t n = test::kSanitized ? 6 : 10;
  if (const char* env = std::getenv("SMRDB_FUZZ_PAGES"); env != nullptr && *env != '\0')
    n = std::strtoull(env, nullptr, 10);
  if (argc == 3 && std::string_view(argv[1]) == "--pages") n = std::strtoull(argv[2], nullptr, 10);
  return n;
}

int smoke(std::size_t pages, std::uint64_t seed) {
  const auto t0 = Clock::now();
  const test::TempDir dir("smrdb-page-fuzz");
  const std::vector<Source> sources = build_sources(dir.path());
  const double setup = seconds_since(t0);
  Rng rng(seed);
  Tallies t;
  std::size_t fuzzed = 0, bytes = 0;
  for (const Source& s : sources) {
    const auto s0 = Clock::now();
    const std::vector<Seed> seeds = read_pages(s);
    for (const Seed& p : seeds) check_seed(p, tally_of(t, "unmutated"));
    g_keep_going = true;
    const std::vector<const Seed*> sampled = sample(seeds, s, std::max<std::size_t>(pages, 1), rng);
    g_case.page = page_name(s, sampled.front()->number);
    regressions(*sampled.front(), t);
    for (const Seed* p : std::span(sampled).first(std::min(pages, sampled.size()))) {
      g_case.page = page_name(s, p->number);
      mutate_bytes(*p, rng, t);
      mutate_parts(*p, rng, t);
      ++fuzzed;
      bytes += p->bytes.size();
    }
    g_keep_going = false;
    std::printf("%s: %llu ops in %zu pages, %zu fuzzed: %.1f s\n", s.model.name.c_str(),
                static_cast<unsigned long long>(s.db->op_count()), seeds.size(),
                std::min(pages, seeds.size()), seconds_since(s0));
  }
  const double total = seconds_since(t0);
  std::size_t decodes = 0;
  std::printf(
      "page_fuzz smoke (seed %#llx): %zu databases, %zu pages (%zu bytes) fuzzed, %.1f s "
      "(%.1f s building the databases)\n",
      static_cast<unsigned long long>(seed), sources.size(), fuzzed, bytes, total, setup);
  for (std::size_t i = 0; i < kKinds.size(); ++i) {
    const Tally& k = t.kinds[i];
    std::printf("  %-9s %8zu decodes: %8zu decoded, %8zu rejected\n", kKinds[i], k.decodes,
                k.decoded, k.rejected);
    decodes += k.decodes;
  }
  std::printf("  %zu decodes; slowest %.1f ms: %s\n", decodes, 1e3 * t.slowest.count(),
              t.slowest_case.c_str());
  std::printf("  accepted: %zu triangles with a corner twice, %zu dying before their op's birth\n",
              g_odd.repeated_corner, g_odd.dies_before_born);
  for (const Failure& f : g_failures) {
    std::fprintf(stderr, "page_fuzz: FAILED %zu times: %s\n  first: %s\n", f.count, f.why.c_str(),
                 f.first_case.c_str());
  }
  if (!g_failures.empty()) return 1;
  // A run whose mutations are all rejected (or all decoded) checks one side only.
  for (const char* kind : {"byte", "records", "geometry"}) {
    if (tally_of(t, kind).decoded == 0 || tally_of(t, kind).rejected == 0) {
      std::fprintf(stderr, "page_fuzz: the %s mutations did not reach both outcomes\n", kind);
      return 1;
    }
  }
  return 0;
}

int write_corpus(const fs::path& dir) {
  const test::TempDir tmp("smrdb-page-fuzz");
  fs::create_directories(dir);
  std::size_t n = 0;
  for (const Source& s : build_sources(tmp.path())) {
    for (const Seed& p : read_pages(s)) {
      std::ofstream out(dir / (s.model.name + "-" + std::to_string(p.number) + ".page"),
                        std::ios::binary);
      out.write(reinterpret_cast<const char*>(p.bytes.data()), std::streamsize(p.bytes.size()));
      ++n;
    }
  }
  std::printf("page_fuzz: %zu pages written to %s\n", n, dir.c_str());
  return 0;
}

int run_main(int argc, char** argv) {
  install_crash_hooks();
  g_watchdog = true;
  std::uint64_t seed = 0x5eed5eedULL;
  if (const char* env = std::getenv("SMRDB_FUZZ_SEED"); env != nullptr && *env != '\0')
    seed = std::strtoull(env, nullptr, 0);
  if (argc == 3 && std::string_view(argv[1]) == "--corpus") return write_corpus(argv[2]);
  if (argc == 1 || std::string_view(argv[1]) == "--pages")
    return smoke(pages_per_source(argc, argv), seed);
  Tally tally;
  for (int i = 1; i < argc; ++i) {
    std::ifstream in(argv[i], std::ios::binary);
    if (!in) {
      std::fprintf(stderr, "page_fuzz: cannot open %s\n", argv[i]);
      return 1;
    }
    const Bytes bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    decode_input(bytes, argv[i], tally);
  }
  std::printf("page_fuzz: %zu decodes: %zu decoded, %zu rejected\n", tally.decodes, tally.decoded,
              tally.rejected);
  return 0;
}

#endif  // SMRDB_LIBFUZZER

}  // namespace
}  // namespace smr::fuzz

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  smr::fuzz::Tally tally;
  smr::fuzz::decode_input(smr::storage::ByteView(data, size), "fuzz-input", tally);
  return 0;
}

#ifndef SMRDB_LIBFUZZER
#if defined(__SANITIZE_ADDRESS__)
// UBSan's report ends the process with exit code 1 and no death callback unless it aborts: with
// abort_on_error the SIGABRT hook prints the case (UBSAN_OPTIONS still overrides it).
extern "C" const char* __ubsan_default_options() {  // NOLINT(bugprone-reserved-identifier)
  return "abort_on_error=1";
}
#endif

int main(int argc, char** argv) {
  return smr::fuzz::run_main(argc, argv);
}
#endif
