// Damage to LMDB's own structure (docs/design.md section 3). reliability_test flips bits inside the
// sealed values; here the file is truncated at every page boundary and single bits are flipped in
// every 4 KiB page of a small database: the two meta pages byte by byte, and in every other page
// its header (page number, flags, lower/upper bounds or overflow page count), its node offsets,
// the node headers (value size or child page, flags, key size) and keys of its first, middle and
// last node, and a few payload bytes; and, in every page where it can occur, the damage that
// crashed LMDB 0.9 itself before storage/lmdb_env.cpp checked pages ahead of it (a zero page
// size, F_DUPDATA on a node of a plain table, a wrong mp_lower, a value running past the file).
// Each damaged file is verified, walked with cursors and extracted from in a worker process, so
// that a crash (SIGSEGV, SIGBUS, abort) or a hang is a test failure instead of the end of the
// test. Every case either reports an smr::Error naming the file (exit code 1), or is harmless:
// verify clean and every extraction equal to the undamaged one. Never "verify says OK" with a
// different mesh, never a different mesh without an error, never an extraction error that verify
// missed.
#include <gtest/gtest.h>

#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "base/error.h"
#include "smr/builders/terrain/greedy_tin.h"
#include "smr/db/database.h"
#include "smr/db/tables.h"
#include "smr/db/verify.h"
#include "smr/db/writer.h"
#include "smr/extract/extract.h"
#include "smr/io/synthetic.h"
#include "smr/query/indexed_source.h"
#include "smr/rcf/spec.h"
#include "storage/lmdb_env.h"
#include "tests/support/extraction_result.h"
#include "tests/support/files.h"
#include "tests/support/sanitized.h"

namespace smr {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr std::size_t kPage = 4096;          // LMDB's page size on the platforms the suite runs on
constexpr int kCaseSeconds = 120;            // a case still running after this is a hang
constexpr std::size_t kSanitizedStride = 5;  // the sweeps' sample under the sanitizers

using test::read_file;
using test::write_file;

struct TempDir : test::TempDir {
  TempDir() : test::TempDir("smrdb-lmdb-damage") {}
};

// ------------------------------------------------------------------------------ the database

// A fine RCF (a thousand triangles, most data pages) and a corner of the model at full
// resolution (a few pages reached through the R-tree and the locators).
std::vector<RcfSpec> specs(const CrmrInfo& info) {
  const Box3& b = info.bounds;
  const double w = b.hi.x - b.lo.x;
  RcfSpec fine, corner;
  fine.floor = 0.95;
  corner.floor = 0.0;
  corner.aois.push_back({b.lo.x + 0.1 * w, b.lo.y + 0.1 * w, 0.08 * w, 1.0});
  return {fine, corner};
}

using test::extract_all;
using test::Result;
using test::same;

// A 65 x 65 fBm terrain in data pages of about 2.4 KB (database format 5: each holds its R-tree
// leaf). The data pages are overflow values; the locators, internal R-tree nodes (fanout 2, so
// that there are many) and meta are values inside leaf pages; the locators, pages and rtree
// tables each have a branch page over two or more leaves.
struct SmallDb {
  TempDir dir;
  std::string path = dir.file("small.smrdb");
  std::string bytes;
  VerifyReport verified;
  std::vector<Result> results;
  SmallDb() {
    GreedyTinOptions build;
    build.max_error = 1.6;
    Crmr crmr = build_greedy_tin(make_fbm(65, 65, 7, 1600.0, 0, 0.5, 10.0), build);
    WriteOptions o;
    o.page_bytes = 2400;  // over LMDB's ~2 KB inline limit: overflow values
    o.rtree_fanout = 2;   // the rtree table holds the internal nodes: enough for a branch page
    write_database(crmr, path, o);
    bytes = read_file(path);
    verified = verify_database(path, nullptr);
    const auto db = Database::open(path, {std::size_t{1} << 30});
    for (const RcfSpec& spec : specs(db->info()))
      results.push_back(extract_all(IndexedSource(*db), spec));
  }
};

const SmallDb& small_db() {
  static const SmallDb db;
  return db;
}

// ------------------------------------------------------------ LMDB's layout (mdb.c, 64-bit)

// Only to name each page and find its structure; the code under test never sees this. MDB_page:
// pgno u64 @0, pad u16 @8, flags u16 @10, lower u16 @12, upper u16 @14 (an overflow page holds
// its page count u32 @12), node offsets u16 @16... MDB_node: lo u16, hi u16 (value size, or
// with flags the child page), flags u16, key size u16, key, value. A meta page holds MDB_meta
// @16: magic, version, address, map size, the free and the main MDB_db (48 bytes each: pad (the
// page size in the free one), flags, depth, branch/leaf/overflow page and entry counts, root),
// last page, transaction id.
constexpr std::uint16_t kBranch = 0x01, kLeaf = 0x02, kLeaf2 = 0x20;
constexpr std::uint16_t kBigData = 0x01, kSubData = 0x02;
constexpr std::size_t kMetaBytes = 16 + 136;  // page header + MDB_meta
constexpr std::size_t kPageSize = 16 + 24, kMainRoot = 16 + 72 + 40;
constexpr std::size_t kLastPgno = 16 + 120, kTxnId = 16 + 128;

std::uint64_t le(const std::string& b, std::size_t at, int bytes) {
  std::uint64_t v = 0;
  for (int i = bytes - 1; i >= 0; --i) v = (v << 8) | static_cast<std::uint8_t>(b.at(at + i));
  return v;
}

struct PageInfo {
  std::string table;            // whose tree holds the page ("main": the table of tables)
  std::string kind = "unused";  // meta, branch, leaf, overflow, overflow data, unused
};

// What every page of a (clean) file is, from a walk of its trees.
class Layout {
 public:
  explicit Layout(const std::string& file) : file_(file), pages_(file.size() / kPage) {
    for (std::size_t m = 0; m < 2 && m < pages_.size(); ++m) pages_[m].kind = "meta";
    const std::size_t meta = le(file, kTxnId, 8) >= le(file, kPage + kTxnId, 8) ? 0 : kPage;
    last_pgno_ = le(file, meta + kLastPgno, 8);
    walk(le(file, meta + kMainRoot, 8), "main", 0);
  }
  const std::vector<PageInfo>& pages() const { return pages_; }
  std::uint64_t last_pgno() const { return last_pgno_; }
  std::size_t count(const std::string& table, const std::string& kind) const {
    return static_cast<std::size_t>(std::count_if(
        pages_.begin(), pages_.end(), [&](auto& p) { return p.table == table && p.kind == kind; }));
  }

 private:
  void walk(std::uint64_t pgno, const std::string& table, int depth) {
    if (pgno == ~std::uint64_t{0}) return;  // an empty tree
    ASSERT_LT(pgno, pages_.size());
    ASSERT_LT(depth, 16);
    const std::size_t at = pgno * kPage;
    const auto flags = static_cast<std::uint16_t>(le(file_, at + 10, 2));
    ASSERT_TRUE((flags & (kBranch | kLeaf)) != 0 && (flags & kLeaf2) == 0) << pgno;
    pages_[pgno] = {table, (flags & kBranch) ? "branch" : "leaf"};
    for (std::size_t i = 0; i < (le(file_, at + 12, 2) - 16) / 2; ++i) {
      const std::size_t node = at + le(file_, at + 16 + 2 * i, 2);
      if (flags & kBranch) {
        walk(le(file_, node, 6), table, depth + 1);
        continue;
      }
      const auto node_flags = static_cast<std::uint16_t>(le(file_, node + 4, 2));
      const std::size_t ksize = le(file_, node + 6, 2);
      const std::size_t data = node + 8 + ksize;
      if (node_flags & kBigData) {
        const std::uint64_t first = le(file_, data, 8);
        ASSERT_LT(first, pages_.size());
        pages_[first] = {table, "overflow"};
        for (std::uint64_t k = 1; k < le(file_, first * kPage + 12, 4); ++k) {
          pages_.at(first + k) = {table, "overflow data"};
        }
      } else if (node_flags & kSubData) {
        walk(le(file_, data + 40, 8), file_.substr(node + 8, ksize), depth + 1);
      }
    }
  }

  const std::string& file_;
  std::vector<PageInfo> pages_;
  std::uint64_t last_pgno_ = 0;
};

// ------------------------------------------------------------------ one case in a child process

struct Case {
  std::string what;   // "page 17 (rtree leaf) byte 14 bit 3 (page header)", "truncated to 8192"
  std::string group;  // what the summary counts it under
  std::size_t offset = 0;
  int bit = -1;            // -1: truncate the file to `offset` bytes instead
  bool must_fail = false;  // the damage cannot be harmless
};

struct Outcome {
  bool finished = false;  // the child exited normally and reported
  std::string death;      // otherwise: how it ended
  bool verify_ok = false;
  std::vector<std::string> faults;    // the first faults verify reported
  std::vector<std::string> errors;    // smr::Error messages from opening, cursors, extraction
  std::vector<std::string> problems;  // violations the child found
};

std::string one_line(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  if (s.size() > 400) s.resize(400);
  return s;
}

// Runs in the child: verify, every table through a cursor, then the extractions. Writes lines
// "<tag>\t<text>" to `out`.
void examine(const std::string& path, const SmallDb& clean, std::string& out) {
  auto line = [&](const char* tag, const std::string& text) {
    out += tag;
    out += '\t';
    out += one_line(text);
    out += '\n';
  };
  auto error = [&](const Error& e, const char* where) {
    line("error", e.what());
    if (e.exit_code() != 1) line("problem", std::string("exit code 2 (internal) from ") + where);
  };
  const VerifyReport report = verify_database(path, nullptr);
  line("verify", report.ok() ? "ok" : "faults");
  for (std::size_t i = 0; i < report.faults.size() && i < 3; ++i) line("fault", report.faults[i]);
  try {
    const storage::Env env = storage::Env::open_read_only(path, kTableNames);
    const storage::ReadTxn txn = env.read();
    for (Table table : kAllTables) {
      std::uint64_t entries = 0;
      txn.for_each(table, [&](storage::ByteView, storage::ByteView) { ++entries; });
      if (entries != txn.count(table)) {
        line("error", path + ": table '" + std::string(table_name(table)) + "' counts " +
                          std::to_string(txn.count(table)) + " entries, a cursor finds " +
                          std::to_string(entries));
      }
    }
    env.release_mapped_pages();
  } catch (const Error& e) {
    error(e, "a cursor");
  }
  std::unique_ptr<Database> db;
  try {
    db = Database::open(path, {std::size_t{1} << 30});
  } catch (const Error& e) {
    error(e, "open");
    return;
  }
  const std::vector<RcfSpec> s = specs(db->info());
  for (std::size_t i = 0; i < s.size() && i < clean.results.size(); ++i) {
    try {
      if (same(extract_all(IndexedSource(*db), s[i]), clean.results[i])) {
        line("same", std::to_string(i));
      } else {
        line("problem", "RCF " + std::to_string(i) + ": a different mesh without an error");
      }
    } catch (const Error& e) {
      error(e, "extraction");
    }
  }
}

// The file `c` describes: the clean bytes with one bit flipped, or cut short.
std::string damaged(const std::string& clean, const Case& c) {
  std::string bytes = clean;
  if (c.bit < 0) {
    bytes.resize(c.offset);
  } else {
    bytes[c.offset] = static_cast<char>(bytes[c.offset] ^ (1 << c.bit));
  }
  return bytes;
}

void write_all(int fd, const std::string& s) {
  for (std::size_t done = 0; done < s.size();) {
    const ssize_t n = ::write(fd, s.data() + done, s.size() - done);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
    } else if (n < 0 && errno != EINTR) {
      return;
    }
  }
}

// A worker process examines case after case: the parent writes a case's index to `to`; the
// worker writes that damaged file to `path`, examines it and answers on `from`, ending with the
// line "end". Forking once per worker rather than once per case keeps the sweep's cost in the
// examination (a fork per case spent more time in copy-on-write page faults than in the test).
// A worker that dies (a crash, a sanitizer's abort, the alarm of a hang) takes only its current
// case with it: that case's outcome is the death, and the next case gets a new worker. A case
// that corrupted memory without a crash could disturb the worker's later cases; that can only
// add failures, and under the sanitizers the corruption itself is the failure.
struct Worker {
  pid_t pid = -1;
  int to = -1, from = -1;
  std::string path;            // its damaged copy of the file
  const Case* busy = nullptr;  // the case it is examining
  std::string answer;          // its answer to that case so far
};

[[noreturn]] void work(int in, int out, const std::vector<Case>& cases, const std::string& path,
                       const SmallDb& clean) {
  for (;;) {
    std::size_t i = 0;
    if (::read(in, &i, sizeof i) != static_cast<ssize_t>(sizeof i) || i >= cases.size()) {
      ::_exit(0);  // no atexit handlers or static destructors: those belong to the parent
    }
    ::alarm(kCaseSeconds);
    std::string answer;
    try {
      write_file(path, damaged(clean.bytes, cases[i]));
      examine(path, clean, answer);
    } catch (const std::exception& e) {
      answer += "problem\tan exception that is not an smr::Error: " + one_line(e.what()) + "\n";
    } catch (...) {
      answer += "problem\tan unknown exception\n";
    }
    answer += "end\t\n";
    ::alarm(0);
    write_all(out, answer);
  }
}

void close_pipes(Worker& w) {
  for (int* fd : {&w.to, &w.from}) {
    if (*fd >= 0) ::close(*fd);
    *fd = -1;
  }
}

// Forks worker `w` (closing, in the child, every other worker's pipes, so that a worker's death
// is seen as the end of its pipe).
void start_worker(Worker& w, std::vector<Worker>& all, const std::vector<Case>& cases,
                  const SmallDb& clean) {
  int commands[2], answers[2];
  if (::pipe(commands) != 0 || ::pipe(answers) != 0) throw std::runtime_error("pipe failed");
  std::fflush(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    for (Worker& other : all) close_pipes(other);
    ::close(commands[1]);
    ::close(answers[0]);
    work(commands[0], answers[1], cases, w.path, clean);
  }
  ::close(commands[0]);
  ::close(answers[1]);
  w.pid = pid;
  w.to = commands[1];
  w.from = answers[0];
}

// The outcome of a worker's complete answer.
Outcome parse(const std::string& answer) {
  Outcome o;
  std::istringstream in(answer);
  for (std::string l; std::getline(in, l);) {
    const std::size_t tab = l.find('\t');
    const std::string tag = l.substr(0, tab);
    const std::string rest = tab == std::string::npos ? "" : l.substr(tab + 1);
    if (tag == "verify") o.verify_ok = rest == "ok";
    if (tag == "fault") o.faults.push_back(rest);
    if (tag == "error") o.errors.push_back(rest);
    if (tag == "problem") o.problems.push_back(rest);
    if (tag == "end") o.finished = true;
  }
  return o;
}

// The outcome of a worker that ended in the middle of a case (reaped here).
Outcome death(Worker& w) {
  close_pipes(w);
  int status = 0;
  while (::waitpid(w.pid, &status, 0) < 0 && errno == EINTR) {
  }
  w.pid = -1;
  Outcome o;
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    o.death = sig == SIGALRM ? "hung (no result after " + std::to_string(kCaseSeconds) + " s)"
                             : "killed by signal " + std::to_string(sig) + " (" +
                                   std::string(strsignal(sig)) + ")";
  } else {
    o.death = "exited with status " + std::to_string(WEXITSTATUS(status)) + " without reporting";
  }
  return o;
}

// Reads what worker `w` has to say; returns its outcome once the case is complete.
std::optional<Outcome> hear(Worker& w) {
  char buf[4096];
  const ssize_t n = ::read(w.from, buf, sizeof buf);
  if (n < 0 && errno == EINTR) return std::nullopt;
  if (n <= 0) return death(w);
  w.answer.append(buf, static_cast<std::size_t>(n));
  if (w.answer.size() < 5 || w.answer.compare(w.answer.size() - 5, 5, "end\t\n") != 0) {
    return std::nullopt;
  }
  Outcome o = parse(w.answer);
  w.answer.clear();
  return o;
}

// --------------------------------------------------------------------------------- the sweep

struct Tally {
  std::size_t cases = 0, caught = 0, harmless = 0, crashes = 0, wrong = 0;
  std::string example;  // the first error reported
};

// The failures of one case (none: it passed).
std::vector<std::string> judge(const Case& c, const Outcome& o, const std::string& path) {
  std::vector<std::string> failures;
  if (!o.finished) return {o.death};
  failures = o.problems;
  for (const std::string& e : o.errors) {
    if (e.find(path) == std::string::npos) failures.push_back("an error not naming the file: " + e);
  }
  for (const std::string& f : o.faults) {  // only the first 3 are reported back
    if (f.find(path) == std::string::npos) failures.push_back("a fault not naming the file: " + f);
  }
  if (o.verify_ok && !o.errors.empty()) {
    failures.push_back("verify found nothing, but: " + o.errors.front());
  }
  if (o.verify_ok && o.errors.empty() && c.must_fail) {
    failures.push_back("the damage went unnoticed");
  }
  return failures;
}

void print_summary(const std::string& label, const std::map<std::string, Tally>& tally,
                   Clock::time_point start) {
  const Tally& t = tally.at("all");
  std::printf("%s: %zu cases, %zu errors caught, %zu harmless, %zu crashes, %zu wrong (%.1f s)\n",
              label.c_str(), t.cases, t.caught, t.harmless, t.crashes, t.wrong,
              std::chrono::duration<double>(Clock::now() - start).count());
  for (const auto& [group, g] : tally) {
    if (group == "all") continue;
    std::printf("  %-16s %4zu cases, %4zu caught, %4zu harmless, %zu crashes, %zu wrong; e.g. %s\n",
                group.c_str(), g.cases, g.caught, g.harmless, g.crashes, g.wrong,
                g.example.substr(0, 160).c_str());
  }
}

// Runs every case, in as many workers as there are cores (up to four; each with its own damaged
// copy of the file), judges each outcome and counts them, overall ("all") and per group.
std::map<std::string, Tally> sweep(const std::vector<Case>& all, const std::string& label) {
  // Under the sanitizers a sample: every 5th case, so that each kind of damage still occurs and,
  // 5 being prime to the 8 bytes of a field, every byte of a field somewhere.
  std::vector<Case> cases;
  for (std::size_t i = 0; i < all.size(); ++i) {
    if (smr::test::in_sample(i, kSanitizedStride)) cases.push_back(all[i]);
  }
  const auto start = Clock::now();
  const SmallDb& clean = small_db();
  TempDir dir;
  const std::size_t slots = std::clamp<std::size_t>(std::thread::hardware_concurrency(), 1, 4);
  std::vector<Worker> workers(slots);
  for (std::size_t s = 0; s < slots; ++s) {
    workers[s].path = dir.file("damaged" + std::to_string(s) + ".smrdb");
  }
  std::map<std::string, Tally> tally;
  std::size_t failing = 0;

  auto count = [&](const Case& c, const Outcome& o, const std::string& path) {
    const std::vector<std::string> failures = judge(c, o, path);
    const std::string first = !o.errors.empty()   ? o.errors.front()
                              : !o.faults.empty() ? o.faults.front()
                                                  : "";
    for (const std::string& group : {std::string("all"), c.group}) {
      Tally& t = tally[group];
      ++t.cases;
      if (!o.finished) {
        ++t.crashes;
      } else if (!failures.empty()) {
        ++t.wrong;
      } else if (!o.verify_ok || !o.errors.empty()) {
        ++t.caught;
        if (t.example.empty()) t.example = first;
      } else {
        ++t.harmless;
      }
    }
    if (!failures.empty() && ++failing <= 40) {
      std::string text;
      for (const std::string& f : failures) text += "\n  " + f;
      if (!o.faults.empty()) text += "\n  (verify: " + o.faults.front() + ")";
      if (!o.errors.empty()) text += "\n  (error: " + o.errors.front() + ")";
      ADD_FAILURE() << label << ": " << c.what << text;
    }
  };

  // A worker that died is gone before the next case is sent, so a write to a closed pipe
  // cannot happen; SIGPIPE is ignored all the same, as a kill from outside could race it.
  struct sigaction ignore {
  }, before{};
  ignore.sa_handler = SIG_IGN;
  ::sigaction(SIGPIPE, &ignore, &before);
  std::size_t next = 0, busy = 0;
  while (next < cases.size() || busy > 0) {
    for (Worker& w : workers) {
      if (w.busy != nullptr || next >= cases.size()) continue;
      if (w.pid < 0) start_worker(w, workers, cases, clean);
      const std::size_t i = next++;
      if (::write(w.to, &i, sizeof i) != static_cast<ssize_t>(sizeof i)) {
        throw std::runtime_error("cannot send a case to a worker");
      }
      w.busy = &cases[i];
      ++busy;
    }
    std::vector<pollfd> fds;
    std::vector<Worker*> polled;
    for (Worker& w : workers) {
      if (w.busy == nullptr) continue;
      fds.push_back({w.from, POLLIN, 0});
      polled.push_back(&w);
    }
    if (::poll(fds.data(), fds.size(), -1) < 0 && errno != EINTR) {
      throw std::runtime_error("poll failed");
    }
    for (std::size_t k = 0; k < fds.size(); ++k) {
      if (fds[k].revents == 0) continue;
      Worker& w = *polled[k];
      if (const std::optional<Outcome> o = hear(w)) {
        count(*w.busy, *o, w.path);
        w.busy = nullptr;
        --busy;
      }
    }
  }
  for (Worker& w : workers) {
    if (w.pid < 0) continue;
    close_pipes(w);  // the end of its commands: the worker exits
    while (::waitpid(w.pid, nullptr, 0) < 0 && errno == EINTR) {
    }
  }
  ::sigaction(SIGPIPE, &before, nullptr);
  if (failing > 40) ADD_FAILURE() << label << ": " << failing - 40 << " more failing cases";
  print_summary(label, tally, start);
  return tally;
}

// The cases of a list, each (offset, bit) once.
class Cases {
 public:
  void flip(std::size_t pgno, const PageInfo& p, std::size_t byte, int bit,
            const std::string& field, bool must_fail = false) {
    if (byte >= kPage || !seen_.insert({pgno * kPage + byte, bit}).second) return;
    Case c;
    c.offset = pgno * kPage + byte;
    c.bit = bit;
    c.must_fail = must_fail;
    c.group = p.table.empty() ? p.kind : p.table + " " + p.kind;
    c.what = "page " + std::to_string(pgno) + " (" + c.group + ") byte " + std::to_string(byte) +
             " bit " + std::to_string(bit) + " (" + field + ")";
    list_.push_back(c);
  }
  void truncate(std::size_t length, std::size_t of) {
    Case c;
    c.offset = length;
    c.what = "truncated to " + std::to_string(length) + " of " + std::to_string(of) + " bytes";
    c.group = length % kPage == 0 ? "page boundary" : "odd size";
    c.must_fail = true;
    list_.push_back(c);
  }
  const std::vector<Case>& list() const { return list_; }

 private:
  std::vector<Case> list_;
  std::set<std::pair<std::size_t, int>> seen_;
};

// ---------------------------------------------------------------------------------- the tests

TEST(LmdbDamage, SmallDatabaseSpansSeveralPagesPerTable) {
  const SmallDb& db = small_db();
  ASSERT_TRUE(db.verified.ok()) << db.verified.faults.front();
  ASSERT_EQ(db.results.size(), 2u);
  EXPECT_GT(db.results[0].minimal.triangles.size(), 500u);
  EXPECT_EQ(le(db.bytes, kPageSize, 4), kPage) << "LMDB's page size";
  EXPECT_EQ(db.bytes.size() % kPage, 0u);
  EXPECT_GE(db.bytes.size(), 100 * kPage);
  EXPECT_LE(db.bytes.size(), std::size_t{2} << 20);
  const Layout layout(db.bytes);
  EXPECT_EQ(layout.last_pgno() + 1, db.bytes.size() / kPage);
  EXPECT_EQ(layout.count("main", "leaf"), 1u);
  EXPECT_GE(layout.count("meta", "leaf"), 1u);
  for (const char* table : {"locators", "pages", "rtree"}) {
    EXPECT_GE(layout.count(table, "branch"), 1u) << table;
    EXPECT_GE(layout.count(table, "leaf"), 2u) << table;
  }
  EXPECT_GE(layout.count("pages", "overflow"), 50u);
  // A compacted copy has no free pages (and no free-list tree).
  EXPECT_EQ(layout.count("", "unused"), 0u);
  std::map<std::string, int> kinds;
  for (const PageInfo& p : layout.pages())
    ++kinds[p.table.empty() ? p.kind : p.table + " " + p.kind];
  std::string text;
  for (const auto& [kind, n] : kinds) text += " " + std::to_string(n) + " " + kind + ";";
  std::printf("%zu bytes, %zu LMDB pages:%s\n", db.bytes.size(), layout.pages().size(),
              text.c_str());
}

// Every byte of the page header and MDB_meta of both meta pages (page size, map size, both
// tables' records, last page, transaction id), one bit each.
TEST(LmdbDamage, BitFlipsInTheMetaPages) {
  const SmallDb& db = small_db();
  const Layout layout(db.bytes);
  Cases cases;
  for (std::size_t m = 0; m < 2; ++m) {
    for (std::size_t byte = 0; byte < kMetaBytes; ++byte) {
      cases.flip(m, layout.pages()[m], byte, static_cast<int>((byte + 3 * m) % 8),
                 byte < 16 ? "page header" : "meta");
    }
  }
  const auto tally = sweep(cases.list(), "meta pages");
  EXPECT_EQ(tally.at("all").crashes, 0u);
}

// The bits and bytes move with the page number, so that over the pages every bit of every header
// byte and every byte of a node header is flipped somewhere.
TEST(LmdbDamage, BitFlipsInEveryPage) {
  const SmallDb& db = small_db();
  const Layout layout(db.bytes);
  Cases cases;
  for (std::size_t pgno = 2; pgno < layout.pages().size(); ++pgno) {
    const PageInfo& p = layout.pages()[pgno];
    const std::size_t at = pgno * kPage;
    auto add = [&](std::size_t byte, const std::string& field, std::size_t salt = 0) {
      cases.flip(pgno, p, byte, static_cast<int>((byte * 5 + pgno + salt) % 8), field);
    };
    if (p.kind == "branch" || p.kind == "leaf") {
      add(pgno % 8, "page number");
      add((pgno + 4) % 8, "page number");
      for (std::size_t b = 8; b < 16; ++b) add(b, "page header");  // pad, flags, lower, upper
      add(10, "page flags", 3);
      add(12, "page lower", 3);
      const std::size_t n = (le(db.bytes, at + 12, 2) - 16) / 2;
      add(16 + pgno % 2, "node offsets");
      add(16 + 2 * (n - 1) + pgno % 2, "node offsets");
      add(16 + 2 * n + pgno % 2, "free space");
      // Half the node header (value size or child page, flags, key size) of the first, middle
      // and last node, and a key byte.
      for (const std::size_t i : {std::size_t{0}, n / 2, n - 1}) {
        const std::size_t node = le(db.bytes, at + 16 + 2 * i, 2);
        const std::size_t ksize = le(db.bytes, at + node + 6, 2);
        const std::string name = "node " + std::to_string(i) + " of " + std::to_string(n);
        for (std::size_t b = (pgno + i) % 2; b < 8; b += 2) add(node + b, name + " header");
        if (ksize > 0) add(node + 8 + (i + pgno) % ksize, name + " key");
      }
      add(kPage / 2, "middle");
      add(kPage - 1, "end");
    } else if (p.kind == "overflow") {
      // LMDB reads no byte of the header (a reader checks the page number, flags and page
      // count); the value is checksummed.
      if (pgno % 2 == 0) {
        add(pgno / 2 % 16, "page header");
      } else {
        add(pgno % 4 == 1 ? 16 : kPage - 1, "value");
      }
    } else {
      add(kPage / 2, "value");  // a later page of an overflow value: no header
    }
  }
  const auto tally = sweep(cases.list(), "every page");
  EXPECT_EQ(tally.at("all").crashes, 0u);
}

// The damage that crashed LMDB 0.9 (SIGFPE, SIGSEGV, SIGBUS, or an internal error) before
// storage/lmdb_env.cpp checked pages ahead of it, in every page where it can occur: each must be
// an error.
TEST(LmdbDamage, DamageThatCrashedLmdbIsAnError) {
  const SmallDb& db = small_db();
  const Layout layout(db.bytes);
  Cases cases;
  const std::size_t meta = le(db.bytes, kTxnId, 8) >= le(db.bytes, kPage + kTxnId, 8) ? 0 : 1;
  const PageInfo& m = layout.pages()[meta];
  cases.flip(meta, m, kPageSize + 1, 4, "page size 4096 ^ 4096 = 0: division by zero", true);
  cases.flip(meta, m, kPageSize + 2, 5, "page size ^ 2 MiB: reads past the file", true);
  cases.flip(meta, m, kPageSize + 3, 6, "page size ^ 1 GiB: reads past the file", true);
  cases.flip(meta, m, kLastPgno + 7, 2, "last page ^ 2^58: MDB_MAP_RESIZED", true);
  for (std::size_t pgno = 2; pgno < layout.pages().size(); ++pgno) {
    const PageInfo& p = layout.pages()[pgno];
    if (p.kind != "branch" && p.kind != "leaf") continue;
    const std::size_t at = pgno * kPage;
    // mp_lower ^ 16 or ^ 32: LMDB reads 8 or 16 node offsets more (from the free space) or less.
    cases.flip(pgno, p, 12, 4, "page lower ^ 16", true);
    cases.flip(pgno, p, 12, 5, "page lower ^ 32", true);
    if (p.kind != "leaf") continue;
    const std::size_t n = (le(db.bytes, at + 12, 2) - 16) / 2;
    for (const std::size_t i : {std::size_t{0}, n / 2, n - 1}) {
      const std::size_t node = le(db.bytes, at + 16 + 2 * i, 2);
      const std::string name = "node " + std::to_string(i) + " ";
      const std::size_t ksize = le(db.bytes, at + node + 6, 2);
      if (p.table == "main") {
        // A table's record: MDB_DUPSORT or MDB_INTEGERKEY, its root page ^ 2^56.
        cases.flip(pgno, p, node + 8 + ksize + 4, 2, name + "table flags + MDB_DUPSORT", true);
        cases.flip(pgno, p, node + 8 + ksize + 4, 3, name + "table flags + MDB_INTEGERKEY", true);
        cases.flip(pgno, p, node + 8 + ksize + 47, 0, name + "table root ^ 2^56", true);
        continue;
      }
      // F_DUPDATA in a table without MDB_DUPSORT: LMDB follows a null sub-cursor.
      cases.flip(pgno, p, node + 4, 2, name + "flags + F_DUPDATA", true);
      // The value size ^ 64 KiB or ^ 2 GiB: past its page, or past the file.
      cases.flip(pgno, p, node + 2, 0, name + "value size ^ 64 KiB", true);
      cases.flip(pgno, p, node + 3, 7, name + "value size ^ 2 GiB", true);
    }
  }
  const auto tally = sweep(cases.list(), "known crashes");
  EXPECT_EQ(tally.at("all").caught, tally.at("all").cases);
  std::size_t sampled = 0;
  for (std::size_t i = 0; i < cases.list().size(); ++i)
    sampled += smr::test::in_sample(i, kSanitizedStride);
  EXPECT_EQ(tally.at("all").cases, sampled);
}

// Truncation to every page boundary, to a size inside every other page and to one byte short
// (reliability_test tries a dozen sizes).
TEST(LmdbDamage, TruncationAtEveryPageBoundary) {
  const SmallDb& db = small_db();
  const std::size_t pages = db.bytes.size() / kPage;
  Cases cases;
  for (std::size_t p = 0; p < pages; ++p) {
    cases.truncate(p * kPage, db.bytes.size());
    if (p % 2 == 0) cases.truncate(p * kPage + 1 + (p * 977) % (kPage - 1), db.bytes.size());
  }
  cases.truncate(db.bytes.size() - 1, db.bytes.size());
  const auto tally = sweep(cases.list(), "truncation");
  EXPECT_EQ(tally.at("all").caught, tally.at("all").cases);
}

}  // namespace
}  // namespace smr
